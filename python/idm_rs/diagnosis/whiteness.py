"""The lag-1 whiteness test of a residual (no noise level needed): the one statistic the noise
model, the fits and the verdict rules read to tell noise from a systematic residual."""

from __future__ import annotations

import math
from typing import Sequence

import numpy as np
from numpy.typing import NDArray


def whiteness_z(residuals: Sequence[NDArray[np.float64]]) -> float:
    """Lag-1 autocorrelation of the residuals (per file, pooled) times sqrt(n): about N(0, 1) for
    white noise, large for a smooth systematic residual — without needing the noise level."""
    num = den = 0.0
    n = 0
    for r in residuals:
        r = r - r.mean()
        num += float(np.dot(r[1:], r[:-1]))
        den += float(np.dot(r, r))
        n += r.size
    return num / den * math.sqrt(n) if den > 0 else 0.0
