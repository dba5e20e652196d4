"""Two fits that are not nested weighed (diagnosis/closer.py): Vuong's z about N(0, 1) where both
predictions are as far from the truth and large where one is the truth, its spread kept near 1
under correlated noise by the autocovariance it counts; Cox's tests choose the true model where
the two differ by a few noise units, and neither where the data lie between them."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.signal import lfilter

from idm_rs.diagnosis.closer import contest

N = 4000
T = np.linspace(0.0, 1.0, N)
#: the two models' difference: a smooth signature (as a delay against a lag), sum of squares 400
DELTA = np.sin(2 * np.pi * 3 * T) * np.exp(-2 * T)
DELTA *= 20.0 / np.linalg.norm(DELTA)


def _zs(noise: np.ndarray, truth_is_b: bool, lags: int) -> np.ndarray:
    out = []
    for e in noise:
        # residual = data - prediction; a and b sit at +-delta/2 about the truth, or b on it
        r_a, r_b = (e - DELTA, e) if truth_is_b else (e - DELTA / 2, e + DELTA / 2)
        out.append(contest(r_a, r_b, lags).z)
    return np.array(out)


def test_two_fits_equally_far_give_a_standard_normal() -> None:
    # the spread is read off b's residual, which holds half the signature here: a little wide
    # (z's spread 0.83), on the side of calling them alike
    z = _zs(np.random.default_rng(1).standard_normal((400, N)), truth_is_b=False, lags=20)
    assert abs(z.mean()) < 0.2 and 0.75 < z.std() < 1.1


def test_the_true_model_is_found_closer_by_half_the_root_of_the_difference() -> None:
    # chi2_a - chi2_b = |delta|^2 + 2 delta.e: mean 400, spread 2 |delta| = 40 -> z about 10
    z = _zs(np.random.default_rng(2).standard_normal((100, N)), truth_is_b=True, lags=20)
    assert 9.0 < z.mean() < 11.0 and z.min() > 6.0


def test_correlated_noise_is_counted_in_the_spread() -> None:
    # AR(1) noise of lag-1 0.8: without lags the chi^2 difference looks 3 x surer than it is
    e = lfilter([1.0], [1.0, -0.8], np.random.default_rng(3).standard_normal((400, N)), axis=1)
    e *= np.sqrt(1 - 0.8**2)
    assert _zs(e, truth_is_b=False, lags=0).std() > 2.5
    assert 0.7 < _zs(e, truth_is_b=False, lags=20).std() < 1.3


def test_residuals_over_different_samples_are_refused() -> None:
    with pytest.raises(ValueError, match="same samples"):
        contest(np.zeros(10), np.zeros(11), 5)


def _contests(d_norm: float, truth_at: float, n_draws: int, seed: int) -> list:
    """Contests of a (at 0) and b (at d_norm along DELTA's direction) on data at `truth_at`
    along it (0: a is the truth, d_norm: b is, between: neither)."""
    u = DELTA / np.linalg.norm(DELTA)
    out = []
    for e in np.random.default_rng(seed).standard_normal((n_draws, N)):
        y = truth_at * u + e
        out.append(contest(y, y - d_norm * u, lags=20))
    return out


def test_cox_chooses_a_true_model_that_vuong_alone_would_not() -> None:
    # D = 49 (a lag 7 noise units from the delay): Vuong's z is 3.5 on average, under 3 a
    # third of the time; Cox rejects a every time and b (at 2) 2.3 % of the time, mostly where
    # Vuong's z is past 3
    b_true = _contests(7.0, 7.0, 200, 4)
    assert np.mean([c.z > 3 for c in b_true]) < 0.9
    assert np.mean([c.b_stands(3.0, 2.0) for c in b_true]) > 0.97
    a_true = _contests(7.0, 0.0, 200, 5)
    assert not any(c.b_stands(3.0, 2.0) for c in a_true)


def test_data_between_the_two_fits_choose_neither() -> None:
    # the data halfway: both rejected by Cox (D = 100, each 5 units off), Vuong's z about N(0, 1)
    between = _contests(10.0, 5.0, 200, 6)
    assert np.mean([c.b_stands(3.0, 2.0) for c in between]) < 0.01
    assert np.mean([c.z_against_a > 3 and c.z_against_b < -3 for c in between]) > 0.9
