"""Diagnosis on measured rig data: locate the residual of the identified friction model, name
the missing physics from a catalogue of rig effects, refit with it and show the improvement
(``idm-rs diagnose PATH`` with a data file).

The rigs' identified models are linear in their parameters (``fit.py``'s inverse models, on the
rows ``regressors.py`` prepares for both), so
each candidate effect is a few more regression columns, refitted exactly by least squares:

* ``stribeck_peak`` — a static-friction excess at low speed: ``s · exp(−(v/vs)²) sgn v`` with
  s > 0 (a negative amplitude is not a static excess and is not named), vs scanned;
* ``position_dependent`` — friction varying along the stroke: ``(p1 u + p2 u²) sgn v``, u the
  position scaled to −1..1 over the stroke (amplitudes in the regression's unit);
* ``cogging`` — a ripple with the position: ``a sin(2π q/λ) + b cos(2π q/λ)``, λ scanned over
  wavelengths with at least two periods in the stroke;
* ``position_force`` — a smooth force of the position alone (a non-linear spring, a slope):
  ``n2 u² + n3 u³``;
* ``stick_time_aging`` (spring–slider) — the static friction grows with the time stuck before a
  slip (rate/state friction): ``Fs = F0 + β ln(t_stick)``.

A direction asymmetry of the Coulomb level is not a separate candidate for EMPS and the frame:
their identified models hold a constant force, and ``fc sgn v + offset`` already is a level of
``fc + offset`` forward and ``fc − offset`` backward (the offset is the asymmetry's half).

A candidate is named when it lowers BIC by at least ``BIC_THRESHOLD`` and its amplitude is
beyond ``NULL_SIGMAS`` σ of zero — several amplitudes jointly, by a Wald test at that level —
with the physical sign where it has one. Real data do not fit to their noise floor: the report says
what remains (residual RMS against the white-noise estimate, and where it lives).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Callable, Optional

import numpy as np
from numpy.typing import NDArray

from ..diagnosis.thresholds import BIC_THRESHOLD
from .data import RigData
from .fit import RESIDUAL_UNITS
from .regressors import emps_regression, frame_regression, slider_events
from .signals import lstsq

#: a candidate's amplitudes must each be this many σ from zero (its BIC gain must reach the IDM
#: diagnosis's ``BIC_THRESHOLD``)
NULL_SIGMAS = 2.0
#: each rig effect in words and the term it adds (u: the position scaled to -1..1 over the stroke)
EFFECT_WORDS: dict[str, tuple[str, str]] = {
    "stribeck_peak": ("a static-friction peak at low speed (Stribeck)", "s exp(-(v/vs)^2) sgn v"),
    "position_dependent": ("friction that changes along the stroke", "(p1 u + p2 u^2) sgn v"),
    "cogging": ("a force rippling with the position (cogging)", "a sin(2 pi q/lambda) + b cos(2 pi q/lambda)"),
    "position_force": ("a smooth force of the position alone (a non-linear spring or a slope)", "n2 u^2 + n3 u^3"),
    "stick_time_aging": ("static friction that grows with the time stuck before a slip (rate/state aging)",
                         "Fs = F0 + beta ln(t_stick / 1 s)"),
    "drift_over_record": ("an onset force that drifts over the record", "Fs = F0 + drift t"),
}


def param_unit(rig: str, name: str) -> str:
    """The unit of a rig candidate's amplitude: the regression's left-hand side (N for EMPS and
    the slider's forces, m for the frame's deflection), per second for a drift."""
    if name == "drift_N_per_s":
        return "N/s"
    if name.endswith("_N"):
        return "N"
    return RESIDUAL_UNITS.get(rig, "")


def _with_unit(value: float, std: float, unit: str) -> str:
    return f"{value:.4g} ± {std:.2g}" + (f" {unit}" if unit else "")


#: scanned Stribeck velocities [m/s] and cogging wavelengths [m]
STRIBECK_VS = (1e-3, 3e-3, 1e-2, 3e-2)
COGGING_WAVELENGTHS = tuple(np.geomspace(2e-3, 0.1, 25))


@dataclass
class RigCandidate:
    effect: str
    delta_bic: float
    rms_after: float
    values: dict[str, float]
    std: dict[str, float]
    setting: str = ""

    #: amplitudes that must be positive to be this physics
    positive: tuple[str, ...] = ()
    #: the residual with this candidate refitted
    residual: NDArray[np.float64] = field(default_factory=lambda: np.zeros(0), repr=False)
    #: covariance of the amplitudes (in `values` order), for their joint test
    cov: NDArray[np.float64] = field(default_factory=lambda: np.zeros((0, 0)), repr=False)

    @property
    def significant(self) -> bool:
        return not self.why_not_named()

    def why_not_named(self) -> str:
        """Why this candidate cannot be named whatever its BIC gain ("" when it can): an
        amplitude with the unphysical sign, or one within ``NULL_SIGMAS`` σ of zero."""
        for k, v in self.values.items():
            if k in self.positive and v <= 0:
                return (f"its amplitude {k} = {v:.4g} has the unphysical sign (a static-friction excess must be "
                        "positive)")
        names = list(self.values)
        if len(names) == 1 or self.cov.shape != (len(names), len(names)):
            weak = [k for k, v in self.values.items() if not abs(v) > NULL_SIGMAS * self.std[k]]
            if weak:
                return (f"its amplitude{'s' if len(weak) > 1 else ''} {', '.join(weak)} "
                        f"{'are' if len(weak) > 1 else 'is'} within {NULL_SIGMAS:g} σ of zero")
            return ""
        # several amplitudes (a linear and a quadratic term, a sine and a cosine): jointly away
        # from zero, as far as one amplitude beyond NULL_SIGMAS σ is (a Wald test at its level;
        # one of them may well be zero: a purely linear dependence, a ripple in phase)
        from scipy.stats import chi2, norm

        b = np.array([self.values[k] for k in names])
        wald = float(b @ np.linalg.pinv(self.cov) @ b)
        level = 2.0 * float(norm.sf(NULL_SIGMAS))
        if not wald > chi2.isf(level, len(names)):
            return (f"its amplitudes {', '.join(names)} are jointly within {NULL_SIGMAS:g} σ of zero "
                    f"(Wald χ² {wald:.1f} on {len(names)})")
        return ""


@dataclass
class RigDiagnosis:
    rig: str
    name: str
    verdict: str
    reason: str
    rms_before: float
    rms_after: float
    noise_rms: float
    ranking: list[RigCandidate]
    locations: list[str] = field(default_factory=list)
    arrays: dict[str, NDArray[np.float64]] = field(default_factory=dict, repr=False)

    def plain_summary(self) -> list[str]:
        """What was found, how sure, what remains and what to do, in words (as the IDM
        diagnosis's report opens)."""
        from ..diagnosis.report_format import evidence_words

        unit = RESIDUAL_UNITS.get(self.rig, "SI")
        named = next((c for c in self.ranking if c.effect == self.verdict), None)
        lines = ["In plain words"]
        if named is not None:
            words, term = EFFECT_WORDS.get(named.effect, (named.effect, ""))
            values = ", ".join(f"{k} = {_with_unit(v, named.std[k], param_unit(self.rig, k))}"
                               for k, v in named.values.items())
            lines.append(f"  Found: {words}.")
            lines.append(f"  How sure: {evidence_words(named.delta_bic)} evidence (BIC lower by {named.delta_bic:.0f}; "
                         f"its amplitudes beyond {NULL_SIGMAS:g} σ of zero).")
            lines.append(f"  What to do: add {term} to the identified friction model with {values}"
                         + (f" ({named.setting})" if named.setting else "") + ".")
        elif self.verdict == "none":
            lines.append("  Found: nothing missing — the identified model leaves the record's noise.")
            lines.append("  What to do: keep the identified model (rig-fit gives its parameters).")
        elif self.verdict == "not_converged":
            lines.append(f"  Found: no answer — {self.reason}.")
            lines.append("  What to do: record a longer run.")
        else:
            lines.append("  Found: no catalogue effect explains the residual.")
            lines.append("  What to do: look at where the residual lives (below) and at the residual figure.")
        if self.noise_rms > 0 and math.isfinite(self.rms_after):
            ratio = self.rms_after / self.noise_rms
            lines.append(f"  What remains: a residual RMS of {self.rms_after:.4g} {unit}, {ratio:.1f} x the record's "
                         "white-noise estimate" + (" (real data do not fit to their noise floor)" if ratio > 1.5
                                                    else "") + ".")
        return lines

    def report(self) -> str:
        unit = RESIDUAL_UNITS.get(self.rig, "SI")
        lines = [f"{self.rig}: {self.name}", *self.plain_summary(), "", "The numbers behind it",
                 f"VERDICT: {self.verdict.upper()} — {self.reason}",
                 f"residual RMS {self.rms_before:.4g} {unit} (identified model) -> {self.rms_after:.4g} {unit} "
                 f"(with the verdict); white-noise estimate {self.noise_rms:.4g} {unit}", "Where the residual lives:"]
        lines += [f"  {loc}" for loc in self.locations]
        lines.append("Candidates (ΔBIC > 0: better than the identified model; σ: smallest |amplitude|/σ):")
        for c in self.ranking:
            z = min((abs(v) / c.std[k] for k, v in c.values.items() if c.std[k] > 0), default=math.nan)
            vals = ", ".join(f"{k} = {_with_unit(v, c.std[k], param_unit(self.rig, k))}" for k, v in c.values.items())
            lines.append(f"  {c.effect:<22} ΔBIC {c.delta_bic:10.1f}   {z:6.1f} σ   RMS {c.rms_after:.4g} {unit}   "
                         f"{vals}" + (f"   [{c.setting}]" if c.setting else ""))
        # a candidate whose BIC gain passes the threshold but that is not named: say why
        named = next((c for c in self.ranking if c.effect == self.verdict), None)
        for c in self.ranking:
            why = c.why_not_named()
            if why and c.delta_bic >= BIC_THRESHOLD:
                more = named is not None and c.delta_bic > named.delta_bic
                lines.append(f"  Not named: {c.effect} lowers BIC{' more' if more else ''} (by {c.delta_bic:.0f}), "
                             f"but {why}.")
        if not self.noise_rms > 0:
            lines.append("What remains: not judged — the record's white noise could not be estimated.")
        elif self.rms_after > 1.5 * self.noise_rms:
            ratio = self.rms_after / self.noise_rms if self.noise_rms > 0 else math.inf
            lines.append(f"What remains: {ratio:.1f} x the white-noise estimate — real data "
                         "do not fit to their noise floor; the remainder is not explained by this catalogue.")
        return "\n".join(lines)

    def to_dict(self) -> dict[str, Any]:
        return {"rig": self.rig, "name": self.name, "verdict": self.verdict, "reason": self.reason,
                "rms_before": self.rms_before, "rms_after": self.rms_after, "noise_rms": self.noise_rms,
                "locations": self.locations,
                "residual_unit": RESIDUAL_UNITS.get(self.rig, ""),
                "ranking": [{"effect": c.effect, "words": EFFECT_WORDS.get(c.effect, (c.effect, ""))[0],
                             "term": EFFECT_WORDS.get(c.effect, ("", ""))[1], "delta_bic": c.delta_bic,
                             "rms_after": c.rms_after, "values": c.values, "std": c.std,
                             "units": {k: param_unit(self.rig, k) for k in c.values}, "setting": c.setting,
                             "significant": c.significant} for c in self.ranking]}


def _bic(e: NDArray[np.float64], k: int) -> float:
    n = e.size
    return n * math.log(float(np.mean(e ** 2))) + k * math.log(n)


def _candidates(X0: NDArray[np.float64], y: NDArray[np.float64], columns: dict[str, list[tuple[str, list[str],
                Callable[[], NDArray[np.float64]]]]]) -> tuple[list[RigCandidate], NDArray[np.float64]]:
    """Each effect's best setting (by BIC) added to the base regression X0 -> y."""
    _, e0, _ = lstsq(X0, y)
    bic0 = _bic(e0, X0.shape[1])
    out = []
    for effect, settings in columns.items():
        best: Optional[RigCandidate] = None
        for setting, names, make in settings:
            extra = make()
            X = np.column_stack([X0, extra])
            beta, e, cov = lstsq(X, y)
            k0 = X0.shape[1]
            c = RigCandidate(effect, bic0 - _bic(e, X.shape[1]), float(np.sqrt(np.mean(e ** 2))),
                             {n: float(beta[k0 + i]) for i, n in enumerate(names)},
                             {n: float(math.sqrt(max(cov[k0 + i, k0 + i], 0.0))) for i, n in enumerate(names)}, setting,
                             residual=e, cov=cov[k0:, k0:].copy())
            if best is None or c.delta_bic > best.delta_bic:
                best = c
        assert best is not None
        out.append(best)
    out.sort(key=lambda c: -c.delta_bic)
    return out, e0


def _refine_cogging(c: RigCandidate, X0: NDArray[np.float64], y: NDArray[np.float64], q: NDArray[np.float64],
                    e0: NDArray[np.float64]) -> RigCandidate:
    """The cogging candidate with its wavelength refined between the scanned neighbours of the
    best one (a ripple off by 2 % in wavelength dephases over a long stroke)."""
    from scipy.optimize import minimize_scalar

    lam0 = float(c.setting.split("=")[1].split()[0]) * 1e-3
    grid = np.array(COGGING_WAVELENGTHS)
    i = int(np.argmin(np.abs(grid - lam0)))
    lo, hi = grid[max(i - 1, 0)], grid[min(i + 1, grid.size - 1)]

    def fit(lam: float) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
        X = np.column_stack([X0, np.sin(2 * np.pi * q / lam), np.cos(2 * np.pi * q / lam)])
        return lstsq(X, y)

    best = minimize_scalar(lambda lam: float(np.mean(fit(lam)[1] ** 2)), bounds=(lo, hi), method="bounded",
                           options={"xatol": 1e-4 * lam0})
    lam = float(best.x)
    beta, e, cov = fit(lam)
    k0 = X0.shape[1]
    # the wavelength is one more fitted parameter in the BIC
    dbic = _bic(e0, k0) - _bic(e, k0 + 3)
    return RigCandidate("cogging", dbic, float(np.sqrt(np.mean(e ** 2))),
                        {"a": float(beta[k0]), "b": float(beta[k0 + 1])},
                        {"a": float(math.sqrt(cov[k0, k0])), "b": float(math.sqrt(cov[k0 + 1, k0 + 1]))},
                        f"wavelength = {lam * 1e3:.4g} mm (refined)", residual=e, cov=cov[k0:, k0:].copy())


def _verdict(ranking: list[RigCandidate], rms0: float, noise: float) -> tuple[str, str, float]:
    eligible = [c for c in ranking if c.delta_bic >= BIC_THRESHOLD and c.significant]
    if not eligible:
        if not noise > 0:
            return "unexplained", ("the record's noise could not be estimated, so whether the residual is noise "
                                   "cannot be judged; no catalogue effect lowers BIC by "
                                   f"{BIC_THRESHOLD:g} with its amplitudes beyond {NULL_SIGMAS:g} σ"), rms0
        if rms0 <= 1.5 * noise:
            return "none", "the identified model leaves noise; no catalogue effect is supported", rms0
        ratio = rms0 / noise if noise > 0 else math.inf
        return "unexplained", (f"a residual of {ratio:.1f} x the noise estimate remains and no catalogue effect "
                               f"lowers BIC by {BIC_THRESHOLD:g} with its amplitudes beyond {NULL_SIGMAS:g} σ"), rms0
    best = eligible[0]
    return best.effect, (f"{best.effect} lowers BIC by {best.delta_bic:.0f} "
                         f"(amplitudes beyond {NULL_SIGMAS:g} σ) and the residual RMS from {rms0:.4g} "
                         f"to {best.rms_after:.4g}"), best.rms_after


def _locate_by(e: NDArray[np.float64], labels: dict[str, NDArray[np.bool_]]) -> list[str]:
    total = float(np.sum(e ** 2))
    out = []
    for name, mask in labels.items():
        if mask.any():
            share = float(np.sum(e[mask] ** 2)) / total
            out.append(f"{name}: {100 * mask.mean():.0f} % of the samples hold {100 * share:.0f} % of the residual "
                       f"(RMS {np.sqrt(np.mean(e[mask] ** 2)):.3g})")
    return out


def _linear_rig(rig: str, name: str, X0: NDArray[np.float64], y: NDArray[np.float64], q: NDArray[np.float64],
                v: NDArray[np.float64], noise: float, t: NDArray[np.float64], force_sign: float = 1.0) -> RigDiagnosis:
    """``force_sign``: +1 when ``y`` is the force that overcomes friction (EMPS), -1 when it is
    the spring deflection that balances it with the opposite sign convention."""
    sg = np.sign(v)
    stroke = float(np.ptp(q))
    qc = (q - 0.5 * (q.max() + q.min())) / (0.5 * stroke)  # -1 .. 1 over the stroke: amplitudes in y's unit
    # each column builder is called without arguments (Callable[..., ...]: the loop values are bound as defaults)
    columns: dict[str, list[tuple[str, list[str], Callable[..., NDArray[np.float64]]]]] = {
        "stribeck_peak": [(f"vs = {vs:g} m/s", ["s"], (lambda vs=vs: force_sign * np.exp(-((v / vs) ** 2)) * sg))
                          for vs in STRIBECK_VS],
        "position_dependent": [("", ["p1", "p2"], lambda: np.column_stack([qc * sg, qc ** 2 * sg]))],
        "cogging": [(f"wavelength = {lam * 1e3:.3g} mm", ["a", "b"],
                     (lambda lam=lam: np.column_stack([np.sin(2 * np.pi * q / lam), np.cos(2 * np.pi * q / lam)])))
                    for lam in COGGING_WAVELENGTHS if lam <= stroke / 2],
        "position_force": [("", ["n2", "n3"], lambda: np.column_stack([qc ** 2, qc ** 3]))],
    }
    columns = {k: v_ for k, v_ in columns.items() if v_}
    ranking, e0 = _candidates(X0, y, columns)
    ranking = [_refine_cogging(c, X0, y, q, e0) if c.effect == "cogging" else c for c in ranking]
    for c in ranking:
        if c.effect == "stribeck_peak":
            c.positive = ("s",)
    ranking.sort(key=lambda c: (not c.significant, -c.delta_bic))
    rms0 = float(np.sqrt(np.mean(e0 ** 2)))
    verdict, reason, rms_after = _verdict(ranking, rms0, noise)
    half = 0.5 * (q.min() + q.max())
    locations = _locate_by(e0, {"moving forward": v > 0, "moving backward": v < 0,
                                "first half of the stroke": q < half, "second half of the stroke": q >= half,
                                "low speed (|v| < 10 % of its max)": np.abs(v) < 0.1 * np.abs(v).max()})
    named = next((c for c in ranking if c.effect == verdict), None)
    return RigDiagnosis(rig, name, verdict, reason, rms0, rms_after, noise, ranking, locations,
                        {"t": t, "residual": e0, "residual_after": named.residual if named is not None else e0,
                         "q": q, "v": v})


def diagnose_emps(data: RigData) -> RigDiagnosis:
    reg = emps_regression(data)
    return _linear_rig("emps", data.name, reg.X, reg.y, reg.q, reg.v, reg.noise, reg.t)


def diagnose_frame(data: RigData) -> RigDiagnosis:
    # y - x is the spring's deflection: it balances friction with the same sign as x'
    reg = frame_regression(data)
    return _linear_rig("frame", data.name, reg.X, reg.y, reg.q, reg.v, reg.noise, reg.t)


def diagnose_spring_slider(data: RigData) -> RigDiagnosis:
    """The slips' onset forces against the time stuck before them: constant (Coulomb static
    friction) or growing with ln(t_stick) (rate/state aging); plus a drift over the record."""
    ev = slider_events(data)
    force, noise, peaks, troughs = ev.force, ev.noise, ev.peaks, ev.troughs
    # the stick before each slip: from the previous trough to the peak
    pairs = [(int(troughs[troughs < pk].max()), int(pk)) for pk in peaks if (troughs < pk).any()]
    if len(pairs) < 5:
        return RigDiagnosis("spring_slider", data.name, "not_converged", "fewer than 5 stick-slip cycles to compare",
                            math.nan, math.nan, noise, [])
    tr_i = np.array([p[0] for p in pairs])
    pk_i = np.array([p[1] for p in pairs])
    fs = force[pk_i]
    t_stick = data.t[pk_i] - data.t[tr_i]
    X0 = np.ones((fs.size, 1))
    columns = {
        "stick_time_aging": [("", ["beta_N"], lambda: np.log(t_stick))],
        "drift_over_record": [("", ["drift_N_per_s"], lambda: data.t[pk_i])],
    }
    ranking, e0 = _candidates(X0, fs, columns)
    rms0 = float(np.sqrt(np.mean(e0 ** 2)))
    # the noise of one peak reading: the force record's noise
    verdict, reason, rms_after = _verdict(ranking, rms0, noise)
    locations = [f"{fs.size} slips; onset force {fs.mean():.4f} ± {fs.std():.4f} N, stick times "
                 f"{t_stick.min():.3g}-{t_stick.max():.3g} s"]
    named = next((c for c in ranking if c.effect == verdict), None)
    return RigDiagnosis("spring_slider", data.name, verdict, reason, rms0, rms_after, noise, ranking, locations,
                        {"t_stick": t_stick, "t_onset": data.t[pk_i], "fs": fs, "residual": e0,
                         "residual_after": named.residual if named is not None else e0})


def diagnose_rig(data: RigData) -> RigDiagnosis:
    """Diagnose a measured friction rig's recording: fit the friction model the rig's structure
    calls for, rank the candidate effects of that rig against it and say which one (if any) the
    data support.

    Parameters
    ----------
    data : RigData
        A recording loaded by :func:`idm_rs.rigs.load` (its ``rig`` says which: ``"emps"``, a
        linear axis driven in force; ``"frame"``, a block pulled in a frame; ``"spring_slider"``,
        a slider pulled through a spring, stick-slip).

    Returns
    -------
    RigDiagnosis
        The verdict (a candidate effect, or none), the reason in words, the residual RMS before
        and after [the rig's unit], the noise, the ranked candidates and where the misfit lives;
        ``.report()`` prints it, :func:`idm_rs.rigs.plot_rig_diagnosis` draws it.

    Examples
    --------
    >>> from idm_rs.rigs import load, diagnose_rig            # doctest: +SKIP
    >>> rd = diagnose_rig(load("k1002Nm_v42.mat"))            # doctest: +SKIP
    >>> print(rd.report())                                    # doctest: +SKIP
    """
    return {"emps": diagnose_emps, "frame": diagnose_frame, "spring_slider": diagnose_spring_slider}[data.rig](data)
