"""The third effect: after two effects are supported together but leave a systematic residual, a
third catalogue effect searched from the model with the pair, named only under the second
round's rules (a residual at noise, the held-out experiment predicted better than with the
pair) plus each of the pair paying its own way beside the other two."""

from __future__ import annotations

from .case_model import ModelSpec
from .catalogue import CATALOGUE, Effect
from .fitting import FreeParam, fit
from .problem import CalibratedNull, HeldOut, Problem, Refit
from .results import SecondSearch, ThirdSearch
from .rules import candidate_explains, is_eligible, is_finite
from .second_effect import round_beside
from .thresholds import BIC_THRESHOLD, POLISH_NFEV


def wants_third(pb: Problem, second: SecondSearch) -> bool:
    """A pair that both effects support (each pays its own way, the second over the first by
    BIC_THRESHOLD) but that leaves a systematic residual: a third effect may be missing."""
    pair = second.pair
    return (not second.named and pair is not None and second.base is not None and is_eligible(pair)
            and not candidate_explains(pb, pair) and is_finite(second.over_second_alone)
            and second.over_second_alone >= BIC_THRESHOLD)


def search_third_effect(pb: Problem, cal: CalibratedNull, second: SecondSearch, heldout: HeldOut) -> ThirdSearch:
    """A third catalogue effect from the model with the pair (`second`): the pair's optimum is
    the null of a third round (screening, multistart fits of the SECOND_TOP best scored, the
    polish); the triple is named when it leaves noise, predicts the held-out experiment better
    than the pair, and dropping either of the pair's effects (the other two refitted from the
    triple's values) costs BIC_THRESHOLD."""
    pair = second.pair
    assert pair is not None and second.base is not None  # wants_third
    names = (second.first.effect, pair.effect)
    out = ThirdSearch(pair=names, pair_heldout_rms=second.heldout_rms)
    _, _, ranked = round_beside(pb, cal, second.base, second.free, set(names), wide=False)
    if ranked is None:
        out.reason = f"no other catalogue effect applies beside {names[0]} and {names[1]}"
        return out
    out.ranking = [r.candidate for r in ranked]
    best = next((r for r in ranked if is_eligible(r.candidate)), None)
    if best is None:
        top = ranked[0].candidate if ranked else None
        out.reason = (f"no third effect is supported beside {names[0]} and {names[1]}"
                      + (f" (best: {top.effect}, ΔBIC {top.delta_bic:.0f} over the pair)" if top else ""))
        return out
    return judge_triple(pb, cal, out, best, heldout)


def without(cal: CalibratedNull, keep: list[Effect], triple: Refit) -> tuple[ModelSpec, list[FreeParam]]:
    """The model of the effects `keep` (on the calibrated null's model) and its free parameters
    at the triple's values: the calibrated subset and the kept effects' own."""
    structure = cal.fit.spec.structure
    for e in keep:
        structure = e.structure(structure)
    own = {ep.name for e in keep for ep in e.params} | {f.name for f in cal.free}
    return (ModelSpec(structure, dict(cal.fit.spec.params), dict(cal.fit.spec.effects)),
            [f for f in triple.free if f.name in own])


def judge_triple(pb: Problem, cal: CalibratedNull, out: ThirdSearch, best: Refit, heldout: HeldOut) -> ThirdSearch:
    """The rules a triple must pass to be named (`best`: its refit, scored against the pair)."""
    third = best.candidate
    out.third, out.free, out.base = third, best.free, best.base
    by_id = {e.id: e for e in CATALOGUE}
    members = [by_id[n] for n in (*out.pair, third.effect)]
    for e in members[:2]:
        base, start = without(cal, [m for m in members if m is not e], best)
        r = fit(pb.obj, base, start, max_nfev=POLISH_NFEV, progress=pb.tick)
        out.over_without[e.id] = (r.chi2 + (len(start) + pb.n_offsets) * pb.ln_n) - third.bic
    out.heldout_rms = third.heldout_rms = heldout.rms(best.base, best.free)
    sigma = pb.sigma
    trio = f"{third.effect} beside {out.pair[0]} and {out.pair[1]}"
    weakest = min(out.over_without, key=lambda k: out.over_without[k])
    if not candidate_explains(pb, third):
        out.reason = (f"{trio} improves BIC by {third.delta_bic:.0f} but leaves a systematic residual (RMS "
                      f"{third.rms_after / sigma:.2f} x noise, whiteness z = {third.whiteness_z:.1f})")
    elif is_finite(out.heldout_rms) and is_finite(out.pair_heldout_rms) and out.heldout_rms > out.pair_heldout_rms:
        out.reason = (f"{trio} leaves noise but does not predict the held-out experiment better "
                      f"({out.pair_heldout_rms * 1e9:.2f} → {out.heldout_rms * 1e9:.2f} nm)")
    elif out.over_without[weakest] < BIC_THRESHOLD:
        out.reason = (f"{trio} leaves noise, but without {weakest} the other two fit nearly as well (ΔBIC "
                      f"{out.over_without[weakest]:.0f} < {BIC_THRESHOLD:g}): {weakest} does not pay its own way")
    else:
        out.named = True
        out.reason = (f"three effects: {out.pair[0]}, {out.pair[1]} and {third.effect}. With all three the residual "
                      f"is noise (RMS {third.rms_after / sigma:.2f} x noise); {third.effect} improves BIC by "
                      f"{third.delta_bic:.0f} over the pair, dropping {out.pair[0]} or {out.pair[1]} costs ΔBIC "
                      f"{out.over_without[out.pair[0]]:.0f} and {out.over_without[out.pair[1]]:.0f}, and the held-out "
                      f"experiment is predicted better ({out.pair_heldout_rms * 1e9:.2f} → "
                      f"{out.heldout_rms * 1e9:.2f} nm)")
    return out
