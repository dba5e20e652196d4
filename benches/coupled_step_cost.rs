//! Cost and accuracy of a friction step coupled to the mechanics, against RK4 over the whole
//! state at the diagnosis's fit step (2e-7 s), in Rust on one thread:
//! `cargo bench --bench coupled_step_cost`.
//!
//! The presliding force Fh (and the asperity deformation g it drives) is the state that sets
//! the fit step: in a fast slip its stiffness |v1| (a/S + b + |c|) is ~1e8 1/s, beyond RK4's
//! stability at any step the mechanics need. The coupled step (a probe, not a method of the
//! package; `benches/probe_friction_split.py` is its Python twin): the mechanics' RK4 step with
//! (g, Fh) held predicts v1 at the step's end; (g, Fh) are sub-stepped by RK4 at their own stable
//! step along v1 linear between the two; the mechanics' step is taken again with Fh at the
//! step's start, middle and end for RK4's stages. Both integrators call the engine's scalar
//! right-hand side (`Model::rhs`), so the ratio is that of the steps, not of two codes. Each
//! run's main-body position every 10 us (the recordings' sample step) is compared with RK4 at
//! 1e-8 s; the recordings' noise is 1-2 nm.

use std::time::Instant;

use idm_rs::model::Model;
use idm_rs::physics::effects::Effects;
use idm_rs::physics::mechanics::Structure;
use idm_rs::physics::params::Params;
use idm_rs::physics::waveform::PiecewiseLinear;

const SAMPLE: f64 = 1e-5;
/// Room for the LPS's state (7 with hysteresis).
const MAX_DIM: usize = 16;

/// V and dV/dt at `t` inside the segment holding `probe` (steps never straddle a breakpoint).
fn input(wave: &PiecewiseLinear, t: f64, probe: f64) -> (f64, f64) {
    let i = wave.segment(probe);
    let (bt, bv) = (wave.times(), wave.values());
    if probe < bt[0] || i + 1 >= bt.len() {
        return (bv[i.min(bv.len() - 1)], 0.0);
    }
    let s = wave.slope(i, probe);
    (bv[i] + s * (t - bt[i]), s)
}

/// One RK4 step of the whole state; with `held`, (g, Fh) are not integrated and Fh takes the
/// given values at the start, middle and end of the step for the stages.
fn rk4_step(m: &Model, wave: &PiecewiseLinear, t: f64, dt: f64, y: &mut [f64], held: Option<[f64; 3]>) {
    let (ig, ifh) = (m.layout.g, m.layout.fh);
    let n = y.len();
    // on the stack: an allocation per step would weigh on the integrator with more steps
    let mut k = [[0.0; MAX_DIM]; 4];
    let mut stage = [0.0; MAX_DIM];
    stage[..n].copy_from_slice(y);
    let frac = [0.0, 0.5, 0.5, 1.0];
    // the input is linear over a step (a step never straddles a breakpoint): one lookup
    let (v_start, slope) = input(wave, t, t + 0.5 * dt);
    for s in 0..4 {
        if s > 0 {
            for j in 0..n {
                stage[j] = y[j] + frac[s] * dt * k[s - 1][j];
            }
        }
        if let Some(fh) = held {
            stage[ifh] = fh[if s == 0 {
                0
            } else if s < 3 {
                1
            } else {
                2
            }];
        }
        let ts = t + frac[s] * dt;
        let (v, dv) = (v_start + slope * frac[s] * dt, slope);
        m.rhs(ts, v, dv, &stage[..n], &mut k[s][..n]);
        if held.is_some() {
            k[s][ig] = 0.0;
            k[s][ifh] = 0.0;
        }
    }
    for j in 0..n {
        y[j] += dt / 6.0 * (k[0][j] + 2.0 * k[1][j] + 2.0 * k[2][j] + k[3][j]);
    }
}

/// (g, Fh) over `dt` with v1 linear from `v0` to `v1`, RK4 sub-steps within RK4's limit
/// (lambda h <= 2, an even number of them): Fh at the middle, (g, Fh) at the end, sub-steps.
fn friction_along(m: &Model, g: f64, fh: f64, v0: f64, v1: f64, dt: f64) -> (f64, f64, f64, usize) {
    // Fh's stiffness bound |v| (a/S + b + |c|) (fric_n = 1), at the faster end
    let p = &m.params;
    let stiff = |v: f64| v.abs() * (p.fric_alpha / m.friction.stribeck(v) + p.fric_beta + p.fric_gamma.abs());
    let lam = stiff(v0).max(stiff(v1));
    let subs = 2 * ((lam * dt / 4.0).ceil() as usize).max(1);
    let h = dt / subs as f64;
    let rate = |tau: f64, fh: f64| m.friction.rates(v0 + (v1 - v0) * tau / dt, fh);
    let (mut g, mut fh, mut middle) = (g, fh, fh);
    for k in 0..subs {
        let tau = k as f64 * h;
        let (g1, f1) = rate(tau, fh);
        let (g2, f2) = rate(tau + 0.5 * h, fh + 0.5 * h * f1);
        let (g3, f3) = rate(tau + 0.5 * h, fh + 0.5 * h * f2);
        let (g4, f4) = rate(tau + h, fh + h * f3);
        g += h / 6.0 * (g1 + 2.0 * g2 + 2.0 * g3 + g4);
        fh += h / 6.0 * (f1 + 2.0 * f2 + 2.0 * f3 + f4);
        if k + 1 == subs / 2 {
            middle = fh;
        }
    }
    (middle, g, fh, subs)
}

/// Main-body positions every SAMPLE over the wave's span, and Fh sub-steps per step (0 for RK4).
fn run(m: &Model, wave: &PiecewiseLinear, t_end: f64, dt: f64, coupled: bool) -> (Vec<f64>, f64) {
    let mut y = m.rest_state();
    let (ig, ifh, iv) = (m.layout.g, m.layout.fh, m.layout.dof);
    let steps = (t_end / dt).round() as usize;
    let every = (SAMPLE / dt).round() as usize;
    let mut out = Vec::with_capacity(steps / every + 1);
    let mut subs = 0usize;
    for i in 0..steps {
        if i % every == 0 {
            out.push(y[0]);
        }
        let t = i as f64 * dt;
        if coupled {
            let fh0 = y[ifh];
            let mut predicted = [0.0; MAX_DIM];
            predicted[..y.len()].copy_from_slice(&y);
            rk4_step(m, wave, t, dt, &mut predicted[..y.len()], Some([fh0; 3]));
            let (middle, g, fh, k) = friction_along(m, y[ig], fh0, y[iv], predicted[iv], dt);
            rk4_step(m, wave, t, dt, &mut y, Some([fh0, middle, fh]));
            y[ig] = g;
            y[ifh] = fh;
            subs += k;
        } else {
            rk4_step(m, wave, t, dt, &mut y, None);
        }
    }
    out.push(y[0]);
    (out, subs as f64 / steps as f64)
}

fn main() {
    let model = Model::new(Params::paper(), Effects::default(), Structure::Lps, true, false).unwrap();
    let drives = [
        (
            "sawtooth 80 V, 100 Hz, 0.5 ms edge, 4 cycles",
            PiecewiseLinear::sawtooth(80.0, 100.0, 4, 0.5e-3, true, 0.0).unwrap(),
            40e-3,
        ),
        (
            "triangle 150 V, 0.1 ms rise (slips at ~16 mm/s)",
            PiecewiseLinear::triangle(150.0, 0.1e-3, 9.9e-3, 0.0).unwrap(),
            10e-3,
        ),
    ];
    println!("| drive | integrator | step [s] | max |x1 - reference| [nm] | s per simulated s | vs RK4 at 2e-7 s | Fh sub-steps per step |");
    println!("|---|---|---|---|---|---|---|");
    for (name, wave, t_end) in drives.iter() {
        let (reference, _) = run(&model, wave, *t_end, 1e-8, false);
        assert!(reference.iter().all(|x| x.is_finite()), "the reference run diverged");
        let mut base = f64::NAN;
        for (label, dt, coupled) in [
            ("RK4", 2e-7, false),
            ("coupled", 5e-7, true),
            ("coupled", 1e-6, true),
            ("coupled", 2e-6, true),
        ] {
            let mut best = f64::INFINITY;
            let mut res = (Vec::new(), 0.0);
            for _ in 0..3 {
                let t = Instant::now();
                res = run(&model, wave, *t_end, dt, coupled);
                best = best.min(t.elapsed().as_secs_f64());
            }
            let (xs, subs) = res;
            let err = xs
                .iter()
                .zip(&reference)
                .map(|(a, b)| (a - b).abs())
                // a NaN is not skipped: a run that diverged says so
                .fold(
                    0.0,
                    |m: f64, e| if e.is_nan() || m.is_nan() { f64::NAN } else { m.max(e) },
                );
            let err = if err.is_finite() && xs.len() == reference.len() {
                format!("{:.3}", err * 1e9)
            } else {
                "diverges".into()
            };
            let per = best / t_end;
            if !coupled {
                base = per;
            }
            println!(
                "| {name} | {label} | {dt:e} | {err} | {per:.3} | {:.2} | {subs:.1} |",
                base / per
            );
        }
    }
}
