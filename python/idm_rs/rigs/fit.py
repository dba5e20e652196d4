"""Identification of a friction rig from its measurements (``idm-rs rig-fit``).

EMPS (the ball-screw drive of the nonlinearbenchmark.org EMPS set) is identified in two steps:

1. **Inverse model, least squares** (the benchmark's own IDIM-LS): the measured position is
   low-passed (4th-order Butterworth at 100 Hz, zero phase), differentiated twice by central
   differences, and the motor force ``gtau vir`` is regressed on [a, v, sgn v, 1] after
   decimation: ``F = m a + fv v + fc sgn(v) + offset``. The parameters' standard deviations come
   from the residual's spread and (XᵀX)⁻¹; their correlations likewise. A Stribeck term
   (``(fs − fc) exp(−(v/vs)²) sgn v``) is tried beside it: when its amplitude is within 2σ of
   zero, the data do not identify a static-friction peak (reported in ``not_identifiable``,
   with the presliding parameters, which 1 kHz position data cannot resolve).
2. **Forward simulation in the closed loop** with the engine's rig mechanism (one body on the
   same Leuven friction element as the IDM, driven by the benchmark's P-P position loop with its
   gains and 10 V saturation) from the measured reference: the benchmark's metric, the relative
   error ‖q − q_sim‖ / ‖q‖ [%] (and the same for the force), on the estimation run and on the
   validation run (its external force pulses act on the body).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Optional

import numpy as np
from numpy.typing import NDArray

from .data import RealDataError, RigData
from .regressors import (
    EMPS_BORDER,
    EMPS_DECIMATE,
    EMPS_FILTER_HZ,
    EMPS_FILTER_ORDER,
    SLIDER_MIN_GAP,
    SLIDER_PROMINENCE,
    Regression,
    emps_regression,
    frame_regression,
    slider_events,
)
from .signals import low_pass_derivatives, lstsq, slips

#: the benchmark's published reference model (Janot, Gautier & Brunot 2019, Simulation_EMPS.m)
EMPS_REFERENCE = {"m": 95.1089, "fv": 203.5034, "fc": 20.3935, "offset": -3.1648}
#: Stribeck velocity tried for a static-friction peak [m/s]
EMPS_STRIBECK_VS = 5e-3
#: presliding stiffness of the Leuven element in the simulation [N/m]: stiff enough that
#: presliding is far below the encoder's resolution, the contact then acts as Coulomb friction
EMPS_PRESLIDING_STIFFNESS = 1e8

#: the unit of every reported parameter (SI; "1": dimensionless)
UNITS = {"m": "kg", "fv": "N s/m", "fc": "N", "offset": "N", "mu_s": "1", "mu_k": "1", "fs": "N",
         "mu_sliding": "1", "f0_Hz": "Hz", "zeta": "1", "fc_over_k_m": "m", "mu_over_k_m_per_N": "m/N",
         "offset_m": "m"}
#: each metric a fit reports, in words, with its unit
METRIC_WORDS: dict[str, tuple[str, str]] = {
    "position_relative_error_pct": ("simulated position against the measured one: relative error", "%"),
    "force_relative_error_pct": ("simulated force against the measured one: relative error", "%"),
    "reference_model_position_relative_error_pct": ("the benchmark's reference model, position: relative error",
                                                    "%"),
    "reference_model_force_relative_error_pct": ("the benchmark's reference model, force: relative error", "%"),
    "validation_inverse_model_force_relative_error_pct": (
        "validation run, the inverse model's force (parameters from the estimation run): relative error", "%"),
    "validation_position_relative_error_pct": ("validation run, simulated position: relative error", "%"),
    "validation_force_relative_error_pct": ("validation run, simulated force: relative error", "%"),
    "inverse_model_relative_error_pct": ("the inverse model (the fitted equation on the measured motion): "
                                         "relative error", "%"),
    "stribeck_amplitude_sigmas": ("a Stribeck peak beside the Coulomb level: its amplitude in σ", "σ"),
    "sliding_share": ("share of the samples in sliding", ""),
    "slip_events": ("stick-slip events in the record", ""),
    "period_s": ("stick-slip period (median)", "s"),
    "peak_spread_N": ("spread of the slip-onset forces (1σ)", "N"),
    "trough_spread_N": ("spread of the forces where slips end (1σ)", "N"),
    "simulated_period_s": ("simulated stick-slip period", "s"),
    "simulated_peak_N": ("simulated slip-onset force (mean)", "N"),
    "simulated_trough_N": ("simulated force where slips end (mean)", "N"),
    "force_rms_residual_N": ("RMS of the simulated minus the measured force", "N"),
}

#: the unit of each rig's residual and noise RMS (its regression's left-hand side)
RESIDUAL_UNITS = {"emps": "N", "spring_slider": "N", "frame": "m"}

#: when a fit describes its record (``judge``): the benchmark's relative errors [%] of the
#: simulated force (EMPS; the published reference model reaches 5.4 %) or position (frame,
#: 5-11 % on the four loads) at most this; a spring–slider's simulated stick-slip period and
#: force swing within these shares of the measured ones (the slow runs: < 1 %)
MAX_RELATIVE_ERROR_PCT = 20.0
MAX_PERIOD_ERROR, MAX_SWING_ERROR = 0.10, 0.25


@dataclass
class RigFit:
    """What ``rig-fit`` reports (SI units)."""

    rig: str
    name: str
    params: dict[str, float]
    params_std: dict[str, float]
    rms: float  #: RMS of the fit's residual [N for EMPS's force equation]
    noise_rms: float  #: estimated measurement-noise RMS of the same quantity (NaN: could not be estimated)
    not_identifiable: list[str]
    correlation: dict[str, dict[str, float]] = field(default_factory=dict)
    metrics: dict[str, float] = field(default_factory=dict)
    reference: dict[str, float] = field(default_factory=dict)
    arrays: dict[str, NDArray[np.float64]] = field(default_factory=dict, repr=False)
    #: whether the identified model describes the record (None: not judged, e.g. no simulation)
    describes: Optional[bool] = None
    #: why, in one sentence with the numbers
    judgement: str = ""

    def report(self) -> str:
        """The fit in words first (does it describe the record, why), then every parameter with
        its unit and uncertainty, the residual against the noise, and every metric in words."""
        unit = RESIDUAL_UNITS[self.rig]
        lines = [f"{self.rig}: {self.name}", "In plain words"]
        if self.describes is None:
            lines.append("  The identified model was not judged against the record (no simulation was run).")
        else:
            lines.append(f"  The identified model {'describes' if self.describes else 'DOES NOT DESCRIBE'} the record: "
                         f"{self.judgement}.")
        if self.not_identifiable:
            lines.append("  Not identifiable from these data (not fitted): " + ", ".join(self.not_identifiable) + ".")
        if self.describes is False:
            lines.append("  What to do: do not use these values as a model of this record; diagnose the record "
                         "(idm-rs diagnose) to see what the model misses.")
        lines += ["", "The numbers behind it", "  parameters (±1σ):"]
        caveat = "   (not a model of this record: see above)" if self.describes is False else ""
        for k, v in self.params.items():
            ref = self.reference.get(k)
            u = UNITS.get(k, "")
            shown = f" {u}" if u and u != "1" else ""
            lines.append(f"    {k:<8} = {v:12.5g} ± {self.params_std[k]:.2g}{shown}"
                         + (f"   (benchmark reference {ref:g}{shown})" if ref else "") + caveat)
        noise = (f"{self.noise_rms:.4g} {unit} (robust estimate)"
                 if math.isfinite(self.noise_rms) and self.noise_rms > 0 else "could not be estimated")
        lines.append(f"  residual RMS {self.rms:.4g} {unit}, noise RMS {noise}")
        for k, v in self.metrics.items():
            words, u = METRIC_WORDS.get(k, (k.replace("_", " "), ""))
            value = f"{v:.0f}" if k == "slip_events" else f"{v:.4g}"
            lines.append(f"  {words}: {value}" + (f" {u}" if u else ""))
        return "\n".join(lines)

    def to_dict(self) -> dict[str, Any]:
        return {"rig": self.rig, "name": self.name, "params": self.params, "params_std": self.params_std,
                "units": {k: UNITS.get(k, "") for k in self.params}, "residual_unit": RESIDUAL_UNITS[self.rig],
                "rms": self.rms, "noise_rms": self.noise_rms, "not_identifiable": self.not_identifiable,
                "correlation": self.correlation, "metrics": self.metrics,
                "metric_words": {k: METRIC_WORDS.get(k, (k, ""))[0] for k in self.metrics},
                "metric_units": {k: METRIC_WORDS.get(k, ("", ""))[1] for k in self.metrics},
                "reference": self.reference,
                "describes": self.describes, "judgement": self.judgement}


def idim_ls(data: RigData) -> tuple[dict[str, float], dict[str, float], dict[str, dict[str, float]], float,
                                     NDArray[np.float64], float, Regression]:
    """(values, std, correlations, residual RMS [N], residual, Stribeck amplitude / its σ, the
    regression) of the inverse-model least squares on an EMPS run."""
    from scipy.signal import decimate

    if data.force is None:
        raise RealDataError(f"{data.name}: no measured force")
    reg = emps_regression(data)
    beta, e, cov = lstsq(reg.X, reg.y)
    names = list(reg.names)
    std = np.sqrt(np.diag(cov))
    corr = cov / np.outer(std, std)
    # a static-friction peak beside the Coulomb level: does the data support one?
    v = reg.signals["v"][EMPS_BORDER:-EMPS_BORDER]
    stribeck = decimate(np.exp(-((v / EMPS_STRIBECK_VS) ** 2)) * np.sign(v), EMPS_DECIMATE)
    b2, _, cov2 = lstsq(np.column_stack([reg.X, stribeck]), reg.y)
    z = float(abs(b2[-1]) / math.sqrt(cov2[-1, -1]))
    return (dict(zip(names, map(float, beta))), dict(zip(names, map(float, std))),
            {a: {b: float(corr[i, j]) for j, b in enumerate(names) if j != i} for i, a in enumerate(names)},
            float(np.sqrt(np.mean(e ** 2))), e, z, reg)


def simulate_emps(data: RigData, params: dict[str, float], *, rtol: float = 1e-6) -> tuple[NDArray[np.float64],
                                                                                          NDArray[np.float64]]:
    """(position [m], motor force [N]) of the closed loop driven by the run's reference, with the
    engine's rig mechanism and Leuven friction (Coulomb ``fc``, viscous ``fv``, no Stribeck peak,
    stiff presliding), the body of mass ``m`` and a constant force ``-offset``, sampled at the
    run's times. The validation run's external force pulses are not modelled (the rig takes one
    input; and their recorded scale, uint8 0-5, did not improve even the inverse model with
    either sign)."""
    from ..core.batch import Rig
    from ..core.params import Params
    from ..core.simulation import simulate as run_simulation
    from ..core.waveforms import Sampled

    meta = data.meta
    fc = max(params["fc"], 1e-6)
    p = Params(m1=params["m"], normal_force=1.0, mu_k=fc, mu_s=fc, sigma2=max(params["fv"], 0.0),
                      sigma1=0.0, fric_alpha=EMPS_PRESLIDING_STIFFNESS,
                      fric_beta=EMPS_PRESLIDING_STIFFNESS / (100.0 * fc), fric_gamma=0.0,
                      load_force=-params["offset"])
    rig = Rig("closed_loop", kp=meta["kp_per_s"], kv=meta["kv_V_s_per_m"], gain=meta["gtau_N_per_V"],
              limit=meta["saturation_V"])
    wave = Sampled(data.t, data.drive)
    r = run_simulation(p, wave, t_end=float(data.t[-1]), model=rig, piezo_hysteresis=False, method="rodas4",
                        rtol=rtol, atol=rtol, save_every=1, first_step=1e-5)
    q = np.interp(data.t, r.t, r.main_body)
    v = np.interp(data.t, r.t, r.main_body_velocity)
    u = meta["kv_V_s_per_m"] * (meta["kp_per_s"] * (data.drive - q) - v)
    force = meta["gtau_N_per_V"] * np.clip(u, -meta["saturation_V"], meta["saturation_V"])
    return q, force


def relative_error(measured: NDArray[np.float64], simulated: NDArray[np.float64]) -> float:
    """The benchmark's metric: 100 ‖measured − simulated‖ / ‖measured‖ [%] (edges dropped)."""
    m, s = measured[EMPS_BORDER:], simulated[EMPS_BORDER:]
    return float(100.0 * np.linalg.norm(m - s) / np.linalg.norm(m))


def fit_emps(data: RigData, *, simulate: bool = True) -> RigFit:
    values, std, corr, rms, resid, z_stribeck, reg = idim_ls(data)
    # white measurement noise of the force equation, from the residual's sample-to-sample part
    noise = reg.noise
    not_identifiable = ["fric_alpha (presliding stiffness)", "sigma1 (presliding damping)"]
    if z_stribeck < 2.0:
        not_identifiable.insert(0, "mu_s - mu_k (static-friction peak)")
    fit = RigFit("emps", data.name, values, std, rms, noise, not_identifiable, corr,
                 reference=dict(EMPS_REFERENCE), metrics={"stribeck_amplitude_sigmas": z_stribeck,
                 "inverse_model_relative_error_pct": float(100 * np.linalg.norm(resid) / np.linalg.norm(reg.y))})
    if simulate:
        q_sim, f_sim = simulate_emps(data, values)
        qf = reg.signals["q"]
        fit.metrics["position_relative_error_pct"] = relative_error(qf, q_sim)
        if data.force is not None:
            fit.metrics["force_relative_error_pct"] = relative_error(data.force, f_sim)
        q_ref, f_ref = simulate_emps(data, EMPS_REFERENCE)
        fit.metrics["reference_model_position_relative_error_pct"] = relative_error(qf, q_ref)
        if data.force is not None:
            fit.metrics["reference_model_force_relative_error_pct"] = relative_error(data.force, f_ref)
        fit.arrays = {"t": data.t, "q": data.response, "q_sim": q_sim, "force": data.force if data.force is not None
                      else np.full_like(data.t, np.nan), "force_sim": f_sim}
    return fit


def validate_emps(fit: RigFit, validation: RigData, *, simulate: bool = True) -> None:
    """Add the benchmark's validation to ``fit`` (identified on the estimation run): the inverse
    model's force prediction on the validation run and, with ``simulate``, the closed loop's
    position and force errors there (``validation_*`` metrics) [%]."""
    qf, dq, ddq = low_pass_derivatives(validation.response, validation.t, EMPS_FILTER_HZ, EMPS_FILTER_ORDER)
    p = fit.params
    pred = p["m"] * ddq + p["fv"] * dq + p["fc"] * np.sign(dq) + p["offset"]
    assert validation.force is not None
    sl = slice(EMPS_BORDER, -EMPS_BORDER)
    err = validation.force[sl] - pred[sl]
    fit.metrics["validation_inverse_model_force_relative_error_pct"] = float(
        100.0 * np.linalg.norm(err) / np.linalg.norm(validation.force[sl]))
    if simulate:
        q_sim, f_sim = simulate_emps(validation, p)
        fit.metrics["validation_position_relative_error_pct"] = relative_error(qf, q_sim)
        fit.metrics["validation_force_relative_error_pct"] = relative_error(validation.force, f_sim)


#: the simulated stick-slip: presliding stiffness [N/m] and number of periods simulated. In the
#: Leuven element a stuck body creeps at k V / (a (1 - Fh/S)); it breaks away when that reaches
#: the Stribeck velocity, at Fh = S (1 - k V / (a vs)): a stiff contact (a vs >> k V) makes the
#: breakaway force the static level Fs the record shows
SLIDER_PRESLIDING_STIFFNESS, SLIDER_PERIODS = 1e7, 8


def fit_spring_slider(data: RigData, *, simulate: bool = True) -> RigFit:
    """Static and kinetic friction of the spring–slider from its stick-slip: the spring force at
    each slip onset is the static friction force Fs; during a slip against constant kinetic
    friction the force swings symmetrically about Fc, so Fc = (peak + trough) / 2. Impulsive
    noise is removed by a running median first. Then the engine's rig mechanism (a spring pulled
    at the drive speed, the Leuven element with those levels) is simulated over
    ``SLIDER_PERIODS`` periods and its peaks, troughs and period compared with the record's.
    A run without stick-slip (steady sliding) gives the sliding friction level only."""
    from ..core.batch import Rig
    from ..core.params import Params
    from ..core.simulation import simulate as run_simulation
    from ..core.waveforms import Sampled

    meta = data.meta
    n_force, k, speed = meta["normal_force_N"], meta["stiffness_N_per_m"], meta["drive_speed_m_per_s"]
    ev = slider_events(data)
    force, noise, peaks, troughs = ev.force, ev.noise, ev.peaks, ev.troughs
    if peaks.size < 3 or troughs.size < 3:
        level = float(np.median(force))
        spread = float(np.std(force))
        return RigFit("spring_slider", data.name, {"mu_sliding": level / n_force},
                      {"mu_sliding": spread / n_force / math.sqrt(force.size)}, spread, noise,
                      ["mu_s (no stick-slip: no breakaway to read)", "mu_k vs stribeck_velocity and sigma2 (one speed)",
                       "fric_alpha", "sigma1"],
                      metrics={"slip_events": float(peaks.size)})
    fs_i, fm_i = force[peaks], force[troughs]
    fs, fm = float(fs_i.mean()), float(fm_i.mean())
    fc = 0.5 * (fs + fm)
    fs_sd, fm_sd = float(fs_i.std(ddof=1) / math.sqrt(fs_i.size)), float(fm_i.std(ddof=1) / math.sqrt(fm_i.size))
    period = float(np.median(np.diff(data.t[peaks])))
    params = {"mu_s": fs / n_force, "mu_k": fc / n_force, "fs": fs, "fc": fc}
    std = {"mu_s": fs_sd / n_force, "mu_k": 0.5 * math.hypot(fs_sd, fm_sd) / n_force, "fs": fs_sd,
           "fc": 0.5 * math.hypot(fs_sd, fm_sd)}
    metrics = {"slip_events": float(peaks.size), "period_s": period,
               "peak_spread_N": float(fs_i.std(ddof=1)), "trough_spread_N": float(fm_i.std(ddof=1))}
    fit = RigFit("spring_slider", data.name, params, std, float(np.std(fs_i)), noise,
                 ["stribeck_velocity (the slips are too fast for 2 kHz force samples)", "sigma2",
                  "fric_alpha", "sigma1"], metrics=metrics)
    if simulate:
        t_end = min(float(data.t[-1]), SLIDER_PERIODS * period)
        a = SLIDER_PRESLIDING_STIFFNESS
        p = Params(m1=meta["mass_kg"], normal_force=n_force, mu_s=params["mu_s"], mu_k=params["mu_k"],
                          stribeck_velocity=1e-4, sigma2=0.0, sigma1=0.0, fric_alpha=a, fric_beta=a / (100 * fs),
                          fric_gamma=0.0)
        # the record starts mid-stick: the spring already holds the first sample's force
        state = np.zeros(5)  # the rig's state: x, v, g, Fh, h
        state[0], state[3] = -force[0] / k, np.clip(force[0], -0.999 * fs, 0.999 * fs)
        drive = Sampled([0.0, t_end], [0.0, speed * t_end])
        r = run_simulation(p, drive, t_end=t_end, model=Rig("position", stiffness=k), piezo_hysteresis=False,
                            method="rodas4", rtol=1e-7, atol=1e-7, save_every=1, first_step=1e-6,
                            initial_state=state)
        sel = data.t <= t_end
        f_sim = k * (speed * data.t[sel] - np.interp(data.t[sel], r.t, r.main_body))
        sp, st = slips(data.t[sel], f_sim, SLIDER_PROMINENCE, SLIDER_MIN_GAP)
        metrics.update({
            "simulated_period_s": float(np.median(np.diff(data.t[sel][sp]))) if sp.size > 1 else math.nan,
            "simulated_peak_N": float(f_sim[sp].mean()) if sp.size else math.nan,
            "simulated_trough_N": float(f_sim[st].mean()) if st.size else math.nan,
            "force_rms_residual_N": float(np.sqrt(np.mean((force[sel] - f_sim) ** 2))),
        })
        fit.arrays = {"t": data.t[sel], "force": force[sel], "force_sim": f_sim}
    return fit


#: the simulated frame's mass [kg]: only ratios to the stiffness are identified, so any mass
#: with the identified m/k, c/k and Fc/k gives the same motion
FRAME_SIM_MASS = 1.0


def fit_frame(data: RigData, *, simulate: bool = True) -> RigFit:
    """The base-excited frame: m x'' = k (y - x) + c (y' - x') - Ff. Only the top plate's and the
    base's displacements are measured (no force), so the equation divided by k is identified:
    y - x = (m/k) x'' + (c/k) x' + (Fc/k) sgn x' + offset, regressed on the sliding samples
    (``FRAME_SLIDING_SHARE``) of the low-passed kinematics. Reported: the natural frequency
    f0 = 1 / (2 pi sqrt(m/k)) [Hz], the damping ratio, Fc/k [m] (the spring deflection at which
    the contact slides) and Fc / (k N) [m/N] with N the disc's weight. The mass, the stiffness
    and the friction coefficient are not identifiable on their own. The identified frame is then
    simulated with the engine's rig mechanism driven by the measured base motion."""
    t = data.t
    reg = frame_regression(data)
    x, y = reg.signals["x"], reg.signals["drive"]
    beta, e, cov = lstsq(reg.X, reg.y)
    sd = np.sqrt(np.diag(cov))
    m_k, c_k, fc_k, off = map(float, beta)
    weight = data.meta["disc_weight_N"]
    f0 = 1.0 / (2.0 * math.pi * math.sqrt(m_k))
    zeta = c_k / (2.0 * math.sqrt(m_k))
    params = {"f0_Hz": f0, "zeta": zeta, "fc_over_k_m": fc_k, "mu_over_k_m_per_N": fc_k / weight, "offset_m": off}
    std = {"f0_Hz": 0.5 * f0 * float(sd[0]) / m_k, "zeta": float(sd[1]) / (2.0 * math.sqrt(m_k)),
           "fc_over_k_m": float(sd[2]), "mu_over_k_m_per_N": float(sd[2]) / weight, "offset_m": float(sd[3])}
    noise = reg.noise
    fit = RigFit("frame", data.name, params, std, float(np.sqrt(np.mean(e ** 2))), noise,
                 ["m", "k", "mu_k (only mu_k N / k: no force is measured)", "mu_s - mu_k", "stribeck_velocity",
                  "fric_alpha", "sigma1"],
                 metrics={"sliding_share": float(reg.signals["sliding"].mean()),
                          "inverse_model_relative_error_pct": float(100 * np.linalg.norm(e) /
                                                                    np.linalg.norm(reg.y))})
    if simulate:
        from ..core.batch import Rig
        from ..core.params import Params
        from ..core.simulation import simulate as run_simulation
        from ..core.waveforms import Sampled

        k = FRAME_SIM_MASS / m_k
        fc = max(fc_k * k, 1e-9)
        alpha = 1e3 * k
        p = Params(m1=FRAME_SIM_MASS, normal_force=1.0, mu_s=fc, mu_k=fc, stribeck_velocity=1e-4,
                          sigma2=0.0, sigma1=0.0, fric_alpha=alpha, fric_beta=alpha / (100 * fc), fric_gamma=0.0,
                          load_force=-off * k)
        rig = Rig("position", stiffness=k, damping=max(c_k, 0.0) * k)
        r = run_simulation(p, Sampled(t, y), t_end=float(t[-1]), model=rig, piezo_hysteresis=False,
                            method="rodas4", rtol=1e-7, atol=1e-7, save_every=1, first_step=1e-5,
                            initial_state=np.array([x[0], 0.0, 0.0, 0.0, 0.0]))
        x_sim = np.interp(t, r.t, r.main_body)
        fit.metrics["position_relative_error_pct"] = float(100 * np.linalg.norm(x - x_sim) / np.linalg.norm(x))
        fit.arrays = {"t": t, "q": data.response, "q_sim": x_sim, "drive": data.drive}
    return fit


def rig_fit(data: RigData, *, simulate: bool = True) -> RigFit:
    """Identify the rig that recorded ``data`` and judge whether the identified model describes
    the record (:func:`judge`). For the EMPS estimation run, the validation run
    (``DATA_EMPS_PULSES.mat`` beside it) is evaluated too when present.

    Parameters
    ----------
    data : RigData
        A recording loaded by :func:`idm_rs.rigs.load` (its ``rig``: ``"emps"``, ``"frame"`` or
        ``"spring_slider"``).
    simulate : bool
        Also simulate the identified model against the record (what :func:`judge` reads).

    Returns
    -------
    RigFit
        The identified parameters with their 1σ [SI], the fit's RMS and the noise RMS [the rig's
        unit: N for the EMPS force equation], what the record cannot identify, and whether the
        identified model describes the record; ``.report()`` prints it.

    Examples
    --------
    >>> from idm_rs.rigs import load, rig_fit          # doctest: +SKIP
    >>> print(rig_fit(load("DATA_EMPS.mat")).report())  # doctest: +SKIP
    """
    if data.rig == "emps":
        fit = fit_emps(data, simulate=simulate)
        other = data.path.with_name("DATA_EMPS_PULSES.mat")
        if data.path.name == "DATA_EMPS.mat" and other.exists():
            from .data import load_emps

            validate_emps(fit, load_emps(other), simulate=simulate)
    elif data.rig == "spring_slider":
        fit = fit_spring_slider(data, simulate=simulate)
    elif data.rig == "frame":
        fit = fit_frame(data, simulate=simulate)
    else:
        raise RealDataError(f"rig-fit of the {data.rig} data set is not implemented")
    fit.describes, fit.judgement = judge(fit)
    return fit


def judge(fit: RigFit) -> tuple[Optional[bool], str]:
    """Whether ``fit``'s identified model describes its record, and why (one sentence with the
    numbers): the simulation against the record where one was run (EMPS: the force's relative
    error; frame: the position's; spring–slider: the stick-slip period and force swing), else the
    inverse model's relative error. None where nothing judges it."""
    m = fit.metrics
    lim = MAX_RELATIVE_ERROR_PCT
    if fit.rig == "spring_slider":
        if "period_s" not in m:
            return True, "steady sliding (no stick-slip): the record gives the sliding friction level only"
        if "simulated_period_s" not in m:
            return None, "not judged: no simulation was run (--no-simulation)"
        t_meas, t_sim = m["period_s"], m["simulated_period_s"]
        swing = 2.0 * (fit.params["fs"] - fit.params["fc"])  # peak - trough, measured
        swing_sim = m["simulated_peak_N"] - m["simulated_trough_N"]
        dt, ds = t_sim / t_meas - 1.0, swing_sim / swing - 1.0
        what = (f"simulated stick-slip period {t_sim:.4g} s against {t_meas:.4g} s measured ({100 * dt:+.0f} %), "
                f"force swing {swing_sim:.3g} N against {swing:.3g} N ({100 * ds:+.0f} %)")
        if not math.isfinite(dt) or abs(dt) > MAX_PERIOD_ERROR or not math.isfinite(ds) or abs(ds) > MAX_SWING_ERROR:
            return False, (f"{what}: the model (constant mu_s and mu_k, a stiff contact) does not reproduce this "
                           f"record (limits {100 * MAX_PERIOD_ERROR:.0f} % and {100 * MAX_SWING_ERROR:.0f} %); "
                           "mu_s and mu_k are the levels of its slips, not a model of it")
        return True, what
    if fit.rig == "emps":
        key, what = "force_relative_error_pct", "simulated motor force"
    else:
        key, what = "position_relative_error_pct", "simulated top-plate position"
    if key not in m:  # no simulation: the inverse model's residual against its left-hand side
        key, what = "inverse_model_relative_error_pct", ("inverse model's force" if fit.rig == "emps"
                                                          else "inverse model's spring deflection")
    err = m[key]
    text = f"{what}: relative error {err:.3g} % (limit {lim:g} %)"
    if not (err <= lim):
        return False, f"{text}: the identified model does not describe this record"
    return True, text
