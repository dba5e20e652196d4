"""The diagnosis beyond the catalogue around :mod:`.discovery`: where discovery starts, a found
term's gain taken against a refitted null, and whether a first effect is needed beside the
found term (or was spurious)."""

from __future__ import annotations

import time
from dataclasses import replace
from typing import NamedTuple, Optional

import numpy as np

from .case_model import ModelSpec
from .discovery import Discovery
from .discovery.form_words import look_alike_note
from .discovery.refit import eliminated, start_record
from .fitting import FitResult, FreeParam, apply, fit
from .problem import CalibratedNull, HeldOut, Nominal, Problem, Refit
from .rules import leaves_noise
from .thresholds import (
    ALONE_FORMS,
    BIC_THRESHOLD,
    NOISE_RATIO_OK,
)
from .whiteness import whiteness_z


def found_against_null(pb: Problem, cal: CalibratedNull, found: Discovery) -> None:
    """A found term's gain, taken against the nominal model refitted from where the term's
    refit left the calibrated subset (as every catalogue candidate's is, refit_nulls): the
    refit starts from the nominal values too, and a better basin of the nominal parameters it
    reaches is the null's credit, not the term's. When the term no longer pays by BIC_THRESHOLD
    there, it is not discovered (the reason says so, with both figures)."""
    r = found.refit
    if r is None:
        return
    start = [f.at(r.values[f.name]) for f in cal.free if f.name in r.values]
    if len(start) != len(cal.free):
        return
    n0 = fit(pb.obj, cal.fit.spec, start, max_nfev=6, progress=pb.tick)
    k = len(found.values)
    gain = min(cal.fit.chi2, n0.chi2) - r.chi2 - k * pb.ln_n
    found.delta_bic = min(found.delta_bic, gain)
    if gain < BIC_THRESHOLD:
        found.discovered = False
        found.reason = (f"{found.reason}; but the nominal model refitted from where the term's refit left the "
                        f"calibrated parameters reaches RMS {n0.rms / pb.sigma:.2f} x noise (the term "
                        f"{r.rms / pb.sigma:.2f}): ΔBIC {gain:.0f} < {BIC_THRESHOLD:g}, the gain was a better "
                        f"calibration, not the term")


def term_alone(pb: Problem, cal: CalibratedNull, found: Discovery) -> tuple[FitResult, list[FreeParam]]:
    """The form of `found` (found and refitted from the model with a first effect) refitted
    from the calibrated null without that effect, started at the found values: the term alone's
    refit and its library parameters."""
    from .discovery.refit import _refit

    assert found.form is not None and found.refit is not None
    v = found.refit.values
    form = found.form
    alone_form = replace(form, coefficients={t.param: v.get(t.param, form.coefficients[t.param]) for t in form.terms},
                         wavelength=v.get("lib_wavelength", form.wavelength))
    start = [f.at(v.get(f.name, f.x0)) for f in cal.free]
    return _refit(pb.obj, cal.fit.spec, start, alone_form, pb.tick)


def _take_alone(pb: Problem, cal: CalibratedNull, d: Discovery, r: FitResult, lib: list[FreeParam]) -> None:
    """`d`'s figures from its form's refit `r` alone from the calibrated null (library
    parameters `lib`): the refit, its RMS, free parameters, library values and ΔBIC."""
    d.refit, d.rms_after, d.whiteness_z = r, r.rms, whiteness_z(r.residuals, pb.obj)
    d.free = [f.at(r.values[f.name]) for f in list(cal.free) + lib]
    d.values = {f.name: (r.values[f.name], r.std.get(f.name)) for f in lib}
    d.delta_bic = cal.fit.chi2 - r.chi2 - len(lib) * pb.ln_n


def _look_alike_alone(pb: Problem, cal: CalibratedNull, found: Discovery) -> str:
    """The look-alike that fitted as well as `found` beside the first effect (its
    :attr:`~.discovery.Discovery.look_alike`), refitted alone from the calibrated null as the
    found term just was, so the two are compared (and the next experiment sought) on the same
    model: kept when still within BIC_THRESHOLD, else dropped with the figure. Returns the
    sentence for the reason ('' when there is none)."""
    alt = found.look_alike
    if alt is None or alt.form is None or alt.refit is None:
        return ""
    _take_alone(pb, cal, alt, *term_alone(pb, cal, alt))
    gain = alt.delta_bic - found.delta_bic
    terms = ", ".join(t.symbol for t in alt.form.terms)
    if abs(gain) < BIC_THRESHOLD:
        return f"; its look-alike {terms}, refitted alone too: ΔBIC {gain:+.0f}, the data do not choose"
    found.look_alike = None
    return (f"; its look-alike {terms}, refitted alone too, {'gains' if gain > 0 else 'loses'} ΔBIC {abs(gain):.0f}"
            + (" (the found form stays named: the look-alike came second where both had the first effect)"
               if gain > 0 else ""))


def without_lead(pb: Problem, cal: CalibratedNull, lead: Refit, found: Discovery
                  ) -> tuple[float, FitResult, list[FreeParam]]:
    """ΔBIC of the discovered term with the first effect (`found`, discovered from the model
    with it) over the term alone, refitted from the calibrated null: the first effect must pay
    its own way beside the found term (it may have mimicked part of it). Returns (ΔBIC, the
    term alone's refit, its library parameters)."""
    assert found.refit is not None
    r0, lib = term_alone(pb, cal, found)
    n_lib = len(lib)
    with_lead = found.refit.chi2 + (len(lead.free) + n_lib) * pb.ln_n
    alone = r0.chi2 + (len(cal.free) + n_lib) * pb.ln_n
    return alone - with_lead, r0, lib


def alone_explains(pb: Problem, cal: CalibratedNull, heldout: HeldOut, ho_cal: float, lead: Refit,
                    found: Discovery) -> Optional[Discovery]:
    """A form found from the model with a first effect that did not stand there, refitted
    alone from the calibrated null: the first effect may be spurious (it mimicked part of the
    missing force and, kept, spoils the held-out prediction). The forms that gained by BIC are
    tried in the order of their RMS (at most ALONE_FORMS, each refitted and eliminated to the
    units that pay); the first returned as discovered when alone it leaves noise, predicts the
    held-out experiment to noise and better than the null, and improves BIC, else None (beside
    the spurious effect the form nearest noise need not be the true one: on a ±2.2 % friction
    periodic over 11.8 um, sin, Ff sin, cos at 1.04 x noise and the true Ff sin, Ff cos at 1.05 x)."""
    tried = sorted((t for t in [found, *found.tried] if t.refit is not None and t.form is not None and t.form.terms
                    and t.delta_bic >= BIC_THRESHOLD), key=lambda t: t.rms_after)
    done: set[frozenset[str]] = set()
    for candidate in tried[:ALONE_FORMS]:
        out = _alone(pb, cal, heldout, ho_cal, lead, found, candidate, done)
        if out is not None:
            return out
    return None


def _alone(pb: Problem, cal: CalibratedNull, heldout: HeldOut, ho_cal: float, lead: Refit, found: Discovery,
           best: Discovery, done: set[frozenset[str]]) -> Optional[Discovery]:
    """:func:`alone_explains` for one form `best` (skipped when its eliminated form was judged
    already, `done`)."""
    assert best.form is not None  # tried keeps found forms only
    t0 = time.perf_counter()
    r0, lib = term_alone(pb, cal, best)
    # alone, a unit of the form may no longer pay its way (it mopped up what the first effect did)
    form, r0, lib = eliminated(pb.obj, cal.fit.spec, cal.free, best.form, r0, lib, pb.tick)
    starts = [start_record("alone, calibrated", r0, pb.sigma, time.perf_counter() - t0)]
    key = frozenset(t.param for t in form.terms)
    if key in done:
        return None
    done.add(key)
    best = replace(best, form=form)
    assert best.form is not None
    delta_bic = cal.fit.chi2 - r0.chi2 - len(lib) * pb.ln_n
    ho = heldout.rms(r0.spec, [f.at(r0.values[f.name]) for f in list(cal.free) + lib])
    sigma = pb.sigma
    terms = ", ".join(t.symbol for t in best.form.terms)
    # alone, the form must leave noise as discovery's own rule asks: RMS and a white residual
    wz = whiteness_z(r0.residuals, pb.obj)
    if not (delta_bic >= BIC_THRESHOLD and leaves_noise(r0.rms, wz, sigma) and ho <= NOISE_RATIO_OK * sigma
            and ho < ho_cal):
        found.reason += (f"; without {lead.candidate.effect}, the form {terms} alone leaves RMS "
                         f"{r0.rms / sigma:.2f} x noise, held out {ho / sigma:.2f} x noise, whiteness z = "
                         f"{wz:.1f} (ΔBIC {delta_bic:.0f})")
        # kept among the forms tried (the experiment that would decide it is looked for there)
        found.tried.append(replace(best, refit=r0, rms_after=r0.rms, whiteness_z=wz, delta_bic=delta_bic,
                                   heldout_rms_after=ho, starts=starts,
                                   free=[f.at(r0.values[f.name]) for f in list(cal.free) + lib], tried=[]))
        return None
    from .discovery.form_words import describe, equation

    out = replace(best, discovered=True, refit=r0, rms_after=r0.rms, whiteness_z=wz, delta_bic=delta_bic,
                  rms_before=cal.fit.rms, heldout_rms_before=ho_cal, heldout_rms_after=ho, tried=[], starts=starts)
    vals = {f.name: r0.values[f.name] for f in lib}
    out.values = {n: (x, r0.std.get(n)) for n, x in vals.items()}
    out.equation = equation(best.form, vals)
    if best.body in best.forces:
        out.description = describe(best.form, vals, best.forces[best.body])
    where = "main body" if best.body == "main" else "weight"
    out.reason = (f"a force on the {where} of the form {terms}, found from the model with {lead.candidate.effect} "
                  f"(where it did not stand: {best.reason}), refitted without it: it improves BIC by "
                  f"{delta_bic:.0f} over the calibrated model (RMS {cal.fit.rms / sigma:.2f} → {r0.rms / sigma:.2f} "
                  f"x noise) and predicts the held-out experiment ({ho_cal * 1e9:.2f} → {ho * 1e9:.2f} nm); "
                  f"{lead.candidate.effect} had mimicked part of it")
    return out


class DiscoveryPath(NamedTuple):
    """Where one discovery path starts: the model, its free calibrated parameters centred there,
    the held-out RMS [m] a found term must beat, the first effect it is found beside (or None),
    and whether it starts from the nominal values as given."""
    spec: ModelSpec
    free: list[FreeParam]
    heldout_rms: float
    lead: Optional[Refit]
    from_nominal: bool

    @property
    def origin(self) -> str:
        """Where the path starts, in words."""
        if self.lead is not None:
            return f"the model with {self.lead.candidate.effect}"
        return "the nominal values as given" if self.from_nominal else "the calibrated model"


def discovery_paths(verdict: str, lead: Optional[Refit], cal: CalibratedNull, nominal: Nominal, ho_cal: float
                    ) -> list[DiscoveryPath]:
    """The paths discovery takes in turn until one names a term (`lead`: the first effect that
    stands but leaves structure, or None). After "not_converged", first the nominal values as
    given (the calibration's basins each compensate for the missing force their own way),
    judged against the calibrated null's held-out RMS; else first the model with the first
    effect when one stands, then the calibrated null, then the nominal values as given (a
    calibration that converged may have absorbed the missing force in a basin of its own). A
    first effect that leaves structure has
    not earned the right to shape the search, so with one the other start follows: the
    calibrated null without it after "unexplained"; the model with it after "not_converged"
    (its fit has moved the calibrated parameters into a basin of its own, nearer the truth
    when it mimics part of the missing force: a dry friction on the weight, led by the weight's
    drag at 2.8 x noise against the calibration's 8.3 x)."""
    beside = [DiscoveryPath(apply(lead.base, lead.free, np.zeros(len(lead.free))), list(lead.free),
                            lead.candidate.heldout_rms, lead, False)] if lead is not None else []
    calibrated = DiscoveryPath(cal.fit.spec, list(cal.at), ho_cal, None, False)
    from_nominal = DiscoveryPath(nominal.spec, list(cal.free), ho_cal, None, True)
    if verdict == "not_converged":
        return [from_nominal] + beside
    # last, the nominal values as given: a calibration can converge into a basin that absorbed
    # the missing force its own way (a linear drag on the LPS, sigma2's own form at ~300 x
    # sigma2: from the calibrated model the inferred force left 3 x noise and no form; from the
    # nominal values it regressed onto v1 at -110 N s/m for -108.6, benches/RESULTS.md §44)
    return beside + [calibrated, from_nominal]


def settle_discovery(pb: Problem, cal: CalibratedNull, heldout: HeldOut, ho_cal: float, found: Discovery,
                     d_lead: Optional[Refit], from_nominal: bool, verdict: str, reason: str, rms_after: float
                     ) -> tuple[Discovery, str, str, float]:
    """What discovery's result `found` makes of the verdict (`verdict`, `reason`, `rms_after` as
    the catalogue left them; `d_lead` the first effect discovery started beside, or None;
    `from_nominal` when it started from the nominal values as given): the found term taken
    against a refitted null, its figures against the best calibrated null after a calibration
    that did not converge, the first effect kept only when it pays its own way beside the term,
    and a form that did not stand beside a first effect tried alone. Returns (the discovery,
    verdict, reason, RMS after [m])."""
    if found.discovered and d_lead is None:
        found_against_null(pb, cal, found)
    if found.discovered and from_nominal:
        # its figures against the best calibrated null (discovery's own are against the
        # nominal values as given, far off when a force is missing)
        sigma = pb.sigma
        found.rms_before, found.heldout_rms_before = cal.fit.rms, ho_cal
        where = "main body" if found.body == "main" else "weight"
        terms = ", ".join(t.symbol for t in found.form.terms) if found.form is not None else ""
        why = (f"the calibration did not converge ({cal.search.summary()})" if verdict == "not_converged"
               else "from the calibrated model no form stood")
        found.reason = (f"{why}; discovery from the "
                        f"nominal values as given: a force on the {where} of the form {terms} "
                        f"({found.description}) improves BIC by {found.delta_bic:.0f} over the best calibrated "
                        f"null (RMS {cal.fit.rms / sigma:.2f} → {found.rms_after / sigma:.2f} x noise) and "
                        f"predicts the held-out experiment ({ho_cal * 1e9:.2f} → "
                        f"{found.heldout_rms_after * 1e9:.2f} nm)"
                        + (f" (refitted from a global search: {found.searched})" if found.searched else "")
                        + look_alike_note(found.form) + found.separation)
    if found.discovered:
        verdict, reason, rms_after = "discovered", found.reason, found.rms_after
        if d_lead is not None:
            without, r0, lib = without_lead(pb, cal, d_lead, found)
            if without >= BIC_THRESHOLD:
                verdict = f"{d_lead.candidate.effect}+discovered"
                reason = (f"{d_lead.candidate.effect} stands but leaves a systematic residual; beyond it, "
                          f"{reason}; {d_lead.candidate.effect} pays its own way beside the found term "
                          f"(ΔBIC {without:.0f} against the term alone)")
            else:
                # the term alone is the answer: its own refit from the calibrated null
                _take_alone(pb, cal, found, r0, lib)
                rms_after = r0.rms
                reason = (f"{reason} (found from the model with {d_lead.candidate.effect}, which is not needed "
                          f"beside it: ΔBIC {without:.0f} < {BIC_THRESHOLD:g} against the term alone, "
                          f"refitted from the calibrated model: RMS {r0.rms / pb.sigma:.2f} x noise)")
                reason += _look_alike_alone(pb, cal, found)
        return found, verdict, reason, rms_after
    # d_lead is the first effect when set (discovery_paths)
    alone = alone_explains(pb, cal, heldout, ho_cal, d_lead, found) if d_lead is not None else None
    if alone is not None:
        return alone, "discovered", alone.reason, alone.rms_after
    return found, verdict, reason + f"; discovery: {found.reason}", rms_after
