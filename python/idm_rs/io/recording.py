"""Reader for IDM lab recordings in the ``idm-recording/1`` format (``docs/RECORDINGS.md``).

A *case* is a directory holding ``meta.json`` and one CSV file (``t,voltage,x``) per experiment::

    rec = idm_rs.io.recording.load_case("recordings/dev/dev01")
    rec.nominal.params                  # idm_rs.Params of meta.json (normal_force as given)
    for e in rec.experiments:
        e.t, e.voltage, e.x             # numpy arrays [s], [V], [m]
        e.waveform                      # the idm_rs.Sawtooth that meta.json describes

Malformed input is refused with a :class:`RecordingError` (a ``ValueError``) whose message starts
with the file and, where there is one, the line (counting the header as line 1) and the column:
missing or extra columns, non-numeric or non-finite values, non-uniform time, a time axis not
starting at 0, ``x`` not in metres, and every way ``meta.json`` can disagree with a file (sample
rate, duration, amplitude, waveform shape, resolution, a file name that says otherwise).
"""

from __future__ import annotations

import json
import math
import re
from dataclasses import dataclass, field, fields
from pathlib import Path
from typing import Any, Iterator, Mapping, Optional, Sequence, Union, cast

import numpy as np
from numpy.typing import NDArray

from ..core.declarations import IDM_MODELS, Model, structure
from ..core.params import Params
from ..core.waveforms import Sampled, Sawtooth
from .recording_error import FORMAT_ID, HEADER, META, PathLike, RecordingError
from .recording_table import check_experiment, read_csv, sampled_from_table

__all__ = [
    "FORMAT_ID",
    "HEADER",
    "META",
    "Experiment",
    "Nominal",
    "Recording",
    "RecordingError",
    "load_case",
]


_NAME_PATTERN = re.compile(
    r"^exp\d+_(?P<direction>forward|backward)_(?P<amp>[0-9.]+)V_(?P<freq>[0-9.]+)Hz\.csv$"
)


#: parameters a recording's nominal may leave out (their default applies)
OPTIONAL_PARAMS = ("load_force",)


# --------------------------------------------------------------------------------------------
# data classes
# --------------------------------------------------------------------------------------------
@dataclass(frozen=True, eq=False)
class Experiment:
    """One CSV file of a case: the drive described in ``meta.json`` and the samples.

    ``t`` [s] (from 0, uniform step), ``voltage`` [V] (commanded), ``x`` [m] (measured main-body
    displacement, with an unknown constant offset, noise and quantisation)."""

    file: str  #: file name as listed in meta.json
    path: Path  #: full path of the CSV file
    amplitude_V: float
    frequency_Hz: float
    direction: str  #: "forward" or "backward" ("sampled" for a sampled drive)
    cycles: int
    rest_s: float  #: 0 V before the first cycle [s]
    edge_s: float  #: duration of the fast edge [s]
    t: NDArray[np.float64] = field(repr=False)
    voltage: NDArray[np.float64] = field(repr=False)
    x: NDArray[np.float64] = field(repr=False)
    #: how the rig stood on the bench: "normal", or "reversed" (turned end for end, 180 degrees
    #: about the vertical: forces fixed to the bench, gravity along a tilted guide, act the other
    #: way in the device's frame; the contact, the sensor and the drive turn with it)
    orientation: str = "normal"

    @property
    def is_reversed(self) -> bool:
        """True when the rig was turned end for end for this experiment (``orientation``)."""
        return self.orientation == "reversed"

    @property
    def is_sampled(self) -> bool:
        """True for a drive recorded sample by sample (``waveform: "sampled"``): the CSV's
        voltage column is the input, piecewise linear between samples."""
        return self.direction == "sampled"

    @property
    def waveform(self) -> Union[Sawtooth, Sampled]:
        """The drive: an ``idm_rs.Sawtooth`` (delay = rest_s, rise = edge_s), or for a sampled
        drive the recorded voltage as an ``idm_rs.Sampled``."""
        if self.is_sampled:
            return Sampled(self.t, self.voltage)
        return Sawtooth(
            amplitude=self.amplitude_V,
            frequency=self.frequency_Hz,
            cycles=self.cycles,
            rise=self.edge_s,
            direction=self.direction,  # type: ignore[arg-type]  # not "sampled" here
            delay=self.rest_s,
        )

    @property
    def duration(self) -> float:
        """End of the last cycle = time of the last sample [s]."""
        return self.rest_s + self.cycles / self.frequency_Hz

    @property
    def n_samples(self) -> int:
        return int(self.t.size)

    @property
    def name(self) -> str:
        """The file name without ``.csv``."""
        return Path(self.file).stem

    @property
    def rest_mask(self) -> NDArray[np.bool_]:
        """Samples before the first cycle starts (t < rest_s): the device is at rest there."""
        step = self.t[1] - self.t[0] if self.t.size > 1 else 0.0
        return self.t < self.rest_s - 0.5 * step

    def __len__(self) -> int:
        return self.n_samples


@dataclass(frozen=True)
class Nominal:
    """The model a case is compared with: structure and believed parameter values.

    ``n_elements`` is the number of PE elements for ``"dps"`` and 1 for ``"lps"`` (as in
    :class:`idm_rs.SimulationResult`)."""

    model: Model  #: "lps" or "dps"
    n_elements: int
    piezo_hysteresis: bool
    params: Params

    def simulate_kwargs(self) -> dict[str, Any]:
        """``model``, ``n_elements`` and ``piezo_hysteresis`` for :func:`idm_rs.simulate`."""
        return {"model": self.model, "n_elements": self.n_elements, "piezo_hysteresis": self.piezo_hysteresis}


@dataclass(frozen=True, eq=False)
class Recording:
    """A loaded case: the nominal model, the experiments and the sensor properties."""

    path: Path  #: the case directory
    name: str  #: the directory name
    nominal: Nominal
    experiments: list[Experiment]
    sample_rate_Hz: float
    resolution_m: float
    meta: dict[str, Any] = field(repr=False, default_factory=dict)  #: meta.json as read
    #: how the sensor reads, as the diagnosis learned it (its noise colour, nuisance columns and
    #: channel delay: ``diagnosis.measurement.Measurement``); None (as loaded): white noise
    measurement: Any = field(repr=False, default=None)

    @classmethod
    def load(cls, path: PathLike) -> "Recording":
        """Read and validate a case directory (raises :class:`RecordingError`)."""
        return load_case(path)

    @property
    def noise_rms_m(self) -> Optional[float]:
        """The sensor noise RMS [m] given in meta.json (``sensor.noise_rms_m``), if any."""
        v = self.meta.get("sensor", {}).get("noise_rms_m")
        return None if v is None else float(v)

    @property
    def sample_step(self) -> float:
        """1 / sample_rate_Hz [s]."""
        return 1.0 / self.sample_rate_Hz

    @property
    def n_samples(self) -> int:
        """Samples over all experiments."""
        return sum(e.n_samples for e in self.experiments)

    def __len__(self) -> int:
        return len(self.experiments)

    def __iter__(self) -> Iterator[Experiment]:
        return iter(self.experiments)

    def __getitem__(self, key: Union[int, str]) -> Experiment:
        """An experiment by index, file name or file stem."""
        if isinstance(key, str):
            for e in self.experiments:
                if key in (e.file, e.name):
                    return e
            raise KeyError(f"no experiment {key!r} in {self.path}; files: {[e.file for e in self.experiments]}")
        return self.experiments[key]


# --------------------------------------------------------------------------------------------
# meta.json
# --------------------------------------------------------------------------------------------
def _require(obj: Any, keys: Sequence[str], meta: Path, where: str) -> None:
    if not isinstance(obj, dict):
        raise RecordingError(meta, f"must be a JSON object, got {type(obj).__name__}", column=where or None)
    missing = [k for k in keys if k not in obj]
    if missing:
        prefix = f"{where}." if where else ""
        raise RecordingError(
            meta,
            f"missing key{'s' if len(missing) > 1 else ''} "
            + ", ".join(f"'{prefix}{k}'" for k in missing),
        )


def _number(obj: Mapping[str, Any], key: str, meta: Path, where: str, *, positive: bool = False,
            non_negative: bool = False) -> float:
    v = obj[key]
    path = f"{where}.{key}"
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        raise RecordingError(meta, f"must be a number, got {v!r}", column=path)
    v = float(v)
    if not math.isfinite(v):
        raise RecordingError(meta, f"must be finite, got {v}", column=path)
    if positive and v <= 0:
        raise RecordingError(meta, f"must be positive, got {v}", column=path)
    if non_negative and v < 0:
        raise RecordingError(meta, f"must be non-negative, got {v}", column=path)
    return v


def _read_meta(case: Path) -> dict[str, Any]:
    meta = case / META
    if not case.is_dir():
        raise RecordingError(case, "not a directory (a case is a directory with meta.json and CSV files)")
    if not meta.is_file():
        raise RecordingError(meta, f"missing: a case directory must hold {META}")
    text = meta.read_text(encoding="utf-8")
    try:
        data = json.loads(text)
    except json.JSONDecodeError as exc:
        raise RecordingError(meta, f"invalid JSON (column {exc.colno}): {exc.msg}", line=exc.lineno) from None
    if not isinstance(data, dict):
        raise RecordingError(meta, f"must hold a JSON object, got {type(data).__name__}")
    if "format" not in data:
        raise RecordingError(meta, f"missing key 'format' (expected \"{FORMAT_ID}\")")
    if data["format"] != FORMAT_ID:
        raise RecordingError(meta, f"unsupported format {data['format']!r}; this reader reads \"{FORMAT_ID}\"",
                             column="format")
    _require(data, ["nominal", "experiments", "sensor"], meta, "")
    return data


def _parse_nominal(nom: Any, meta: Path) -> Nominal:
    _require(nom, ["model", "piezo_hysteresis", "params"], meta, "nominal")
    model = nom["model"]
    if model not in IDM_MODELS:
        raise RecordingError(meta, f"must be one of {', '.join(repr(m) for m in IDM_MODELS)}, got {model!r}",
                             column="nominal.model")
    if structure(model).elements:
        if "n_elements" not in nom:
            raise RecordingError(meta, "missing key 'nominal.n_elements' (required for model \"dps\")")
        n = nom["n_elements"]
        if isinstance(n, bool) or not isinstance(n, int) or n < 1:
            raise RecordingError(meta, f"must be a positive integer, got {n!r}", column="nominal.n_elements")
    else:
        n = 1
    hyst = nom["piezo_hysteresis"]
    if not isinstance(hyst, bool):
        raise RecordingError(meta, f"must be true or false, got {hyst!r}", column="nominal.piezo_hysteresis")
    raw = nom["params"]
    if not isinstance(raw, dict):
        raise RecordingError(meta, f"must be a JSON object, got {type(raw).__name__}", column="nominal.params")
    known = [f.name for f in fields(Params)]
    unknown = sorted(set(raw) - set(known))
    if unknown:
        raise RecordingError(
            meta,
            f"unknown parameter name{'s' if len(unknown) > 1 else ''} {', '.join(repr(u) for u in unknown)}; "
            f"known: {', '.join(known)}",
            column="nominal.params",
        )
    # the operating load is not part of a device's nominal description: absent means none
    missing = [k for k in known if k not in raw and k not in OPTIONAL_PARAMS]
    if missing:
        raise RecordingError(
            meta, f"missing parameter{'s' if len(missing) > 1 else ''} {', '.join(repr(m) for m in missing)}",
            column="nominal.params",
        )
    values = {k: _number(raw, k, meta, "nominal.params") for k in known if k in raw}
    try:
        params = Params(**values)
    except (TypeError, ValueError) as exc:
        raise RecordingError(meta, str(exc), column="nominal.params") from None
    return Nominal(model=model, n_elements=int(n), piezo_hysteresis=hyst, params=params)


_EXPERIMENT_KEYS = ("file", "waveform", "amplitude_V", "frequency_Hz", "direction", "cycles", "rest_s", "edge_s")


#: how a rig may stand on the bench (an experiment's optional ``orientation``)
ORIENTATIONS = ("normal", "reversed")


def _parse_orientation(e: dict[str, Any], where: str, meta: Path) -> str:
    """An experiment's optional ``orientation`` ("normal" when absent)."""
    value = e.get("orientation", "normal")
    if value not in ORIENTATIONS:
        raise RecordingError(meta, f"must be \"normal\" or \"reversed\" (the rig turned end for end on the bench), "
                             f"got {value!r}", column=f"{where}.orientation")
    return cast(str, value)  # one of ORIENTATIONS


def _parse_experiment_meta(e: Any, i: int, meta: Path) -> dict[str, Any]:
    where = f"experiments[{i}]"
    if isinstance(e, dict) and e.get("waveform") == "sampled":
        return dict(_parse_sampled_meta(e, i, meta), orientation=_parse_orientation(e, where, meta))
    _require(e, _EXPERIMENT_KEYS, meta, where)
    name = e["file"]
    if not isinstance(name, str) or not name or Path(name).name != name or name in (".", ".."):
        raise RecordingError(meta, f"must be a plain file name in the case directory, got {name!r}",
                             column=f"{where}.file")
    if e["waveform"] != "sawtooth":
        raise RecordingError(meta, f"unsupported waveform {e['waveform']!r} (\"sawtooth\" or \"sampled\")",
                             column=f"{where}.waveform")
    if e["direction"] not in ("forward", "backward"):
        raise RecordingError(meta, f"must be \"forward\" or \"backward\", got {e['direction']!r}",
                             column=f"{where}.direction")
    cycles = e["cycles"]
    if isinstance(cycles, bool) or not isinstance(cycles, (int, float)) or cycles != int(cycles) or cycles < 1:
        raise RecordingError(meta, f"must be a positive integer, got {cycles!r}", column=f"{where}.cycles")
    out: dict[str, Any] = {
        "file": name,
        "amplitude_V": _number(e, "amplitude_V", meta, where),
        "frequency_Hz": _number(e, "frequency_Hz", meta, where, positive=True),
        "direction": e["direction"],
        "cycles": int(cycles),
        "rest_s": _number(e, "rest_s", meta, where, non_negative=True),
        "edge_s": _number(e, "edge_s", meta, where, positive=True),
        "orientation": _parse_orientation(e, where, meta),
    }
    if out["edge_s"] >= 1.0 / out["frequency_Hz"]:
        raise RecordingError(
            meta, f"edge_s = {out['edge_s']} s must be shorter than the period 1/frequency_Hz = "
            f"{1.0 / out['frequency_Hz']} s", column=f"{where}.edge_s",
        )
    m = _NAME_PATTERN.match(name)
    if m is not None:  # a name in the usual pattern must agree with its meta entry
        said: dict[str, Any] = {"direction": m["direction"], "amplitude_V": float(m["amp"]),
                                "frequency_Hz": float(m["freq"])}
        for key, value in said.items():
            if (value != out[key]) if key == "direction" else not math.isclose(value, out[key], rel_tol=1e-9):
                raise RecordingError(
                    meta, f"disagrees with the file name {name!r}: meta.json says {key} = {e[key]!r}, "
                    f"the name says {value!r}", column=f"{where}.{key}",
                )
    return out


def _parse_sampled_meta(e: dict[str, Any], i: int, meta: Path) -> dict[str, Any]:
    """A sampled drive: the CSV's voltage column is the input. Keys: ``file``, ``waveform``
    and, optionally, ``rest_s`` (how long the device rests before the drive starts [s];
    default: until the voltage first leaves 0). The amplitude and the record's duration come
    from the file."""
    where = f"experiments[{i}]"
    _require(e, ["file", "waveform"], meta, where)
    name = e["file"]
    if not isinstance(name, str) or not name or Path(name).name != name or name in (".", ".."):
        raise RecordingError(meta, f"must be a plain file name in the case directory, got {name!r}",
                             column=f"{where}.file")
    rest = _number(e, "rest_s", meta, where, non_negative=True) if "rest_s" in e else math.nan
    return {"file": name, "amplitude_V": math.nan, "frequency_Hz": math.nan, "direction": "sampled", "cycles": 1,
            "rest_s": rest, "edge_s": math.nan}


# --------------------------------------------------------------------------------------------
# CSV files
# --------------------------------------------------------------------------------------------
def load_case(path: PathLike) -> Recording:
    """Read and validate the case directory ``path`` (``meta.json`` + CSV files).

    Parameters
    ----------
    path : path
        A case directory in the ``idm-recording/1`` format (docs/RECORDINGS.md).

    Returns
    -------
    Recording
        The nominal model, the sensor (sample rate [Hz], resolution [m]) and the experiments
        (time [s], voltage [V], position [m]).

    Raises
    ------
    RecordingError
        The file, line and column of the first problem found.

    Examples
    --------
    >>> rec = idm_rs.load_case("path/to/case")   # doctest: +SKIP
    >>> [e.name for e in rec.experiments]         # doctest: +SKIP
    """
    case = Path(path)
    meta_path = case / META
    data = _read_meta(case)
    nominal = _parse_nominal(data["nominal"], meta_path)

    sensor = data["sensor"]
    _require(sensor, ["sample_rate_Hz", "resolution_m"], meta_path, "sensor")
    sample_rate = _number(sensor, "sample_rate_Hz", meta_path, "sensor", positive=True)
    resolution = _number(sensor, "resolution_m", meta_path, "sensor", non_negative=True)
    if "noise_rms_m" in sensor:  # optional: the sensor's noise, when the user knows it
        _number(sensor, "noise_rms_m", meta_path, "sensor", positive=True)

    exps_meta = data["experiments"]
    if not isinstance(exps_meta, list) or not exps_meta:
        raise RecordingError(meta_path, "must be a non-empty list of experiments", column="experiments")
    parsed = [_parse_experiment_meta(e, i, meta_path) for i, e in enumerate(exps_meta)]
    seen: dict[str, int] = {}
    for i, e in enumerate(parsed):
        if e["file"] in seen:
            raise RecordingError(
                meta_path, f"file {e['file']!r} is listed twice (experiments[{seen[e['file']]}] and [{i}])",
                column=f"experiments[{i}].file",
            )
        seen[e["file"]] = i

    experiments = []
    for i, e in enumerate(parsed):
        csv = case / e["file"]
        if not csv.is_file():
            raise RecordingError(csv, f"missing: listed in {META} (experiments[{i}].file) but not in {case}")
        table = read_csv(csv)
        check_experiment(table, csv, meta_path, f"experiments[{i}]", e, sample_rate, resolution)
        if e["direction"] == "sampled":
            e = sampled_from_table(e, table)
        experiments.append(
            Experiment(
                path=csv,
                t=np.ascontiguousarray(table[:, 0]),
                voltage=np.ascontiguousarray(table[:, 1]),
                x=np.ascontiguousarray(table[:, 2]),
                **e,
            )
        )
    return Recording(
        path=case,
        name=case.resolve().name,
        nominal=nominal,
        experiments=experiments,
        sample_rate_Hz=sample_rate,
        resolution_m=resolution,
        meta=data,
    )
