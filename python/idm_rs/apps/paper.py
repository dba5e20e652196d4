"""The paper case (Figs. 6 and 7 of the IDM paper) as data and functions.

The paper drives the IDM with a single triangular wave, 0 → 80 V in 0.5 ms and back to 0 V at
10 ms, and reports the main body's position x1 at 10 ms for the lumped (LPS) and distributed
(DPS, FEM) models. ``docs/MODEL.md`` fixes the conventions the paper leaves open (fall time, normal
force) and gives reference values for them; :func:`comparison_table` sets ours beside both.

Fig. 7 sweeps one parameter at a time around the paper case; :func:`fig7_sweeps` describes the
four sweeps, :func:`run_sweep` runs one's time histories (``simulate``) and :func:`run_dense` its
final-position summary over a dense grid (one ``idm_rs.sweep`` through the parallel batch engine).
"""

from __future__ import annotations

import dataclasses
import math
import textwrap
from dataclasses import dataclass
from typing import Any, Callable, NamedTuple, Optional

import numpy as np

from ..core.declarations import Model
from ..core.methods import MethodName
from ..core.params import Params
from ..core.simulation import DivergenceError, simulate
from ..core.simulation_result import SimulationResult
from ..core.waveforms import Triangle, Waveform

# --- the paper's reported values (Section 3, Fig. 6a) -------------------------------------------
PAPER_LPS_UM = 2.413  #: paper: LPS x1(10 ms) [µm]
PAPER_DPS_UM = 2.459  #: paper: DPS x1(10 ms) [µm]

# --- docs/MODEL.md's reference values for idm-rs's conventions (RK4, dt = 1e-8 s) -------------------
REFERENCE_LPS_UM = 1.678  #: docs/MODEL.md: LPS x1(10 ms) [µm]
REFERENCE_DPS4_UM = 1.711  #: docs/MODEL.md: DPS (n = 4) x1(10 ms) [µm]

# --- the case itself ------------------------------------------------------------------------------
PAPER_AMPLITUDE = 80.0  #: peak voltage [V]
PAPER_RISE = 0.5e-3  #: rise time [s]
PAPER_FALL = 9.5e-3  #: fall time [s] (not stated by the paper; docs/MODEL.md's convention)
PAPER_T_END = 10e-3  #: simulated time [s]
PAPER_N_ELEMENTS = 4  #: FEM elements of the DPS
PAPER_DT = 1e-8  #: RK4 step [s] of the reference values
PAPER_WAVEFORM = Triangle(PAPER_AMPLITUDE, PAPER_RISE, PAPER_FALL)
#: the Fig. 6c/6d window [s]
TRANSIENT_WINDOW = (4e-3, 10e-3)

PAPER_NOTE = (
    "Note: the paper's text alone does not reproduce its absolute values under any reading tried "
    "(fall times 0.5-9.5 ms, three choices of the normal force; see docs/MODEL.md). "
    "The DPS-LPS gap has the paper's sign and size (ours {gap:+.0f} nm, paper {paper_gap:+.0f} nm). "
    "Almost all of the gap comes from the mass-proportional Rayleigh damping alpha_c*Mp "
    "(a drag of about alpha_c*mPE/2 on the centre of mass), not from the inertia of the PE."
)


def _signed(x: float, width: int, decimals: int) -> str:
    """``x`` with an explicit sign, and no "-0" for values that round to zero."""
    x = round(x, decimals) + 0.0
    return f"{x:>+{width}.{decimals}f}"


def paper_params() -> Params:
    """The paper's Table 1 (``Params()`` defaults; normal force (m1 + m2 + mPE) g)."""
    return Params()


class PaperCase(NamedTuple):
    """The LPS and DPS (n = 4) results of the paper case."""

    lps: SimulationResult
    dps: SimulationResult


def run_paper_case(dt: float = PAPER_DT, save_every: int = 100) -> PaperCase:
    """Run the paper case (10 ms, ``Triangle(80, 0.5e-3, 9.5e-3)``, Table 1, piezo hysteresis on)
    with the LPS and the DPS of four elements; returns ``PaperCase(lps, dps)``."""
    p = paper_params()
    common: dict[str, Any] = dict(t_end=PAPER_T_END, dt=dt, save_every=save_every, piezo_hysteresis=True)
    lps = simulate(p, PAPER_WAVEFORM, model="lps", **common)
    dps = simulate(p, PAPER_WAVEFORM, model="dps", n_elements=PAPER_N_ELEMENTS, **common)
    return PaperCase(lps, dps)


def comparison_table(lps: SimulationResult, dps: SimulationResult) -> str:
    """A text table of x1(10 ms): ours vs the paper vs docs/MODEL.md's reference, the DPS − LPS gap,
    and a plain note on what does and does not agree."""
    ours_l = lps.final_position * 1e6
    ours_d = dps.final_position * 1e6
    rows = [
        ("LPS", ours_l, PAPER_LPS_UM, REFERENCE_LPS_UM),
        (f"DPS (n = {dps.n_elements})", ours_d, PAPER_DPS_UM, REFERENCE_DPS4_UM),
    ]
    head = f"{'x1(10 ms) [um]':<16}{'ours':>10}{'paper':>10}{'reference':>10}{'ours-paper':>12}{'ours-ref':>10}"
    lines = [
        f"Paper case: triangle 0 -> {PAPER_AMPLITUDE:g} V in {PAPER_RISE * 1e3:g} ms, back to 0 V at "
        f"{(PAPER_RISE + PAPER_FALL) * 1e3:g} ms; RK4, dt = {dps.dt:g} s",
        head,
        "-" * len(head),
    ]
    for name, ours, paper, ref in rows:
        lines.append(
            f"{name:<16}{ours:>10.3f}{paper:>10.3f}{ref:>10.3f}"
            f"{_signed(ours - paper, 12, 3)}{_signed(ours - ref, 10, 3)}"
        )
    gap = (ours_d - ours_l) * 1e3
    paper_gap = (PAPER_DPS_UM - PAPER_LPS_UM) * 1e3
    ref_gap = (REFERENCE_DPS4_UM - REFERENCE_LPS_UM) * 1e3
    lines.append(
        f"{'DPS-LPS [nm]':<16}{_signed(gap, 10, 0)}{_signed(paper_gap, 10, 0)}{_signed(ref_gap, 10, 0)}"
        f"{_signed(gap - paper_gap, 12, 0)}{_signed(gap - ref_gap, 10, 0)}"
    )
    lines.append("")
    lines.append(textwrap.fill(PAPER_NOTE.format(gap=gap, paper_gap=paper_gap), width=len(head) + 24))
    return "\n".join(lines)


# --- Fig. 7: one-parameter sweeps around the paper case --------------------------------------------


@dataclass(frozen=True)
class Case:
    """One simulation of a sweep."""

    params: Params
    waveform: Waveform
    model: Model = "dps"
    n_elements: int = PAPER_N_ELEMENTS


@dataclass(frozen=True)
class Sweep:
    """One panel of Fig. 7: ``values`` of a swept quantity, and ``build(value)`` giving the case."""

    key: str  #: "7a" … "7d"
    title: str  #: what is swept (the title reads "Fig. 7a — Effect of the <title>")
    quantity: str  #: axis label of the swept quantity, with unit
    values: tuple[float, ...]
    reference: float  #: the paper case's value of the swept quantity
    build: Callable[[float], Case]
    fmt: str = "{:g}"  #: legend format of a value
    note: str = ""  #: the model, and what else changes along the sweep
    dense: tuple[float, ...] = ()  #: a finer grid for the final-position summary
    axis: str = ""  #: the ``idm_rs.sweep`` grid axis that ``build`` varies
    axis_scale: float = 1.0  #: the axis value of a swept value ``v`` is ``v * axis_scale``


class FinalPoint(NamedTuple):
    """x1(t_end) of one value of a sweep's dense grid."""

    value: float
    final_position: float  #: [m] (NaN if the point diverged at every step tried)
    dt: float  #: the step used [s] (rk4), or the smallest accepted step (dopri5)
    status: int = 1  #: the sweep's status: 1 ok, 2 ok at a smaller step, 3 diverged


@dataclass(frozen=True)
class SweepRun:
    """A sweep's simulation: the swept value, the result, and the step actually used."""

    value: float
    result: SimulationResult
    dt: float


def fig7_sweeps(quick: bool = False) -> list[Sweep]:
    """The four sweeps of Fig. 7 (a: PE-to-main-body mass ratio, with the n = 1 FEM special case
    of eq. 18; b: weight-to-main-body mass ratio; c: PE stiffness; d: voltage; b–d with the DPS of
    four elements). Each has a dense grid for the final-position summary; ``quick`` keeps two or
    three values per sweep and a coarser summary grid (``QUICK_DENSE`` values, plus the curves'
    values)."""
    p = paper_params()
    pe_volume = p.pe_area * p.pe_length

    def mass_pe(r: float) -> Case:
        return Case(p.replace(pe_density=r * p.m1 / pe_volume), PAPER_WAVEFORM, "dps", 1)

    def mass_weight(r: float) -> Case:
        return Case(p.replace(m2=r * p.m1), PAPER_WAVEFORM)

    def stiffness(f: float) -> Case:
        return Case(p.replace(pe_youngs=p.pe_youngs * f), PAPER_WAVEFORM)

    def voltage(v: float) -> Case:
        return Case(p, Triangle(v, PAPER_RISE, PAPER_FALL))

    sweeps = [
        Sweep(
            "7a", "PE-to-main-body mass ratio", "m_PE / m1 [-]",
            (0.01, 0.05, 0.1, 0.2), p.pe_mass / p.m1, mass_pe,
            note="DPS, n = 1 (eq. 18); ρp varied, normal force (m1 + m2 + mPE)·g follows",
            dense=_grid(0.01, 0.2, 20), axis="pe_mass_ratio",
        ),
        Sweep(
            "7b", "weight-to-main-body mass ratio", "m2 / m1 [-]",
            (0.25, 0.5, 0.75, 1.0, 1.5, 2.0), p.m2 / p.m1, mass_weight,
            note="DPS, n = 4; m2 varied, normal force (m1 + m2 + mPE)·g follows",
            dense=_grid(0.25, 2.0, 36), axis="mass_ratio",
        ),
        Sweep(
            "7c", "PE stiffness", "k_p / k_p0 [-]",
            (0.5, 0.75, 1.0, 1.5, 2.0), 1.0, stiffness,
            fmt="{:g} k_p0", note="DPS, n = 4; Ep varied, k_p0 = 2.77e7 N/m",
            dense=_grid(0.5, 2.0, 31), axis="pe_youngs", axis_scale=p.pe_youngs,
        ),
        Sweep(
            "7d", "applied voltage", "peak voltage [V]",
            (40.0, 60.0, 80.0, 100.0, 120.0), PAPER_AMPLITUDE, voltage, fmt="{:g} V",
            note="DPS, n = 4; triangle, rise 0.5 ms, fall 9.5 ms",
            dense=_grid(40.0, 120.0, 17), axis="voltage",
        ),
    ]
    if quick:
        keep = {
            "7a": (0.01, 0.2),
            "7b": (0.5, 0.75, 1.0),
            "7c": (0.5, 1.0, 2.0),
            "7d": (40.0, 80.0, 120.0),
        }
        sweeps = [
            dataclasses.replace(
                s, values=keep[s.key],
                dense=tuple(sorted({*_grid(s.dense[0], s.dense[-1], QUICK_DENSE), *keep[s.key]})),
            )
            for s in sweeps
        ]
    return sweeps


#: values of each summary grid in quick mode
QUICK_DENSE = 9


def _grid(lo: float, hi: float, n: int) -> tuple[float, ...]:
    return tuple(float(round(v, 10)) for v in np.linspace(lo, hi, n))


def save_every_for(dt: float, interval: float = 1e-6) -> int:
    """Steps between saved points for a save interval of about ``interval`` [s]."""
    return max(1, int(round(interval / dt)))


def run_case(
    case: Case, dt: float, t_end: float = PAPER_T_END, interval: float = 1e-6, max_halvings: int = 4
) -> tuple[SimulationResult, float]:
    """Simulate ``case``; on a :class:`DivergenceError` halve ``dt`` (at most ``max_halvings``
    times) and try again. Returns the result and the step used."""
    for attempt in range(max_halvings + 1):
        try:
            r = simulate(
                case.params, case.waveform, t_end=t_end, dt=dt, model=case.model,
                n_elements=case.n_elements, save_every=save_every_for(dt, interval),
            )
            return r, dt
        except DivergenceError:
            if attempt == max_halvings:
                raise
            dt /= 2
    raise AssertionError("unreachable")  # pragma: no cover


def run_sweep(
    sweep: Sweep, dt: float, on_done: Optional[Callable[[], None]] = None, interval: float = 1e-6
) -> list[SweepRun]:
    """Run every value of ``sweep`` (halving ``dt`` for a curve that diverges);
    ``on_done()`` is called after each run (a progress bar's update)."""
    runs = []
    for v in sweep.values:
        r, used = run_case(sweep.build(v), dt, interval=interval)
        runs.append(SweepRun(v, r, used))
        if on_done is not None:
            on_done()
    return runs


def run_dense(
    sweep: Sweep,
    dt: float,
    on_done: Optional[Callable[[], None]] = None,
    *,
    method: MethodName = "rk4",
    rtol: Optional[float] = None,
    atol: Optional[float] = None,
    max_halvings: int = 4,
    threads: Optional[int] = None,
) -> list[FinalPoint]:
    """x1(10 ms) over ``sweep.dense``, as one :func:`idm_rs.sweep` along ``sweep.axis`` (the batch
    engine on all cores; no trajectory is kept). With ``method="rk4"`` each point is bit for bit
    ``simulate()`` of ``sweep.build(value)`` at step ``dt``; a point that diverges is retried at
    dt/2, ... (``max_halvings`` times) and, if it still diverges, returned with a NaN position and
    status 3. ``method="dopri5"`` is the adaptive Dormand-Prince 5(4) with ``rtol``/``atol`` (default 1e-7; "auto" as in
    :func:`idm_rs.sweep`).
    ``on_done()`` is called once per point when the sweep is done."""
    from ..sweeps.sweep import sweep as batch_sweep

    if not sweep.dense:
        return []
    if not sweep.axis:
        raise ValueError(f"sweep {sweep.key} has no batch axis")
    base = sweep.build(sweep.reference)  # the swept field is overridden point by point
    values = np.asarray(sweep.dense, dtype=float)
    ds = batch_sweep(
        base.params, base.waveform, {sweep.axis: values * sweep.axis_scale}, t_end=PAPER_T_END, dt=dt,
        model=base.model, n_elements=base.n_elements, metrics=("final_position",), method=method,
        rtol=rtol, atol=atol, retries=max_halvings, progress=False, threads=threads,
    )
    points = [
        FinalPoint(float(v), float(x), float(used), int(st))
        for v, x, used, st in zip(values, ds["final_position"].values, ds["dt_used"].values, ds["status"].values)
    ]
    if on_done is not None:
        for _ in points:
            on_done()
    return points


def step_convergence(
    case: Optional[Case] = None, coarse: float = 2e-8, fine: float = 1e-8
) -> float:
    """|x1(10 ms; coarse) − x1(10 ms; fine)| [m] for one case (default: the DPS paper case)."""
    case = case or Case(paper_params(), PAPER_WAVEFORM)
    a = simulate(case.params, case.waveform, PAPER_T_END, dt=coarse, model=case.model,
                 n_elements=case.n_elements, save_every=save_every_for(coarse, 1e-4))
    b = simulate(case.params, case.waveform, PAPER_T_END, dt=fine, model=case.model,
                 n_elements=case.n_elements, save_every=save_every_for(fine, 1e-4))
    return abs(a.final_position - b.final_position)


def fig7_check_case() -> Case:
    """The case on which Fig. 7's step is checked: the lightest weight (m2/m1 = 0.25), whose small
    normal force makes the friction state stiffest, so the step limit tightest."""
    p = paper_params()
    return Case(p.replace(m2=0.25 * p.m1), PAPER_WAVEFORM)


FIG7_CHECK_CASE_NAME = "the m2/m1 = 0.25 case"


def choose_fig7_dt(
    preferred: float = 2e-8, fallback: float = 1e-8, tol: float = 1e-11, case: Optional[Case] = None
) -> tuple[float, float]:
    """The step for Fig. 7: ``preferred`` if x1(10 ms) agrees with ``fallback``'s to ``tol`` [m] on
    ``case`` (default :func:`fig7_check_case`), else ``fallback``. Returns (dt, the difference)."""
    case = case or fig7_check_case()
    if math.isclose(preferred, fallback):
        return fallback, 0.0
    diff = step_convergence(case, coarse=preferred, fine=fallback)
    return (preferred if diff < tol else fallback), diff
