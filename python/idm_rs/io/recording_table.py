"""One experiment's CSV table read and checked against ``meta.json``: the header, numbers that
parse and are finite, a uniform time axis from 0, x in metres, and the drive, duration,
resolution and sample rate meta.json describes. Every refusal is a :class:`RecordingError`
naming the file, line and column."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any, Literal

import numpy as np
from numpy.typing import NDArray

from ..core.waveforms import Sawtooth, voltage_at
from .recording_error import HEADER, RecordingError

#: |t_k - k/sample_rate| tolerance, as a fraction of the step (times are written exactly)
TIME_TOLERANCE = 1e-2
#: largest |x| [m] accepted as a displacement in metres (the format's scale is µm)
MAX_ABS_X_M = 1e-3
#: the voltage peak may differ from amplitude_V by at most this fraction (or 1 V) ...
PEAK_TOLERANCE = 0.2
#: ... and every sample from the sawtooth of meta.json by at most this fraction of amplitude_V
WAVEFORM_TOLERANCE = 1e-2
#: x / resolution_m may differ from an integer by at most this much (10 significant digits)
QUANTUM_TOLERANCE = 0.05


def _check_header(line: str, csv: Path) -> None:
    clean = line.rstrip("\r\n").lstrip("\ufeff")  # a byte-order mark and CRLF are tolerated
    expected = ",".join(HEADER)
    if clean == expected:
        return
    got = [c.strip() for c in clean.split(",")]
    if tuple(got) == HEADER:
        raise RecordingError(csv, f"header must be exactly '{expected}' (no spaces), got {line.rstrip()!r}", line=1)
    if all(_is_float(c) for c in got if c):
        raise RecordingError(csv, f"no header: the first line must be '{expected}', got {line.rstrip()!r}", line=1)
    missing = [c for c in HEADER if c not in got]
    extra = [c for c in got if c not in HEADER]
    parts = []
    if missing:
        parts.append(f"missing column{'s' if len(missing) > 1 else ''} " + ", ".join(f"'{c}'" for c in missing))
    if extra:
        parts.append(
            f"extra column{'s' if len(extra) > 1 else ''} "
            + ", ".join(f"'{c}' (column {got.index(c) + 1})" for c in extra)
        )
    if not parts:
        parts.append(f"columns in the wrong order or repeated ({', '.join(got)})")
    raise RecordingError(csv, f"header must be exactly '{expected}': {'; '.join(parts)}", line=1)


def _is_float(s: str) -> bool:
    try:
        float(s)
    except ValueError:
        return False
    return True


def _locate_parse_error(lines: list[str], csv: Path) -> RecordingError:
    """The first line/column that np.loadtxt could not read (slow path, only on failure)."""
    for k, line in enumerate(lines[1:], start=2):
        cells = line.rstrip("\r").split(",")
        if line.strip() == "":
            return RecordingError(csv, "empty line", line=k)
        if len(cells) != len(HEADER):
            return RecordingError(
                csv, f"{len(cells)} value{'s' if len(cells) != 1 else ''}, expected {len(HEADER)} "
                f"({','.join(HEADER)}): {line.rstrip()!r}", line=k,
            )
        for name, cell in zip(HEADER, cells):
            if not _is_float(cell):
                return RecordingError(csv, f"not a number: {cell!r}", line=k, column=name)
    return RecordingError(csv, "could not be read as numbers")


def read_csv(csv: Path) -> NDArray[np.float64]:
    try:
        text = csv.read_text(encoding="utf-8")
    except UnicodeDecodeError as exc:
        raise RecordingError(csv, f"not a UTF-8 text file ({exc.reason} at byte {exc.start})") from None
    lines = text.split("\n")
    while lines and lines[-1].strip() == "":  # trailing newline(s)
        lines.pop()
    if not lines:
        raise RecordingError(csv, f"empty file (expected the header '{','.join(HEADER)}' and samples)")
    _check_header(lines[0], csv)
    if len(lines) < 3:
        raise RecordingError(csv, f"{len(lines) - 1} sample(s); a recording needs at least 2")
    try:
        data = np.loadtxt(lines[1:], delimiter=",", comments=None, dtype=float, ndmin=2)
    except ValueError:
        raise _locate_parse_error(lines, csv) from None
    if data.shape != (len(lines) - 1, len(HEADER)):  # e.g. a blank line skipped by loadtxt
        raise _locate_parse_error(lines, csv)
    finite = np.isfinite(data)
    if not finite.all():
        row, col = np.argwhere(~finite)[0]
        raw = lines[row + 1].rstrip("\r").split(",")[col]
        raise RecordingError(csv, f"value is not finite: {raw!r}", line=int(row) + 2, column=HEADER[col])
    return data


def check_experiment(
    data: NDArray[np.float64], csv: Path, meta: Path, where: str, e: dict[str, Any],
    sample_rate: float, resolution: float,
) -> None:
    t, v, x = data[:, 0], data[:, 1], data[:, 2]
    n = t.size
    step = 1.0 / sample_rate
    tol = TIME_TOLERANCE * step
    if abs(t[0]) > tol:
        raise RecordingError(csv, f"time must start at 0, got t = {float(t[0])!r} s", line=2, column="t")
    d = np.diff(t)
    if np.any(d <= 0):
        k = int(np.flatnonzero(d <= 0)[0])
        raise RecordingError(
            csv, f"time does not increase: t = {float(t[k + 1])!r} s after t = {float(t[k])!r} s", line=k + 3,
            column="t",
        )
    file_step = float(np.median(d))
    if abs(file_step - step) > tol:
        hint = ""
        for unit, factor in (("ms", 1e3), ("µs", 1e6)):
            if abs(file_step / factor - step) <= tol:
                hint = f" (or t is in {unit}, not s)"
        raise RecordingError(
            csv, f"time step is {file_step:.6g} s ({1 / file_step:.6g} Hz) but {meta.name} gives "
            f"sensor.sample_rate_Hz = {sample_rate:g} (step {step:.6g} s): {meta.name} disagrees with the "
            f"file{hint}", line=3, column="t",
        )
    bad = np.abs(d - step) > tol
    if bad.any():
        k = int(np.flatnonzero(bad)[0])
        raise RecordingError(
            csv, f"non-uniform time step: t jumps from {float(t[k])!r} s to {float(t[k + 1])!r} s "
            f"(step {d[k]:.6g} s, expected {step:.6g} s = 1/sensor.sample_rate_Hz)", line=k + 3, column="t",
        )
    drift = np.abs(t - np.arange(n) * step) > tol
    if drift.any():
        k = int(np.flatnonzero(drift)[0])
        raise RecordingError(
            csv, f"non-uniform time: t = {float(t[k])!r} s but sample {k} should be at {k * step:.10g} s "
            f"(step {step:.6g} s = 1/sensor.sample_rate_Hz)", line=k + 2, column="t",
        )
    sampled = e["direction"] == "sampled"
    duration = e["rest_s"] + e["cycles"] / e["frequency_Hz"]
    if not sampled and abs(t[-1] - duration) > 0.5 * step:
        raise RecordingError(
            csv, f"last sample at t = {float(t[-1])!r} s, but {meta.name} ({where}) describes rest_s + cycles / "
            f"frequency_Hz = {e['rest_s']:g} + {e['cycles']} / {e['frequency_Hz']:g} = {duration:.10g} s: "
            f"{meta.name} disagrees with the file", line=n + 1, column="t",
        )
    big = np.abs(x) > MAX_ABS_X_M
    if big.any():
        k = int(np.flatnonzero(big)[0])
        raise RecordingError(
            csv, f"x = {float(x[k]):.10g} looks like it is not in metres (|x| > {MAX_ABS_X_M:g} m; displacements of "
            f"an IDM recording are µm-scale: was it written in µm or nm?)", line=k + 2, column="x",
        )
    if sampled:
        if not np.all(np.isfinite(v)):
            k = int(np.flatnonzero(~np.isfinite(v))[0])
            raise RecordingError(csv, "voltage must be finite (it is the drive)", line=k + 2, column="voltage")
        return
    amp = e["amplitude_V"]
    peak_k = int(np.argmax(np.abs(v)))
    peak = float(v[peak_k])
    if abs(peak - amp) > max(PEAK_TOLERANCE * abs(amp), 1.0):
        raise RecordingError(
            csv, f"voltage peaks at {peak:g} V but {meta.name} gives amplitude_V = {amp:g} ({where}): "
            f"{meta.name} disagrees with the file (or the voltage is not in V)", line=peak_k + 2, column="voltage",
        )
    wave = Sawtooth(amp, e["frequency_Hz"], e["cycles"], e["edge_s"], e["direction"], e["rest_s"])
    expected = voltage_at(wave, np.arange(n) * step)
    off = np.abs(v - expected) > max(WAVEFORM_TOLERANCE * abs(amp), 1e-6)
    if off.any():
        k = int(np.flatnonzero(off)[0])
        hint = ""
        other: Literal["forward", "backward"] = "backward" if e["direction"] == "forward" else "forward"
        alt = voltage_at(Sawtooth(amp, e["frequency_Hz"], e["cycles"], e["edge_s"], other, e["rest_s"]),
                         np.arange(n) * step)
        if np.all(np.abs(v - alt) <= max(WAVEFORM_TOLERANCE * abs(amp), 1e-6)):
            hint = f"; the file holds a {other} sawtooth"
        raise RecordingError(
            csv, f"voltage {v[k]:.10g} V differs from the sawtooth {meta.name} describes ({where}: "
            f"{e['direction']}, {amp:g} V, {e['frequency_Hz']:g} Hz, {e['cycles']} cycles, rest {e['rest_s']:g} s, "
            f"edge {e['edge_s']:g} s), which is {expected[k]:.10g} V at t = {float(t[k])!r} s{hint}: "
            f"{meta.name} disagrees with the file", line=k + 2, column="voltage",
        )
    if resolution > 0:
        q = x / resolution
        # 10 significant digits: |x| up to 1e-3 m at 1e-10 m steps still rounds to < 1e-2 of a step
        bad_q = np.abs(q - np.round(q)) > QUANTUM_TOLERANCE
        if bad_q.any():
            k = int(np.flatnonzero(bad_q)[0])
            raise RecordingError(
                csv, f"x = {float(x[k])!r} m is not a multiple of sensor.resolution_m = {resolution:g} m: "
                f"{meta.name} disagrees with the file", line=k + 2, column="x",
            )


# --------------------------------------------------------------------------------------------
# the case
# --------------------------------------------------------------------------------------------
def sampled_from_table(e: dict[str, Any], table: NDArray[np.float64]) -> dict[str, Any]:
    """A sampled experiment's amplitude (peak |V|), rest (until V first leaves 0, unless given)
    and one "cycle" spanning the drive to the last sample (so duration = the record's end)."""
    t, v = table[:, 0], table[:, 1]
    moving = np.flatnonzero(np.abs(v) > 0)
    rest = e["rest_s"]
    if not math.isfinite(rest):
        rest = float(t[moving[0]]) if moving.size else 0.0
    span = float(t[-1]) - rest
    return {**e, "amplitude_V": float(np.max(np.abs(v))), "rest_s": rest,
            "frequency_Hz": 1.0 / span if span > 0 else math.inf}
