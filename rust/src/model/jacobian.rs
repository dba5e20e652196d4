//! The analytic Jacobian of the model's right-hand side, for implicit (Rosenbrock) integrators:
//! J = df/dy (row-major, dim x dim) and the explicit time derivative df/dt along the step's
//! linear input. Every term mirrors one term of `Model::rhs_impl`; a test checks the whole
//! matrix against the Jacobian derived from the right-hand side itself by dual numbers
//! ([`Model::derived_jacobian`]) for every structure and effect. The hand-written one stays
//! because it costs a fraction of the derived one per Rodas4 step (benches/RESULTS.md).

use num_dual::Dual64;

use crate::model::Model;
use crate::numbers::scalar::{Scalar, Seedable};
use crate::physics::actuation::Actuation;
use crate::physics::effects::{LagInput, AMPLIFIER, CREEP, LAGS};

impl<T: Scalar> Model<T> {
    /// Fill `jac` (dim x dim, row-major) with df/dy and `dfdt` (dim) with df/dt at time `t` [s],
    /// state `y`, commanded voltage `v_cmd` [V] rising at `dv_cmd` [V/s] (constant over the step).
    // Long: the partial derivatives term for term in the order of `rhs_impl`, so each reads
    // against its term (the test compares the whole with the dual-number Jacobian).
    // the damping matrix is indexed (i, j) beside v[i], term for term as in rhs_impl
    #[allow(clippy::needless_range_loop)]
    pub fn jacobian(&self, t: f64, v_cmd: f64, dv_cmd: f64, y: &[T], jac: &mut [T], dfdt: &mut [T]) {
        let l = &self.layout;
        let (n, dim) = (l.dof, l.dim);
        let (ig, ifh, ih) = (l.g, l.fh, l.h);
        jac[..dim * dim].fill(T::zero());
        dfdt[..dim].fill(T::zero());
        let mut set = |r: usize, c: usize, x: T| jac[r * dim + c] += x;
        let (q, v) = (&y[..n], &y[n..2 * n]);

        // PE voltage: commanded, or behind the amplifier lag (dV/dt then depends on the state)
        let amp = l.lags[AMPLIFIER];
        let (v_pe, dv_pe) = match amp {
            Some(i) => (y[i], (-y[i] + v_cmd) * self.inv_tau[AMPLIFIER]),
            None => (T::from(v_cmd), T::from(dv_cmd)),
        };
        // d(v_pe)/dt along the step when v_pe is the command itself
        let vpe_t = if amp.is_some() { 0.0 } else { dv_cmd };
        if let Some(hy) = self.hysteresis {
            let (d_ddv, d_dh) = hy.rate_partials(dv_pe, y[ih]);
            set(ih, ih, d_dh);
            if let Some(i) = amp {
                set(ih, i, -d_ddv * self.inv_tau[AMPLIFIER]);
                dfdt[ih] = d_ddv * dv_cmd * self.inv_tau[AMPLIFIER];
            }
        }
        let kappa_d33 = self.effect_values.kappa * self.d33;
        // every lag effect that is on: y' = (u - y) / tau, by itself and by what it follows
        for (k, lag) in LAGS.iter().enumerate() {
            let Some(i) = l.lags[k] else { continue };
            let inv = self.inv_tau[k];
            set(i, i, -inv);
            match (lag.follows, amp) {
                (LagInput::Command, _) => dfdt[i] = inv * dv_cmd,
                (LagInput::CreepTarget, Some(j)) => set(i, j, kappa_d33 * inv),
                (LagInput::CreepTarget, None) => dfdt[i] = kappa_d33 * vpe_t * inv,
                (LagInput::Position, _) => set(i, 0, inv),
            }
        }

        // piezo force fp = kp (d33 v_pe + xc - h): its partials [N per unit] and rate [N/s]
        let xc = l.lags[CREEP].map_or(T::zero(), |i| y[i]);
        let fp = crate::physics::piezo::piezo_force(self.kp, self.d33, v_pe, xc, y[ih]);
        let fp_d = [
            Some((ih, -self.kp)),
            l.lags[CREEP].map(|i| (i, self.kp)),
            amp.map(|i| (i, self.kp * self.d33)),
        ];
        let fp_d = fp_d.iter().flatten();
        let fp_t = self.kp * self.d33 * vpe_t;

        // friction: g, Fh and Ff = Fh + sigma2 v1 + sigma1 dg/dt
        let [gdot, _, dg_dv, dg_dfh, dfh_dv, dfh_dfh] = self.friction.rate_partials(v[0], y[ifh]);
        let (s1, s2) = (self.values.sigma1, self.values.sigma2);
        set(ig, n, dg_dv);
        set(ig, ifh, dg_dfh);
        set(ifh, n, dfh_dv);
        set(ifh, ifh, dfh_dfh);
        let ff = self.friction.force(v[0], y[ifh], gdot);
        let ff_d = [(n, s2 + s1 * dg_dv), (ifh, s1 * dg_dfh + 1.0)];

        // external forces: spring to ground on the main body, drag on the weight
        let (kg, cw) = (self.effect_values.k_ground, self.effect_values.c_weight);
        let last = n + n - 1;

        // forces only some runs have (the sampled force, the library forces): their values on
        // the main body and the weight, their partials by state component, their rates
        let mut extra_f = (T::zero(), T::zero());
        let mut extra_d: Vec<(usize, T, T)> = Vec::new();
        let mut extra_t = (T::zero(), T::zero());
        if let Some(x) = &self.external {
            let (f, slope) = x.at(t);
            match x.body {
                crate::physics::external_force::Body::Main => (extra_f.0, extra_t.0) = (f, slope),
                crate::physics::external_force::Body::Weight => (extra_f.1, extra_t.1) = (f, slope),
            }
        }
        if self.library.0 || self.library.1 {
            let st = self.library_states(t, q, v, v_pe, dv_pe, ff);
            let zero = (T::zero(), [T::zero(); 8]);
            let (fm, dm) = if self.library.0 {
                self.effect_values.library_force_main(&st)
            } else {
                zero
            };
            let (fw, dw) = if self.library.1 {
                self.effect_values.library_force_weight(&st)
            } else {
                zero
            };
            extra_f = (extra_f.0 + fm, extra_f.1 + fw);
            // [x1, v1, x2, v2, volt, dvolt, ff, t] -> state components and df/dt
            for (c, k) in [(0, 0), (n, 1), (n - 1, 2), (last, 3)] {
                extra_d.push((c, dm[k], dw[k]));
            }
            for &(c, d) in &ff_d {
                extra_d.push((c, dm[6] * d, dw[6] * d));
            }
            extra_t = (extra_t.0 + dm[7], extra_t.1 + dw[7]);
            match amp {
                Some(i) => {
                    let inv = self.inv_tau[AMPLIFIER];
                    extra_d.push((i, dm[4] - dm[5] * inv, dw[4] - dw[5] * inv));
                    extra_t = (extra_t.0 + dm[5] * inv * dv_cmd, extra_t.1 + dw[5] * inv * dv_cmd);
                }
                None => extra_t = (extra_t.0 + dm[4] * vpe_t, extra_t.1 + dw[4] * vpe_t),
            }
        }

        // mechanics: dv/dt = -M^-1 K q - M^-1 C v + m0 F_main + ml F_weight
        let mech = &self.mech;
        let [dm_dfp, dl_dfp, dm_du, dm_dx, dm_dv] = self.actuator.force_partials(v_pe, q[0], v[0]);
        for i in 0..n {
            set(i, n + i, T::one());
        }
        for i in 0..n {
            let r = n + i;
            for j in 0..n {
                set(r, j, -mech.minv_k[i * n + j]);
                set(r, n + j, -mech.minv_c[i * n + j]);
            }
            let (m0, ml) = (mech.minv_main[i], mech.minv_weight[i]);
            for &(c, d) in &ff_d {
                set(r, c, -m0 * d);
            }
            set(r, 0, -m0 * kg);
            set(r, last, -ml * cw);
            // the actuation: through the piezo force, and through the input and the main body
            let via_fp = m0 * dm_dfp + ml * dl_dfp;
            for &(c, d) in fp_d.clone() {
                set(r, c, via_fp * d);
            }
            set(r, 0, m0 * dm_dx);
            set(r, n, m0 * dm_dv);
            dfdt[r] = via_fp * fp_t + m0 * dm_du * dv_cmd + m0 * extra_t.0 + ml * extra_t.1;
            for &(c, dfm, dfw) in &extra_d {
                set(r, c, m0 * dfm + ml * dfw);
            }
        }

        if let Some(a) = l.accounting {
            // work of the actuation
            let (f_main, _) = self.actuator.forces(fp, v_pe, dv_pe, q[0], v[0]);
            let [dp_df, dp_dvm, dp_dvl] = self.actuator.power_partials(f_main, v[0], v[n - 1]);
            for &(c, d) in fp_d.clone() {
                set(a, c, dp_df * dm_dfp * d);
            }
            set(a, n, dp_dvm);
            set(a, n, dp_df * dm_dv);
            set(a, last, dp_dvl);
            set(a, 0, dp_df * dm_dx);
            dfdt[a] = dp_df * (fp_t * dm_dfp + dm_du * dv_cmd);
            // work of friction ff v1, and friction's impulse
            for &(c, d) in &ff_d {
                set(a + 1, c, d * v[0]);
                set(a + 4, c, d);
            }
            set(a + 1, n, ff);
            // damping's dissipation v'Cv
            for j in 0..n {
                let mut s = T::zero();
                for i in 0..n {
                    s += (mech.damping[(i, j)] + mech.damping[(j, i)]) * v[i];
                }
                set(a + 2, n + j, s);
            }
            // external work and impulse
            let f_main = self.f_constant - kg * q[0] + extra_f.0;
            set(a + 3, 0, -kg * v[0]);
            set(a + 3, n, f_main);
            set(a + 3, last, -(cw * 2.0) * v[n - 1] + extra_f.1);
            for &(c, dfm, dfw) in &extra_d {
                set(a + 3, c, dfm * v[0] + dfw * v[n - 1]);
                set(a + 6, c, dfm + dfw);
            }
            dfdt[a + 3] = extra_t.0 * v[0] + extra_t.1 * v[n - 1];
            dfdt[a + 6] = extra_t.0 + extra_t.1;
            for j in 0..n {
                set(a + 5, n + j, self.values.rayleigh_alpha * self.pe_mass_sums[j]);
            }
            set(a + 6, 0, -kg);
            set(a + 6, last, -cw);
        }
    }
}

impl Model {
    /// This model with its values as one-component dual numbers (no parameter seeded): the
    /// model [`Model::derived_jacobian`] differentiates.
    pub fn dual(&self) -> Model<Dual64> {
        Model::build(
            self.params,
            self.effects,
            self.structure,
            self.hysteresis.is_some(),
            self.layout.accounting.is_some(),
            |_, v| Dual64::from(v),
            false,
        )
        .map(|mut m| {
            m.external = self.external.as_ref().map(|x| x.lift(|_, v| Dual64::from(v)));
            m
        })
        .expect("a model that was built once builds again")
    }
}

impl Model<Dual64> {
    /// df/dy and df/dt (as [`Model::jacobian`]) derived from the right-hand side itself by
    /// forward-mode dual numbers: one pass per state component, seeded in that component, and
    /// one seeded in the commanded voltage (df/dt = df/dV dV/dt along the step's linear input).
    /// No hand-derived term: the reference the analytic Jacobian is tested against, and the
    /// Jacobian an implicit method could use for any new term (at `dim + 1` evaluations of the
    /// right-hand side on dual numbers; see benches/RESULTS.md for its cost).
    /// The explicit time dependence (a sampled force, the library's time term) is taken by a
    /// central difference in `t` over 100 us: the one term not carried by a dual number.
    pub fn derived_jacobian(&self, t: f64, v_cmd: f64, dv_cmd: f64, y: &[f64], jac: &mut [f64], dfdt: &mut [f64]) {
        let d = y.len();
        let mut yd: Vec<Dual64> = y.iter().map(|&x| Dual64::from(x)).collect();
        let mut f = vec![Dual64::from(0.0); d];
        let mut col = [0.0];
        let v = Dual64::from(v_cmd);
        for c in 0..d {
            yd[c] = Dual64::seed(y[c], 0);
            self.rhs_impl::<0, true>(t, v, dv_cmd, &yd, &mut f);
            for r in 0..d {
                f[r].derivatives(&mut col);
                jac[r * d + c] = col[0];
            }
            yd[c] = Dual64::from(y[c]);
        }
        self.rhs_impl::<0, true>(t, Dual64::seed(v_cmd, 0), dv_cmd, &yd, &mut f);
        for r in 0..d {
            f[r].derivatives(&mut col);
            dfdt[r] = col[0] * dv_cmd;
        }
        // the explicit time dependence is linear within a piece of the sampled force (and in the
        // library's t), so the central difference is exact up to rounding; 100 us keeps that
        // rounding below 1e-13 of an acceleration's rate (a knot within 100 us of t mixes the
        // slopes of its two pieces: the reference is for times inside a longer piece)
        let h = 1e-4;
        let (mut fp, mut fm) = (f.clone(), f.clone());
        self.rhs_impl::<0, true>(t + h, v, dv_cmd, &yd, &mut fp);
        self.rhs_impl::<0, true>(t - h, v, dv_cmd, &yd, &mut fm);
        for r in 0..d {
            dfdt[r] += (fp[r].re - fm[r].re) / (2.0 * h);
        }
    }
}

#[cfg(test)]
mod tests {
    use crate::model::Model;
    use crate::physics::effects::{Effects, EFFECT_PARAMS};
    use crate::physics::external_force::{Body, ExternalForce};
    use crate::physics::mechanics::Structure;
    use crate::physics::params::Params;
    use crate::physics::rig::RigDrive;

    /// The time the Jacobians are compared at [s] (between two samples of the test's force).
    const T_CHECK: f64 = 1.3e-3;

    fn check(m: &Model, y: &[f64], v: f64, dv: f64) {
        let d = y.len();
        let (mut jac, mut ft) = (vec![0.0; d * d], vec![0.0; d]);
        m.jacobian(T_CHECK, v, dv, y, &mut jac, &mut ft);
        let (mut nj, mut nt) = (vec![0.0; d * d], vec![0.0; d]);
        m.dual().derived_jacobian(T_CHECK, v, dv, y, &mut nj, &mut nt);
        let names = m.layout.components();
        for r in 0..d {
            // each row compared at the scale of its largest entry times the column's magnitude
            let row_scale = (0..d)
                .map(|c| (nj[r * d + c] * y[c].abs().max(1e-12)).abs())
                .fold(0.0f64, f64::max)
                .max(1e-300);
            for c in 0..d {
                let err = (jac[r * d + c] - nj[r * d + c]).abs() * y[c].abs().max(1e-12);
                assert!(
                    err <= 1e-12 * row_scale,
                    "d f[{}] / d {}: analytic {:e}, derived {:e}",
                    names[r].0,
                    names[c].0,
                    jac[r * d + c],
                    nj[r * d + c]
                );
            }
            assert!(
                (ft[r] - nt[r]).abs() <= 1e-12 * nt[r].abs() + 1e-12 * row_scale,
                "d f[{}] / dt: analytic {:e}, derived {:e}",
                names[r].0,
                ft[r],
                nt[r]
            );
        }
    }

    /// A state away from every kink (v1, g-rate, Fh, h all non-zero), with every component set.
    fn state(m: &Model) -> Vec<f64> {
        let d = m.layout.dim;
        (0..d)
            .map(|i| {
                let x = 1.0 + 0.37 * i as f64;
                let l = &m.layout;
                if i < l.dof {
                    1e-6 * x
                } else if i < 2 * l.dof {
                    2e-3 * x * if i % 2 == 0 { 1.0 } else { -0.7 }
                } else if i == l.fh {
                    0.21 * m.presliding_bound()
                } else if Some(i) == m.layout.lags[crate::physics::effects::AMPLIFIER] {
                    47.0
                } else {
                    3e-7 * x
                }
            })
            .collect()
    }

    // Long: every catalogue effect on at once and each state's partials compared, one table
    #[test]
    fn analytic_jacobian_equals_the_one_derived_from_the_right_hand_side() {
        let p = Params::paper();
        // every catalogue effect on at once, from the declarations: a new effect parameter stops
        // this test until it has a value here (so its partials are compared)
        let mut all = Effects::default();
        for d in EFFECT_PARAMS.iter().filter(|d| !d.name.starts_with("lib")) {
            let value = match d.name {
                "tau_amp" => 2e-5,
                "kappa" => 0.05,
                "tau_creep" => 3e-3,
                "tau_sensor" => 4e-5,
                "k_ground" => 2e3,
                "c_weight" => 0.3,
                "eps" => 0.07,
                "theta_rad" => 0.1,
                "drift_rate" => 1e-6,
                other => panic!("give effect parameter '{other}' a value in this test"),
            };
            all.set(d.name, value).unwrap();
        }
        // every library term on at once, on the main body and on the weight
        let library = Effects {
            lib_x1: 3e3,
            lib_v1: 0.2,
            lib_dx: -1e3,
            lib_dv: 0.1,
            lib_sgn: 0.05,
            lib_abs: 0.3,
            lib_vv: 20.0,
            lib_volt: 1e-3,
            lib_dvolt: 2e-7,
            lib_t: 5.0,
            lib_x1sq: 1e8,
            lib_x1cube: 1e13,
            lib_sin: 0.02,
            lib_cos: -0.01,
            lib_ff: 0.03,
            lib_ff_sin: 0.05,
            lib_ff_cos: 0.02,
            lib_wavelength: 12e-6,
            libw_x2: 2e3,
            libw_v2: 0.1,
            libw_dx: 500.0,
            libw_dv: 0.05,
            libw_sgn: 0.01,
            libw_vv: 5.0,
            libw_volt: 1e-3,
            libw_dvolt: 1e-7,
            ..Effects::default()
        };
        let mut odd = p;
        odd.fric_n = 1.6;
        odd.stribeck_exponent = 1.3;
        for (params, effects, structure, hyst, acc) in [
            (p, Effects::default(), Structure::Lps, true, false),
            (p, Effects::default(), Structure::Dps(4), true, false),
            (p, all, Structure::Lps, true, true),
            (odd, all, Structure::Dps(3), true, true),
            (
                p,
                Effects {
                    k_ground: 1e3,
                    eps: 0.05,
                    tau_sensor: 1e-4,
                    ..Effects::default()
                },
                Structure::Rig(RigDrive::Position {
                    stiffness: 5e4,
                    damping: 2.0,
                }),
                false,
                true,
            ),
            (
                p,
                Effects {
                    eps: 0.05,
                    ..Effects::default()
                },
                Structure::Rig(RigDrive::ClosedLoop {
                    kp: 160.0,
                    kv: 240.0,
                    gain: 35.0,
                    limit: 1e3,
                }),
                false,
                true,
            ),
            (
                p,
                Effects {
                    eps: 0.05,
                    ..Effects::default()
                },
                Structure::Rig(RigDrive::Force),
                false,
                true,
            ),
            (p, library, Structure::Lps, true, true),
            (
                p,
                Effects {
                    tau_amp: 2e-5,
                    ..library
                },
                Structure::Dps(3),
                true,
                true,
            ),
            (
                p,
                Effects {
                    lib_wavelength: 0.0,
                    ..library
                },
                Structure::Lps,
                false,
                false,
            ),
        ] {
            let mut m = Model::new(params, effects, structure, hyst, acc).unwrap();
            if effects.library_on().0 {
                // with a sampled force on the weight (main-body forces are the library's)
                let f = ExternalForce::new(Body::Weight, vec![0.0, 1e-3, 2e-3], vec![0.0, 0.4, -0.3]).unwrap();
                m = m.with_external_force(f).unwrap();
            }
            let y = state(&m);
            // the same state with the hysteresis state, the presliding force and the main body's
            // velocity on the other side of their kinks (h < 0: the |h| branch of dh/dt)
            let mut flipped = y.clone();
            flipped[m.layout.h] = -y[m.layout.h];
            flipped[m.layout.fh] = -y[m.layout.fh];
            flipped[m.layout.dof] = -y[m.layout.dof];
            // the rig's input is a position [m] or a force [N]; the IDM's a voltage [V]
            let inputs = match structure {
                Structure::Rig(RigDrive::Force) => [(0.4, 30.0), (-0.25, -12.0)],
                Structure::Rig(_) => [(2e-6, 1e-3), (-3e-6, -4e-4)],
                _ => [(40.0, 1.6e5), (75.0, -8.4e3)],
            };
            for (v, dv) in inputs {
                check(&m, &y, v, dv);
                check(&m, &flipped, v, dv);
            }
        }
    }
}
