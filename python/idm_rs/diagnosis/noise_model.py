"""The noise model, estimated from the recording and stated: its colour (an AR(p) fitted to the
rest before the drive, p by AIC), spikes (rejected, counted), mains hum (lines at 50/60 Hz and
harmonics, per-file amplitude and phase), the reading's resolution, a sensor zero drifting within
a file, and a delay of the displacement channel. :func:`learn` takes the calibrated model's
prediction (the device's motion, as well as the nominal model can tell it) and returns what the
objective must apply (:class:`.measurement.Measurement`) with the recording cleaned of its spikes,
and the report's account (:class:`NoiseModel`)."""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import Any, Callable, Optional, Sequence

import numpy as np
from numpy.typing import NDArray

from ..io.recording import Recording
from .measurement import Measurement, Profile, Whitener
from .segments import segment_starts
from .spikes import reject_spikes
from .thresholds import (
    AR_MAX_ORDER,
    COLOUR_CONFIRM_LR,
    COLOUR_ITERATIONS,
    COLOUR_SEGMENT_MAX,
    DELAY_MIN_S,
    DELAY_RANGE_S,
    DELAY_STEP_S,
    DRIFT_REST_ALPHA,
    LINE_SPREAD_ALPHA,
    MAINS_HARMONICS,
    MAINS_HZ,
    MEASUREMENT_ALPHA,
)
from .whiteness import whiteness_z


@dataclass(frozen=True)
class NoiseModel:
    """What the diagnosis found the sensor's reading to carry besides the device's motion."""

    sigma: float  #: marginal RMS of the noise [m] (as `NoiseEstimate.sigma`)
    order: int  #: autoregressive order of its colour (0: white)
    lag1: float  #: its lag-1 autocorrelation
    rho: tuple[float, ...]  #: its autocorrelation at lags 0..order
    lines: tuple[tuple[float, float], ...] = ()  #: (frequency [Hz], mean amplitude [m]) profiled out
    resolution: float = 0.0  #: the reading's resolution [m] (meta.json)
    outliers: int = 0  #: samples rejected as spikes (replaced by their neighbours' median)
    delay_s: float = math.nan  #: the displacement channel's delay estimated behind the voltage [s]
    delay_applied: bool = False  #: the delay is taken as a measurement property in every fit
    #: the lines, the drift and the delay are profiled out of every fit (they explained what the
    #: verdict would otherwise have blamed on physics); else found and reported only
    artefacts_applied: bool = False
    drift_m: tuple[float, ...] = ()  #: each file's zero drift over its length [m] (when applied)
    notes: tuple[str, ...] = ()  #: what could not be told apart, or was estimated and not applied

    @property
    def coloured(self) -> bool:
        return self.order > 0

    def to_dict(self) -> dict[str, Any]:
        return {"summary": self.describe(), "sigma_m": self.sigma, "ar_order": self.order, "lag1": self.lag1,
                "acf": list(self.rho), "lines": [{"frequency_Hz": f, "amplitude_m": a} for f, a in self.lines],
                "resolution_m": self.resolution, "outliers": self.outliers,
                "delay_s": self.delay_s if math.isfinite(self.delay_s) else None, "delay_applied": self.delay_applied,
                "artefacts_applied": self.artefacts_applied,
                "drift_m": list(self.drift_m), "notes": list(self.notes)}

    def describe(self) -> str:
        """One line: "coloured noise (AR(2)), lag-1 0.89, 2.1 nm; a 50 Hz line of 3.0 nm in the
        reading; resolution 4 nm; 5 spikes rejected; ..." """
        parts = [(f"coloured noise (AR({self.order})), lag-1 {self.lag1:.2f}, " if self.coloured
                  else "white noise, ") + f"{self.sigma * 1e9:.2f} nm"]
        for f, a in self.lines:
            parts.append(f"a {f:g} Hz line of {a * 1e9:.1f} nm in the reading" if self.artefacts_applied
                         else f"a {f:g} Hz component of {a * 1e9:.1f} nm (not taken as hum)")
        if self.resolution > 0:
            parts.append(f"resolution {self.resolution * 1e9:.3g} nm")
        if self.outliers:
            parts.append(f"{self.outliers} spike{'s' if self.outliers != 1 else ''} rejected")
        if self.delay_applied:
            parts.append(f"the reading {self.delay_s * 1e6:.1f} us late")
        elif math.isfinite(self.delay_s) and abs(self.delay_s) >= DELAY_MIN_S:
            parts.append(f"a delay of {self.delay_s * 1e6:.1f} us estimated (not taken)")
        if self.drift_m and self.artefacts_applied:
            parts.append("a zero drifting " + ", ".join(f"{d * 1e9:+.1f}" for d in self.drift_m) + " nm per file")
        return "; ".join(parts)


# --- the colour -----------------------------------------------------------------------------------


@dataclass(frozen=True)
class Colour:
    """An AR fit to the rest: marginal RMS [m], autocorrelation 0..p, samples, and the evidence."""

    sigma: float
    rho: NDArray[np.float64]
    n: int
    lr: float  #: 2 ln likelihood ratio of the AR(p) against white noise


def fit_colour(segments: Sequence[NDArray[np.float64]], max_order: int = AR_MAX_ORDER) -> Optional[Colour]:
    """The noise's AR model from still segments, each with its own unknown offset and slope
    removed (a zero that drifts, or a hum, is a slope over a 2 ms rest): pooled
    autocovariances, corrected to what the model expects them to be after that removal (the
    exact expectation, tr(M Sigma M S_k), M the removal and Sigma the model's covariance: a
    strongly correlated noise loses a large share of its variance to a short segment's line),
    the order by AIC, white unless the colour is significant (MEASUREMENT_ALPHA)."""
    from scipy.linalg import toeplitz
    from scipy.stats import chi2 as chi2_dist
    from statsmodels.tsa.arima_process import arma_acf
    from statsmodels.tsa.stattools import levinson_durbin

    segs = [np.asarray(s[:COLOUR_SEGMENT_MAX], dtype=float) for s in segments if s.size > 2 * max_order + 8]
    if not segs:
        return None
    n = sum(s.size for s in segs)
    p_max = max(1, min(max_order, min(s.size for s in segs) // 8))
    makers = []
    raw = np.zeros(p_max + 1)
    for s in segs:
        B = np.stack([np.ones(s.size), np.linspace(-1.0, 1.0, s.size)], axis=1)
        Q, _ = np.linalg.qr(B)
        M = np.eye(s.size) - Q @ Q.T
        makers.append(M)
        y = M @ s
        for k in range(p_max + 1):
            raw[k] += float(np.dot(y[k:], y[: y.size - k]))
    raw /= n
    gamma = raw.copy()
    order, lr = 0, 0.0
    longest = max(s.size for s in segs)
    for _ in range(COLOUR_ITERATIONS):
        if gamma[0] <= 0:
            return None
        ld = levinson_durbin(gamma / gamma[0], nlags=p_max, isacov=True)
        sig_k = np.r_[1.0, np.asarray(ld.sigma)[1:]]
        aic = n * np.log(np.maximum(sig_k, 1e-300)) + 2.0 * np.arange(p_max + 1)
        order = int(np.argmin(aic))
        lr = float(n * math.log(1.0 / max(sig_k[order], 1e-300)))
        if order == 0 or lr <= chi2_dist.isf(MEASUREMENT_ALPHA, order):
            order = 0
        phi = np.asarray(ld.phi)[1: order + 1, order] if order else np.zeros(0)
        acov = gamma[0] * arma_acf(np.r_[1.0, -phi], [1.0], lags=longest)
        expected = np.zeros(p_max + 1)
        for M in makers:
            A = M @ toeplitz(acov[: M.shape[0]]) @ M
            expected += [np.trace(A, offset=k) for k in range(p_max + 1)]
        # the estimator's bias under the current model, taken off the raw autocovariances
        gamma = raw - (expected / n - acov[: p_max + 1])
    rho = gamma[: order + 1] / gamma[0]
    return Colour(math.sqrt(gamma[0]), rho, n, lr)


def rest_segments(rec: Recording, lines: Optional[Sequence[NDArray[np.float64]]] = None
                  ) -> list[NDArray[np.float64]]:
    """Each file's rest before the drive (the device still), less the hum fitted there."""
    out = []
    for j, e in enumerate(rec.experiments):
        mask = e.rest_mask
        x = e.x[mask]
        if lines is not None:
            x = x - lines[j][mask]
        out.append(x)
    return out


# --- nuisances tested on the calibrated residual ----------------------------------------------------


@dataclass
class Residuals:
    """The calibrated model's data-minus-prediction per file, with each file's segment starts and
    the calibrated parameters' Jacobian in a measurement's metric (`jac_of`: whitened, nuisances
    profiled, noise units; None where there is none): a nuisance is credited only with what a
    refit of those parameters could not take up (a calibration bends its parameters to mimic
    part of a hum or a drift, differently in each file)."""

    rec: Recording
    preds: list[NDArray[np.float64]]
    starts: list[list[int]]
    jac_of: Callable[[Measurement], Optional[NDArray[np.float64]]]
    _profiles: dict[tuple[Measurement, int], Profile] = field(default_factory=dict, repr=False)

    @classmethod
    def of(cls, rec: Recording, preds: Sequence[NDArray[np.float64]],
           jac_of: Optional[Callable[[Measurement], Optional[NDArray[np.float64]]]] = None) -> "Residuals":
        starts = [segment_starts(e, rec.sample_rate_Hz, e.n_samples) for e in rec.experiments]
        return cls(rec, [np.asarray(p)[: e.n_samples] for p, e in zip(preds, rec.experiments)], starts,
                   jac_of if jac_of is not None else (lambda m: None))

    def profile(self, m: Measurement, f: int) -> Profile:
        """File f's nuisance projection in `m`'s metric (the delay plays no part in it: a delay
        scan builds each file's once)."""
        key = (m.with_delay(0.0), f)
        if key not in self._profiles:
            e = self.rec.experiments[f]
            self._profiles[key] = Profile(key[0], e.t, self.starts[f])
        return self._profiles[key]

    def chi2(self, m: Measurement, sigma: float) -> float:
        total = 0.0
        for f, (e, p) in enumerate(zip(self.rec.experiments, self.preds)):
            d = e.x - m.shifted(p, self.rec.sample_step)
            if not np.all(np.isfinite(d)):
                return math.inf
            w, _ = self.profile(m, f).residual(d)
            total += float(w @ w)
        return total / sigma**2

    def joint(self, m: Measurement, cols: Sequence[NDArray[np.float64]], sigma: float) -> "Joint":
        """The least squares of extra columns `cols[j]` (samples x k of file j, the same k for
        every file) beyond `m`'s nuisances and the calibrated parameters, in `m`'s metric."""
        ws, blocks, late = [], [], []
        for f, (e, p, X) in enumerate(zip(self.rec.experiments, self.preds, cols)):
            prof = self.profile(m, f)
            shifted = m.shifted(p, self.rec.sample_step)
            w, _ = prof.residual(e.x - shifted)
            ws.append(w / sigma)
            blocks.append(prof.columns(X.T).T / sigma)
            if m.delay_s:
                late.append(prof.columns(-np.gradient(shifted, e.t)[None, :])[0] / sigma)
        w = np.concatenate(ws)
        k = blocks[0].shape[1]
        X = np.zeros((w.size, k * len(blocks)))
        row = 0
        for f, B in enumerate(blocks):
            X[row: row + B.shape[0], f * k: (f + 1) * k] = B
            row += B.shape[0]
        J = self.jac_of(m)
        if J is not None and (J.shape[0] != w.size or not np.all(np.isfinite(J))):
            J = None
        if late:
            # the delay is an estimate too: a line or a trend is credited only with what a
            # slightly different delay could not take up (a delay read 0.25 us short of 12.1 us
            # left each file's 60 Hz amplitude 0.6 nm apart, and the hum's test failed)
            d = np.concatenate(late)[:, None]
            J = d if J is None else np.concatenate([J, d], axis=1)
        if J is not None:
            Q, _ = np.linalg.qr(J)
            X = X - Q @ (Q.T @ X)
            w = w - Q @ (Q.T @ w)
        A, b = X.T @ X, X.T @ w
        cov = np.linalg.pinv(A)
        coef = cov @ b
        return Joint(A, b, coef, cov, k)


@dataclass
class Joint:
    """A joint least squares of per-file extra columns: Gram A, inner products b (noise units),
    coefficients [m per column unit] and their covariance, k columns per file."""

    A: NDArray[np.float64]
    b: NDArray[np.float64]
    coef: NDArray[np.float64]
    cov: NDArray[np.float64]
    k: int

    @property
    def gain(self) -> float:
        """chi^2 the columns take off the residual."""
        return float(self.b @ self.coef)

    def of_file(self, f: int) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """(coefficients, standard errors) of file f."""
        s = slice(f * self.k, (f + 1) * self.k)
        return self.coef[s], np.sqrt(np.maximum(np.diag(self.cov)[s], 0.0))


def _sinusoids(rec: Recording, f: float) -> list[NDArray[np.float64]]:
    return [np.stack([np.sin(2 * math.pi * f * e.t), np.cos(2 * math.pi * f * e.t)], axis=1) for e in rec.experiments]


def _slopes(rec: Recording) -> list[NDArray[np.float64]]:
    return [(e.t - e.t.mean())[:, None] for e in rec.experiments]


def _beside_slopes(rec: Recording, cols: Sequence[NDArray[np.float64]]) -> list[NDArray[np.float64]]:
    """Each file's columns with its own slope beside them (last): a hum and a drifting zero are
    fitted together, as a record of one or two mains periods cannot tell a line's slow part from
    a trend — tested alone, each takes a share of the other, differently in each file."""
    return [np.concatenate([X, s], axis=1) for X, s in zip(cols, _slopes(rec))]


def _line_test(res: Residuals, m: Measurement, f: float, sigma: float
               ) -> tuple[float, NDArray[np.float64], NDArray[np.float64]]:
    """(chi^2 the sinusoid at `f` gains beyond a slope per file, each file's amplitude [m] and its
    standard error) in the metric of `m`."""
    both = res.joint(m, _beside_slopes(res.rec, _sinusoids(res.rec, f)), sigma)
    slopes = res.joint(m, _slopes(res.rec), sigma)
    nf = len(res.rec.experiments)
    amps, se = np.zeros(nf), np.zeros(nf)
    for k in range(nf):
        c, e = both.of_file(k)
        amps[k], se[k] = math.hypot(float(c[0]), float(c[1])), max(float(np.mean(e[:2])), 1e-300)
    return both.gain - slopes.gain, amps, se


def find_lines(res: Residuals, m: Measurement, sigma: float) -> tuple[tuple[float, float], ...]:
    """Mains hum: the fundamental (50 or 60 Hz) whose per-file sine and cosine lower chi^2
    significantly (2 per file degrees of freedom, beyond a slope per file) with amplitudes alike
    in every file (the mains feed each file alike, at its own phase; a missing effect's residual
    projects unevenly on a sinusoid, most where the drive is strongest), then its harmonics that
    add significantly and alike."""
    best: Optional[tuple[float, float, float]] = None
    for f0 in MAINS_HZ:
        found = _line(res, m, f0, sigma)
        if found is not None and (best is None or found[0] > best[1]):
            best = (f0, *found)
    if best is None:
        return ()
    lines = [(best[0], best[2])]
    for k in MAINS_HARMONICS:
        # a harmonic can fall on a drive's frequency (100 Hz): alike in every file, or not hum
        found = _line(res, replace(m, lines_Hz=tuple(f for f, _ in lines)), k * best[0], sigma)
        if found is not None:
            lines.append((k * best[0], found[1]))
    return tuple(lines)


def _line(res: Residuals, m: Measurement, f: float, sigma: float) -> Optional[tuple[float, float]]:
    """(chi^2 gained, the amplitude [m]) of a line at `f` that lowers chi^2 significantly with
    amplitudes alike in every file; None where there is none."""
    from scipy.stats import chi2 as chi2_dist

    nf = len(res.rec.experiments)
    gain, amps, se = _line_test(res, m, f, sigma)
    if gain <= chi2_dist.isf(MEASUREMENT_ALPHA, 2 * nf):
        return None
    mean = float(np.average(amps, weights=se**-2))
    if nf > 1 and float(np.sum(((amps - mean) / se) ** 2)) > chi2_dist.isf(LINE_SPREAD_ALPHA, nf - 1):
        return None
    return gain, mean


def line_values(rec: Recording, res: Residuals, m: Measurement, sigma: float) -> list[NDArray[np.float64]]:
    """Each file's fitted hum [m] at every sample (fitted beside a slope per file), for the rest
    without it (its colour, its slope)."""
    if not m.lines_Hz:
        return [np.zeros(e.n_samples) for e in rec.experiments]
    cols = [Measurement(lines_Hz=m.lines_Hz).columns(e.t) for e in rec.experiments]
    jt = res.joint(replace(m, lines_Hz=()), _beside_slopes(rec, cols), sigma)
    return [X @ jt.of_file(f)[0][: X.shape[1]] for f, X in enumerate(cols)]


def find_drift(res: Residuals, m: Measurement, sigma: float) -> tuple[bool, tuple[float, ...], bool]:
    """A sensor zero drifting within each file: (per-file slopes significant beyond one slope
    common to every file, each file's drift over its length [m], a common slope significant). A
    common slope alone is the catalogue's thermal drift (a device property, left to it). The hum
    of `m`'s lines (:func:`line_values`) is taken off each rest before its slope is read (a 2 ms
    rest holds a tenth of a 50 Hz period: a slope of its own)."""
    from scipy.stats import chi2 as chi2_dist

    exps = res.rec.experiments
    nf = len(exps)
    jt, differ, common_sig = _slopes_tested(res, m, sigma)
    if not differ:
        return False, (), common_sig
    # a zero drifts before the drive as it does after: each file's slope over its rest (the
    # device still) must agree with its slope over the whole file. A missing effect puts a
    # trend into the residual of the moving part only
    hum = line_values(res.rec, res, replace(m, drift=False), sigma)
    z2 = 0.0
    for f, e in enumerate(exps):
        c, se_file = jt.of_file(f)
        x = e.x - hum[f]
        tr = e.t[e.rest_mask]
        slope, se = rest_slope(tr, x[e.rest_mask], m.whiten, sigma)
        if math.isfinite(slope):
            q = rounding_slope(res.rec.resolution_m, float(tr[-1] - tr[0]))
            z2 += (slope - float(c[0])) ** 2 / (se * se + q * q + float(se_file[0]) ** 2)
    if z2 > chi2_dist.isf(DRIFT_REST_ALPHA, nf):
        return False, (), common_sig
    drift = tuple(float(jt.of_file(f)[0][0]) * float(e.t[-1] - e.t[0]) for f, e in enumerate(exps))
    return True, drift, common_sig


def _slopes_tested(res: Residuals, m: Measurement, sigma: float) -> tuple["Joint", bool, bool]:
    """Each file's slope fitted (jointly, beside `m`'s nuisances and the calibrated parameters):
    (the fit, the slopes differ significantly beyond one common to every file, the common one
    is significant)."""
    from scipy.stats import chi2 as chi2_dist

    nf = len(res.rec.experiments)
    jt = res.joint(m, _slopes(res.rec), sigma)
    ones = np.ones(nf)
    common = float(ones @ jt.b) ** 2 / max(float(ones @ jt.A @ ones), 1e-300)
    common_sig = common > chi2_dist.isf(MEASUREMENT_ALPHA, 1)
    return jt, nf >= 2 and jt.gain - common > chi2_dist.isf(MEASUREMENT_ALPHA, nf - 1), common_sig


def slopes_differ(res: Residuals, m: Measurement, sigma: float) -> bool:
    """Whether the files' slopes of `res` differ significantly beyond one slope common to every
    file (the first half of :func:`find_drift`; the rest's check is the drift's, not this)."""
    return _slopes_tested(res, m, sigma)[1]


def rounding_slope(resolution: float, span: float) -> float:
    """The 1-sigma error [m/s] a reading's rounding puts into the slope of a still segment of
    `span` [s]: where the noise is too small to dither it, the rounding error is no white noise
    but the staircase of the slow motion, a ramp of up to one step over the segment (a size
    uniform in +-resolution: resolution / sqrt(3)). A 2 ms rest read at 6 nm with 1.4 nm noise
    gave slopes 6-17 nm (over the file) off the file's own, at a white-noise error of 5 nm."""
    return resolution / math.sqrt(3.0) / max(span, 1e-300)


def rest_slope(t: NDArray[np.float64], x: NDArray[np.float64], whiten: Whitener, sigma: float
               ) -> tuple[float, float]:
    """Slope [m/s] of a still segment (generalised least squares in the noise's colour) and its
    standard error; NaN where the segment is too short."""
    if t.size < 8:
        return math.nan, math.inf
    B = np.stack([np.ones(t.size), t - t.mean()], axis=1)
    Bw, xw = whiten(B.T).T, whiten(x - x.mean())
    cov = np.linalg.inv(Bw.T @ Bw) * sigma**2
    return float(np.linalg.lstsq(Bw, xw, rcond=None)[0][1]), math.sqrt(float(cov[1, 1]))


def find_delay(res: Residuals, m: Measurement, sigma: float) -> tuple[float, float, float]:
    """The displacement channel's delay behind the voltage [s] by a scan of the prediction's
    shift (no simulation: the reading is the same motion, read late), refined by a parabola
    through the best three; the chi^2 it gains over none, and the chi^2 it leaves."""
    taus = np.arange(-DELAY_RANGE_S, DELAY_RANGE_S + 0.5 * DELAY_STEP_S, DELAY_STEP_S)
    c = np.array([res.chi2(m.with_delay(float(t)), sigma) for t in taus])
    c0 = res.chi2(m.with_delay(0.0), sigma)
    k = int(np.argmin(c))
    tau = float(taus[k])
    if 0 < k < taus.size - 1:
        den = c[k - 1] - 2.0 * c[k] + c[k + 1]
        if den > 0:
            tau += 0.5 * DELAY_STEP_S * (c[k - 1] - c[k + 1]) / den
    best = min(res.chi2(m.with_delay(tau), sigma), float(c[k]))
    return tau, c0 - best, best


def delay_significant(gain: float, delay_s: float) -> bool:
    """A delay that lowers chi^2 significantly and is long enough to be one (DELAY_MIN_S)."""
    from scipy.stats import chi2 as chi2_dist

    return gain > chi2_dist.isf(MEASUREMENT_ALPHA, 1) and abs(delay_s) >= DELAY_MIN_S


# --- everything, in order ----------------------------------------------------------------------------


@dataclass
class Learned:
    """What :func:`learn` found: the recording cleaned of spikes, the measurement every fit
    applies from the start (the noise's colour), the artefacts that may explain what the verdict
    would blame on physics (lines, a drifting zero, a delay: weighed against the verdict by the
    caller), and the report's account."""

    rec: Recording
    measurement: Measurement
    model: NoiseModel
    lines_Hz: tuple[float, ...]  #: hum lines found
    drift: bool  #: per-file zero slopes are significant
    delay_s: float
    delay_gain: float  #: chi^2 the delay gains over none

    @property
    def artefacts(self) -> bool:
        """Anything beyond the colour that could stand in for missing physics."""
        return bool(self.lines_Hz) or self.drift or delay_significant(self.delay_gain, self.delay_s)

    @property
    def weighable(self) -> bool:
        """Something a verdict that blames physics is weighed against: an artefact, or a colour
        (estimated from a short rest, to be estimated again from the null's residual)."""
        return self.artefacts or self.measurement.whiten.order > 0


def _confirmed(colour: Optional[Colour], res: Residuals, m: Measurement) -> bool:
    """A colour found on the rest stands when its evidence is well past the test's critical value,
    or when it whitens the calibrated residual (COLOUR_CONFIRM_LR)."""
    from scipy.stats import chi2 as chi2_dist

    if colour is None or colour.rho.size < 2:
        return True
    if colour.lr > COLOUR_CONFIRM_LR * chi2_dist.isf(MEASUREMENT_ALPHA, colour.rho.size - 1):
        return True
    return whitens(res, m)


def whitens(res: Residuals, m: Measurement) -> bool:
    """Whether the colour of `m` (read off the short rest before the drive: a few hundred samples
    per file) makes the calibrated residual (thousands) whiter, by the lag-1 test on each file's
    residual with its nuisances removed. White noise's rest passes the colour test now and then
    (the order chosen by AIC: a healthy LPS+h, 1.9 nm white, gave AR(2), lag-1 -0.09, LR 18.8
    against 18.4), and whitening a white residual by it makes the residual look systematic
    (whiteness z -1.9 -> 6.4, a false alarm): such a colour is not the noise's. A coloured
    noise's own model whitens its residual, whatever else the residual holds."""
    if m.whiten.order == 0:
        return True
    z = []
    for metric in (Measurement(), m):
        ws = [res.profile(metric, f).residual(e.x - metric.shifted(p, res.rec.sample_step))[0]
              for f, (e, p) in enumerate(zip(res.rec.experiments, res.preds))]
        z.append(abs(whiteness_z(ws)))
    return z[1] <= z[0]


def learn(rec: Recording, preds: Sequence[NDArray[np.float64]], sigma: float,
          jac_of: Optional[Callable[[Recording, Measurement], Optional[NDArray[np.float64]]]] = None) -> Learned:
    """The noise model from the recording and the calibrated model's prediction `preds` (per
    experiment), with the white-noise level `sigma` [m] estimated so far: spikes rejected, the
    hum found, the colour fitted to the rest without the hum, the hum re-tested in that colour,
    a drifting zero and a channel delay tested."""
    rec, n_out = reject_spikes(rec, preds)
    cleaned = rec
    res = Residuals.of(rec, preds, (lambda m: jac_of(cleaned, m)) if jac_of is not None else None)
    colour = fit_colour(rest_segments(rec))
    white = Measurement()

    def measurement_of(c: Optional[Colour]) -> tuple[Measurement, float]:
        if c is None or c.rho.size < 2:
            return white, (c.sigma if c is not None else sigma)
        return Measurement(whiten=Whitener.from_acf(c.rho, c.rho.size - 1)), c.sigma

    colour = colour if _confirmed(colour, res, measurement_of(colour)[0]) else None
    m, s = measurement_of(colour)
    s = s if colour is not None else sigma
    lines = find_lines(res, m, s)
    if lines:
        # the colour again, of the rest without the hum, and the hum tested in it
        colour = fit_colour(rest_segments(rec, line_values(rec, res, replace(m, lines_Hz=tuple(
            f for f, _ in lines)), s)))
        colour = colour if _confirmed(colour, res, measurement_of(colour)[0]) else None
        m, s = measurement_of(colour)
        s = s if colour is not None else sigma
        lines = find_lines(res, m, s) or lines
    rho = colour.rho if colour is not None and colour.rho.size > 1 else np.ones(1)
    model = NoiseModel(
        sigma=s if colour is not None and colour.rho.size > 1 else sigma, order=int(rho.size - 1),
        lag1=float(rho[1]) if rho.size > 1 else 0.0, rho=tuple(float(v) for v in rho), lines=lines,
        resolution=float(rec.resolution_m), outliers=n_out)
    return _with_artefacts(res, m, s, lines, model)


def _with_artefacts(res: Residuals, m: Measurement, s: float, lines: tuple[tuple[float, float], ...],
                    model: NoiseModel) -> Learned:
    """What :func:`learn` found, the delay and a drifting zero tested on `res` in the metric of
    `m` (noise level `s` [m]) beside the hum `lines`, into `model`."""
    with_lines = replace(m, lines_Hz=tuple(f for f, _ in lines))
    # the delay before the drift: a late reading leaves a trend of its own in each file (the slow
    # phase read late), which the drift test would take for a drifting zero
    tau, gain, _ = find_delay(res, with_lines, s)
    drift, drift_m, common = find_drift(res, with_lines.with_delay(tau) if delay_significant(gain, tau) else with_lines,
                                        s)
    notes = [n for n in model.notes if "drifts alike" not in n]
    if common and not drift:
        notes.append("the reading drifts alike in every file: a sensor zero drifting so cannot be told "
                     "from the catalogue's thermal drift")
    model = replace(model, lines=lines, delay_s=tau, drift_m=drift_m if drift else (), notes=tuple(notes))
    return Learned(res.rec, m, model, with_lines.lines_Hz, drift, tau, gain)


def relearn(rec: Recording, preds: Sequence[NDArray[np.float64]], sigma: float, found: Learned,
            jac_of: Optional[Callable[[Recording, Measurement], Optional[NDArray[np.float64]]]] = None) -> Learned:
    """The hum, a drifting zero and a delay tested again against a later null's prediction
    `preds` on the recording as cleaned (`rec`, its colour kept: `found.measurement`): the null
    the calibration returned can sit far from the data (four values mis-set: 29 x noise, a
    residual whose slopes were its own misfit) where the null refitted from the candidates'
    optima reaches noise."""
    res = Residuals.of(rec, preds, (lambda m: jac_of(rec, m)) if jac_of is not None else None)
    m = replace(found.measurement, lines_Hz=(), drift=False, delay_s=0.0)
    return _with_artefacts(res, m, sigma, find_lines(res, m, sigma), found.model)

