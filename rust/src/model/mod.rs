//! The IDM as one first-order system: structure + piezo force + friction + optional effects.
//! Owns the state layout and the right-hand side; the integrator and the driver are elsewhere.

pub mod jacobian;
mod layout;

pub use layout::{Layout, N_ACCOUNTING};

use nalgebra::ComplexField;

use crate::error::InputError;
use crate::numbers::lane_real::Lanewise;
use crate::numbers::real::Real;
use crate::numbers::scalar::Scalar;
use crate::physics::actuation::Actuation;
use crate::physics::effects::{
    first_order_rate, ground_spring_force, weight_drag, Effects, LagInput, LagScale, LibraryStates, AMPLIFIER, CREEP,
    LAGS, N_LAGS, SENSOR,
};
use crate::physics::external_force::{Body, ExternalForce};
use crate::physics::friction::Leuven;
use crate::physics::mechanics::{Actuator, Mechanics, Structure};
use crate::physics::params::Params;
use crate::physics::piezo::{piezo_force, PiezoHysteresis};

/// Dispatch on the state size: `$fixed!(N, D, EXTRAS)` for a state of a common node count N
/// that the fixed-size paths hold (see [`Model::lane_lags`]: `$lags` is `Some(k)` with k lag
/// states, D = 2N + 3 + k components, EXTRAS whether k > 0), `$dynamic` otherwise. The fixed
/// sizes let the compiler keep a step's state in registers (and put the runs on the vector
/// lanes); the physics is the same code either way. Every size is compiled once per
/// instruction set and costs build time: a plain state for 1-6 nodes (the rig, the LPS, the
/// DPS up to n = 5), and one lag state for the LPS and the DPS with n = 4 (2 and 5 nodes) — the
/// structures of the diagnosis, whose lag-effect candidates (amplifier, creep, sensor) each add
/// one state.
macro_rules! with_state_size {
    ($lags:expr, $dof:expr, $fixed:ident, $dynamic:expr) => {
        match ($lags, $dof) {
            (Some(0), 1) => $fixed!(1, 5, false),
            (Some(0), 2) => $fixed!(2, 7, false),
            (Some(0), 3) => $fixed!(3, 9, false),
            (Some(0), 4) => $fixed!(4, 11, false),
            (Some(0), 5) => $fixed!(5, 13, false),
            (Some(0), 6) => $fixed!(6, 15, false),
            (Some(1), 2) => $fixed!(2, 8, true),
            (Some(1), 5) => $fixed!(5, 14, true),
            _ => $dynamic,
        }
    };
}
pub(crate) use with_state_size;

/// Everything the right-hand side needs, precomputed once. `T` is the number the physics runs
/// on: `f64` for plain runs, a dual number when derivatives with respect to parameters are
/// asked for (see [`Model::build`]); `params` and `effects` keep the plain values either way.
#[derive(Clone, Debug)]
pub struct Model<T: Real = f64> {
    pub params: Params,
    pub effects: Effects,
    pub structure: Structure,
    pub mech: Mechanics<T>,
    pub friction: Leuven<T>,
    pub layout: Layout,
    /// Table 1 and the effect parameters as the physics reads them (as `T`)
    pub(crate) values: Params<T>,
    pub(crate) effect_values: Effects<T>,
    pub(crate) hysteresis: Option<PiezoHysteresis<T>>,
    /// how the input acts on the bodies (the piezo element, or a rig's drive)
    pub(crate) actuator: Actuator,
    pub(crate) kp: T,
    pub(crate) d33: T,
    /// constant external force on the main body (incline + load) [N]
    pub(crate) f_constant: T,
    /// 1 / tau of each lag (`effects::LAGS`; 0 where off) [1/s]
    pub(crate) inv_tau: [T; N_LAGS],
    pub(crate) pe_mass_sums: Vec<T>,
    /// a sampled external force on a body (`Model::with_external_force`), or none
    pub external: Option<ExternalForce<T>>,
    /// whether the library force on the main body, and on the weight, is on
    pub(crate) library: (bool, bool),
}

/// What a state component's error scale is (see [`Model::state_scales`]): out of the norm, the
/// free stroke (positions, h, a creep or sensor lag), the stroke times the LPS frequency
/// (velocities), the static friction (Fh), or the voltage amplitude (the amplifier lag).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ScaleKind {
    Excluded,
    Stroke,
    Velocity,
    Force,
    Voltage,
}

/// What every lane of one group must share: all that is not a number (the structure, the state
/// layout, the mechanism, which parts of the physics are on, the external force's body and knot
/// times). Models of one shape differ only in values, so one [`Model`] over lanes holds them.
#[derive(Clone, Debug, PartialEq)]
pub struct Shape {
    structure: Structure,
    layout: Layout,
    actuator: Actuator,
    hysteresis: bool,
    library: (bool, bool),
    external: Option<(Body, Vec<f64>)>,
}

impl<T: Real> Model<T> {
    /// This model's [`Shape`].
    pub fn shape(&self) -> Shape {
        Shape {
            structure: self.structure,
            layout: self.layout,
            actuator: self.actuator,
            hysteresis: self.hysteresis.is_some(),
            library: self.library,
            external: self.external.as_ref().map(|x| (x.body, x.knots.times().to_vec())),
        }
    }
}

/// `L` models of one [`Shape`] as one model over lanes (the plain values, `params` and
/// `effects`, are lane 0's).
impl<S: Real + nalgebra::Scalar, T: Real + nalgebra::Scalar + Lanewise<S>> Lanewise<Model<S>> for Model<T>
where
    T::Mask: Lanewise<S::Mask>,
{
    fn splat(m: &Model<S>) -> Self {
        Model {
            params: m.params,
            effects: m.effects,
            structure: m.structure,
            mech: Lanewise::splat(&m.mech),
            friction: Lanewise::splat(&m.friction),
            layout: m.layout,
            values: Lanewise::splat(&m.values),
            effect_values: Lanewise::splat(&m.effect_values),
            hysteresis: Lanewise::splat(&m.hysteresis),
            actuator: m.actuator,
            kp: Lanewise::splat(&m.kp),
            d33: Lanewise::splat(&m.d33),
            f_constant: Lanewise::splat(&m.f_constant),
            inv_tau: Lanewise::splat(&m.inv_tau),
            pe_mass_sums: Lanewise::splat(&m.pe_mass_sums),
            external: Lanewise::splat(&m.external),
            library: m.library,
        }
    }

    fn set_lane(&mut self, i: usize, m: &Model<S>) {
        debug_assert!(self.shape() == m.shape(), "lanes of one shape");
        self.mech.set_lane(i, &m.mech);
        self.friction.set_lane(i, &m.friction);
        self.values.set_lane(i, &m.values);
        self.effect_values.set_lane(i, &m.effect_values);
        self.hysteresis.set_lane(i, &m.hysteresis);
        self.kp.set_lane(i, &m.kp);
        self.d33.set_lane(i, &m.d33);
        self.f_constant.set_lane(i, &m.f_constant);
        self.inv_tau.set_lane(i, &m.inv_tau);
        self.pe_mass_sums.set_lane(i, &m.pe_mass_sums);
        self.external.set_lane(i, &m.external);
    }
}

impl Model {
    pub fn new(
        params: Params,
        effects: Effects,
        structure: Structure,
        piezo_hysteresis: bool,
        accounting: bool,
    ) -> Result<Self, InputError> {
        Model::build(
            params,
            effects,
            structure,
            piezo_hysteresis,
            accounting,
            |_, x| x,
            false,
        )
    }
}

impl<T: Scalar + ComplexField> Model<T> {
    /// The model with every parameter read as `lift(name, value)` (Table 1 and effect names):
    /// a dual number seeded for the parameters whose derivatives are asked for. With
    /// `derived_normal_force` the normal force is (m1 + m2 + mPE) g of the lifted masses, so
    /// its derivative follows theirs.
    pub fn build(
        params: Params,
        effects: Effects,
        structure: Structure,
        piezo_hysteresis: bool,
        accounting: bool,
        lift: impl Fn(&str, f64) -> T,
        derived_normal_force: bool,
    ) -> Result<Self, InputError> {
        params.validate()?;
        effects.validate()?;
        let mut p = params.lift(&lift);
        if derived_normal_force {
            p.normal_force = p.default_normal_force();
        }
        let e = effects.lift(&lift);
        let mech = Mechanics::new(&p, structure)?;
        let layout = Layout::new(mech.dof, &effects, accounting);
        let inv = |tau: T| if tau.value() > 0.0 { T::one() / tau } else { T::zero() };
        let actuator = structure.actuator();
        actuator.check(&effects, piezo_hysteresis)?;
        let total_mass = actuator.supported_mass(&p);
        Ok(Model {
            friction: Leuven::new(&p, p.normal_force * e.normal_scale(), e.eps),
            hysteresis: piezo_hysteresis.then(|| PiezoHysteresis::new(p.hyst_alpha, p.hyst_beta, p.hyst_gamma, p.d33)),
            actuator,
            kp: p.kp(),
            d33: p.d33,
            f_constant: e.incline_force(total_mass) + p.load_force,
            inv_tau: std::array::from_fn(|k| inv(e.value_of(LAGS[k].tau).unwrap_or(T::zero()))),
            pe_mass_sums: mech.pe_mass_column_sums(),
            external: None,
            library: e.library_on(),
            values: p,
            effect_values: e,
            params,
            effects,
            structure,
            mech,
            layout,
        })
    }
}

impl<T: Real> Model<T> {
    /// This model with a sampled external force on one of its bodies (see `physics/external_force.rs`).
    /// A rig has one body: only `Body::Main` there.
    pub fn with_external_force(mut self, force: ExternalForce<T>) -> Result<Self, InputError> {
        if force.body == Body::Weight && self.layout.dof < 2 {
            return Err("external force on the weight: this mechanism has one body; use body 'main'".into());
        }
        self.external = Some(force);
        Ok(self)
    }

    /// The library forces [N] on the main body and on the weight (each 0 when off). Out of line:
    /// only discovery's runs have them, and every copy of the right-hand side the lane drivers
    /// inline would otherwise carry them.
    #[inline(never)]
    fn library_forces(&self, t: T::Value, q: &[T], v: &[T], volt: T, dvolt: T, ff: T) -> (T, T) {
        let s = self.library_states(t, q, v, volt, dvolt, ff);
        let main = if self.library.0 {
            self.effect_values.library_force_main(&s).0
        } else {
            T::zero()
        };
        let weight = if self.library.1 {
            self.effect_values.library_force_weight(&s).0
        } else {
            T::zero()
        };
        (main, weight)
    }

    /// The sampled external force [N] on the main body and on the last node at time `t` [s].
    /// Out of line, as `library_forces`.
    #[inline(never)]
    fn timed_forces(&self, t: T::Value) -> (T, T) {
        let mut f = (T::zero(), T::zero());
        if let Some(x) = &self.external {
            let (v, _) = x.at(t);
            match x.body {
                Body::Main => f.0 = v,
                Body::Weight => f.1 = v,
            }
        }
        f
    }

    /// Bound on |Fh| [N] (MODEL.md invariant), with the effective normal force and asymmetry.
    pub fn presliding_bound(&self) -> f64 {
        let p = &self.params;
        let fs = p.mu_s.max(p.mu_k) * p.normal_force * self.effects.normal_scale() * (1.0 + self.effects.eps.abs());
        fs.min(p.fric_alpha / (p.fric_beta + p.fric_gamma))
    }

    /// The state at rest: everything zero (the paper's initial condition).
    pub fn rest_state(&self) -> Vec<f64> {
        vec![0.0; self.layout.dim]
    }

    /// Refuse an initial state of the wrong size, not finite, or with |Fh| beyond its bound (the
    /// friction law cannot start there); the message names the component.
    pub fn check_state(&self, y: &[f64]) -> Result<(), InputError> {
        let names = self.layout.components();
        if y.len() != names.len() {
            return Err(crate::input!(
                "initial state has {} components but this model has {} ({})",
                y.len(),
                names.len(),
                names.iter().map(|(n, _)| n.as_str()).collect::<Vec<_>>().join(", ")
            ));
        }
        if let Some(i) = y.iter().position(|x| !x.is_finite()) {
            return Err(crate::input!(
                "initial state component '{}' must be finite, got {}",
                names[i].0,
                y[i]
            ));
        }
        let fh = y[self.layout.fh];
        if fh.abs() > self.presliding_bound() * (1.0 + 1e-6) + 1e-12 {
            return Err(crate::input!(
                "initial state component 'fh' = {fh:e} N exceeds the presliding bound {:e} N",
                self.presliding_bound()
            ));
        }
        Ok(())
    }

    /// PE voltage and its rate [V, V/s] given the commanded ones (the amplifier may lag).
    #[inline(always)]
    fn pe_voltage(&self, v_cmd: T, dv_cmd: T::Value, y: &[T]) -> (T, T) {
        match self.layout.lags[AMPLIFIER] {
            Some(i) => (y[i], first_order_rate(v_cmd, y[i], self.inv_tau[AMPLIFIER])),
            None => (v_cmd, T::of_value(dv_cmd)),
        }
    }

    /// Characteristic magnitude of each state component, for adaptive error norms: positions
    /// and h by the free stroke d33 V_max, velocities by stroke x the LPS frequency, Fh by Fs;
    /// g and the accounting states are left out (inf).
    pub fn state_scales(&self, v_max: f64) -> Vec<f64> {
        let (stroke_per_v, omega, fs) = self.scale_parts();
        let stroke = (stroke_per_v * v_max.abs()).max(1e-9);
        self.state_scale_kinds()
            .iter()
            .map(|k| match k {
                ScaleKind::Excluded => f64::INFINITY,
                ScaleKind::Stroke => stroke,
                ScaleKind::Velocity => stroke * omega,
                ScaleKind::Force => fs,
                ScaleKind::Voltage => v_max.abs().max(1.0),
            })
            .collect()
    }

    /// What each state component's scale in [`Model::state_scales`] is made of (the GPU kernel
    /// combines them the same way, from its generated list).
    pub fn state_scale_kinds(&self) -> Vec<ScaleKind> {
        let l = &self.layout;
        let mut s = vec![ScaleKind::Excluded; l.dim];
        for i in 0..l.dof {
            s[i] = ScaleKind::Stroke;
            s[l.dof + i] = ScaleKind::Velocity;
        }
        // g feeds nothing back (Ff uses Fh and dg/dt), so its error need not limit the step
        s[l.g] = ScaleKind::Excluded;
        s[l.fh] = ScaleKind::Force;
        s[l.h] = ScaleKind::Stroke;
        for (slot, lag) in l.lags.iter().zip(LAGS) {
            if let Some(i) = *slot {
                s[i] = match lag.scale {
                    LagScale::Voltage => ScaleKind::Voltage,
                    LagScale::Stroke => ScaleKind::Stroke,
                };
            }
        }
        s
    }

    /// The numbers the scales are made of: the free stroke per volt d33 [m/V], the LPS
    /// frequency sqrt(kp (1/m1 + 1/m2)) [rad/s] and the static friction Fs [N].
    pub fn scale_parts(&self) -> (f64, f64, f64) {
        let p = &self.params;
        let omega = (p.kp() * (1.0 / p.m1 + 1.0 / p.m2)).sqrt();
        (p.d33, omega, p.mu_s.max(p.mu_k) * p.normal_force)
    }

    /// Friction force Ff [N] on the main body in state `y`.
    #[inline(always)]
    pub fn friction_force(&self, y: &[T]) -> T {
        let v1 = y[self.layout.dof];
        let fh = y[self.layout.fh];
        let (gdot, _) = self.friction.rates(v1, fh);
        self.friction.force(v1, fh, gdot)
    }

    /// What the library forces read at time `t` [s].
    #[inline(always)]
    pub(crate) fn library_states(&self, t: T::Value, q: &[T], v: &[T], volt: T, dvolt: T, ff: T) -> LibraryStates<T> {
        let n = q.len();
        LibraryStates {
            x1: q[0],
            v1: v[0],
            x2: q[n - 1],
            v2: v[n - 1],
            volt,
            dvolt,
            ff,
            t,
            vs: self.values.stribeck_velocity,
        }
    }

    /// True when the state is just nodes, g, Fh and h (no lagged effects, no accounting).
    pub fn is_plain(&self) -> bool {
        self.layout.dim == 2 * self.layout.dof + 3
    }

    /// The number of lag states when the state is nodes, g, Fh, h and the lag effects' states
    /// (no accounting states): the states the fixed-size paths (the vector lanes among them)
    /// hold; `None` when the state has accounting states.
    pub fn lane_lags(&self) -> Option<usize> {
        let l = &self.layout;
        let lags = l.lags.iter().flatten().count();
        (l.accounting.is_none() && l.dim == 2 * l.dof + 3 + lags).then_some(lags)
    }

    /// The right-hand side. `N` > 0 fixes the node count at compile time; `EXTRAS = false`
    /// promises a plain state (see [`Model::is_plain`]). Both only let the compiler keep the
    /// state in registers; the physics is the same code. Returns (Ff [N], dg/dt [m/s]) at `y`,
    /// which the sweep metrics reuse instead of evaluating the friction again.
    #[inline(always)]
    pub fn rhs_impl<const N: usize, const EXTRAS: bool>(
        &self,
        t: T::Value,
        v_cmd: T,
        dv_cmd: T::Value,
        y: &[T],
        dy: &mut [T],
    ) -> (T, T) {
        let l = &self.layout;
        let n = if N > 0 { N } else { l.dof };
        let (ig, ifh, ih) = (2 * n, 2 * n + 1, 2 * n + 2);
        let (q, v) = (&y[..n], &y[n..2 * n]);
        let (v_pe, dv_pe) = if EXTRAS {
            self.pe_voltage(v_cmd, dv_cmd, y)
        } else {
            (v_cmd, T::of_value(dv_cmd))
        };
        let h = y[ih];
        dy[ih] = self.hysteresis.map_or(T::zero(), |hy| hy.rate(dv_pe, h));
        let mut xc = T::zero();
        if EXTRAS {
            // every lag effect that is on: y' = (u - y) / tau, u what it follows
            for (k, lag) in LAGS.iter().enumerate() {
                if let Some(i) = l.lags[k] {
                    let u = match lag.follows {
                        LagInput::Command => v_cmd,
                        LagInput::CreepTarget => self.effect_values.kappa * self.d33 * v_pe,
                        LagInput::Position => q[0],
                    };
                    dy[i] = first_order_rate(u, y[i], self.inv_tau[k]);
                }
            }
            xc = l.lags[CREEP].map_or(xc, |i| y[i]);
        }
        let fp = piezo_force(self.kp, self.d33, v_pe, xc, h);

        let (v1, fh) = (v[0], y[ifh]);
        let (gdot, fhdot) = self.friction.rates(v1, fh);
        let ff = self.friction.force(v1, fh, gdot);
        dy[ig] = gdot;
        dy[ifh] = fhdot;

        let mut f_ext_main = self.f_constant + ground_spring_force(self.effect_values.k_ground, q[0]);
        let mut f_ext_weight = weight_drag(self.effect_values.c_weight, v[n - 1]);
        // what only some runs have: a sampled force, library forces (skipped when off, so
        // a run without them keeps its bits)
        if self.external.is_some() {
            let (a, b) = self.timed_forces(t);
            f_ext_main += a;
            f_ext_weight += b;
        }
        if self.library.0 || self.library.1 {
            let (a, b) = self.library_forces(t, q, v, v_pe, dv_pe, ff);
            if self.library.0 {
                f_ext_main += a;
            }
            if self.library.1 {
                f_ext_weight += b;
            }
        }
        // a loop, not copy_from_slice: on the lane path a memcpy call the compiler leaves out of
        // line runs as baseline code outside pulp's dispatch (see `Real::select`)
        #[allow(clippy::manual_memcpy)]
        for i in 0..n {
            dy[i] = v[i];
        }
        let (f_main, f_last) = self.actuator.forces(fp, v_pe, dv_pe, q[0], v[0]);
        self.mech.accelerations(
            q,
            v,
            (f_main + f_ext_main) - ff,
            f_ext_weight + f_last,
            &mut dy[n..2 * n],
        );

        if EXTRAS {
            if let Some(a) = l.accounting {
                dy[a] = self.actuator.power(f_main, v[0], v[n - 1]);
                dy[a + 1] = ff * v[0];
                dy[a + 2] = self.mech.dissipation(v);
                dy[a + 3] = f_ext_main * v[0] + f_ext_weight * v[n - 1];
                dy[a + 4] = ff;
                dy[a + 5] =
                    self.values.rayleigh_alpha * self.pe_mass_sums.iter().zip(v).map(|(m, vi)| *m * *vi).sum::<T>();
                dy[a + 6] = f_ext_main + f_ext_weight;
            }
        }
        (ff, gdot)
    }
}

/// What needs the value as one `f64` (a scalar, a dual number or a tangent; not lanes).
impl<T: Real<Value = f64>> Model<T> {
    /// The divergence criterion: the state is no longer finite where it matters, or |Fh| left
    /// its bound [N] (which a correct solution never does; see MODEL.md's invariants).
    #[inline(always)]
    // true for NaN as well: a non-finite value counts as beyond the bound
    #[allow(clippy::neg_cmp_op_on_partial_ord)]
    pub fn is_diverged(&self, y: &[T], fh_bound: f64) -> bool {
        let l = &self.layout;
        !(y[l.fh].value().abs() <= fh_bound) || !y[l.dof].value().is_finite() || !y[0].value().is_finite()
    }

    /// Piezo force Fp [N] in state `y` at commanded voltage `v_cmd`.
    #[inline(always)]
    pub fn piezo_force(&self, v_cmd: f64, y: &[T]) -> T {
        let (v, _) = self.pe_voltage(T::from(v_cmd), 0.0, y);
        let xc = self.layout.lags[CREEP].map_or(T::zero(), |i| y[i]);
        piezo_force(self.kp, self.d33, v, xc, y[self.layout.h])
    }

    /// What the sensor reads [m] at time `t` [s] in state `y`.
    #[inline(always)]
    pub fn reading(&self, t: f64, y: &[T]) -> T {
        let x = self.layout.lags[SENSOR].map_or(y[0], |i| y[i]);
        x + self.effect_values.drift_rate * t
    }

    /// dy/dt at time `t` [s] and commanded voltage `v_cmd` [V] rising at `dv_cmd` [V/s].
    #[inline(always)]
    pub fn rhs(&self, t: f64, v_cmd: f64, dv_cmd: f64, y: &[T], dy: &mut [T]) {
        self.rhs_impl::<0, true>(t, T::from(v_cmd), dv_cmd, y, dy);
    }
}
