"""The diagnosis: calibrate the nominal model, locate the residual, try every catalogue effect,
rank them by information criterion and held-out prediction, and give a verdict.

:func:`diagnose` runs the stages of ``PIPELINE`` in order over one state object (``_State``):
the nominal model as given, the calibration, screening, the candidates' fits, the null refitted
from where they went, the polish of the leaders, the wider search, the held-out prediction, the
verdict, a second effect, discovery beyond the catalogue, and the next experiment. Each stage is
a small function here; the work is in the modules named by role (:mod:`.candidates`,
:mod:`.second_effect`, :mod:`.beyond_catalogue`, :mod:`.verdict`, :mod:`.proposals`, over the
types of :mod:`.problem`). The results are the types of :mod:`.results`."""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Callable, Optional, Union

import numpy as np

from ..core.engine import DivergenceError
from ..core.interrupted import interrupted
from ..core.solver import Solver, resolve_solver
from ..io.recording import Recording, load_case
from .beyond_catalogue import DiscoveryPath, discovery_paths, settle_discovery
from .candidates import (
    calibrate_null,
    fit_candidates,
    nominal_model,
    polish_leaders,
    refit_nulls,
    renoised,
    screen_candidates,
    structural_calibrations,
    wide_search,
)
from .case_model import CaseSimulator
from .catalogue import Effect
from .discovery import Discovery, NumericalFailure
from .discovery import discover as run_discovery
from .fitting import Objective
from .locate import Location, locate, merge_windows
from .next_experiment import ParameterProposal, Proposal
from .noise import NoiseEstimate, cross_check, estimate_noise
from .noise_model import Learned
from .pair_twins import judged_pairs
from .problem import CalibratedNull, HeldOut, Nominal, Problem, Refit
from .progress import Clock, Progress, part, progress_bar
from .proposals import determining_experiment, look_alike_experiment, separating_experiment, travel_experiment
from .remeasure import COMMON_DRIFT_EFFECT, artefacts_instead, drift_beside, relearned, remeasured, synced
from .results import Alternative, Candidate, Diagnosis, SecondSearch, ThirdSearch
from .rules import better_of, by_rank, candidate_explains, is_finite, null_leaves_noise
from .screening import Screened, near_degenerate
from .second_effect import joint_pair, partial_leader, search_second_effect
from .third_effect import pair_share, search_third_effect, third_base
from .thresholds import (
    FIT_DT,
    NULL_REFITS,
    REFIT_TOP,
    SEPARATION,
    THIRD_PAIR_SHARE,
)
from .verdict import alternatives_to, decide_verdict, rank_with_heldout


@dataclass
class _State:
    """The one object the stages work on: the inputs, then what each stage finished (kept as it
    finishes, so an interrupted run returns it)."""

    rec: Recording
    noise: NoiseEstimate
    sim: CaseSimulator
    bar: Optional[Progress]
    refit_top: int
    discover: bool
    t_start: float
    stage: str = "the nominal model"
    pb: Optional[Problem] = None
    nominal: Optional[Nominal] = None
    clock: Clock = field(default_factory=Clock)
    cal: Optional[CalibratedNull] = None
    null_source: str = "calibration"
    heldout: Optional[HeldOut] = None
    order: list[Effect] = field(default_factory=list)
    screened: dict[str, Screened] = field(default_factory=dict)
    #: the candidates fitted so far, each appended as it finishes
    refits: list[Refit] = field(default_factory=list)
    searched_wide: bool = False
    ranking: list[Candidate] = field(default_factory=list)
    ho_cal: float = math.nan
    locations: list[Location] = field(default_factory=list)
    spans: list[Location] = field(default_factory=list)
    verdict: str = ""
    reason: str = ""
    rms_after: float = math.nan
    lead: Optional[Refit] = None
    second: Optional[SecondSearch] = None
    third: Optional[ThirdSearch] = None
    found_other: Optional[Discovery] = None
    learned_chi2: float = math.inf  #: the null's chi^2 the artefacts were learned against
    found: Optional[Discovery] = None
    degenerate: list[tuple[str, str, float]] = field(default_factory=list)
    alternatives: list[Alternative] = field(default_factory=list)
    proposal: Optional[Proposal] = None
    parameter_proposal: Optional[ParameterProposal] = None
    learned: Optional[Learned] = None


def diagnose(case: Union[str, Path, Recording], *, progress: bool = True, dt: float = FIT_DT,
             threads: Optional[int] = None, refit_top: int = REFIT_TOP, discover: bool = True,
             solver: Optional[Solver] = None) -> Diagnosis:
    """Diagnose a recorded case (a directory in the `idm-recording/1` format, or a Recording).
    With `discover` (the default), a case no catalogue effect explains goes on to discovery
    (:mod:`.discovery`): the missing force inferred, its form found in a library, modelled and
    refitted; verdict "discovered" when it stands. Ctrl-C raises a KeyboardInterrupt whose
    ``partial`` (:func:`idm_rs.partial_result`) is what was finished — the calibration and the
    candidates fitted so far — as a Diagnosis with verdict "interrupted" and ``complete`` False, which
    :func:`text_report` and :func:`plot_diagnosis` show.

    Parameters
    ----------
    case : path or Recording
        A case directory (``meta.json`` and one CSV per experiment) or a loaded recording.
    progress : bool
        A progress bar by stage with an estimate of the time left.
    dt : float
        RK4 step of the fits' simulations [s].
    threads : int, optional
        Threads of the engine (default: every core).
    refit_top : int
        Candidates refitted over every experiment after the screening.
    discover : bool
        Go beyond the catalogue when no effect of it explains the residual.
    solver : Solver, optional
        The fits' integration as an :class:`idm_rs.Solver`: RK4 (their exact derivatives are
        RK4's) with its ``dt``; another method is refused.

    Returns
    -------
    Diagnosis
        ``verdict`` (a catalogue id, a pair "a+b", "none", "discovered", "unexplained" or
        "not_converged"), ``reason`` in words, the residual RMS before / calibrated / after [m],
        the noise model, the ranked candidates with their fitted values ±1σ, the look-alikes and
        the experiment that would separate them; ``to_dict()`` is the JSON.

    Raises
    ------
    RecordingError
        A recording that does not follow the format (file, line and column named).
    KeyboardInterrupt
        Ctrl-C; its ``partial`` is the Diagnosis of what finished.

    Examples
    --------
    >>> d = idm_rs.diagnose("path/to/case")          # doctest: +SKIP
    >>> d.verdict, d.rms_after / d.noise.sigma       # doctest: +SKIP
    ('spring_to_ground', 1.01)
    >>> print(idm_rs.text_report(d))                 # doctest: +SKIP
    """
    t_start = time.perf_counter()
    how = resolve_solver(solver, dict(method="rk4", dt=dt), dict(method="rk4", dt=FIT_DT), "diagnose")
    if how["method"] != "rk4":
        raise ValueError(f"diagnose fits with RK4 (its derivatives are exact for RK4's steps); got "
                         f"solver.method = {how['method']!r}: use Solver('rk4', dt=...)")
    dt = how["dt"]
    rec = case if isinstance(case, Recording) else load_case(case)
    noise = estimate_noise(rec)
    sim = CaseSimulator(rec, dt=dt, threads=threads)
    bar = progress_bar(progress, rec.name, lambda: sim.evaluations)
    s = _State(rec, noise, sim, bar, refit_top, discover, t_start)
    s.clock = Clock(bar, lambda: sim.evaluations)
    # every BLAS on one thread: the engine's threads own the cores, and OpenBLAS's own threads
    # spin-wait after every small factorisation of the fits, taking cycles from them (measured on
    # 2 cores: dev14 84.6 -> 78.3 s, mean of three alternating pairs). threadpoolctl limits only
    # the libraries loaded when it is called, and scipy.linalg loads its own OpenBLAS: where the
    # caller had not imported it, the first fit loaded it inside the limit and it ran on every
    # core, so discovery's large least squares depended on what the caller had imported before
    # and on the machine's core count (a discovery device took other paths, RESULTS §61)
    _load_every_blas()
    from threadpoolctl import threadpool_limits  # with scikit-learn; lazily, as scipy

    try:
        with threadpool_limits(limits=1, user_api="blas"):
            with s.clock.active():
                for s.stage, stage in PIPELINE:
                    stage(s)
    except KeyboardInterrupt:
        if bar is not None:
            bar.close(done=False)
        partial = _interrupted(s, noise)
        raise interrupted(f"diagnose interrupted: {partial.reason} (the Diagnosis of what finished is the "
                          "exception's .partial)", partial=partial) from None
    if bar is not None:
        bar.close()
    return _result(s)


def _load_every_blas() -> None:
    """Load every BLAS and LAPACK the diagnosis calls (numpy's is loaded with numpy; scipy's
    with scipy.linalg, which scikit-learn uses too), so that one thread limit holds them all
    whatever the caller imported."""
    import importlib

    importlib.import_module("scipy.linalg")


# --- the stages, in order: each reads what the ones before it left in the state -------------------


def _nominal_stage(s: _State) -> None:
    s.pb = Problem(s.rec, s.noise, s.sim, Objective(s.rec, s.sim, s.noise.sigma),
                   s.bar.update if s.bar is not None else None)
    s.nominal = nominal_model(s.pb)
    s.clock.restart()


def _calibration_stage(s: _State) -> None:
    assert s.pb is not None and s.nominal is not None
    cal = calibrate_null(s.pb, s.nominal)
    # the noise model (colour, spikes, hum, a drifting zero) learned against the calibrated
    # prediction, and the null refitted in its metric (nothing changes on a white recording)
    s.pb, cal, s.noise, s.learned = remeasured(s.pb, cal, s.nominal, s.noise)
    s.rec = s.pb.rec
    # the noise floor cross-checked against the calibrated residual's high-frequency content
    s.noise = synced(cross_check(s.noise, cal.fit.residuals))
    s.pb, s.cal = renoised(s.pb, cal, s.noise)
    s.learned_chi2 = s.cal.fit.chi2
    s.clock.lap("calibration")


def _screening_stage(s: _State) -> None:
    assert s.pb is not None and s.cal is not None and s.nominal is not None
    s.heldout = HeldOut(s.pb)
    s.order, s.screened = screen_candidates(s.pb, s.cal, s.nominal)
    s.clock.lap("screening")


def _candidate_stage(s: _State) -> None:
    assert s.pb is not None and s.cal is not None
    s.refits = fit_candidates(s.pb, s.cal, s.order, s.screened, s.refit_top, sink=s.refits)
    s.clock.lap("candidate fits")


def _null_refit_stage(s: _State) -> None:
    assert s.pb is not None and s.cal is not None and s.nominal is not None
    s.cal, s.null_source = refit_nulls(s.pb, s.nominal, s.cal, s.refits, NULL_REFITS)
    s.clock.lap("null refits")


def _polish_stage(s: _State) -> None:
    assert s.pb is not None and s.cal is not None and s.nominal is not None
    # the leaders fitted to convergence before their residuals are judged: a candidate fit
    # stops after a fixed budget, and one that stopped short of noise would send the case to
    # the wider search for nothing (a creep device left at 1.09 x noise after its budget)
    polish_leaders(s.pb, s.cal, s.refits)
    # and the null gets the same chance from where the polished leader's nominal values went
    s.cal, s.null_source = refit_nulls(s.pb, s.nominal, s.cal, s.refits, NULL_REFITS)
    s.clock.lap("polish")


def _wider_search_stage(s: _State) -> None:
    pb, nominal = s.pb, s.nominal
    assert pb is not None and s.cal is not None and nominal is not None
    if not any(candidate_explains(pb, r.candidate) for r in s.refits) and not null_leaves_noise(pb, s.cal):
        # a systematic residual that no candidate fitted so far explains: the wider search
        # (a population search of every candidate's own, from the best null found so far)
        # before the answer may be "unexplained"
        s.refits = wide_search(pb, s.cal, s.order, s.screened, s.refits)
        s.searched_wide = True
        before = s.cal.fit.chi2
        s.cal, s.null_source = refit_nulls(pb, nominal, s.cal, s.refits, NULL_REFITS)
        if s.cal.fit.chi2 < 0.5 * before and not any(candidate_explains(pb, r.candidate) for r in s.refits):
            # a candidate led the null to a far better basin of the nominal parameters: the
            # candidates start again from there (scored and fitted as in the first round)
            s.order, s.screened = screen_candidates(pb, s.cal, nominal)
            again = fit_candidates(pb, s.cal, s.order, s.screened, s.refit_top)
            s.refits = better_of(s.refits, again)
            s.cal, s.null_source = refit_nulls(pb, nominal, s.cal, s.refits, NULL_REFITS)
        polish_leaders(pb, s.cal, s.refits)
    if not s.cal.search.converged and not any(candidate_explains(pb, r.candidate) for r in s.refits):
        # the calibration's local fits disagree and nothing explains the residual: a wrong
        # structure (a PE whose mass matters, modelled lumped) calibrates badly in the nominal
        # structure, and the structural candidate's fits start from that calibration; each
        # structural candidate gets a global calibration of its own
        s.stage = "the structural calibrations"
        s.refits = structural_calibrations(pb, s.cal, nominal, s.refits)
        polish_leaders(pb, s.cal, s.refits)
    s.clock.lap("wider search")


def _heldout_stage(s: _State) -> None:
    assert s.heldout is not None and s.cal is not None
    s.ranking = rank_with_heldout(s.refits, s.heldout)
    # the null's held-out prediction, for comparison, only where a candidate has one
    if any(is_finite(c.heldout_rms) for c in s.ranking):
        s.ho_cal = s.heldout.rms(s.cal.fit.spec, s.cal.at)
    s.clock.lap("held-out")


def _verdict_stage(s: _State) -> None:
    assert s.pb is not None and s.cal is not None and s.nominal is not None
    s.locations, windows = locate(s.rec, s.cal.fit.residuals, s.pb.sigma)
    s.spans = merge_windows(windows, s.pb.sigma)
    s.verdict, s.reason, s.rms_after = decide_verdict(s.ranking, s.cal, s.noise, s.ho_cal, s.searched_wide)
    if s.verdict != "none" and s.learned is not None:
        if s.cal.fit.chi2 < s.learned_chi2 - SEPARATION:
            # the null refitted from the candidates' optima left the calibration's far behind:
            # its residual, not the calibration's misfit, says what the reading carries
            s.learned = relearned(s.pb, s.cal, s.nominal, s.noise, s.learned)
            s.noise = synced(replace(s.noise, model=s.learned.model))
        if s.learned.weighable:
            _artefact_check(s)


def _artefact_check(s: _State) -> None:
    """A verdict that blames physics, weighed against what the reading was found to carry (hum
    lines, a zero drifting in each file, a late channel): where the calibrated null with them
    leaves noise as well as the verdict's model, they are measurement properties and nothing is
    missing."""
    assert s.pb is not None and s.cal is not None and s.nominal is not None and s.learned is not None
    named = [c for c in s.ranking if c.effect in s.verdict.split("+")] if s.verdict not in (
        "unexplained", "not_converged") else []
    lead_chi2 = min((c.chi2 for c in named), default=math.inf)
    fitted = [c for c in s.ranking if not c.screened_only and c.calibrated]
    leads = named or fitted
    learned = s.learned
    drifting = [c.spec for c in named if c.effect == COMMON_DRIFT_EFFECT and c.spec is not None]
    if learned.drift and drifting and not drift_beside(s.pb, s.cal, s.nominal, s.noise, learned, drifting[0]):
        # one rate for every file explains the slopes the per-file zeros took
        learned = replace(learned, drift=False)
        if not learned.weighable:
            return
    out = artefacts_instead(s.pb, s.cal, s.nominal, s.noise, learned, lead_chi2,
                            dict(leads[0].calibrated) if leads else None, named[0].spec if named else None)
    if out is None:
        return
    s.pb, s.cal, s.noise = out
    s.rec = s.pb.rec
    was = s.verdict
    s.verdict, s.rms_after = "none", s.cal.fit.rms
    what = s.noise.model.describe() if s.noise.model is not None else "measurement properties"
    s.reason = (f"the reading carries measurement properties, not physics ({what}): the calibrated model with "
                f"them leaves noise (RMS {s.cal.fit.rms / s.pb.sigma:.2f} x noise, whiteness z = "
                f"{s.cal.whiteness_z:.1f})"
                + (f" as well as {was} did" if named else f", where without them the verdict was {was}"))
    s.locations, windows = locate(s.rec, s.cal.fit.residuals, s.pb.sigma)
    s.spans = merge_windows(windows, s.pb.sigma)


def _second_effect_stage(s: _State) -> None:
    """One effect stands but leaves a systematic residual: a second one, from the model with it."""
    assert s.pb is not None and s.cal is not None and s.heldout is not None
    if s.verdict in ("unexplained", "not_converged"):
        s.lead = partial_leader(s.pb, s.refits)
    if s.lead is None:
        return
    s.clock.begin("second effect")
    first_twins = near_degenerate(list(s.screened.values()))
    with part("second round"):
        second = search_second_effect(s.pb, s.cal, s.lead, s.heldout, s.refits, first_twins)
    joint: Optional[SecondSearch] = None
    if not second.named:
        # two effects that each mimic part of the other from the leader's optimum: the
        # supported candidates' pairs fitted together from their fits alone
        with part("joint pair"):
            joint = joint_pair(s.pb, s.cal, s.refits, s.heldout, first_twins)
        if joint is not None and joint.named:
            second = joint
        elif joint is not None:
            second.reason += (f"; fitted jointly, {joint.first.effect} with "
                              f"{joint.pair.effect if joint.pair else '-'}: {joint.reason}")
            if joint.alone is not None and (second.alone is None or joint.alone.chi2 < second.alone.chi2):
                second.alone = joint.alone
    if second.named and second.pair is not None:
        s.verdict, s.reason, s.rms_after = (f"{second.first.effect}+{second.pair.effect}", second.reason,
                                            second.pair.rms_after)
    elif second.alone is not None:
        _second_alone(s, second)
    else:
        s.reason += f"; second effect: {second.reason}"
    s.second = second
    for search in (second, joint):
        if search is not None and search.pair is not None:
            search.misfit_share = pair_share(s.pb, s.cal, search)
    s.clock.lap("second effect")
    base, small = third_base(s.pb, s.cal, second, joint)
    if small is not None:
        s.reason += (f"; no third effect searched: {small.first.effect} with "
                     f"{small.pair.effect if small.pair else '-'} took {small.misfit_share:.0%} of the "
                     f"misfit the calibrated model leaves above noise (a third is searched beside a pair that "
                     f"took at least {THIRD_PAIR_SHARE:.0%}: of three effects missing, the two that explain "
                     f"most take about two thirds)")
    if base is not None:
        # a pair both effects support that leaves structure: a third from the model with the two
        s.clock.begin("third effect")
        with part("third round"):
            third = search_third_effect(s.pb, s.cal, base, s.heldout, first_twins)
        if third.named and third.third is not None:
            s.verdict, s.reason, s.rms_after = ("+".join((*third.pair, third.third.effect)), third.reason,
                                                third.third.rms_after)
        elif third.instead is not None:
            # one of the first pair was the look-alike of the third: the other two are the answer
            s.verdict, s.reason, s.rms_after = "+".join(third.instead), third.reason, third.instead_rms
        else:
            s.reason += f"; third effect: {third.reason}"
        s.third = third
        s.clock.lap("third effect")


def _second_alone(s: _State, second: SecondSearch) -> None:
    """The second effect alone, refitted from the pair's values, explains the residual and the
    first round's leader does not pay its own way beside it: the verdict is the second alone
    (its candidate replaces its first-round fit in the ranking)."""
    alone = second.alone
    assert alone is not None and s.pb is not None
    s.ranking = [alone] + [c for c in s.ranking if c.effect != alone.effect]
    note = ("; held-out prediction does not improve" if is_finite(alone.heldout_rms) and is_finite(s.ho_cal)
            and alone.heldout_rms > s.ho_cal * 1.02 else "")
    s.verdict, s.rms_after = alone.effect, alone.rms_after
    s.reason = (f"{alone.effect} improves BIC by {alone.delta_bic:.0f} over the best null fit and leaves noise "
                f"(RMS {alone.rms_after / s.pb.sigma:.2f} x noise){note}: found beside the first round's leader "
                f"{second.first.effect} (which left RMS {second.first.rms_after / s.pb.sigma:.2f} x noise) and "
                f"refitted alone from there; {second.first.effect} does not pay its own way beside it")


def _discovery_stage(s: _State) -> None:
    """Beyond the catalogue: only where every catalogue effect left a systematic residual; along
    the paths of :func:`.beyond_catalogue.discovery_paths` in turn until one names a term. After
    "not_converged" from the nominal values as given first: a missing force leaves the null
    several bad basins, each compensating for it its own way, and the force inferred from the
    best of them is bent by that compensation (a quadratic drag on the main body: from the
    calibration's best, 4.7 x noise, no form stood; from the nominal values, v1|v1| at the true
    coefficient, 1.00 x noise, held out 1.04 x: benches/RESULTS.md 15d-e). The found term's gain
    is then taken against the calibrated null too (:func:`.beyond_catalogue.found_against_null`)."""
    pb, cal, nominal, heldout = s.pb, s.cal, s.nominal, s.heldout
    assert pb is not None and cal is not None and nominal is not None and heldout is not None
    if not (s.discover and s.verdict in ("unexplained", "not_converged")):
        return
    s.clock.begin("discovery")
    if not is_finite(s.ho_cal):
        s.ho_cal = heldout.rms(cal.fit.spec, cal.at)
    was = (s.verdict, s.reason, s.rms_after)
    first, *others = discovery_paths(s.verdict, s.lead, cal, nominal, s.ho_cal)
    with part(f"discovery from {first.origin}"):
        _discover_from(s, first)
    earlier = ""  # what the paths before found, in words
    before_origin = first.origin
    for path in others:
        if s.verdict not in ("unexplained", "not_converged"):
            break
        # the other start, the data deciding; the path before is kept in the JSON
        before = s.found
        if before is not None:
            earlier += f"; discovery from {before_origin}: {before.reason}"
        s.verdict, s.reason, s.rms_after = was
        with part(f"discovery from {path.origin}"):
            _discover_from(s, path)
        s.found_other = before
        if s.verdict in ("unexplained", "not_converged"):
            s.reason += earlier
        before_origin = path.origin
    s.clock.lap("discovery")


def _discover_from(s: _State, path: DiscoveryPath) -> None:
    """Discovery along `path` (its model, free calibrated parameters, the held-out RMS [m] a
    found term must beat, the first effect beside it or None), settled into the verdict."""
    pb, cal, nominal, heldout = s.pb, s.cal, s.nominal, s.heldout
    assert pb is not None and cal is not None and nominal is not None and heldout is not None
    try:
        found = run_discovery(s.rec, path.spec, path.free, pb.obj, heldout, path.heldout_rms, nominal=nominal.spec,
                              progress=pb.tick)
    except DivergenceError as e:
        # a model the simulator cannot run through the inferred force: no discovery, said so
        s.reason += f"; discovery stopped: the simulator could not follow the inferred force ({e})"
    except (np.linalg.LinAlgError, NumericalFailure) as e:
        s.reason += f"; discovery stopped by a numerical failure, which says nothing about the physics: {e}"
    else:
        s.found, s.verdict, s.reason, s.rms_after = settle_discovery(
            pb, cal, heldout, s.ho_cal, found, path.lead, path.from_nominal, s.verdict, s.reason, s.rms_after)


def _next_experiment_stage(s: _State) -> None:
    """The experiment that separates the verdict from an alternative the data cannot tell apart
    from it, and the one that determines what the data left undetermined."""
    assert s.pb is not None
    s.degenerate = near_degenerate(list(s.screened.values()))
    s.alternatives = alternatives_to(s.ranking, s.verdict, _judged_twins(s))
    if s.alternatives:
        s.reason += "; cannot be told apart from " + ", ".join(f"{a.effect} ({a.why})" for a in s.alternatives)
        first = s.alternatives[0]
        s.clock.begin("next experiment")
        s.proposal = separating_experiment(s.pb, s.refits, first.replaces or s.verdict, first.effect)
        s.clock.lap("next experiment")
    elif s.found is not None and s.found.discovered and s.found.look_alike is not None:
        s.clock.begin("next experiment (look-alike)")
        s.proposal = look_alike_experiment(s.pb, s.found)
        s.clock.lap("next experiment (look-alike)")
    s.parameter_proposal = determining_experiment(s.pb, s.refits, s.verdict)
    if (s.parameter_proposal is None and s.verdict in ("unexplained", "not_converged") and s.found is not None
            and not s.found.discovered):
        s.parameter_proposal = travel_experiment(s.pb, s.found)
    if s.parameter_proposal is not None:
        s.clock.lap("next experiment (parameter)")


def _judged_twins(s: _State) -> list[tuple[str, str, float]]:
    """The near-parallel pairs the verdict's alternatives are read from: the first round's, and
    for a verdict of two or three effects their look-alikes as judged in each one's place."""
    named = set(s.verdict.split("+"))
    for search in (s.third, s.second):
        if search is not None and search.twins_judged and set(search.twins_judged) == named:
            return judged_pairs(s.degenerate, search.twins, named)
    return s.degenerate


#: the diagnosis: (what it is doing, for an interrupted run's report; the stage), in order
PIPELINE: tuple[tuple[str, Callable[[_State], None]], ...] = (
    ("the nominal model", _nominal_stage),
    ("the calibration", _calibration_stage),
    ("the screening", _screening_stage),
    ("the candidate fits", _candidate_stage),
    ("the null refits", _null_refit_stage),
    ("the polish", _polish_stage),
    ("the wider search", _wider_search_stage),
    ("the held-out prediction", _heldout_stage),
    ("the verdict", _verdict_stage),
    ("the second effect", _second_effect_stage),
    ("discovery", _discovery_stage),
    ("the next experiment", _next_experiment_stage),
)


def _result(s: _State) -> Diagnosis:
    """The Diagnosis of a finished run."""
    pb, nominal, cal, heldout = s.pb, s.nominal, s.cal, s.heldout
    assert pb is not None and nominal is not None and cal is not None and heldout is not None
    rec = s.rec
    return Diagnosis(
        case=rec.name, verdict=s.verdict, reason=s.reason, ranking=s.ranking, noise=s.noise,
        rms_before=math.sqrt(sum(float(np.sum(r * r)) for r in nominal.residuals) / pb.obj.n),
        rms_calibrated=cal.fit.rms, rms_after=s.rms_after,
        calibrated=cal.fit.values, calibrated_std=cal.fit.std, locations=s.locations, windows=s.spans,
        heldout_experiment=rec.experiments[heldout.index].name, heldout_rms_calibrated=s.ho_cal,
        whiteness_z_calibrated=cal.whiteness_z, seconds=time.perf_counter() - s.t_start, timings=s.clock.timings,
        timings_parts=s.clock.parts,
        simulations=s.sim.evaluations, recording=rec, nominal_residuals=nominal.residuals,
        calibrated_residuals=cal.fit.residuals, nominal_spec=nominal.spec, calibrated_spec=cal.fit.spec,
        simulator=s.sim, calibration_converged=cal.search.converged, calibration_summary=cal.search.summary(),
        calibration_chi2=[p.chi2 for p in cal.search.polishes], null_source=s.null_source,
        alternatives=s.alternatives,
        screening={k: v.delta_chi2 for k, v in sorted(s.screened.items(), key=lambda kv: -kv[1].delta_chi2)},
        degenerate_pairs=[list(p) for p in s.degenerate], searched_wide=s.searched_wide,
        calibration_multistart=cal.search.multistart.to_dict() if cal.search.multistart is not None else {},
        discovery=s.found, discovery_other=s.found_other, second=s.second, third=s.third,
        proposal=s.proposal, parameter_proposal=s.parameter_proposal,
    )


def _interrupted(s: _State, noise: NoiseEstimate) -> Diagnosis:
    """The Diagnosis of a run stopped by Ctrl-C: what was finished, marked incomplete (`noise`:
    the first estimate, before the calibration's cross-check)."""
    rec, cal, nominal = s.rec, s.cal, s.nominal
    n_all = s.pb.obj.n if s.pb is not None else max(rec.n_samples, 1)
    ranking = [r.candidate for r in by_rank(s.refits)]
    rms0 = (math.sqrt(sum(float(np.sum(r * r)) for r in nominal.residuals) / n_all) if nominal is not None
            else math.nan)
    locations: list[Location] = []
    if cal is not None:
        locations, _ = locate(rec, cal.fit.residuals, noise.sigma)
    fitted = sum(1 for c in ranking if not c.screened_only)
    return Diagnosis(
        case=rec.name, verdict="interrupted",
        reason=(f"stopped by Ctrl-C during {s.stage} after {time.perf_counter() - s.t_start:.0f} s; "
                f"finished: {'the calibration' if cal is not None else 'nothing past the nominal model'}"
                + (f" and {fitted} candidate fit{'s' if fitted != 1 else ''}" if fitted else "")
                + " (no verdict was reached)"),
        ranking=ranking, noise=noise, rms_before=rms0,
        rms_calibrated=cal.fit.rms if cal is not None else math.nan,
        rms_after=cal.fit.rms if cal is not None else math.nan,
        calibrated=dict(cal.fit.values) if cal is not None else {},
        calibrated_std=dict(cal.fit.std) if cal is not None else {}, locations=locations, windows=[],
        heldout_experiment="", heldout_rms_calibrated=math.nan,
        whiteness_z_calibrated=cal.whiteness_z if cal is not None else math.nan,
        seconds=time.perf_counter() - s.t_start, timings=s.clock.timings, timings_parts=s.clock.parts,
        simulations=s.sim.evaluations,
        recording=rec, nominal_residuals=nominal.residuals if nominal is not None else [],
        calibrated_residuals=cal.fit.residuals if cal is not None else [],
        nominal_spec=nominal.spec if nominal is not None else None,
        calibrated_spec=cal.fit.spec if cal is not None else None, simulator=s.sim,
        calibration_converged=cal.search.converged if cal is not None else False,
        calibration_summary=cal.search.summary() if cal is not None else "",
        screening={k: v.delta_chi2 for k, v in sorted(s.screened.items(), key=lambda kv: -kv[1].delta_chi2)},
        complete=False,
    )
