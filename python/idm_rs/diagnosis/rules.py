"""The small rules every stage applies to candidates: supported (ΔBIC, present), explaining the
residual (noise and white), their rank order, and whether the null itself leaves noise."""

from __future__ import annotations

import math

from .problem import CalibratedNull, Problem, Refit
from .results import Candidate
from .thresholds import (
    BIC_THRESHOLD,
    NOISE_RATIO_OK,
    WHITENESS_Z,
)


def leaves_noise(rms: float, wz: float, sigma: float) -> bool:
    """A residual of RMS `rms` [m] and lag-1 whiteness z `wz` is noise of level `sigma` [m]: at
    most NOISE_RATIO_OK x sigma and white (z at most WHITENESS_Z)."""
    return rms <= NOISE_RATIO_OK * sigma and wz <= WHITENESS_Z


def null_leaves_noise(pb: Problem, cal: CalibratedNull) -> bool:
    """The calibrated null's residual is noise: nothing large is compensated by far-off nominal
    values, so a candidate's least squares from the null it contains needs no global search."""
    return leaves_noise(cal.fit.rms, cal.whiteness_z, pb.sigma)


def better_of(a: list[Refit], b: list[Refit]) -> list[Refit]:
    """Per effect, the fitted candidate with the lower chi^2 of two rounds."""
    out = {r.candidate.effect: r for r in a}
    for r in b:
        old = out.get(r.candidate.effect)
        if old is None or (not r.candidate.screened_only
                           and (old.candidate.screened_only or r.candidate.chi2 < old.candidate.chi2)):
            out[r.candidate.effect] = r
    return list(out.values())


def candidate_explains(pb: Problem, c: Candidate) -> bool:
    """A supported candidate whose fit leaves noise (as the verdict requires)."""
    return is_eligible(c) and leaves_noise(c.rms_after, c.whiteness_z, pb.sigma)


def is_finite(x: float) -> bool:
    return isinstance(x, float) and math.isfinite(x)


def is_eligible(c: Candidate) -> bool:
    return not c.screened_only and c.present and c.delta_bic >= BIC_THRESHOLD


def by_rank(refits: list[Refit]) -> list[Refit]:
    """Refitted candidates first, present ones before those at or near "no effect", by ΔBIC."""
    return sorted(refits, key=lambda r: (r.candidate.screened_only, not r.candidate.present, -r.candidate.delta_bic))
