"""The ``idm-rs`` command line: ``idm-rs reproduce`` (the paper's Figs. 6 and 7),
``idm-rs simulate`` (one case), ``idm-rs sweep`` (a grid of cases through the batch engine,
saved as netCDF with a heat map) and ``idm-rs diagnose`` (a recorded case against its nominal
model: report, JSON and plots). ``python -m idm_rs`` is the same command.

Errors in the input (a bad parameter, a step that does not fit the waveform, a run that
diverges) print one ``error: ...`` line to stderr and exit with status 2.
"""

from __future__ import annotations

import argparse
import dataclasses
import math
import sys
import time
from pathlib import Path
from typing import TYPE_CHECKING, Any, Callable, Literal, Optional, Sequence, cast

import numpy as np

from . import methods, options
from .cli_figures import plot_result, plot_sweep
from .cli_outputs import check_outputs
from .declarations import IDM_MODELS, structure_label
from .effects import Effects
from .engine import __version__
from .interrupted import partial_result
from .methods import METHODS
from .params import Params
from .simulation import DivergenceError, SimulationResult, simulate
from .sweep_plan import METRICS, STEADY_METRICS
from .units import si
from .waveforms import STARTUP_CYCLES, Sampled, Sawtooth, Triangle, Waveform

if TYPE_CHECKING:
    import xarray

EXIT_ERROR = 2
#: every command stopped by Ctrl-C exits with this (128 + SIGINT), after saying what it kept
EXIT_INTERRUPTED = 130
CSV_COLUMNS = ("t_s", "voltage_V", "x1_m", "x2_m", "friction_N", "fh_N")
#: the xarray netCDF writers the CLI uses (netCDF4 when installed, else scipy's netCDF3)
NetcdfEngine = Literal["netcdf4", "scipy"]


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


def _int_at_least(low: int, words: str) -> Callable[[str], int]:
    """An argparse type: an integer >= ``low`` (``words`` says what that means in the error)."""
    def parse(text: str) -> int:
        try:
            v = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"not an integer: {text!r}") from None
        if v < low:
            raise argparse.ArgumentTypeError(f"must be {words}, got {text}")
        return v

    return parse


_positive_int = _int_at_least(1, "a positive integer")
_non_negative_int = _int_at_least(0, "0 or more")


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="idm-rs",
        description="Dynamics of piezoelectric impact drive mechanisms (stick-slip actuators).",
    )
    parser.add_argument("--version", action="version", version=f"idm-rs {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")

    _add_reproduce_parser(sub)
    _add_simulate_parser(sub)
    _add_characterize_parser(sub)
    _add_rig_fit_parser(sub)
    _add_sweep_parser(sub)
    _add_diagnose_parser(sub)
    return parser


def _add_reproduce_parser(sub: "argparse._SubParsersAction[argparse.ArgumentParser]") -> None:
    rp = sub.add_parser(
        "reproduce",
        help="run the paper case, print the comparison table, write Figs. 6a-7d",
        description=(
            "Run the paper case (LPS and DPS n = 4, triangle 0 -> 80 V in 0.5 ms, back to 0 V at 10 ms), "
            "print x1(10 ms) beside the paper's and the reference values of docs/MODEL.md, "
            "and write fig6a.png ... fig7d.png "
            "and paper_case.csv (the trajectories) into DIR."
        ),
    )
    rp.add_argument("--out", default="idm-rs-paper", metavar="DIR", help="output folder (default: %(default)s)")
    rp.add_argument("--dt", type=_positive_float, default=None, metavar="DT",
                    help="RK4 step of the paper case [s] (default 1e-8; 2e-8 with --quick)")
    rp.add_argument("--quick", action="store_true",
                    help="fewer Fig. 7 curves, 9-point dopri5 final-position summaries, dt 2e-8 s (for tests)")
    rp.add_argument("--threads", type=_positive_int, default=None, metavar="N",
                    help="threads of the Fig. 7 summary sweeps (default: all cores)")
    rp.add_argument("--no-progress", action="store_true", help="no progress bar")


def _add_simulate_parser(sub: "argparse._SubParsersAction[argparse.ArgumentParser]") -> None:
    sp = sub.add_parser(
        "simulate",
        help="simulate one case and save its trajectory",
        description="Simulate one IDM case from rest and print x1(t_end).",
    )
    sp.add_argument("--model", choices=IDM_MODELS, default="dps", help="lumped or FEM model (default: dps)")
    sp.add_argument("--n-elements", type=_positive_int, default=None, metavar="N",
                    help="FEM elements of the DPS (default: 4)")
    _add_method_arguments(sp)
    sp.add_argument("--t-end", type=_positive_float, default=None, metavar="T",
                    help="simulated time [s] (default: the end of the waveform)")
    sp.add_argument("--save-every", type=_positive_int, default=100, metavar="K",
                    help="save every K-th step (default: 100)")
    _add_case_arguments(sp)
    sp.add_argument("--out", default=None, metavar="FILE",
                    help="save the trajectory: FILE.csv (columns " + ", ".join(CSV_COLUMNS) + ", and reading "
                         "where a sensor effect makes it differ from x1; the unit in each name) "
                         "or FILE.nc (netCDF, every variable)")
    sp.add_argument("--plot", default=None, metavar="FILE.png", help="plot voltage, x1, x2 and friction")
    sp.add_argument("--no-progress", action="store_true",
                    help="no progress bar (an RK4 run of more than 10^7 steps shows one)")


def _add_characterize_parser(sub: "argparse._SubParsersAction[argparse.ArgumentParser]") -> None:
    ch = sub.add_parser(
        "characterize",
        help="the actuator's characteristic curves: velocity vs frequency, step and back-slip vs voltage, "
             "velocity vs load and the stall force",
        description=(
            "Drive the design with sawtooth trains and write the standard characteristics into DIR: "
            "velocity_vs_frequency.png (one curve per voltage), step_backslip_vs_voltage.png, "
            "velocity_vs_load.png (stall force marked) and characteristics.nc (every number, with units). "
            "Steady state = the cycles after --skip-cycles start-up cycles. Defaults suit the paper's device."
        ),
    )
    ch.add_argument("--out", default="idm-rs-characteristics", metavar="DIR",
                    help="output folder (default: %(default)s)")
    ch.add_argument("--model", choices=IDM_MODELS, default="dps", help="lumped or FEM model (default: dps)")
    ch.add_argument("--n-elements", type=_positive_int, default=None, metavar="N",
                    help="FEM elements of the DPS (default: 4)")
    ch.add_argument("--frequencies", default=None, metavar="SPEC",
                    help="drive frequencies [Hz]: A:B:N (log-spaced) or F1,F2,... "
                         "(default: 12 from 20 Hz to 0.9/(2 rise), at most 1.5 kHz)")
    ch.add_argument("--voltages", default="40,60,80,100,120", metavar="V1,V2,...",
                    help="amplitudes of the velocity curves [V] (default: %(default)s)")
    ch.add_argument("--step-voltages", default="20:120:11", metavar="SPEC",
                    help="amplitudes of the step/back-slip curve [V]: A:B:N (linear) or V1,V2,... "
                         "(default: %(default)s)")
    ch.add_argument("--frequency", type=_positive_float, default=100.0, metavar="HZ",
                    help="design frequency of the step and load curves (default: 100)")
    ch.add_argument("--voltage", type=float, default=80.0, metavar="V",
                    help="design amplitude of the load curve (default: 80)")
    ch.add_argument("--rise", type=_positive_float, default=0.5e-3, metavar="S",
                    help="fast-edge time [s] (default: 5e-4)")
    ch.add_argument("--cycles", type=_positive_int, default=6, metavar="N", help="periods per run (default: 6)")
    ch.add_argument("--skip-cycles", type=_non_negative_int, default=STARTUP_CYCLES, metavar="K",
                    help="start-up cycles the steady-state metrics leave out (default: %(default)s, as sweep)")
    ch.add_argument("--loads", type=_positive_int, default=9, metavar="N",
                    help="points of the coarse load curve, 0 to 1.5 mu_s Fn (default: 9)")
    ch.add_argument("--method", choices=METHODS, default="auto", help="integration method (default: auto)")
    ch.add_argument("--param", action="extend", nargs="+", default=[], metavar="NAME=VALUE",
                    help="override a parameter (SI units), e.g. --param m2=0.4")
    ch.add_argument("--threads", type=_positive_int, default=None, metavar="N",
                    help="worker threads (default: all cores)")
    ch.add_argument("--no-progress", action="store_true", help="no progress bars")


def _add_rig_fit_parser(sub: "argparse._SubParsersAction[argparse.ArgumentParser]") -> None:
    rf = sub.add_parser(
        "rig-fit",
        help="identify a friction rig from a measured data file (EMPS, spring-slider, frame)",
        description=(
            "Identify the friction and rig parameters from one file of the measured data sets (see "
            "docs/REALDATA.md): print them with their 1-sigma uncertainties, what the data cannot identify, "
            "and the benchmark's simulation errors; --json writes rig, params, params_std (SI), rms, noise_rms "
            "and not_identifiable; --plots writes measured vs simulated figures."
        ),
    )
    rf.add_argument("path", metavar="PATH",
                    help="a data file of one of the measured sets (docs/REALDATA.md says where to get them), "
                         "e.g. DATA_EMPS.mat")
    rf.add_argument("--json", default=None, metavar="OUT", help="write the result as JSON")
    rf.add_argument("--plots", default=None, metavar="DIR", help="write figures into DIR")
    rf.add_argument("--no-simulation", action="store_true", help="identify only (skip the closed-loop simulations)")


def _add_sweep_parser(sub: "argparse._SubParsersAction[argparse.ArgumentParser]") -> None:
    sw = sub.add_parser(
        "sweep",
        help="sweep a grid of parameter values, save the metrics (netCDF) and a heat map",
        description=(
            "Run the outer product of the --grid axes through the parallel batch engine (no trajectories "
            "are stored: each point is reduced to final_position, step_per_cycle, peak_velocity, "
            "peak_friction, slip_fraction, the steady-state metrics of sawtooth trains (mean_velocity, step_mean, "
            "step_std, backslip, backslip_ratio, direction) and a status with its reason), print a summary, "
            "and save the labelled results "
            "(--out FILE.nc) and a heat map of one metric (--plot FILE.png). The normal force follows "
            "the swept masses, (m1+m2+mPE) g per point, unless set with --param normal_force=VALUE."
        ),
        epilog=(
            "Axis names: any Table 1 parameter (m1, mu_k, ...), any waveform field (amplitude, rise, fall, "
            "frequency, cycles, delay), any effect parameter, or a derived axis: mass_ratio (m2/m1, m1 fixed), "
            "pe_mass_ratio (mPE/m1 through the PE density), stiffness (kp [N/m] through Ep), voltage "
            "(the amplitude [V]). Example: idm-rs sweep --model lps --dt 5e-8 --grid mass_ratio=0.25:2:200 "
            "--grid voltage=40:120:200 --out sweep.nc --plot heat.png"
        ),
    )
    sw.add_argument("--grid", action="append", default=[], required=True, metavar="NAME=SPEC",
                    help="a sweep axis: NAME=A:B:N (numpy.linspace(A, B, N)), NAME=V1,V2,... or NAME=V; "
                         "repeat for more axes (dimensions in the given order)")
    sw.add_argument("--model", choices=IDM_MODELS, default="dps", help="lumped or FEM model (default: dps)")
    sw.add_argument("--n-elements", type=_positive_int, default=None, metavar="N",
                    help="FEM elements of the DPS (default: 4)")
    _add_method_arguments(sw)
    sw.add_argument("--retries", type=int, default=2, metavar="K",
                    help="rk4: retry a diverging point at dt/2, ..., dt/2^K before flagging it (default: 2)")
    sw.add_argument("--t-end", type=_positive_float, default=None, metavar="T",
                    help="simulated time [s] of every point (default: each point to the end of its own waveform; "
                         "one that cuts a sawtooth train short is refused)")
    sw.add_argument("--skip-cycles", type=_non_negative_int, default=STARTUP_CYCLES, metavar="K",
                    help="start-up cycles the steady-state metrics leave out (default: %(default)s, as characterize)")
    _add_case_arguments(sw)
    sw.add_argument("--threads", type=_positive_int, default=None, metavar="N",
                    help="worker threads (default: all cores)")
    sw.add_argument("--scheduler", default=None, metavar="ADDRESS",
                    help="run on a Dask cluster at ADDRESS (e.g. tcp://host:8786, from `dask scheduler`) "
                         "instead of the local thread pool")
    sw.add_argument("--out", default=None, metavar="FILE.nc|DIR.zarr",
                    help="save the results as netCDF (.nc, written at the end) or into a Zarr store (.zarr, written "
                         "block by block as they finish: for sweeps larger than memory)")
    sw.add_argument("--plot", default=None, metavar="FILE.png",
                    help="heat map (2 axes) or line plot (1 axis) of --metric; diverged points hatched grey")
    sw.add_argument("--metric", choices=(*METRICS, "dt_used", "steps"), default="final_position",
                    help="what --plot shows (default: final_position)")
    sw.add_argument("--no-progress", action="store_true", help="no progress bar")


def _add_diagnose_parser(sub: "argparse._SubParsersAction[argparse.ArgumentParser]") -> None:
    dp = sub.add_parser(
        "diagnose",
        help="diagnose a recorded case: locate the mismatch, name the missing physics, refit",
        description=(
            "Compare the recordings of CASE_DIR (format idm-recording/1: meta.json and one CSV per "
            "experiment) with their nominal model: calibrate the plausibly-off parameters, locate the "
            "residual, try every catalogue effect, and print the verdict (a catalogue id, two of them as "
            "'first+second', 'none', 'discovered' or 'unexplained') with the evidence. "
            "When no catalogue effect explains the residual, "
            "discovery infers the missing force from the data, finds its form in a library of terms, refits "
            "it, and names it when it stands ('discovered'). "
            "Given a measured rig data file instead (see docs/REALDATA.md), "
            "diagnose the rig's identified friction model against the rig-effect catalogue."
        ),
    )
    dp.add_argument("case_dir", metavar="CASE_DIR", help="the case directory, or a rig data file (.mat)")
    dp.add_argument("--json", default=None, metavar="OUT",
                    help="write the diagnosis as JSON (verdict, ranking, RMS figures [m], locations, ...)")
    dp.add_argument("--plots", default=None, metavar="DIR",
                    help="write the figures (fits per experiment, residual phases, ranking, RMS story) into DIR")
    dp.add_argument("--no-progress", action="store_true", help="no progress bar")
    dp.add_argument("--threads", type=_positive_int, default=None, metavar="N",
                    help="threads of the batch simulations (default: all cores)")
    dp.add_argument("--no-discover", action="store_true",
                    help="stop at the catalogue: no discovery of off-catalogue physics (verdict 'unexplained' "
                         "where no catalogue effect explains the residual)")


def _add_method_arguments(sp: argparse.ArgumentParser) -> None:
    """The integration method and its step or tolerances (simulate and sweep)."""
    sp.add_argument("--method", choices=METHODS, default="rk4",
                    help="fixed-step RK4 (the reference), adaptive Dormand-Prince 5(4), adaptive Rosenbrock "
                         "Rodas4 (implicit; fastest where friction is stiff), or auto (the adaptive setting "
                         "measured to stay within 1 nm of RK4) (default: rk4)")
    sp.add_argument("--dt", type=_positive_float, default=None, metavar="DT",
                    help="RK4 step [s] (default: 1e-8); adaptive methods need none (given, it is their first step)")
    sp.add_argument("--first-step", type=_positive_float, default=None, metavar="H",
                    help="adaptive methods' first trial step [s] (default: 1e-8)")
    sp.add_argument("--rtol", type=_positive_float, default=None,
                    help="adaptive relative tolerance (default: 1e-7; auto: 3e-7, the setting measured to keep "
                         "1 nm; given, auto honours it)")
    sp.add_argument("--atol", type=_positive_float, default=None,
                    help="adaptive absolute tolerance, in units of each state's scale (default: as --rtol)")


def _add_case_arguments(sp: argparse.ArgumentParser) -> None:
    """The waveform, parameter and hysteresis options shared by ``simulate`` and ``sweep``."""
    sp.add_argument("--waveform", choices=("triangle", "sawtooth"), default="triangle",
                    help="input voltage (default: triangle, the paper's single wave)")
    sp.add_argument("--amplitude", type=float, default=80.0, metavar="V", help="peak voltage [V] (default: 80)")
    sp.add_argument("--rise", type=_positive_float, default=0.5e-3, metavar="S", help="rise time [s] (default: 5e-4)")
    sp.add_argument("--fall", type=_positive_float, default=None, metavar="S",
                    help="triangle: fall time [s] (default: 9.5e-3)")
    sp.add_argument("--frequency", type=_positive_float, default=None, metavar="HZ",
                    help="sawtooth: frequency [Hz] (default: 100)")
    sp.add_argument("--cycles", type=_positive_int, default=None, metavar="N", help="sawtooth: periods (default: 3)")
    sp.add_argument("--direction", choices=("forward", "backward"), default=None,
                    help="sawtooth: step direction (default: forward)")
    sp.add_argument("--delay", type=float, default=0.0, metavar="S", help="0 V before the wave [s] (default: 0)")
    sp.add_argument("--voltage-csv", default=None, metavar="FILE",
                    help="drive with a measured voltage instead: a CSV of time [s] and voltage [V] columns "
                         "(a header line is skipped), piecewise linear between samples")
    sp.add_argument("--param", action="extend", nargs="+", default=[], metavar="NAME=VALUE",
                    help="override a parameter of Table 1 (SI units), e.g. --param m2=0.4 mu_k=0.45; "
                         "normal_force=auto restores (m1+m2+mPE) g")
    sp.add_argument("--effect", action="extend", nargs="+", default=[], metavar="NAME=VALUE",
                    help="switch on an effect parameter at a fixed value (SI units), e.g. --effect theta_rad=0.01; "
                         "names: " + ", ".join(f.name for f in dataclasses.fields(Effects)))
    sp.add_argument("--no-hysteresis", action="store_true", help="turn off the piezo (Bouc-Wen) hysteresis")


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


def _warn_past_samples(waveform: Waveform, t_end: float) -> None:
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


def _snap(t: float, dt: float) -> float:
    """``t`` rounded to a whole number of steps when it is within 1e-9 of one."""
    from .sweep_plan import snap_to_steps

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


# --- commands ------------------------------------------------------------------------------------


def cmd_simulate(a: argparse.Namespace) -> int:
    params = params_from_overrides(a.param)
    waveform = waveform_from_args(a)
    adaptive = methods.is_adaptive(a.method)
    if a.first_step is not None and not adaptive:
        raise CliError("--first-step is for the adaptive methods; RK4 takes --dt")
    dt = a.dt if a.dt is not None else 1e-8
    t_end = a.t_end if a.t_end is not None else waveform.duration
    _warn_past_samples(waveform, t_end)
    if not adaptive:
        t_end = _snap(t_end, dt)
    out = Path(a.out) if a.out else None
    # the figure draws every accepted step of an adaptive run and at most PLOT_INTERVAL of an
    # RK4 one (the step a run saves at is no measure of its dynamics: every 100th adaptive step
    # aliases a slip into a zig-zag); the CSV keeps every --save-every-th of those states
    plot_every = (1 if adaptive else _largest_divisor_at_most(a.save_every, max(1, round(PLOT_INTERVAL / dt)))
                  ) if a.plot else a.save_every
    t0 = time.perf_counter()
    full = _kept_on_interrupt(
        simulate, params, waveform, t_end=t_end, dt=None if adaptive else dt, model=a.model, n_elements=a.n_elements,
        save_every=plot_every, piezo_hysteresis=not a.no_hysteresis, effects=effects_from_overrides(a.effect),
        method=a.method, rtol=a.rtol, atol=a.atol,
        first_step=a.first_step if a.first_step is not None else a.dt if adaptive else None,
        progress=not a.no_progress and not adaptive and t_end / dt > PROGRESS_STEPS,
    )
    elapsed = time.perf_counter() - t0
    result = full.thinned(a.save_every // plot_every)
    label = structure_label(a.model, a.n_elements)
    t_last = float(result.t[-1])
    how = (f"dt = {dt:g} s" if not adaptive else
           f"{a.method}" + (f" ({result.method})" if result.method != a.method else "")
           + f", rtol = {result.rtol:g}, atol = {result.atol:g}")
    print(f"{label}, {waveform!r}, t_end = {t_end:g} s, {how}")
    if not result.complete:
        print(f"interrupted at t = {t_last:g} s: the trajectory up to there is kept")
    print(f"{'final' if result.complete else 'last'} position x1({t_last * 1e3:g} ms) = "
          f"{si(result.final_position, 'm', 7)}")
    if adaptive:
        print(f"run time {elapsed:.3f} s ({result.t.size} saved times, every {a.save_every} accepted steps)")
    else:
        steps = round(t_last / dt)
        print(f"run time {elapsed:.3f} s ({steps} steps, {steps / max(elapsed, 1e-9) / 1e6:.1f} M steps/s)")
    if out is not None:
        save_trajectory(result, out)
        print(f"wrote {out}")
    if a.plot:
        plot_result(full, Path(a.plot))
        every = "every accepted step" if plot_every == 1 and adaptive else f"every {plot_every * dt:g} s"
        print(f"wrote {a.plot} ({full.t.size} states: {every})")
    return 0 if result.complete else EXIT_INTERRUPTED


#: an RK4 run of more steps than this shows a progress bar (seconds and more)
PROGRESS_STEPS = 1e7


#: the coarsest spacing [s] of the states an RK4 run's figure draws (the PE's fastest modes of
#: the paper's device have periods of tens of µs)
PLOT_INTERVAL = 1e-6


def _largest_divisor_at_most(n: int, limit: int) -> int:
    """The largest divisor of ``n`` not above ``limit`` (so that thinning by the quotient keeps
    the states a run with ``save_every = n`` saves)."""
    return max(d for d in range(1, min(n, limit) + 1) if n % d == 0)


def cmd_sweep(a: argparse.Namespace) -> int:
    from .sweep import sweep

    grid = parse_grid(a.grid)
    if a.plot and len(grid) not in (1, 2):
        raise CliError(f"--plot draws sweeps of 1 or 2 axes; --grid gives {len(grid)} ({', '.join(grid)})")
    store = a.out if a.out and Path(a.out).suffix.lower() == ".zarr" else None
    params = params_from_overrides(a.param)
    waveform = waveform_from_args(a)
    if a.metric in (*STEADY_METRICS, "step_per_cycle") and not isinstance(waveform, Sawtooth):
        raise CliError(f"--metric {a.metric} is defined for sawtooth trains only (--waveform sawtooth); "
                       f"this sweep drives a {type(waveform).__name__.lower()}")
    if a.first_step is not None and not methods.is_adaptive(a.method):
        raise CliError("--first-step is for the adaptive methods; RK4 takes --dt")
    dt = a.dt if a.dt is not None else 1e-8
    t_end = a.t_end  # None: each point to its own waveform's end
    if t_end is not None:
        _warn_past_samples(waveform, t_end)
        if not methods.is_adaptive(a.method):
            t_end = _snap(t_end, dt)
    client = None
    if a.scheduler:
        from dask.distributed import Client

        client = Client(a.scheduler)  # type: ignore[no-untyped-call, unused-ignore]
    try:
        ds = _kept_on_interrupt(
            sweep, params, waveform, grid, t_end=t_end, dt=a.dt, model=a.model,
            n_elements=a.n_elements, method=a.method, rtol=a.rtol, atol=a.atol, first_step=a.first_step,
            retries=a.retries, effects=effects_from_overrides(a.effect), skip_cycles=a.skip_cycles,
            piezo_hysteresis=not a.no_hysteresis, progress=not a.no_progress, client=client,
            threads=a.threads, out=store,
        )
    finally:
        if client is not None:
            client.close()  # type: ignore[no-untyped-call, unused-ignore]
    print(sweep_summary(ds, a.metric))
    if store is not None:
        print(f"wrote {store} (Zarr, written block by block)")
    elif a.out:
        engine = write_sweep_netcdf(ds, Path(a.out))
        print(f"wrote {a.out} (netCDF, {engine} engine)")
    if a.plot:
        plot_sweep(ds, a.metric, Path(a.plot))
        print(f"wrote {a.plot}")
    return 0 if ds.attrs["complete"] else EXIT_INTERRUPTED


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
        report = write_figures(case, out, quick=a.quick, fig7_dt=2e-8 if a.quick else None, bar=bar,
                               threads=a.threads)
    elapsed = time.perf_counter() - t0
    print(paper.comparison_table(case.lps, case.dps))
    print()
    print(report.summary())
    print()
    print(f"wrote {out / 'paper_case.csv'} and " + ", ".join(p.name for p in report.paths.values()) + f" in {out}")
    print(f"total time {elapsed:.1f} s")
    return 0


def _values(spec: str, name: str, log: bool = False, positive: bool = False) -> np.ndarray:
    """``A:B:N`` (linear, or log-spaced with ``log``) or ``V1,V2,...`` as floats; ``positive``:
    every value must be > 0 (frequencies). The error names what is wrong, not only the form."""
    usage = "use A:B:N or V1,V2,..."
    if ":" in spec:
        parts = [t.strip() for t in spec.split(":")]
        if len(parts) != 3:
            raise CliError(f"--{name}: expected A:B:N, got {spec!r} ({usage})")
        try:
            a, b = float(parts[0]), float(parts[1])
        except ValueError:
            raise CliError(f"--{name}: cannot read {spec!r}: A and B must be numbers ({usage})") from None
        if not parts[2].isdigit() or int(parts[2]) < 1:
            raise CliError(f"--{name}: N must be a positive integer, got {parts[2]!r} in {spec!r}")
        if log and not (a > 0 and b > 0):
            zero = "A" if not a > 0 else "B"
            raise CliError(f"--{name} {spec}: the values are log-spaced, so A and B must be > 0 (got {zero} = "
                           f"{a if zero == 'A' else b:g}); "
                           f"e.g. {max(a, 1e-12) if a > 0 else 20:g}:{b if b > 0 else 1000:g}:{parts[2]}")
        values = np.geomspace(a, b, int(parts[2])) if log else np.linspace(a, b, int(parts[2]))
    else:
        try:
            values = np.array([float(x) for x in spec.split(",") if x.strip()])
        except ValueError:
            raise CliError(f"--{name}: cannot read {spec!r} ({usage})") from None
    if values.size == 0:
        raise CliError(f"--{name}: no values in {spec!r}")
    if not np.all(np.isfinite(values)):
        raise CliError(f"--{name}: values must be finite, got {spec!r}")
    if positive and not np.all(values > 0):
        raise CliError(f"--{name}: every value must be > 0, got {values[values <= 0][0]:g} in {spec!r}")
    return values


def cmd_characterize(a: argparse.Namespace) -> int:
    from .actuator import characterize, plot_characteristics

    params = params_from_overrides(a.param)
    t0 = time.perf_counter()
    ds = _kept_on_interrupt(
        characterize, params, model=a.model, n_elements=a.n_elements,
        frequencies=None if a.frequencies is None else _values(a.frequencies, "frequencies", log=True, positive=True),
        voltages=_values(a.voltages, "voltages"), step_voltages=_values(a.step_voltages, "step-voltages"),
        frequency=a.frequency, voltage=a.voltage, rise=a.rise, cycles=a.cycles, skip_cycles=a.skip_cycles,
        loads=a.loads, method=a.method, threads=a.threads, progress=not a.no_progress,
    )
    out = Path(a.out)
    if not ds.attrs.get("complete", 1):
        out.mkdir(parents=True, exist_ok=True)
        write_sweep_netcdf(ds, out / "characteristics.nc")
        print(f"interrupted: wrote {out / 'characteristics.nc'} with {ds.attrs['kept']} (no figures, no stall force)")
        return EXIT_INTERRUPTED
    paths = plot_characteristics(ds, out)
    write_sweep_netcdf(ds, out / "characteristics.nc")
    at = ds.attrs
    print(f"design point {at['design_frequency_Hz']:g} Hz, {at['design_voltage_V']:g} V ({at['model'].upper()}, "
          f"rise {at['rise_s']:g} s, {at['method']}): mean velocity {at['velocity_at_design_m_per_s'] * 1e3:.4g} mm/s, "
          f"stall force {at['stall_force_N']:.4g} N")
    print(f"steady state: the cycles after the first {at['skip_cycles']} of {at['cycles']} (--skip-cycles), "
          "as in sweep")
    print(f"wrote {out / 'characteristics.nc'} and " + ", ".join(p.name for p in paths) + f" in {out} "
          f"({time.perf_counter() - t0:.1f} s)")
    return 0


def cmd_rig_fit(a: argparse.Namespace) -> int:
    import json

    from .rigs import load, plot_rig_fit, rig_fit

    t0 = time.perf_counter()
    fit = rig_fit(load(a.path), simulate=not a.no_simulation)
    print(fit.report())
    if a.json:
        out = Path(a.json)
        out.parent.mkdir(parents=True, exist_ok=True)
        out.write_text(json.dumps(fit.to_dict(), indent=2) + "\n", encoding="utf-8")
        print(f"wrote {out}")
    if a.plots:
        paths = plot_rig_fit(fit, a.plots)
        print(f"wrote {', '.join(str(p) for p in paths)}")
    print(f"({time.perf_counter() - t0:.1f} s)")
    return 0


def cmd_diagnose(a: argparse.Namespace) -> int:
    import json

    from .diagnosis import diagnose, plot_diagnosis, text_report
    from .diagnosis.report import json_safe

    if Path(a.case_dir).is_file():  # a measured rig data file: the rig diagnosis
        from .rigs import diagnose_rig, load, plot_rig_diagnosis

        rd = diagnose_rig(load(a.case_dir))
        print(rd.report())
        if a.json:
            out = Path(a.json)
            out.parent.mkdir(parents=True, exist_ok=True)
            out.write_text(json.dumps(json_safe(rd.to_dict()), indent=2, allow_nan=False) + "\n", encoding="utf-8")
            print(f"wrote {out}")
        if a.plots:
            paths = plot_rig_diagnosis(rd, a.plots)
            print(f"wrote {len(paths)} figures in {a.plots}: " + ", ".join(p.name for p in paths))
        return 0
    d = _kept_on_interrupt(diagnose, a.case_dir, progress=not a.no_progress, threads=a.threads,
                           discover=not a.no_discover)
    print(text_report(d))
    if not d.complete:
        print("interrupted: the report above and the JSON (\"complete\": false) hold what was finished",
              file=sys.stderr)
    if a.json:
        out = Path(a.json)
        if out.parent != Path(""):
            out.parent.mkdir(parents=True, exist_ok=True)
        out.write_text(json.dumps(json_safe(d.to_dict()), indent=2, allow_nan=False) + "\n", encoding="utf-8")
        print(f"wrote {out}")
    if a.plots:  # what finished, also after Ctrl-C
        paths = plot_diagnosis(d, a.plots)
        if paths:
            kept = "" if d.complete else " (of what finished before the interrupt)"
            print(f"wrote {len(paths)} figures{kept} in {a.plots}: " + ", ".join(p.name for p in paths))
        else:
            print(f"no figures: the run was interrupted before the calibration finished ({a.plots} not written)")
    return 0 if d.complete else EXIT_INTERRUPTED


def _kept_on_interrupt(call: Any, *args: Any, **kwargs: Any) -> Any:
    """``call(*args, **kwargs)``, or after Ctrl-C what it had finished (the KeyboardInterrupt's
    ``partial``): the command writes that, says so and exits 130. A call stopped before it had
    anything to keep lets the interrupt travel on."""
    try:
        return call(*args, **kwargs)
    except KeyboardInterrupt as stop:
        partial = partial_result(stop)
        if partial is None:
            raise
        return partial


def _one_line(exc: BaseException) -> str:
    msg = exc.args[0] if exc.args and isinstance(exc.args[0], str) else str(exc)
    return " ".join(str(msg).split())


def _plain_warning(message: "Warning | str", category: type, filename: str, lineno: int, file: object = None,
                   line: Optional[str] = None) -> None:
    """Print a warning as one ``warning: ...`` line (not Python's file path and source line)."""
    print(f"warning: {' '.join(str(message).split())}", file=sys.stderr)


def _value_options(parser: argparse.ArgumentParser) -> set[str]:
    """Every option string (of the parser and its subcommands) that takes exactly one value."""
    found: set[str] = set()
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for sub in action.choices.values():
                found |= _value_options(sub)
        elif action.option_strings and action.nargs is None and action.const is None:
            found.update(action.option_strings)
    return found


def _negatives_as_values(parser: argparse.ArgumentParser, argv: Sequence[str]) -> list[str]:
    """``--dt -1e-8`` as ``--dt=-1e-8``: argparse takes a value such as -1e-8 (unlike -1 or
    -0.5) for an option and says "expected one argument"; joined, the option's own check names
    it ("must be a positive number")."""
    options = _value_options(parser)
    out: list[str] = []
    i = 0
    while i < len(argv):
        tok = argv[i]
        if tok in options and i + 1 < len(argv) and argv[i + 1].startswith("-"):
            try:
                float(argv[i + 1])
            except ValueError:
                pass
            else:
                out.append(f"{tok}={argv[i + 1]}")
                i += 2
                continue
        out.append(tok)
        i += 1
    return out


def main(argv: Optional[Sequence[str]] = None) -> int:
    """Entry point of ``idm-rs`` and ``python -m idm_rs``; returns the exit status."""
    import warnings

    parser = build_parser()
    a = parser.parse_args(_negatives_as_values(parser, list(sys.argv[1:] if argv is None else argv)))
    if a.command is None:
        parser.print_help()
        return EXIT_ERROR
    with warnings.catch_warnings():
        warnings.showwarning = _plain_warning
        return _run(a)


def _run(a: argparse.Namespace) -> int:
    try:
        check_outputs(a)
        if hasattr(a, "n_elements"):  # 4 for the DPS by default; the LPS has none (said if given)
            a.n_elements = options.elements(a.model, a.n_elements, say_ignored=True)
        command = {"reproduce": cmd_reproduce, "simulate": cmd_simulate, "sweep": cmd_sweep,
                   "characterize": cmd_characterize, "rig-fit": cmd_rig_fit, "diagnose": cmd_diagnose}[a.command]
        return command(a)
    except (ValueError, DivergenceError, OSError, MemoryError, ImportError) as exc:
        print(f"error: {_one_line(exc)}", file=sys.stderr)
        return EXIT_ERROR
    except KeyboardInterrupt:
        print("error: interrupted", file=sys.stderr)
        return EXIT_INTERRUPTED
