"""What the ``idm-rs`` commands read and write: parameter, effect and waveform overrides from
the arguments, a sampled voltage from CSV, the sweep grid's axes; trajectories and sweeps as CSV
and netCDF, and a sweep's summary in words."""

from __future__ import annotations

import argparse
import dataclasses
import math
from pathlib import Path
from typing import TYPE_CHECKING, Any, Literal, Optional, Sequence, cast

import numpy as np

from ..core import methods
from ..core.declarations import structure_label
from ..core.effects import Effects
from ..core.params import Params
from ..core.simulation_result import SimulationResult
from ..core.waveforms import STARTUP_CYCLES, Sampled, Sawtooth, Triangle, Waveform
from ..sweeps.plan import STEADY_METRICS

if TYPE_CHECKING:
    import xarray


#: the xarray netCDF writers the CLI uses (netCDF4 when installed, else scipy's netCDF3)
NetcdfEngine = Literal["netcdf4", "scipy"]
CSV_COLUMNS = ("t_s", "voltage_V", "x1_m", "x2_m", "friction_N", "fh_N")


class CliError(ValueError):
    """An input error found by the command line itself."""



# --- helpers -------------------------------------------------------------------------------------


def parse_param_overrides(items: Sequence[str]) -> dict[str, Optional[float]]:
    """``["m1=0.5", "normal_force=auto"]`` → ``{"m1": 0.5, "normal_force": None}``."""
    out: dict[str, Optional[float]] = {}
    for item in items:
        name, sep, text = item.partition("=")
        name, text = name.strip(), text.strip()
        if not sep or not name or not text:
            raise CliError(f"--param expects NAME=VALUE, got {item!r}")
        if name == "normal_force" and text.lower() in ("auto", "none", "derived"):
            out[name] = None
            continue
        try:
            out[name] = float(text)
        except ValueError:
            raise CliError(f"parameter '{name}': cannot read {text!r} as a number") from None
    return out


def params_from_overrides(items: Sequence[str]) -> Params:
    return Params.from_dict(parse_param_overrides(items))


def waveform_from_args(a: argparse.Namespace) -> Waveform:
    """The input the options describe; an option that does not apply to it is refused."""
    sawtooth_only = {"--frequency": a.frequency, "--cycles": a.cycles, "--direction": a.direction}
    if a.voltage_csv is not None:
        given = [k for k, v in {**sawtooth_only, "--fall": a.fall}.items() if v is not None]
        if given or a.waveform != "triangle":
            raise CliError(f"--voltage-csv gives the whole input; drop {', '.join(given) or '--waveform'}")
        return sampled_from_csv(Path(a.voltage_csv))
    if a.waveform == "triangle":
        given = [k for k, v in sawtooth_only.items() if v is not None]
        if given:
            raise CliError(f"{', '.join(given)} {'applies' if len(given) == 1 else 'apply'} to "
                           "--waveform sawtooth, not to the triangle")
        return Triangle(amplitude=a.amplitude, rise=a.rise, fall=9.5e-3 if a.fall is None else a.fall,
                        delay=a.delay)
    if a.fall is not None:
        raise CliError("--fall applies to the triangle; a sawtooth falls over the rest of its period")
    return Sawtooth(
        amplitude=a.amplitude, frequency=100.0 if a.frequency is None else a.frequency,
        cycles=3 if a.cycles is None else a.cycles, rise=a.rise,
        direction=a.direction or "forward", delay=a.delay,
    )


def sampled_from_csv(path: Path) -> Sampled:
    """A :class:`Sampled` input from a CSV of time [s] and voltage [V] (first two columns; one
    header line and ``#`` comments are skipped). Every error names the file, and the line (as an
    editor counts them, from 1) and column of a cell that is not a number."""
    where = f"--voltage-csv {path}"
    try:
        text = Path(path).read_text(encoding="utf-8")
    except FileNotFoundError:
        raise CliError(f"{where}: no such file") from None
    except UnicodeDecodeError as exc:
        raise CliError(f"{where}: not a UTF-8 text file ({exc.reason} at byte {exc.start})") from None
    rows: list[tuple[float, float]] = []
    header_seen = False
    for lineno, raw in enumerate(text.splitlines(), 1):
        line = raw.split("#", 1)[0].strip()
        if not line:
            continue
        cells = [c.strip() for c in line.split(",")]
        if len(cells) < 2:
            raise CliError(f"{where}, line {lineno}: needs two columns, time [s] and voltage [V]; got {raw.strip()!r}")
        try:
            rows.append((float(cells[0]), float(cells[1])))
        except ValueError:
            if not rows and not header_seen:  # the header line
                header_seen = True
                continue
            col = 1 if not _is_number(cells[0]) else 2
            raise CliError(f"{where}, line {lineno}, column {col}: "
                           f"cannot read {cells[col - 1]!r} as a number") from None
    if len(rows) < 2:
        raise CliError(f"{where}: {len(rows)} sample(s); a sampled input needs at least 2 (time [s], voltage [V])")
    data = np.array(rows)
    bad = np.flatnonzero(~np.isfinite(data).all(axis=1))
    if bad.size:
        raise CliError(f"{where}: sample {bad[0] + 1} is not finite ({data[bad[0]].tolist()})")
    back = np.flatnonzero(np.diff(data[:, 0]) <= 0)
    if back.size:
        i = int(back[0])
        raise CliError(f"{where}: times must increase strictly; sample {i + 2} (t = {data[i + 1, 0]:g} s) is not after "
                       f"sample {i + 1} (t = {data[i, 0]:g} s)")
    if data[-1, 0] > LONG_DRIVE_S:
        import warnings

        warnings.warn(f"{where}: the times run to {data[-1, 0]:g} s (read in seconds): a drive of "
                      f"{data[-1, 0] - data[0, 0]:g} s; if they are milliseconds, divide the column by 1000",
                      UserWarning, stacklevel=2)
    try:
        return Sampled(data[:, 0], data[:, 1])
    except ValueError as exc:
        raise CliError(f"{where}: {exc}") from None


#: a sampled drive longer than this [s] is said to be long (an IDM's records last milliseconds;
#: a column in milliseconds read as seconds runs a thousand times too long)
LONG_DRIVE_S = 1.0


def _is_number(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True


def warn_past_samples(waveform: Waveform, t_end: float) -> None:
    """A sampled input holds its last value after its last sample: say so when the run goes on."""
    if isinstance(waveform, Sampled) and t_end > waveform.t[-1] * (1 + 1e-12):
        import warnings

        warnings.warn(f"--t-end {t_end:g} s is past the last sample of --voltage-csv (t = {waveform.t[-1]:g} s): "
                      f"the input holds {waveform.voltage[-1]:g} V from there", UserWarning, stacklevel=2)


def effects_from_overrides(items: Sequence[str]) -> Effects:
    """``["theta_rad=0.01"]`` → ``Effects(theta_rad=0.01)``; unknown names are refused."""
    values = {}
    known = {f.name for f in dataclasses.fields(Effects)}
    for item in items:
        name, sep, text = item.partition("=")
        name, text = name.strip(), text.strip()
        if not sep or not name or not text:
            raise CliError(f"--effect expects NAME=VALUE, got {item!r}")
        if name not in known:
            raise CliError(f"unknown effect parameter '{name}'; known: {', '.join(sorted(known))}")
        try:
            values[name] = float(text)
        except ValueError:
            raise CliError(f"effect parameter '{name}': cannot read {text!r} as a number") from None
    return Effects(**values)


def snap(t: float, dt: float) -> float:
    """``t`` rounded to a whole number of steps when it is within 1e-9 of one."""
    from ..sweeps.plan import snap_to_steps

    return cast(float, snap_to_steps(t, dt))  # a number in, a number out


def write_csv(result: SimulationResult, path: Path) -> None:
    """Columns t, voltage, x1, x2, friction, fh (SI units), full double precision, and
    ``reading`` (what the sensor reads [m]) where a sensor effect makes it differ from x1."""
    cols = [result.t, result.voltage, result.main_body, result.weight, result.friction, result.fh]
    names = list(CSV_COLUMNS)
    if not np.array_equal(result.reading, result.main_body):
        cols.append(result.reading)
        names.append("reading_m")
    np.savetxt(path, np.column_stack(cols), delimiter=",", header=",".join(names), comments="", fmt="%.17g")


def write_netcdf(result: SimulationResult, path: Path) -> None:
    ds = result.to_xarray()
    engine: NetcdfEngine
    try:
        import netCDF4  # noqa: F401

        engine = "netcdf4"
    except ImportError:
        engine = "scipy"
    ds.to_netcdf(path, engine=engine)


def save_trajectory(result: SimulationResult, path: Path) -> None:
    suffix = path.suffix.lower()
    if suffix not in (".csv", ".nc"):
        raise CliError(f"--out: unknown file type {path.suffix!r} (use .csv or .nc)")
    path.parent.mkdir(parents=True, exist_ok=True)
    (write_csv if suffix == ".csv" else write_netcdf)(result, path)


def paper_case_csv(lps: SimulationResult, dps: SimulationResult, path: Path, every: int = 1) -> None:
    """Both paper-case trajectories in one CSV: t, voltage, then x1, x2, friction, fh per model."""
    if lps.t.shape != dps.t.shape or not np.array_equal(lps.t, dps.t):
        raise ValueError("LPS and DPS results have different time grids")
    idx = np.arange(0, lps.t.size, every)
    if idx[-1] != lps.t.size - 1:
        idx = np.append(idx, lps.t.size - 1)
    cols = [lps.t, lps.voltage]
    names = ["t_s", "voltage_V"]
    for tag, r in (("lps", lps), ("dps", dps)):
        cols += [r.main_body, r.weight, r.friction, r.fh]
        names += [f"x1_{tag}_m", f"x2_{tag}_m", f"friction_{tag}_N", f"fh_{tag}_N"]
    data = np.column_stack(cols)[idx]
    np.savetxt(path, data, delimiter=",", header=",".join(names), comments="", fmt="%.17g")


# --- sweep helpers -------------------------------------------------------------------------------


def parse_grid_axis(item: str) -> tuple[str, np.ndarray]:
    """``"voltage=40:120:5"`` → ``("voltage", numpy.linspace(40, 120, 5))``; ``"mu_k=0.4,0.5"`` →
    ``("mu_k", [0.4, 0.5])``; ``"m1=0.3"`` → ``("m1", [0.3])``."""
    name, sep, spec = item.partition("=")
    name, spec = name.strip(), spec.strip()
    if not sep or not name or not spec:
        raise CliError(f"--grid expects NAME=A:B:N or NAME=V1,V2,..., got {item!r}")
    bad = CliError(f"--grid {name}: cannot read {spec!r} as A:B:N or a list of numbers")
    if ":" in spec:
        parts = [t.strip() for t in spec.split(":")]
        if len(parts) != 3:
            raise CliError(f"--grid {name}: expected A:B:N (numpy.linspace(A, B, N)), got {spec!r}")
        try:
            a, b = float(parts[0]), float(parts[1])
        except ValueError:
            raise bad from None
        if not parts[2].isdigit() or int(parts[2]) < 1:
            raise CliError(f"--grid {name}: N must be a positive integer, got {parts[2]!r}")
        values = np.linspace(a, b, int(parts[2]))
    else:
        try:
            values = np.array([float(v) for v in spec.split(",") if v.strip()])
        except ValueError:
            raise bad from None
    if values.size == 0:
        raise CliError(f"--grid {name}: no values")
    if not np.all(np.isfinite(values)):
        raise CliError(f"--grid {name}: values must be finite, got {spec!r}")
    return name, values


def parse_grid(items: Sequence[str]) -> dict[str, np.ndarray]:
    """Several ``--grid`` items → an ordered ``{name: values}`` (a name may appear once)."""
    grid: dict[str, np.ndarray] = {}
    for item in items:
        name, values = parse_grid_axis(item)
        if name in grid:
            raise CliError(f"--grid {name} is given twice")
        grid[name] = values
    return grid


def write_sweep_netcdf(ds: "xarray.Dataset", path: Path, engine: Optional[NetcdfEngine] = None) -> str:
    """Save a sweep Dataset as netCDF, with the netCDF4 engine when it is installed, else scipy's
    netCDF3 writer (which has no unsigned or 64-bit integers: ``steps`` is then stored as float64,
    exact below 2**53, and ``status`` as int8). Returns the engine used."""
    if engine is None:
        try:
            import netCDF4  # noqa: F401

            engine = "netcdf4"
        except ImportError:
            engine = "scipy"
    if engine == "scipy":
        ds = ds.copy()
        for name in list(ds.variables):
            var = ds[name]
            if var.dtype.kind == "u" or var.dtype == np.int64:
                target = np.int8 if var.dtype.itemsize == 1 else np.float64
                ds[name] = var.astype(target)
                ds[name].attrs = dict(var.attrs)
            elif var.dtype.kind in ("U", "O"):  # netCDF3 has fixed-width bytes only
                ds[name] = var.astype(str).astype("S")
                ds[name].attrs = dict(var.attrs)
            for key, value in list(ds[name].attrs.items()):
                if isinstance(value, np.ndarray) and (value.dtype.kind == "u" or value.dtype == np.int64):
                    ds[name].attrs[key] = value.astype(np.int8 if value.dtype.itemsize == 1 else np.float64)
        for key, value in list(ds.attrs.items()):
            if isinstance(value, (bool, np.bool_)):
                ds.attrs[key] = int(value)
    path.parent.mkdir(parents=True, exist_ok=True)
    ds.to_netcdf(path, engine=engine)
    return engine


STATUS_NAMES = ("not run", "ok", "ok at a smaller dt", "diverged", "invalid")


#: points read at a time when a summary scans a sweep's variable (a store of 10^8 points is
#: never loaded whole)
SUMMARY_BLOCK = 10_000_000


def _row_blocks(var: "xarray.DataArray") -> Any:
    """``var``'s values in blocks of whole rows of its first axis, about SUMMARY_BLOCK points each."""
    if var.ndim == 0 or var.size <= SUMMARY_BLOCK:
        yield np.asarray(var.values)
        return
    rows = max(1, SUMMARY_BLOCK // max(var.size // var.shape[0], 1))
    for i in range(0, var.shape[0], rows):
        yield np.asarray(var[i:i + rows].values)


def _finite_range(var: "xarray.DataArray") -> Optional[tuple[float, float]]:
    """(min, max) of ``var``'s finite values, read block by block; None when there is none."""
    lo, hi = math.inf, -math.inf
    for block in _row_blocks(var):
        finite = block[np.isfinite(block.astype(float))]
        if finite.size:
            lo, hi = min(lo, float(finite.min())), max(hi, float(finite.max()))
    return (lo, hi) if lo <= hi else None


def sweep_summary(ds: "xarray.Dataset", metric: str) -> str:
    """A few lines: the grid, the wall time and rate, the statuses and the metric's range."""
    a = ds.attrs
    axes = " x ".join(f"{d} ({ds.sizes[d]})" for d in ds["status"].dims) or "?"
    n = int(a["points"])
    wall = float(a["wall_time_s"])
    model = structure_label(a["model"], a["n_elements"])
    step = (f"rtol = {a['rtol']:g}, atol = {a['atol']:g}" if methods.is_adaptive(a["method"])
            else f"dt = {a['dt_s']:g} s")
    counts = np.zeros(len(STATUS_NAMES), dtype=np.int64)
    for block in _row_blocks(ds["status"]):
        counts += np.bincount(block.ravel().astype(np.int64), minlength=len(STATUS_NAMES))
    statuses = ", ".join(f"{name} {int(c)}" for name, c in zip(STATUS_NAMES, counts) if c or name in ("ok", "diverged"))
    rule = a.get("t_end_rule", "as given")
    t_end = f"t_end = {a['t_end_s']:g} s" if rule in ("as given", "the waveform's end") else f"t_end: {rule}"
    finished = int(a.get("points_finished", n))
    rate = (f"{finished / wall:.1f} points/s" if finished and wall > 0 else "no point finished")
    lines = [
        f"sweep of {axes} = {n} points: {model}, {a['method']} ({step}), {t_end}, {a['executor']}",
        f"wall time {wall:.2f} s, {rate}" + (f" ({finished} of {n} points)" if finished != n else ""),
        f"status: {statuses}",
    ]
    steady = next((m for m in STEADY_METRICS if m in ds), None)
    if steady is not None and _finite_range(ds[steady]) is not None:
        k = int(a.get("skip_cycles", STARTUP_CYCLES))
        lines.append(f"steady state: the cycles after the first {k} (--skip-cycles)")
    if metric in ds:
        span = _finite_range(ds[metric])
        units = ds[metric].attrs.get("units", "")
        if span is not None:
            lines.append(f"{metric}: min {span[0]:.6g}, max {span[1]:.6g} [{units}]")
    if not a.get("complete", 1):
        lines.append(f"interrupted: {int(a['points_finished'])} of {n} points finished; the rest are NaN")
    return "\n".join(lines)
