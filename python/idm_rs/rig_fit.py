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
from typing import Any

import numpy as np
from numpy.typing import NDArray

from .realdata import RealDataError, RigData

#: the benchmark's published reference model (Janot, Gautier & Brunot 2019, Simulation_EMPS.m)
EMPS_REFERENCE = {"m": 95.1089, "fv": 203.5034, "fc": 20.3935, "offset": -3.1648}
#: the benchmark's filter and decimation (Script_IDIM_LS.m)
EMPS_FILTER_HZ, EMPS_FILTER_ORDER, EMPS_BORDER = 100.0, 4, 50
EMPS_DECIMATE = 5
#: Stribeck velocity tried for a static-friction peak [m/s]
EMPS_STRIBECK_VS = 5e-3
#: presliding stiffness of the Leuven element in the simulation [N/m]: stiff enough that
#: presliding is far below the encoder's resolution, the contact then acts as Coulomb friction
EMPS_PRESLIDING_STIFFNESS = 1e8


@dataclass
class RigFit:
    """What ``rig-fit`` reports (SI units)."""

    rig: str
    name: str
    params: dict[str, float]
    params_std: dict[str, float]
    rms: float  #: RMS of the fit's residual [N for EMPS's force equation]
    noise_rms: float  #: estimated measurement-noise RMS of the same quantity
    not_identifiable: list[str]
    correlation: dict[str, dict[str, float]] = field(default_factory=dict)
    metrics: dict[str, float] = field(default_factory=dict)
    reference: dict[str, float] = field(default_factory=dict)
    arrays: dict[str, NDArray[np.float64]] = field(default_factory=dict, repr=False)

    def to_dict(self) -> dict[str, Any]:
        return {"rig": self.rig, "name": self.name, "params": self.params, "params_std": self.params_std,
                "rms": self.rms, "noise_rms": self.noise_rms, "not_identifiable": self.not_identifiable,
                "correlation": self.correlation, "metrics": self.metrics, "reference": self.reference}


def _differentiate(q: NDArray[np.float64], t: NDArray[np.float64]) -> tuple[NDArray[np.float64], ...]:
    from scipy.signal import butter, filtfilt

    fs = 1.0 / float(np.median(np.diff(t)))
    b, a = butter(EMPS_FILTER_ORDER, EMPS_FILTER_HZ / (fs / 2.0))
    qf = filtfilt(b, a, q)
    dq = np.gradient(qf, t)
    ddq = np.gradient(dq, t)
    return qf, dq, ddq


def _lstsq(X: NDArray[np.float64], y: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.float64],
                                                                     NDArray[np.float64]]:
    beta, *_ = np.linalg.lstsq(X, y, rcond=None)
    e = y - X @ beta
    cov = np.var(e, ddof=X.shape[1]) * np.linalg.inv(X.T @ X)
    return beta, e, cov


def idim_ls(data: RigData) -> tuple[dict[str, float], dict[str, float], dict[str, dict[str, float]], float,
                                     NDArray[np.float64], float]:
    """(values, std, correlations, residual RMS [N], residual, Stribeck amplitude / its σ) of the
    inverse-model least squares on an EMPS run."""
    from scipy.signal import decimate

    qf, dq, ddq = _differentiate(data.response, data.t)
    sl = slice(EMPS_BORDER, -EMPS_BORDER)
    force = data.force[sl] if data.force is not None else None
    if force is None:
        raise RealDataError(f"{data.name}: no measured force")
    cols = [ddq[sl], dq[sl], np.sign(dq[sl]), np.ones_like(dq[sl])]
    X = np.column_stack([decimate(c, EMPS_DECIMATE) for c in cols])
    y = decimate(force, EMPS_DECIMATE)
    beta, e, cov = _lstsq(X, y)
    names = ["m", "fv", "fc", "offset"]
    std = np.sqrt(np.diag(cov))
    corr = cov / np.outer(std, std)
    # a static-friction peak beside the Coulomb level: does the data support one?
    v = dq[sl]
    stribeck = decimate(np.exp(-((v / EMPS_STRIBECK_VS) ** 2)) * np.sign(v), EMPS_DECIMATE)
    b2, _, cov2 = _lstsq(np.column_stack([X, stribeck]), y)
    z = float(abs(b2[-1]) / math.sqrt(cov2[-1, -1]))
    return (dict(zip(names, map(float, beta))), dict(zip(names, map(float, std))),
            {a: {b: float(corr[i, j]) for j, b in enumerate(names) if j != i} for i, a in enumerate(names)},
            float(np.sqrt(np.mean(e ** 2))), e, z)


def simulate_emps(data: RigData, params: dict[str, float], *, rtol: float = 1e-6) -> tuple[NDArray[np.float64],
                                                                                          NDArray[np.float64]]:
    """(position [m], motor force [N]) of the closed loop driven by the run's reference, with the
    engine's rig mechanism and Leuven friction (Coulomb ``fc``, viscous ``fv``, no Stribeck peak,
    stiff presliding), the body of mass ``m`` and a constant force ``-offset``, sampled at the
    run's times. The validation run's external force pulses are not modelled (the rig takes one
    input; and their recorded scale, uint8 0-5, did not improve even the inverse model with
    either sign)."""
    import idm_rs
    from idm_rs.batch import Rig

    meta = data.meta
    fc = max(params["fc"], 1e-6)
    p = idm_rs.Params(m1=params["m"], normal_force=1.0, mu_k=fc, mu_s=fc, sigma2=max(params["fv"], 0.0),
                      sigma1=0.0, fric_alpha=EMPS_PRESLIDING_STIFFNESS,
                      fric_beta=EMPS_PRESLIDING_STIFFNESS / (100.0 * fc), fric_gamma=0.0,
                      load_force=-params["offset"])
    rig = Rig("closed_loop", kp=meta["kp_per_s"], kv=meta["kv_V_s_per_m"], gain=meta["gtau_N_per_V"],
              limit=meta["saturation_V"])
    wave = idm_rs.Sampled(data.t, data.drive)
    r = idm_rs.simulate(p, wave, t_end=float(data.t[-1]), model=rig, piezo_hysteresis=False, method="rodas4",
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
    values, std, corr, rms, resid, z_stribeck = idim_ls(data)
    # white measurement noise of the force equation, from the residual's sample-to-sample part
    noise = float(np.std(np.diff(resid)) / math.sqrt(2.0))
    not_identifiable = ["fric_alpha (presliding stiffness)", "sigma1 (presliding damping)"]
    if z_stribeck < 2.0:
        not_identifiable.insert(0, "mu_s - mu_k (static-friction peak)")
    fit = RigFit("emps", data.name, values, std, rms, noise, not_identifiable, corr,
                 reference=dict(EMPS_REFERENCE), metrics={"stribeck_amplitude_sigmas": z_stribeck})
    if simulate:
        q_sim, f_sim = simulate_emps(data, values)
        qf = _differentiate(data.response, data.t)[0]
        fit.metrics["position_relative_error_pct"] = relative_error(qf, q_sim)
        if data.force is not None:
            fit.metrics["force_relative_error_pct"] = relative_error(data.force, f_sim)
        q_ref, f_ref = simulate_emps(data, EMPS_REFERENCE)
        fit.metrics["reference_model_position_relative_error_pct"] = relative_error(qf, q_ref)
        fit.metrics["reference_model_force_relative_error_pct"] = relative_error(data.force, f_ref)
        fit.arrays = {"t": data.t, "q": data.response, "q_sim": q_sim, "force": data.force if data.force is not None
                      else np.full_like(data.t, np.nan), "force_sim": f_sim}
    return fit


def validate_emps(fit: RigFit, validation: RigData, *, simulate: bool = True) -> None:
    """Add the benchmark's validation to ``fit`` (identified on the estimation run): the inverse
    model's force prediction on the validation run and, with ``simulate``, the closed loop's
    position and force errors there (``validation_*`` metrics) [%]."""
    qf, dq, ddq = _differentiate(validation.response, validation.t)
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


def rig_fit(data: RigData, *, simulate: bool = True) -> RigFit:
    """Identify the rig that recorded ``data``. For the EMPS estimation run, the validation run
    (``DATA_EMPS_PULSES.mat`` beside it) is evaluated too when present."""
    if data.rig == "emps":
        fit = fit_emps(data, simulate=simulate)
        other = data.path.with_name("DATA_EMPS_PULSES.mat")
        if data.path.name == "DATA_EMPS.mat" and other.exists():
            from .realdata import load_emps

            validate_emps(fit, load_emps(other), simulate=simulate)
        return fit
    raise RealDataError(f"rig-fit of the {data.rig} data set is not implemented yet (EMPS is)")


def plot_rig_fit(fit: RigFit, directory: Any) -> list[Any]:
    """Measured vs simulated position and force, and their residuals (one PNG)."""
    from pathlib import Path

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    if not fit.arrays:
        return []
    out = Path(directory)
    out.mkdir(parents=True, exist_ok=True)
    a = fit.arrays
    fig, axes = plt.subplots(4, 1, figsize=(10, 9), sharex=True, constrained_layout=True)
    axes[0].plot(a["t"], a["q"] * 1e3, color="0.3", lw=2, alpha=0.5, label="measured")
    axes[0].plot(a["t"], a["q_sim"] * 1e3, color="C3", lw=0.9, label="simulated (closed loop)")
    axes[0].set_ylabel("position [mm]")
    axes[0].legend(fontsize=8)
    axes[1].plot(a["t"], (a["q"] - a["q_sim"]) * 1e3, color="C3", lw=0.7)
    axes[1].set_ylabel("position error [mm]")
    axes[2].plot(a["t"], a["force"], color="0.3", lw=1.5, alpha=0.5, label="measured gtau vir")
    axes[2].plot(a["t"], a["force_sim"], color="C0", lw=0.7, label="simulated")
    axes[2].set_ylabel("motor force [N]")
    axes[2].legend(fontsize=8)
    axes[3].plot(a["t"], a["force"] - a["force_sim"], color="C0", lw=0.6)
    axes[3].set_ylabel("force error [N]")
    axes[3].set_xlabel("time t [s]")
    for ax in axes:
        ax.grid(alpha=0.3)
    m = fit.metrics
    axes[0].set_title(f"{fit.name}: m = {fit.params['m']:.2f} kg, fc = {fit.params['fc']:.2f} N, "
                      f"fv = {fit.params['fv']:.1f} N s/m, offset = {fit.params['offset']:.2f} N; relative error "
                      f"position {m.get('position_relative_error_pct', math.nan):.3g} %, "
                      f"force {m.get('force_relative_error_pct', math.nan):.3g} %", fontsize=9)
    path = out / f"rig_fit_{fit.name}.png"
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return [path]

