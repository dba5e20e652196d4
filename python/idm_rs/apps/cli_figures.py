"""The command line's figures: a simulated trajectory (``idm-rs simulate --plot``) and a sweep's
heat map or line plot (``idm-rs sweep --plot``), with the titles that say what was run."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Any, Sequence

import numpy as np

from ..core.declarations import structure_label
from ..core.methods import is_adaptive
from ..core.simulation_result import SimulationResult
from ..core.waveforms import Sawtooth

if TYPE_CHECKING:
    import xarray
    from matplotlib.figure import Figure


class PlotError(ValueError):
    """A figure that cannot be drawn from what was asked (the command line prints it as an error)."""


def result_title(result: SimulationResult) -> str:
    """The trajectory plot's title: the model, the effects that were on, x1(t_end)."""
    label = structure_label(result.model, result.n_elements)
    on = result.effects.active()
    effects = ("; " + ", ".join(f"{k} = {v:g}" for k, v in on.items())) if on else ""
    return f"{label}{effects}: x1(t_end) = {result.final_position * 1e6:.4f} µm"


def plot_result(result: SimulationResult, path: Path) -> "Figure":
    """Displacements and voltage over the run, and the friction force. A sawtooth train of 4 or
    more cycles switches friction between ±Fs several times per cycle, which over the whole run
    is a solid band: its friction panel zooms on the last full cycle instead (shaded above)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    t = result.t * 1e3
    w = result.waveform
    zoom = isinstance(w, Sawtooth) and w.cycles >= 4
    fig, (ax, axf) = plt.subplots(2, 1, figsize=(8, 6.5), sharex=not zoom, layout="constrained")
    ax.plot(t, result.main_body * 1e6, color="C0", label="x1 (main body)")
    ax.plot(t, result.weight * 1e6, color="C2", ls="--", lw=1.0, label="x2 (weight)")
    ax.set_ylabel("displacement [µm]")
    ax.grid(alpha=0.3)
    axv = ax.twinx()
    axv.plot(t, result.voltage, color="0.5", lw=0.9, label="voltage")
    axv.set_ylabel("voltage V [V]", color="0.4")
    lines = ax.get_lines() + axv.get_lines()
    # above the axes, never over the traces
    ax.legend(lines, [ln.get_label() for ln in lines], fontsize=8.5, loc="lower center", bbox_to_anchor=(0.5, 1.0),
              ncol=3, frameon=False)
    fig.suptitle(result_title(result), fontsize=10)
    if zoom:
        assert isinstance(w, Sawtooth)
        last = min(w.cycles, int((result.t[-1] - w.delay) / w.period + 1e-9)) - 1
        t0 = w.delay + max(last, 0) * w.period
        sel = (result.t >= t0 - 1e-12) & (result.t <= t0 + w.period + 1e-12)
        ax.axvspan(t0 * 1e3, (t0 + w.period) * 1e3, color="C3", alpha=0.08, lw=0)
        axf.plot((result.t[sel] - t0) * 1e3, result.friction[sel], color="C3", lw=0.8)
        axf.set_xlabel(f"time in cycle {last + 1} of {w.cycles} [ms] (from t = {t0 * 1e3:g} ms; shaded above)")
        ax.set_xlabel("time t [ms]")
        ax.set_xlim(t[0], t[-1])
    else:
        axf.plot(t, result.friction, color="C3", lw=0.8)
        axf.set_xlabel("time t [ms]")
        axf.set_xlim(t[0], t[-1])
    axf.set_ylabel("friction force Ff [N]")
    axf.grid(alpha=0.3)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=130)
    plt.close(fig)
    return fig  # closed: what was drawn, for a caller that checks it


def _cell_edges(c: np.ndarray) -> np.ndarray:
    """Edges of the cells centred on the (sorted or not) coordinates ``c``."""
    c = np.asarray(c, dtype=float)
    if c.size == 1:
        half = 0.05 * abs(c[0]) or 0.5
        return np.array([c[0] - half, c[0] + half])
    mid = 0.5 * (c[1:] + c[:-1])
    return np.concatenate([[c[0] - (mid[0] - c[0])], mid, [c[-1] + (c[-1] - mid[-1])]])


def _display_scale(units: str) -> tuple[float, str]:
    """Plot lengths in µm and velocities in mm/s; everything else in its own units."""
    return {"m": (1e6, "µm"), "m/s": (1e3, "mm/s")}.get(units, (1.0, units))


def _axis_label(da: "xarray.DataArray", name: str) -> str:
    """``name [units]``; a dimensionless quantity shows ``[-]``."""
    units = da.attrs.get("units", "")
    return f"{name} [{'-' if units == '1' else units}]" if units else name


def plot_sweep(ds: "xarray.Dataset", metric: str, path: Path) -> None:
    """A heat map of ``metric`` over a 2-axis sweep (pcolormesh, colour bar with units) or a line
    plot over a 1-axis sweep. Points that diverged (status 3) are hatched grey, points not run
    (an interrupted sweep) plain grey."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.collections import PatchCollection
    from matplotlib.patches import Patch, Rectangle

    da = ds[metric]
    dims = [str(d) for d in da.dims]  # a sweep's axes are named by str
    if len(dims) not in (1, 2):
        raise PlotError(f"--plot draws sweeps of 1 or 2 axes; this one has {len(dims)} ({', '.join(dims)})")
    scale, units = _display_scale(da.attrs.get("units", ""))
    values = da.values.astype(float) * scale
    status = ds["status"].values
    diverged = status == 3
    not_run = status == 0
    label = f"{metric} [{units}]" if units and units != "1" else metric
    long_name = da.attrs.get("long_name", metric)
    hatch: dict[str, Any] = dict(facecolor="0.75", edgecolor="0.35", hatch="///", lw=0.0)

    fig, ax = plt.subplots(figsize=(8, 6) if len(dims) == 2 else (8, 4.5), layout="constrained")
    if len(dims) == 2:
        ydim, xdim = dims
        x, y = ds[xdim].values, ds[ydim].values
        xe, ye = _cell_edges(x), _cell_edges(y)
        finite = values[np.isfinite(values)]
        signed = finite.size > 0 and finite.min() < 0 < finite.max()
        # a signed quantity (a displacement that can go either way) on a diverging map centred on 0
        if signed:
            from matplotlib.colors import TwoSlopeNorm

            cmap = plt.get_cmap("RdBu_r").with_extremes(bad="0.75")
            norm = TwoSlopeNorm(vcenter=0.0, vmin=float(finite.min()), vmax=float(finite.max()))
        else:
            cmap, norm = plt.get_cmap("viridis").with_extremes(bad="0.75"), None
        mesh = ax.pcolormesh(xe, ye, np.ma.masked_invalid(values), cmap=cmap, norm=norm, shading="flat")
        cb = fig.colorbar(mesh, ax=ax)
        cb.set_label(f"{long_name} [{units}]" if units and units != "1" else long_name)
        rects = [Rectangle((xe[j], ye[i]), xe[j + 1] - xe[j], ye[i + 1] - ye[i]) for i, j in zip(*np.nonzero(diverged))]
        if rects:
            ax.add_collection(PatchCollection(rects, **hatch))
        ax.set_xlabel(_axis_label(ds[xdim], xdim))
        ax.set_ylabel(_axis_label(ds[ydim], ydim))
    else:
        (xdim,) = dims
        x = ds[xdim].values
        xe = _cell_edges(x)
        ax.plot(x, values, ".-", color="C0", lw=1.2, ms=4)
        for j in np.flatnonzero(diverged):
            ax.axvspan(xe[j], xe[j + 1], **hatch)
        for j in np.flatnonzero(not_run):
            ax.axvspan(xe[j], xe[j + 1], color="0.85", lw=0)
        ax.set_xlabel(_axis_label(ds[xdim], xdim))
        ax.set_ylabel(label)
        ax.grid(alpha=0.3)
    handles = []
    if diverged.any():
        handles.append(Patch(**hatch, label=f"diverged ({int(diverged.sum())})"))
    if not_run.any():
        handles.append(Patch(facecolor="0.75" if len(dims) == 2 else "0.85", label=f"not run ({int(not_run.sum())})"))
    if handles:
        ax.legend(handles=handles, loc="best", fontsize=8.5)
    ax.set_title(sweep_title(ds, metric), fontsize=9.5)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=130)
    plt.close(fig)


def sweep_title(ds: "xarray.Dataset", metric: str) -> str:
    """The sweep plot's title: the metric, then the model, method, span and waveform, wrapped to
    the figure's width (at 9.5 pt about 95 characters fit in 8 inches)."""
    import textwrap

    a = ds.attrs
    model = structure_label(str(a.get("model")), int(a.get("n_elements", 1)))
    step = f"rtol = {a.get('rtol'):g}" if is_adaptive(str(a.get("method"))) else f"dt = {a.get('dt_s'):g} s"
    on = [k[len("effect_"):] + f" = {v:g}" for k, v in a.items() if k.startswith("effect_")]
    method = str(a.get("method"))
    asked = str(a.get("method_asked", method))
    how = f"{asked} ({method}, {step})" if asked != method else f"{method} ({step})"
    rule = str(a.get("t_end_rule", "as given"))
    span = (f"t_end = {a.get('t_end_s'):g} s" if rule in ("as given", "the waveform's end")
            else "each point to its own waveform's end")
    details = (f"{model}, {how}, {span}, "
               f"{_waveform_title(str(a.get('waveform')), [str(d) for d in ds[metric].dims])}"
               + (f"; effects: {', '.join(on)}" if on else ""))
    name: str = ds[metric].attrs.get("long_name", metric)
    return name + "\n" + textwrap.fill(details, 95)


def _waveform_title(text: str, swept: Sequence[str]) -> str:
    """The waveform's repr with the fields a sweep varies shown as swept (``voltage`` is the
    ``amplitude``), not at the base value that no point of the plot has."""
    import re

    for name in swept:
        field = "amplitude" if name == "voltage" else name
        text = re.sub(rf"\b{field}=[^,)]+", f"{field}=swept", text)
    return text
