"""Signal helpers shared by the rigs' identification and diagnosis: least squares with the
parameters' covariance, low-passed derivatives, slip events of a force record and a robust
estimate of a record's white noise."""

from __future__ import annotations

import math
from typing import cast

import numpy as np
from numpy.typing import NDArray

#: MAD to standard deviation for Gaussian noise
MAD_TO_SIGMA = 1.4826


def lstsq(X: NDArray[np.float64], y: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.float64],
                                                                    NDArray[np.float64]]:
    """(coefficients, residual, covariance of the coefficients) of the least squares X b = y."""
    beta, *_ = np.linalg.lstsq(X, y, rcond=None)
    e = y - X @ beta
    # pinv: a candidate's columns may be nearly collinear with the base model's (the diagnosis)
    cov = np.var(e, ddof=X.shape[1]) * np.linalg.pinv(X.T @ X)
    return cast("NDArray[np.float64]", beta), e, cov  # numpy's stub types it floating[Any]


def low_pass_derivatives(q: NDArray[np.float64], t: NDArray[np.float64], cutoff_hz: float,
                         order: int) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """(q, dq/dt, d²q/dt²) after a zero-phase Butterworth low-pass of ``order`` at ``cutoff_hz``
    [Hz]; derivatives by central differences."""
    from scipy.signal import butter, filtfilt

    fs = 1.0 / float(np.median(np.diff(t)))
    b, a = butter(order, cutoff_hz / (fs / 2.0))
    qf = filtfilt(b, a, q)
    dq = np.gradient(qf, t)
    ddq = np.gradient(dq, t)
    return qf, dq, ddq


def slips(t: NDArray[np.float64], force: NDArray[np.float64], prominence: float,
          min_gap: float) -> tuple[NDArray[np.intp], NDArray[np.intp]]:
    """Indices of a stick-slip force record's peaks (slip onsets) and troughs (slip ends): drops
    of at least ``prominence`` of the force's 1-99 % range, at least ``min_gap`` [s] apart."""
    from scipy.signal import find_peaks

    span = float(np.percentile(force, 99) - np.percentile(force, 1))
    gap = max(1, int(min_gap / float(np.median(np.diff(t)))))
    peaks, _ = find_peaks(force, prominence=prominence * span, distance=gap)
    troughs, _ = find_peaks(-force, prominence=prominence * span, distance=gap)
    return peaks, troughs


def robust_noise_rms(x: NDArray[np.float64]) -> float:
    """The white-noise RMS of a sampled record, robust to impulsive spikes and to the signal's
    own slow motion: the MAD of successive differences (each holds two samples' noise, hence
    / sqrt 2). A quantised record whose noise is below its step has mostly equal neighbours; the
    quantisation noise, step / sqrt 12, is then the floor (the step: the smallest non-zero
    difference). NaN when neither can be read (a constant record)."""
    d = np.diff(np.asarray(x, dtype=float))
    if d.size == 0:
        return math.nan
    mad = MAD_TO_SIGMA * float(np.median(np.abs(d - np.median(d)))) / math.sqrt(2.0)
    nonzero = np.abs(d[d != 0.0])
    step = float(nonzero.min()) if nonzero.size else 0.0
    est = max(mad, step / math.sqrt(12.0))
    return est if est > 0.0 else math.nan
