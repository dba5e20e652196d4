"""The ``idm-rs`` command line: ``idm-rs reproduce`` (the paper's Figs. 6 and 7),
``idm-rs simulate`` (one case), ``idm-rs sweep`` (a grid of cases through the batch engine,
saved as netCDF with a heat map) and ``idm-rs diagnose`` (a recorded case against its nominal
model: report, JSON and plots). ``python -m idm_rs`` is the same command.

Errors in the input (a bad parameter, a step that does not fit the waveform, a run that
diverges) print one ``error: ...`` line to stderr and exit with status 2.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path
from typing import TYPE_CHECKING, Any, Optional, Sequence

import numpy as np

from ..core import methods, options
from ..core.declarations import structure_label
from ..core.interrupted import partial_result
from ..core.simulation import DivergenceError, simulate
from ..core.units import si
from ..core.waveforms import Sawtooth
from ..sweeps.plan import STEADY_METRICS
from .cli_figures import plot_result, plot_sweep
from .cli_files import (
    CliError,
    effects_from_overrides,
    paper_case_csv,
    params_from_overrides,
    parse_grid,
    save_trajectory,
    snap,
    sweep_summary,
    warn_past_samples,
    waveform_from_args,
    write_sweep_netcdf,
)
from .cli_interrupts import interrupts_not_swallowed
from .cli_outputs import check_outputs
from .cli_parser import build_parser

if TYPE_CHECKING:
    pass

EXIT_ERROR = 2
#: every command stopped by Ctrl-C exits with this (128 + SIGINT), after saying what it kept
EXIT_INTERRUPTED = 130





# --- commands ------------------------------------------------------------------------------------


def cmd_simulate(a: argparse.Namespace) -> int:
    params = params_from_overrides(a.param)
    waveform = waveform_from_args(a)
    adaptive = methods.is_adaptive(a.method)
    if a.first_step is not None and not adaptive:
        raise CliError("--first-step is for the adaptive methods; RK4 takes --dt")
    dt = a.dt if a.dt is not None else 1e-8
    t_end = a.t_end if a.t_end is not None else waveform.duration
    warn_past_samples(waveform, t_end)
    if not adaptive:
        t_end = snap(t_end, dt)
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
    from ..sweeps.sweep import sweep

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
        warn_past_samples(waveform, t_end)
        if not methods.is_adaptive(a.method):
            t_end = snap(t_end, dt)
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

    from ..rigs import load, plot_rig_fit, rig_fit

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

    from ..diagnosis import diagnose, plot_diagnosis, text_report
    from ..diagnosis.report import json_safe

    if Path(a.case_dir).is_file():  # a measured rig data file: the rig diagnosis
        from ..rigs import diagnose_rig, load, plot_rig_diagnosis

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
    with warnings.catch_warnings(), interrupts_not_swallowed():
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
