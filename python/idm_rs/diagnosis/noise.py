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
    """The sensor noise given in meta.json (``sensor.noise_rms_m``) when there is one. Else:
    before the first cycle the body is at rest, so the reading there is offset + noise: the
    spread about each file's mean is the noise; without any rest, the second differences. Second differences over whole files give a
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
    rest_sigma, n_rest, rel = math.nan, 0, 0.05
    if rest:
        r = np.concatenate(rest)
        dof = r.size - len(rest)
        rest_sigma = float(math.sqrt(np.sum(r * r) / max(dof, 1)))
        n_rest, rel = int(r.size), 1.0 / math.sqrt(2.0 * max(dof, 1))
    given = rec.noise_rms_m
    if given is not None:  # the user knows the sensor: that is the noise floor
        return NoiseEstimate(given, rest_sigma, diff_sigma, n_rest, 0.0)
    if rest:
        return NoiseEstimate(rest_sigma, rest_sigma, diff_sigma, n_rest, rel)
    # no rest segment (a sampled drive that starts at once): the high-frequency content, from
    # fourth differences (variance 70 sigma^2 for white noise): the body's ringing, 50+ samples
    # per period, passes a fourth difference ~1e-4 times attenuated where a second one lets
    # ~1e-2 through
    d4 = np.concatenate([np.diff(e.x, 4) for e in rec.experiments])
    hf_sigma = float(1.4826 * np.median(np.abs(d4 - np.median(d4))) / math.sqrt(70.0))
    return NoiseEstimate(hf_sigma, math.nan, hf_sigma, 0, 0.05)
