//! The tangent pass: fixed-step RK4 of K derivatives at once on vector arithmetic, step for
//! step as the plain driver takes it (the coefficients of `integrate/tableau.rs`).

use std::sync::atomic::{AtomicBool, Ordering};

use super::Recorder;
use crate::integrate::tableau::{rk4_factor, rk4_sum, RK4_NODES};
use crate::integrate::task::LaneEnd;
use crate::model::Model;
use crate::numbers::tangent::Tangent;
use crate::physics::waveform::{Cursor, PiecewiseLinear};

/// [`rk4_pass`] as one operation for `pulp` to compile per instruction set (as the lane
/// drivers are: `drive::PlainGroups`): a tangent's K derivatives are K-wide vector arithmetic,
/// and IEEE operations give the same bits at any width.
pub(super) struct TangentRun<'r, 'm, const K: usize> {
    pub(super) model: &'r Model<Tangent<K>>,
    pub(super) wave: &'r PiecewiseLinear,
    pub(super) t_start: f64,
    pub(super) t_end: f64,
    pub(super) y0: &'r [Tangent<K>],
    pub(super) dt: f64,
    pub(super) rec: &'r mut Recorder<'m, Tangent<K>>,
    pub(super) cancel: &'r AtomicBool,
}

impl<const K: usize> pulp::WithSimd for TangentRun<'_, '_, K> {
    type Output = Option<(LaneEnd, Vec<Tangent<K>>)>;
    #[inline(always)]
    fn with_simd<S: pulp::Simd>(self, _simd: S) -> Self::Output {
        rk4_pass(
            self.model,
            self.wave,
            self.t_start,
            self.t_end,
            self.y0,
            self.dt,
            self.rec,
            self.cancel,
        )
    }
}

/// Fixed-step RK4 of one tangent run, step for step as the generic driver takes it with one
/// lane (`drive::drive_lanes`, `integrate/rk4.rs`): step k from t = k dt, the input through the step from
/// the breakpoint cursor at its midpoint, the four stages and the update in the same order,
/// the same divergence check; the recorder sees each accepted step. Stops early (as
/// `Finished`, with the recorder holding the time) once a recorded derivative is not finite.
/// `None` if cancelled.
#[allow(clippy::too_many_arguments)]
#[inline(always)]
fn rk4_pass<const K: usize>(
    model: &Model<Tangent<K>>,
    wave: &PiecewiseLinear,
    t_start: f64,
    t_end: f64,
    y0: &[Tangent<K>],
    dt: f64,
    rec: &mut Recorder<Tangent<K>>,
    cancel: &AtomicBool,
) -> Option<(LaneEnd, Vec<Tangent<K>>)> {
    let n = y0.len();
    let dof = model.layout.dof;
    let bound = model.presliding_bound() * (1.0 + crate::integrate::rk4::BOUND_SLACK) + 1e-12;
    let mut y = y0.to_vec();
    let zero = Tangent::constant(0.0);
    let (mut k1, mut k2, mut k3, mut k4, mut tmp) = (
        vec![zero; n],
        vec![zero; n],
        vec![zero; n],
        vec![zero; n],
        vec![zero; n],
    );
    let [c1, c2, c3, c4] = RK4_NODES.map(|c| c * dt);
    let factor = rk4_factor(dt);
    let mut k = (t_start / dt).round() as usize;
    let k_end = k + ((t_end - t_start) / dt).round() as usize;
    let mut cursor = Cursor::at(wave, t_start);
    let mut v_last = y[dof].re;
    let mut steps = 0u64;
    rec.record(t_start, &y);
    loop {
        if steps.is_multiple_of(crate::integrate::task::CANCEL_CHECK_ATTEMPTS as u64) && cancel.load(Ordering::Relaxed)
        {
            return None;
        }
        let t0 = k as f64 * dt;
        let probe = t0 + 0.5 * dt;
        cursor.advance(wave, probe);
        let (v0, s) = cursor.input(wave, t0, probe);
        // plain calls, not a closure: code left out of line runs as baseline (see `Real::select`)
        stage_rate(model, t0, v0, s, c1, &y, &mut k1);
        axpy(&mut tmp, &y, c2, &k1);
        stage_rate(model, t0, v0, s, c2, &tmp, &mut k2);
        axpy(&mut tmp, &y, c3, &k2);
        stage_rate(model, t0, v0, s, c3, &tmp, &mut k3);
        axpy(&mut tmp, &y, c4, &k3);
        stage_rate(model, t0, v0, s, c4, &tmp, &mut k4);
        for j in 0..n {
            y[j] += rk4_sum(k1[j], k2[j], k3[j], k4[j]) * factor;
        }
        k += 1;
        let t_new = k as f64 * dt;
        if model.is_diverged(&y, bound) {
            return Some((
                LaneEnd::Diverged {
                    t: t_new,
                    why: None,
                    v_last,
                },
                y,
            ));
        }
        v_last = y[dof].re;
        steps += 1;
        let done = k == k_end;
        rec.on_step(t_new, &y, done);
        if done || rec.blew_up.is_some() {
            return Some((LaneEnd::Finished { steps, min_step: dt }, y));
        }
    }
}

/// The right-hand side at `tau` [s] into the step from `t0` [s], the input `v0 + s tau` [V]
/// (as `integrate::model_rhs::ModelRhs::eval`).
#[inline(always)]
fn stage_rate<const K: usize>(
    model: &Model<Tangent<K>>,
    t0: f64,
    v0: f64,
    s: f64,
    tau: f64,
    y: &[Tangent<K>],
    dy: &mut [Tangent<K>],
) {
    model.rhs_impl::<0, true>(t0 + tau, Tangent::constant(v0 + s * tau), s, y, dy);
}

/// out = y + h k (as `integrate/rk4.rs`)
#[inline(always)]
fn axpy<const K: usize>(out: &mut [Tangent<K>], y: &[Tangent<K>], h: f64, k: &[Tangent<K>]) {
    for j in 0..out.len() {
        out[j] = y[j] + k[j] * h;
    }
}
