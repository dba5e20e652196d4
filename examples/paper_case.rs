//! Paper case from Rust alone (used for profiling): `cargo run --release --example paper_case`.
use idm_rs::model::Model;
use idm_rs::physics::{effects::Effects, mechanics::Structure, params::Params, waveform::PiecewiseLinear};
use idm_rs::simulate::simulate_from_rest;

fn main() {
    let structure = match std::env::args().nth(1).as_deref() {
        Some("dps") => Structure::Dps(4),
        _ => Structure::Lps,
    };
    let mut p = Params::paper();
    if std::env::args().nth(2).as_deref() == Some("no-stribeck") {
        p.mu_s = p.mu_k;
    }
    let m = Model::new(p, Effects::default(), structure, true, false).unwrap();
    let w = PiecewiseLinear::triangle(80.0, 0.5e-3, 9.5e-3, 0.0).unwrap();
    let t = std::time::Instant::now();
    let r = simulate_from_rest(&m, &w, 10e-3, 1e-8, 1_000_000).unwrap();
    println!(
        "{structure:?} x1 = {:.10e} m, {:.1} ns/step",
        r.final_state[0],
        t.elapsed().as_secs_f64() * 1e9 / 1e6
    );
}
