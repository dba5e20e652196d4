"""Figures 6 and 7 of the IDM paper, redrawn from idm-rs simulations (matplotlib, Agg backend).

Each ``fig*`` function draws one figure and writes it as a PNG; :func:`write_figures` runs the
Fig. 7 sweeps and writes all eight (``fig6a.png`` … ``fig7d.png``). Nothing is displayed.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Optional, Sequence, Union

import matplotlib

matplotlib.use("Agg")  # files only, never a display

import matplotlib.pyplot as plt
import numpy as np
from matplotlib.collections import LineCollection
from matplotlib.figure import Figure
from matplotlib.ticker import FormatStrFormatter

from ..core.declarations import structure_label
from ..core.methods import MethodName
from ..core.simulation_result import SimulationResult
from .paper import (
    FIG7_CHECK_CASE_NAME,
    PAPER_DPS_UM,
    PAPER_LPS_UM,
    PAPER_T_END,
    TRANSIENT_WINDOW,
    FinalPoint,
    PaperCase,
    Sweep,
    SweepRun,
    choose_fig7_dt,
    fig7_sweeps,
    run_dense,
    run_sweep,
)

PathLike = Union[str, "os.PathLike[str]"]

DPI = 150
DPS_STYLE: dict[str, Any] = dict(color="C0", lw=1.4)
LPS_STYLE: dict[str, Any] = dict(color="C3", lw=1.2, ls="--")
VOLT_STYLE: dict[str, Any] = dict(color="0.45", lw=1.0)
FIG6_NAMES = ("fig6a", "fig6b", "fig6c", "fig6d")
FIG7_NAMES = ("fig7a", "fig7b", "fig7c", "fig7d")


def _label(r: SimulationResult) -> str:
    return structure_label(r.model, r.n_elements)


def _style(r: SimulationResult) -> dict[str, Any]:
    return LPS_STYLE if r.model == "lps" else DPS_STYLE


def _save(fig: Figure, path: PathLike) -> Path:
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=DPI)
    plt.close(fig)
    return path


def _window(r: SimulationResult, t0: float, t1: float) -> np.ndarray:
    return (r.t >= t0 - 1e-12) & (r.t <= t1 + 1e-12)


# --- Fig. 6 --------------------------------------------------------------------------------------


def fig6a(lps: SimulationResult, dps: SimulationResult, path: PathLike) -> Path:
    """Fig. 6a: the input voltage (right axis) and x1 of the DPS and the LPS (left axis) vs time."""
    fig, ax = plt.subplots(figsize=(8, 5), layout="constrained")
    lines = []
    for r, paper in ((dps, PAPER_DPS_UM), (lps, PAPER_LPS_UM)):
        (ln,) = ax.plot(
            r.t * 1e3, r.main_body * 1e6, **_style(r),
            label=f"x1, {_label(r)}: {r.final_position * 1e6:.3f} µm at 10 ms (paper {paper:.3f})",
        )
        lines.append(ln)
    ax.set_xlabel("time t [ms]")
    ax.set_ylabel("main body displacement x1 [µm]")
    ax.set_xlim(0, dps.t[-1] * 1e3)
    ax.set_ylim(bottom=0)
    ax.grid(alpha=0.3)
    axv = ax.twinx()
    (lv,) = axv.plot(dps.t * 1e3, dps.voltage, **VOLT_STYLE, label="input voltage V")
    axv.set_ylabel("input voltage V [V]", color=VOLT_STYLE["color"])
    axv.tick_params(axis="y", colors=VOLT_STYLE["color"])
    axv.set_ylim(0, max(1.0, float(np.max(dps.voltage))) * 1.15)
    ax.legend(handles=[*lines, lv], loc="upper right", fontsize=8.5)
    ax.set_title("Fig. 6a — Input voltage and main body displacement x1 (DPS and LPS)")
    return _save(fig, path)


def fig6b(
    lps: SimulationResult, dps: SimulationResult, path: PathLike, v_zoom: float = 0.5e-3
) -> Path:
    """Fig. 6b: friction force vs main-body velocity, zoomed to |v| ≤ ``v_zoom`` [m/s] (where the
    force lags the velocity: hysteresis), with the whole (Stribeck) curve as an inset."""
    fig, ax = plt.subplots(figsize=(8, 5.5), layout="constrained")
    for r in (dps, lps):
        ax.plot(r.main_body_velocity * 1e3, r.friction, **{**_style(r), "lw": 0.8}, label=_label(r))
    ax.set_xlim(-v_zoom * 1e3, v_zoom * 1e3)
    fmax = float(max(np.max(np.abs(dps.friction)), np.max(np.abs(lps.friction))))
    ax.set_ylim(-1.12 * fmax, 1.12 * fmax)
    ax.axvline(0, color="0.6", lw=0.6)
    ax.axhline(0, color="0.6", lw=0.6)
    ax.set_xlabel("main body velocity v = dx1/dt [mm/s]")
    ax.set_ylabel("friction force Ff [N]")
    ax.grid(alpha=0.3)
    ax.legend(loc="upper left", fontsize=9)
    ax.set_title("Fig. 6b — Friction force vs main body velocity near v = 0")

    ins = ax.inset_axes((0.64, 0.07, 0.34, 0.36))
    for r in (dps, lps):
        ins.plot(r.main_body_velocity * 1e3, r.friction, **{**_style(r), "lw": 0.7})
    ins.axvline(0, color="0.6", lw=0.5)
    ins.set_title("whole curve: Ff [N] vs v [mm/s]", fontsize=8)
    ins.tick_params(labelsize=7)
    ins.set_facecolor("white")
    ins.grid(alpha=0.3)
    return _save(fig, path)


def fig6c(
    lps: SimulationResult, dps: SimulationResult, path: PathLike,
    window: tuple[float, float] = TRANSIENT_WINDOW,
) -> Path:
    """Fig. 6c: transients of x1 in ``window`` [s] (4–10 ms), DPS and LPS on their own y scales
    (the 33 nm gap between them is much larger than the ringing)."""
    fig, axes = plt.subplots(2, 1, figsize=(8, 6), sharex=True, layout="constrained")
    for ax, r in zip(axes, (dps, lps)):
        m = _window(r, *window)
        ax.plot(r.t[m] * 1e3, r.main_body[m] * 1e6, **{**_style(r), "ls": "-"}, label=_label(r))
        ax.yaxis.set_major_formatter(FormatStrFormatter("%.4f"))
        ax.set_ylabel("x1 [µm]")
        ax.grid(alpha=0.3)
        span = (np.ptp(r.main_body[m]) * 1e9) if m.any() else 0.0
        ax.legend(loc="upper right", fontsize=9, title=f"peak-to-peak {span:.2f} nm", title_fontsize=8)
    axes[-1].set_xlabel("time t [ms]")
    axes[-1].set_xlim(window[0] * 1e3, window[1] * 1e3)
    axes[0].set_title("Fig. 6c — Transients of x1 from 4 to 10 ms (DPS above, LPS below)")
    return _save(fig, path)


def _time_colored(ax: Any, x: np.ndarray, y: np.ndarray, t: np.ndarray, cmap: str) -> LineCollection:
    pts = np.column_stack([x, y]).reshape(-1, 1, 2)
    # an (N, 2, 2) array of segments, as documented; matplotlib's stub wants a Sequence
    lc = LineCollection(np.concatenate([pts[:-1], pts[1:]], axis=1),  # type: ignore[arg-type]
                        cmap=cmap, lw=1.0, capstyle="round")
    lc.set_array(t[:-1])
    ax.add_collection(lc)
    ax.set_xlim(float(x.min()), float(x.max()))
    pad = 0.05 * float(np.ptp(y)) or 1.0
    ax.set_ylim(float(y.min()) - pad, float(y.max()) + pad)
    return lc


def fig6d(
    lps: SimulationResult, dps: SimulationResult, path: PathLike,
    window: tuple[float, float] = TRANSIENT_WINDOW,
) -> Path:
    """Fig. 6d: friction force vs x1 in ``window`` [s] (4–10 ms): presliding hysteresis loops,
    coloured by time; DPS left, LPS right. The saw-teeth at the loop tips are physics (the body
    rings at the structure's higher modes where the slow motion reverses), not sampling: at the
    0.5 µs drawn here the loops match the 0.1 µs trajectory to < 1e-4 of their range."""
    fig, axes = plt.subplots(1, 2, figsize=(10, 5), sharey=True, layout="constrained")
    lc = None
    for ax, r in zip(axes, (dps, lps)):
        m = np.flatnonzero(_window(r, *window))
        m = m[:: max(1, m.size // 12_000)]  # enough points for the loops, few enough to draw cleanly
        lc = _time_colored(ax, r.main_body[m] * 1e6, r.friction[m], r.t[m] * 1e3, "viridis")
        ax.xaxis.set_major_formatter(FormatStrFormatter("%.4f"))
        ax.tick_params(axis="x", labelrotation=30)
        ax.set_xlabel("main body displacement x1 [µm]")
        ax.set_title(_label(r), fontsize=10)
        ax.grid(alpha=0.3)
    axes[0].set_ylabel("friction force Ff [N]")
    if lc is not None:
        fig.colorbar(lc, ax=axes, label="time t [ms]", shrink=0.9)
    fig.suptitle("Fig. 6d — Friction force vs x1 from 4 to 10 ms: presliding hysteresis loops")
    return _save(fig, path)


# --- Fig. 7 --------------------------------------------------------------------------------------


def fig7(
    sweep: Sweep, runs: Sequence[SweepRun], path: PathLike, dense: Sequence[FinalPoint] = (),
    dense_label: Optional[str] = None,
) -> Path:
    """One Fig. 7 panel: x1/l vs time for each swept value (left), and x1(10 ms) vs the swept
    value (right: the curves' values as coloured markers, ``dense`` points, from one
    ``idm_rs.sweep``, as a thin line labelled ``dense_label``; diverged points are left out and
    marked with a grey x on the axis)."""
    fig, (ax, axs) = plt.subplots(
        1, 2, figsize=(12, 5), width_ratios=[2.2, 1], layout="constrained"
    )
    cmap = plt.get_cmap("viridis")
    n = len(runs)
    for i, run in enumerate(runs):
        r = run.result
        length = r.params.pe_length
        label = sweep.fmt.format(run.value)
        if np.isclose(run.value, sweep.reference):
            label += " (paper case)"
        if run.dt != runs[0].dt:
            label += f" [dt = {run.dt:g} s]"
        ax.plot(r.t * 1e3, r.main_body / length * 1e5, color=cmap(i / max(1, n - 1) * 0.9), lw=1.2, label=label)
    ax.set_xlabel("time t [ms]")
    ax.set_ylabel("x1 / l  [×10⁻⁵]")
    ax.set_xlim(0, PAPER_T_END * 1e3)
    ax.axhline(0, color="0.6", lw=0.6)
    ax.grid(alpha=0.3)
    ax.legend(title=sweep.quantity, fontsize=8.5, title_fontsize=8.5, loc="best")
    ax.set_title("response of the main body")

    if len(dense):
        dv = np.array([p.value for p in dense])
        dx = np.array([p.final_position * 1e6 for p in dense])
        axs.plot(dv, dx, ".-", color="0.35", lw=0.9, ms=3.5, label=dense_label or f"{len(dense)} values")
        status = np.array([p.status for p in dense])
        # a point is called diverged only when its run said so (status 3); one that never ran
        # (status 0) is not a finding about the device
        for flag, marker, what in ((3, "x", "diverged"), (0, "+", "not run")):
            bad = (status == flag) & ~np.isfinite(dx)
            if bad.any():
                axs.plot(dv[bad], np.zeros(int(bad.sum())), marker, color="0.5", ms=6,
                         label=f"{what} ({int(bad.sum())})")
    else:
        axs.plot([r.value for r in runs], [r.result.final_position * 1e6 for r in runs], "-", color="0.35", lw=0.9)
    for i, run in enumerate(runs):
        is_ref = bool(np.isclose(run.value, sweep.reference))
        axs.plot(
            run.value, run.result.final_position * 1e6, "s" if is_ref else "o", ms=9 if is_ref else 7,
            color=cmap(i / max(1, n - 1) * 0.9), mec="k" if is_ref else "none", zorder=3,
            label="paper case" if is_ref else None,
        )
    if len(dense) or any(np.isclose(run.value, sweep.reference) for run in runs):
        axs.legend(fontsize=8.5, loc="best")
    axs.axhline(0, color="0.6", lw=0.6)
    axs.set_xlabel(sweep.quantity)
    axs.set_ylabel("final position x1(10 ms) [µm]")
    axs.grid(alpha=0.3)
    axs.set_title("final position")
    sub = f"\n{sweep.note}" if sweep.note else ""
    fig.suptitle(f"Fig. {sweep.key} — Effect of the {sweep.title} on the response{sub}", fontsize=11)
    return _save(fig, path)


# --- everything ----------------------------------------------------------------------------------


@dataclass
class FiguresReport:
    """What :func:`write_figures` wrote and how."""

    paths: dict[str, Path] = field(default_factory=dict)  #: figure name → PNG
    fig7_dt: float = 0.0  #: the step used for Fig. 7 (before any halving) [s]
    fig7_dt_check: float = 0.0  #: |x1(2e-8) − x1(1e-8)| on the check case [m] (nan: unchecked)
    dense_method: MethodName = "rk4"  #: the method of the final-position summary sweeps
    sweeps: dict[str, list[SweepRun]] = field(default_factory=dict)
    dense: dict[str, list[FinalPoint]] = field(default_factory=dict)

    def summary(self) -> str:
        """A few lines: the Fig. 7 step and each sweep's final positions."""
        check = (
            f" (|x1(2e-8 s) - x1(1e-8 s)| = {self.fig7_dt_check:.1e} m on {FIG7_CHECK_CASE_NAME})"
            if self.fig7_dt_check == self.fig7_dt_check
            else " (not checked against 1e-8 s)"
        )
        lines = [f"Fig. 7: dt = {self.fig7_dt:g} s{check}"]
        npts = sum(len(d) for d in self.dense.values())
        if npts:
            how = (f"RK4, dt = {self.fig7_dt:g} s" if self.dense_method == "rk4"
                   else f"{self.dense_method}, adaptive")
            lines.append(f"  final-position summaries: {npts} points through idm_rs.sweep ({how})")
        for key, runs in self.sweeps.items():
            dense = self.dense.get(key, []) if self.dense_method == "rk4" else []  # dopri5's dt is its own
            both: list[Union[SweepRun, FinalPoint]] = [*runs, *dense]
            halved = [f"{r.value:g}: dt {r.dt:g}" for r in both if r.dt != self.fig7_dt]
            diverged = [f"{p.value:g}" for p in self.dense.get(key, []) if p.status == 3]
            if diverged:
                halved.append("diverged at every step tried: " + ", ".join(diverged))
            finals = ", ".join(f"{r.value:g} -> {r.result.final_position * 1e6:+.3f}" for r in runs)
            lines.append(f"  {key} x1(10 ms) [um]: {finals}"
                         + (f"  (halved dt: {'; '.join(halved)})" if halved else ""))
        return "\n".join(lines)


def fig7_run_count(quick: bool = False) -> int:
    """How many simulations the Fig. 7 sweeps take."""
    return sum(len(s.values) + len(s.dense) for s in fig7_sweeps(quick))


def write_figures(
    case: PaperCase,
    out_dir: PathLike,
    *,
    quick: bool = False,
    fig7_dt: Optional[float] = None,
    bar: Any = None,
    progress: bool = True,
    dense_method: Optional[MethodName] = None,
    threads: Optional[int] = None,
) -> FiguresReport:
    """Write fig6a.png … fig7d.png into ``out_dir`` from the paper case and the Fig. 7 sweeps.

    ``fig7_dt``: the Fig. 7 step; by default 2e-8 s if it agrees with 1e-8 s to 1e-11 m on the
    stiffest case, m2/m1 = 0.25 (checked here), else 1e-8 s; with ``quick`` 2e-8 s unchecked. A curve that
    diverges is rerun with half the step. The final-position summaries (right panels) run as one
    :func:`idm_rs.sweep` per panel on ``threads`` threads (default all cores), with
    ``dense_method`` (default ``"rk4"`` at ``fig7_dt``, bit for bit ``simulate()``; ``"dopri5"``
    with ``quick``). ``bar``: a tqdm bar to advance by one per simulation and per figure (else one
    is made, shown if ``progress``)."""
    from tqdm.auto import tqdm

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    sweeps = fig7_sweeps(quick)
    own_bar = bar is None
    if own_bar:
        bar = tqdm(total=2 + fig7_run_count(quick) + 8, desc="figures", unit="run", disable=not progress)
    rep = FiguresReport(dense_method=dense_method or ("dopri5" if quick else "rk4"))
    try:
        if fig7_dt is None:
            if quick:
                fig7_dt, rep.fig7_dt_check = 2e-8, float("nan")
            else:
                bar.set_postfix_str("dt check")
                fig7_dt, rep.fig7_dt_check = choose_fig7_dt()
            bar.update(2)
        else:
            rep.fig7_dt_check = float("nan")
        rep.fig7_dt = fig7_dt
        lps, dps = case
        fig6: tuple[Callable[[SimulationResult, SimulationResult, PathLike], Path], ...] = (fig6a, fig6b, fig6c, fig6d)
        for name, fn in zip(FIG6_NAMES, fig6):
            bar.set_postfix_str(name)
            rep.paths[name] = fn(lps, dps, out / f"{name}.png")
            bar.update(1)
        for name, sweep in zip(FIG7_NAMES, sweeps):
            bar.set_postfix_str(name)
            runs = run_sweep(sweep, fig7_dt, on_done=lambda: bar.update(1))
            dense = run_dense(sweep, fig7_dt, on_done=lambda: bar.update(1), method=rep.dense_method,
                              threads=threads)
            rep.sweeps[sweep.key] = runs
            rep.dense[sweep.key] = dense
            how = f"RK4 {fig7_dt:g} s" if rep.dense_method == "rk4" else rep.dense_method
            label = f"{len(dense)} values (idm_rs.sweep, {how})"
            rep.paths[name] = fig7(sweep, runs, out / f"{name}.png", dense, dense_label=label)
            bar.update(1)
    finally:
        if own_bar:
            bar.close()
    return rep
