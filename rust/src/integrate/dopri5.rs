//! Adaptive Dormand-Prince 5(4) with first-same-as-last stages and an elementary step-size
//! controller. Like `rk4`, it knows nothing of the physics; the driver hands it each lane's
//! segment end (the next input breakpoint or the end of the run) and it lands there exactly,
//! never stepping across a kink of the input (the method's order would be lost there).

#[cfg(test)]
use crate::integrate::stepper::Held;
use crate::integrate::stepper::{
    AdaptiveOptions, AdaptiveStats, Attempt, Controller, Rhs, State, Stepper, HELD_EXHAUSTED,
};
use crate::integrate::stiffness::h_lambda;
use crate::numbers::scalar::Scalar;

/// Dormand-Prince's control: a 4th-order embedded estimate (q = 5), growth up to 5x.
pub(crate) const CONTROL: Controller = Controller {
    exponent: 0.2,
    max_growth: 5.0,
};

use crate::integrate::tableau::{
    DP5_A2 as A2, DP5_A3 as A3, DP5_A4 as A4, DP5_A5 as A5, DP5_A6 as A6, DP5_B as B, DP5_C as C, DP5_E as E,
};

/// What a crawling explicit run is told (`integrate/crawl.rs`).
pub(crate) const EXPLICIT_CRAWL_HINT: &str =
    "the explicit method is held at its stability limit (the run is stiff): use method 'rodas4' or 'auto'";

/// Stages, step sizes and options of `L` lanes; each lane keeps its own step size.
pub struct Dopri5<S, const L: usize = 1> {
    opts: [AdaptiveOptions; L],
    /// stage derivatives, stage-major (`k[stage][lane]`) so a stage of every lane is one array
    k: [[S; L]; 7],
    tmp: [S; L],
    y_new: [S; L],
    h: [f64; L],
    /// the first stage must be evaluated afresh (start, or a new input segment)
    fresh: [bool; L],
    /// number of components in each lane's error norm
    in_norm: [f64; L],
    pub stats: [AdaptiveStats; L],
    /// estimate h|λ| on accepted steps for Hairer's stiffness test (`integrate/stiffness.rs`); off: not
    /// even computed
    detect: bool,
    /// each lane's h|λ| at its last accepted step
    pub h_lambda: [f64; L],
}

impl<S: State, const L: usize> Dopri5<S, L> {
    /// Buffers shaped like `zero` (all zeros), one set of options per lane.
    pub fn new(opts: [AdaptiveOptions; L], zero: S) -> Self {
        let h = std::array::from_fn(|i| opts[i].h_init.min(opts[i].h_max));
        let in_norm = std::array::from_fn(|i| opts[i].scale.iter().filter(|s| s.is_finite()).count().max(1) as f64);
        Dopri5 {
            k: std::array::from_fn(|_| std::array::from_fn(|_| zero.clone())),
            tmp: std::array::from_fn(|_| zero.clone()),
            y_new: std::array::from_fn(|_| zero.clone()),
            h,
            fresh: [true; L],
            in_norm,
            stats: [AdaptiveStats::default(); L],
            opts,
            detect: false,
            h_lambda: [0.0; L],
        }
    }

    /// The same, estimating h|λ| on every accepted step (`h_lambda`).
    pub fn with_stiffness_test(mut self) -> Self {
        self.detect = true;
        self
    }

    /// The step lane `i` tries next [s].
    pub fn proposed_step(&self, i: usize) -> f64 {
        self.h[i]
    }

    /// Accepted steps of lane `i` so far.
    pub fn accepted(&self, i: usize) -> u64 {
        self.stats[i].accepted
    }

    /// Go on with lane `i` afresh (first stage evaluated anew) from step `h` [s], `accepted`
    /// steps taken so far.
    pub fn take_over(&mut self, i: usize, h: f64, accepted: u64) {
        self.fresh[i] = true;
        self.h[i] = h.min(self.opts[i].h_max);
        self.stats[i].accepted = accepted;
    }
}

impl<S: State, const L: usize> Stepper<S, L> for Dopri5<S, L> {
    const FIXED_STEP: bool = false;
    const EVALUATES_START: bool = false;

    /// The error control keeps the state near, not on, the bound's side: only a state that is
    /// no longer finite counts as diverged.
    fn bound_slack(&self) -> f64 {
        f64::INFINITY
    }

    fn crawl_hint(&self, _lane: usize) -> &'static str {
        EXPLICIT_CRAWL_HINT
    }

    fn restart(&mut self, lane: usize) {
        self.fresh[lane] = true;
    }

    #[inline(always)]
    fn attempt<F: Rhs<S::Elem>>(
        &mut self,
        f: &mut F,
        ys: &mut [S; L],
        t: &[f64; L],
        end: &[f64; L],
        active: &[bool; L],
    ) -> [Attempt; L] {
        let mut step = [0.0; L];
        let mut last = [false; L];
        let was_active = *active;
        let mut run = *active;
        for i in 0..L {
            if active[i] {
                let Some(h) = self.opts[i].next_step(self.h[i], self.stats[i].accepted as usize) else {
                    run[i] = false;
                    continue;
                };
                if self.fresh[i] {
                    f.eval(i, 0.0, ys[i].as_ref(), self.k[0][i].as_mut());
                    self.stats[i].evaluations += 1;
                    self.fresh[i] = false;
                }
                last[i] = end[i] - (t[i] + h) < 1e-3 * h;
                step[i] = if last[i] { end[i] - t[i] } else { h };
            }
        }
        let active = &run;
        for (s, a) in [
            (1usize, &A2[..]),
            (2, &A3[..]),
            (3, &A4[..]),
            (4, &A5[..]),
            (5, &A6[..]),
        ] {
            for i in 0..L {
                if active[i] {
                    combine(self.tmp[i].as_mut(), ys[i].as_ref(), step[i], a, &self.k, i);
                }
            }
            // the stage of every lane at once (vector lanes where the right-hand side has them)
            let tau: [f64; L] = std::array::from_fn(|i| C[s] * step[i]);
            f.eval_lanes(&tau, &self.tmp, &mut self.k[s], active);
        }
        for i in 0..L {
            if active[i] {
                combine(self.y_new[i].as_mut(), ys[i].as_ref(), step[i], &B, &self.k, i);
            }
        }
        f.eval_lanes(&step, &self.y_new, &mut self.k[6], active);
        std::array::from_fn(|i| {
            if !active[i] {
                return match was_active[i] {
                    true => Attempt::Failed(HELD_EXHAUSTED.into()), // its held steps ran out
                    false => Attempt::Idle,
                };
            }
            self.stats[i].evaluations += 6;
            let err = self.error_norm(i, ys[i].as_ref(), step[i]); // NaN when the state blew up
            let o = &self.opts[i];
            if err <= 1.0 || !o.held.is_empty() {
                if self.detect {
                    let (y6, k6, y7, k7) = (
                        self.tmp[i].as_ref(),
                        self.k[5][i].as_ref(),
                        self.y_new[i].as_ref(),
                        self.k[6][i].as_ref(),
                    );
                    let hl = h_lambda(
                        step[i],
                        y7.len(),
                        |c| o.scale[c],
                        |c| y6[c].value(),
                        |c| k6[c].value(),
                        |c| y7[c].value(),
                        |c| k7[c].value(),
                    );
                    self.h_lambda[i] = hl;
                }
                ys[i].as_mut().copy_from_slice(self.y_new[i].as_ref());
                let (first, rest) = self.k.split_at_mut(6);
                std::mem::swap(&mut first[0][i], &mut rest[0][i]); // first same as last
                if !o.held.is_empty() {
                    o.pin(self.stats[i].accepted as usize, ys[i].as_mut());
                    self.fresh[i] = true; // the last stage was evaluated before the pin
                }
                self.stats[i].accepted += 1;
                self.h[i] = CONTROL.after_accept(err, step[i], last[i], self.h[i], o);
                Attempt::Accepted {
                    step: step[i],
                    last: last[i],
                }
            } else {
                self.stats[i].rejected += 1;
                let (h, outcome) = CONTROL.after_reject(err, step[i], o);
                self.h[i] = h;
                outcome
            }
        })
    }
}

impl<S: State, const L: usize> Dopri5<S, L> {
    /// Scaled RMS of the embedded error estimate of lane `i`'s last attempt [-].
    #[inline(always)]
    fn error_norm(&self, i: usize, y: &[S::Elem], step: f64) -> f64 {
        let (ynv, o, k) = (self.y_new[i].as_ref(), &self.opts[i], &self.k);
        let mut err2 = 0.0;
        for c in 0..y.len() {
            if o.scale[c].is_finite() {
                let mut e = 0.0;
                for (j, ej) in E.iter().enumerate() {
                    e += ej * k[j][i].as_ref()[c].value();
                }
                let tol = o.atol * o.scale[c] + o.rtol * y[c].value().abs().max(ynv[c].value().abs());
                err2 += (step * e / tol).powi(2);
            }
        }
        (err2 / self.in_norm[i]).sqrt()
    }
}

/// out = y + h sum_j a_j k_j
#[inline(always)]
fn combine<T: Scalar, S: AsRef<[T]>, const L: usize>(
    out: &mut [T],
    y: &[T],
    h: f64,
    a: &[f64],
    k: &[[S; L]; 7],
    lane: usize,
) {
    for i in 0..out.len() {
        let mut s = T::zero();
        for (j, aj) in a.iter().enumerate() {
            s += k[j][lane].as_ref()[i] * *aj;
        }
        out[i] = y[i] + s * h;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn opts(rtol: f64) -> AdaptiveOptions {
        AdaptiveOptions {
            rtol,
            atol: rtol,
            scale: vec![1.0; 2],
            h_init: 1e-3,
            h_min: 1e-12,
            h_max: 1.0,
            held: Held::default(),
        }
    }

    /// Lanes integrated from 0 to `t1[i]` with the bare stepper.
    fn run<F: Rhs, const L: usize>(f: &mut F, ys: &mut [[f64; 2]; L], t1: [f64; L], o: &AdaptiveOptions) {
        let mut st: Dopri5<[f64; 2], L> = Dopri5::new(std::array::from_fn(|_| o.clone()), [0.0; 2]);
        let mut t = [0.0; L];
        let mut active = [true; L];
        while active.iter().any(|&a| a) {
            let r = st.attempt(f, ys, &t, &t1, &active);
            for i in 0..L {
                match r[i] {
                    Attempt::Accepted { step, last } => {
                        t[i] = if last { t1[i] } else { t[i] + step };
                        active[i] = t[i] < t1[i];
                    }
                    Attempt::Failed(_) => panic!("failed"),
                    _ => {}
                }
            }
        }
    }

    #[test]
    fn harmonic_oscillator_meets_tolerance() {
        let mut y = [[1.0, 0.0]];
        let mut f = |_l: usize, _tau: f64, y: &[f64], dy: &mut [f64]| {
            dy[0] = y[1];
            dy[1] = -y[0];
        };
        run(&mut f, &mut y, [10.0], &opts(1e-9));
        assert!((y[0][0] - 10f64.cos()).abs() < 1e-7, "{}", y[0][0]);
    }

    #[test]
    fn lanes_agree_bitwise_with_single_runs() {
        let o = opts(1e-8);
        let ws = [1.0, 3.0, 0.5];
        let t1s = [2.0, 5.0, 1.0];
        let mut ys = [[1.0, 0.0]; 3];
        let mut f = |lane: usize, _tau: f64, y: &[f64], dy: &mut [f64]| {
            dy[0] = y[1];
            dy[1] = -ws[lane] * ws[lane] * y[0].sin();
        };
        run(&mut f, &mut ys, t1s, &o);
        for i in 0..3 {
            let mut y = [[1.0, 0.0]];
            let mut g = |_l: usize, _tau: f64, y: &[f64], dy: &mut [f64]| {
                dy[0] = y[1];
                dy[1] = -ws[i] * ws[i] * y[0].sin();
            };
            run(&mut g, &mut y, [t1s[i]], &o);
            assert_eq!(ys[i], y[0]);
        }
    }
}
