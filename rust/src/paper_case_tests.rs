//! End-to-end checks of the paper case against MODEL.md's reference values.

use crate::effects::Effects;
use crate::mechanics::Structure;
use crate::model::Model;
use crate::params::Params;
use crate::simulate::simulate;
use crate::waveform::PiecewiseLinear;

fn paper_run(structure: Structure, dt: f64) -> f64 {
    let m = Model::new(Params::paper(), Effects::default(), structure, true, false).unwrap();
    let w = PiecewiseLinear::triangle(80.0, 0.5e-3, 9.5e-3, 0.0).unwrap();
    let r = simulate(&m, &w, 10e-3, dt, 100_000).unwrap();
    r.final_state[0]
}

#[test]
fn paper_case_final_positions_match_model_md() {
    let lps = paper_run(Structure::Lps, 1e-8);
    let dps = paper_run(Structure::Dps(4), 1e-8);
    eprintln!("LPS {lps:.6e}  DPS4 {dps:.6e}");
    assert!((lps - 1.678e-6).abs() < 1e-9, "LPS {lps}");
    assert!((dps - 1.711e-6).abs() < 1e-9, "DPS {dps}");
}

#[test]
fn too_large_step_is_reported_as_divergence() {
    let m = Model::new(
        Params::paper(),
        Effects::default(),
        Structure::Lps,
        true,
        false,
    )
    .unwrap();
    let w = PiecewiseLinear::triangle(80.0, 0.5e-3, 9.5e-3, 0.0).unwrap();
    match simulate(&m, &w, 10e-3, 5e-7, 100) {
        Err(crate::simulate::SimError::Diverged { t, message }) => {
            assert!(t > 0.0 && t < 10e-3);
            assert!(message.contains("try dt <="), "{message}");
        }
        other => panic!("expected divergence, got {other:?}"),
    }
}
