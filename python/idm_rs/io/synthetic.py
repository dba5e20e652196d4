"""Synthetic recordings: simulate a "true" device and write it as an ``idm-recording/1`` case.

The case holds what a lab would record: the commanded sawtooth, and the sensor reading of the
true device (true parameters, structure and effects) with a per-file offset, white Gaussian
noise and quantisation. ``meta.json`` holds the *nominal* model, which may differ from the truth:
that is how test cases with known answers (mis-set parameters, missing physics) are made::

    p = idm_rs.Params(normal_force=6.90624)
    case = make_case(tmp / "case", nominal_params=p, effects=idm_rs.Effects(k_ground=5e3))
    rec = idm_rs.io.recording.load_case(case)
"""

from __future__ import annotations

import dataclasses
import json
import math
from dataclasses import fields
from pathlib import Path
from typing import Any, Mapping, Optional, Sequence, Union

import numpy as np

from ..core.declarations import Model, structure
from ..core.effects import Effects, oriented
from ..core.params import Params
from ..core.simulation import simulate
from ..core.waveforms import Sampled, Sawtooth, voltage_at
from .recording import FORMAT_ID, HEADER, META, ORIENTATIONS
from .sensor_noise import SensorNoise

__all__ = ["DEFAULT_EXPERIMENTS", "make_case"]

#: a small, fast default: two 2-cycle bursts at 200 Hz, one each way (12 ms of motion each)
DEFAULT_EXPERIMENTS: tuple[dict[str, Any], ...] = (
    {"amplitude_V": 80, "frequency_Hz": 200, "direction": "forward", "cycles": 2},
    {"amplitude_V": 60, "frequency_Hz": 200, "direction": "backward", "cycles": 2},
)
#: offsets are drawn uniformly in ±this [m] unless given
OFFSET_RANGE_M = 2e-6


def _fmt_number(v: float) -> Union[int, float]:
    """Integers as JSON integers (80, not 80.0), as in docs/RECORDINGS.md."""
    return int(v) if float(v).is_integer() and abs(v) < 2**53 else float(v)


def experiment_file_name(index: int, direction: str, amplitude_V: float, frequency_Hz: float) -> str:
    """``exp{index}_{direction}_{A}V_{f}Hz.csv`` (index from 1)."""
    return f"exp{index}_{direction}_{_fmt_number(amplitude_V):g}V_{_fmt_number(frequency_Hz):g}Hz.csv"


def make_case(
    directory: Union[str, Path],
    *,
    nominal_params: Params,
    true_params: Optional[Params] = None,
    model: Model = "lps",
    n_elements: int = 4,
    piezo_hysteresis: bool = False,
    true_model: Optional[Model] = None,
    true_n_elements: Optional[int] = None,
    true_piezo_hysteresis: Optional[bool] = None,
    effects: Optional[Effects] = None,
    experiments: Optional[Sequence[Mapping[str, Any]]] = None,
    noise_rms: float = 1.5e-9,
    resolution: Optional[float] = 2.5e-10,
    offsets: Optional[Sequence[float]] = None,
    seed: int = 0,
    dt: float = 1e-8,
    rest_s: float = 0.002,
    edge_s: float = 0.0005,
    sample_rate_Hz: float = 1e5,
    write_noise_rms: bool = False,
    noise: Optional[SensorNoise] = None,
) -> Path:
    """Simulate the true device and write a case directory; returns ``Path(directory)``.

    ``nominal_params`` / ``model`` / ``n_elements`` / ``piezo_hysteresis`` go to ``meta.json``
    (``normal_force`` written explicitly, resolved from the masses when ``None``). The device
    simulated is ``true_params`` / ``true_model`` / ``true_n_elements`` /
    ``true_piezo_hysteresis`` (each defaulting to the nominal one) with ``effects``.

    ``experiments``: dicts with ``amplitude_V``, ``frequency_Hz``, ``direction``, ``cycles`` and
    optionally ``rest_s``, ``edge_s``, ``file`` and ``orientation`` ("reversed": the rig turned end
    for end, so bench-fixed effects such as an incline act the other way; written to meta.json)
    (default :data:`DEFAULT_EXPERIMENTS`); or,
    for a drive recorded sample by sample, ``{"sampled": idm_rs.Sampled(t, V)}`` (its times on
    the sample grid, from 0; optionally ``file``), written as ``waveform: "sampled"``.
    ``write_noise_rms`` puts the noise RMS in meta.json (``sensor.noise_rms_m``).
    ``noise`` (an :class:`idm_rs.io.sensor_noise.SensorNoise`) replaces the white noise of
    ``noise_rms`` with what a lab's reading carries: coloured noise, hum, spikes, a drifting zero,
    a late displacement channel (the device is driven that much later than the voltage column
    says, the delay rounded to ``dt``; its motion after the file's end is not recorded).
    Each file's ``x`` is the simulated ``reading`` (sampled at ``sample_rate_Hz``, integrated at
    step ``dt``) + an offset (``offsets[i]``, or uniform in ±2 µm) + white Gaussian noise of RMS
    ``noise_rms`` [m], rounded to multiples of ``resolution`` [m] (``None`` or 0: no rounding).
    Everything random comes from ``numpy.random.default_rng(seed)``.

    Parameters
    ----------
    directory : path
        The case directory to write (created).
    nominal_params, model, n_elements, piezo_hysteresis
        The nominal model written to ``meta.json``.
    true_params, true_model, true_n_elements, true_piezo_hysteresis
        The device simulated (default: the nominal one).
    effects : Effects, optional
        Physics the nominal model lacks, simulated.
    experiments : sequence of dict, optional
        The drives, one file each (default :data:`DEFAULT_EXPERIMENTS`).
    noise_rms : float
        White noise of the reading [m].
    resolution : float, optional
        The reading's quantisation step [m] (None or 0: none).
    offsets : sequence of float, optional
        Each file's zero [m] (default uniform in ±2 µm).
    seed : int
        The random generator's seed.
    dt : float
        RK4 step of the simulation [s].
    rest_s, edge_s : float
        Rest before the drive and the sawtooth's fast edge [s], unless an experiment gives its own.
    sample_rate_Hz : float
        The reading's sample rate [Hz].
    write_noise_rms : bool
        Put the noise RMS in meta.json.
    noise : SensorNoise, optional
        A lab's reading (coloured noise, hum, spikes, drift, a late channel) instead of white noise.

    Returns
    -------
    Path
        The directory, ready for :func:`idm_rs.load_case` and :func:`idm_rs.diagnose`.

    Examples
    --------
    >>> from idm_rs.io.synthetic import make_case
    >>> case = make_case("/tmp/spring_case", nominal_params=idm_rs.Params(),
    ...                  effects=idm_rs.Effects(k_ground=2e4))   # doctest: +SKIP
    """
    if not isinstance(nominal_params, Params):
        raise TypeError(f"nominal_params must be idm_rs.Params, got {type(nominal_params).__name__}")
    structure(model)  # an IDM structure, else a ValueError naming the choices
    true_params = nominal_params if true_params is None else true_params
    true_model = model if true_model is None else true_model
    true_n_elements = n_elements if true_n_elements is None else true_n_elements
    true_piezo_hysteresis = piezo_hysteresis if true_piezo_hysteresis is None else true_piezo_hysteresis
    exps = [dict(e) for e in (DEFAULT_EXPERIMENTS if experiments is None else experiments)]
    if not exps:
        raise ValueError("experiments must not be empty")
    if noise is not None and not isinstance(noise, SensorNoise):
        raise TypeError(f"noise must be idm_rs.io.sensor_noise.SensorNoise, got {type(noise).__name__}")
    if not (noise_rms >= 0 and math.isfinite(noise_rms)):
        raise ValueError(f"noise_rms must be finite and non-negative, got {noise_rms}")
    sensor = noise if noise is not None else SensorNoise(rms=noise_rms)
    resolution = float(resolution or 0.0)
    if resolution < 0 or not math.isfinite(resolution):
        raise ValueError(f"resolution must be finite and non-negative, got {resolution}")
    ratio = 1.0 / (sample_rate_Hz * dt)
    save_every = int(round(ratio))
    if save_every < 1 or abs(ratio - save_every) > 1e-6 * ratio:
        raise ValueError(
            f"dt = {dt:g} s must divide the sample step 1/sample_rate_Hz = {1 / sample_rate_Hz:g} s"
        )

    rng = np.random.default_rng(seed)
    if offsets is None:
        offs = rng.uniform(-OFFSET_RANGE_M, OFFSET_RANGE_M, size=len(exps))
    else:
        offs = np.asarray(offsets, dtype=float)
        if offs.shape != (len(exps),):
            raise ValueError(f"offsets: {offs.size} values for {len(exps)} experiments")

    out = Path(directory)
    out.mkdir(parents=True, exist_ok=True)
    meta_exps = []
    for i, e in enumerate(exps):
        allowed = {"sampled", "file", "orientation"} if "sampled" in e else {
            "amplitude_V", "frequency_Hz", "direction", "cycles", "rest_s", "edge_s", "file", "orientation"}
        unknown = set(e) - allowed
        if unknown:
            raise ValueError(f"experiments[{i}]: unknown key(s) {sorted(unknown)}")
        orientation = e.get("orientation", "normal")
        if orientation not in ORIENTATIONS:
            raise ValueError(f"experiments[{i}]: orientation must be one of {ORIENTATIONS}, got {orientation!r}")
        # the device's frame: a rig turned end for end feels bench-fixed forces the other way
        acting = effects
        if effects is not None and orientation == "reversed":
            acting = Effects(**oriented(dataclasses.asdict(effects), True))
        placed = {} if orientation == "normal" else {"orientation": orientation}
        if "sampled" in e:
            meta_exps.append(dict(_sampled_experiment(out, i, e, true_params, true_model, true_n_elements,
                                                      true_piezo_hysteresis, acting, offs[i], sensor, resolution,
                                                      rng, dt, save_every, sample_rate_Hz), **placed))
            continue
        meta_exps.append(dict(_sawtooth_experiment(out, i, e, true_params, true_model, true_n_elements,
                                                   true_piezo_hysteresis, acting, offs[i], sensor, resolution,
                                                   rng, dt, save_every, sample_rate_Hz, rest_s, edge_s),
                              **placed))

    nominal: dict[str, Any] = {"model": model}
    if structure(model).elements:
        nominal["n_elements"] = int(n_elements)
    nominal["piezo_hysteresis"] = bool(piezo_hysteresis)
    resolved = nominal_params.to_dict(resolved=True)
    nominal["params"] = {f.name: resolved[f.name] for f in fields(Params)}  # the Params order
    meta: dict[str, Any] = {
        "format": FORMAT_ID,
        "nominal": nominal,
        "experiments": meta_exps,
        "sensor": {"sample_rate_Hz": float(sample_rate_Hz), "resolution_m": resolution},
    }
    if write_noise_rms:
        meta["sensor"]["noise_rms_m"] = float(sensor.rms)
    (out / META).write_text(json.dumps(meta, indent=2) + "\n", encoding="utf-8")
    return out


def _on_grid(delay_s: float, dt: float) -> float:
    """A channel delay [s] rounded to the integration step (the drive's breakpoints must fall on
    step boundaries)."""
    return round(delay_s / dt) * dt


def _noise(sensor: SensorNoise, t: np.ndarray, rng: np.random.Generator, step: float) -> np.ndarray:
    """One file's noise and artefacts. White noise alone draws exactly as it always has (the
    recordings of a given seed stay the same)."""
    plain = not (sensor.ar or sensor.pink or sensor.hum or sensor.outliers or sensor.drift_m[1] > 0)
    if plain:
        return rng.normal(0.0, sensor.rms, size=t.size) if sensor.rms > 0 else np.zeros(t.size)
    return sensor.random(t.size, step, rng) + sensor.artefacts(t, rng)


def _sawtooth_experiment(out: Path, i: int, e: Mapping[str, Any], params: Params, model: Model, n_elements: int,
                         hysteresis: bool, effects: Optional[Effects], offset: float, sensor: SensorNoise,
                         resolution: float, rng: np.random.Generator, dt: float, save_every: int,
                         sample_rate_Hz: float, rest_s: float, edge_s: float) -> dict[str, Any]:
    """One sawtooth experiment simulated and written (its file, and its entry of meta.json)."""
    rest = float(e.get("rest_s", rest_s))
    edge = float(e.get("edge_s", edge_s))
    wave = Sawtooth(
        amplitude=float(e["amplitude_V"]),
        frequency=float(e["frequency_Hz"]),
        cycles=int(e["cycles"]),
        rise=edge,
        direction=e["direction"],
        delay=rest,
    )
    # a late displacement channel: the motion it reads began delay_s after the voltage
    felt = wave if sensor.delay_s == 0 else dataclasses.replace(wave, delay=rest + _on_grid(sensor.delay_s, dt))
    n = int(round(wave.duration * sample_rate_Hz)) + 1
    t = np.arange(n) / sample_rate_Hz
    if abs(t[-1] - wave.duration) > 1e-9 / sample_rate_Hz:
        raise ValueError(
            f"experiments[{i}]: the duration rest_s + cycles/frequency_Hz = {wave.duration:g} s is not a "
            f"multiple of the sample step {1 / sample_rate_Hz:g} s"
        )
    sim = simulate(
        params,
        felt,
        t_end=t[-1],
        dt=dt,
        model=model,
        n_elements=n_elements,
        save_every=save_every,
        piezo_hysteresis=hysteresis,
        effects=effects,
    )
    if sim.t.shape != t.shape or np.max(np.abs(sim.t - t)) > 1e-3 / sample_rate_Hz:
        raise RuntimeError(f"experiments[{i}]: simulation saved {sim.t.size} times, expected {n}")
    x = sim.reading + offset + _noise(sensor, t, rng, 1.0 / sample_rate_Hz)
    if resolution > 0:
        x = np.round(x / resolution) * resolution
    v = voltage_at(wave, t)
    name = e.get("file") or experiment_file_name(i + 1, wave.direction, wave.amplitude, wave.frequency)
    np.savetxt(
        out / name,
        np.column_stack([t, v, x]),
        fmt="%.10g",
        delimiter=",",
        header=",".join(HEADER),
        comments="",
    )
    return {"file": name, "waveform": "sawtooth", "amplitude_V": _fmt_number(wave.amplitude),
            "frequency_Hz": _fmt_number(wave.frequency), "direction": wave.direction, "cycles": wave.cycles,
            "rest_s": rest, "edge_s": edge}


def _sampled_experiment(out: Path, i: int, e: Mapping[str, Any], params: Params, model: Model, n_elements: int,
                        hysteresis: bool, effects: Optional[Effects], offset: float, sensor: SensorNoise,
                        resolution: float, rng: np.random.Generator, dt: float, save_every: int,
                        sample_rate_Hz: float) -> dict[str, Any]:
    """One experiment driven by a recorded voltage (a Sampled), written as ``waveform: "sampled"``."""
    wave = e["sampled"]
    if not isinstance(wave, Sampled):
        raise TypeError(f"experiments[{i}]['sampled'] must be an idm_rs.Sampled")
    n = int(round(wave.duration * sample_rate_Hz)) + 1
    t = np.arange(n) / sample_rate_Hz
    late = _on_grid(sensor.delay_s, dt)
    felt = wave if late == 0 else Sampled(np.r_[0.0, wave.t + late], np.r_[wave.voltage[0], wave.voltage])
    sim = simulate(params, felt, t_end=t[-1], dt=dt, model=model, n_elements=n_elements,
                   save_every=save_every, piezo_hysteresis=hysteresis, effects=effects)
    x = sim.reading + offset + _noise(sensor, t, rng, 1.0 / sample_rate_Hz)
    if resolution > 0:
        x = np.round(x / resolution) * resolution
    v = np.interp(t, wave.t, wave.voltage)
    name = e.get("file") or f"exp{i + 1}_sampled.csv"
    np.savetxt(out / name, np.column_stack([t, v, x]), fmt="%.10g", delimiter=",", header=",".join(HEADER),
               comments="")
    return {"file": name, "waveform": "sampled"}
