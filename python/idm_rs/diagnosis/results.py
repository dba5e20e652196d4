"""What a diagnosis returns (:class:`Diagnosis`, with a :class:`Candidate` per catalogue effect
tried). The algorithm (:mod:`.diagnose`) builds these; the report (:func:`.report.text_report`)
and the figures (:func:`.plots.plot_diagnosis`) are functions of a :class:`Diagnosis` that read
these classes for their types only: this module imports neither, so the imports run one way."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, Optional

import numpy as np
from numpy.typing import NDArray

from ..io.recording import Recording
from .case_model import CaseSimulator, ModelSpec
from .identifiability import ParamStatus
from .locate import Location
from .noise import NoiseEstimate
from .thresholds import LR_ALPHA

if TYPE_CHECKING:
    from .discovery import Discovery
    from .next_experiment import ParameterProposal, Proposal


@dataclass
class Candidate:
    """One catalogue effect tried on the case."""

    effect: str
    description: str
    params: dict[str, float]  #: fitted effect parameters (catalogue names, SI)
    std: dict[str, float]  #: their 1-sigma uncertainty from the Jacobian
    calibrated: dict[str, float]  #: the nominal subset refitted alongside
    chi2: float  #: residual energy / noise variance
    n_params: int  #: fitted parameters (nominal subset + effect + offsets)
    bic: float
    delta_bic: float  #: BIC improvement over the calibrated nominal model (positive: better)
    rms_after: float  #: [m]
    heldout_rms: float  #: RMS on the held-out experiment after fitting the others [m] (NaN if not run)
    whiteness_z: float  #: lag-1 autocorrelation of the residual, as a z-score
    screened_only: bool  #: True when fitted over the first cycle only (not refined over everything)
    residuals: list[NDArray[np.float64]] = field(default_factory=list, repr=False)
    spec: Optional[ModelSpec] = field(default=None, repr=False)
    #: 1-sigma of `params` where known (for a reparametrised fit, propagated to the reported names)
    reported_std: dict[str, float] = field(default_factory=dict, repr=False)
    #: distance of each fitted effect parameter from its "no effect" value, in its 1-sigma
    significance: dict[str, float] = field(default_factory=dict)
    #: correlation matrix of the effect's fitted parameters (names in `params` order of the fit)
    correlation: dict[str, dict[str, float]] = field(default_factory=dict)
    #: the fit ended no better than the null model, so it is reported at "no effect"
    at_null: bool = False
    #: the screening score at the null optimum (chi^2 drop of one linearised step)
    score: float = math.nan
    #: the multistart's local fits: where each started and ended (empty when not fitted)
    multistart: dict[str, Any] = field(default_factory=dict, repr=False)

    #: likelihood ratio against the null model it contains: null chi^2 minus this fit's chi^2
    lr_chi2: float = math.nan
    #: which fitted parameters (effect and calibrated) the experiments determine (Fisher matrix)
    identifiability: list[ParamStatus] = field(default_factory=list, repr=False)
    #: 1-sigma of `calibrated` (the nominal subset refitted alongside) from the Jacobian
    calibrated_std: dict[str, float] = field(default_factory=dict)

    @property
    def fit_label(self) -> str:
        """How the candidate's numbers came about, in the words the report and the figures share:
        "score only" (not fitted: the screening step's linearised numbers), "at null" (fitted, and
        no better than the null model it contains: reported at that null) or "fitted"."""
        return "score only" if self.screened_only else "at null" if self.at_null else "fitted"

    def rms_over_noise(self, sigma: float) -> float:
        """RMS after / noise where the candidate was fitted; NaN for a score-only one, whose
        fit never ran (its residual is the null's: no number of its own to show)."""
        return self.rms_after / sigma if not self.screened_only and sigma > 0 else math.nan

    @property
    def delta_bic_words(self) -> str:
        """ΔBIC as the report's table and the ranking figure both show it: the number where the
        candidate beats the null, else "not supported" (a large negative number says nothing
        more, and the figure draws no bar for it)."""
        if not math.isfinite(self.delta_bic):
            return "–"
        return f"{self.delta_bic:.1f}" if self.delta_bic > 0 else "not supported"

    @property
    def lr_critical(self) -> float:
        from scipy.stats import chi2

        return float(chi2.isf(LR_ALPHA, max(len(self.significance), 1)))

    @property
    def present(self) -> bool:
        """Whether the effect differs from its absence: the likelihood-ratio test against the null
        model it contains rejects "no effect" at LR_ALPHA (a per-parameter Wald distance misleads
        for an effect whose parameters are correlated with each other or with a nominal
        parameter at its bound: a creep's amplitude and time constant, fitted to 1 % and 18 %,
        each came out ~1 sigma from zero)."""
        return not self.at_null and math.isfinite(self.lr_chi2) and self.lr_chi2 > self.lr_critical

    def to_dict(self) -> dict[str, Any]:
        return {
            "effect": self.effect,
            "params": self.params,
            "params_std": self.std,
            "rms_after": self.rms_after,
            "bic": self.bic,
            "delta_bic": self.delta_bic,
            "heldout_rms": None if math.isnan(self.heldout_rms) else self.heldout_rms,
            "chi2": self.chi2,
            "n_params": self.n_params,
            "whiteness_z": self.whiteness_z,
            "screened_only": self.screened_only,
            "calibrated": self.calibrated,
            "calibrated_std": self.calibrated_std,
            "significance_sigmas": self.significance,
            "correlation": self.correlation,
            "present": self.present,
            "likelihood_ratio_chi2": None if math.isnan(self.lr_chi2) else self.lr_chi2,
            "score": None if math.isnan(self.score) else self.score,
            "multistart": self.multistart,
            "identifiability": [p.to_dict() for p in self.identifiability],
        }


@dataclass(frozen=True)
class Alternative:
    """An effect the data cannot tell apart from the verdict's, and why."""

    effect: str
    delta_bic: float
    why: str
    #: for a verdict of two effects: the one of them this effect could stand in for ("" otherwise)
    replaces: str = ""

    def to_dict(self) -> dict[str, Any]:
        out: dict[str, Any] = {"effect": self.effect, "delta_bic": self.delta_bic, "why": self.why}
        if self.replaces:
            out["replaces"] = self.replaces
        return out


@dataclass
class SecondSearch:
    """The search for a second effect from the model with the first (the leader that is
    supported but leaves a systematic residual)."""

    first: Candidate  #: the first effect, as fitted in the first round
    pair: Optional[Candidate] = None  #: the best second effect fitted with the first (its spec holds both)
    named: bool = False  #: both effects stand: the verdict names them
    reason: str = ""
    #: each effect's share of the chi^2 the pair removes from the calibrated null (sums to 1)
    shares: dict[str, float] = field(default_factory=dict)
    #: the pair's held-out RMS [m], and the first effect's alone
    heldout_rms: float = math.nan
    first_heldout_rms: float = math.nan
    #: ΔBIC of the pair over each effect alone (each must pay its own way)
    over_first: float = math.nan
    over_second_alone: float = math.nan
    ranking: list[Candidate] = field(default_factory=list)  #: the second round's candidates (with the first)
    #: the pair's free parameters at its optimum and its model before them (for a refit)
    free: list[Any] = field(default_factory=list, repr=False)
    base: Optional[ModelSpec] = field(default=None, repr=False)
    #: how the pair was found: False, from the first's optimum (screening and multistart fits);
    #: True, the two fitted together from the nominal values, each at its fit alone
    joint: bool = False
    #: the second effect alone, refitted from the pair's values, where it explains the residual
    #: and the first does not pay its own way beside it: the first round's leader only mimicked
    #: part of it, and this is the answer (scored against the calibrated null)
    alone: Optional[Candidate] = None
    #: a named pair's look-alikes refitted in each effect's place (:class:`.pair_twins.Twin`), and
    #: the effects so judged
    twins: list[Any] = field(default_factory=list)
    twins_judged: list[str] = field(default_factory=list)
    #: the share of the chi^2 the calibrated null leaves above noise that the pair took
    #: (:func:`.third_effect.pair_share`; a third is searched only beside a pair with a third of it)
    misfit_share: float = math.nan

    def to_dict(self) -> dict[str, Any]:
        return {
            "first": self.first.effect, "joint": self.joint, "misfit_share": self.misfit_share,
            "twins": [t.to_dict() for t in self.twins],
            "second": self.pair.effect if self.pair else None,
            "named": self.named,
            "reason": self.reason, "shares": self.shares, "heldout_rms": self.heldout_rms,
            "first_heldout_rms": self.first_heldout_rms, "delta_bic_over_first": self.over_first,
            "delta_bic_over_second_alone": self.over_second_alone,
            "pair": self.pair.to_dict() if self.pair else None,
            "alone": self.alone.to_dict() if self.alone else None,
            "ranking": [c.to_dict() for c in self.ranking],
        }


@dataclass
class ThirdSearch:
    """The search for a third effect from the model with a pair that both effects support but
    that leaves a systematic residual."""

    pair: tuple[str, str]  #: the pair's effects (first, second)
    third: Optional[Candidate] = None  #: the best third effect fitted with the pair (its spec holds all three)
    named: bool = False  #: all three stand: the verdict names them
    reason: str = ""
    #: the triple's held-out RMS [m], and the pair's
    heldout_rms: float = math.nan
    pair_heldout_rms: float = math.nan
    #: ΔBIC of the triple over the other two without each of the pair's effects
    over_without: dict[str, float] = field(default_factory=dict)
    ranking: list[Candidate] = field(default_factory=list)  #: the third round's candidates (with the pair)
    free: list[Any] = field(default_factory=list, repr=False)
    base: Optional[ModelSpec] = field(default=None, repr=False)
    #: the two effects named instead of the triple when one of the first pair does not pay its
    #: own way beside the other two and those two leave noise (the pair's first effect was the
    #: look-alike of the third), with their RMS [m]; else None
    instead: Optional[tuple[str, str]] = None
    instead_rms: float = math.nan
    #: the two's fit (the second's candidate; its spec holds both), when `instead` is set
    instead_candidate: Optional[Candidate] = None
    #: the named effects' look-alikes refitted in each one's place (:class:`.pair_twins.Twin`),
    #: and the effects so judged (the triple's, or the two's named instead)
    twins: list[Any] = field(default_factory=list)
    twins_judged: list[str] = field(default_factory=list)
    #: (the pair's member, its look-alike in its place) where this round ran from the pair with
    #: the look-alike because the round from the pair as found named nothing; that round's
    #: reason in `first_path`
    swapped: Optional[tuple[str, str]] = None
    first_path: str = ""
    #: (the pair's member dropped, the third kept in its place) where this round ran from the
    #: other member and the first round's third because the triple left a systematic residual;
    #: that round's reason in `first_path`
    exchanged: Optional[tuple[str, str]] = None

    def to_dict(self) -> dict[str, Any]:
        return {"pair": list(self.pair), "third": self.third.effect if self.third else None, "named": self.named,
                "swapped": list(self.swapped) if self.swapped else None, "first_path": self.first_path,
                "exchanged": list(self.exchanged) if self.exchanged else None,
                "instead": list(self.instead) if self.instead else None, "instead_rms": self.instead_rms,
                "reason": self.reason, "heldout_rms": self.heldout_rms, "pair_heldout_rms": self.pair_heldout_rms,
                "delta_bic_without": self.over_without, "triple": self.third.to_dict() if self.third else None,
                "ranking": [c.to_dict() for c in self.ranking], "twins": [t.to_dict() for t in self.twins]}


@dataclass
class Diagnosis:
    """What `diagnose` found. `verdict` is a catalogue id; "none" (the calibrated nominal model
    leaves noise and no effect is supported); "unexplained" (a systematic residual remains that
    no catalogue effect explains, although the calibration converged, and discovery found no term
that stands); "discovered" (no catalogue effect, but a force of a library form found in the data,
modelled and refitted, improves BIC by the threshold and the held-out prediction: see
``discovery``); or "not_converged" (the
    calibration's independent searches did not agree and the residual is not noise: the tool's
    own fit failed, which says nothing about missing physics); or "interrupted" (Ctrl-C stopped it:
``complete`` is False and the result holds what was finished)."""

    case: str
    verdict: str
    reason: str
    ranking: list[Candidate]
    noise: NoiseEstimate
    rms_before: float  #: nominal model, offsets fitted [m]
    rms_calibrated: float  #: after calibrating the nominal subset [m]
    rms_after: float  #: after adding the verdict's effect (= calibrated for none/unexplained) [m]
    calibrated: dict[str, float]
    calibrated_std: dict[str, float]
    locations: list[Location]  #: experiment x phase, sorted by share of excess residual energy
    windows: list[Location]  #: systematic time windows (merged), for plots
    heldout_experiment: str
    heldout_rms_calibrated: float
    whiteness_z_calibrated: float
    seconds: float
    timings: dict[str, float]  #: seconds per stage
    simulations: int
    recording: Recording = field(repr=False)
    nominal_residuals: list[NDArray[np.float64]] = field(default_factory=list, repr=False)
    calibrated_residuals: list[NDArray[np.float64]] = field(default_factory=list, repr=False)
    nominal_spec: Optional[ModelSpec] = field(default=None, repr=False)
    calibrated_spec: Optional[ModelSpec] = field(default=None, repr=False)
    simulator: Optional[CaseSimulator] = field(default=None, repr=False)
    #: the calibration's convergence evidence: independent polishes agreed
    calibration_converged: bool = True
    calibration_summary: str = ""
    #: chi^2 of each independent calibration polish (noise units), best first
    calibration_chi2: list[float] = field(default_factory=list)
    #: null refits: the nominal model refitted from each candidate's nominal parameters; the best
    #: one found anywhere is the null every candidate is compared with
    null_source: str = "calibration"
    #: effects the data cannot tell apart from the verdict's (the verdict stays the leader)
    alternatives: list[Alternative] = field(default_factory=list)
    #: screening score of every applicable effect at the null optimum (chi^2 units), best first
    screening: dict[str, float] = field(default_factory=dict)
    #: pairs of effects whose projected signatures are near-parallel: [effect, effect, |cos|]
    degenerate_pairs: list[list[Any]] = field(default_factory=list)
    #: every candidate was fitted (the residual was systematic and the first round found nothing)
    searched_wide: bool = False
    #: the calibration's multistart: every local fit's start and end
    calibration_multistart: dict[str, Any] = field(default_factory=dict, repr=False)
    #: False when Ctrl-C stopped the run: verdict "interrupted", what was finished is kept
    complete: bool = True
    #: discovery beyond the catalogue (run when no catalogue effect explained the residual):
    #: verdict "discovered" when its found term stood; None when it did not run
    discovery: Optional["Discovery"] = None
    #: seconds, simulated runs and calls of the named parts of the stages ("second effect /
    #: round beside / wide search": a part inside another is counted in both)
    timings_parts: dict[str, list[float]] = field(default_factory=dict)
    #: where discovery ran from the model with a first effect that left structure and then from
    #: the calibrated model without it: the path not taken (``discovery`` holds the other)
    discovery_other: Optional["Discovery"] = None
    #: the search for a second effect (run when one effect stood but left a systematic
    #: residual); verdict "first+second" when both stood
    second: Optional[SecondSearch] = None
    #: the search for a third effect (run when a supported pair left a systematic residual);
    #: verdict "first+second+third" when all three stood
    third: Optional[ThirdSearch] = None
    #: the drive that would best tell the verdict from its near-parallel alternative (None when
    #: there is none)
    proposal: Optional["Proposal"] = None
    #: the drive that would best determine an effect parameter the recordings leave undetermined
    parameter_proposal: Optional["ParameterProposal"] = None

    @property
    def best(self) -> Optional[Candidate]:
        return self.ranking[0] if self.ranking else None

    @property
    def effects(self) -> list[str]:
        """The catalogue effects the verdict names (none, one, or two or three joined by "+")."""
        ids = {c.effect for c in self.ranking}
        for search in (self.second, self.third):
            ids |= {c.effect for c in search.ranking} if search is not None else set()
        return [v for v in self.verdict.split("+") if v in ids]

    @property
    def verdict_candidate(self) -> Optional[Candidate]:
        """The fitted model of the verdict: the named effect's candidate, or for two effects the
        second's fitted with the first (its spec holds both), for three the third's fitted with
        the pair; None otherwise."""
        if self.verdict.count("+") == 2 and self.third is not None and self.third.named:
            return self.third.third
        if "+" in self.verdict and self.second is not None and self.second.named:
            return self.second.pair
        if self.third is not None and self.third.instead is not None and self.verdict == "+".join(self.third.instead):
            return self.third.instead_candidate
        return next((c for c in self.ranking if c.effect == self.verdict), None)

    def to_dict(self) -> dict[str, Any]:
        return {
            "case": self.case,
            "complete": self.complete,
            "verdict": self.verdict,
            "reason": self.reason,
            "ranking": [c.to_dict() for c in self.ranking],
            "rms_before": self.rms_before,
            "rms_calibrated": self.rms_calibrated,
            "rms_after": self.rms_after,
            "noise_rms": self.noise.sigma,
            "noise": {**{k: v for k, v in self.noise.__dict__.items() if k != "model"},
                      "model": self.noise.model.to_dict() if self.noise.model is not None else None},
            "calibrated": self.calibrated,
            "calibrated_std": self.calibrated_std,
            "locations": [loc.to_dict() for loc in self.locations],
            "systematic_windows": [w.to_dict() for w in self.windows],
            "heldout_experiment": self.heldout_experiment,
            "heldout_rms_calibrated": self.heldout_rms_calibrated,
            "whiteness_z_calibrated": self.whiteness_z_calibrated,
            "seconds": self.seconds,
            "timings": self.timings,
            "timings_parts": self.timings_parts,
            "simulations": self.simulations,
            "calibration": {"converged": self.calibration_converged, "summary": self.calibration_summary,
                            "polish_chi2": self.calibration_chi2, "null_from": self.null_source,
                            "multistart": self.calibration_multistart},
            "alternatives": [a.to_dict() for a in self.alternatives],
            "screening_scores": self.screening,
            "degenerate_pairs": self.degenerate_pairs,
            "searched_wide": self.searched_wide,
            "discovery": self.discovery.to_dict() if self.discovery is not None else None,
            "discovery_other_path": self.discovery_other.to_dict() if self.discovery_other is not None else None,
            "effects": self.effects,
            "second_effect": self.second.to_dict() if self.second is not None else None,
            "third_effect": self.third.to_dict() if self.third is not None else None,
            "next_experiment": self.proposal.to_dict() if self.proposal is not None else None,
            "determining_experiment": (self.parameter_proposal.to_dict() if self.parameter_proposal is not None
                                       else None),
        }
