"""How the sensor reads, as the objective uses it: the noise's colour (an autoregressive model,
by which every residual is prewhitened: generalised least squares, the prediction-error method
with a noise model), nuisance columns profiled out of every residual with the segment offsets
(mains-hum sinusoids of their own amplitude and phase per file, a per-file zero slope), and a
fixed delay of the displacement channel behind the voltage. None of it is device physics.

With no colour, no lines, no slope and no delay the objective never builds a `Measurement`:
white-noise recordings are compared exactly as before (bit for bit)."""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import Sequence, cast

import numpy as np
from numpy.typing import NDArray


@dataclass(frozen=True)
class Whitener:
    """Exact prewhitening by an AR(p) noise model: the innovations of the Cholesky factor of its
    covariance (Levinson-Durbin's partial predictors for the first p samples, the order-p one
    after), each scaled to the noise's marginal RMS, so white noise of RMS sigma maps to white
    noise of RMS sigma and a coloured one of marginal RMS sigma does too."""

    #: partial[k] = the order-k predictor's coefficients (k = 0..p; partial[p] is the model's)
    partial: tuple[tuple[float, ...], ...]
    #: scale[k] = sqrt(gamma0 / v_k), v_k the order-k prediction error variance
    scale: tuple[float, ...]

    @property
    def order(self) -> int:
        return len(self.partial) - 1

    @classmethod
    def from_acf(cls, rho: NDArray[np.float64], order: int) -> "Whitener":
        """From the autocorrelation rho[0..order] (rho[0] = 1)."""
        from statsmodels.tsa.stattools import levinson_durbin

        if order == 0:
            return cls(((),), (1.0,))
        ld = levinson_durbin(np.asarray(rho[: order + 1], dtype=float), nlags=order, isacov=True)
        phi, sig = np.asarray(ld.phi), np.asarray(ld.sigma)
        partial = tuple(tuple(float(v) for v in phi[1: k + 1, k]) for k in range(order + 1))
        var = [1.0] + [float(s) for s in sig[1: order + 1]]
        return cls(partial, tuple(1.0 / math.sqrt(max(v, 1e-12)) for v in var))

    def __call__(self, a: NDArray[np.float64]) -> NDArray[np.float64]:
        """Whitened copy of `a` along its last axis (1-D or rows)."""
        from scipy.signal import lfilter

        p = self.order
        a = np.asarray(a, dtype=float)
        if p == 0:
            return cast("NDArray[np.float64]", a.copy())
        out = lfilter(np.r_[1.0, -np.asarray(self.partial[p])], [1.0], a, axis=-1) * self.scale[p]
        n = a.shape[-1]
        for t in range(min(p, n)):
            c = np.asarray(self.partial[t])
            prev = a[..., t - 1::-1][..., :t] if t else a[..., :0]
            out[..., t] = (a[..., t] - (prev @ c if t else 0.0)) * self.scale[t]
        return cast("NDArray[np.float64]", out)


@dataclass(frozen=True)
class Measurement:
    """What the objective applies to every comparison (see the module docstring)."""

    whiten: Whitener = field(default_factory=lambda: Whitener(((),), (1.0,)))
    lines_Hz: tuple[float, ...] = ()  #: sinusoids profiled out per file (sin and cos each)
    drift: bool = False  #: a zero slope per file profiled out
    delay_s: float = 0.0  #: the displacement channel's delay behind the voltage [s]

    @property
    def trivial(self) -> bool:
        return self.whiten.order == 0 and not self.lines_Hz and not self.drift and self.delay_s == 0.0

    def columns(self, t: NDArray[np.float64]) -> NDArray[np.float64]:
        """The nuisance columns beyond the segment offsets at sample times `t` (samples x k)."""
        cols = []
        for f in self.lines_Hz:
            cols += [np.sin(2 * math.pi * f * t), np.cos(2 * math.pi * f * t)]
        if self.drift:
            cols.append(t - t.mean())
        return np.stack(cols, axis=1) if cols else np.zeros((t.size, 0))

    def shifted(self, a: NDArray[np.float64], step: float) -> NDArray[np.float64]:
        """`a` (a prediction, or rows of its derivatives) read `delay_s` late: a(t - delay),
        linear between samples, held at the first (last) sample beyond the record."""
        if self.delay_s == 0.0:
            return a
        return shift(a, self.delay_s / step)

    def with_delay(self, delay_s: float) -> "Measurement":
        return replace(self, delay_s=float(delay_s))


def shift(a: NDArray[np.float64], lag: float) -> NDArray[np.float64]:
    """a(i - lag) along the last axis, linear interpolation, ends held."""
    n = a.shape[-1]
    x = np.clip(np.arange(n) - lag, 0.0, n - 1.0)
    i0 = np.minimum(np.floor(x).astype(int), max(n - 2, 0))
    w = x - i0
    i1 = np.minimum(i0 + 1, n - 1)
    return cast("NDArray[np.float64]", a[..., i0] * (1.0 - w) + a[..., i1] * w)


class Profile:
    """One experiment's nuisance projection in the whitened metric: the segment offsets and the
    measurement's columns, whitened, orthonormalised (generalised least squares profiles them
    out exactly)."""

    def __init__(self, m: Measurement, t: NDArray[np.float64], starts: Sequence[int]) -> None:
        n = t.size
        bounds = list(starts) + [n]
        seg = np.zeros((n, len(starts)))
        for k, (a, b) in enumerate(zip(bounds[:-1], bounds[1:])):
            seg[a:b, k] = 1.0
        B = np.concatenate([seg, m.columns(t)], axis=1)
        self.m = m
        self.n_segments = len(starts)
        Bw = m.whiten(B.T).T
        self.Q, self.R = np.linalg.qr(Bw)

    def residual(self, d: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """(whitened residual of data-minus-prediction `d` with the nuisances removed, the
        nuisance coefficients: segment offsets [m] first)."""
        w = self.m.whiten(d)
        c = self.Q.T @ w
        try:
            coef = np.linalg.solve(self.R, c)
        except np.linalg.LinAlgError:
            coef = np.full(c.shape, math.nan)
        return w - self.Q @ c, coef

    def columns(self, s: NDArray[np.float64]) -> NDArray[np.float64]:
        """The same for rows `s` (derivatives of the prediction, rows x samples)."""
        w = self.m.whiten(s)
        return cast("NDArray[np.float64]", w - (w @ self.Q) @ self.Q.T)
