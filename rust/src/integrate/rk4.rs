//! Classical fixed-step fourth-order Runge-Kutta over a flat state vector (the reference
//! method). It knows nothing of the physics: the right-hand side is an [`Rhs`] evaluated at
//! offsets 0, dt/2 and dt from the step's start.
//!
//! Generic over the storage: a `Vec<f64>` for any state size, or a fixed `[f64; D]` so that for
//! the common small models the whole step stays in registers. One step advances `L` independent
//! systems ("lanes") stage by stage: a single trajectory is latency-bound (each stage waits on an
//! exp and a division), and interleaving independent lanes fills the idle execution units. Each
//! lane's arithmetic is exactly that of a one-lane step.

use crate::integrate::stepper::{Attempt, Rhs, State, Stepper};
use crate::integrate::tableau::{rk4_factor, rk4_sum, RK4_NODES};
use crate::numbers::scalar::Scalar;

/// RK4's slack on the presliding bound [relative]: it may overshoot by its truncation error.
pub const BOUND_SLACK: f64 = 1e-6;

/// Step size and stage buffers for `L` lanes, allocated once per run.
#[derive(Clone, Debug)]
pub struct Rk4<S, const L: usize = 1> {
    /// the step [s]
    pub dt: f64,
    k1: [S; L],
    k2: [S; L],
    k3: [S; L],
    k4: [S; L],
    tmp: [S; L],
}

impl<S: State, const L: usize> Rk4<S, L> {
    /// Step `dt` [s]; buffers shaped like `zero` (which should be all zeros).
    pub fn new(dt: f64, zero: S) -> Self {
        let z = || std::array::from_fn(|_| zero.clone());
        Rk4 {
            dt,
            k1: z(),
            k2: z(),
            k3: z(),
            k4: z(),
            tmp: z(),
        }
    }

    /// Advance every lane `i` with `active[i]` by one step `dt`.
    #[inline(always)]
    pub fn step_lanes<F: Rhs<S::Elem>>(&mut self, f: &mut F, dt: f64, ys: &mut [S; L], active: &[bool; L]) {
        let [c1, c2, c3, c4] = RK4_NODES.map(|c| c * dt);
        f.eval_lanes(&[c1; L], ys, &mut self.k1, active);
        self.stage(ys, c2, Stage::K1, active);
        f.eval_lanes(&[c2; L], &self.tmp, &mut self.k2, active);
        self.stage(ys, c3, Stage::K2, active);
        f.eval_lanes(&[c3; L], &self.tmp, &mut self.k3, active);
        self.stage(ys, c4, Stage::K3, active);
        f.eval_lanes(&[c4; L], &self.tmp, &mut self.k4, active);
        let factor = rk4_factor(dt);
        for i in 0..L {
            if active[i] {
                let (y, k1, k2, k3, k4) = (
                    ys[i].as_mut(),
                    self.k1[i].as_ref(),
                    self.k2[i].as_ref(),
                    self.k3[i].as_ref(),
                    self.k4[i].as_ref(),
                );
                for j in 0..y.len() {
                    y[j] += rk4_sum(k1[j], k2[j], k3[j], k4[j]) * factor;
                }
            }
        }
    }

    /// tmp = y + h k for the stage's k on every active lane.
    #[inline(always)]
    fn stage(&mut self, ys: &[S; L], h: f64, k: Stage, active: &[bool; L]) {
        for i in 0..L {
            if active[i] {
                let k = match k {
                    Stage::K1 => &self.k1[i],
                    Stage::K2 => &self.k2[i],
                    Stage::K3 => &self.k3[i],
                };
                axpy(self.tmp[i].as_mut(), ys[i].as_ref(), h, k.as_ref());
            }
        }
    }
}

#[derive(Clone, Copy)]
enum Stage {
    K1,
    K2,
    K3,
}

impl<S: State> Rk4<S, 1> {
    /// Advance `y` by one step (the one-lane case).
    #[inline(always)]
    pub fn step<F: Rhs<S::Elem>>(&mut self, f: &mut F, y: &mut S) {
        let ys: &mut [S; 1] = std::slice::from_mut(y).try_into().unwrap();
        self.step_lanes(f, self.dt, ys, &[true]);
    }
}

impl<S: State, const L: usize> Stepper<S, L> for Rk4<S, L> {
    const FIXED_STEP: bool = true;
    const EVALUATES_START: bool = true;

    /// RK4 may overshoot the bound by its truncation error.
    fn bound_slack(&self) -> f64 {
        BOUND_SLACK
    }

    fn restart(&mut self, _lane: usize) {}

    #[inline(always)]
    fn attempt<F: Rhs<S::Elem>>(
        &mut self,
        f: &mut F,
        ys: &mut [S; L],
        _t: &[f64; L],
        _end: &[f64; L],
        active: &[bool; L],
    ) -> [Attempt; L] {
        self.step_lanes(f, self.dt, ys, active);
        std::array::from_fn(|i| {
            if active[i] {
                Attempt::Accepted {
                    step: self.dt,
                    last: false,
                }
            } else {
                Attempt::Idle
            }
        })
    }
}

/// out = y + h k
#[inline(always)]
fn axpy<T: Scalar>(out: &mut [T], y: &[T], h: f64, k: &[T]) {
    for j in 0..out.len() {
        out[j] = y[j] + k[j] * h;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn pendulum(_l: usize, _c: f64, y: &[f64], dy: &mut [f64]) {
        dy[0] = y[1];
        dy[1] = -y[0].sin();
    }

    fn oscillator_error(n: usize) -> f64 {
        let dt = 10.0 / n as f64;
        let mut y = [1.0, 0.0];
        let mut rk = Rk4::new(dt, [0.0; 2]);
        let mut f = |_l: usize, _c: f64, y: &[f64], dy: &mut [f64]| {
            dy[0] = y[1];
            dy[1] = -y[0];
        };
        for _ in 0..n {
            rk.step(&mut f, &mut y);
        }
        (y[0] - 10f64.cos()).abs()
    }

    #[test]
    fn order_four_on_harmonic_oscillator() {
        let order = (oscillator_error(200) / oscillator_error(400)).log2();
        assert!((order - 4.0).abs() < 0.1, "order {order}");
    }

    #[test]
    fn vec_array_and_lane_storage_agree_bitwise() {
        let mut a = [0.3, -0.2];
        let mut v = vec![0.3, -0.2];
        let mut lanes = [[0.3, -0.2], [1.0, 0.0], [0.3, -0.2]];
        let (mut ra, mut rv) = (Rk4::new(0.01, [0.0; 2]), Rk4::new(0.01, vec![0.0; 2]));
        let mut rl: Rk4<[f64; 2], 3> = Rk4::new(0.01, [0.0; 2]);
        for _ in 0..100 {
            ra.step(&mut pendulum, &mut a);
            rv.step(&mut pendulum, &mut v);
            rl.step_lanes(&mut pendulum, 0.01, &mut lanes, &[true, true, true]);
        }
        assert_eq!(a.to_vec(), v);
        assert_eq!(lanes[0], a);
        assert_eq!(lanes[2], a);
        assert_ne!(lanes[1], a);
    }
}
