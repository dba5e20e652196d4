"""The ``idm-rs`` command line: ``idm-rs reproduce`` (the paper's Figs. 6 and 7) and
``idm-rs simulate`` (one case). ``python -m idm_rs`` is the same command.

Errors in the input (a bad parameter, a step that does not fit the waveform, a run that
diverges) print one ``error: ...`` line to stderr and exit with status 2.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path
from typing import Optional, Sequence

import numpy as np

from . import __version__
from .params import Params
from .simulation import DivergenceError, SimulationResult, simulate
from .waveforms import Sawtooth, Triangle, Waveform

EXIT_ERROR = 2
CSV_COLUMNS = ("t", "voltage", "x1", "x2", "friction", "fh")
CSV_UNITS = ("s", "V", "m", "m", "N", "N")


class CliError(ValueError):
    """An input error found by the command line itself."""


# --- argument parsing ------------------------------------------------------------------------------


def _positive_float(text: str) -> float:
    try:
        v = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a number: {text!r}") from None
    if not v > 0 or v == float("inf"):
        raise argparse.ArgumentTypeError(f"must be a positive number, got {text}")
    return v


def _positive_int(text: str) -> int:
    try:
        v = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not an integer: {text!r}") from None
    if v < 1:
        raise argparse.ArgumentTypeError(f"must be a positive integer, got {text}")
    return v


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="idm-rs",
        description="Dynamics of piezoelectric impact drive mechanisms (stick-slip actuators).",
    )
    parser.add_argument("--version", action="version", version=f"idm-rs {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")

    rp = sub.add_parser(
        "reproduce",
        help="run the paper case, print the comparison table, write Figs. 6a-7d",
        description=(
            "Run the paper case (LPS and DPS n = 4, triangle 0 -> 80 V in 0.5 ms, back to 0 V at 10 ms), "
            "print x1(10 ms) beside the paper's and MODEL.md's values, and write fig6a.png ... fig7d.png "
            "and paper_case.csv (the trajectories) into DIR."
        ),
    )
    rp.add_argument("--out", default="idm-rs-paper", metavar="DIR", help="output folder (default: %(default)s)")
    rp.add_argument("--dt", type=_positive_float, default=None, metavar="DT",
                    help="RK4 step of the paper case [s] (default 1e-8; 2e-8 with --quick)")
    rp.add_argument("--quick", action="store_true",
                    help="fewer Fig. 7 curves, no dense summary, dt 2e-8 s (for tests)")
    rp.add_argument("--no-progress", action="store_true", help="no progress bar")

    sp = sub.add_parser(
        "simulate",
        help="simulate one case and save its trajectory",
        description="Simulate one IDM case from rest and print x1(t_end).",
    )
    sp.add_argument("--model", choices=("lps", "dps"), default="dps", help="lumped or FEM model (default: dps)")
    sp.add_argument("--n-elements", type=_positive_int, default=4, metavar="N",
                    help="FEM elements of the DPS (default: 4)")
    sp.add_argument("--dt", type=_positive_float, default=1e-8, metavar="DT", help="RK4 step [s] (default: 1e-8)")
    sp.add_argument("--t-end", type=_positive_float, default=None, metavar="T",
                    help="simulated time [s] (default: the end of the waveform)")
    sp.add_argument("--save-every", type=_positive_int, default=100, metavar="K",
                    help="save every K-th step (default: 100)")
    sp.add_argument("--waveform", choices=("triangle", "sawtooth"), default="triangle",
                    help="input voltage (default: triangle, the paper's single wave)")
    sp.add_argument("--amplitude", type=float, default=80.0, metavar="V", help="peak voltage [V] (default: 80)")
    sp.add_argument("--rise", type=_positive_float, default=0.5e-3, metavar="S", help="rise time [s] (default: 5e-4)")
    sp.add_argument("--fall", type=_positive_float, default=9.5e-3, metavar="S",
                    help="triangle: fall time [s] (default: 9.5e-3)")
    sp.add_argument("--frequency", type=_positive_float, default=100.0, metavar="HZ",
                    help="sawtooth: frequency [Hz] (default: 100)")
    sp.add_argument("--cycles", type=_positive_int, default=3, metavar="N", help="sawtooth: periods (default: 3)")
    sp.add_argument("--direction", choices=("forward", "backward"), default="forward",
                    help="sawtooth: step direction (default: forward)")
    sp.add_argument("--delay", type=float, default=0.0, metavar="S", help="0 V before the wave [s] (default: 0)")
    sp.add_argument("--param", action="extend", nargs="+", default=[], metavar="NAME=VALUE",
                    help="override a parameter of Table 1 (SI units), e.g. --param m2=0.4 mu_k=0.45; "
                         "normal_force=auto restores (m1+m2+mPE) g")
    sp.add_argument("--no-hysteresis", action="store_true", help="turn off the piezo (Bouc-Wen) hysteresis")
    sp.add_argument("--out", default=None, metavar="FILE",
                    help="save the trajectory: FILE.csv (columns " + ", ".join(CSV_COLUMNS) + "; SI units) "
                         "or FILE.nc (netCDF, every variable)")
    sp.add_argument("--plot", default=None, metavar="FILE.png", help="plot voltage, x1, x2 and friction")
    return parser


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
    if a.waveform == "triangle":
        return Triangle(amplitude=a.amplitude, rise=a.rise, fall=a.fall, delay=a.delay)
    return Sawtooth(
        amplitude=a.amplitude, frequency=a.frequency, cycles=a.cycles, rise=a.rise,
        direction=a.direction, delay=a.delay,
    )


def _snap(t: float, dt: float) -> float:
    """``t`` rounded to a whole number of steps when it is within 1e-9 of one."""
    k = round(t / dt)
    return k * dt if abs(k * dt - t) <= 1e-9 * max(1.0, abs(t)) else t


def write_csv(result: SimulationResult, path: Path) -> None:
    """Columns t, voltage, x1, x2, friction, fh (SI units), full double precision."""
    data = np.column_stack(
        [result.t, result.voltage, result.main_body, result.weight, result.friction, result.fh]
    )
    np.savetxt(path, data, delimiter=",", header=",".join(CSV_COLUMNS), comments="", fmt="%.17g")


def write_netcdf(result: SimulationResult, path: Path) -> None:
    ds = result.to_xarray()
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


def plot_result(result: SimulationResult, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    t = result.t * 1e3
    fig, (ax, axf) = plt.subplots(2, 1, figsize=(8, 6.5), sharex=True, layout="constrained")
    ax.plot(t, result.main_body * 1e6, color="C0", label="x1 (main body)")
    ax.plot(t, result.weight * 1e6, color="C2", ls="--", lw=1.0, label="x2 (weight)")
    ax.set_ylabel("displacement [µm]")
    ax.grid(alpha=0.3)
    axv = ax.twinx()
    axv.plot(t, result.voltage, color="0.5", lw=0.9, label="voltage")
    axv.set_ylabel("voltage V [V]", color="0.4")
    lines = ax.get_lines() + axv.get_lines()
    ax.legend(lines, [ln.get_label() for ln in lines], fontsize=8.5, loc="best")
    label = "LPS" if result.model == "lps" else f"DPS (n = {result.n_elements})"
    ax.set_title(f"{label}: x1(t_end) = {result.final_position * 1e6:.4f} µm")
    axf.plot(t, result.friction, color="C3", lw=0.8)
    axf.set_ylabel("friction force Ff [N]")
    axf.set_xlabel("time t [ms]")
    axf.set_xlim(t[0], t[-1])
    axf.grid(alpha=0.3)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=130)
    plt.close(fig)


def paper_case_csv(lps: SimulationResult, dps: SimulationResult, path: Path, every: int = 1) -> None:
    """Both paper-case trajectories in one CSV: t, voltage, then x1, x2, friction, fh per model."""
    if lps.t.shape != dps.t.shape or not np.array_equal(lps.t, dps.t):
        raise ValueError("LPS and DPS results have different time grids")
    idx = np.arange(0, lps.t.size, every)
    if idx[-1] != lps.t.size - 1:
        idx = np.append(idx, lps.t.size - 1)
    cols = [lps.t, lps.voltage]
    names = ["t", "voltage"]
    for tag, r in (("lps", lps), ("dps", dps)):
        cols += [r.main_body, r.weight, r.friction, r.fh]
        names += [f"x1_{tag}", f"x2_{tag}", f"friction_{tag}", f"fh_{tag}"]
    data = np.column_stack(cols)[idx]
    np.savetxt(path, data, delimiter=",", header=",".join(names), comments="", fmt="%.17g")


# --- commands ------------------------------------------------------------------------------------


def cmd_simulate(a: argparse.Namespace) -> int:
    params = params_from_overrides(a.param)
    waveform = waveform_from_args(a)
    t_end = _snap(a.t_end if a.t_end is not None else waveform.duration, a.dt)
    out = Path(a.out) if a.out else None
    if out is not None and out.suffix.lower() not in (".csv", ".nc"):
        raise CliError(f"--out: unknown file type {out.suffix!r} (use .csv or .nc)")
    t0 = time.perf_counter()
    result = simulate(
        params, waveform, t_end=t_end, dt=a.dt, model=a.model, n_elements=a.n_elements,
        save_every=a.save_every, piezo_hysteresis=not a.no_hysteresis,
    )
    elapsed = time.perf_counter() - t0
    label = "LPS" if a.model == "lps" else f"DPS (n = {a.n_elements})"
    steps = round(t_end / a.dt)
    print(f"{label}, {waveform!r}, t_end = {t_end:g} s, dt = {a.dt:g} s")
    print(f"final position x1({t_end * 1e3:g} ms) = {result.final_position * 1e6:.6f} µm")
    print(f"run time {elapsed:.3f} s ({steps} steps, {steps / max(elapsed, 1e-9) / 1e6:.1f} M steps/s)")
    if out is not None:
        save_trajectory(result, out)
        print(f"wrote {out}")
    if a.plot:
        plot_result(result, Path(a.plot))
        print(f"wrote {a.plot}")
    return 0


def cmd_reproduce(a: argparse.Namespace) -> int:
    from tqdm.auto import tqdm

    from . import paper
    from .figures import fig7_run_count, write_figures

    dt = a.dt if a.dt is not None else (2e-8 if a.quick else paper.PAPER_DT)
    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    # save about every 0.1 µs for smooth Fig. 6 curves (1 µs in quick mode)
    interval = 1e-6 if a.quick else 1e-7
    save_every = paper.save_every_for(dt, interval)
    t0 = time.perf_counter()
    total = 2 + 2 + fig7_run_count(a.quick) + 8
    with tqdm(total=total, desc="reproduce", unit="run", disable=a.no_progress, file=sys.stderr) as bar:
        bar.set_postfix_str("paper case")
        case = paper.run_paper_case(dt=dt, save_every=save_every)
        bar.update(2)
        csv_every = max(1, round(1e-6 / (dt * save_every)))  # the CSV at about 1 µs
        paper_case_csv(case.lps, case.dps, out / "paper_case.csv", every=csv_every)
        report = write_figures(case, out, quick=a.quick, fig7_dt=2e-8 if a.quick else None, bar=bar)
    elapsed = time.perf_counter() - t0
    print(paper.comparison_table(case.lps, case.dps))
    print()
    print(report.summary())
    print()
    print(f"wrote {out / 'paper_case.csv'} and " + ", ".join(p.name for p in report.paths.values()) + f" in {out}")
    print(f"total time {elapsed:.1f} s")
    return 0


def _one_line(exc: BaseException) -> str:
    msg = exc.args[0] if exc.args and isinstance(exc.args[0], str) else str(exc)
    return " ".join(str(msg).split())


def main(argv: Optional[Sequence[str]] = None) -> int:
    """Entry point of ``idm-rs`` and ``python -m idm_rs``; returns the exit status."""
    parser = build_parser()
    a = parser.parse_args(argv)
    if a.command is None:
        parser.print_help()
        return EXIT_ERROR
    try:
        return cmd_reproduce(a) if a.command == "reproduce" else cmd_simulate(a)
    except (ValueError, DivergenceError, OSError) as exc:
        print(f"error: {_one_line(exc)}", file=sys.stderr)
        return EXIT_ERROR
    except KeyboardInterrupt:
        print("error: interrupted", file=sys.stderr)
        return 130
