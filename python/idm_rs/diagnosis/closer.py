"""Which of two fits that are not nested in each other the data choose: Cox's test of each
against the other (1961) and Vuong's test of which is closer (1989), conditioned on the design.
Two models with as many parameters, fitted to one recording, leave whitened residuals r_a and
r_b; their chi^2 differ by Delta = 2 sum(delta_i m_i), delta = r_a - r_b (the two predictions'
difference, fixed by the drive) and m = (r_a + r_b) / 2. Where model b is the truth, m = e +
delta / 2 and Delta = D + 2 delta.e (D = |delta|^2); where a is, Delta = -D + 2 delta.e; where
neither (a structure s both miss), Delta = 2 delta.(e + s) +- D. The spread of 2 delta.e under the
noise is s_D = 2 sqrt(delta' Gamma delta), Gamma the residual's autocovariance (Bartlett-tapered):
a coarse reading's rounding error, constant while the body sticks, is correlated noise that
either model can take a share of."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray


@dataclass(frozen=True)
class Contest:
    """Two fits weighed: the chi^2 difference a - b, its spread under the noise, and D."""

    gain: float  #: chi^2_a - chi^2_b (b closer where positive)
    spread: float  #: standard deviation of the gain under the noise (chi^2 units)
    distance: float  #: D = |r_a - r_b|^2, how far apart the two predictions are (noise units)

    @property
    def z(self) -> float:
        """Vuong's z: b closer than a (about N(0, 1) where both are as close)."""
        return self.gain / self.spread

    @property
    def z_against_a(self) -> float:
        """Cox's z against a being the truth (about N(0, 1) where it is; large where it is not)."""
        return (self.gain + self.distance) / self.spread

    @property
    def z_against_b(self) -> float:
        """Cox's z against b being the truth (about N(0, 1) where it is; very negative where not)."""
        return (self.gain - self.distance) / self.spread

    def b_stands(self, z: float, z_fits: float) -> bool:
        """b is chosen over a: a is rejected as the truth beyond `z` and b fits within `z_fits`
        (Cox), or b is closer by more than `z` (Vuong). Where neither is rejected the data
        cannot tell them apart; where both are, only Vuong's closeness counts (data between two
        fits, a few noise units from each, do not choose the nearer by chance)."""
        cox = self.z_against_a > z and self.z_against_b >= -z_fits
        return bool(cox or self.z > z)


def _autocovariance(x: NDArray[np.float64], lags: int) -> NDArray[np.float64]:
    n = x.size
    return np.array([float(x[k:] @ x[: n - k]) for k in range(lags + 1)])


def contest(r_a: NDArray[np.float64], r_b: NDArray[np.float64], lags: int) -> Contest:
    """Fits a and b weighed from their whitened residuals (noise units, one vector over every
    file, the same samples). `lags`: the autocovariance lags the spread counts (Bartlett
    weights), read off b's residual."""
    if r_a.shape != r_b.shape or r_a.size == 0:
        raise ValueError(f"contest needs residuals over the same samples: {r_a.shape} and {r_b.shape}")
    n = r_a.size
    lags = max(0, min(int(lags), n - 1))
    delta = r_a - r_b
    gamma = _autocovariance(r_b, lags) / n
    cd = _autocovariance(delta, lags)
    w = 1.0 - np.arange(lags + 1) / (lags + 1.0)
    var = 4.0 * float(gamma[0] * cd[0] + 2.0 * np.sum(w[1:] * gamma[1:] * cd[1:]))
    return Contest(float(r_a @ r_a - r_b @ r_b), math.sqrt(var) if var > 0.0 else math.nan, float(cd[0]))

