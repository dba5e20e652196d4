//! The lanes against the one-lane driver: bitwise equal results, refills, divergence,
//! cancellation.

use super::*;
use crate::drive::{run_tasks, run_tasks_one_by_one};
use crate::integrate::method::Method;
use crate::integrate::task::{LaneEnd, Observer, Task};
use crate::physics::effects::Effects;
use crate::physics::mechanics::Structure;
use crate::physics::params::Params;
use crate::physics::waveform::PiecewiseLinear;
use std::sync::atomic::AtomicBool;

struct Nothing;
impl Observer for Nothing {
    fn start(&mut self, _: usize, _: f64, _: &[f64]) {}
    fn step(&mut self, _: usize, _: f64, _: f64, _: &[f64], _: f64, _: Option<(f64, f64)>, _: bool) {}
}

/// Eleven devices that differ in every constant the physics reads — Stribeck peak or none,
/// Stribeck exponent, Bouc-Wen exponent, direction asymmetry, effects that add no state —
/// of one shape (piezo hysteresis off; see `models_with`).
fn models(structure: Structure) -> Vec<Model> {
    models_with(structure, false)
}

fn models_with(structure: Structure, hysteresis: bool) -> Vec<Model> {
    (0..11)
        .map(|k| {
            let f = 1.0 + 0.07 * k as f64;
            let mut p = Params::paper();
            p.m2 *= f;
            p.mu_k *= 1.0 / f.sqrt();
            p.sigma1 *= f;
            p.fric_alpha *= f;
            p.d33 *= 2.0 - f.sqrt();
            p.hyst_alpha *= f;
            if k == 3 {
                p.mu_s = p.mu_k; // no Stribeck peak
            }
            if k == 6 {
                p.stribeck_exponent = 1.5; // a power per lane, not the square
            }
            if k == 8 {
                p.fric_n = 1.3;
            }
            let mut e = Effects::default();
            if k % 4 == 1 {
                e.k_ground = 300.0 * k as f64;
                e.c_weight = 0.1;
            }
            if k % 5 == 2 {
                e.eps = 0.05;
            }
            Model::new(p, e, structure, hysteresis, false).unwrap()
        })
        .collect()
}

fn run(models: &[Model], wave: &PiecewiseLinear, lanes8: bool) -> Vec<Vec<f64>> {
    run_with(models, wave, lanes8, &Method::Rk4 { dt: 5e-8 })
}

/// Over 1 ms: the triangle's rise and half its fall, slip and sticking on every device
/// (bitwise equality needs no more).
fn run_with(models: &[Model], wave: &PiecewiseLinear, lanes8: bool, method: &Method) -> Vec<Vec<f64>> {
    run_for(models, wave, lanes8, method, 1e-3)
}

fn run_for(models: &[Model], wave: &PiecewiseLinear, lanes8: bool, method: &Method, t_end: f64) -> Vec<Vec<f64>> {
    let y0: Vec<Vec<f64>> = models.iter().map(|m| m.rest_state()).collect();
    let tasks: Vec<Task> = models
        .iter()
        .zip(&y0)
        .map(|(m, y)| Task {
            model: m,
            wave,
            t_start: 0.0,
            t_end,
            y0: y,
        })
        .collect();
    let cancel = AtomicBool::new(false);
    let ends = if lanes8 {
        run_tasks::<_, 8>(&tasks, method, &mut Nothing, &cancel)
    } else {
        run_tasks_one_by_one(&tasks, method, &Default::default(), &mut Nothing, &cancel)
    };
    ends.unwrap().into_iter().map(|(_, y)| y).collect()
}

#[test]
fn vector_lanes_are_bitwise_the_scalar_model_with_and_without_simd() {
    let wave = PiecewiseLinear::triangle(80.0, 0.5e-3, 1.0e-3, 0.0).unwrap();
    for (structure, hysteresis) in [
        (Structure::Lps, false),
        (Structure::Lps, true),
        (Structure::Dps(4), true),
    ] {
        let ms = models_with(structure, hysteresis);
        let n = ms[0].layout.dof;
        let group: [&Model; 8] = std::array::from_fn(|i| &ms[i]);
        assert!(PlainLanes::<2, 8>::new(&group).is_some() || n != 2);
        let reference = run(&ms, &wave, false);
        set_simd_level("scalar");
        let scalar = run(&ms, &wave, true);
        set_simd_level("avx2");
        let vector = run(&ms, &wave, true);
        assert_eq!(
            scalar, reference,
            "{structure:?}: forced-scalar lanes differ from the model"
        );
        assert_eq!(
            vector,
            reference,
            "{structure:?}: {} lanes differ from the model",
            simd_level()
        );
        let x: Vec<f64> = reference.iter().map(|y| y[0]).collect();
        assert!(x.iter().all(|x| x.abs() > 1e-8), "every device moved: {x:?}");
    }
}

#[test]
fn dopri5_stages_on_vector_lanes_are_bitwise_the_scalar_model() {
    // per-lane steps: the lanes' stages sit at different offsets within their steps
    let wave = PiecewiseLinear::triangle(80.0, 0.5e-3, 1.0e-3, 0.0).unwrap();
    let method = Method::Dopri5 {
        rtol: 1e-7,
        atol: 1e-7,
        first_step: 1e-8,
    };
    for structure in [Structure::Lps, Structure::Dps(4)] {
        let ms = models(structure);
        let reference = run_with(&ms, &wave, false, &method);
        for level in ["scalar", "avx2", "avx512"] {
            set_simd_level(level);
            assert_eq!(run_with(&ms, &wave, true, &method), reference, "{structure:?} {level}");
        }
        set_simd_level("avx2");
    }
}

#[test]
fn rodas4_on_lanes_is_bitwise_rodas4_alone() {
    // per-lane pivots, steps and rejections; the stages' right-hand side as vectors where half
    // the lanes are busy (the eleven devices: one full group of 8, one of 3, lane by lane)
    let wave = PiecewiseLinear::triangle(80.0, 0.5e-3, 1.0e-3, 0.0).unwrap();
    let method = Method::Rodas4 {
        rtol: 1e-6,
        atol: 1e-6,
        first_step: 1e-8,
    };
    for structure in [Structure::Lps, Structure::Dps(4)] {
        let ms = models(structure);
        let reference = run_with(&ms, &wave, false, &method);
        assert!(reference.iter().all(|y| y[0].abs() > 1e-8), "every device moved");
        for level in ["scalar", "avx2"] {
            set_simd_level(level);
            assert_eq!(run_with(&ms, &wave, true, &method), reference, "{structure:?} {level}");
        }
        set_simd_level("avx2");
    }
}

/// The accepted steps after which each run changed method (to Rodas4, back, ...).
#[derive(Default)]
struct Switches(std::collections::BTreeMap<usize, Vec<u64>>);
impl Observer for Switches {
    fn start(&mut self, _: usize, _: f64, _: &[f64]) {}
    fn step(&mut self, _: usize, _: f64, _: f64, _: &[f64], _: f64, _: Option<(f64, f64)>, _: bool) {}
    fn switched(&mut self, task: usize, accepted: u64) {
        self.0.entry(task).or_default().push(accepted);
    }
}

#[test]
fn auto_on_vector_lanes_hands_stiff_runs_over_bitwise_as_the_scalar_path() {
    // the eleven devices, and three whose friction state is far stiffer (a presliding
    // stiffness 1,000x the paper's, a near-frictionless contact): those switch to Rodas4
    let wave = PiecewiseLinear::triangle(80.0, 0.5e-3, 1.0e-3, 0.0).unwrap();
    let method = Method::Auto {
        rtol: 3e-7,
        atol: 3e-7,
        first_step: 1e-8,
    };
    for structure in [Structure::Lps, Structure::Dps(4)] {
        let mut ms = models(structure);
        for (alpha, mu) in [(1e3, 1.0), (3e3, 1.0), (1.0, 1e-5)] {
            let mut p = Params::paper();
            p.fric_alpha *= alpha;
            p.mu_k *= mu;
            p.mu_s *= mu;
            ms.insert(4, Model::new(p, Effects::default(), structure, false, false).unwrap());
        }
        let y0: Vec<Vec<f64>> = ms.iter().map(|m| m.rest_state()).collect();
        let tasks: Vec<Task> = ms
            .iter()
            .zip(&y0)
            .map(|(m, y)| Task {
                model: m,
                wave: &wave,
                t_start: 0.0,
                t_end: 2e-3,
                y0: y,
            })
            .collect();
        let cancel = AtomicBool::new(false);
        let mut seen = Switches::default();
        let reference = run_tasks_one_by_one(&tasks, &method, &Default::default(), &mut seen, &cancel).unwrap();
        // the three stiff devices (inserted at 4: tasks 4-6) change to Rodas4 early
        for i in 4..7 {
            let at = &seen.0[&i];
            // after TRY_IMPLICIT_AFTER steps at the stability limit (and the run's first,
            // non-stiff steps): measured 467-545
            assert!(
                at[0] < 3 * crate::integrate::stiffness::TRY_IMPLICIT_AFTER as u64,
                "{structure:?} task {i}: switches {at:?}"
            );
        }
        for level in ["scalar", "avx2"] {
            set_simd_level(level);
            let mut lanes = Switches::default();
            let ends = run_tasks::<_, 8>(&tasks, &method, &mut lanes, &cancel).unwrap();
            assert_eq!(ends, reference, "{structure:?} {level}");
            assert_eq!(
                lanes.0, seen.0,
                "{structure:?} {level}: the same runs switch at the same step"
            );
        }
        set_simd_level("avx2");
    }
}

#[test]
fn a_crawling_lane_stops_as_on_the_scalar_path_and_its_neighbours_finish() {
    // a near-frictionless contact (mu 1e-6) holds Dormand-Prince at its stability limit
    let wave = PiecewiseLinear::triangle(50.0, 0.5e-3, 0.5e-3, 0.0).unwrap();
    let method = Method::Dopri5 {
        rtol: 3e-7,
        atol: 3e-7,
        first_step: 1e-8,
    };
    let mut ms = models(Structure::Lps);
    let mut p = Params::paper();
    p.mu_k = 1e-6;
    p.mu_s = 1e-6;
    ms.insert(
        2,
        Model::new(p, Effects::default(), Structure::Lps, false, false).unwrap(),
    );
    let y0: Vec<Vec<f64>> = ms.iter().map(|m| m.rest_state()).collect();
    // the crawling lane runs to 10 ms: its projected count passes the limit within a few
    // checks (at 1 ms it hovered at the limit for 557,056 steps: most of this test's CI time)
    let tasks: Vec<Task> = ms
        .iter()
        .zip(&y0)
        .enumerate()
        .map(|(i, (m, y))| Task {
            model: m,
            wave: &wave,
            t_start: 0.0,
            t_end: if i == 2 { 1e-2 } else { 1e-3 },
            y0: y,
        })
        .collect();
    let cancel = AtomicBool::new(false);
    let reference = run_tasks_one_by_one(&tasks, &method, &Default::default(), &mut Nothing, &cancel).unwrap();
    for (i, (end, _)) in reference.iter().enumerate() {
        match end {
            LaneEnd::Diverged { why: Some(why), .. } if i == 2 => {
                assert!(why.starts_with(crate::integrate::crawl::CRAWL_PREFIX), "{why}");
                let steps: u64 = why
                    .split(" steps so far")
                    .next()
                    .and_then(|x| x.rsplit(' ').next())
                    .unwrap()
                    .parse()
                    .unwrap();
                assert!(
                    steps <= 10 * crate::integrate::crawl::CRAWL_CHECK_STEPS,
                    "caught within a few checks: {why}"
                );
            }
            LaneEnd::Finished { .. } if i != 2 => {}
            other => panic!("task {i}: {other:?}"),
        }
    }
    for level in ["scalar", "avx2"] {
        set_simd_level(level);
        let ends = run_tasks::<_, 8>(&tasks, &method, &mut Nothing, &cancel).unwrap();
        assert_eq!(ends, reference, "{level}");
    }
    set_simd_level("avx2");
}

#[test]
fn models_of_another_shape_run_lane_by_lane() {
    // hysteresis on and off are two shapes (a state the other lacks the physics of); a
    // Stribeck exponent other than 2 is only a value
    let mut p = Params::paper();
    p.stribeck_exponent = 1.5;
    let odd = Model::new(p, Effects::default(), Structure::Lps, false, false).unwrap();
    let plain = Model::new(Params::paper(), Effects::default(), Structure::Lps, false, false).unwrap();
    let hyst = Model::new(Params::paper(), Effects::default(), Structure::Lps, true, false).unwrap();
    assert!(PlainLanes::<2, 2>::new(&[&plain, &odd]).is_some());
    assert!(PlainLanes::<2, 2>::new(&[&plain, &hyst]).is_none());
    let e = Effects {
        tau_sensor: 1e-5,
        ..Effects::default()
    }; // a lag: another state layout, on lanes
    let lagged = Model::new(Params::paper(), e, Structure::Lps, false, false).unwrap();
    assert!(PlainLanes::<2, 2>::accepts(&lagged));
    assert!(PlainLanes::<2, 2>::new(&[&plain, &lagged]).is_none());
    // accounting states are not held by the lane drivers
    let counted = Model::new(Params::paper(), Effects::default(), Structure::Lps, false, true).unwrap();
    assert!(!PlainLanes::<2, 2>::accepts(&counted));
    let ms = vec![plain.clone(), hyst.clone(), odd, hyst, plain, lagged];
    let wave = PiecewiseLinear::triangle(80.0, 0.5e-3, 1.0e-3, 0.0).unwrap();
    assert_eq!(run(&ms, &wave, true), run(&ms, &wave, false));
}

#[test]
fn lag_states_on_vector_lanes_are_bitwise_the_scalar_model() {
    // each lag effect (one extra state) on the eleven devices, its time constant per lane;
    // RK4 and auto (Dormand-Prince, whose stiff lanes hand over to Rodas4); every lag on
    // the LPS, the sensor's on the DPS4 (1 ms: the unoptimised CI build runs it)
    let wave = PiecewiseLinear::triangle(80.0, 0.5e-3, 1.0e-3, 0.0).unwrap();
    let methods = [
        Method::Rk4 { dt: 5e-8 },
        Method::Auto {
            rtol: 3e-7,
            atol: 3e-7,
            first_step: 1e-8,
        },
    ];
    let cases = [
        (Structure::Lps, "tau_amp"),
        (Structure::Lps, "tau_creep"),
        (Structure::Lps, "tau_sensor"),
        (Structure::Dps(4), "tau_sensor"),
    ];
    for (structure, lag) in cases {
        let ms: Vec<Model> = models(structure)
            .into_iter()
            .enumerate()
            .map(|(k, m)| {
                let mut e = m.effects;
                let tau = 2e-6 * (1.0 + 0.3 * k as f64);
                match lag {
                    "tau_amp" => e.tau_amp = tau,
                    "tau_creep" => (e.kappa, e.tau_creep) = (0.02 * (1.0 + 0.1 * k as f64), 100.0 * tau),
                    _ => e.tau_sensor = tau,
                }
                Model::new(m.params, e, structure, false, false).unwrap()
            })
            .collect();
        assert_eq!(ms[0].lane_lags(), Some(1), "{lag}");
        let group: [&Model; 8] = std::array::from_fn(|i| &ms[i]);
        assert!(PlainLanes::<2, 8>::new(&group).is_some() || structure != Structure::Lps);
        for method in &methods {
            let reference = run_for(&ms, &wave, false, method, 1e-3);
            assert!(
                reference
                    .iter()
                    .all(|y| y.len() == ms[0].layout.dim && y[0].abs() > 1e-8),
                "{lag}: moved"
            );
            for level in ["scalar", "avx2"] {
                set_simd_level(level);
                assert_eq!(
                    run_for(&ms, &wave, true, method, 1e-3),
                    reference,
                    "{structure:?} {lag} {method:?} {level}"
                );
            }
            set_simd_level("avx2");
        }
    }
}

#[test]
fn library_forces_on_vector_lanes_are_bitwise_the_scalar_model() {
    // every library term, with time and position in it: each lane reads its own clock
    let wave = PiecewiseLinear::triangle(80.0, 0.5e-3, 1.0e-3, 0.0).unwrap();
    let ms: Vec<Model> = models(Structure::Lps)
        .into_iter()
        .enumerate()
        .map(|(k, m)| {
            let mut e = m.effects;
            let f = 1.0 + 0.1 * k as f64;
            (e.lib_x1sq, e.lib_sin, e.lib_wavelength, e.lib_ff_cos) = (1e6 * f, 0.05 * f, 20e-6 * f, 0.02);
            (e.lib_t, e.lib_abs, e.libw_sgn, e.libw_vv) = (0.5 * f, 0.3, 0.01 * f, 2.0);
            if k == 4 {
                e.lib_wavelength = 0.0; // no periodic term in this lane
            }
            Model::new(m.params, e, Structure::Lps, false, false).unwrap()
        })
        .collect();
    let group: [&Model; 8] = std::array::from_fn(|i| &ms[i]);
    assert!(PlainLanes::<2, 8>::new(&group).is_some());
    let reference = run(&ms, &wave, false);
    for level in ["scalar", "avx2"] {
        set_simd_level(level);
        assert_eq!(run(&ms, &wave, true), reference, "{level}");
    }
    set_simd_level("avx2");
    let plain = run(&models(Structure::Lps), &wave, false);
    assert!(
        reference.iter().zip(&plain).all(|(a, b)| a[0] != b[0]),
        "the library forces act"
    );
}
