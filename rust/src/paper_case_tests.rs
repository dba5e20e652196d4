//! End-to-end checks of the paper case against MODEL.md's reference values.

use crate::model::Model;
use crate::physics::effects::Effects;
use crate::physics::mechanics::Structure;
use crate::physics::params::Params;
use crate::physics::waveform::PiecewiseLinear;
use crate::simulate::simulate_from_rest as simulate;

fn paper_run(structure: Structure, dt: f64) -> f64 {
    let m = Model::new(Params::paper(), Effects::default(), structure, true, false).unwrap();
    let w = PiecewiseLinear::triangle(80.0, 0.5e-3, 9.5e-3, 0.0).unwrap();
    let r = simulate(&m, &w, 10e-3, dt, 100_000).unwrap();
    r.final_state[0]
}

#[test]
fn too_large_step_is_reported_as_divergence() {
    let m = Model::new(Params::paper(), Effects::default(), Structure::Lps, true, false).unwrap();
    let w = PiecewiseLinear::triangle(80.0, 0.5e-3, 9.5e-3, 0.0).unwrap();
    match simulate(&m, &w, 10e-3, 5e-7, 100) {
        Err(crate::integrate::task::SimError::Diverged { t, message }) => {
            assert!(t > 0.0 && t < 10e-3);
            // a step from the stability estimate, fitted to the run's breakpoints, that works
            let hint: f64 = message
                .split("try dt = ")
                .nth(1)
                .and_then(|r| r.split(' ').next())
                .and_then(|x| x.parse().ok())
                .unwrap_or_else(|| panic!("no hint in {message}"));
            assert!((5e-7 / 64.0..5e-7).contains(&hint), "{message}");
            assert!(simulate(&m, &w, 10e-3, hint, 100_000).is_ok(), "{hint:e} diverges too");
        }
        other => panic!("expected divergence, got {other:?}"),
    }
}

/// The paper case's final positions against MODEL.md's reference values and to the last bit
/// (RK4, dt = 1e-8): a refactor of the engine must not change them. (Bits of commit 5eeb5d8,
/// before the single driver.) One test for both: each run is a million steps.
#[test]
fn paper_case_final_positions_match_model_md_and_are_pinned_to_the_bit() {
    let lps = paper_run(Structure::Lps, 1e-8);
    let dps = paper_run(Structure::Dps(4), 1e-8);
    eprintln!("LPS {lps:.6e}  DPS4 {dps:.6e}");
    assert!((lps - 1.678e-6).abs() < 1e-9, "LPS {lps}");
    assert!((dps - 1.711e-6).abs() < 1e-9, "DPS {dps}");
    assert_eq!(lps.to_bits(), 0x3ebc2738ea19fa1d);
    assert_eq!(dps.to_bits(), 0x3ebcb2e3bae1b355);
}

/// RK4 batch outputs (metrics and recorded traces of 18 points: LPS and DPS4, effects with extra
/// states, mixed durations, a retried point) folded into one number, pinned like the paper case.
#[test]
fn rk4_batch_outputs_are_pinned_to_the_bit() {
    use crate::batch::*;
    use crate::integrate::method::Method;
    use std::sync::atomic::{AtomicBool, AtomicUsize};
    let mut specs = Vec::new();
    for i in 0..9 {
        let mut p = Params::paper();
        p.m2 = 0.15 + 0.05 * i as f64;
        p.normal_force = p.default_normal_force();
        let mut e = Effects::default();
        if i % 3 == 1 {
            e.tau_sensor = 2e-5;
            e.k_ground = 3e3;
        }
        if i % 3 == 2 {
            e.tau_amp = 3e-6;
            e.kappa = 0.01;
            e.tau_creep = 1e-3;
            e.drift_rate = 1e-6;
        }
        let w = PiecewiseLinear::sawtooth(40.0 + 10.0 * i as f64, 1000.0, 2, 0.2e-3, i % 2 == 0, 0.1e-3);
        let mut sp = PointSpec::new(p, e, w.unwrap(), Some(crate::batch::Train::new(1000.0, 2, 0.1e-3)));
        sp.t_end = if i == 4 { Some(1.5e-3) } else { None };
        specs.push(sp);
    }
    let mut digest = 0u64;
    let mut retried = 0;
    for structure in [Structure::Lps, Structure::Dps(4)] {
        let cfg = BatchConfig {
            structure,
            piezo_hysteresis: true,
            t_end: 2.1e-3,
            method: Method::Rk4 { dt: 5e-8 },
            retries: 2,
            record_every: 25,
            final_states: false,
            skip_cycles: 0,
            sensitivities: Vec::new(),
            derivatives_only: false,
        };
        let r = run_batch(&cfg, &specs, &AtomicBool::new(false), &AtomicUsize::new(0)).unwrap();
        for o in &r {
            let m = o.metrics;
            let values = [
                m.final_position,
                m.step_per_cycle,
                m.peak_velocity,
                m.peak_friction,
                m.slip_fraction,
                m.dt_used,
            ];
            for x in values.iter().chain(&o.trace) {
                digest = digest.rotate_left(5) ^ x.to_bits();
            }
            digest = digest.rotate_left(5) ^ (m.steps + 1000 * m.status as u64);
            retried += usize::from(m.status == Status::Retried);
        }
    }
    // the digest covers what it says: at least one point finished only at a smaller step
    assert!(retried >= 1, "no retried point among the 18");
    eprintln!("digest {digest:#018x}");
    assert_eq!(digest, 0x8a450cd85fedae43);
}
