"""The verdict from the ranked candidates and the calibrated null, the alternatives the data cannot
tell apart from it, and the ranking with the leader's held-out prediction."""

from __future__ import annotations

from .noise import NoiseEstimate
from .problem import CalibratedNull, HeldOut, Refit
from .results import Alternative, Candidate
from .rules import by_rank, is_eligible, is_finite, leaves_noise
from .thresholds import (
    BIC_THRESHOLD,
    LR_ALPHA,
    SEPARATION,
)


def rank_with_heldout(refits: list[Refit], heldout: HeldOut) -> list[Candidate]:
    """The candidates in rank order; the leading refitted one gets its held-out prediction."""
    refits = by_rank(refits)
    for r in [r for r in refits if is_eligible(r.candidate)][:1]:
        r.candidate.heldout_rms = heldout.rms(r.base, r.free)
    return [r.candidate for r in refits]


def alternatives_to(ranking: list[Candidate], verdict: str, degenerate: list[tuple[str, str, float]]
                  ) -> list[Alternative]:
    """Effects the data cannot tell apart from the verdict's: a supported candidate within
    SEPARATION in ΔBIC of it, or one whose screening direction is near-parallel to it. For a
    verdict of two effects, each effect's near-parallel twin, named with the one it could stand
    in for (:attr:`Alternative.replaces`)."""
    if "+" in verdict:
        return _pair_alternatives(ranking, verdict, degenerate)
    lead = next((c for c in ranking if c.effect == verdict), None)
    if lead is None:
        return []
    out: dict[str, Alternative] = {}
    for c in ranking:
        if c is lead or not is_eligible(c):
            continue
        if lead.delta_bic - c.delta_bic < SEPARATION:
            out[c.effect] = Alternative(c.effect, c.delta_bic, f"ΔBIC {c.delta_bic:.0f} against the leader's "
                                        f"{lead.delta_bic:.0f}, within {SEPARATION:g}")
    for a, b, cos in degenerate:
        other = b if a == verdict else a if b == verdict else None
        if other is None or other in out:
            continue
        match = next((x for x in ranking if x.effect == other), None)
        if match is not None and is_eligible(match):
            out[other] = Alternative(other, match.delta_bic,
                                     f"its signature is parallel to the leader's (|cos| = {cos:.3f})")
    return list(out.values())


def _pair_alternatives(ranking: list[Candidate], verdict: str, degenerate: list[tuple[str, str, float]]
                       ) -> list[Alternative]:
    """The near-parallel twins of a pair's effects (an incline beside a spring to ground named as
    friction asymmetry + spring: the data cannot choose the incline's twin over it). A twin must
    be supported by the data on its own (ΔBIC ≥ BIC_THRESHOLD, fitted or screened): alone, with
    the other effect missing, it need not leave noise."""
    named = verdict.split("+")
    out: dict[str, Alternative] = {}
    for a, b, cos in degenerate:
        for member, other in ((a, b), (b, a)):
            if member not in named or other in named or other in out:
                continue
            match = next((x for x in ranking if x.effect == other), None)
            if match is not None and match.delta_bic >= BIC_THRESHOLD:
                out[other] = Alternative(other, match.delta_bic, f"in place of {member}: its signature is parallel "
                                         f"to {member}'s (|cos| = {cos:.3f})", replaces=member)
    return list(out.values())


def decide_verdict(ranking: list[Candidate], cal: CalibratedNull, noise: NoiseEstimate, ho_cal: float,
             searched_wide: bool = False) -> tuple[str, str, float]:
    """An effect is the verdict only if it was fitted over everything, is present (its
    likelihood-ratio test against the null rejects "no effect" at LR_ALPHA), improves BIC over the best null by
    BIC_THRESHOLD and leaves noise. Otherwise "none" when the null leaves noise — a white
    residual at the noise floor: "none" never stands while the whiteness test flags structure;
    else "not_converged" when the calibration's local fits did not reach one optimum (the tool's
    fit failed), else "unexplained" (after the wider search of every candidate)."""
    sigma = noise.sigma
    fit, wz_cal = cal.fit, cal.whiteness_z
    cal_ratio = fit.rms / sigma
    cal_is_noise = leaves_noise(fit.rms, wz_cal, sigma)
    eligible = [c for c in ranking if is_eligible(c)]
    best = eligible[0] if eligible else None
    residual = f"RMS {cal_ratio:.2f} x noise, whiteness z = {wz_cal:.1f}"
    if best is None:
        if cal_is_noise:
            return ("none", f"after calibration the residual is noise ({residual}) and no effect is supported "
                    f"(ΔBIC ≥ {BIC_THRESHOLD:g} and a likelihood-ratio test against 'no effect' at {LR_ALPHA:g})",
                    fit.rms)
        if not cal.search.converged:
            return ("not_converged", f"the calibration did not converge ({cal.search.summary()}) and a systematic "
                    f"residual remains ({residual}); no verdict on missing physics", fit.rms)
        wide = " (every candidate fitted, the wider search)" if searched_wide else ""
        return ("unexplained", f"a systematic residual remains after a converged calibration ({residual}) and "
                f"no catalogue effect explains it{wide}", fit.rms)
    ratio = best.rms_after / sigma
    explained = leaves_noise(best.rms_after, best.whiteness_z, sigma)
    if not explained:
        if not cal.search.converged:
            return ("not_converged", f"the calibration did not converge ({cal.search.summary()}); the best effect "
                    f"({best.effect}) leaves RMS {ratio:.2f} x noise", fit.rms)
        return ("unexplained", f"the best effect ({best.effect}, ΔBIC {best.delta_bic:.0f}) leaves a systematic "
                f"residual (RMS {ratio:.2f} x noise, whiteness z = {best.whiteness_z:.1f})", fit.rms)
    others = [c for c in eligible[1:]]
    note = ""
    if others and best.delta_bic - others[0].delta_bic < SEPARATION:
        note = f"; runner-up {others[0].effect} is close (ΔBIC {others[0].delta_bic:.0f})"
    if is_finite(best.heldout_rms) and is_finite(ho_cal) and best.heldout_rms > ho_cal * 1.02:
        note += "; held-out prediction does not improve"
    return (best.effect, f"{best.effect} improves BIC by {best.delta_bic:.0f} over the best null fit and leaves noise "
            f"(RMS {ratio:.2f} x noise){note}", best.rms_after)
