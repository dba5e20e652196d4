"""One regressor per rig: the preprocessing that turns a record into the rows of its identified
model, shared by the identification (``fit.py``) and the diagnosis (``diagnosis.py``) so that
both see the same samples.

* EMPS: the measured position low-passed (4th-order Butterworth at 100 Hz, zero phase),
  differentiated twice, edges dropped; the motor force regressed on [a, v, sgn v, 1], every
  column decimated by 5 (the benchmark's IDIM-LS, ``Script_IDIM_LS.m``).
* Frame: both displacements low-passed at 20 Hz; the spring deflection y − x regressed on
  [x'', x', sgn x', 1] over the sliding samples.
* Spring–slider: the force record median-filtered against its impulsive noise, and its slip
  events (peaks: onsets, troughs: ends).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Callable

import numpy as np
from numpy.typing import NDArray

from .data import RigData
from .signals import MAD_TO_SIGMA, low_pass_derivatives, lstsq, robust_noise_rms, slips

#: EMPS: the benchmark's filter and decimation (Script_IDIM_LS.m); border samples dropped
EMPS_FILTER_HZ, EMPS_FILTER_ORDER, EMPS_BORDER = 100.0, 4, 50
EMPS_DECIMATE = 5
#: frame: low-pass of the kinematics [Hz] (the drive is 1 Hz, the frame's mode ~3 Hz); samples
#: counted as sliding: |dx/dt| above this share of its 95th percentile (while stuck, the
#: friction force is anywhere in [-Fs, Fs] and says nothing about Fc)
FRAME_FILTER_HZ, FRAME_SLIDING_SHARE, FRAME_BORDER = 20.0, 0.2, 25
#: spring-slider: median-filter width against the impulsive noise [samples], slip events are
#: drops of at least this share of the force's 1-99 % range, at least this far apart [s]
SLIDER_MEDIAN, SLIDER_PROMINENCE, SLIDER_MIN_GAP = 7, 0.1, 0.05


@dataclass
class Regression:
    """A rig's identified model as a linear regression y ≈ X b (rows: the samples used), with
    each row's position ``q`` [m], velocity ``v`` [m/s] and time ``t`` [s], and the white-noise
    RMS of ``y`` (its unit: N for EMPS, m for the frame)."""

    X: NDArray[np.float64]
    y: NDArray[np.float64]
    names: tuple[str, ...]
    q: NDArray[np.float64]
    v: NDArray[np.float64]
    t: NDArray[np.float64]
    noise: float
    #: the full-length preprocessed signals a rig's simulation needs (by name)
    signals: dict[str, NDArray[np.float64]] = field(default_factory=dict, repr=False)


def emps_regression(data: RigData) -> Regression:
    """The motor force on [a, v, sgn v, 1] (``m``, ``fv``, ``fc``, ``offset``); the noise from
    the base fit's residual, its sample-to-sample part (a white error's differences have twice
    its variance)."""
    from scipy.signal import decimate

    if data.force is None:
        raise ValueError(f"{data.name}: no measured force")
    qf, dq, ddq = low_pass_derivatives(data.response, data.t, EMPS_FILTER_HZ, EMPS_FILTER_ORDER)
    sl = slice(EMPS_BORDER, -EMPS_BORDER)
    dec: Callable[[NDArray[np.float64]], NDArray[np.float64]] = lambda a: decimate(a, EMPS_DECIMATE)  # noqa: E731
    cols = [ddq[sl], dq[sl], np.sign(dq[sl]), np.ones_like(dq[sl])]
    X = np.column_stack([dec(c) for c in cols])
    y = dec(data.force[sl])
    _, e, _ = lstsq(X, y)
    noise = float(np.std(np.diff(e)) / math.sqrt(2.0))
    return Regression(X, y, ("m", "fv", "fc", "offset"), dec(qf[sl]), dec(dq[sl]), data.t[sl][::EMPS_DECIMATE],
                      noise, {"q": qf, "v": dq, "a": ddq})


def frame_regression(data: RigData) -> Regression:
    """The spring deflection y − x on [x'', x', sgn x', 1] over the sliding samples (the frame's
    equation divided by k: ``m/k``, ``c/k``, ``Fc/k``, ``offset``); the noise of the top plate's
    record against its low-passed self (robust: MAD)."""
    from scipy.signal import butter, filtfilt

    t = data.t
    b, a = butter(4, FRAME_FILTER_HZ / (data.sample_rate_Hz / 2.0))
    x, yb = filtfilt(b, a, data.response), filtfilt(b, a, data.drive)
    dx = np.gradient(x, t)
    ddx = np.gradient(dx, t)
    slide = np.abs(dx) > FRAME_SLIDING_SHARE * np.percentile(np.abs(dx), 95)
    slide[:FRAME_BORDER] = slide[-FRAME_BORDER:] = False
    X = np.column_stack([ddx, dx, np.sign(dx), np.ones_like(x)])[slide]
    noise = float(MAD_TO_SIGMA * np.median(np.abs(data.response - x)))
    return Regression(X, (yb - x)[slide], ("m_k", "c_k", "fc_k", "offset"), x[slide], dx[slide], t[slide], noise,
                      {"x": x, "drive": yb, "sliding": slide.astype(float)})


@dataclass
class SliderEvents:
    """A spring–slider record's median-filtered force [N], its white-noise RMS [N] (robust:
    ``signals.robust_noise_rms`` of the raw record) and its slip onsets and ends (indices)."""

    force: NDArray[np.float64]
    noise: float
    peaks: NDArray[np.intp]
    troughs: NDArray[np.intp]


def slider_events(data: RigData) -> SliderEvents:
    from scipy.signal import medfilt

    force = medfilt(data.response, SLIDER_MEDIAN)
    peaks, troughs = slips(data.t, force, SLIDER_PROMINENCE, SLIDER_MIN_GAP)
    return SliderEvents(force, robust_noise_rms(data.response), peaks, troughs)
