"""A named set's look-alikes (two or three effects), judged where each effect stands.

The first round compares effects' signatures at the calibrated null, which compensates for every
missing effect at once; with several effects missing it can bend a twin toward or away from the
one it resembles. After a set is named, each of its effects is compared with the others at the
model with the set's *other* effects in place (screened there), and every effect whose signature
is near (|cos| >= TWIN_CHECK_COS) is refitted in its place: where the set with the twin instead
leaves noise, or is within SEPARATION of the set, the data cannot tell them apart and the twin is
an alternative; where it leaves a systematic residual, the data separate them and the reason
says so with the figures."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Optional

from .case_model import ModelSpec
from .catalogue import CATALOGUE
from .fitting import FitResult, FreeParam, fit
from .problem import Problem
from .screening import Screened, screen
from .thresholds import NOISE_RATIO_OK, SEPARATION, TWIN_CHECK_COS, TWIN_NFEV


@dataclass(frozen=True)
class Twin:
    """An effect of a named set (`member`) and a look-alike (`twin`) refitted in its place."""

    member: str
    twin: str
    cos: float  #: |cos| of their projected signatures at the model with the set's other effects
    chi2: float  #: the set with `twin` in place of `member`, refitted
    chi2_pair: float  #: the named set's
    rms: float  #: that refit's residual RMS [m]
    sigma: float  #: the noise RMS [m]

    @property
    def stands(self) -> bool:
        """The data cannot tell them apart: in its place the twin leaves noise as well, or comes
        within SEPARATION of the set."""
        return self.rms <= NOISE_RATIO_OK * self.sigma or self.chi2 - self.chi2_pair < SEPARATION

    def words(self) -> str:
        if self.stands:
            return (f"{self.twin} in place of {self.member} fits as well (RMS {self.rms / self.sigma:.2f} x noise, "
                    f"Δχ² {self.chi2 - self.chi2_pair:.0f}; |cos| = {self.cos:.3f} beside the others)")
        return (f"{self.twin} in place of {self.member} leaves a systematic residual (RMS "
                f"{self.rms / self.sigma:.2f} x noise, Δχ² {self.chi2 - self.chi2_pair:.0f} against the named effects; "
                f"|cos| = {self.cos:.3f} beside the others): the data tell them apart")

    def to_dict(self) -> dict[str, Any]:
        return {"member": self.member, "twin": self.twin, "cos": self.cos, "chi2": self.chi2,
                "chi2_pair": self.chi2_pair, "rms": self.rms, "stands": self.stands}


def look_alikes(pb: Problem, without: FitResult, at: list[FreeParam], member: str, others: set[str],
                also: set[str]) -> Optional[list[tuple[Screened, float]]]:
    """The look-alikes of `member` where the `others` stand: at the model with them alone
    (`without`, its free parameters `at`), every effect not among them screened beside `member`;
    those whose projected signature is within TWIN_CHECK_COS of `member`'s, or that are in `also`
    (the first round's twins of it), with their |cos|, nearest first. None where `member` has
    no signature there."""
    import numpy as np

    structure, params = without.spec.structure, without.spec.params
    effects = [e for e in CATALOGUE if e.id not in others and e.applies(structure, params)]
    screened = {s.effect.id: s for s in screen(pb.obj, without, at, effects, pb.sigma, pb.tick)}
    own = screened.get(member)
    if own is None or own.direction is None:
        return None
    out: list[tuple[Screened, float]] = []
    for eid, s in screened.items():
        if eid == member or s.direction is None:
            continue
        cos = abs(float(np.dot(own.direction, s.direction)))
        if cos >= TWIN_CHECK_COS or eid in also:
            out.append((s, cos))
    return sorted(out, key=lambda sc: -sc[1])


def twins_in_place(pb: Problem, without: FitResult, at: list[FreeParam], member: str, others: set[str],
                   chi2_pair: float, also: set[str]) -> Optional[list[Twin]]:
    """The look-alikes of `member`, one effect of a named set whose fit has chi^2 `chi2_pair`
    (:func:`look_alikes` at the model with the `others` alone), each refitted there in its place
    (:func:`in_place`). None where `member` has no signature there (nothing judged)."""
    found = look_alikes(pb, without, at, member, others, also)
    if found is None:
        return None
    out: list[Twin] = []
    for s, cos in found:
        r, _, _ = in_place(pb, without, at, s)
        out.append(Twin(member, s.effect.id, cos, r.chi2, chi2_pair, r.rms, pb.sigma))
    return out


def first_round_twins(member: str, first_round: list[tuple[str, str, float]]) -> set[str]:
    """The effects the first round found near-parallel to `member`."""
    return {b if a == member else a for a, b, _ in first_round if member in (a, b)}


def in_place(pb: Problem, without: FitResult, at: list[FreeParam], s: Screened
             ) -> tuple[FitResult, ModelSpec, list[FreeParam]]:
    """The effect screened as `s` added to the model `without` (its free parameters `at`) and
    refitted from its screened step (TWIN_NFEV evaluations): (the fit, its model, its start)."""
    eff = s.effect
    base = ModelSpec(eff.structure(without.spec.structure), dict(without.spec.params), dict(without.spec.effects))
    start = list(at) + [ep.free(v) for ep, v in zip(eff.params, s.estimate)]
    return fit(pb.obj, base, start, max_nfev=TWIN_NFEV, progress=pb.tick), base, start


def judge_set(pb: Problem, placed: list[tuple[str, set[str], FitResult, list[FreeParam]]], chi2_set: float,
              first_twins: list[tuple[str, str, float]]) -> tuple[list[Twin], list[str], str]:
    """Every effect of a named set judged against its look-alikes in its place: `placed` holds,
    per member, (member, the set's other effects, the fit of the model with those others alone,
    its free parameters at it); `chi2_set` the named set's chi^2. Returns (the twins refitted, the
    members judged, what the data separate in words: "; ..." or "")."""
    twins: list[Twin] = []
    judged: list[str] = []
    for member, others, fit_, at in placed:
        found = twins_in_place(pb, fit_, at, member, others, chi2_set, first_round_twins(member, first_twins))
        if found is not None:
            twins += found
            judged.append(member)
    return twins, judged, "".join(f"; {t.words()}" for t in twins if not t.stands)


def judged_pairs(degenerate: list[tuple[str, str, float]], twins: list[Twin], judged: set[str]
                 ) -> list[tuple[str, str, float]]:
    """The near-parallel pairs an alternative to a named set is read from: the first round's,
    except that an effect of the set judged in place (`judged`) is paired only with the twins
    that stood there (the refit in place supersedes the first-order angle at the calibrated null)."""
    kept = [p for p in degenerate if not ({p[0], p[1]} & judged)]
    return sorted(kept + [(t.member, t.twin, t.cos) for t in twins if t.stands], key=lambda p: -p[2])
