"""The next experiment: the drive a lab can run that best tells two look-alike models apart.

When the verdict has a near-parallel alternative (two effects that explain the recordings
about equally well), each sawtooth drive of a grid within the rig's limits (the recorded
amplitudes at most, frequencies within a factor 2 of the recorded ones, both directions, the
recorded edge and rest) is scored by the **expected ΔBIC** it would add between the two models
at their fitted values: the difference of their predicted readings (each segment's offset
removed, as the diagnosis compares them), less what the other model's fitted parameters could
absorb by refitting (its exact Jacobian on that experiment, to first order), in noise units
— taken both ways (either may be the truth) and the smaller kept. The raw difference of every
drive comes first (predictions only); the absorption is computed for the PROPOSAL_SHORTLIST drives that
differ most (it only lowers a drive's figure). The drive with the largest
score is proposed, with that figure and the same figure for the recordings already made.
Where either model has a force fixed to the bench (an incline), each drive is also scored
with the rig turned end for end (``orientation: "reversed"``): the only experiment that
separates an incline from a direction-dependent friction.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import Any, Callable, Optional, Sequence

import numpy as np
from numpy.typing import NDArray

from ..core.effects import BENCH_FIXED
from ..io.recording import Experiment, Recording
from .case_model import CaseSimulator, ModelSpec
from .fitting import FreeParam, Objective
from .thresholds import (
    FIT_DT,
    PROPOSAL_AMPLITUDE_SHARES,
    PROPOSAL_CYCLES,
    PROPOSAL_FREQUENCIES,
    PROPOSAL_FREQUENCY_SPAN,
    PROPOSAL_SHORTLIST,
    SEPARATES,
    TRAVEL_CYCLES,
    TRAVEL_SHARES,
)

#: look-alikes no voltage drive can tell apart, and what can (physics, not a search result)
NOT_BY_DRIVE: dict[tuple[str, str], str] = {
    ("incline", "friction_asymmetry"): (
        "they differ only while the main body is stuck (an incline loads the stuck contact, by "
        "|m g sin(theta)| / fric_alpha, ~1e-13 m here); record with the rig turned end for end on the bench "
        "(orientation \"reversed\"): the incline then acts the other way, a direction-dependent friction of the "
        "contact does not (tilting by a known angle does not separate them: both models absorb the known tilt)"),
    # discovery's look-alike terms (a form's symbols)
    ("x1 - x2", "V"): (
        "the PE's extension x2 - x1 is d33 V less its compression by the force it carries (F / k_pe: ~0.1 um "
        "under a 3 N friction force against ~10 um of stroke), so a force c V and a spring (c / d33) (x1 - x2) "
        "between the bodies differ by ~1 % of themselves, below the noise on every sawtooth of the rig's limits; "
        "a reading of the PE's own extension (a strain gauge or a second position sensor on the weight) "
        "beside the body's tells them apart"),
}


#: library symbols that read the same variable as another up to its sign (the weight's terms)
_SAME_UP_TO_SIGN: dict[str, str] = {"x2 - x1": "x1 - x2", "v2 - v1": "v1 - v2"}


def not_by_drive(names: tuple[str, str]) -> str:
    """Why no drive separates the look-alikes `names` (either order, either body's sign of the
    PE's extension) and what does; "" when a drive can."""
    a, b = (_SAME_UP_TO_SIGN.get(n, n) for n in names)
    return NOT_BY_DRIVE.get((a, b)) or NOT_BY_DRIVE.get((b, a), "")


@dataclass(frozen=True)
class Drive:
    """A sawtooth experiment a lab can run."""

    direction: str
    amplitude_V: float
    frequency_Hz: float
    cycles: int
    edge_s: float
    rest_s: float
    #: "normal", or "reversed": the rig turned end for end on the bench (an experiment's
    #: ``orientation`` in meta.json)
    orientation: str = "normal"

    def words(self) -> str:
        turned = " with the rig turned end for end on the bench (orientation \"reversed\")" \
            if self.orientation == "reversed" else ""
        return (f"{self.direction} sawtooth, {self.amplitude_V:.0f} V, {self.frequency_Hz:.0f} Hz, {self.cycles} "
                f"cycles, {self.edge_s * 1e3:.2g} ms edge, {self.rest_s * 1e3:.2g} ms rest{turned}")

    def to_dict(self) -> dict[str, Any]:
        return {"waveform": "sawtooth", "direction": self.direction, "amplitude_V": self.amplitude_V,
                "frequency_Hz": self.frequency_Hz, "cycles": self.cycles, "edge_s": self.edge_s,
                "rest_s": self.rest_s, "orientation": self.orientation}


@dataclass
class Proposal:
    """The proposed drive and its predicted effect."""

    purpose: str  #: e.g. "tell incline from friction_asymmetry"
    models: tuple[str, str]
    drive: Drive
    predicted_delta_bic: float  #: expected ΔBIC between the two models from this drive alone
    recorded_delta_bic: float  #: the same figure for the recordings already made
    scored: list[tuple[Drive, float]] = field(default_factory=list, repr=False)  #: every drive tried
    #: what separates the pair where no drive does (physics), or ""
    hint: str = ""

    @property
    def separates(self) -> bool:
        """Whether the best drive is predicted to separate the pair (ΔBIC >= SEPARATES)."""
        return self.predicted_delta_bic >= SEPARATES

    def words(self) -> str:
        if not self.separates:
            return (f"no drive within the rig's limits tells {self.models[0]} from {self.models[1]}: the best of "
                    f"{len(self.scored)} tried ({self.drive.words()}) is predicted to separate them by ΔBIC "
                    f"≈ {self.predicted_delta_bic:.1f} (10 would be very strong evidence; the recordings so far: "
                    f"{self.recorded_delta_bic:.1f})" + (f"; {self.hint}" if self.hint else ""))
        return (f"to {self.purpose}, record a {self.drive.words()}: it is predicted to separate them by ΔBIC "
                f"≈ {self.predicted_delta_bic:.0f} on its own (the recordings so far: {self.recorded_delta_bic:.0f}; "
                f"10 is very strong evidence)")

    def to_dict(self) -> dict[str, Any]:
        return {"purpose": self.purpose, "models": list(self.models), "drive": self.drive.to_dict(),
                "separates": self.separates, "hint": self.hint,
                "predicted_delta_bic": self.predicted_delta_bic, "recorded_delta_bic": self.recorded_delta_bic,
                "scored": [dict(d.to_dict(), delta_bic=s) for d, s in self.scored]}


def drives(rec: Recording, cycles: int = PROPOSAL_CYCLES, orientations: Sequence[str] = ("normal",),
           shares: Sequence[float] = PROPOSAL_AMPLITUDE_SHARES) -> list[Drive]:
    """The sawtooth drives within the rig's limits (module docstring), in each of
    `orientations` (the rig as it stands, and turned end for end where a model has a force
    fixed to the bench)."""
    saw = [e for e in rec.experiments if not e.is_sampled]
    if not saw:
        return []
    a_max = max(e.amplitude_V for e in saw)
    f_lo = min(e.frequency_Hz for e in saw) / PROPOSAL_FREQUENCY_SPAN
    f_hi = max(e.frequency_Hz for e in saw) * PROPOSAL_FREQUENCY_SPAN
    freqs = sorted({f for f in PROPOSAL_FREQUENCIES if f_lo <= f <= f_hi} | {e.frequency_Hz for e in saw})
    edge = min(e.edge_s for e in saw)
    rest = max(e.rest_s for e in saw)
    out = []
    for orientation in orientations:
        for direction in ("forward", "backward"):
            for share in shares:
                for f in freqs:
                    if edge >= 0.5 / f:
                        continue  # the edge must fit in the period
                    out.append(Drive(direction, round(share * a_max, 1), f, cycles, edge, rest, orientation))
    return out


def orientations_for(*specs: ModelSpec) -> tuple[str, ...]:
    """The rig's orientations worth trying: turned end for end too when any of `specs` has a
    bench-fixed force (BENCH_FIXED: it then acts the other way, and nothing else changes)."""
    bench = any(abs(float(s.effects.get(n, 0.0))) > 0.0 for s in specs for n in BENCH_FIXED)
    return ("normal", "reversed") if bench else ("normal",)


def virtual_recording(rec: Recording, drive_list: Sequence[Drive]) -> Recording:
    """`rec`'s device and sensor with the experiments `drive_list` (readings all zero: only
    their times and drives are used)."""
    step = rec.sample_step
    exps = []
    for i, d in enumerate(drive_list):
        duration = d.rest_s + d.cycles / d.frequency_Hz
        n = int(round(duration / step)) + 1
        t = np.arange(n, dtype=np.float64) * step
        name = f"proposed{i + 1}_{d.direction}_{d.amplitude_V:g}V_{d.frequency_Hz:g}Hz.csv"
        exps.append(Experiment(name, rec.path / name, d.amplitude_V, d.frequency_Hz, d.direction, d.cycles, d.rest_s,
                               d.edge_s, t, np.zeros(n), np.zeros(n), orientation=d.orientation))
    return replace(rec, experiments=exps)


def _blocks(obj: Objective) -> list[slice]:
    """Each experiment's rows in the objective's residual vector."""
    out, a = [], 0
    for j in obj.experiments:
        out.append(slice(a, a + obj.samples[j]))
        a += obj.samples[j]
    return out


def _jacobian(obj: Objective, spec: ModelSpec, free: Sequence[FreeParam]) -> NDArray[np.float64]:
    if not free:
        return np.zeros((obj.n, 0))
    _, J, _ = obj.jacobian(spec, free, np.zeros(len(free)))
    return np.where(np.isfinite(J), J, 0.0)


def _fisher_by_experiment(rec: Recording, sigma: float, spec: ModelSpec, free: Sequence[FreeParam], dt: float
                          ) -> tuple[list[NDArray[np.float64]], list[int], NDArray[np.float64]]:
    """Each experiment's Fisher information J'J in the fit units (noise units, exact Jacobian at
    `spec`), its number of samples, and all experiments' together."""
    obj = Objective(rec, CaseSimulator(rec, dt=dt), sigma)
    J = _jacobian(obj, spec, free)
    blocks = _blocks(obj)
    return [J[sl].T @ J[sl] for sl in blocks], [sl.stop - sl.start for sl in blocks], J.T @ J


def _per_unit(f: FreeParam) -> float:
    """A parameter's value per fit unit at the fit's centre (log-scaled ones included)."""
    h = 1e-6
    return abs(f.value(h) - f.value(-h)) / (2 * h)


def _unabsorbed(diff: NDArray[np.float64], J: NDArray[np.float64]) -> float:
    """||diff - J u*||^2 with u* the least-squares step (noise units)."""
    if J.shape[1] == 0:
        return float(diff @ diff)
    u = np.linalg.lstsq(J, diff, rcond=None)[0]
    r = diff - J @ u
    return float(r @ r)


def separations(rec: Recording, sigma: float, a: tuple[ModelSpec, Sequence[FreeParam]],
                b: tuple[ModelSpec, Sequence[FreeParam]], dt: float = FIT_DT, each: bool = True) -> list[float]:
    """Expected ΔBIC (chi^2 units) between models a and b on `rec`'s experiments: the
    offset-profiled difference of their predictions less what each one's parameters absorb,
    the smaller of the two ways; per experiment (`each`) or for all together (one value). The
    predictions and Jacobians of every experiment are one batch call each."""
    sim = CaseSimulator(rec, dt=dt)
    obj = Objective(rec, sim, sigma)
    pa, pb = obj.predict([a[0], b[0]])
    ra = np.concatenate(obj.profiled(pa)[0]) / sigma
    rb = np.concatenate(obj.profiled(pb)[0]) / sigma
    diff = ra - rb
    # residual of "data = a" under b refitted, and of "data = b" under a refitted: the
    # residual vector's Jacobian is minus the prediction's, so the sign of diff is immaterial
    Ja, Jb = _jacobian(obj, a[0], a[1]), _jacobian(obj, b[0], b[1])
    blocks = _blocks(obj) if each else [slice(0, obj.n)]
    out = []
    for sl in blocks:
        d = diff[sl]
        if not np.all(np.isfinite(d)):
            out.append(math.nan)
            continue
        out.append(min(_unabsorbed(d, Jb[sl]), _unabsorbed(-d, Ja[sl])))
    return out


def raw_differences(rec: Recording, sigma: float, a: tuple[ModelSpec, Sequence[FreeParam]],
                    b: tuple[ModelSpec, Sequence[FreeParam]], dt: float = FIT_DT) -> list[float]:
    """Per experiment, ||offset-profiled prediction of a - of b||^2 in noise units: the
    separation before either model's parameters absorb anything (an upper bound of it)."""
    sim = CaseSimulator(rec, dt=dt)
    obj = Objective(rec, sim, sigma)
    pa, pb = obj.predict([a[0], b[0]])
    diff = (np.concatenate(obj.profiled(pa)[0]) - np.concatenate(obj.profiled(pb)[0])) / sigma
    return [float(diff[sl] @ diff[sl]) if np.all(np.isfinite(diff[sl])) else math.nan for sl in _blocks(obj)]


def separation(rec: Recording, sigma: float, a: tuple[ModelSpec, Sequence[FreeParam]],
               b: tuple[ModelSpec, Sequence[FreeParam]], dt: float = FIT_DT) -> float:
    """:func:`separations` of all `rec`'s experiments together."""
    return separations(rec, sigma, a, b, dt, each=False)[0]


def propose(rec: Recording, sigma: float, names: tuple[str, str], a: tuple[ModelSpec, Sequence[FreeParam]],
            b: tuple[ModelSpec, Sequence[FreeParam]], dt: float = FIT_DT) -> Optional[Proposal]:
    """The drive (of :func:`drives`) that best separates models `a` and `b` (their names in
    `names`), or None when the recording has no sawtooth drive to take the rig's limits from."""
    grid = drives(rec, orientations=orientations_for(a[0], b[0]))
    if not grid:
        return None
    # the raw difference of every drive first (predictions only: one batch call); what the
    # parameters absorb only lowers it, so the Jacobians are taken for the PROPOSAL_SHORTLIST drives
    # that differ most (the rest keep their raw difference, an upper bound, in `scored`)
    raw = raw_differences(virtual_recording(rec, grid), sigma, a, b, dt)
    order = sorted(range(len(grid)), key=lambda i: -(raw[i] if math.isfinite(raw[i]) else -math.inf))
    short = order[:PROPOSAL_SHORTLIST]
    scores = dict(zip(short, separations(virtual_recording(rec, [grid[i] for i in short]), sigma, a, b, dt)))
    scored = sorted(((grid[i], scores[i] if i in scores else raw[i]) for i in range(len(grid))),
                    key=lambda x: -(x[1] if math.isfinite(x[1]) else -math.inf))
    scored = [(d, x if math.isfinite(x) else -math.inf) for d, x in scored]
    recorded = separation(rec, sigma, a, b, dt)
    best, score = scored[0]
    return Proposal(f"tell {names[0]} from {names[1]}", names, best, score, recorded, scored, not_by_drive(names))


@dataclass
class ParameterProposal:
    """The drive that would best determine a parameter the recordings leave undetermined."""

    parameter: str
    drive: Drive
    std_now: float  #: its 1-sigma from the recordings [its unit]
    std_with: float  #: predicted 1-sigma with the drive added
    value: float
    scored: list[tuple[Drive, float]] = field(default_factory=list, repr=False)  #: (drive, std with it)
    #: why the proposal is made, said before it ("" for an effect's parameter)
    context: str = ""
    #: for a proposal for the held-out check (propose_for_heldout): the held-out experiment's
    #: RMS predicted from the others' fit [x noise], now and with the drive added; else NaN
    heldout_now: float = math.nan
    heldout_with: float = math.nan

    def words(self) -> str:
        lead = f"{self.context}; " if self.context else ""
        held = (f": the held-out check's refit is then predicted to reproduce its experiment to "
                f"{self.heldout_with:.2f} x noise (now {self.heldout_now:.2f} x), and "
                if math.isfinite(self.heldout_with) else ": ")
        return (f"{lead}to determine {self.parameter}, record a {self.drive.words()}{held}its 1-sigma is predicted to "
                f"fall from {self.std_now:.3g} ({100 * self.std_now / abs(self.value):.0f} % of its value) to "
                f"{self.std_with:.3g} ({100 * self.std_with / abs(self.value):.0f} %)")

    def to_dict(self) -> dict[str, Any]:
        return {"parameter": self.parameter, "drive": self.drive.to_dict(), "std_now": self.std_now,
                "std_with": self.std_with, "value": self.value, "context": self.context,
                "heldout_now": self.heldout_now, "heldout_with": self.heldout_with}


def propose_for_parameter(rec: Recording, sigma: float, name: str, model: tuple[ModelSpec, Sequence[FreeParam]],
                          dt: float = FIT_DT) -> Optional[ParameterProposal]:
    """The drive (of :func:`drives`) whose readings, added to the recordings', most reduce the
    variance of the fitted parameter `name` (Fisher information of the recordings plus the
    drive's, from exact Jacobians at the fitted model; the parameter's 1-sigma in its own units
    through the fit unit's scale at the optimum). None without sawtooth drives or when `name` is
    not among the model's free parameters."""
    spec, free = model
    idx = next((i for i, f in enumerate(free) if f.name == name), None)
    grid = drives(rec)
    if idx is None or not grid:
        return None
    _, _, F0 = _fisher_by_experiment(rec, sigma, spec, free, dt)
    grid_F, _, _ = _fisher_by_experiment(virtual_recording(rec, grid), sigma, spec, free, dt)
    f = free[idx]
    scale = _per_unit(f)
    value = f.value(0.0)

    def std(F: NDArray[np.float64]) -> float:
        try:
            var = float(np.linalg.pinv(F)[idx, idx])
        except np.linalg.LinAlgError:
            return math.inf
        return math.sqrt(max(var, 0.0)) * scale

    now = std(F0)
    scored = [(d, std(F0 + Fd)) for d, Fd in zip(grid, grid_F)]
    scored.sort(key=lambda x: x[1])
    best, with_ = scored[0]
    return ParameterProposal(name, best, now, with_, value, scored)


def propose_for_heldout(rec: Recording, sigma: float, name: str, model: tuple[ModelSpec, Sequence[FreeParam]],
                        heldout_index: Callable[[Recording], int], dt: float = FIT_DT,
                        cycles: Sequence[int] = TRAVEL_CYCLES, shares: Sequence[float] = TRAVEL_SHARES
                        ) -> Optional[ParameterProposal]:
    """The drive after which the held-out check would pass for a form that leaves noise.

    A found form that leaves noise on every recording but fails the held-out prediction has
    parameters that only the held-out experiment pins down (a friction periodic in position
    whose wavelength and phase only the experiment that travels furthest spans: refitted without
    it, they wander). With drive `d` added, the experiment held out is
    ``heldout_index(recordings + d)``, h. The refit on the others leaves the parameters with
    covariance F_train^-1 (Fisher information of the fitted experiments, exact Jacobians at
    the fitted `model`), which adds tr(F_h F_train^-1) to the held-out experiment's chi^2 to
    first order: its predicted RMS is sqrt(1 + that / n_h) x noise. `d` (of ``cycles`` cycles
    at ``shares`` of the largest recorded amplitude: a force along the stroke needs travel) is
    scored by that figure, lowest first; ``heldout_now`` is the figure for the recordings as
    they are, and ``std_now`` / ``std_with`` the 1-sigma of `name` from the fitted experiments.
    None without sawtooth drives or when `name` is not free."""
    spec, free = model
    idx = next((i for i, f in enumerate(free) if f.name == name), None)
    grid = [d for c in cycles for d in drives(rec, c, shares=shares)]
    if idx is None or not grid:
        return None
    F_exp, n_exp, F_all = _fisher_by_experiment(rec, sigma, spec, free, dt)
    virtual = virtual_recording(rec, grid)
    grid_F, grid_n, _ = _fisher_by_experiment(virtual, sigma, spec, free, dt)
    scale = _per_unit(free[idx])
    f = free[idx]

    def judged(F_train: NDArray[np.float64], F_h: NDArray[np.float64], n_h: int) -> tuple[float, float]:
        """(the held-out RMS predicted [x noise], name's 1-sigma from the fitted experiments)"""
        try:
            cov = np.linalg.pinv(F_train)
        except np.linalg.LinAlgError:
            return math.inf, math.inf
        extra = float(np.trace(F_h @ cov))
        return math.sqrt(1.0 + max(extra, 0.0) / n_h), math.sqrt(max(float(cov[idx, idx]), 0.0)) * scale

    held = heldout_index(rec)
    ho_now, now = judged(F_all - F_exp[held], F_exp[held], n_exp[held])
    scored, figures = [], {}
    for d, e, Fd, nd in zip(grid, virtual.experiments, grid_F, grid_n):
        h_d = heldout_index(replace(rec, experiments=[*rec.experiments, e]))
        if h_d == len(rec.experiments):
            figure = judged(F_all, Fd, nd)
        else:
            figure = judged(F_all + Fd - F_exp[h_d], F_exp[h_d], n_exp[h_d])
        scored.append((d, figure[0]))
        figures[d] = figure
    scored.sort(key=lambda x: x[1])
    best = scored[0][0]
    return ParameterProposal(name, best, now, figures[best][1], f.value(0.0), scored,
                             heldout_now=ho_now, heldout_with=figures[best][0])
