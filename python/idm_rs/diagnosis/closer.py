"""Which of two fits that are not nested in each other is closer to the data: Vuong's test
(1989), conditioned on the design. Two models with as many parameters, fitted to one recording,
leave whitened residuals r_a and r_b; their chi^2 differ by 2 sum(delta_i m_i), delta = r_a - r_b
(the two predictions' difference, fixed by the drive) and m = (r_a + r_b) / 2 (the noise, and
what neither model holds). Its spread under the noise is 4 delta' Gamma delta, Gamma the
residual's autocovariance (Bartlett-tapered): a coarse reading's rounding error, constant while
the body sticks, is correlated noise that either model can take a share of."""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray


def _autocovariance(x: NDArray[np.float64], lags: int) -> NDArray[np.float64]:
    n = x.size
    return np.array([float(x[k:] @ x[: n - k]) for k in range(lags + 1)])


def closer_z(r_a: NDArray[np.float64], r_b: NDArray[np.float64], lags: int) -> float:
    """z of model b being closer than model a: (chi^2_a - chi^2_b) over its standard deviation
    under the noise, from the whitened residuals (noise units, one vector over every file, the
    same samples). About N(0, 1) where both are as close; large where b is closer. `lags`: the
    autocovariance lags the spread counts (Bartlett weights). NaN where the two are equal."""
    if r_a.shape != r_b.shape or r_a.size == 0:
        raise ValueError(f"closer_z needs residuals over the same samples: {r_a.shape} and {r_b.shape}")
    n = r_a.size
    lags = max(0, min(int(lags), n - 1))
    delta = r_a - r_b
    gain = float(r_a @ r_a - r_b @ r_b)
    gamma = _autocovariance(r_b, lags) / n  # the closer-claimed model's residual: the noise
    cd = _autocovariance(delta, lags)
    w = 1.0 - np.arange(lags + 1) / (lags + 1.0)
    var = 4.0 * float(gamma[0] * cd[0] + 2.0 * np.sum(w[1:] * gamma[1:] * cd[1:]))
    if not var > 0.0:
        return math.nan
    return gain / math.sqrt(var)
