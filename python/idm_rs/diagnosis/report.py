"""The diagnosis as readable text, in the spirit of PySINDy's printed models and SciML's
"missing physics" story: the verdict, how the residual RMS falls (nominal -> calibrated -> with
the effect) against the noise floor, the calibrated parameters, where the residual lives, the
candidate ranking with its evidence, and the refitted model in one line. Units everywhere."""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Callable

from ..core.declarations import structure_label
from .report_format import (
    calibrated_rows,
    evidence_words,
    first_effect_params,
    format_params,
    in_nm,
    is_finite_number,
    pm,
    ratio_words,
    refit_model_line,
    refit_parameter_rows,
    text_table,
    unit_of,
)

if TYPE_CHECKING:
    from .results import Alternative, Candidate, Diagnosis, ThirdSearch

#: experiment x phase locations listed in the report
TOP_LOCATIONS = 6
#: systematic time windows listed in the report
TOP_WINDOWS = 4

def _one_effect_summary(d: Diagnosis, best: Candidate, alts: list[Alternative], ratio: Callable[[float], float]
                        ) -> list[str]:
    """The plain words of a verdict naming one effect (`best`)."""
    lines: list[str] = []
    params = format_params(best)
    lines.append(f"  Found: {best.description}"
                 + (f" ({params})" if params not in ("–", "(structure only)") else "")
                 + " — the nominal model lacks it. With it added and the nominal values re-fitted, the model "
                 f"matches the recordings to {ratio(best.rms_after):.2f} × their noise, against "
                 f"{ratio(d.rms_calibrated):.2f} × with the nominal values re-fitted alone.")
    sure = f"  How sure: {evidence_words(best.delta_bic)} evidence against \"nothing missing\""
    if is_finite_number(best.heldout_rms):
        sure += (f"; the refitted model also predicts an experiment it was not fitted to "
                 f"({ratio(best.heldout_rms):.2f} × noise)")
    if alts:
        sure += (f". But {', '.join(a.effect for a in alts)} explain{'s' if len(alts) == 1 else ''} these "
                 "recordings about as well: the data cannot tell them apart")
    weak = [p for p in getattr(best, "identifiability", []) if not p.determined]
    if weak:
        sure += (". These experiments do not determine " + ", ".join(
            f"{p.name} (95 % interval {p.low:.3g} to {p.high:.3g}"
            + (f", traded off against {p.partner}" if p.partner else "") + ")" for p in weak)
            + ": the values printed are one point of that range")
    lines.append(sure + ".")
    todo = "  What to do: add this effect to your model with the fitted values (the refit model below)"
    prop = getattr(d, "proposal", None)
    if prop is not None:
        todo += "; " + prop.words() + (", and diagnose again with it added" if prop.separates else "")
    elif alts:
        todo += ("; to decide between it and the alternative, record experiments that excite them differently "
                 "(the other drive direction, another amplitude or frequency)")
    pp = getattr(d, "parameter_proposal", None)
    if pp is not None:
        todo += "; " + pp.words()
    lines.append(todo + ".")
    return lines


def plain_summary(d: Diagnosis) -> list[str]:
    """What was found, how sure, what to do — for a reader who does not speak statistics; the
    numbers behind each sentence follow in the report."""
    sigma = d.noise.sigma
    ratio: Callable[[float], float] = lambda x: x / sigma if sigma > 0 else math.nan  # noqa: E731
    best = d.verdict_candidate
    sec = getattr(d, "second", None)
    p_meta = d.recording.nominal.params.to_dict(resolved=False)
    moved = sorted(((n, v / p_meta[n] - 1.0) for n, v in d.calibrated.items()
                    if is_finite_number(p_meta.get(n)) and p_meta[n]), key=lambda kv: -abs(kv[1]))
    biggest = f"; the largest change is {moved[0][0]} {100 * moved[0][1]:+.1f} % against meta.json" if moved else ""
    where = next((loc for loc in d.locations if loc.systematic), None)
    alts, third = getattr(d, "alternatives", []) or [], getattr(d, "third", None)
    lines = ["In plain words"]
    if third is not None and third.named and best is not None:
        lines.append(f"  Found: three effects the nominal model lacks — {', '.join(third.pair)} and "
                     f"{best.description} ({format_params(best)}). With all three added and the nominal values "
                     f"re-fitted, the model matches the recordings to {ratio(best.rms_after):.2f} × their noise, "
                     f"against {ratio(d.rms_calibrated):.2f} × with none.")
        lines.append(f"  How sure: {evidence_words(best.delta_bic)} evidence for the third beside the pair (ΔBIC "
                     f"{best.delta_bic:.0f}); dropping either of the pair costs ΔBIC "
                     + " and ".join(f"{v:.0f}" for v in third.over_without.values())
                     + f"; the three predict an experiment they were not fitted to at {ratio(third.heldout_rms):.2f} "
                     "× noise.")
        lines.append("  What to do: add the three effects to your model with the fitted values (the refit model "
                     "below).")
    elif third is not None and third.instead is not None and best is not None:
        lines += _instead_lines(d, third, best)
    elif sec is not None and sec.named and best is not None:
        share = " and ".join(f"{k} {100 * v:.0f} %" for k, v in sec.shares.items())
        lines.append(f"  Found: two effects the nominal model lacks — {sec.first.description} "
                     f"({first_effect_params(d)}), and {best.description} ({format_params(best)}). With both added "
                     f"and the nominal values re-fitted, the model matches the recordings to "
                     f"{ratio(best.rms_after):.2f} × their noise, against {ratio(sec.first.rms_after):.2f} × with "
                     f"the first alone and {ratio(d.rms_calibrated):.2f} × with neither (share of the improvement: "
                     f"{share}).")
        lines.append(f"  How sure: {evidence_words(best.delta_bic)} evidence for the second beside the first (ΔBIC "
                     f"{best.delta_bic:.0f}) and for the first beside the second (ΔBIC {sec.over_second_alone:.0f}); "
                     f"the pair predicts an experiment it was not fitted to at {ratio(sec.heldout_rms):.2f} × noise.")
        if alts:
            twins = "; ".join(f"{a.effect} in place of {a.replaces}" if a.replaces else a.effect for a in alts)
            lines.append(f"  Could also be: {twins} — a signature these experiments cannot tell from the named "
                         "effect's.")
        todo = "  What to do: add both effects to your model with the fitted values (the refit model below)"
        prop = getattr(d, "proposal", None)
        if alts and prop is not None:
            todo += "; " + prop.words() + (", and diagnose again with it added" if prop.separates else "")
        lines.append(todo + ".")
    elif best is not None:
        lines += _one_effect_summary(d, best, alts, ratio)
    elif d.verdict == "none":
        lines.append(f"  Found: nothing missing. The nominal model with re-fitted values matches the recordings to "
                     f"their noise ({ratio(d.rms_calibrated):.2f} × noise){biggest}.")
        top = next((c for c in d.ranking if not c.screened_only), None)
        lines.append("  How sure: no catalogue effect improves the fit by more than the noise allows"
                     + (f" (the closest, {top.effect}, gains ΔBIC {top.delta_bic:.0f}; 10 would be needed)"
                        if top is not None and is_finite_number(top.delta_bic) else "") + ".")
        lines.append("  What to do: use the re-fitted values below; where one moved far from meta.json, check that "
                     "setting of the device.")
    elif d.verdict.endswith("discovered") and getattr(d, "discovery", None) is not None:
        f = d.discovery
        assert f is not None  # the condition above
        lines.append(f"  Found: physics the catalogue does not list — {f.description}. Inferred from the data as a "
                     f"force on the {'main body' if f.body == 'main' else 'weight'}, its form found in a library of "
                     f"terms and refitted with the nominal values: the model now matches the recordings to "
                     f"{ratio(f.rms_after):.2f} × their noise, against {ratio(d.rms_calibrated):.2f} × without it.")
        lines.append(f"  How sure: {evidence_words(f.delta_bic)} evidence against \"nothing missing\" (ΔBIC "
                     f"{f.delta_bic:.0f}), and the model refitted without one experiment predicts it better "
                     f"({ratio(f.heldout_rms_before):.2f} → {ratio(f.heldout_rms_after):.2f} × noise). The form is "
                     "the simplest library combination that reproduces the force across experiments; a different "
                     "mechanism with the same signature on these experiments cannot be excluded.")
        todo = ("  What to do: add the term (the refit model below) and look for its physical cause (the "
                "variable it depends on says where); confirm with experiments that excite it differently")
        prop = getattr(d, "proposal", None)
        if prop is not None:
            todo += "; " + prop.words() + (", and diagnose again with it added" if prop.separates else "")
        lines.append(todo + ".")
    elif d.verdict == "unexplained":
        lines.append(f"  Found: the recordings disagree with the model in a way no catalogue effect explains: "
                     f"{ratio(d.rms_after):.2f} × the noise remains"
                     + (f", most of it in {where.experiment} ({where.phase})" if where is not None else "") + ".")
        lines.append("  How sure: the residual is systematic, not noise "
                     f"(whiteness z = {d.whiteness_z_calibrated:.1f}; noise gives |z| < 3).")
        todo = ("  What to do: look at the located windows and the fit figures: the missing physics is not "
                "among the catalogue's effects")
        pp = getattr(d, "parameter_proposal", None)
        if pp is not None:
            todo += "; " + pp.words() + ", and diagnose again with it added"
        lines.append(todo + ".")
    elif d.verdict == "interrupted":
        lines.append(f"  Found: no answer yet — {d.reason}.")
        lines.append("  How sure: not at all: the run did not reach a verdict; the numbers below are what it "
                     "had finished.")
        lines.append("  What to do: run it again to the end.")
    else:
        lines.append(f"  Found: no firm answer ({d.verdict}): {d.reason}.")
        lines.append("  How sure: not sure — the fits that should agree did not.")
        lines.append("  What to do: record more experiments (both directions, several amplitudes), check meta.json, "
                     "and run again.")
    return lines


RMS_TITLE = "Residual RMS (a position offset fitted per drive-cycle segment: multiple shooting by translation)"



def _instead_lines(d: Diagnosis, third: "ThirdSearch", best: "Candidate") -> list[str]:
    """The plain words for two effects named instead of a triple (`third.instead`: one of the
    first pair stood in for the third, its look-alike); `best` is the two's fit."""
    sigma = d.noise.sigma
    ratio: Callable[[float], float] = lambda x: x / sigma if sigma > 0 else math.nan  # noqa: E731
    instead = third.instead
    assert instead is not None  # the caller's condition
    dropped = next(e for e in third.pair if e not in instead)
    return [f"  Found: two effects the nominal model lacks — {instead[0]} and {best.description} "
            f"({format_params(best)}). With both added and the nominal values re-fitted, the model matches "
            f"the recordings to {ratio(best.rms_after):.2f} × their noise, against "
            f"{ratio(d.rms_calibrated):.2f} × with neither; the search had gone through {dropped}, which "
            "does not pay its own way beside them.",
            f"  How sure: the pair predicts an experiment it was not fitted to at {ratio(best.heldout_rms):.2f} × "
            "noise; the reason below gives each effect's ΔBIC.",
            "  What to do: add the two effects to your model with the fitted values (the refit model below)."]

def _noise_model_lines(d: Diagnosis) -> list[str]:
    """What the reading carries besides the motion, and the metric the figures below are in."""
    model = getattr(d.noise, "model", None)
    if model is None:
        return []
    out = ["", f"Noise model: {model.describe()}"] + [f"  note: {n}" for n in model.notes]
    if model.coloured or model.artefacts_applied:
        out.append("  every residual, chi^2 and RMS below is in the whitened metric (generalised least squares)"
                   + (", the lines, drift and delay above profiled out as measurement properties"
                      if model.artefacts_applied else ""))
    return out


# Long: a public function's numpydoc docstring; the body is the report's sections in order
def text_report(d: Diagnosis) -> str:
    """The diagnosis `d` as text: the verdict in plain words, the RMS story against the noise
    floor, the calibrated parameters, where the residual lives, the ranking with its evidence,
    discovery and a second effect when they ran, what the data do not determine, the experiment
    that would separate look-alikes, and the refitted model in one line (units throughout).

    Parameters
    ----------
    d : Diagnosis
        What :func:`idm_rs.diagnose` returned (or an interrupted run's ``partial``: then only
        what it finished is printed).

    Returns
    -------
    str
        The report, lines of at most about 100 characters.

    Examples
    --------
    >>> print(idm_rs.text_report(idm_rs.diagnose("path/to/case")))   # doctest: +SKIP
    """
    sigma = d.noise.sigma
    rec = d.recording
    lines: list[str] = []
    title = f"Diagnosis of case {d.case!r}"
    lines += [title, "=" * len(title)]
    lines.append(f"{len(rec.experiments)} experiments, {rec.n_samples} samples at {rec.sample_rate_Hz / 1e3:g} kHz; "
                 f"nominal {structure_label(rec.nominal.model, rec.nominal.n_elements)}"
                 + f"; {d.simulations} simulated runs in {d.seconds:.1f} s")
    timings = getattr(d, "timings", None) or {}
    if timings:
        lines.append("time per stage: " + ", ".join(f"{k} {v:.1f} s" for k, v in timings.items()))
    lines.append("")
    lines += plain_summary(d)
    lines += ["", "The numbers behind it", "---------------------"]
    lines.append(f"VERDICT: {d.verdict.upper()}")
    lines.append(f"  {d.reason}")
    for a in getattr(d, "alternatives", []) or []:
        lines.append(f"  ALTERNATIVE: {a.effect} (ΔBIC {a.delta_bic:.0f}): {a.why}")
    prop = getattr(d, "proposal", None)
    if prop is not None:
        top = ", ".join(f"{dr.direction} {dr.amplitude_V:.0f} V {dr.frequency_Hz:.0f} Hz: {s:.0f}"
                        for dr, s in prop.scored[:4])
        lines.append(f"  NEXT EXPERIMENT: {prop.words()}. Expected ΔBIC of the best drives tried: {top}")

    # --- what the reading carries besides the motion, then the RMS story
    best = d.verdict_candidate
    lines += _noise_model_lines(d) + ["", RMS_TITLE]
    rows = [
        [f"noise floor ({getattr(d.noise, 'source', 'rest')})", in_nm(sigma), "1.00 ×",
         f"rest {in_nm(d.noise.rest_sigma)}, fitted residual's 2nd differences "
         f"{in_nm(getattr(d.noise, 'residual_sigma', math.nan))}, ±{100 * d.noise.relative_uncertainty:.1f} %"],
        ["nominal model (meta.json)", in_nm(d.rms_before), ratio_words(d.rms_before, sigma), ""],
    ]
    if is_finite_number(d.rms_calibrated):  # an interrupted run may stop before the calibration
        rows.append(["calibrated nominal", in_nm(d.rms_calibrated), ratio_words(d.rms_calibrated, sigma),
                     f"whiteness z = {d.whiteness_z_calibrated:.1f}"])
    label = d.verdict.replace("+", " + ") if "+" in d.verdict and best is not None else (best.effect if best else "")
    if best is not None:
        rows.append([f"with {label}", in_nm(best.rms_after), ratio_words(best.rms_after, sigma),
                     f"whiteness z = {best.whiteness_z:.1f}" if is_finite_number(best.whiteness_z) else ""])
    if d.heldout_experiment:  # not computed when the run was interrupted before it
        rows.append([f"held-out {d.heldout_experiment}: calibrated", in_nm(d.heldout_rms_calibrated),
                     ratio_words(d.heldout_rms_calibrated, sigma), "fitted on the other experiments"])
    if best is not None and is_finite_number(best.heldout_rms):
        rows.append([f"held-out {d.heldout_experiment}: with {label}", in_nm(best.heldout_rms),
                     ratio_words(best.heldout_rms, sigma), ""])
    lines += text_table(["model", "RMS", "/ noise", "note"], rows, "lrrl")

    # --- calibrated nominal parameters
    lines += ["", "Calibrated nominal parameters (±1σ from the Jacobian), against meta.json"]
    rows = calibrated_rows(d, d.calibrated, d.calibrated_std)
    lines += text_table(["parameter", "meta.json", "calibrated", "change"], rows, "lrrr")
    summary = getattr(d, "calibration_summary", "")
    if summary:
        lines.append(f"  convergence: {summary}; null model from the {getattr(d, 'null_source', 'calibration')}")
        if not getattr(d, "calibration_converged", True):
            lines.append("  the local fits did NOT reach the same optimum: treat the calibration as unreliable")

    # --- where the residual lives
    lines += ["", "Where the residual lives (calibrated model; share of the residual energy above the noise)"]
    locs = [loc for loc in d.locations if loc.phase != "window"]
    if locs:
        rows = []
        for loc in locs[:TOP_LOCATIONS]:
            rows.append([loc.experiment, loc.phase, f"{1e3 * loc.t_start:.2f}–{1e3 * loc.t_end:.2f}",
                         f"{100 * loc.excess_share:.1f} %", f"{loc.rms_over_noise:.2f}",
                         f"yes (z = {loc.z:.0f})" if loc.systematic else "no"])
        lines += text_table(["experiment", "phase", "span [ms]", "share", "RMS/noise", "systematic"], rows, "llrrrl")
        n_sys = sum(loc.systematic for loc in locs)
        lines.append(f"  {n_sys} of {len(locs)} experiment × phase cells hold a systematic residual")
    if d.windows:
        total = sum(w.t_end - w.t_start for w in d.windows)
        largest = sorted(d.windows, key=lambda w: -w.excess_share)[:TOP_WINDOWS]
        lines.append(f"  systematic time windows: {len(d.windows)} spans, {1e3 * total:.1f} ms in all; largest: "
                     + "; ".join(f"{w.experiment} {1e3 * w.t_start:.1f}–{1e3 * w.t_end:.1f} ms "
                                 f"({100 * w.excess_share:.0f} %, {w.rms_over_noise:.1f} × noise)" for w in largest))
    elif not d.complete:
        lines.append("  systematic time windows: not computed (interrupted)")
    else:
        lines.append("  no systematic time window")

    # --- candidate ranking
    if not d.ranking and not d.complete:
        lines += ["", "Candidate effects: none fitted before the interrupt"]
    else:
        lines += _ranking_lines(d, sigma)
    lines += _discovery_and_second_lines(d, sigma)
    lines += _identifiability_lines(d)
    lines += ["", "Refit model:", "  " + refit_model_line(d)]
    rows = refit_parameter_rows(d)
    if rows:
        lines += ["  every fitted parameter (±1σ from the Jacobian; the values to put in your model):"]
        lines += ["  " + line for line in text_table(["parameter", "meta.json", "refit", "change"], rows, "lrrr")]
    return "\n".join(lines) + "\n"


def _ranking_lines(d: Diagnosis, sigma: float) -> list[str]:
    """The candidate table and what it implies (correlations, degeneracies, the wider search)."""
    lines: list[str] = []
    lines += ["", "Candidate effects (score: the chi² one linearised step from the null optimum would gain, "
                  "which orders the fits; \"fitted\": multistart local fits with the calibrated subset and the "
                  "offsets, the null it contains among the starts; \"at null\": the fit ended no better than that "
                  "null; \"score only\": not fitted, only its score and linearised ΔBIC; ΔBIC > 0: better than "
                  "the best null fit; LR: likelihood ratio against the null it contains, with its 1e-3 critical "
                  "value)"]
    rows = []
    for i, c in enumerate(d.ranking, 1):
        mark = "*" if c.effect == d.verdict else " "
        lr = getattr(c, "lr_chi2", math.nan)
        score = getattr(c, "score", math.nan)
        ratio = c.rms_over_noise(sigma)
        rows.append([f"{mark}{i}", c.effect, format_params(c), in_nm(c.rms_after) if is_finite_number(ratio) else "–",
                     f"{ratio:.2f} ×" if is_finite_number(ratio) else "–",
                     f"{score:.0f}" if is_finite_number(score) else "–",
                     c.delta_bic_words,
                     f"{lr:.0f} / {c.lr_critical:.1f}" if is_finite_number(lr) and not c.screened_only else "–",
                     in_nm(c.heldout_rms) if is_finite_number(c.heldout_rms) else "–",
                     c.fit_label])
    lines += text_table(["#", "effect", "fitted parameters (±1σ)", "RMS after", "/ noise", "score", "ΔBIC", "LR / crit",
                     "held-out RMS", "fit"], rows, "rllrrrrrrl")
    for c in d.ranking:
        corr = getattr(c, "correlation", {}) or {}
        names = list(corr)
        for a in range(len(names)):
            for b in range(a + 1, len(names)):
                rho = corr[names[a]].get(names[b], math.nan)
                if is_finite_number(rho) and abs(rho) > 0.8:
                    lines.append(f"  {c.effect}: {names[a]} and {names[b]} are correlated (ρ = {rho:+.2f}): the data "
                                 f"constrain a combination of them; each value alone is uncertain beyond its ±1σ")
    pairs = getattr(d, "degenerate_pairs", []) or []
    if pairs:
        lines.append("  near-degenerate (projected signatures almost parallel; the data tell them apart only "
                     "beyond first order): " + "; ".join(f"{a} ~ {b} (|cos| = {c:.3f})" for a, b, c in pairs))
    if getattr(d, "searched_wide", False):
        lines.append("  the wider search ran: every candidate got a population search of its own")
    return lines


def _discovery_and_second_lines(d: Diagnosis, sigma: float) -> list[str]:
    """Discovery's forces and form, and the second-effect search, where they ran."""
    lines: list[str] = []

    found = getattr(d, "discovery", None)
    if found is not None:
        lines += ["", "Discovery beyond the catalogue (a force inferred through the simulator, its form by sparse "
                      "regression on a library, cross-validated across experiments, then refitted)"]
        rows = []
        for body, f in found.forces.items():
            rows.append([body, f"{f.chi2_before:.0f}", f"{f.chi2_after:.0f}", f"{f.dof:.1f}",
                         f"{f.smoothing:.2g}", f"{f.seconds:.0f} s"])
        lines += text_table(["force on", "chi² before", "with force", "eff. params", "smoothing (GCV)", "time"],
                        rows, "lrrrrr")
        if found.form is not None:
            form = found.form
            lines.append(f"  form on the {found.body}: " + (", ".join(t.symbol for t in form.terms) or "no term")
                         + (f" (lambda scanned, chosen {form.wavelength * 1e6:.3g} µm)" if form.wavelength > 0 else "")
                         + "; leave-one-experiment-out error by number of terms: "
                         + ", ".join(f"{e:.3f}" for e in form.cv_by_size))
        if found.values:
            lines.append("  refitted: " + ", ".join(f"{n} = {pm(v, sd)}" for n, (v, sd) in found.values.items()))
            lines.append(f"  ΔBIC {found.delta_bic:.0f}; RMS {in_nm(found.rms_before)} → {in_nm(found.rms_after)} "
                         f"({ratio_words(found.rms_before, sigma)} → {ratio_words(found.rms_after, sigma)}); held-out "
                         f"{found.heldout_experiment}: "
                         f"{in_nm(found.heldout_rms_before)} → {in_nm(found.heldout_rms_after)}")
        lines.append(f"  {'DISCOVERED' if found.discovered else 'not discovered'}: {found.reason}")

    sec = getattr(d, "second", None)
    if sec is not None:
        how = ("fitted together with" if getattr(sec, "joint", False) else "searched from the model with")
        lines += ["", f"A second effect, {how} {sec.first.effect} (which left RMS "
                      f"{ratio_words(sec.first.rms_after, sigma)}, whiteness z = {sec.first.whiteness_z:.1f})"
                      + (" from the nominal values, each at its fit alone" if getattr(sec, "joint", False) else "")]
        rows = [[c.effect, format_params(c), ratio_words(c.rms_after, sigma),
                 f"{c.delta_bic:.1f}" if c.delta_bic >= 0 else "not supported", c.fit_label] for c in sec.ranking]
        if rows:
            lines += text_table(["effect (beside the first)", "fitted parameters (±1σ)", "RMS / noise",
                             "ΔBIC over the first alone", "fit"], rows, "llrrl")
        if sec.shares:
            lines.append("  share of the improvement over the calibrated null: "
                         + ", ".join(f"{k} {100 * v:.0f} %" for k, v in sec.shares.items()))
        lines.append(f"  {'BOTH NAMED' if sec.named else 'no second effect named'}: {sec.reason}")
    third = getattr(d, "third", None)
    if third is not None:
        lines += ["", f"A third effect, searched from the model with {third.pair[0]} and {third.pair[1]}"]
        if getattr(third, "swapped", None):
            member, twin = third.swapped
            lines.append(f"  ({twin} in place of its look-alike {member}: from the pair as found the round named "
                         f"nothing — {third.first_path})")
        if getattr(third, "exchanged", None):
            member, kept = third.exchanged
            lines.append(f"  ({member} dropped and {kept} kept in its place: the triple with {member} left a "
                         f"systematic residual — {third.first_path})")
        rows = [[c.effect, format_params(c), ratio_words(c.rms_after, sigma),
                 f"{c.delta_bic:.1f}" if c.delta_bic >= 0 else "not supported", c.fit_label] for c in third.ranking]
        if rows:
            lines += text_table(["effect (beside the pair)", "fitted parameters (±1σ)", "RMS / noise",
                             "ΔBIC over the pair", "fit"], rows, "llrrl")
        lines.append(f"  {'ALL THREE NAMED' if third.named else 'no third effect named'}: {third.reason}")
    return lines


def _identifiability_lines(d: Diagnosis) -> list[str]:
    """What the experiments determine of the verdict's refit (Fisher matrix: 95 % intervals)."""
    c = d.verdict_candidate
    statuses = list(getattr(c, "identifiability", []) or []) if c is not None else []
    if not statuses:
        return []
    out = ["", "What these experiments determine (refit model; 95 % intervals from the Fisher matrix)"]
    out += ["  " + p.words(unit_of(p.name)) for p in statuses]
    weak = [p.name for p in statuses if not p.determined]
    out.append("  all determined" if not weak else
               f"  not determined: {', '.join(weak)} — their values are one point of a range the data allow; "
               "an experiment that excites them differently would narrow it")
    return out


def json_safe(obj: object) -> object:
    """`obj` made strictly JSON-serialisable: numpy scalars and arrays to Python numbers and lists,
    NaN and ±inf to None, tuples to lists, dataclass-free mappings with string keys."""
    import numpy as np

    if isinstance(obj, dict):
        return {str(k): json_safe(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [json_safe(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return [json_safe(v) for v in obj.tolist()]
    if isinstance(obj, (bool, np.bool_)):
        return bool(obj)
    if isinstance(obj, (int, np.integer)):
        return int(obj)
    if isinstance(obj, (float, np.floating)):
        v = float(obj)
        return v if math.isfinite(v) else None
    if obj is None or isinstance(obj, str):
        return obj
    return str(obj)
