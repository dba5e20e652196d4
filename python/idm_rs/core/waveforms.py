"""Input voltage waveforms. All are piecewise linear; each gives its breakpoints (t [s], V [V])
to the Rust core, which steps exactly onto them."""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass, field
from typing import Literal, Mapping, Union, cast

import numpy as np
from numpy.typing import ArrayLike, NDArray

from . import engine


def _check(name: str, value: float, *, positive: bool = False, non_negative: bool = False) -> float:
    value = float(value)
    if not math.isfinite(value):
        raise ValueError(f"parameter '{name}' must be finite, got {value}")
    if positive and value <= 0:
        raise ValueError(f"parameter '{name}' must be positive, got {value}")
    if non_negative and value < 0:
        raise ValueError(f"parameter '{name}' must be non-negative, got {value}")
    return value


#: Start-up cycles a sawtooth train's steady-state metrics leave out by default, the same in
#: ``sweep``, ``characterize``, ``steady_state``, ``stall_force`` and the CLI (``--skip-cycles``).
#: Two, because on the paper's device (DPS, 80 V, 0.5 ms edge) the first cycle's step is 2-16 x
#: the later ones at 50-500 Hz and the second still differs by up to 90 %; the approach to the
#: steady state can last longer (at 500 Hz the step still shrinks after 8 cycles), which
#: ``step_std`` shows: run more cycles or skip more where it is large.
STARTUP_CYCLES: int = 2


def _engine_breakpoints(kind: str, fields: Mapping[str, float]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """A family's breakpoints from the engine (rust/src/physics/waveform.rs), its fields in the
    engine's order: the package does not derive them again."""
    return engine.wave_breakpoints(kind, [float(fields[f]) for f in engine.wave_fields(kind)])


@dataclass(frozen=True)
class Triangle:
    """Single triangular wave: 0 V until ``delay`` [s], linear to ``amplitude`` [V] at
    delay + ``rise`` [s], linear back to 0 V at delay + rise + ``fall`` [s], then 0 V.
    The paper case is ``Triangle(80.0, 0.5e-3, 9.5e-3)``.

    Parameters
    ----------
    amplitude : float
        Peak voltage [V].
    rise, fall : float
        Durations of the rising and the falling edge [s] (> 0).
    delay : float
        0 V before the rise [s] (>= 0).

    Examples
    --------
    >>> idm_rs.Triangle(amplitude=80.0, rise=0.5e-3, fall=9.5e-3).duration
    0.01
    """

    amplitude: float = 80.0
    rise: float = 0.5e-3
    fall: float = 9.5e-3
    delay: float = 0.0

    def __post_init__(self) -> None:
        _check("amplitude", self.amplitude)
        _check("rise", self.rise, positive=True)
        _check("fall", self.fall, positive=True)
        _check("delay", self.delay, non_negative=True)

    def breakpoints(self) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """(t [s], V [V]) of the corners, as the engine builds the input."""
        return _engine_breakpoints(self.batch_kind, self.batch_fields())

    @property
    def duration(self) -> float:
        """End of the wave [s]."""
        return self.delay + self.rise + self.fall

    #: the batch engine's name for this family
    batch_kind = "triangle"

    def batch_fields(self) -> dict[str, float]:
        """This wave's per-point fields in the batch engine (see ``engine.wave_fields``)."""
        return {"amplitude": self.amplitude, "rise": self.rise, "fall": self.fall, "delay": self.delay}

    def with_fields(self, f: Mapping[str, float]) -> "Triangle":
        """The same family with batch fields ``f`` (a sweep point's wave)."""
        return Triangle(f["amplitude"], f["rise"], f["fall"], f["delay"])


@dataclass(frozen=True)
class Sawtooth:
    """A train of ``cycles`` sawtooth periods of 1/``frequency`` [Hz] after ``delay`` [s].

    ``direction="forward"``: rise 0 → ``amplitude`` [V] in ``rise`` [s], then a linear fall to 0
    over the rest of the period (fast extension, slow contraction: the body steps forward).
    ``"backward"``: rise over (period − rise), fall in ``rise``. 0 V before and after.

    Parameters
    ----------
    amplitude : float
        Peak voltage [V].
    frequency : float
        Periods per second [Hz] (> 0; ``rise`` shorter than the period).
    cycles : int
        Periods in the train (>= 1).
    rise : float
        The fast edge [s].
    direction : {"forward", "backward"}
        Which edge is the fast one.
    delay : float
        0 V before the train [s] (>= 0).

    Examples
    --------
    >>> idm_rs.Sawtooth(amplitude=80.0, frequency=200.0, cycles=6).duration
    0.03
    """

    amplitude: float = 80.0
    frequency: float = 100.0
    cycles: int = 3
    rise: float = 0.5e-3
    direction: Literal["forward", "backward"] = "forward"
    delay: float = 0.0

    def __post_init__(self) -> None:
        _check("amplitude", self.amplitude)
        _check("frequency", self.frequency, positive=True)
        _check("rise", self.rise, positive=True)
        _check("delay", self.delay, non_negative=True)
        if int(self.cycles) != self.cycles or self.cycles < 1:
            raise ValueError(f"parameter 'cycles' must be a positive integer, got {self.cycles}")
        object.__setattr__(self, "cycles", int(self.cycles))
        if self.direction not in ("forward", "backward"):
            raise ValueError(f"parameter 'direction' must be 'forward' or 'backward', got {self.direction!r}")
        if self.rise >= 1.0 / self.frequency:
            raise ValueError(
                f"parameter 'rise' ({self.rise} s) must be shorter than the period ({1 / self.frequency} s)"
            )

    @property
    def period(self) -> float:
        """1/frequency [s]."""
        return 1.0 / self.frequency

    @property
    def duration(self) -> float:
        """End of the last cycle [s]."""
        return self.delay + self.cycles * self.period

    batch_kind = "sawtooth"

    def batch_fields(self) -> dict[str, float]:
        """This wave's per-point fields in the batch engine (see ``engine.wave_fields``)."""
        return {"amplitude": self.amplitude, "frequency": self.frequency, "cycles": float(self.cycles),
                "rise": self.rise, "forward": 1.0 if self.direction == "forward" else 0.0, "delay": self.delay}

    def with_fields(self, f: Mapping[str, float]) -> "Sawtooth":
        """The same family with batch fields ``f`` (a sweep point's wave)."""
        return Sawtooth(f["amplitude"], f["frequency"], int(f["cycles"]), f["rise"],
                        "forward" if f["forward"] else "backward", f["delay"])

    def breakpoints(self) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """(t [s], V [V]) of the corners, as the engine builds the input."""
        return _engine_breakpoints(self.batch_kind, self.batch_fields())


@dataclass(frozen=True, eq=False)
class Sampled:
    """Any sampled waveform, piecewise linear through (``t`` [s], ``voltage`` [V]); the first
    value holds before ``t[0]`` and the last after ``t[-1]``. Times must increase strictly; the
    step ``dt`` of a simulation must divide every sample time that falls inside the run.

    Parameters
    ----------
    t : array
        Sample times [s], strictly increasing (a first sample after t = 0 at a non-zero voltage
        is a step at t = 0, and is said).
    voltage : array
        The voltage at them [V].

    Examples
    --------
    >>> w = idm_rs.Sampled([0.0, 0.5e-3, 10e-3], [0.0, 80.0, 0.0])   # the paper's triangle
    >>> w.duration
    0.01
    """

    t: NDArray[np.float64] = field(repr=False)
    voltage: NDArray[np.float64] = field(repr=False)

    def __init__(self, t: ArrayLike, voltage: ArrayLike) -> None:
        tt = np.ascontiguousarray(t, dtype=float)
        vv = np.ascontiguousarray(voltage, dtype=float)
        for name, a in (("t", tt), ("voltage", vv)):
            if a.ndim > 1:
                raise ValueError(f"Sampled: '{name}' must be 1-D, got an array of shape {a.shape}")
        tt, vv = tt.ravel(), vv.ravel()
        if tt.shape != vv.shape:
            raise ValueError(f"Sampled: {tt.size} times but {vv.size} voltages")
        if tt.size == 0:
            raise ValueError("Sampled: needs at least one sample")
        if not (np.all(np.isfinite(tt)) and np.all(np.isfinite(vv))):
            bad = int(np.flatnonzero(~(np.isfinite(tt) & np.isfinite(vv)))[0])
            raise ValueError(f"Sampled: sample {bad} is not finite")
        if np.any(np.diff(tt) <= 0):
            bad = int(np.flatnonzero(np.diff(tt) <= 0)[0])
            raise ValueError(f"Sampled: times must increase strictly (t[{bad}] >= t[{bad + 1}])")
        if tt[0] > 0 and vv[0] != 0:
            warnings.warn(f"Sampled: the first sample is at t = {tt[0]:g} s with {vv[0]:g} V and the drive holds that "
                          "value before it, a voltage step at t = 0; start the samples at t = 0 (or at 0 V) if the "
                          "step is not meant", UserWarning, stacklevel=2)
        object.__setattr__(self, "t", tt)
        object.__setattr__(self, "voltage", vv)

    def breakpoints(self) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        return self.t, self.voltage

    batch_kind = "sampled"

    def batch_fields(self) -> dict[str, float]:
        """Per-point field in the batch engine: a scale on the shared samples (1 = as given)."""
        return {"amplitude": 1.0}

    def with_fields(self, f: Mapping[str, float]) -> "Sampled":
        """These samples scaled by ``f["amplitude"]``."""
        return Sampled(self.t, self.voltage * f["amplitude"])

    @property
    def duration(self) -> float:
        return float(self.t[-1])

    def __repr__(self) -> str:
        return f"Sampled({self.t.size} samples, t = {self.t[0]:g}..{self.t[-1]:g} s)"


Waveform = Union[Triangle, Sawtooth, Sampled]


def voltage_at(waveform: Waveform, t: ArrayLike) -> NDArray[np.float64]:
    """V(t) [V] of any waveform, evaluated with numpy (for plots and checks)."""
    bt, bv = waveform.breakpoints()
    return cast("NDArray[np.float64]", np.interp(np.asarray(t, dtype=float), bt, bv))
