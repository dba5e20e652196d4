"""Spikes in a reading (a lab's outliers): isolated samples far from their neighbours' median,
found in the calibrated residual and replaced by that median before anything is fitted."""

from __future__ import annotations

import math
from dataclasses import replace
from typing import Sequence

import numpy as np
from numpy.typing import NDArray

from ..io.recording import Recording
from .thresholds import OUTLIER_ISOLATION, OUTLIER_Z


def spikes(r: NDArray[np.float64], resolution: float = 0.0) -> tuple[NDArray[np.int64], NDArray[np.float64]]:
    """Isolated spikes of a residual, alone or two side by side: (indices, deviation from the
    median of the six neighbours [m]). See OUTLIER_Z. The deviation's robust scale is held at
    least at the rounding error of the reading's `resolution` [m] (a reading coarser than its
    noise sits on one level for long stretches: a scale of zero, and every step of one level a
    "spike")."""
    from scipy.ndimage import median_filter

    if r.size < 16:
        return np.zeros(0, dtype=np.int64), np.zeros(0)
    foot = np.array([1, 1, 1, 0, 1, 1, 1], dtype=bool)
    m = r - median_filter(r, footprint=foot, mode="nearest")
    scale = max(1.4826 * float(np.median(np.abs(m - np.median(m)))), resolution / math.sqrt(12.0))
    if not scale > 0:
        return np.zeros(0, dtype=np.int64), np.zeros(0)
    a = np.abs(m)
    big = a > OUTLIER_Z * scale
    # isolated: each neighbour's deviation small, or small beside this one's (a spike beside a
    # slip, where the residual itself moves fast, still stands out of it)
    quiet = 0.5 * OUTLIER_Z * scale
    nb = np.maximum(np.r_[0.0, a[:-1]], np.r_[a[1:], 0.0])
    calm = nb < np.maximum(quiet, OUTLIER_ISOLATION * a)
    # two spikes side by side (each the other's neighbour, so neither is isolated alone): the
    # pair is one when the samples either side of it are calm beside the smaller of the two
    pair = big[:-1] & big[1:]
    low = np.minimum(a[:-1], a[1:])
    before, after = np.r_[0.0, a[:-2]], np.r_[a[2:], 0.0]
    pair &= np.maximum(before, after) < np.maximum(quiet, OUTLIER_ISOLATION * low)
    first = np.flatnonzero(pair)
    idx = np.union1d(np.flatnonzero(big & calm), np.r_[first, first + 1]).astype(np.int64)
    return idx, m[idx]


def reject_spikes(rec: Recording, preds: Sequence[NDArray[np.float64]]) -> tuple[Recording, int]:
    """The recording with every isolated spike of the calibrated residual replaced by its
    neighbours' median (the reading there is unknown; the neighbours say what it would be), and
    the count."""
    exps, count = [], 0
    for e, p in zip(rec.experiments, preds):
        d = e.x - np.asarray(p)[: e.x.size]
        if not np.all(np.isfinite(d)):
            exps.append(e)
            continue
        idx, dev = spikes(d, rec.resolution_m)
        if idx.size:
            x = e.x.copy()
            x[idx] -= dev
            e = replace(e, x=x)
            count += int(idx.size)
        exps.append(e)
    return (replace(rec, experiments=exps) if count else rec), count
