//! The derivative passes against central differences, across structures, effects, methods
//! and widths.

use super::*;
use crate::physics::effects::Effects;
use crate::physics::mechanics::Structure;
use crate::physics::params::Params;
use crate::physics::rig::RigDrive;
use crate::simulate::simulate_keeping;

static NEVER: AtomicBool = AtomicBool::new(false);

/// A device: parameters, effects, structure, input, span, RK4 step or adaptive method.
#[derive(Clone)]
struct Case {
    p: Params,
    e: Effects,
    s: Structure,
    hyst: bool,
    wave: PiecewiseLinear,
    t_end: f64,
    method: Method,
    every: usize,
    derived_fn: bool,
}

fn paper(s: Structure, e: Effects) -> Case {
    Case {
        p: Params::paper(),
        e,
        s,
        hyst: true,
        wave: PiecewiseLinear::triangle(80.0, 0.5e-3, 9.5e-3, 0.0).unwrap(),
        t_end: 1e-3,
        // a fifth of the paper case's RK4 stability limit (1e-7 s): the comparison is within
        // one discretisation, and these are the longest unit tests
        method: Method::Rk4 { dt: 2e-8 },
        every: 1000,
        derived_fn: false,
    }
}

impl Case {
    fn with(&self, name: &str, v: f64) -> Case {
        let mut c = self.clone();
        if c.p.set(name, v).is_err() {
            c.e.set(name, v).unwrap();
        }
        if c.derived_fn {
            c.p.normal_force = c.p.default_normal_force();
        }
        c
    }

    fn model(&self) -> Model {
        Model::new(self.p, self.e, self.s, self.hyst, false).unwrap()
    }

    /// Readings on the saver's schedule, and the steps and states an adaptive run held.
    fn readings(&self, y0: &[f64]) -> (Vec<f64>, Held) {
        let (r, _) = simulate_keeping(
            &self.model(),
            &self.wave,
            0.0,
            self.t_end,
            y0,
            &self.method,
            self.every,
            true,
            &NEVER,
        )
        .unwrap();
        (r.reading, r.held)
    }

    /// The engine's derivatives of the readings, [time][name].
    fn engine(&self, names: &[&str]) -> Vec<f64> {
        let m = self.model();
        let rest = m.rest_state();
        let (base, held) = self.readings(&rest);
        let names_s: Vec<String> = names.iter().map(|s| s.to_string()).collect();
        let seeds = parse_seeds(&m, &names_s, self.derived_fn).unwrap();
        let schedule = Schedule {
            every: self.every,
            also_last: true,
        };
        let d = derivatives(
            &m,
            &self.wave,
            0.0,
            self.t_end,
            &rest,
            &self.method,
            &held,
            schedule,
            &seeds,
            self.derived_fn,
            &NEVER,
        )
        .unwrap()
        .unwrap();
        assert_eq!(d.readings.len(), base.len() * names.len());
        d.readings
    }

    /// Central differences of the readings with steps `h`, [time][name].
    fn differences(&self, names: &[&str], h: &[f64]) -> Vec<f64> {
        let m = self.model();
        let rest = m.rest_state();
        let names_s: Vec<String> = names.iter().map(|s| s.to_string()).collect();
        let seeds = parse_seeds(&m, &names_s, self.derived_fn).unwrap();
        let n = names.len();
        let mut fd = Vec::new();
        for (j, name) in names.iter().enumerate() {
            let (plus, minus) = match seeds[j] {
                Seed::State(c) => {
                    let (mut yp, mut ym) = (rest.clone(), rest.clone());
                    yp[c] += h[j];
                    ym[c] -= h[j];
                    (self.readings(&yp).0, self.readings(&ym).0)
                }
                _ => {
                    let v = m.params.get(name).or(m.effects.get(name)).unwrap();
                    (
                        self.with(name, v + h[j]).readings(&rest).0,
                        self.with(name, v - h[j]).readings(&rest).0,
                    )
                }
            };
            if fd.is_empty() {
                fd = vec![0.0; plus.len() * n];
            }
            for t in 0..plus.len() {
                fd[t * n + j] = (plus[t] - minus[t]) / (2.0 * h[j]);
            }
        }
        fd
    }

    /// Every name's derivative within `rel` of its central difference, relative to the
    /// largest |derivative| of that name over the run.
    ///
    /// A central difference of a stick-slip run is off in two ways: the run's rounding
    /// noise divided by the step (friction switching amplifies it), and, where a step of
    /// the run straddles a kink of the friction law (v1 = 0 inside a stage), a bias
    /// proportional to the step. So each name is tried at steps h, h/10, h/100 and passes
    /// at the first where the engine agrees within `rel` of the scale plus four times the
    /// differences' own spread (h against 2h). A dropped or wrong term is off by far more.
    fn check(&self, names: &[&str], h: &[f64], rel: f64) {
        let d = self.engine(names);
        let n = names.len();
        let nt = d.len() / n;
        for (j, name) in names.iter().enumerate() {
            let mut verdicts = Vec::new();
            let passed = [1.0, 0.1, 0.01].iter().any(|f| {
                let fd = self.differences(&[name], &[h[j] * f]);
                let fd2 = self.differences(&[name], &[2.0 * h[j] * f]);
                let scale = fd.iter().fold(0.0f64, |a, b| a.max(b.abs()));
                assert!(scale > 0.0, "{name}: the reading does not depend on it");
                let noise = fd.iter().zip(&fd2).map(|(a, b)| (a - b).abs()).fold(0.0, f64::max);
                let worst = (0..nt).map(|t| (d[t * n + j] - fd[t]).abs()).fold(0.0, f64::max);
                verdicts.push(format!(
                    "h x {f}: {:.2e} of the scale (spread {:.2e})",
                    worst / scale,
                    noise / scale
                ));
                noise <= 1e-3 * scale && worst <= rel * scale + 4.0 * noise
            });
            eprintln!("{name}: {}", verdicts.join("; "));
            assert!(
                passed,
                "{name}: engine and central differences disagree: {}",
                verdicts.join("; ")
            );
        }
    }
}

/// `go` on the pass over `names` from `y0` (the case's input, span, method and schedule).
fn with_pass<T>(c: &Case, names: &[&str], y0: &[f64], go: impl FnOnce(&Pass) -> T) -> T {
    let m = c.model();
    let names_s: Vec<String> = names.iter().map(|s| s.to_string()).collect();
    let seeds = parse_seeds(&m, &names_s, c.derived_fn).unwrap();
    let held = Held::default();
    let pass = Pass {
        model: &m,
        wave: &c.wave,
        t_start: 0.0,
        t_end: c.t_end,
        y0,
        method: &c.method,
        held: &held,
        schedule: Schedule {
            every: c.every,
            also_last: true,
        },
        seeds: &seeds,
        normal_force_derived: c.derived_fn,
    };
    go(&pass)
}

/// One pass over `names` on num-dual's 8-wide numbers and on `Tangent<8>`.
fn both_passes(c: &Case, names: &[&str], y0: &[f64]) -> (Result<PassOutput, SimError>, Result<PassOutput, SimError>) {
    let dt = c.method.fixed_step().unwrap();
    with_pass(c, names, y0, |pass| {
        (
            pass.go::<DualSVec64<MAX_PER_PASS>>(&NEVER).unwrap(),
            pass.go_tangent::<MAX_PER_PASS>(dt, &NEVER).unwrap(),
        )
    })
}

/// Equal, a -0.0 for a +0.0 allowed (num-dual's "no derivative" is 0 in a tangent).
fn assert_same(a: &[f64], b: &[f64], what: &str) {
    assert_eq!(a.len(), b.len(), "{what}");
    for (i, (x, y)) in a.iter().zip(b).enumerate() {
        assert!(
            x.to_bits() == y.to_bits() || (*x == 0.0 && *y == 0.0),
            "{what} [{i}]: {x:e} vs {y:e}"
        );
    }
}

/// Every kind of model (both structures, piezo hysteresis, the lags and effects, a derived
/// normal force), each with names of its own, at RK4 steps coarser than the difference tests'
/// (equality needs no accuracy).
fn every_kind_of_model() -> Vec<(Case, Vec<&'static str>)> {
    let lags = Effects {
        kappa: 0.05,
        tau_creep: 2e-4,
        tau_sensor: 5e-6,
        c_weight: 30.0,
        drift_rate: 1e-4,
        ..Effects::default()
    };
    let mut cases = vec![
        (
            paper(Structure::Lps, Effects::default()),
            vec![
                "mu_k",
                "mu_s",
                "m2",
                "fric_alpha",
                "sigma1",
                "d33",
                "hyst_alpha",
                "stribeck_velocity",
            ],
        ),
        (
            paper(Structure::Dps(3), Effects::default()),
            vec![
                "m1",
                "pe_youngs",
                "pe_density",
                "rayleigh_alpha",
                "normal_force",
                "stribeck_exponent",
            ],
        ),
        (
            paper(Structure::Lps, lags),
            vec![
                "kappa",
                "tau_creep",
                "tau_sensor",
                "c_weight",
                "drift_rate",
                "m1",
                "fric_n",
            ],
        ),
    ];
    let mut derived = paper(Structure::Lps, Effects::default());
    derived.derived_fn = true;
    derived.hyst = false;
    cases.push((derived, vec!["m1", "m2", "mu_k"]));
    for (c, _) in cases.iter_mut() {
        c.method = Method::Rk4 { dt: 5e-8 };
        c.every = 400;
    }
    cases
}

#[test]
fn tangent_passes_are_num_duals_bit_for_bit_on_every_kind_of_model() {
    let cases = every_kind_of_model();
    for (c, names) in cases.iter() {
        let rest = c.model().rest_state();
        let (a, b) = both_passes(c, names, &rest);
        let ((ra, fa), (rb, fb)) = (a.unwrap(), b.unwrap());
        assert!(
            ra.iter().any(|x| *x != 0.0),
            "{names:?}: the pass carried no derivative"
        );
        assert_same(&ra, &rb, &format!("readings {names:?}"));
        assert_same(&fa, &fb, &format!("final state {names:?}"));
    }
    // initial-state seeds
    let c = paper(Structure::Lps, Effects::default());
    let mut y0 = c.model().rest_state();
    y0[0] = 1e-7;
    y0[2] = -1e-3;
    let (a, b) = both_passes(&c, &["q0", "v0", "mu_k"], &y0);
    let ((ra, _), (rb, _)) = (a.unwrap(), b.unwrap());
    assert_same(&ra, &rb, "initial-state seeds");
}

/// More names than one pass carries (the Table 1 parameters the diagnosis fits and a state).
const MORE_THAN_ONE_PASS: [&str; 11] = [
    "mu_k",
    "mu_s",
    "m1",
    "m2",
    "fric_alpha",
    "sigma1",
    "sigma2",
    "d33",
    "hyst_alpha",
    "stribeck_velocity",
    "q0",
];

#[test]
fn every_pass_width_gives_each_name_its_scalar_dual_bits() {
    // the passes `derivatives` forms for the first k names (widths 1, 2, 4 and 8; beyond 8
    // names, two passes side by side) against each name alone on num-dual's scalar dual
    // through the generic driver
    let mut cases = every_kind_of_model();
    let (mut many, _) = cases[0].clone();
    many.hyst = true;
    cases.push((many, MORE_THAN_ONE_PASS.to_vec()));
    for (c, names) in cases {
        let rest = c.model().rest_state();
        let alone: Vec<PassOutput> = names
            .iter()
            .map(|name| with_pass(&c, &[name], &rest, |pass| pass.go::<Dual64>(&NEVER).unwrap().unwrap()))
            .collect();
        let from = if names.len() > MAX_PER_PASS {
            MAX_PER_PASS + 1
        } else {
            1
        };
        for k in from..=names.len() {
            let got = c.engine(&names[..k]);
            for (j, (reference, _)) in alone.iter().enumerate().take(k) {
                let column: Vec<f64> = got.iter().skip(j).step_by(k).copied().collect();
                assert_same(&column, reference, &format!("{} of {:?}", names[j], &names[..k]));
            }
        }
    }
}

#[test]
fn a_tangent_pass_that_blows_up_stops_there_with_the_reason() {
    // a step far beyond the friction state's stability limit while sliding: the run stays
    // bounded, its derivatives do not
    let mut c = paper(Structure::Lps, Effects::default());
    c.hyst = false;
    c.method = Method::Rk4 { dt: 2e-7 };
    c.every = 10;
    c.t_end = 5e-3;
    c.wave = PiecewiseLinear::triangle(100.0, 2e-4, 1e-6, 0.0).unwrap();
    let rest = c.model().rest_state();
    let (a, b) = both_passes(&c, &["mu_k", "m1", "sigma1"], &rest);
    let (ea, eb) = (a.unwrap_err().to_string(), b.unwrap_err().to_string());
    let at = |e: &str| {
        e.split("from t = ")
            .nth(1)
            .map(|x| x.split(' ').next().unwrap().to_string())
    };
    assert!(eb.contains("not finite") && eb.contains("smaller dt"), "{eb}");
    assert_eq!(at(&ea), at(&eb), "the same first time: {ea} | {eb}");
    // a one-name pass (num-dual's scalar dual, the generic driver) stops there too
    let m = c.model();
    let seeds = parse_seeds(&m, &["mu_k".to_string()], false).unwrap();
    let (_, held) = c.readings(&rest);
    let schedule = Schedule {
        every: c.every,
        also_last: true,
    };
    let one = derivatives(
        &m, &c.wave, 0.0, c.t_end, &rest, &c.method, &held, schedule, &seeds, false, &NEVER,
    )
    .unwrap();
    let e1 = one.unwrap_err().to_string();
    assert!(e1.contains("not finite"), "{e1}");
    // a pass cancelled from outside is cancelled, not an error
    let cancelled = AtomicBool::new(true);
    assert!(
        derivatives(&m, &c.wave, 0.0, c.t_end, &rest, &c.method, &held, schedule, &seeds, false, &cancelled).is_none()
    );
}

fn rel_step(c: &Case, name: &str) -> f64 {
    1e-6 * c.p.get(name).or(c.e.get(name)).unwrap().abs()
}

#[test]
fn lps_sensitivities_equal_central_differences() {
    let c = paper(Structure::Lps, Effects::default());
    let names = [
        "mu_k",
        "mu_s",
        "m2",
        "fric_alpha",
        "sigma1",
        "sigma2",
        "d33",
        "hyst_alpha",
        "fric_beta",
        "stribeck_velocity",
    ];
    // the reading hardly depends on sigma1 over this run: a larger step keeps its
    // difference above the rounding noise
    let h: Vec<f64> = names
        .iter()
        .map(|n| rel_step(&c, n) * if *n == "sigma1" { 100.0 } else { 1.0 })
        .collect();
    c.check(&names, &h, 1e-6);
}

#[test]
fn exponents_at_their_special_values_are_differentiated_through_the_power() {
    // delta = 2 and n = 1 take shortcuts in the plain run; their derivatives need the power
    let c = paper(Structure::Lps, Effects::default());
    c.check(&["stribeck_exponent", "fric_n"], &[2e-6, 1e-6], 1e-6);
}

#[test]
fn dps_sensitivities_equal_central_differences_including_the_bar() {
    let c = paper(Structure::Dps(4), Effects::default());
    let names = [
        "m1",
        "pe_youngs",
        "pe_density",
        "rayleigh_alpha",
        "rayleigh_beta",
        "normal_force",
        "pe_length",
    ];
    let h: Vec<f64> = names.iter().map(|n| rel_step(&c, n)).collect();
    c.check(&names, &h, 1e-6);
}

#[test]
fn derived_normal_force_follows_the_masses() {
    let mut c = paper(Structure::Lps, Effects::default());
    c.derived_fn = true;
    c.check(&["m1", "m2"], &[1e-7, 1e-7], 1e-6);
    let m = c.model();
    let err = parse_seeds(&m, &["normal_force".into()], true).unwrap_err();
    assert!(err.contains("derived"), "{err}");
}

#[test]
fn initial_state_sensitivities_equal_central_differences() {
    let c = paper(Structure::Lps, Effects::default());
    c.check(&["q0", "v0", "v1"], &[1e-12, 1e-9, 1e-9], 1e-6);
}

#[test]
fn every_effect_parameter_has_its_sensitivity() {
    let e = Effects {
        theta_rad: 0.05,
        k_ground: 2e3,
        tau_amp: 2e-5,
        kappa: 0.05,
        tau_creep: 3e-4,
        c_weight: 1.0,
        eps: 0.05,
        tau_sensor: 1e-5,
        drift_rate: 1e-4,
        // the library at small values (its derivatives are what discovery screens with)
        // each large enough (~1-10 mN along the run) for a central difference to resolve it
        lib_x1: 1e3,
        lib_v1: 0.1,
        lib_dx: 1e3,
        lib_dv: 0.5,
        lib_sgn: 0.01,
        lib_abs: 0.5,
        lib_vv: 200.0,
        lib_volt: 1e-4,
        lib_dvolt: 1e-8,
        lib_t: 0.5,
        lib_x1sq: 1e9,
        lib_x1cube: 1e16,
        lib_sin: 0.01,
        lib_cos: 0.01,
        lib_ff: 0.01,
        lib_ff_sin: 0.02,
        lib_ff_cos: 0.01,
        lib_wavelength: 20e-6,
        libw_x2: 1e4,
        libw_v2: 0.5,
        libw_dx: 1e4,
        libw_dv: 0.5,
        libw_sgn: 0.01,
        libw_vv: 100.0,
        libw_volt: 1e-4,
        libw_dvolt: 1e-8,
    };
    let mut c = paper(Structure::Lps, e);
    // the rise and the first of the fall, slip and sticking: the longest of these tests (CI time)
    c.t_end = 0.6e-3;
    let names = EFFECT_NAMES;
    let h: Vec<f64> = names.iter().map(|n| rel_step(&c, n)).collect();
    c.check(&names, &h, 1e-6);
}

#[test]
fn a_rig_has_its_sensitivities() {
    let mut p = Params::paper();
    p.m1 = 0.5;
    p.normal_force = 4.9;
    let c = Case {
        p,
        e: Effects::default(),
        s: Structure::Rig(RigDrive::Position {
            stiffness: 2e4,
            damping: 5.0,
        }),
        hyst: false,
        wave: PiecewiseLinear::new(vec![0.0, 1.0], vec![0.0, 2e-2]).unwrap(),
        // breakaway at 7.6 ms, then 1.4 ms of sliding; dt half the friction state's stability
        // limit while it slides (1e-7-2e-7 s)
        t_end: 9e-3,
        method: Method::Rk4 { dt: 5e-8 },
        every: 2_000,
        derived_fn: false,
    };
    let names = ["m1", "mu_k", "mu_s", "sigma2", "normal_force"];
    let h: Vec<f64> = names.iter().map(|n| rel_step(&c, n)).collect();
    c.check(&names, &h, 1e-6);
}

#[test]
fn adaptive_runs_are_differentiated_with_their_steps_held() {
    // the derivative of each adaptive run against RK4's (checked against differences
    // above): two discretisations of one derivative, agreeing to their tolerance
    let mut rk4 = paper(Structure::Lps, Effects::default());
    rk4.method = Method::Rk4 { dt: 2e-9 };
    rk4.every = 5_000;
    rk4.t_end = 0.6e-3;
    let names = ["mu_k", "m2", "fric_alpha", "hyst_alpha"];
    let reference = rk4.engine(&names);
    for method in [
        Method::Dopri5 {
            rtol: 1e-9,
            atol: 1e-9,
            first_step: 1e-9,
        },
        Method::Rodas4 {
            rtol: 1e-8,
            atol: 1e-8,
            first_step: 1e-9,
        },
    ] {
        let mut c = rk4.clone();
        c.method = method;
        c.every = 1;
        // the adaptive run saves every step: compare at the end of the run
        let d = c.engine(&names);
        let last = &d[d.len() - names.len()..];
        let r_last = &reference[reference.len() - names.len()..];
        for (j, name) in names.iter().enumerate() {
            let rel = (last[j] - r_last[j]).abs() / r_last[j].abs();
            eprintln!("{method:?} {name}: {rel:.2e} from RK4's");
            assert!(rel < 1e-3, "{method:?} {name}: {} vs RK4 {}", last[j], r_last[j]);
        }
        let m = c.model();
        let (_, held) = c.readings(&m.rest_state());
        assert_eq!(held.steps.len() * m.layout.dim, held.states.len());
    }
}

#[test]
fn more_names_than_one_pass_carries_agree_with_fewer() {
    let c = paper(Structure::Lps, Effects::default());
    let many = MORE_THAN_ONE_PASS;
    let d_many = c.engine(&many);
    let d_one = c.engine(&["hyst_alpha"]);
    let n = many.len();
    for t in 0..d_one.len() {
        assert_eq!(d_many[t * n + 8], d_one[t], "sample {t}");
    }
}

#[test]
fn without_a_stribeck_peak_moving_mu_s_with_mu_k_is_differentiable() {
    // at mu_s = mu_k the readings have a kink in mu_s - mu_k (docs/SENSITIVITIES.md); along
    // mu_s = mu_k they are smooth and the sum of the two derivatives is that direction's
    let mut c = paper(Structure::Lps, Effects::default());
    c.p.mu_s = c.p.mu_k;
    let d = c.engine(&["mu_k", "mu_s"]);
    let shifted = |s: f64| {
        let mut x = c.clone();
        x.p.mu_k += s;
        x.p.mu_s += s;
        x.readings(&x.model().rest_state()).0
    };
    let h = 1e-7;
    let (up, down) = (shifted(h), shifted(-h));
    let fd: Vec<f64> = up.iter().zip(&down).map(|(a, b)| (a - b) / (2.0 * h)).collect();
    let scale = fd.iter().fold(0.0f64, |a, b| a.max(b.abs()));
    let worst = (0..fd.len())
        .map(|t| (d[2 * t] + d[2 * t + 1] - fd[t]).abs())
        .fold(0.0, f64::max);
    eprintln!("tied mu_s = mu_k: {:.2e} of the scale", worst / scale);
    assert!(scale > 0.0 && worst < 1e-5 * scale, "{worst:e} vs scale {scale:e}");
}

#[test]
fn bad_names_are_refused_with_the_reason() {
    let m = paper(Structure::Lps, Effects::default()).model();
    let err =
        |names: &[&str]| parse_seeds(&m, &names.iter().map(|s| s.to_string()).collect::<Vec<_>>(), false).unwrap_err();
    assert!(err(&["wind"]).contains("unknown sensitivity 'wind'"));
    assert!(err(&["mu_k", "mu_k"]).contains("twice"));
    assert!(err(&["tau_amp"]).contains("off"));
    assert!(err(&["kappa"]).contains("off"));
}
