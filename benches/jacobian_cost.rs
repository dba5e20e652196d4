//! What the hand-written Jacobian saves: ns per call of `Model::jacobian` (analytic) and of
//! `Model::derived_jacobian` (dual numbers through the right-hand side), and ns per Rodas4
//! attempt (Jacobian + LU + six stages) with each, for the LPS and the DPS4 paper device in a
//! sliding state. Run: `cargo bench --bench jacobian_cost`.

use std::hint::black_box;
use std::time::Instant;

use idm_rs::integrate::method::Method;
use idm_rs::integrate::model_rhs::ModelRhs;
use idm_rs::integrate::rodas4::Rodas4;
use idm_rs::integrate::stepper::AdaptiveOptions;
use idm_rs::integrate::stepper::{Rhs, Stepper};
use idm_rs::model::Model;
use idm_rs::physics::effects::Effects;
use idm_rs::physics::mechanics::Structure;
use idm_rs::physics::params::Params;
use idm_rs::physics::waveform::PiecewiseLinear;
use idm_rs::simulate::simulate;
use num_dual::Dual64;

/// The model's right-hand side with the derived Jacobian in place of the analytic one.
struct Derived<'a> {
    inner: ModelRhs<'a, f64, 0, true, 1>,
    dual: &'a Model<Dual64>,
}

impl Rhs for Derived<'_> {
    fn eval(&mut self, lane: usize, tau: f64, y: &[f64], dy: &mut [f64]) {
        self.inner.eval(lane, tau, y, dy)
    }
    fn admissible(&self, lane: usize, y: &[f64]) -> bool {
        self.inner.admissible(lane, y)
    }
    fn jacobian(&mut self, _lane: usize, tau: f64, y: &[f64], jac: &mut [f64], dfdt: &mut [f64]) {
        let (v0, s) = (self.inner.v0[0], self.inner.slope[0]);
        self.dual
            .derived_jacobian(self.inner.t0[0] + tau, v0 + s * tau, s, y, jac, dfdt);
    }
}

fn ns_per<F: FnMut()>(reps: usize, mut f: F) -> f64 {
    let mut best = f64::INFINITY;
    for _ in 0..7 {
        let t = Instant::now();
        for _ in 0..reps {
            f();
        }
        best = best.min(t.elapsed().as_secs_f64() * 1e9 / reps as f64);
    }
    best
}

fn main() {
    println!("| structure | analytic J [ns] | derived J [ns] | ratio | Rodas4 attempt, analytic J [ns] | with derived J [ns] | ratio |");
    println!("|---|---:|---:|---:|---:|---:|---:|");
    for (label, structure) in [("LPS", Structure::Lps), ("DPS4", Structure::Dps(4))] {
        let m = Model::new(Params::paper(), Effects::default(), structure, true, false).unwrap();
        let wave = PiecewiseLinear::triangle(80.0, 0.5e-3, 9.5e-3, 0.0).unwrap();
        // a sliding state: during the rise, when the body is carried along
        let r = simulate(&m, &wave, 0.0, 0.3e-3, &m.rest_state(), &Method::Rk4 { dt: 1e-8 }, 1000).unwrap();
        let y = r.final_state.clone();
        let d = y.len();
        let (v, dv) = (wave.value(0.3e-3), 80.0 / 0.5e-3);
        let dual = m.dual();
        let (mut jac, mut ft) = (vec![0.0; d * d], vec![0.0; d]);
        let analytic = ns_per(200_000, || {
            m.jacobian(0.3e-3, black_box(v), dv, black_box(&y), &mut jac, &mut ft)
        });
        let derived = ns_per(20_000, || {
            dual.derived_jacobian(0.3e-3, black_box(v), dv, black_box(&y), &mut jac, &mut ft)
        });

        let opts = AdaptiveOptions {
            rtol: 1e-6,
            atol: 1e-6,
            scale: m.state_scales(80.0),
            h_init: 2e-8,
            h_min: 1e-14,
            h_max: 1.0,
            held: Default::default(),
        };
        let rhs = || ModelRhs::<f64, 0, true, 1> {
            models: [&m],
            t0: [0.3e-3],
            v0: [v],
            slope: [dv],
            at_start: [(0.0, 0.0)],
            bound: [m.presliding_bound() * 2.0],
        };
        let attempt = |derive: bool| {
            let mut st: Rodas4<Vec<f64>, 1, 0> = Rodas4::new([opts.clone()], vec![0.0; d]);
            let mut plain = rhs();
            let mut with = Derived {
                inner: rhs(),
                dual: &dual,
            };
            ns_per(20_000, || {
                let mut ys = [y.clone()];
                if derive {
                    black_box(st.attempt(&mut with, &mut ys, &[0.0], &[1.0], &[true]));
                } else {
                    black_box(st.attempt(&mut plain, &mut ys, &[0.0], &[1.0], &[true]));
                }
            })
        };
        let (ra, rd) = (attempt(false), attempt(true));
        println!(
            "| {label} | {analytic:.0} | {derived:.0} | {:.1} | {ra:.0} | {rd:.0} | {:.2} |",
            derived / analytic,
            rd / ra
        );
    }
}
