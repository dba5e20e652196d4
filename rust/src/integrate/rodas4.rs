//! Rodas4 (Hairer & Wanner, Solving ODEs II, sec. IV.7): a stiffly accurate, L-stable
//! Rosenbrock method of order 4 with an embedded order-3 estimate, for the stiff phases of the
//! model (the presliding friction state while sliding, fast effect lags), where an explicit
//! method is held at its stability limit whatever the tolerance. Each step solves six linear
//! systems with one LU factorisation of I/(gamma h) - J, J the right-hand side's Jacobian
//! ([`Rhs::jacobian`]; the model's is analytic). Like `dopri5` it lands on every input
//! breakpoint and keeps one step size per lane.

use crate::numbers::scalar::Scalar;
#[cfg(test)]
use crate::integrate::stepper::Held;
use crate::integrate::stepper::{AdaptiveOptions, AdaptiveStats, Attempt, Controller, Rhs, State, Stepper, HELD_EXHAUSTED, OUT_OF_DOMAIN};

/// Rodas4's control: a 3rd-order embedded estimate (q = 4), growth up to 6x.
const CONTROL: Controller = Controller { exponent: 0.25, max_growth: 6.0 };

const GAMMA: f64 = 0.25;
/// stage times (fractions of the step)
const C: [f64; 6] = [0.0, 0.386, 0.21, 0.63, 1.0, 1.0];
/// df/dt weights of each stage
const DT_WEIGHT: [f64; 6] = [0.25, -0.1043, 0.1035, -0.3620000000000023e-01, 0.0, 0.0];
// Hairer & Wanner's coefficients in their printed 16-digit form (trailing zeros included)
#[allow(clippy::excessive_precision)]
const A51: [f64; 4] = [
    0.1221224509226641e+01,
    0.6019134481288629e+01,
    0.1253708332932087e+02,
    -0.6878860361058950e+00,
];
/// stage-value coefficients a_sj (row s, j < s); the last stage is the fifth plus its own
/// increment (stiff accuracy)
// as A51: the printed 16-digit form
#[allow(clippy::excessive_precision)]
const A: [&[f64]; 6] = [
    &[],
    &[0.1544000000000000e+01],
    &[0.9466785280815826e+00, 0.2557011698983284e+00],
    &[0.3314825187068521e+01, 0.2896124015972201e+01, 0.9986419139977817e+00],
    &A51,
    &[A51[0], A51[1], A51[2], A51[3], 1.0],
];
/// increment coefficients c_sj / h
// as A51: the printed 16-digit form
#[allow(clippy::excessive_precision)]
const CC: [&[f64]; 6] = [
    &[],
    &[-0.5668800000000000e+01],
    &[-0.2430093356833875e+01, -0.2063599157091915e+00],
    &[-0.1073529058151375e+00, -0.9594562251023355e+01, -0.2047028614809616e+02],
    &[
        0.7496443313967647e+01,
        -0.1024680431464352e+02,
        -0.3399990352819905e+02,
        0.1170890893206160e+02,
    ],
    &[
        0.8083246795921522e+01,
        -0.7981132988064893e+01,
        -0.3152159432874371e+02,
        0.1631930543123136e+02,
        -0.6058818238834054e+01,
    ],
];

/// What a crawling implicit run is told (`integrate/crawl.rs`).
pub(crate) const IMPLICIT_CRAWL_HINT: &str = "even the implicit method's step collapsed (a discontinuity in the \
    model, or parameters far outside the physical range): check the parameters, or loosen 'rtol'/'atol'";

/// Stages, Jacobians, factorisations and step sizes of `L` lanes.
pub struct Rodas4<S: State, const L: usize = 1, const D: usize = 0> {
    opts: [AdaptiveOptions; L],
    u: [[S; 6]; L],
    f: [S; L],
    y_stage: [S; L],
    dfdt: [S; L],
    jac: [Vec<S::Elem>; L],
    lu: [Vec<S::Elem>; L],
    pivot: [Vec<usize>; L],
    h: [f64; L],
    in_norm: [f64; L],
    pub stats: [AdaptiveStats; L],
}

impl<S: State, const L: usize, const D: usize> Rodas4<S, L, D> {
    /// Buffers shaped like `zero` (all zeros), one set of options per lane.
    pub fn new(opts: [AdaptiveOptions; L], zero: S) -> Self {
        let d = zero.as_ref().len();
        Rodas4 {
            u: std::array::from_fn(|_| std::array::from_fn(|_| zero.clone())),
            f: std::array::from_fn(|_| zero.clone()),
            y_stage: std::array::from_fn(|_| zero.clone()),
            dfdt: std::array::from_fn(|_| zero.clone()),
            jac: std::array::from_fn(|_| vec![S::Elem::from(0.0); d * d]),
            lu: std::array::from_fn(|_| vec![S::Elem::from(0.0); d * d]),
            pivot: std::array::from_fn(|_| vec![0; d]),
            h: std::array::from_fn(|i| opts[i].h_init.min(opts[i].h_max)),
            in_norm: std::array::from_fn(|i| {
                opts[i].scale.iter().filter(|s| s.is_finite()).count().max(1) as f64
            }),
            stats: [AdaptiveStats::default(); L],
            opts,
        }
    }
}

impl<S: State, const L: usize, const D: usize> Stepper<S, L> for Rodas4<S, L, D> {
    const FIXED_STEP: bool = false;
    const EVALUATES_START: bool = true;

    /// Steps that would leave the bound (by more than RK4's slack) are rejected and retried
    /// smaller, so an accepted state never does.
    fn bound_slack(&self) -> f64 {
        1e-6
    }

    fn crawl_hint(&self, _lane: usize) -> &'static str {
        IMPLICIT_CRAWL_HINT
    }

    /// Nothing is carried between steps (the Jacobian is evaluated afresh every step).
    fn restart(&mut self, _lane: usize) {}

    // Long: Rodas4's six stages share one LU and the stage vectors; written stage by stage in
    // the tableau's order so it reads against Hairer & Wanner's.
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
        let mut ok = *active;
        let mut ran_out = [false; L];
        for i in 0..L {
            if !active[i] {
                continue;
            }
            let Some(h) = self.opts[i].next_step(self.h[i], self.stats[i].accepted as usize) else {
                (ok[i], ran_out[i]) = (false, true);
                continue;
            };
            last[i] = end[i] - (t[i] + h) < 1e-3 * h;
            step[i] = if last[i] { end[i] - t[i] } else { h };
            f.jacobian(i, 0.0, ys[i].as_ref(), &mut self.jac[i], self.dfdt[i].as_mut());
            // E = I / (gamma h) - J
            let d = if D > 0 { D } else { ys[i].as_ref().len() };
            let inv = 1.0 / (GAMMA * step[i]);
            for (e, j) in self.lu[i].iter_mut().zip(&self.jac[i]) {
                *e = -*j;
            }
            for r in 0..d {
                self.lu[i][r * d + r] += inv;
            }
            ok[i] = lu_factor::<_, D>(&mut self.lu[i], &mut self.pivot[i], d);
        }
        for s in 0..6 {
            for i in 0..L {
                if !ok[i] {
                    continue;
                }
                let (h, y) = (step[i], ys[i].as_ref());
                if s == 0 {
                    f.eval(i, 0.0, y, self.f[i].as_mut());
                } else {
                    let ys_ = self.y_stage[i].as_mut();
                    for c in 0..y.len() {
                        let mut acc = y[c];
                        for (j, a) in A[s].iter().enumerate() {
                            acc += self.u[i][j].as_ref()[c] * *a;
                        }
                        ys_[c] = acc;
                    }
                    f.eval(i, C[s] * h, self.y_stage[i].as_ref(), self.f[i].as_mut());
                }
                // right-hand side of stage s: f + sum_j c_sj / h u_j + h d_s df/dt
                let (u, rhs) = {
                    let (done, rest) = self.u[i].split_at_mut(s);
                    (done, rest[0].as_mut())
                };
                let (fs, ft) = (self.f[i].as_ref(), self.dfdt[i].as_ref());
                let inv_h = 1.0 / h;
                let mut cc = [0.0; 5];
                for (k, c) in CC[s].iter().enumerate() {
                    cc[k] = c * inv_h;
                }
                let hd = h * DT_WEIGHT[s];
                for c in 0..rhs.len() {
                    let mut acc = fs[c] + ft[c] * hd;
                    for (j, ccj) in cc[..s].iter().enumerate() {
                        acc += u[j].as_ref()[c] * *ccj;
                    }
                    rhs[c] = acc;
                }
                lu_solve::<_, D>(&self.lu[i], &self.pivot[i], rhs);
            }
        }
        std::array::from_fn(|i| {
            if !active[i] {
                return Attempt::Idle;
            }
            if ran_out[i] {
                return Attempt::Failed(HELD_EXHAUSTED.into());
            }
            self.stats[i].evaluations += 6;
            let err = if ok[i] {
                let e = self.finish(i, ys[i].as_ref()); // NaN when the state blew up
                // a state the model rules out (presliding force beyond its bound) is an
                // overshoot of the linearisation: the relative tolerance would grow with it
                if f.admissible(i, self.y_stage[i].as_ref()) {
                    e
                } else {
                    OUT_OF_DOMAIN
                }
            } else {
                f64::NAN
            };
            let o = &self.opts[i];
            // held steps are taken whatever their error (unless the factorisation failed)
            if err <= 1.0 || (!o.held.is_empty() && ok[i]) {
                ys[i].as_mut().copy_from_slice(self.y_stage[i].as_ref());
                if !o.held.is_empty() {
                    o.pin(self.stats[i].accepted as usize, ys[i].as_mut());
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

impl<S: State, const L: usize, const D: usize> Rodas4<S, L, D> {
    /// Continue lane `i` from another method's run: its next step `h` [s] and the number of
    /// steps that run accepted (held steps are counted from the run's start).
    /// Accepted steps of lane `i` so far.
    pub fn accepted(&self, i: usize) -> u64 {
        self.stats[i].accepted
    }

    /// The step [s] lane `i` tries next.
    pub fn proposed_step(&self, i: usize) -> f64 {
        self.h[i]
    }

    pub fn take_over(&mut self, i: usize, h: f64, accepted: u64) {
        self.h[i] = h.min(self.opts[i].h_max);
        self.stats[i].accepted = accepted;
    }

    /// Put the new state y + sum a_5j u_j + u_5 + u_6 in `y_stage[i]` and return the scaled
    /// RMS of the embedded error estimate (the last increment) [-].
    #[inline(always)]
    fn finish(&mut self, i: usize, y: &[S::Elem]) -> f64 {
        let o = &self.opts[i];
        let (u, out) = (&self.u[i], self.y_stage[i].as_mut());
        let mut err2 = 0.0;
        for c in 0..y.len() {
            let mut acc = y[c];
            for (j, a) in A[5].iter().enumerate() {
                acc += u[j].as_ref()[c] * *a;
            }
            let e = u[5].as_ref()[c];
            out[c] = acc + e;
            if o.scale[c].is_finite() {
                let tol = o.atol * o.scale[c] + o.rtol * y[c].value().abs().max(out[c].value().abs());
                err2 += (e.value() / tol).powi(2);
            }
        }
        (err2 / self.in_norm[i]).sqrt()
    }
}

/// In-place LU factorisation with partial pivoting of the `d` x `d` row-major matrix `a` (the
/// diagonal of U stored as its reciprocal)
/// (nalgebra's LU owns and allocates its matrix; this runs once per step on a lane's own
/// buffer). `D` > 0 fixes the size at compile time (the loops unroll). False when the matrix
/// is singular or not finite.
#[inline(always)]
fn lu_factor<T: Scalar, const D: usize>(a: &mut [T], pivot: &mut [usize], d: usize) -> bool {
    let d = if D > 0 { D } else { d };
    let (a, pivot) = (&mut a[..d * d], &mut pivot[..d]);
    for k in 0..d {
        let mut p = k;
        let mut best = a[k * d + k].value().abs();
        for r in k + 1..d {
            let x = a[r * d + k].value().abs();
            if x > best {
                best = x;
                p = r;
            }
        }
        if !(best > 0.0 && best.is_finite()) {
            return false;
        }
        pivot[k] = p;
        if p != k {
            for c in 0..d {
                a.swap(k * d + c, p * d + c);
            }
        }
        let inv = T::one() / a[k * d + k];
        // the solves multiply by the pivot's reciprocal: a division is a long serial latency
        a[k * d + k] = inv;
        for r in k + 1..d {
            let m = a[r * d + k] * inv;
            a[r * d + k] = m;
            if !m.is_exactly(0.0) {
                for c in k + 1..d {
                    let akc = a[k * d + c];
                    a[r * d + c] -= m * akc;
                }
            }
        }
    }
    true
}

/// Solve A x = b in place with the factors of [`lu_factor`].
#[inline(always)]
// the row swaps by pivot index, in the factorisation's order, like the loops below
#[allow(clippy::needless_range_loop)]
fn lu_solve<T: Scalar, const D: usize>(lu: &[T], pivot: &[usize], b: &mut [T]) {
    let d = if D > 0 { D } else { b.len() };
    let (lu, pivot, b) = (&lu[..d * d], &pivot[..d], &mut b[..d]);
    for k in 0..d {
        b.swap(k, pivot[k]);
    }
    for r in 1..d {
        let mut s = b[r];
        for c in 0..r {
            s -= lu[r * d + c] * b[c];
        }
        b[r] = s;
    }
    for r in (0..d).rev() {
        let mut s = b[r];
        for c in r + 1..d {
            s -= lu[r * d + c] * b[c];
        }
        b[r] = s * lu[r * d + r];
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn opts(rtol: f64, d: usize) -> AdaptiveOptions {
        AdaptiveOptions {
            rtol,
            atol: rtol,
            scale: vec![1.0; d],
            h_init: 1e-4,
            h_min: 1e-14,
            h_max: 1.0,
            held: Held::default(),
        }
    }

    /// Integrate one lane from 0 to `t1`; returns the accepted step count. `t0` holds each
    /// step's start time for right-hand sides that depend on time (they see the offset only).
    fn run<F: Rhs, const D: usize>(
        f: &mut F,
        y: &mut [f64; D],
        t1: f64,
        o: &AdaptiveOptions,
        t0: &std::cell::Cell<f64>,
    ) -> u64 {
        let mut st: Rodas4<[f64; D], 1> = Rodas4::new([o.clone()], [0.0; D]);
        let mut ys = [*y];
        let mut t = 0.0;
        while t < t1 {
            t0.set(t);
            match &st.attempt(f, &mut ys, &[t], &[t1], &[true])[0] {
                Attempt::Accepted { step, last } => t = if *last { t1 } else { t + step },
                Attempt::Failed(w) => panic!("{w}"),
                _ => {}
            }
        }
        *y = ys[0];
        st.stats[0].accepted
    }

    #[test]
    fn lu_solves_a_pivoting_system() {
        let mut a = vec![0.0, 2.0, 1.0, 1.0, 1.0, 0.0, 3.0, 0.0, 1.0];
        let mut p = vec![0; 3];
        assert!(lu_factor::<f64, 0>(&mut a, &mut p, 3));
        let mut b = vec![5.0, 3.0, 6.0];
        lu_solve::<f64, 3>(&a, &p, &mut b);
        let m = [0.0, 2.0, 1.0, 1.0, 1.0, 0.0, 3.0, 0.0, 1.0];
        for r in 0..3 {
            let s: f64 = (0..3).map(|c| m[r * 3 + c] * b[c]).sum();
            assert!((s - [5.0, 3.0, 6.0][r]).abs() < 1e-14);
        }
        let mut z = vec![1.0, 2.0, 2.0, 4.0];
        assert!(!lu_factor::<f64, 2>(&mut z, &mut p[..2], 2));
    }

    #[test]
    fn non_autonomous_problem_meets_its_tolerance() {
        // y' = -y + t^3 (time enters through df/dt); exact y = t^3 - 3t^2 + 6t - 6 + 7 e^-t
        let t0 = std::cell::Cell::new(0.0);
        let mut f = |_l: usize, tau: f64, y: &[f64], dy: &mut [f64]| {
            dy[0] = -y[0] + (t0.get() + tau).powi(3);
        };
        let exact = 1.0 - 3.0 + 6.0 - 6.0 + 7.0 * (-1f64).exp();
        let mut errs = vec![];
        for rtol in [1e-6, 1e-8, 1e-10] {
            let mut y = [1.0];
            run(&mut f, &mut y, 1.0, &opts(rtol, 1), &t0);
            errs.push((y[0] - exact).abs());
            assert!((y[0] - exact).abs() < 20.0 * rtol, "rtol {rtol}: {}", y[0] - exact);
        }
        assert!(errs[2] < errs[0]);
    }

    #[test]
    fn stiff_problem_takes_steps_set_by_accuracy() {
        // Robertson-like stiff linear pair: a fast mode (-1e7) and a slow one (-1): an explicit
        // method needs ~1e7 steps per unit time; Rodas4 a few dozen.
        let mut f = |_l: usize, _tau: f64, y: &[f64], dy: &mut [f64]| {
            dy[0] = -1e7 * (y[0] - y[1].cos());
            dy[1] = -y[1];
        };
        let mut y = [0.0, 1.0];
        let steps = run(&mut f, &mut y, 2.0, &opts(1e-8, 2), &Default::default());
        assert!(steps < 300, "{steps} steps");
        let y1 = (-2f64).exp();
        assert!((y[1] - y1).abs() < 1e-7, "{}", y[1] - y1);
        // the fast mode tracks its slow manifold: y0 = cos(y1) (to O(1/1e7))
        assert!((y[0] - y1.cos()).abs() < 1e-6, "{}", y[0] - y1.cos());
    }
}
