"""The whiteness test under a coarse reading: noise smaller than the resolution's step leaves the
rounding undithered, and its mean error — a function of where the reading's expectation falls
between two steps — is the same sample after sample while the body sticks. A right model's
residual then reads as correlated; with the objective given, :func:`whiteness_z` takes that mean
error out first, and keeps what a missing effect leaves."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np

from idm_rs.diagnosis.whiteness import whiteness_z

STEP = 8e-9  # the reading's resolution [m]


def _stick_slip(n: int) -> np.ndarray:
    """A main body's motion [m]: slips of 0.5 nm per sample between sticks creeping 2 pm per
    sample (the phase within a step moves fast in a slip and stays while the body sticks)."""
    t = np.arange(n)
    return 1.3e-9 + np.cumsum(np.where((t // 200) % 3 == 0, 0.5e-9, 0.002e-9))


def _read(noise_over_step: float, seed: int, missing: float = 0.0) -> tuple[list[np.ndarray], SimpleNamespace]:
    """The residual of the model (the true motion less `missing` x step of a slow sine) against
    the motion read with white noise and rounded to STEP; the objective it is of."""
    rng = np.random.default_rng(seed)
    y = _stick_slip(6000)
    x = STEP * np.round((y + rng.normal(0.0, noise_over_step * STEP, y.size)) / STEP)
    model = y - missing * STEP * np.sin(2 * np.pi * np.arange(y.size) / 900)
    rec = SimpleNamespace(resolution_m=STEP, experiments=[SimpleNamespace(x=x)])
    return [x - model], SimpleNamespace(recording=rec, experiments=[0], measurement=None)


def test_a_right_models_residual_under_an_undithered_rounding_reads_white_once_its_mean_error_is_out():
    for noise in (0.15, 0.2):
        plain, taken = zip(*[(whiteness_z(r), whiteness_z(r, of)) for r, of in (_read(noise, s) for s in range(20))])
        assert np.mean(plain) > 5.0  # the rounding's mean error alone fails the test (WHITENESS_Z 4)
        assert abs(np.mean(taken)) < 0.8 and max(abs(z) for z in taken) < 4.0


def test_a_missing_effect_under_a_coarse_reading_still_reads_systematic():
    for s in range(5):
        r, of = _read(0.2, s, missing=0.3)
        assert whiteness_z(r, of) > 8.0


def test_a_fine_reading_and_a_whitened_residual_are_tested_as_they_are():
    r, of = _read(0.6, 0)  # noise of 0.6 step: the rounding is dithered, the step below 2 x RMS
    assert whiteness_z(r, of) == whiteness_z(r)
    r, of = _read(0.2, 0)
    whitened = SimpleNamespace(recording=of.recording, experiments=[0], measurement=object())
    assert whiteness_z(r, whitened) == whiteness_z(r)
