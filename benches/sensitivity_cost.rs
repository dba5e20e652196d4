//! A derivative pass (`sensitivity::derivatives`) against the plain run it follows, in plain
//! runs, for 1, 2, 4 and 8 names, on the paper device (2 ms at RK4 dt = 1e-8 s), LPS and DPS4.
//! Run: `cargo bench --bench sensitivity_cost`.

use std::sync::atomic::AtomicBool;
use std::time::Instant;

use idm_rs::integrate::method::Method;
use idm_rs::model::Model;
use idm_rs::physics::effects::Effects;
use idm_rs::physics::mechanics::Structure;
use idm_rs::physics::params::Params;
use idm_rs::physics::waveform::PiecewiseLinear;
use idm_rs::sensitivity::{derivatives, parse_seeds, Schedule};
use idm_rs::simulate::simulate;

fn best<F: FnMut()>(mut f: F) -> f64 {
    (0..5)
        .map(|_| {
            let t = Instant::now();
            f();
            t.elapsed().as_secs_f64()
        })
        .fold(f64::INFINITY, f64::min)
}

fn main() {
    let names = [
        "mu_k",
        "m2",
        "fric_alpha",
        "sigma1",
        "mu_s",
        "d33",
        "hyst_alpha",
        "sigma2",
    ];
    let wave = PiecewiseLinear::triangle(80.0, 0.5e-3, 9.5e-3, 0.0).unwrap();
    let method = Method::Rk4 { dt: 1e-8 };
    let never = AtomicBool::new(false);
    println!("| model | plain [ms] | names | pass [ms] | pass in plain runs | plain + pass (goal <= 1 + n) |");
    println!("|---|---:|---:|---:|---:|---:|");
    for (label, s) in [("LPS", Structure::Lps), ("DPS4", Structure::Dps(4))] {
        let m = Model::new(Params::paper(), Effects::default(), s, true, false).unwrap();
        let y0 = m.rest_state();
        let plain = best(|| {
            simulate(&m, &wave, 0.0, 2e-3, &y0, &method, 100).unwrap();
        });
        for n in [1, 2, 4, 8] {
            let asked: Vec<String> = names[..n].iter().map(|s| s.to_string()).collect();
            let seeds = parse_seeds(&m, &asked, false).unwrap();
            let schedule = Schedule {
                every: 100,
                also_last: true,
            };
            let pass = best(|| {
                derivatives(
                    &m,
                    &wave,
                    0.0,
                    2e-3,
                    &y0,
                    &method,
                    &Default::default(),
                    schedule,
                    &seeds,
                    false,
                    &never,
                )
                .unwrap()
                .unwrap();
            });
            println!(
                "| {label} | {:.1} | {n} | {:.1} | {:.2} | {:.2} |",
                plain * 1e3,
                pass * 1e3,
                pass / plain,
                1.0 + pass / plain
            );
        }
    }
}
