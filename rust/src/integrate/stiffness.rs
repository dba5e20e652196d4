//! Noticing stiffness in an adaptive run.
//!
//! **Stiffness** (Hairer & Wanner, *Solving ODEs II*, §IV.2, as in their DOPRI5 code): after
//! an accepted Dormand-Prince step, the last two stages are evaluated at the same time from two
//! nearby states (the sixth stage's state and the new state), so
//! h·|Δf| / |Δy| estimates h·|λ| for the Jacobian's dominant eigenvalue λ along that direction.
//! Dormand-Prince is stable up to h·|λ| ≈ 3.3 on the negative real axis; a step that keeps
//! sitting at 3.25 is limited by stability, not accuracy. 15 such accepted steps in a row make
//! the run stiff; 6 below it in a row reset the count.
//!
//! `method="auto"` asks, when Dormand-Prince's run of a lane turns stiff (and every
//! [`PROBE_EVERY`] accepted steps whatever the test says), whether the
//! implicit method pays there (`integrate/switching.rs`): one Rodas4 step of [`TRIAL_FACTOR`] times the
//! explicit step, then [`PROBATION_STEPS`] Rodas4 steps whose mean must be [`switch_gain`]
//! times the explicit step. A Rodas4 step costs ~4-6 Dormand-Prince steps as a sweep runs them
//! (Dormand-Prince on vector lanes, benches/RESULTS.md §24), so only a phase where
//! Rodas4's accuracy allows steps that much longer is worth the change. A single long trial step proves little (it can land
//! where the solution is smooth for a moment); the probation's mean is the run's own measure.
//! A failed trial or probation sends the lane back to Dormand-Prince, and the next trial needs
//! twice as many stiff steps in a row (so a moderately stiff run pays a few trials at most).
//! A stiff phase ends (a sliding phase stops): a lane on Rodas4 runs [`PROBATION_STEPS`]
//! Dormand-Prince steps every [`RECHECK_STEPS`] implicit steps (doubling, twice at most, while it stays) and
//! goes back for good when their mean step, times [`implicit_step_cost`], reaches Rodas4's
//! (the paper case turns stiff for a moment: without the check it ran 2.7x slower than
//! Dormand-Prince alone on Rodas4 steps no longer than the explicit ones).

/// Dormand-Prince's stability boundary used by the test (h|λ| above it: at the limit).
pub const STIFF_H_LAMBDA: f64 = 3.25;
/// Accepted steps in a row at the limit that make a run stiff.
pub const STIFF_STEPS: u32 = 15;
/// Accepted steps in a row at the limit after which `method="auto"` tries Rodas4 (Hairer's
/// 15 marks a run stiff; a stiff burst that short does not pay for leaving the vector lanes: at
/// 15 the 256-point DPS4 grid ran 0.88x Dormand-Prince's speed, benches/RESULTS.md §4; a run
/// held at the limit for good, as a near-frictionless contact is, still changes within a few
/// hundred steps).
pub const TRY_IMPLICIT_AFTER: u32 = 256;
/// Accepted explicit steps since a lane started or last came back from Rodas4 after which
/// `method="auto"` tries Rodas4 whatever the stiffness test says (doubling with each failed
/// trial, as the stiff steps a trial needs do). The explicit steps that resolve a lightly damped
/// ringing are held by accuracy, not stability: at the light, fast corner only 4 % of them sit
/// at the limit, the test never fired there, and the run ended on 34,443 explicit steps where
/// Rodas4 alone takes 3,361 (benches/RESULTS.md §36). Counted there, a probe every 1,024 steps
/// brought `auto`'s work within 0.96x of the cheaper single method in every corner; every 512
/// put a corner point 9.7 nm off; timed (§41), every 2,048 was no faster anywhere.
pub const PROBE_EVERY: u32 = 1024;
/// Accepted steps in a row below the limit that reset the count.
pub const NONSTIFF_STEPS: u32 = 6;
/// The trial Rodas4 step of a stiff lane, in units of its explicit step (see above).
pub const TRIAL_FACTOR: f64 = 20.0;
/// Rodas4 steps on probation after an accepted trial (the trial among them).
pub const PROBATION_STEPS: u32 = 8;
/// A Rodas4 step's cost in Dormand-Prince steps for a state of `dim` components, as a sweep runs
/// them (Dormand-Prince on the vector lanes): 3.9 for the LPS (7 components) since Rodas4 runs
/// over the lanes (benches/RESULTS.md §24; 5.0 before, §4) and 6.0 for the DPS with 4 elements
/// (13), the earlier slope scaled alike; the LU and the solves grow faster with the state than
/// the right-hand side does. Linear through both, at least 2.3.
pub fn implicit_step_cost(dim: usize) -> f64 {
    (3.9 + 0.35 * (dim as f64 - 7.0)).max(2.3)
}

/// The mean Rodas4 step over the probation, in units of the explicit step, at which a lane of
/// `dim` components stays implicit: three times [`implicit_step_cost`].
pub fn switch_gain(dim: usize) -> f64 {
    3.0 * implicit_step_cost(dim)
}
/// Implicit steps after which a lane on Rodas4 checks whether Dormand-Prince would now be
/// cheaper (doubling after each check that keeps it implicit, up to [`MAX_RECHECK_BACKOFF`]
/// doublings: a stiff phase that ends is noticed within 128 implicit steps).
pub const RECHECK_STEPS: u32 = 32;
/// Doublings of [`RECHECK_STEPS`] at most.
pub const MAX_RECHECK_BACKOFF: u32 = 2;
/// Failed trials after which the number of stiff steps a new trial needs stops doubling.
pub const MAX_TRIAL_BACKOFF: u32 = 6;

/// Hairer's stiffness counter for one lane.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct StiffnessTest {
    at_limit: u32,
    below: u32,
    /// accepted steps observed since the test was made (a lane's start or its return from Rodas4)
    since: u32,
}

impl StiffnessTest {
    /// Count one accepted step with estimate `h_lambda` = h|λ|; true once `needed` steps in a
    /// row were at the limit ([`STIFF_STEPS`] for Hairer's test), or once [`PROBE_EVERY`] steps
    /// were observed in all, scaled as `needed` is beyond [`TRY_IMPLICIT_AFTER`] (the probe).
    #[inline(always)]
    pub fn observe(&mut self, h_lambda: f64, needed: u32) -> bool {
        self.since += 1;
        if self.since >= PROBE_EVERY.saturating_mul((needed / TRY_IMPLICIT_AFTER).max(1)) {
            return true;
        }
        if h_lambda > STIFF_H_LAMBDA {
            self.below = 0;
            self.at_limit += 1;
        } else {
            self.below += 1;
            if self.below >= NONSTIFF_STEPS {
                self.at_limit = 0;
            }
        }
        self.at_limit >= needed
    }
}

/// h|λ| from the last Dormand-Prince stages of one lane: `step` [s], the sixth stage's state
/// `y6` and derivative `k6`, the new state `y7` and its derivative `k7`, each component read
/// through `get(array, component)` and measured in units of its error scale (components with
/// an infinite scale are left out, as in the error norm). 0 when the two states coincide.
#[inline(always)]
pub fn h_lambda(
    step: f64,
    d: usize,
    scale: impl Fn(usize) -> f64,
    y6: impl Fn(usize) -> f64,
    k6: impl Fn(usize) -> f64,
    y7: impl Fn(usize) -> f64,
    k7: impl Fn(usize) -> f64,
) -> f64 {
    let (mut num, mut den) = (0.0, 0.0);
    for c in 0..d {
        let s = scale(c);
        if s.is_finite() {
            num += ((k7(c) - k6(c)) / s).powi(2);
            den += ((y7(c) - y6(c)) / s).powi(2);
        }
    }
    if den > 0.0 {
        step * (num / den).sqrt()
    } else {
        0.0
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_probe_fires_after_its_steps_whatever_the_test_says_and_later_after_failed_trials() {
        let mut t = StiffnessTest::default();
        for _ in 1..PROBE_EVERY {
            assert!(!t.observe(1.0, TRY_IMPLICIT_AFTER));
        }
        assert!(t.observe(1.0, TRY_IMPLICIT_AFTER));
        // two failed trials: the stiff steps a trial needs and the probe's steps both x4
        let mut t = StiffnessTest::default();
        for _ in 1..4 * PROBE_EVERY {
            assert!(!t.observe(1.0, TRY_IMPLICIT_AFTER << 2));
        }
        assert!(t.observe(1.0, TRY_IMPLICIT_AFTER << 2));
    }

    #[test]
    fn fifteen_steps_at_the_limit_make_a_run_stiff_and_six_below_reset_it() {
        let mut t = StiffnessTest::default();
        for _ in 0..14 {
            assert!(!t.observe(3.3, STIFF_STEPS));
        }
        for _ in 0..5 {
            assert!(!t.observe(1.0, STIFF_STEPS)); // fewer than six below: the count stays
        }
        assert!(t.observe(3.3, STIFF_STEPS));
        let mut t = StiffnessTest::default();
        for _ in 0..14 {
            t.observe(3.3, STIFF_STEPS);
        }
        for _ in 0..6 {
            t.observe(1.0, STIFF_STEPS);
        }
        assert!(
            !t.observe(3.3, STIFF_STEPS),
            "six steps below the limit reset the count"
        );
    }

    #[test]
    fn h_lambda_recovers_a_linear_systems_eigenvalue() {
        // f(y) = -1000 y on the second component, 0 on the first: |Δf|/|Δy| = 1000 along it
        let (y6, y7) = ([1.0, 2.0], [1.0, 2.001]);
        let f = |y: &[f64; 2], c: usize| if c == 1 { -1000.0 * y[1] } else { 0.0 };
        let hl = h_lambda(1e-3, 2, |_| 1.0, |c| y6[c], |c| f(&y6, c), |c| y7[c], |c| f(&y7, c));
        assert!((hl - 1.0).abs() < 1e-9, "{hl}");
        // an infinite scale leaves a component out
        let hl = h_lambda(
            1e-3,
            2,
            |c| if c == 1 { f64::INFINITY } else { 1.0 },
            |c| y6[c],
            |c| f(&y6, c),
            |c| y7[c],
            |c| f(&y7, c),
        );
        assert_eq!(hl, 0.0);
    }
}
