"""The measurement noise level, estimated from the data itself."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..recording import Recording


@dataclass(frozen=True)
class NoiseEstimate:
    """RMS of the sensor noise [m] and how it was found."""

    sigma: float  #: pooled estimate [m]
    rest_sigma: float  #: from the rest segments (the device is exactly at rest there) [m]
    difference_sigma: float  #: from second differences over all samples (robust, MAD) [m]
    n_rest: int  #: rest samples used
    relative_uncertainty: float  #: 1-sigma relative error of `sigma`


def estimate_noise(rec: Recording) -> NoiseEstimate:
    """Before the first cycle the body is at rest, so the reading there is offset + noise: the
    spread about each file's mean is the noise. Second differences over whole files give a
    robust cross-check (motion is smooth on the 10 us sample scale except at edges; the median
    ignores those)."""
    rest = []
    for e in rec.experiments:
        x = e.x[e.rest_mask]
        if x.size > 2:
            rest.append(x - x.mean())
    d2 = np.concatenate([np.diff(e.x, 2) for e in rec.experiments])
    # second difference of white noise has variance 6 sigma^2; 1.4826 MAD -> sigma for a Gaussian
    diff_sigma = float(1.4826 * np.median(np.abs(d2 - np.median(d2))) / math.sqrt(6.0))
    if rest:
        r = np.concatenate(rest)
        dof = r.size - len(rest)
        rest_sigma = float(math.sqrt(np.sum(r * r) / max(dof, 1)))
        return NoiseEstimate(rest_sigma, rest_sigma, diff_sigma, int(r.size), 1.0 / math.sqrt(2.0 * max(dof, 1)))
    return NoiseEstimate(diff_sigma, math.nan, diff_sigma, 0, 0.05)
