"""What a lab's displacement reading carries besides the motion, for writing realistic
recordings (:func:`idm_rs.io.synthetic.make_case` ``noise=``): coloured noise (autoregressive, or
pink: 1/f), mains hum, spikes, a sensor zero drifting within a file and a delay of the
displacement channel behind the voltage. Quantisation is make_case's ``resolution``."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Optional

import numpy as np
from numpy.typing import NDArray


@dataclass(frozen=True)
class SensorNoise:
    """A reading's artefacts. Every random draw comes from the generator make_case passes.

    ``rms`` [m]: marginal RMS of the random noise (white when ``ar`` is empty and ``pink`` 0).
    ``ar``: autoregressive coefficients (x_t = sum ar_k x_{t-k} + e_t), e.g. ``(0.9,)`` for a
    low-passed noise of lag-1 correlation 0.9. ``pink``: share of the variance that is 1/f noise
    (0..1; the rest is white or AR). ``hum``: (frequency [Hz], amplitude [m]) lines, each at a
    random phase per file. ``outliers``: spikes per file, each of ``outlier_sigmas`` (a range) times
    ``rms``, random sign. ``drift_m``: a range [m] of each file's zero drift over its length
    (random sign per file). ``delay_s`` [s]: the displacement channel's delay behind the voltage.
    """

    rms: float = 1.5e-9
    ar: tuple[float, ...] = ()
    pink: float = 0.0
    hum: tuple[tuple[float, float], ...] = ()
    outliers: int = 0
    outlier_sigmas: tuple[float, float] = (15.0, 30.0)
    drift_m: tuple[float, float] = (0.0, 0.0)
    delay_s: float = 0.0

    def __post_init__(self) -> None:
        if not (self.rms >= 0 and math.isfinite(self.rms)):
            raise ValueError(f"SensorNoise.rms must be finite and non-negative [m], got {self.rms}")
        if not 0.0 <= self.pink <= 1.0:
            raise ValueError(f"SensorNoise.pink is a share of the variance in [0, 1], got {self.pink}")
        roots = np.roots(np.r_[1.0, -np.asarray(self.ar, dtype=float)]) if self.ar else np.zeros(0)
        if roots.size and np.max(np.abs(roots)) >= 1.0:
            raise ValueError(f"SensorNoise.ar = {self.ar} is not stationary (a root of 1 - sum ar_k z^-k "
                             "on or outside the unit circle); e.g. (0.9,)")
        if self.outliers < 0:
            raise ValueError(f"SensorNoise.outliers is a count per file, got {self.outliers}")
        if not (self.delay_s >= 0 and math.isfinite(self.delay_s)):
            raise ValueError(f"SensorNoise.delay_s must be finite and non-negative [s], got {self.delay_s}")

    def random(self, n: int, step: float, rng: np.random.Generator) -> NDArray[np.float64]:
        """The random noise of one file: n samples, marginal RMS ``rms``."""
        from scipy.signal import lfilter

        if self.rms == 0 or n == 0:
            return np.zeros(n)
        burn = 2000 if self.ar else 0
        base = rng.normal(0.0, 1.0, n + burn)
        if self.ar:
            base = lfilter([1.0], np.r_[1.0, -np.asarray(self.ar, dtype=float)], base)[burn:]
        base = base / math.sqrt(_ar_variance(self.ar)) if self.ar else base
        out = math.sqrt(1.0 - self.pink) * base
        if self.pink > 0:
            out = out + math.sqrt(self.pink) * pink(n, rng)
        return self.rms * out

    def artefacts(self, t: NDArray[np.float64], rng: np.random.Generator) -> NDArray[np.float64]:
        """Hum, spikes and a drifting zero of one file at sample times ``t`` [m]."""
        out = np.zeros(t.size)
        for f, a in self.hum:
            out += a * np.sin(2.0 * math.pi * f * t + rng.uniform(0.0, 2.0 * math.pi))
        lo, hi = self.drift_m
        if hi > 0:
            span = max(float(t[-1] - t[0]), 1e-300)
            out += rng.choice([-1.0, 1.0]) * rng.uniform(lo, hi) * (t - t[0]) / span
        if self.outliers:
            idx = rng.choice(np.arange(1, t.size), size=min(self.outliers, t.size - 1), replace=False)
            out[idx] += rng.choice([-1.0, 1.0], idx.size) * rng.uniform(*self.outlier_sigmas, idx.size) * self.rms
        return out


def _ar_variance(ar: tuple[float, ...]) -> float:
    """Variance of the AR process driven by unit white noise."""
    from statsmodels.tsa.arima_process import arma_acovf

    return float(arma_acovf(np.r_[1.0, -np.asarray(ar, dtype=float)], [1.0], nobs=1)[0])


def pink(n: int, rng: np.random.Generator, f_min: Optional[float] = None) -> NDArray[np.float64]:
    """Unit-variance 1/f noise of n samples: white noise shaped by 1/sqrt(f) in frequency
    (frequencies below ``f_min``, in cycles per sample, held at its level; default 1/n)."""
    f = np.fft.rfftfreq(n)
    lo = f_min if f_min is not None else 1.0 / n
    shape = 1.0 / np.sqrt(np.maximum(f, lo))
    shape[0] = 0.0
    x = np.fft.irfft(np.fft.rfft(rng.normal(0.0, 1.0, n)) * shape, n)
    return x / max(float(np.std(x)), 1e-300)
