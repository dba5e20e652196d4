"""The thresholds the diagnosis's verdict uses (read by the algorithm, its results, the report and
the figures; this module imports nothing of the package)."""

#: BIC improvement (in chi^2 units) an effect needs to count as found: "very strong" evidence
#: on the Kass-Raftery scale
BIC_THRESHOLD = 10.0
#: an effect must beat the runner-up by this much BIC to be named alone
SEPARATION = 10.0
#: residual RMS / noise RMS below which what is left counts as noise
NOISE_RATIO_OK = 1.1
#: lag-1 autocorrelation z-score above which a residual counts as systematic (about N(0, 1) for
#: white noise: one-sided 3e-5 beyond 4; every healthy dev device's calibrated residual was
#: within 1.4, effect cases mostly beyond 4.4)
WHITENESS_Z = 4.0
#: candidates refitted over everything after the one-cycle fits of all of them
REFIT_TOP = 3
#: significance level of the likelihood-ratio test of an effect against the null model it
#: contains; the effect sits at a boundary of its nested model (a chi-bar-squared reference,
#: Self & Liang 1987), whose tail the chi-squared with as many degrees of freedom as the effect
#: has parameters bounds from above: the test used is that conservative bound
LR_ALPHA = 1e-3
