"""The lag-1 whiteness test of a residual (no noise level needed): the one statistic the noise
model, the fits and the verdict rules read to tell noise from a systematic residual."""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Optional, Sequence

import numpy as np
from numpy.typing import NDArray

from .thresholds import ROUNDING_COARSE, ROUNDING_HARMONICS

if TYPE_CHECKING:
    from .fitting import Objective


def whiteness_z(residuals: Sequence[NDArray[np.float64]], of: Optional["Objective"] = None) -> float:
    """Lag-1 autocorrelation of the residuals (per file, pooled) times sqrt(n): about N(0, 1) for
    white noise, large for a smooth systematic residual — without needing the noise level.
    With `of`, the objective the residuals are of, a reading coarser than ROUNDING_COARSE x the
    residual's RMS has its rounding's mean error taken out first (:func:`rounding_removed`)."""
    if of is not None:
        residuals = rounding_removed(residuals, of)
    num = den = 0.0
    n = 0
    for r in residuals:
        r = r - r.mean()
        num += float(np.dot(r[1:], r[:-1]))
        den += float(np.dot(r, r))
        n += r.size
    return num / den * math.sqrt(n) if den > 0 else 0.0


def rounding_removed(residuals: Sequence[NDArray[np.float64]], of: "Objective") -> list[NDArray[np.float64]]:
    """The residuals less the mean error of the reading's rounding, a function of where the
    reading's expectation y (the reading less the residual) falls between two steps of the
    resolution: noise smaller than the step does not dither the rounding, whose mean error is
    then a sine series in that phase (the harmonics' amplitudes fall as exp(-2 pi^2 m^2 sigma^2 /
    step^2)). It is no noise of its own sample but the same while the body sticks, and a right
    model's residual read at 4 x its noise showed a lag-1 whiteness z of 4.7 from it. The series'
    ROUNDING_HARMONICS sines are fitted by least squares over every file; the residuals
    unchanged where the reading is not that coarse, or the objective whitens them (a
    measurement model: they are no longer the reading less its expectation)."""
    res = list(residuals)
    rec = getattr(of, "recording", None)  # None: no reading to take the rounding from
    if rec is None or rec.resolution_m <= 0.0:
        return res
    step = rec.resolution_m
    files = [rec.experiments[j] for j in of.experiments]
    if (of.measurement is not None or len(res) != len(files)
            or any(r.size > e.x.size or not np.all(np.isfinite(r)) for r, e in zip(res, files))):
        return res
    pooled = np.concatenate(res) if res else np.zeros(0)
    if pooled.size < 4 * ROUNDING_HARMONICS or step < ROUNDING_COARSE * float(np.sqrt(np.mean(pooled**2))):
        return res
    x = np.concatenate([e.x[: r.size] for r, e in zip(res, files)])
    # the grid's origin: the readings are whole steps from it (a circular mean of their phase)
    origin = step * float(np.angle(np.mean(np.exp(2j * np.pi * x / step)))) / (2.0 * np.pi)
    phase = 2.0 * np.pi * (x - pooled - origin) / step
    basis = np.stack([np.sin(m * phase) for m in range(1, ROUNDING_HARMONICS + 1)], axis=1)
    coef = np.linalg.lstsq(basis, pooled, rcond=None)[0]
    bias = basis @ coef
    out, at = [], 0
    for r in res:
        out.append(r - bias[at: at + r.size])
        at += r.size
    return out
