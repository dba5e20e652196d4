"""The experiments the diagnosis proposes: the drive that separates the verdict from its
alternative, the one that determines an undetermined effect parameter, and the one after which
a found form's held-out check would be decided (:mod:`.next_experiment` does the search)."""

from __future__ import annotations

import math
from typing import Optional

import numpy as np

from .catalogue import CATALOGUE
from .discovery import Discovery
from .fitting import apply
from .next_experiment import ParameterProposal, Proposal, propose, propose_for_heldout, propose_for_parameter
from .problem import Problem, Refit, heldout_index
from .rules import is_finite
from .thresholds import (
    BIC_THRESHOLD,
    NOISE_RATIO_OK,
)


def separating_experiment(pb: Problem, refits: list[Refit], winner: str, other: str) -> Optional[Proposal]:
    """The drive that best separates the verdict's refit from its alternative's
    (:mod:`.next_experiment`), each at its own optimum with its own free parameters."""
    by_id = {r.candidate.effect: r for r in refits if not r.candidate.screened_only}
    if winner not in by_id or other not in by_id:
        return None
    models = []
    for r in (by_id[winner], by_id[other]):
        models.append((apply(r.base, r.free, np.zeros(len(r.free))), list(r.free)))
    return propose(pb.rec, pb.sigma, (winner, other), models[0], models[1])


def look_alike_experiment(pb: Problem, found: Discovery) -> Optional[Proposal]:
    """For a discovered form whose look-alike, refitted in its place, fits as well
    (:attr:`Discovery.look_alike`: a force c V and the PE's extension x1 - x2 on slow drives),
    the drive that best separates the two refitted models (:mod:`.next_experiment`)."""
    alt = found.look_alike
    if not found.discovered or alt is None or found.refit is None or alt.refit is None:
        return None
    if found.form is None or alt.form is None:
        return None
    names = (" + ".join(t.symbol for t in found.form.terms), " + ".join(t.symbol for t in alt.form.terms))
    return propose(pb.rec, pb.sigma, names, (found.refit.spec, found.free), (alt.refit.spec, alt.free))


def travel_experiment(pb: Problem, found: Discovery) -> Optional[ParameterProposal]:
    """For a discovery that did not stand because a form that leaves noise on every recording
    failed the held-out prediction, the drive after which the held-out check's training
    experiments would determine the form's least determined parameter (the wavelength of a
    periodic form; else the library coefficient with the largest relative 1-sigma):
    :func:`.next_experiment.propose_for_heldout`. The form is the one with the lowest RMS of
    those that leave noise and gain by BIC. None when no form left noise."""
    sigma = pb.sigma
    forms = [t for t in [found, *found.tried] if t.refit is not None and t.form is not None and t.form.terms
             and t.free and t.delta_bic >= BIC_THRESHOLD and t.rms_after <= NOISE_RATIO_OK * sigma
             and is_finite(t.heldout_rms_after) and t.heldout_rms_after > NOISE_RATIO_OK * sigma]
    if not forms:
        return None
    best = min(forms, key=lambda t: t.rms_after)
    assert best.refit is not None and best.form is not None
    lib = {t.param for t in best.form.terms}
    if "lib_wavelength" in best.refit.values:
        name = "lib_wavelength"
    else:
        refit = best.refit
        name = max(lib, key=lambda n: (refit.std.get(n) or math.inf) / max(abs(refit.values[n]), 1e-300))
    p = propose_for_heldout(pb.rec, pb.sigma, name, (best.refit.spec, best.free), heldout_index)
    terms = ", ".join(t.symbol for t in best.form.terms)
    if p is not None and p.heldout_now <= NOISE_RATIO_OK:
        # the experiments determine the form's parameters (to first order the held-out check
        # should pass): what fails is the form or the refit's nonlinearity, which no drive of
        # the grid is predicted to mend (the 11.8 um periodic friction: "sin, Ff sin, cos"
        # predicted at 1.00 x, measured 1.21 x — the true form is Ff sin, Ff cos)
        found.reason += (f"; the form {terms} is determined by the experiments other than the held-out one (its "
                         f"held-out RMS predicted to first order at {p.heldout_now:.2f} x noise, measured "
                         f"{best.heldout_rms_after / sigma:.2f} x): the form, not the experiments, falls short")
        return None
    if p is not None:
        p.context = (f"the form {terms} leaves {best.rms_after / sigma:.2f} x noise on the recordings but, refitted "
                     f"without {pb.rec.experiments[heldout_index(pb.rec)].name}, predicts it at "
                     f"{best.heldout_rms_after / sigma:.2f} x noise: the other experiments leave {name} undetermined "
                     f"(its 1-sigma below is from the experiments the held-out check fits)")
    return p


def determining_experiment(pb: Problem, refits: list[Refit], verdict: str) -> Optional[ParameterProposal]:
    """For a verdict naming one catalogue effect with an effect parameter the experiments do not
    determine (identifiability), the drive that would best determine it."""
    r = next((x for x in refits if x.candidate.effect == verdict and not x.candidate.screened_only), None)
    if r is None:
        return None
    eff = next(e for e in CATALOGUE if e.id == verdict)
    names = {ep.name for ep in eff.params}
    weak = [p for p in r.candidate.identifiability if p.name in names and not p.determined]
    if not weak:
        return None
    spec = apply(r.base, r.free, np.zeros(len(r.free)))
    return propose_for_parameter(pb.rec, pb.sigma, weak[0].name, (spec, list(r.free)))
