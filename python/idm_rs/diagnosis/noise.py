"""The measurement noise level, estimated from the data itself."""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Optional, Sequence

import numpy as np
from numpy.typing import NDArray

from ..io.recording import Recording
from .noise_model import NoiseModel
from .thresholds import DISAGREE_SIGMAS, RESIDUAL_CLIP
from .whiteness import whiteness_z  # noqa: F401  (the residual test, named here as before)


@dataclass(frozen=True)
class NoiseEstimate:
    """RMS of the sensor noise [m] and how it was found."""

    sigma: float  #: pooled estimate [m]
    rest_sigma: float  #: from the rest segments (the device is exactly at rest there) [m]
    difference_sigma: float  #: from second differences over all samples (robust, MAD) [m]
    n_rest: int  #: rest samples used
    relative_uncertainty: float  #: 1-sigma relative error of `sigma`
    #: from the fitted residual's sample-to-sample differences (NaN before a fit) [m]
    residual_sigma: float = math.nan
    #: which estimate `sigma` is: "given", "rest", "fourth differences", "rest and residual
    #: (pooled)" or "residual (rest disagrees)"
    source: str = "rest"
    #: the noise model: colour, lines, spikes, resolution, drift, delay (None before it is learned)
    model: Optional[NoiseModel] = None


def estimate_noise(rec: Recording) -> NoiseEstimate:
    """The sensor noise given in meta.json (``sensor.noise_rms_m``) when there is one. Else:
    before the first cycle the body is at rest, so the reading there is offset + noise: the
    spread about each file's mean is the noise; without any rest, the second differences. Second
    differences over whole files give a robust cross-check (motion is smooth on the 10 us sample
    scale except at edges; the median ignores those)."""
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
        return NoiseEstimate(given, rest_sigma, diff_sigma, n_rest, 0.0, source="given")
    if rest:
        return NoiseEstimate(rest_sigma, rest_sigma, diff_sigma, n_rest, rel, source="rest")
    # no rest segment (a sampled drive that starts at once): the high-frequency content, from
    # fourth differences (variance 70 sigma^2 for white noise): the body's ringing, 50+ samples
    # per period, passes a fourth difference ~1e-4 times attenuated where a second one lets
    # ~1e-2 through
    d4 = np.concatenate([np.diff(e.x, 4) for e in rec.experiments])
    hf_sigma = float(1.4826 * np.median(np.abs(d4 - np.median(d4))) / math.sqrt(70.0))
    return NoiseEstimate(hf_sigma, math.nan, hf_sigma, 0, 0.05, source="fourth differences")


def residual_sigma(residuals: Sequence[NDArray[np.float64]]) -> tuple[float, float]:
    """The noise in a fitted residual from its second differences: (sigma [m], relative 1-sigma).
    A systematic residual left by missing physics is mostly smooth on the sample scale (a ringing
    of 50 samples per period passes a second difference 2.5e-4 times attenuated in power), so
    this sees the noise over every sample — not just the short rest. But a stick-slip residual
    bends sharply at each slip and stick: a calibrated DPS missing a weight drag (43 nm RMS) put
    0.2 % of its second differences at 10-1,000 x the noise, and a trim of the largest 0.1 % read
    the noise 21 % high (1.79 nm for 1.42 drawn; a nominal model's residual 1.4-4.3 x). So the
    second differences beyond RESIDUAL_CLIP robust scales of their median are left
    out, and the sum of squares of the rest (efficient) is corrected for the Gaussian's
    truncation there."""
    d = np.concatenate([np.diff(r, 2) for r in residuals if r.size > 2])
    d = d[np.isfinite(d)]
    if d.size < 100:
        return math.nan, math.inf
    # the scale from the 90 % quantile of |d - median| (1.645 s for a Gaussian): a coarse reading's
    # second differences are mostly exact zeros, whose median absolute deviation is 0
    med = float(np.median(d))
    scale = float(np.quantile(np.abs(d - med), 0.9)) / 1.6449
    kept = d[np.abs(d - med) <= RESIDUAL_CLIP * scale] if scale > 0 else d
    # E[x^2 given |x| <= c s] / s^2 for a Gaussian (c = RESIDUAL_CLIP: 1 - 1.5e-5 at 5)
    c = RESIDUAL_CLIP
    kept_var = math.erf(c / math.sqrt(2.0)) - 2.0 * c * math.exp(-0.5 * c * c) / math.sqrt(2.0 * math.pi)
    kept_var /= math.erf(c / math.sqrt(2.0))
    # a second difference of white noise has variance 6 sigma^2
    s = float(math.sqrt(np.mean(kept * kept) / kept_var / 6.0))
    # second differences are correlated (lag 1: -2/3, lag 2: 1/6): 1.94x the iid variance
    return s, math.sqrt(1.944 / (2.0 * kept.size))


def cross_check(noise: NoiseEstimate, residuals: Sequence[NDArray[np.float64]]) -> NoiseEstimate:
    """The noise floor cross-checked against the fitted residual's own high-frequency content.
    A given floor stands. Otherwise: where the rest and residual estimates agree (within
    DISAGREE_SIGMAS combined 1-sigma) their inverse-variance mean; where they disagree the
    residual's (it rests on every sample: a short rest segment is what comes out a few percent
    off, enough to hide a small effect — or, biased low, to make noise look systematic)."""
    s_res, rel_res = residual_sigma(residuals)
    if noise.source == "given" or not math.isfinite(s_res):
        return replace(noise, residual_sigma=s_res)
    if not math.isfinite(noise.rest_sigma):
        return replace(noise, sigma=s_res, residual_sigma=s_res, relative_uncertainty=rel_res, source="residual")
    a, ua = noise.rest_sigma, noise.relative_uncertainty * noise.rest_sigma
    b, ub = s_res, rel_res * s_res
    if abs(a - b) > DISAGREE_SIGMAS * math.hypot(ua, ub):
        return replace(noise, sigma=b, residual_sigma=b, relative_uncertainty=rel_res,
                       source="residual (rest disagrees)")
    w_a, w_b = 1.0 / ua**2, 1.0 / ub**2
    pooled = (w_a * a + w_b * b) / (w_a + w_b)
    return replace(noise, sigma=pooled, residual_sigma=b, relative_uncertainty=1.0 / math.sqrt(w_a + w_b) / pooled,
                   source="rest and residual (pooled)")
