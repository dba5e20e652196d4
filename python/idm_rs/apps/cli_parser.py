"""The ``idm-rs`` command line's arguments: one parser builder per command, the options the
commands share (method, a recorded case's), and the argument types that refuse a bad value
with the option's name."""

from __future__ import annotations

import argparse
import dataclasses
from typing import TYPE_CHECKING, Callable

from ..core.declarations import IDM_MODELS
from ..core.effects import Effects
from ..core.engine import __version__
from ..core.methods import METHODS
from ..core.waveforms import STARTUP_CYCLES
from ..sweeps.plan import METRICS
from .cli_files import CSV_COLUMNS

if TYPE_CHECKING:
    pass


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
