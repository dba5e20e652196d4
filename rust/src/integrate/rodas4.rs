//! Rodas4 (Hairer & Wanner, Solving ODEs II, sec. IV.7): a stiffly accurate, L-stable
//! Rosenbrock method of order 4 with an embedded order-3 estimate, for the stiff phases of the
//! model (the presliding friction state while sliding, fast effect lags), where an explicit
//! method is held at its stability limit whatever the tolerance. Each step solves six linear
//! systems with one LU factorisation of I/(gamma h) - J, J the right-hand side's Jacobian
//! ([`Rhs::jacobian`]; the model's is analytic). Like `dopri5` it lands on every input
//! breakpoint and keeps one step size per lane.

#[cfg(test)]
use crate::integrate::stepper::Held;
use crate::integrate::stepper::{
    AdaptiveOptions, AdaptiveStats, Attempt, Controller, Rhs, State, Stepper, HELD_EXHAUSTED, OUT_OF_DOMAIN,
};
use crate::numbers::scalar::Scalar;

/// Rodas4's control: a 3rd-order embedded estimate (q = 4), growth up to 6x.
const CONTROL: Controller = Controller {
    exponent: 0.25,
    max_growth: 6.0,
};

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
    &[
        -0.1073529058151375e+00,
        -0.9594562251023355e+01,
        -0.2047028614809616e+02,
    ],
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

/// Stages, Jacobians, factorisations and step sizes of `L` lanes. The stages, the matrix and
/// its factors are stored component by component (`lu[r * d + c][i]`: entry (r, c) of lane i),
/// so that the factorisation, the solves and the stage sums run over the lanes as vector
/// arithmetic; the states the right-hand side sees (`f`, `y_stage`) lane by lane, as
/// [`Rhs::eval_lanes`] takes them.
pub struct Rodas4<S: State, const L: usize = 1, const D: usize = 0> {
    opts: [AdaptiveOptions; L],
    /// the six stage increments: `u[s * d + c][i]`
    u: Vec<[S::Elem; L]>,
    f: [S; L],
    y_stage: [S; L],
    dfdt: [S; L],
    jac: [Vec<S::Elem>; L],
    lu: Vec<[S::Elem; L]>,
    pivot: Vec<[usize; L]>,
    h: [f64; L],
    in_norm: [f64; L],
    pub stats: [AdaptiveStats; L],
}

impl<S: State, const L: usize, const D: usize> Rodas4<S, L, D> {
    /// Buffers shaped like `zero` (all zeros), one set of options per lane.
    pub fn new(opts: [AdaptiveOptions; L], zero: S) -> Self {
        let d = zero.as_ref().len();
        let z = S::Elem::from(0.0);
        Rodas4 {
            u: vec![[z; L]; 6 * d],
            f: std::array::from_fn(|_| zero.clone()),
            y_stage: std::array::from_fn(|_| zero.clone()),
            dfdt: std::array::from_fn(|_| zero.clone()),
            jac: std::array::from_fn(|_| vec![z; d * d]),
            lu: vec![[z; L]; d * d],
            pivot: vec![[0; L]; d],
            h: std::array::from_fn(|i| opts[i].h_init.min(opts[i].h_max)),
            in_norm: std::array::from_fn(|i| opts[i].scale.iter().filter(|s| s.is_finite()).count().max(1) as f64),
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
        let d = if D > 0 { D } else { ys[0].as_ref().len() };
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
            let inv = 1.0 / (GAMMA * step[i]);
            for (e, j) in self.lu.iter_mut().zip(&self.jac[i]) {
                e[i] = -*j;
            }
            for r in 0..d {
                self.lu[r * d + r][i] += inv;
            }
        }
        let factored = lu_factor::<_, D, L>(&mut self.lu, &mut self.pivot, d, &ok);
        for i in 0..L {
            ok[i] &= factored[i];
        }
        if ok.iter().any(|o| *o) {
            self.stages(f, ys, &step, &ok, d);
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
    /// The six stages of the lanes with `ok` (their matrix factored in `lu`), into `u`: each
    /// stage's state, the right-hand side of every lane at it in one call (so that it may run
    /// as vector arithmetic: `lanes/mod.rs`), the stage's linear system and its solve over the
    /// lanes.
    #[inline(always)]
    // lane loops index several per-lane arrays by the same lane on purpose
    #[allow(clippy::needless_range_loop)]
    fn stages<F: Rhs<S::Elem>>(&mut self, f: &mut F, ys: &[S; L], step: &[f64; L], ok: &[bool; L], d: usize) {
        for s in 0..6 {
            if s == 0 {
                f.eval_lanes(&[0.0; L], ys, &mut self.f, ok);
            } else {
                let mut tau = [0.0; L];
                for i in 0..L {
                    if !ok[i] {
                        continue;
                    }
                    tau[i] = C[s] * step[i];
                    let (y, y_stage) = (ys[i].as_ref(), self.y_stage[i].as_mut());
                    for c in 0..d {
                        let mut acc = y[c];
                        for (j, a) in A[s].iter().enumerate() {
                            acc += self.u[j * d + c][i] * *a;
                        }
                        y_stage[c] = acc;
                    }
                }
                f.eval_lanes(&tau, &self.y_stage, &mut self.f, ok);
            }
            // right-hand side of stage s: f + sum_j c_sj / h u_j + h d_s df/dt
            let mut cc = [[0.0; L]; 5];
            let mut hd = [0.0; L];
            for i in 0..L {
                let inv_h = 1.0 / step[i];
                for (k, c) in CC[s].iter().enumerate() {
                    cc[k][i] = c * inv_h;
                }
                hd[i] = step[i] * DT_WEIGHT[s];
            }
            for c in 0..d {
                for i in 0..L {
                    let mut acc = self.f[i].as_ref()[c] + self.dfdt[i].as_ref()[c] * hd[i];
                    for j in 0..s {
                        acc += self.u[j * d + c][i] * cc[j][i];
                    }
                    self.u[s * d + c][i] = acc;
                }
            }
            lu_solve::<_, D, L>(&self.lu, &self.pivot, &mut self.u[s * d..(s + 1) * d]);
        }
    }

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
        let (u, out) = (&self.u, self.y_stage[i].as_mut());
        let d = y.len();
        let mut err2 = 0.0;
        for c in 0..d {
            let mut acc = y[c];
            for (j, a) in A[5].iter().enumerate() {
                acc += u[j * d + c][i] * *a;
            }
            let e = u[5 * d + c][i];
            out[c] = acc + e;
            if o.scale[c].is_finite() {
                let tol = o.atol * o.scale[c] + o.rtol * y[c].value().abs().max(out[c].value().abs());
                err2 += (e.value() / tol).powi(2);
            }
        }
        (err2 / self.in_norm[i]).sqrt()
    }
}

/// In-place LU factorisation with partial pivoting of each lane's `d` x `d` row-major matrix,
/// stored component by component (`a[r * d + c][i]`: entry (r, c) of lane i; the diagonal of U
/// stored as its reciprocal), each lane with its own pivots (`pivot[k][i]`), so that the
/// elimination runs over the lanes as vector arithmetic; a lane's result is bitwise that of the
/// factorisation alone. (nalgebra's LU owns and allocates one matrix; this runs once per step
/// on the lanes' buffers.) `D` > 0 fixes the size at compile time (the loops unroll). Per lane:
/// false where `on` is false or the matrix is singular or not finite (the other lanes' factors
/// are computed all the same and not used).
#[inline(always)]
// lane loops index several per-lane arrays by the same lane on purpose (the vectorised layout)
#[allow(clippy::needless_range_loop)]
fn lu_factor<T: Scalar, const D: usize, const L: usize>(
    a: &mut [[T; L]],
    pivot: &mut [[usize; L]],
    d: usize,
    on: &[bool; L],
) -> [bool; L] {
    let d = if D > 0 { D } else { d };
    let (a, pivot) = (&mut a[..d * d], &mut pivot[..d]);
    let mut ok = *on;
    for k in 0..d {
        // each lane's pivot: the first row r >= k with the largest |a_rk|
        let mut p = [k; L];
        let mut best: [f64; L] = std::array::from_fn(|i| a[k * d + k][i].value().abs());
        for r in k + 1..d {
            for i in 0..L {
                let x = a[r * d + k][i].value().abs();
                if x > best[i] {
                    best[i] = x;
                    p[i] = r;
                }
            }
        }
        for i in 0..L {
            ok[i] &= best[i] > 0.0 && best[i].is_finite();
        }
        pivot[k] = p;
        for i in 0..L {
            if p[i] != k {
                for c in 0..d {
                    let x = a[k * d + c][i];
                    a[k * d + c][i] = a[p[i] * d + c][i];
                    a[p[i] * d + c][i] = x;
                }
            }
        }
        // the solves multiply by the pivot's reciprocal: a division is a long serial latency
        let inv: [T; L] = std::array::from_fn(|i| T::one() / a[k * d + k][i]);
        a[k * d + k] = inv;
        for r in k + 1..d {
            let m: [T; L] = std::array::from_fn(|i| a[r * d + k][i] * inv[i]);
            a[r * d + k] = m;
            // a zero multiplier leaves its row as it is (bitwise, as the elimination alone skips it)
            let zero: [bool; L] = std::array::from_fn(|i| m[i].is_exactly(0.0));
            if zero.iter().all(|z| *z) {
                continue;
            }
            for c in k + 1..d {
                let akc = a[k * d + c];
                let row = &mut a[r * d + c];
                for i in 0..L {
                    let x = row[i] - m[i] * akc[i];
                    if !zero[i] {
                        row[i] = x;
                    }
                }
            }
        }
    }
    ok
}

/// Solve A x = b in place for every lane with the factors of [`lu_factor`] (`b[c][i]`:
/// component c of lane i).
#[inline(always)]
// the row swaps by pivot index, in the factorisation's order, like the loops below
#[allow(clippy::needless_range_loop)]
fn lu_solve<T: Scalar, const D: usize, const L: usize>(lu: &[[T; L]], pivot: &[[usize; L]], b: &mut [[T; L]]) {
    let d = if D > 0 { D } else { b.len() };
    let (lu, pivot, b) = (&lu[..d * d], &pivot[..d], &mut b[..d]);
    for k in 0..d {
        for i in 0..L {
            let p = pivot[k][i];
            if p != k {
                let x = b[k][i];
                b[k][i] = b[p][i];
                b[p][i] = x;
            }
        }
    }
    for r in 1..d {
        let mut s = b[r];
        for c in 0..r {
            for i in 0..L {
                s[i] -= lu[r * d + c][i] * b[c][i];
            }
        }
        b[r] = s;
    }
    for r in (0..d).rev() {
        let mut s = b[r];
        for c in r + 1..d {
            for i in 0..L {
                s[i] -= lu[r * d + c][i] * b[c][i];
            }
        }
        for i in 0..L {
            b[r][i] = s[i] * lu[r * d + r][i];
        }
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
        let m = [0.0, 2.0, 1.0, 1.0, 1.0, 0.0, 3.0, 0.0, 1.0];
        let mut a: Vec<[f64; 1]> = m.iter().map(|x| [*x]).collect();
        let mut p = vec![[0]; 3];
        assert!(lu_factor::<f64, 0, 1>(&mut a, &mut p, 3, &[true])[0]);
        let mut b = vec![[5.0], [3.0], [6.0]];
        lu_solve::<f64, 3, 1>(&a, &p, &mut b);
        for r in 0..3 {
            let s: f64 = (0..3).map(|c| m[r * 3 + c] * b[c][0]).sum();
            assert!((s - [5.0, 3.0, 6.0][r]).abs() < 1e-14);
        }
        let mut z = vec![[1.0], [2.0], [2.0], [4.0]];
        assert!(!lu_factor::<f64, 2, 1>(&mut z, &mut p[..2], 2, &[true])[0]);
    }

    #[test]
    fn lanes_pivot_each_on_their_own_and_equal_the_factorisation_alone() {
        // lane 0 needs row swaps, lane 1 none, lane 2 is singular: each lane as if alone
        let mats = [
            [0.0, 2.0, 1.0, 1.0, 1.0, 0.0, 3.0, 0.0, 1.0],
            [4.0, 1.0, 0.5, 1.0, 3.0, 0.2, 0.1, 0.3, 2.0],
            [1.0, 2.0, 3.0, 2.0, 4.0, 6.0, 0.0, 1.0, 1.0],
        ];
        let mut a: Vec<[f64; 3]> = (0..9).map(|e| std::array::from_fn(|i| mats[i][e])).collect();
        let mut p = vec![[0; 3]; 3];
        let ok = lu_factor::<f64, 3, 3>(&mut a, &mut p, 3, &[true; 3]);
        assert_eq!(ok, [true, true, false]);
        assert_ne!(p[0][0], 0);
        assert_eq!(
            [p[0][1], p[1][1], p[2][1]],
            [0, 1, 2],
            "the diagonally dominant lane keeps its rows"
        );
        let mut b = vec![[5.0, 1.0, 0.0], [3.0, 2.0, 0.0], [6.0, 3.0, 0.0]];
        lu_solve::<f64, 3, 3>(&a, &p, &mut b);
        for i in 0..2 {
            let mut alone: Vec<[f64; 1]> = mats[i].iter().map(|x| [*x]).collect();
            let mut pa = vec![[0]; 3];
            assert!(lu_factor::<f64, 3, 1>(&mut alone, &mut pa, 3, &[true])[0]);
            let mut x = vec![[[5.0, 1.0][i]], [[3.0, 2.0][i]], [[6.0, 3.0][i]]];
            lu_solve::<f64, 3, 1>(&alone, &pa, &mut x);
            for c in 0..3 {
                assert_eq!(b[c][i].to_bits(), x[c][0].to_bits(), "lane {i} component {c}");
            }
        }
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
