//! Throughput of the lane groups (`lanes/rk4.rs`): scalar (SSE2), AVX2 and AVX-512 code, the C
//! library's exp vs the polynomial, 8 to 32 lanes, and the right-hand side alone. 64 LPS / DPS4 paper-case points (m2 and V varied), 2 ms of the
//! paper's triangle, RK4 at dt = 5e-8 s, one thread. `cargo bench --bench lanes_cost`.

use std::sync::atomic::AtomicBool;
use std::time::Instant;

use idm_rs::drive::run_tasks_exp;
use idm_rs::integrate::method::Method;
use idm_rs::integrate::task::{Observer, Task};
use idm_rs::lanes::{set_simd_level, LaneExp, LibmExp, PolyExp};
use idm_rs::model::Model;
use idm_rs::physics::effects::Effects;
use idm_rs::physics::mechanics::Structure;
use idm_rs::physics::params::Params;
use idm_rs::physics::waveform::PiecewiseLinear;

struct Nothing;
impl Observer for Nothing {
    fn start(&mut self, _: usize, _: f64, _: &[f64]) {}
    fn step(&mut self, _: usize, _: f64, _: f64, _: &[f64], _: f64, _: Option<(f64, f64)>, _: bool) {}
}

fn time<E: LaneExp, const L: usize>(tasks: &[Task], method: &Method) -> (f64, Vec<f64>) {
    let cancel = AtomicBool::new(false);
    let mut best = f64::INFINITY;
    let mut x = Vec::new();
    for _ in 0..3 {
        let t = Instant::now();
        let ends = run_tasks_exp::<_, E, L>(tasks, method, &mut Nothing, &cancel).unwrap();
        best = best.min(t.elapsed().as_secs_f64());
        x = ends.into_iter().map(|(_, y)| y[0]).collect();
    }
    (best, x)
}

/// The right-hand side alone: 8 lanes of the scalar model one by one vs the vector lanes.
fn rhs_only(models: &[Model]) {
    use idm_rs::integrate::model_rhs::{LaneInputs, ModelRhs};
    use idm_rs::integrate::stepper::Rhs;
    use idm_rs::lanes::LanesRhs;
    const D: usize = 7;
    let wave = PiecewiseLinear::triangle(80.0, 0.5e-3, 9.5e-3, 0.0).unwrap();
    let y0 = models[0].rest_state();
    let tasks: Vec<Task> = models[..8]
        .iter()
        .map(|m| Task {
            model: m,
            wave: &wave,
            t_start: 0.0,
            t_end: 1e-3,
            y0: &y0,
        })
        .collect();
    let mut ys = [[0.0; D]; 8];
    for (i, y) in ys.iter_mut().enumerate() {
        y[0] = 1e-9 * i as f64;
        y[2] = 1e-4;
        y[5] = 0.1;
    }
    let mut dys = [[0.0; D]; 8];
    let active = [true; 8];
    let n = 2_000_000;
    struct Op<'r, 'a> {
        r: &'r mut LanesRhs<'a, PolyExp, 2, 7, 8>,
        ys: &'r mut [[f64; D]; 8],
        dys: &'r mut [[f64; D]; 8],
        n: usize,
        vector: bool,
    }
    impl pulp::WithSimd for Op<'_, '_> {
        type Output = f64;
        #[inline(always)]
        fn with_simd<S: pulp::Simd>(self, _s: S) -> f64 {
            let t = Instant::now();
            for k in 0..self.n {
                self.ys[k % 8][2] = k as f64 * 1e-12;
                self.ys[(k + 3) % 8][5] = 0.01 * (k % 7) as f64;
                if self.vector {
                    self.r.eval_lanes(&[0.0; 8], self.ys, self.dys, &[true; 8]);
                } else {
                    for i in 0..8 {
                        self.r.inner.eval(i, 0.0, &self.ys[i], &mut self.dys[i]);
                    }
                }
            }
            t.elapsed().as_secs_f64()
        }
    }
    let mut r = LanesRhs::<PolyExp, 2, 7, 8>::new(ModelRhs::for_tasks(&tasks, 0.0));
    for i in 0..8 {
        r.set_input(i, 0.0, 10.0, 1e5);
    }
    let _ = active;
    {
        use idm_rs::lanes::PlainLanes;
        struct Soa<'r> {
            p: &'r PlainLanes<2, 8, PolyExp>,
            y: [[f64; 8]; D],
            n: usize,
        }
        impl pulp::WithSimd for Soa<'_> {
            type Output = (f64, f64);
            #[inline(always)]
            fn with_simd<S: pulp::Simd>(mut self, _s: S) -> (f64, f64) {
                let mut dy = [[0.0; 8]; D];
                let (t0, v, dv) = ([0.0; 8], [10.0; 8], [1e5; 8]);
                let t = Instant::now();
                let mut acc = 0.0;
                for k in 0..self.n {
                    self.y[2][k % 8] = k as f64 * 1e-12;
                    self.y[5][(k + 3) % 8] = 0.01 * (k % 7) as f64;
                    self.p.rhs_soa::<D, false>(&t0, &v, &dv, &self.y, &mut dy);
                    acc += dy[3][0];
                }
                (t.elapsed().as_secs_f64(), acc)
            }
        }
        let group: [&Model; 8] = std::array::from_fn(|i| &models[i]);
        let p = PlainLanes::<2, 8, PolyExp>::new(&group).unwrap();
        let y: [[f64; 8]; D] = std::array::from_fn(|j| std::array::from_fn(|i| ys[i][j]));
        let (t, _) = pulp::Arch::new().dispatch(Soa { p: &p, y, n });
        println!(
            "  rhs only, {:26} {:6.2} ns per lane-evaluation",
            "SoA vector lanes (poly)",
            t / (8 * n) as f64 * 1e9
        );
    }
    for (label, vector) in [("scalar model x 8", false), ("vector lanes (poly exp)", true)] {
        let t = pulp::Arch::new().dispatch(Op {
            r: &mut r,
            ys: &mut ys,
            dys: &mut dys,
            n,
            vector,
        });
        println!(
            "  rhs only, {label:26} {:6.2} ns per lane-evaluation",
            t / (8 * n) as f64 * 1e9
        );
    }
}

fn main() {
    let wave = PiecewiseLinear::triangle(80.0, 0.5e-3, 9.5e-3, 0.0).unwrap();
    let method = Method::Rk4 { dt: 5e-8 };
    for structure in [Structure::Lps, Structure::Dps(4)] {
        let models: Vec<Model> = (0..64)
            .map(|k| {
                let mut p = Params::paper();
                p.m2 *= 0.5 + k as f64 / 40.0;
                p.normal_force = p.default_normal_force();
                Model::new(p, Effects::default(), structure, false, false).unwrap()
            })
            .collect();
        let y0: Vec<Vec<f64>> = models.iter().map(|m| m.rest_state()).collect();
        let tasks: Vec<Task> = models
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
        let steps = 64.0 * 2e-3 / 5e-8;
        if std::env::var("LANES_PROFILE").is_ok() {
            // one configuration, long enough to profile
            for _ in 0..5 {
                time::<PolyExp, 32>(&tasks, &method);
            }
            return;
        }
        if structure == Structure::Lps {
            rhs_only(&models);
        }
        println!("{structure:?}: 64 points x 40,000 RK4 steps, one thread; ratios against the first row");
        set_simd_level("scalar");
        let (base, xr) = time::<LibmExp, 8>(&tasks, &method);
        let mut rows = vec![("scalar (SSE2) code, libm exp, 8 lanes".to_string(), base)];
        let mut xp = Vec::new();
        for level in ["avx2", "avx512"] {
            set_simd_level(level);
            let (t, x) = time::<LibmExp, 8>(&tasks, &method);
            assert_eq!(x, xr, "{level} lanes differ from scalar ones");
            rows.push((format!("{level} code, libm exp, 8 lanes"), t));
            let (t, _) = time::<LibmExp, 16>(&tasks, &method);
            rows.push((format!("{level} code, libm exp, 16 lanes"), t));
            let (t, x) = time::<PolyExp, 8>(&tasks, &method);
            xp = x;
            rows.push((format!("{level} code, poly exp, 8 lanes"), t));
            let (t, _) = time::<PolyExp, 32>(&tasks, &method);
            rows.push((format!("{level} code, poly exp, 32 lanes"), t));
        }
        set_simd_level("avx2");
        for (label, t) in rows {
            println!("  {label:36} {:7.1} ns/step  {:5.2}x", t / steps * 1e9, base / t);
        }
        let err = xr.iter().zip(&xp).map(|(a, b)| (a - b).abs()).fold(0.0, f64::max);
        println!("  poly exp: max |dx1| against libm exp {err:.1e} m");
        // dopri5 (per-lane steps; stages through the vector right-hand side, lane-major state)
        let adaptive = Method::Dopri5 {
            rtol: 3e-7,
            atol: 3e-7,
            first_step: 1e-8,
        };
        set_simd_level("scalar");
        let (base_d, xd) = time::<LibmExp, 8>(&tasks, &adaptive);
        for level in ["avx2", "avx512"] {
            set_simd_level(level);
            let (t, x) = time::<LibmExp, 8>(&tasks, &adaptive);
            assert_eq!(x, xd);
            let (tp, _) = time::<PolyExp, 8>(&tasks, &adaptive);
            println!(
                "  dopri5 3e-7, 8 lanes: {level} libm exp {:5.2}x, poly exp {:5.2}x against scalar code ({:.1} ms)",
                base_d / t,
                base_d / tp,
                base_d * 1e3
            );
        }
        set_simd_level("avx2");
    }
}
