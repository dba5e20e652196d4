//! `method="auto"`: Dormand-Prince on every lane; when a lane's run turns stiff (Hairer's test,
//! `integrate/stiffness.rs`), a trial Rodas4 step of `TRIAL_FACTOR` times the explicit step, then a
//! probation of `PROBATION_STEPS` Rodas4 steps, decide whether the implicit method pays there:
//! it stays when its mean step over the probation is at least `switch_gain` times the explicit
//! step it replaced (the cost of a Rodas4 step in Dormand-Prince steps, with a margin);
//! otherwise the lane goes back to Dormand-Prince and the next trial needs twice as many stiff
//! steps in a row. Every decision comes from the lane's own run only, so a point's result does
//! not depend on its neighbours, the thread count or the lane width; the vector path
//! (`lanes/dopri5.rs`) hands a lane whose run turned stiff to this stepper with its trial
//! pending, where a lane of this stepper stands at the same step (bitwise the same run). A
//! held run (the replay of a recorded one, for sensitivities) changes method at the accepted
//! steps the recorded run did (`Held::switches`).

use crate::integrate::dopri5::{Dopri5, EXPLICIT_CRAWL_HINT};
use crate::integrate::rodas4::{Rodas4, IMPLICIT_CRAWL_HINT};
use crate::integrate::stepper::{AdaptiveOptions, Attempt, Rhs, State, Stepper};
use crate::integrate::stiffness::{
    implicit_step_cost, switch_gain, StiffnessTest, MAX_RECHECK_BACKOFF, MAX_TRIAL_BACKOFF, PROBATION_STEPS,
    RECHECK_STEPS, STIFF_H_LAMBDA, TRIAL_FACTOR, TRY_IMPLICIT_AFTER,
};

/// Tolerance of the implicit part relative to the explicit one: Rodas4 at rtol = atol = 1e-5,
/// the loosest that kept whole corner grids within 1 nm on its own (benches/RESULTS.md §33; 1e-6
/// before, §4); inside `auto`, with the probe, the grids' largest error was 0.76 nm (§36).
pub const IMPLICIT_TOL_FACTOR: f64 = 1e-5 / 3e-7;

/// Where a lane stands.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Mode {
    Explicit,
    /// the next attempt is a Rodas4 trial; the explicit step [s] to go back to if it fails
    Trial {
        h_explicit: f64,
    },
    /// on Rodas4 since time `since` [s], `steps` accepted steps so far, on probation
    Probation {
        h_explicit: f64,
        since: f64,
        steps: u32,
    },
    /// on Rodas4 for good since time `since` [s], `steps` accepted steps in this window
    Implicit {
        since: f64,
        steps: u32,
    },
    /// Dormand-Prince steps since `since` [s] (`steps` accepted), checking whether they are now
    /// cheaper than Rodas4's mean step `h_implicit` [s] of the window before; `lambda` the
    /// largest |λ| [1/s] Hairer's estimate saw on them
    Recheck {
        h_implicit: f64,
        since: f64,
        steps: u32,
        lambda: f64,
    },
}

impl Mode {
    /// Whether the lane's next attempt is a Dormand-Prince step.
    fn explicit(&self) -> bool {
        matches!(self, Mode::Explicit | Mode::Recheck { .. })
    }
}

/// Two steppers per lane group and which one each lane is on.
pub struct Switching<S: State, const L: usize, const D: usize> {
    explicit: Dopri5<S, L>,
    implicit: Rodas4<S, L, D>,
    mode: [Mode; L],
    test: [StiffnessTest; L],
    /// failed trials and probations so far (each doubles the stiff steps the next trial needs)
    fails: [u32; L],
    /// rechecks that kept the lane on Rodas4 (each doubles the steps to the next)
    kept: [u32; L],
    /// held runs: the accepted steps after which the recorded run changed method, and how
    /// many of them this run has passed
    switches: [Vec<u64>; L],
    passed: [usize; L],
    held: [bool; L],
    /// a lane changed method in the last attempt (after this many accepted steps)
    just_switched: [Option<u64>; L],
}

impl<S: State, const L: usize, const D: usize> Switching<S, L, D> {
    /// `opts`: the explicit method's options per lane (the implicit one's tolerances are
    /// [`IMPLICIT_TOL_FACTOR`] times looser).
    pub fn new(opts: [AdaptiveOptions; L], zero: S) -> Self {
        let loose = std::array::from_fn(|i| {
            let mut o = opts[i].clone();
            o.rtol *= IMPLICIT_TOL_FACTOR;
            o.atol *= IMPLICIT_TOL_FACTOR;
            o
        });
        Switching {
            switches: std::array::from_fn(|i| opts[i].held.switches.clone()),
            passed: [0; L],
            held: std::array::from_fn(|i| !opts[i].held.is_empty()),
            explicit: Dopri5::new(opts, zero.clone()).with_stiffness_test(),
            implicit: Rodas4::new(loose, zero),
            mode: [Mode::Explicit; L],
            test: [StiffnessTest::default(); L],
            fails: [0; L],
            kept: [0; L],
            just_switched: [None; L],
        }
    }

    /// Lane `i`'s run turned stiff after `accepted` steps with explicit step `h` [s] proposed:
    /// its next attempt is the trial (a lane the vector path handed over starts here).
    pub fn start_trial(&mut self, i: usize, h: f64, accepted: u64) {
        self.mode[i] = Mode::Trial { h_explicit: h };
        self.explicit.take_over(i, h, accepted);
        self.implicit.take_over(i, TRIAL_FACTOR * h, accepted);
    }

    /// Whether lane `i` runs the implicit method (on probation or for good).
    pub fn on_implicit(&self, i: usize) -> bool {
        matches!(self.mode[i], Mode::Implicit { .. } | Mode::Probation { .. })
    }

    /// Lane `i` goes on with Dormand-Prince afresh from step `h` [s] after `accepted` steps;
    /// the next trial needs twice as many stiff steps. `switched`: it ran implicit steps (a
    /// failed probation), which a held replay must know.
    fn back_to_explicit(&mut self, i: usize, h: f64, accepted: u64, switched: bool) {
        self.mode[i] = Mode::Explicit;
        self.explicit.take_over(i, h, accepted);
        self.test[i] = StiffnessTest::default();
        self.fails[i] = (self.fails[i] + 1).min(MAX_TRIAL_BACKOFF);
        if switched {
            self.just_switched[i] = Some(accepted);
        }
    }
}

impl<S: State, const L: usize, const D: usize> Stepper<S, L> for Switching<S, L, D> {
    const FIXED_STEP: bool = false;
    const EVALUATES_START: bool = false;

    /// As Dormand-Prince: only a state that is no longer finite counts as diverged.
    fn bound_slack(&self) -> f64 {
        f64::INFINITY
    }

    /// Rodas4's lanes reject a step beyond its bound.
    fn admissible_slack(&self) -> f64 {
        1e-6
    }

    fn restart(&mut self, lane: usize) {
        self.explicit.restart(lane);
        self.implicit.restart(lane);
    }

    fn take_switch(&mut self, lane: usize) -> Option<u64> {
        self.just_switched[lane].take()
    }

    fn crawl_hint(&self, lane: usize) -> &'static str {
        if self.on_implicit(lane) {
            IMPLICIT_CRAWL_HINT
        } else {
            EXPLICIT_CRAWL_HINT
        }
    }

    // Long: the stiffness test, the Rodas4 trial, the probation and the switch back are one
    // decision on one lane's state per attempt; apart, each would re-read that state.
    #[inline(always)]
    fn attempt<F: Rhs<S::Elem>>(
        &mut self,
        f: &mut F,
        ys: &mut [S; L],
        t: &[f64; L],
        end: &[f64; L],
        active: &[bool; L],
    ) -> [Attempt; L] {
        let on_exp: [bool; L] = std::array::from_fn(|i| active[i] && self.mode[i].explicit());
        let on_imp: [bool; L] = std::array::from_fn(|i| active[i] && !self.mode[i].explicit());
        let mut out = if on_exp.iter().any(|a| *a) {
            self.explicit.attempt(f, ys, t, end, &on_exp)
        } else {
            std::array::from_fn(|_| Attempt::Idle)
        };
        if on_imp.iter().any(|a| *a) {
            let imp = self.implicit.attempt(f, ys, t, end, &on_imp);
            for (i, r) in imp.into_iter().enumerate() {
                if !on_imp[i] {
                    continue;
                }
                out[i] = match (self.mode[i], r) {
                    (Mode::Trial { h_explicit }, r @ Attempt::Accepted { .. }) => {
                        self.mode[i] = Mode::Probation {
                            h_explicit,
                            since: t[i],
                            steps: 1,
                        };
                        self.just_switched[i] = Some(self.explicit.accepted(i));
                        r
                    }
                    (Mode::Trial { h_explicit }, _) => {
                        // not even one step that long: Dormand-Prince afresh, the next trial later
                        self.back_to_explicit(i, h_explicit, self.explicit.accepted(i), false);
                        Attempt::Rejected
                    }
                    (
                        Mode::Probation {
                            h_explicit,
                            since,
                            steps,
                        },
                        r @ Attempt::Accepted { step, last },
                    ) => {
                        let steps = steps + 1;
                        self.mode[i] = Mode::Probation {
                            h_explicit,
                            since,
                            steps,
                        };
                        if steps >= PROBATION_STEPS && !last {
                            // the mean implicit step against the explicit one it replaced
                            let mean = (t[i] + step - since) / steps as f64;
                            if mean >= switch_gain(ys[i].as_ref().len()) * h_explicit {
                                self.mode[i] = Mode::Implicit {
                                    since: t[i] + step,
                                    steps: 0,
                                };
                                self.kept[i] = 0;
                            } else {
                                self.back_to_explicit(i, h_explicit, self.implicit.accepted(i), true);
                            }
                        }
                        r
                    }
                    (Mode::Implicit { .. }, r @ Attempt::Accepted { .. }) if self.held[i] => {
                        let n = self.implicit.accepted(i);
                        if self.switches[i].get(self.passed[i]) == Some(&n) {
                            // the recorded run went back to the explicit method here
                            self.passed[i] += 1;
                            self.mode[i] = Mode::Explicit;
                            self.explicit.take_over(i, 0.0, n);
                        }
                        r
                    }
                    (Mode::Implicit { since, steps }, r @ Attempt::Accepted { step, last }) => {
                        let steps = steps + 1;
                        self.mode[i] = Mode::Implicit { since, steps };
                        if steps >= RECHECK_STEPS << self.kept[i] && !last {
                            // has the stiff phase ended? Dormand-Prince from Rodas4's mean step
                            let h_implicit = (t[i] + step - since) / steps as f64;
                            let n = self.implicit.accepted(i);
                            self.mode[i] = Mode::Recheck {
                                h_implicit,
                                since: t[i] + step,
                                steps: 0,
                                lambda: 0.0,
                            };
                            self.explicit.take_over(i, h_implicit, n);
                            self.just_switched[i] = Some(n);
                        }
                        r
                    }
                    (_, r) => r,
                };
            }
        }
        for i in 0..L {
            if let (
                true,
                Mode::Recheck {
                    h_implicit,
                    since,
                    steps,
                    lambda,
                },
                Attempt::Accepted { step, last },
            ) = (on_exp[i], self.mode[i], &out[i])
            {
                let steps = steps + 1;
                let lambda = lambda.max(self.explicit.h_lambda[i] / step);
                self.mode[i] = Mode::Recheck {
                    h_implicit,
                    since,
                    steps,
                    lambda,
                };
                if steps >= PROBATION_STEPS && !*last {
                    let n = self.explicit.accepted(i);
                    // the explicit step: its mean, but no longer than its stability allows (the
                    // first steps past the limit are accepted while the unstable mode grows)
                    let mean = (t[i] + step - since) / steps as f64;
                    let h_explicit = if lambda > 0.0 {
                        mean.min(STIFF_H_LAMBDA / lambda)
                    } else {
                        mean
                    };
                    if h_explicit * implicit_step_cost(ys[i].as_ref().len()) >= h_implicit {
                        // the explicit steps are now the cheaper: back for good
                        self.mode[i] = Mode::Explicit;
                        self.test[i] = StiffnessTest::default();
                    } else {
                        // still stiff: Rodas4 again from its own step, the next check later
                        self.mode[i] = Mode::Implicit {
                            since: t[i] + step,
                            steps: 0,
                        };
                        self.implicit.take_over(i, h_implicit, n);
                        self.kept[i] = (self.kept[i] + 1).min(MAX_RECHECK_BACKOFF);
                        self.just_switched[i] = Some(n);
                    }
                }
                continue;
            }
            if on_exp[i] && matches!(out[i], Attempt::Accepted { .. }) {
                let n = self.explicit.accepted(i);
                if self.held[i] {
                    if self.switches[i].get(self.passed[i]) == Some(&n) {
                        // the recorded run changed to the implicit method here
                        self.passed[i] += 1;
                        self.mode[i] = Mode::Implicit { since: t[i], steps: 0 };
                        self.implicit.take_over(i, 0.0, n);
                    }
                } else if self.test[i].observe(self.explicit.h_lambda[i], TRY_IMPLICIT_AFTER << self.fails[i]) {
                    self.start_trial(i, self.explicit.proposed_step(i), n);
                }
            }
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::integrate::stepper::Held;

    fn opts() -> AdaptiveOptions {
        AdaptiveOptions {
            rtol: 1e-6,
            atol: 1e-6,
            scale: vec![1.0; 2],
            h_init: 1e-4,
            h_min: 1e-14,
            h_max: 1.0,
            held: Held::default(),
        }
    }

    /// y1' = -k (y1 - cos t) - sin t, y0' = 0: smooth solution cos t, stiffness k.
    fn run(k: f64, rtol: f64) -> (bool, u64, f64) {
        let mut o = opts();
        o.rtol = rtol;
        o.atol = rtol;
        let mut st: Switching<[f64; 2], 1, 2> = Switching::new([o], [0.0; 2]);
        let mut f = |_l: usize, tau: f64, y: &[f64], dy: &mut [f64]| {
            let _ = tau;
            dy[0] = 1.0;
            dy[1] = -k * (y[1] - y[0].cos()) - y[0].sin();
        };
        let mut ys = [[0.0, 1.0]];
        let (mut t, mut steps) = (0.0, 0u64);
        while t < 1.0 {
            match &st.attempt(&mut f, &mut ys, &[t], &[1.0], &[true])[0] {
                Attempt::Accepted { step, last } => {
                    t = if *last { 1.0 } else { t + step };
                    steps += 1;
                }
                Attempt::Failed(w) => panic!("{w}"),
                _ => {}
            }
        }
        (st.on_implicit(0), steps, (ys[0][1] - 1f64.cos()).abs())
    }

    #[test]
    fn a_stiff_lane_changes_to_the_implicit_method_and_takes_far_fewer_steps() {
        // |λ| = 1e6: Dormand-Prince would need ~3e5 steps over 1 s at its stability limit
        let (switched, steps, err) = run(1e6, 1e-6);
        assert!(switched);
        assert!(steps < 2_000, "{steps} steps");
        assert!(err < 1e-5, "{err}");
    }

    #[test]
    fn a_non_stiff_lane_stays_explicit() {
        let (switched, _, err) = run(1.0, 1e-6);
        assert!(!switched);
        assert!(err < 1e-5, "{err}");
    }
}
