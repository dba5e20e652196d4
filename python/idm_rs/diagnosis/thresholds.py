"""Every number the diagnosis is tuned by, in one place: what it controls, its unit, and the
measurement or argument that set it. Read by the stages, the results, the report and the
figures; this module imports nothing of the package.

Sections follow the diagnosis's order: the verdict's rules; the noise and where the residual
lives; the fits; the calibration of the nominal parameters; the catalogue candidates; the
second effect; discovery; what the data determine and the experiment proposed next. Counts are
plain numbers (fits, evaluations, cycles); chi^2 is in units of the noise variance.
"""

from __future__ import annotations

from typing import Optional

import numpy as np

# --- the verdict ------------------------------------------------------------------------------

#: BIC improvement [chi^2 units] an effect needs to count as found: "very strong" evidence on
#: the Kass-Raftery scale
BIC_THRESHOLD = 10.0
#: BIC [chi^2 units] by which an effect must beat the runner-up to be named alone
SEPARATION = 10.0
#: a measurement property (a channel delay) that leaves noise stands in for the verdict's effect
#: unless the effect's fit is closer by more than SEPARATION and the data choose it beyond this
#: many standard deviations of the chi^2 difference under the noise (:mod:`.closer`: the
#: delay's null rejected and the effect's fit within CLOSER_FITS_Z, or the effect closer where
#: both are rejected; one-sided 1.3e-3). A delay of 3.3 us read at a resolution of 4.9 x the
#: noise and simulated rounded to a fit step let a sensor lag of 3.3 us fit 12.7 closer,
#: D = 109: both rejected (z 4.8 and -3.8), closer by z = 0.5: neither chosen. The development
#: devices' true lags: sensor 5.5 and 10 us closer by z = 12 and 25; an amplifier lag of 3.9 us
#: under 2.5 nm of noise closer by 41.6 of D = 48.7 (z = 2.9), the delay's null rejected
#: (z = 6.3), the lag's fit within (z = -0.5)
CLOSER_Z = 3.0
#: how far (standard deviations) the effect's own fit may sit from the data for Cox's choice of
#: it: 97.7 % of true lags; data between the two fits, 5 noise units from each, choose the
#: effect by chance 0.2 % of the time (3.2 % at CLOSER_Z)
CLOSER_FITS_Z = 2.0
#: autocovariance lags (samples) the spread of that difference counts: the rounding error of a
#: coarse reading stays while the body sticks
CLOSER_LAGS = 20
#: residual RMS / noise RMS below which what is left counts as noise
NOISE_RATIO_OK = 1.1
#: lag-1 autocorrelation z-score above which a residual counts as systematic (about N(0, 1) for
#: white noise: one-sided 3e-5 beyond 4; every healthy development device's calibrated residual
#: was within 1.4, devices with an effect mostly beyond 4.4)
WHITENESS_Z = 4.0
#: a reading whose resolution step is at least this many times the residual's RMS has its
#: rounding's mean error taken out before the whiteness test (noise below ~0.4 of a step leaves
#: the rounding undithered: its mean error's first harmonic is exp(-2 pi^2 (sigma/step)^2) of
#: step / pi, 4 % at 0.4 of a step, 29 % at a quarter; a residual's RMS counts the rounding's
#: own error, so noise of 0.4 step reads 0.5 step)
ROUNDING_COARSE = 2.0
#: harmonics of the rounding's mean error fitted (the second's amplitude is the first's to the
#: fourth power: 0.7 % of step / 2 pi at a quarter step of noise)
ROUNDING_HARMONICS = 2
#: candidates refitted over everything after the one-cycle fits of all of them
REFIT_TOP = 3
#: significance level of the likelihood-ratio test of an effect against the null model it
#: contains; the effect sits at a boundary of its nested model (a chi-bar-squared reference,
#: Self & Liang 1987), whose tail the chi-squared with as many degrees of freedom as the effect
#: has parameters bounds from above: the test used is that conservative bound
LR_ALPHA = 1e-3

# --- the noise, and where the residual lives --------------------------------------------------

#: the rest and residual noise estimates disagree when they differ by more than this many
#: combined standard deviations
DISAGREE_SIGMAS = 3.0
#: second differences of a fitted residual farther than this many robust scales from their median
#: are a slip's or a stick's bend, not noise, and are left out of the residual's noise estimate
#: (a Gaussian loses 5.7e-7 of its samples there; :func:`.noise.residual_sigma`)
RESIDUAL_CLIP = 5.0
#: window length of the time localisation [s]: a tenth of a 100 Hz drive cycle, two fast edges
WINDOW_S = 1e-3
#: z-score above which a window's or a phase's residual energy counts as systematic
SYSTEMATIC_Z = 4.0

# --- the measurement: the noise's colour, spikes, hum, a drifting zero, a late channel --------

#: significance of every test that adds something to the measurement model (a colour, a line,
#: a zero slope, a delay): the false-detection rate per recording of each, against the one-sided
#: chi^2 of its degrees of freedom. A measurement property wrongly taken on costs a little power;
#: one wrongly left out turns into a false alarm, but the tests run on every white recording too,
#: and there they must stay silent (the white path is then bit for bit the old one)
MEASUREMENT_ALPHA = 1e-4
#: highest autoregressive order of the noise model (chosen by AIC below it): enough for a
#: low-passed or 1/f noise over the 100 kHz sample band the rest segments resolve
AR_MAX_ORDER = 8
#: a sample deviating from the median of its six neighbours by more than this many robust
#: standard deviations of that deviation, its neighbours not, is a spike: rejected (replaced by
#: that median). Beyond 8 sigma a Gaussian sample falls once in 1e15; the isolation keeps a
#: misfit ringing (3 samples a period at 100 kHz) from being taken for one
OUTLIER_Z = 8.0
#: the rest samples of a file the colour is fitted to (the first ones; its removal matrix is
#: square in them), and the fixed-point iterations of the autocovariances' correction
COLOUR_SEGMENT_MAX = 2000
COLOUR_ITERATIONS = 4
#: a colour whose likelihood ratio against white noise is within this factor of its critical
#: value is kept only if it whitens the calibrated residual (noise_model.whitens): white noise's
#: rest passes the test now and then, near the critical value (LR 18.8 against 18.4); a real
#: colour's LR on the rest is far above (lag-1 0.5 over 600 samples: 172 against 15.1), and its
#: check would be read off a residual that can be mostly systematic
COLOUR_CONFIRM_LR = 3.0
#: significance at which a line is refused because its amplitude differs between files more than
#: their standard errors allow: the mains feed every file alike, where low-frequency noise gives
#: each file its own amplitude. An ordinary level: it guards the line against noise
LINE_SPREAD_ALPHA = 1e-2
#: significance at which a zero drift is refused because the rest before the drive (the device
#: still) does not drift as the file does: that test guards against taking a missing effect's
#: trend for the sensor's, so it is run at an ordinary level, not at MEASUREMENT_ALPHA
DRIFT_REST_ALPHA = 1e-3
#: ... or whose neighbours deviate by less than this share of its own deviation (a spike beside a
#: slip, where the residual moves fast: a misfit ringing's neighbours deviate as much as it does)
OUTLIER_ISOLATION = 0.35
#: the mains: fundamental frequencies [Hz] tested for a hum line, and the harmonics tested with
#: a significant fundamental
MAINS_HZ = (50.0, 60.0)
MAINS_HARMONICS = (2, 3)
#: the channel delays scanned [s] (both signs), and the scan's step
DELAY_RANGE_S = 40e-6
DELAY_STEP_S = 1e-6
#: the shortest delay taken for one [s]: a tenth of the 10 us sample step. A missing effect shifts
#: the best alignment of the calibrated prediction by a fraction of a microsecond (a spring to
#: ground: -0.5 us, significant) without any channel being late
DELAY_MIN_S = 1e-6
#: rounds of the delay and the null's parameters estimated in turn (at most), the change of the
#: delay [s] at which it counts as settled, and the share of chi^2 a round must leave (at most) for
#: another while the null does not leave noise: a delay that does not explain the residual stops
#: after two. The lag a delay is weighed against is fitted to convergence; so is the delay
DELAY_ROUNDS = 8
DELAY_TOL_S = 0.05e-6
DELAY_PROGRESS = 0.9
#: the colour read off the null's residual replaces the rest's where its lag-1 correlation is
#: within this many standard errors of the rest estimate's (a healthy device's residual is noise:
#: they agree; one that holds a missing effect reads a far stronger correlation)
RECOLOUR_SIGMAS = 3.0
#: where the residual's colour or level disagrees with the rest's, it is still noise (1/f noise
#: reads stronger over a whole file than over a detrended 2 ms rest) when its whitened residual
#: does not repeat from one drive cycle to the next: the sum over cycle pairs of their inner
#: products is N(0, 1) for noise (z below this, one-sided p 0.0013), and a missing effect
#: repeats with the drive
REPEAT_Z = 3.0
#: least-squares evaluations of the null's refit in the measurement's metric (it starts at the
#: calibrated optimum, which the white metric already found: a few Gauss-Newton steps)
REMEASURE_NFEV = 8

# --- fits ---------------------------------------------------------------------------------------

#: RK4 step of every fit [s]: within ~1e-11 m of dt = 5e-8 s on the development recordings (their
#: noise is ~1e-9 m); divides the 5 and 10 us sample steps and the 0.5 ms edges; a point that
#: diverges is retried at dt/2
FIT_DT = 2e-7
#: a channel delay within this fraction of a fit step of a whole number of steps is run at that
#: number alone (:meth:`.case_model.CaseSimulator.late`; 3.8 us / 0.2 us is 18.999999999999996
#: in floating point), else at the two around it, mixed
LATE_SNAP = 1e-6
#: a derivative of the readings [m per fit unit] beyond this many times the experiment's range of
#: motion (+1 um) has blown up: one fit unit is a few percent of a parameter, which cannot move
#: the reading by more than a few times its whole range
BLOWN_UP = 1e3
#: a knot's derivative column larger than this many times the forward difference of runs at
#: the same knot (norms) has blown up short of BLOWN_UP (discovery.infer._repair_columns): the
#: blown-up columns measured were 1e3-1e5 times the difference, the sound ones within 30 %
KNOT_DERIVATIVE_AGREE = 10.0
#: a fit stops when an accepted step gains less than this many chi^2 units times max(1, chi^2/n)
#: (scipy's `ftol`, relative to the cost, set to FTOL_CHI2 / n). Every decision the diagnosis
#: takes is 100 times coarser (AGREE_CHI2 = 25, the BIC threshold); at scipy's default (1e-8
#: relative, 1e-4 chi^2 units here) a fit started at its optimum took all its 16 evaluations
#: gaining 1e-3 chi^2 each: a third of the candidate-fit time of the slowest development case
FTOL_CHI2 = 0.1
#: a fit's start lies at least this far inside its bounds [fit units] (see fitting.inside_bounds):
#: far beyond scipy's 1e-10 "on the bound", and a change of the parameter of ~1e-8 of itself
START_INSIDE = 1e-6
#: step [fit units] of the central difference of the parameter setters' composition (no
#: simulation: exact for the linear setters, 1e-13 relative for the log-scaled ones)
CHAIN_STEP = 1e-6
#: drive cycles fitted at each stage of a progressive fit (None: all). Stick-slip makes the
#: misfit a rugged function of the parameters over many cycles (a slip event more or less
#: shifts everything after it), but a smooth one over the first cycle; each stage starts in
#: the basin the shorter one found
FIT_HORIZONS: tuple[Optional[int], ...] = (1, 2, None)
#: two local fits reached the same optimum when their chi^2 differ by less than this, in units
#: of the best fit's residual variance (the noise variance, or more where the residual is far
#: from noise: a model that misses an effect cannot tell optima apart more finely than its own
#: misfit, the quasi-likelihood scale of least squares)
AGREE_CHI2 = 25.0
#: a ranked start is worth a local fit when its chi^2 is within this factor of the best start's:
#: a start 100x worse does not reach the best basin in a few exact Gauss-Newton steps, and its
#: local fit costs as much as the best one's
PROMISING = 4.0
#: a local fit "leaves noise" when its chi^2 is within NOISE_CHI2_Z standard deviations of the
#: chi^2 of pure noise (n + z sqrt(2n)) and its residual's lag-1 whiteness z-score is within
#: NOISE_WHITENESS_Z: no other start can then end better by more than the noise's own
#: fluctuation, so `multistart(stop_at_noise=True)` fits no more starts. The whiteness test
#: guards against a noise level estimated a few per cent high, under which a basin that misses
#: a small effect passes the chi^2 test: the effect's smooth residual still shows in the
#: autocorrelation (900 chi^2 units over n = 20,000 samples give z ~ 6)
NOISE_CHI2_Z = 3.0
NOISE_WHITENESS_Z = 2.0

#: a fitted value within this share of its range from a bound counts as at the bound (a bounded
#: least-squares fit stops just inside; the report's change column's two decimals cannot tell
#: it apart)
AT_BOUND_SHARE = 1e-3

# --- the calibration of the nominal parameters -----------------------------------------------

#: the nominal parameters calibrated before any physics is blamed: the ones a lab knows least
#: well (friction levels and damping, the piezo constant, the masses)
CALIBRATED: tuple[str, ...] = ("mu_k", "d33", "sigma1", "sigma2", "fric_alpha", "m1", "m2")
#: bounds of a calibrated parameter, relative to its nominal value, and its fit scale (one fit
#: unit: 5 % of the nominal value)
CALIBRATION_RANGE = (0.6, 1.5)
CALIBRATION_SCALE = 0.05
#: drive cycles of every experiment the population search compares (cheap, and the misfit is
#: smooth over one cycle: FIT_HORIZONS)
SEARCH_CYCLES = 1
#: a calibration's local fits: over the first two drive cycles, then the whole record (a fit
#: over two cycles first keeps a far start out of the basins the later cycles' slips make), and
#: the evaluations of each stage (the later one starts close to its optimum)
CALIBRATION_HORIZONS: tuple[Optional[int], ...] = (2, None)
CALIBRATION_NFEV: tuple[int, ...] = (10, 12)
#: the population search: members per free parameter, generations
SEARCH_POPULATION_PER_PARAM = 6
SEARCH_GENERATIONS = 25
#: distinct good members the search hands on as starts
SEARCH_POLISHES = 2
#: Latin-hypercube starts over the plausible ranges, ranked beside the search's members
LHS_STARTS = 8
#: local fits from the best distinct promising ranked starts (the search's best member, the
#: nominal values and the best 1-D scan start get one each besides)
CALIBRATION_LOCAL_FITS = 1
#: points of each calibrated parameter's 1-D scan over its plausible range (the others at their
#: nominal values), over SCAN_CYCLES drive cycles
SCAN_POINTS = 21
SCAN_CYCLES = 2

# --- the catalogue candidates -----------------------------------------------------------------

#: |cos| of the angle between two effects' projected columns above which the data cannot tell
#: them apart to first order
DEGENERATE_COS = 0.95
#: |cos| at a named pair's model (the other effect in place) above which an effect of the pair and
#: another are refitted in each other's place to learn whether the data tell them apart (below
#: DEGENERATE_COS too: a twin at 0.949 there may still leave noise in its place, or not)
TWIN_CHECK_COS = 0.9
#: a third round that named nothing is run again with each of the pair's members replaced by
#: at most this many of its look-alikes (the nearest first): each costs a third round
RETRIED_TWINS = 1
#: least-squares evaluations of a pair refitted with a twin in place of one of its effects
TWIN_NFEV = 25
#: leading candidates whose nominal parameters seed a refit of the null model
NULL_REFITS = 1
#: least-squares evaluations of the final polish of the leading candidate (and of rivals within
#: SEPARATION of it, at most POLISH_CLOSE candidates in all)
POLISH_NFEV = 12
POLISH_CLOSE = 3
#: a polished leader that leaves structure is fitted again over these horizons (drive cycles of
#: every experiment; None: everything) from the nominal values as given and from the null fit,
#: its effect at its fitted value: over the first cycle the basins are not yet mixed (§39 of
#: benches/RESULTS.md: a weight drag fitted over everything at once slid into a second basin at
#: 1.53 x noise from every start; the first cycle first led to the truth, 0.99 x)
CONTINUATION_HORIZONS: tuple[Optional[int], ...] = (1, None)
CONTINUATION_NFEV: tuple[int, ...] = (16, 16)
#: multiples of an effect parameter's fit scale its multistart tries (both signs where signed)
CANDIDATE_MAGNITUDES = (1.0, 3.0, 10.0, 30.0)
#: the wider search: every candidate's population search (members per free parameter,
#: generations) over the first cycle, and the candidates that then get local fits
WIDE_POPULATION = 5
WIDE_GENERATIONS = 10
WIDE_FITS = 2
#: a candidate whose screening score (the chi^2 a linearised step would gain) is below this is
#: not fitted in the first round: it cannot approach BIC_THRESHOLD + its parameters' penalty
#: (the wider search, run when the residual is systematic, fits every candidate regardless)
MIN_SCORE = 5.0
#: a candidate's local fits: the horizons (drive cycles; None: everything) fitted in turn, and
#: least-squares evaluations at each. Everything at once: a recording holds only 2-5 drive
#: cycles, so two cycles save little, and their optimum can lie elsewhere (measured on a
#: spring-to-ground device of the confusion benchmark: from the nominal values with a spring of
#: 3e4 N/m, 8+8 evaluations over two cycles then everything ended at chi^2 6.3e6 with mu_k at its
#: bound; 12 over everything reach the truth). 16 evaluations: on another confusion device the
#: fit that reaches the truth (chi^2 5,324) stands at 131,830 after 8, behind a local minimum's
#: 17,600 (a short fit for all and a long one for the best misses it)
CANDIDATE_HORIZONS: tuple[Optional[int], ...] = (None,)
CANDIDATE_NFEV: tuple[int, ...] = (16,)
#: local fits per candidate's multistart from its best distinct ranked starts (the best start at
#: the nominal values as given gets one more)
CANDIDATE_FITS = 1

# --- the second effect ------------------------------------------------------------------------

#: candidates fitted (multistart) in the search for a second effect, best screened first
SECOND_TOP = 2
#: supported first-round candidates (best ΔBIC first) whose pairs are fitted jointly when the
#: search from the leader names no second effect, and the least-squares evaluations of each
#: joint fit (measured on a two-effect device, creep and incline mis-set together: from the
#: nominal values with each effect at its own fit alone, 24 evaluations reach noise; 12 stop at
#: 2.06 x noise)
JOINT_TOP = 3
JOINT_NFEV = 30
#: a third effect is searched beside a pair only where the pair took at least this share of the
#: chi^2 the calibrated null leaves above noise: of three effects missing, the two that explain
#: most alone take about two thirds of it where their signatures are orthogonal. Measured
#: (benches/RESULTS.md §59): the pairs of the named triples of the effect-set bench took 0.58-0.99
#: of it; the pairs of discovery devices (a force outside the catalogue) 0.08-0.93, each third
#: round from those below a third naming nothing after 2-7 minutes of fits
THIRD_PAIR_SHARE = 1.0 / 3.0

# --- discovery: the inferred force ------------------------------------------------------------

#: knots of the inferred force per drive cycle: resolves the slow phase's shape and the fast
#: edge to its own length (0.5 ms at 100 Hz)
KNOTS_PER_CYCLE = 20
#: accepted Levenberg-Marquardt steps of the force inference, at most (the force enters
#: linearly; what is left is the stick-slip's own nonlinearity), and trial steps in all
INFER_ITERATIONS = 8
INFER_MAX_TRIALS = 16
#: the first damping (relative to the diagonal of J'J), and the relative chi^2 gain below which
#: the inference has converged (beyond the `dof` units that fitting noise gains): judged on the
#: undamped linear step, so a damped step's small gain is never taken for convergence
INFER_LM_START = 0.01
INFER_CONVERGED_GAIN = 0.01
#: smoothing weights tried by generalised cross-validation, relative to tr(J'J)/tr(D'D)
SMOOTHING_GRID = np.logspace(-8, 2, 41)
#: the integrator of the force inference: Dormand-Prince, landing on every sample time. RK4 at
#: the fit step lets the derivatives grow without bound in fast slips (the friction state's
#: stability limit); the adaptive step keeps both the run and its derivatives stable. Its knot
#: derivatives agree with RK4's at dt = 1e-8 s (where RK4's are stable) to 3 % on the test
#: recordings, in 0.06 s per 8 knots of a 42 ms record (Rodas4's did not, through the kinks)
INFER_METHOD = dict(method="dopri5", rtol=1e-8, atol=1e-8)
#: the force the inference starts from [N], everywhere: not exactly zero, so a body at rest is
#: not exactly on the friction law's kinks (v1 = 0, Fh = 0), where a derivative is one-sided and
#: the side the value picks may be the wrong one for the perturbation (docs/SENSITIVITIES.md);
#: a micronewton moves the body by ~1e-16 m
START_FORCE = 1e-6
#: step [N] of the forward differences that replace a knot's derivative which blew up
FD_FORCE_STEP = 1e-4
#: step [fit units] of the forward differences that replace the calibrated parameters'
#: derivatives which blew up (the fits' own step, fitting.Objective.jacobian)
FD_PARAM_STEP = 1e-3
#: relative size of a pivot below which a column counts as dependent on the others (the
#: library's columns and the knots' bases; normal equations are solved at machine precision)
RANK_TOLERANCE = 1e-12

# --- discovery: the library regression and the refit ------------------------------------------

#: most library terms a discovered force may have
MAX_TERMS = 4
#: of a form that does not stand, the forms with one term swapped for its look-alike
#: (DEGENERATE_COS) refitted after the forms found, at most this many per form
MAX_LOOK_ALIKE_FORMS = 2
#: wavelengths [m] of the periodic library terms tried (their fit refines the one chosen)
WAVELENGTHS = np.geomspace(2e-6, 200e-6, 25)
#: a periodic term must lower the cross-validated error by this factor below the best
#: non-periodic form: the wavelength scan is itself a choice the data must pay for
PERIODIC_GAIN = 0.9
#: a term more must lower the cross-validated error by this factor and by TERM_SHARE of the
#: force's own effect
TERM_GAIN = 0.9
TERM_SHARE = 0.02
#: a found term whose refitted coefficient is within this many standard deviations of zero is
#: dropped unless the model without it is worse by BIC_THRESHOLD
PRUNE_Z = 5.0
#: a library term whose effect keeps less than this share of its size once the calibrated
#: parameters' directions are projected out is their alias (left out of the regression)
ALIAS_SHARE = 0.05
#: a form must predict the held-out experiments' force effect to within this share of it
#: (cross-validated error relative to the force's own effect): at least half explained
FORM_CV_MAX = 0.5
#: rounds of pruning (each drops every weak term at once and refits)
PRUNE_ROUNDS = 3
#: least-squares evaluations of the refit with the found terms
DISCOVERY_REFIT_NFEV = 25
#: backward elimination refits a unit away only where its linearised cost (the Wald chi^2 of
#: its coefficients at zero, from the refit's covariance, less the BIC its parameters save) is
#: within this factor of BIC_THRESHOLD: a refit re-optimises what the linearisation holds fixed
#: and its cost can come out below the linearised one; the factor is the margin left for that (not a
#: measured bound; a strong unit's refit is ~25 evaluations, and refitting every unit each round
#: took ~30 % of a discovery case's time)
ELIMINATION_LINEAR_FACTOR = 10.0
#: a form whose refit leaves more than this x noise is judged as refitted, without pruning or
#: backward elimination: dropping terms refits a model nested in it from its optimum, which
#: cannot come down to NOISE_RATIO_OK from this far (the margin over it is for a refit that
#: stopped short of its optimum in its evaluations); the elimination refits of forms that
#: could not stand took most of a discovery case's refits (benches/RESULTS.md §35, §40)
ELIMINATION_MAX_RATIO = 1.5
#: forms that gain but stop short of noise, searched globally when no form stands (lowest RMS
#: first): the calibrated parameters and the form's coefficients by the calibration's own
#: population search, 1-D scans and local fits. A missing force can hide the truth's basin from
#: every calibration start (a quadratic spring on the LPS with m2 mis-set 12 %: every basin at
#: m2 ~ 0.26 kg, x1^2 refitted from them 2.8 x noise, from the search with x1^2 free 0.99 x);
#: each costs ~1-3 minutes on one core, on cases that would otherwise find nothing
DISCOVERY_WIDE_FORMS = 2
#: the drive cycles a form's global search ranks its population over (None: the whole record,
#: with the ranking of its starts and its local fits over the whole record too). A term that
#: grows with the stroke hardly acts in the first cycle, which other values fit as well: a cubic
#: spring on the DPS 4 was searched to 2.34 x noise over one cycle and to 0.996 x over the whole
#: record, at 1.5 x the search's seconds, centred on the calibrated model (benches/RESULTS.md
#: §64); centred on the model with the first effect, where discovery searched that device, the
#: whole record ended at 2.47 x as one cycle did (§65). One cycle: None is not validated
FORM_SEARCH_CYCLES: Optional[int] = 1
#: forms found beside a first effect that did not stand, refitted alone (lowest RMS first):
#: beside the spurious effect the form nearest noise need not be the true one (RESULTS §21: the
#: 11.8 um periodic friction's true form came second, 1.05 against 1.04 x noise); each costs
#: a refit and its elimination (~1-3 minutes on one core)
ALONE_FORMS = 3

# --- what the data determine, and the experiment proposed next ---------------------------------

#: a parameter counts as determined when its 95 % interval's half-width is at most this share of
#: its value (the datasheet's target: every reported value within 25 % of the truth, or its
#: interval covering it)
DETERMINED_WITHIN = 0.25
#: two parameters whose estimates correlate beyond this are reported as a combination
STRONG_CORRELATION = 0.9
#: multiples of the largest recorded amplitude tried (a lab's amplifier reached the largest;
#: the smallest leave the body in presliding, where friction's shape shows)
PROPOSAL_AMPLITUDE_SHARES = (0.1, 0.25, 0.5, 0.75, 1.0)
#: frequencies tried [Hz]: these within [lowest / PROPOSAL_FREQUENCY_SPAN, highest x
#: PROPOSAL_FREQUENCY_SPAN] recorded, and the recorded ones themselves
PROPOSAL_FREQUENCIES = (10.0, 25.0, 50.0, 100.0, 200.0, 400.0, 800.0)
PROPOSAL_FREQUENCY_SPAN = 4.0
#: a predicted ΔBIC [chi^2 units] below this separates nothing (the verdict's own threshold)
SEPARATES = BIC_THRESHOLD
#: drives whose absorbed separation is computed (those with the largest raw difference): the
#: Jacobians are most of the cost (177 s for 70 drives of a look-alike pair on a busy machine)
PROPOSAL_SHORTLIST = 10
#: drive cycles of a proposed experiment
PROPOSAL_CYCLES = 4
#: a proposal for a force found along the stroke: drive cycles and amplitude shares tried (the
#: body must travel: each cycle advances it by one step, and the small amplitudes hardly move it)
TRAVEL_CYCLES = (4, 8, 16)
TRAVEL_SHARES = (0.75, 1.0)
