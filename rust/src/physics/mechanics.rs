//! Structural mechanics of the IDM: the lumped 2-DOF model (LPS, eq. 19) and the n-element FEM
//! bar (DPS, eqs. 16-17) with consistent mass and Rayleigh damping. Node 0 is the main body,
//! node n the weight. Built once per run with nalgebra; the integrator then only needs the
//! precomputed products M^-1 K, M^-1 C and the two columns of M^-1 that the forces load.

use crate::error::InputError;
use crate::numbers::lane_real::Lanewise;
use crate::numbers::real::Real;
use crate::numbers::scalar::Scalar;
use crate::physics::actuation::Actuation;
use crate::physics::effects::Effects;
use crate::physics::params::Params;
use crate::physics::piezo::PiezoElement;
use crate::physics::rig::RigDrive;
use nalgebra::{ComplexField, DMatrix};

/// The mechanisms' actuations, one arm each (the registration of a mechanism).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Actuator {
    Piezo(PiezoElement),
    Rig(RigDrive),
}

macro_rules! each_actuator {
    ($self:expr, $a:ident => $body:expr) => {
        match $self {
            Actuator::Piezo($a) => $body,
            Actuator::Rig($a) => $body,
        }
    };
}

impl Actuation for Actuator {
    fn check(&self, effects: &Effects, piezo_hysteresis: bool) -> Result<(), InputError> {
        each_actuator!(self, a => a.check(effects, piezo_hysteresis))
    }
    fn supported_mass<T: Scalar>(&self, p: &Params<T>) -> T {
        each_actuator!(self, a => a.supported_mass(p))
    }
    #[inline(always)]
    fn forces<T: Real>(&self, fp: T, u: T, du: T, x: T, v: T) -> (T, T) {
        each_actuator!(self, a => a.forces(fp, u, du, x, v))
    }
    #[inline(always)]
    fn force_partials<T: Scalar>(&self, u: T, x: T, v: T) -> [f64; 5] {
        each_actuator!(self, a => a.force_partials(u, x, v))
    }
    #[inline(always)]
    fn power<T: Real>(&self, f_main: T, v_main: T, v_last: T) -> T {
        each_actuator!(self, a => a.power(f_main, v_main, v_last))
    }
    #[inline(always)]
    fn power_partials<T: Scalar>(&self, f_main: T, v_main: T, v_last: T) -> [T; 3] {
        each_actuator!(self, a => a.power_partials(f_main, v_main, v_last))
    }
}

/// A structure the engine runs, declared once: the name a user passes as `model`, its label in
/// figures and reports, what it is, whether it takes `n_elements` (a FEM bar), and whether it
/// is an IDM (a piezo element between two bodies) or a friction rig. The binding, the Python
/// package's choices, type hints and labels, and the messages below read this list.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct StructureDecl {
    pub name: &'static str,
    pub label: &'static str,
    pub meaning: &'static str,
    pub elements: bool,
    pub idm: bool,
}

/// Every structure, in the order the documentation lists them.
pub const STRUCTURES: &[StructureDecl] = &[
    StructureDecl {
        name: "lps",
        label: "LPS",
        meaning: "lumped parameter system: two masses, the PE a massless spring and damper",
        elements: false,
        idm: true,
    },
    StructureDecl {
        name: "dps",
        label: "DPS",
        meaning: "distributed parameter system: the PE as n_elements two-node FEM bar elements",
        elements: true,
        idm: true,
    },
    StructureDecl {
        name: "rig",
        label: "rig",
        meaning: "a friction test rig: one body on the friction element, driven by the input",
        elements: false,
        idm: false,
    },
];

impl Structure {
    /// The structure named `model` (one of [`STRUCTURES`]): "lps", "dps" with `n_elements` (at
    /// least 1), or "rig" with the drive `rig` builds (called only then); the message names what
    /// is wrong.
    pub fn from_name(
        model: &str,
        n_elements: usize,
        rig: impl FnOnce() -> Result<RigDrive, InputError>,
    ) -> Result<Self, InputError> {
        match model {
            "lps" => Ok(Structure::Lps),
            "dps" if n_elements >= 1 => Ok(Structure::Dps(n_elements)),
            "dps" => Err(crate::input!(
                "parameter 'n_elements' must be at least 1, got {n_elements}"
            )),
            "rig" => Ok(Structure::Rig(rig()?)),
            other => {
                let names: Vec<String> = STRUCTURES.iter().map(|s| format!("'{}'", s.name)).collect();
                Err(crate::input!(
                    "parameter 'model' must be one of {}, got '{other}'",
                    names.join(", ")
                ))
            }
        }
    }

    /// This structure's declaration.
    pub fn declaration(&self) -> &'static StructureDecl {
        let name = match self {
            Structure::Lps => "lps",
            Structure::Dps(_) => "dps",
            Structure::Rig(_) => "rig",
        };
        STRUCTURES
            .iter()
            .find(|s| s.name == name)
            .expect("every structure is declared")
    }

    /// The actuation of this structure.
    pub fn actuator(&self) -> Actuator {
        match *self {
            Structure::Lps | Structure::Dps(_) => Actuator::Piezo(PiezoElement),
            Structure::Rig(d) => Actuator::Rig(d),
        }
    }
}

/// Which mechanism: the IDM's two structures, or a friction test rig.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Structure {
    /// Lumped parameter system: two masses, spring kp, damper beta_c kp; massless PE.
    Lps,
    /// Distributed parameter system: the PE as `n` two-node bar elements.
    Dps(usize),
    /// One body on the friction element driven by the input (see `physics/rig.rs`); no PE.
    Rig(RigDrive),
}

/// Assembled matrices and the dense products the right-hand side uses (row-major).
/// Generic over the number type (f64, or dual numbers carrying derivatives with respect to the
/// parameters the matrices are built from).
#[derive(Clone, Debug)]
pub struct Mechanics<T: Real = f64> {
    /// number of nodes (degrees of freedom)
    pub dof: usize,
    pub mass: DMatrix<T>,
    pub damping: DMatrix<T>,
    pub stiffness: DMatrix<T>,
    /// the PE's own mass matrix Mp (zero for the LPS)
    pub pe_mass_matrix: DMatrix<T>,
    pub(crate) minv_k: Vec<T>,
    pub(crate) minv_c: Vec<T>,
    pub(crate) minv_main: Vec<T>,
    pub(crate) minv_weight: Vec<T>,
}

/// Element mass and stiffness of a two-node bar: rho A le / 6 [[2,1],[1,2]], E A / le [[1,-1],[-1,1]].
fn assemble_bar<T: Scalar + ComplexField>(p: &Params<T>, n_elements: usize) -> (DMatrix<T>, DMatrix<T>) {
    let dof = n_elements + 1;
    let le = p.pe_length / n_elements as f64;
    let me = p.pe_density * p.pe_area * le / 6.0;
    let ke = p.pe_youngs * p.pe_area / le;
    let mut mp = DMatrix::zeros(dof, dof);
    let mut kp = DMatrix::zeros(dof, dof);
    for e in 0..n_elements {
        let (i, j) = (e, e + 1);
        mp[(i, i)] += me * 2.0;
        mp[(j, j)] += me * 2.0;
        mp[(i, j)] += me;
        mp[(j, i)] += me;
        kp[(i, i)] += ke;
        kp[(j, j)] += ke;
        kp[(i, j)] -= ke;
        kp[(j, i)] -= ke;
    }
    (mp, kp)
}

impl<T: Scalar + ComplexField> Mechanics<T> {
    pub fn new(p: &Params<T>, structure: Structure) -> Result<Self, InputError> {
        match structure {
            Structure::Lps => {
                // eq. 19: cp = beta_c kp, no PE mass, no mass-proportional damping
                let kp = p.kp();
                let k = DMatrix::from_row_slice(2, 2, &[kp, -kp, -kp, kp]);
                let c = &k * p.rayleigh_beta;
                let zero = T::from(0.0);
                let m = DMatrix::from_row_slice(2, 2, &[p.m1, zero, zero, p.m2]);
                Self::from_matrices(m, c, k, DMatrix::zeros(2, 2))
            }
            Structure::Dps(n) => {
                if n == 0 {
                    return Err("parameter 'n_elements' must be at least 1".into());
                }
                if n > 1 && p.pe_density.value() == 0.0 {
                    // the bar's inner nodes would carry no mass: M is singular
                    return Err(crate::input!(
                        "parameter 'pe_density' = 0 (a massless PE) leaves the {} inner nodes of the \
                         {n}-element FEM bar without mass; use model 'lps' or n_elements = 1 for a \
                         massless PE, or give pe_density > 0",
                        n - 1
                    ));
                }
                let (mp, kp) = assemble_bar(p, n);
                let mut m = mp.clone();
                m[(0, 0)] += p.m1;
                m[(n, n)] += p.m2;
                let c = &mp * p.rayleigh_alpha + &kp * p.rayleigh_beta;
                Self::from_matrices(m, c, kp, mp)
            }
            Structure::Rig(drive) => {
                drive.validate()?;
                let (m, c, k) = drive.matrices(p);
                Self::from_matrices(m, c, k, DMatrix::zeros(1, 1))
            }
        }
    }

    fn from_matrices(
        mass: DMatrix<T>,
        damping: DMatrix<T>,
        stiffness: DMatrix<T>,
        pe_mass_matrix: DMatrix<T>,
    ) -> Result<Self, InputError> {
        let dof = mass.nrows();
        let minv = mass
            .clone()
            .try_inverse()
            .ok_or_else(|| "mass matrix is singular".to_string())?;
        let row_major = |a: &DMatrix<T>| a.transpose().as_slice().to_vec();
        Ok(Mechanics {
            dof,
            minv_k: row_major(&(&minv * &stiffness)),
            minv_c: row_major(&(&minv * &damping)),
            minv_main: minv.column(0).iter().copied().collect(),
            minv_weight: minv.column(dof - 1).iter().copied().collect(),
            mass,
            damping,
            stiffness,
            pe_mass_matrix,
        })
    }

    /// The PE's momentum weights: column sums of Mp (1'Mp v is its momentum [kg m/s]).
    pub fn pe_mass_column_sums(&self) -> Vec<T> {
        (0..self.dof).map(|j| self.pe_mass_matrix.column(j).sum()).collect()
    }
}

impl<T: Real> Mechanics<T> {
    /// acc = M^-1 (f_main e_0 + f_weight e_n - K q - C v) [m/s^2].
    #[inline(always)]
    pub fn accelerations(&self, q: &[T], v: &[T], f_main: T, f_weight: T, acc: &mut [T]) {
        // Fixed sizes for the common cases let the compiler unroll and drop bounds checks.
        match self.dof {
            2 => self.accelerations_fixed::<2>(q, v, f_main, f_weight, acc),
            3 => self.accelerations_fixed::<3>(q, v, f_main, f_weight, acc),
            4 => self.accelerations_fixed::<4>(q, v, f_main, f_weight, acc),
            5 => self.accelerations_fixed::<5>(q, v, f_main, f_weight, acc),
            6 => self.accelerations_fixed::<6>(q, v, f_main, f_weight, acc),
            _ => self.accelerations_dyn(q, v, f_main, f_weight, acc),
        }
    }

    #[inline(always)]
    fn accelerations_fixed<const N: usize>(&self, q: &[T], v: &[T], f_main: T, f_weight: T, acc: &mut [T]) {
        let q: &[T; N] = q.try_into().unwrap();
        let v: &[T; N] = v.try_into().unwrap();
        let acc: &mut [T; N] = acc.try_into().unwrap();
        let mk: &[T] = &self.minv_k[..N * N];
        let mc: &[T] = &self.minv_c[..N * N];
        let m0: &[T; N] = self.minv_main[..N].try_into().unwrap();
        let ml: &[T; N] = self.minv_weight[..N].try_into().unwrap();
        // The structural part first, the forces last: f_main ends the step's critical
        // dependency chain (it waits on the friction), so nothing should queue behind it.
        for i in 0..N {
            let mut a = T::zero();
            for j in 0..N {
                a -= mk[i * N + j] * q[j] + mc[i * N + j] * v[j];
            }
            acc[i] = a + ml[i] * f_weight + m0[i] * f_main;
        }
    }

    // row i indexes acc, minv_weight and minv_main together, as in the fixed-size version above
    #[allow(clippy::needless_range_loop)]
    fn accelerations_dyn(&self, q: &[T], v: &[T], f_main: T, f_weight: T, acc: &mut [T]) {
        let n = self.dof;
        for i in 0..n {
            let rk = &self.minv_k[i * n..(i + 1) * n];
            let rc = &self.minv_c[i * n..(i + 1) * n];
            let mut a = T::zero();
            for j in 0..n {
                a -= rk[j] * q[j] + rc[j] * v[j];
            }
            acc[i] = a + self.minv_weight[i] * f_weight + self.minv_main[i] * f_main;
        }
    }

    /// v'Cv [W]: the power the structure's damping dissipates.
    pub fn dissipation(&self, v: &[T]) -> T {
        quad(&self.damping, v)
    }
}

impl<S: Real + nalgebra::Scalar, T: Real + nalgebra::Scalar + Lanewise<S>> Lanewise<Mechanics<S>> for Mechanics<T> {
    fn splat(m: &Mechanics<S>) -> Self {
        Mechanics {
            dof: m.dof,
            mass: Lanewise::splat(&m.mass),
            damping: Lanewise::splat(&m.damping),
            stiffness: Lanewise::splat(&m.stiffness),
            pe_mass_matrix: Lanewise::splat(&m.pe_mass_matrix),
            minv_k: Lanewise::splat(&m.minv_k),
            minv_c: Lanewise::splat(&m.minv_c),
            minv_main: Lanewise::splat(&m.minv_main),
            minv_weight: Lanewise::splat(&m.minv_weight),
        }
    }
    fn set_lane(&mut self, i: usize, m: &Mechanics<S>) {
        debug_assert_eq!(self.dof, m.dof, "lanes of one shape");
        self.mass.set_lane(i, &m.mass);
        self.damping.set_lane(i, &m.damping);
        self.stiffness.set_lane(i, &m.stiffness);
        self.pe_mass_matrix.set_lane(i, &m.pe_mass_matrix);
        self.minv_k.set_lane(i, &m.minv_k);
        self.minv_c.set_lane(i, &m.minv_c);
        self.minv_main.set_lane(i, &m.minv_main);
        self.minv_weight.set_lane(i, &m.minv_weight);
    }
}

impl Mechanics {
    /// Highest natural frequency of the undamped structure [rad/s] (generalised eigenproblem
    /// K x = w^2 M x, solved through the Cholesky factor of M).
    pub fn highest_frequency(&self) -> f64 {
        let chol = match self.mass.clone().cholesky() {
            Some(c) => c,
            None => return f64::INFINITY,
        };
        let linv = chol
            .l()
            .try_inverse()
            .unwrap_or_else(|| DMatrix::zeros(self.dof, self.dof));
        let a = &linv * &self.stiffness * linv.transpose();
        let sym = (&a + a.transpose()) * 0.5;
        let w2 = sym.symmetric_eigenvalues().iter().copied().fold(0.0f64, f64::max);
        w2.max(0.0).sqrt()
    }

    /// The eigenvalues [1/s] of the damped structure's first-order system
    /// d/dt (q, v) = [[0, I], [-M⁻¹K, -M⁻¹C]] (q, v): what an explicit step must keep inside its
    /// stability region. Stiffness-proportional damping puts the fine bar's fastest modes far out
    /// on the negative real axis (|λ| ≈ β ω²), beyond the undamped ω.
    pub fn eigenvalues(&self) -> Vec<nalgebra::Complex<f64>> {
        let n = self.dof;
        let mut a = DMatrix::zeros(2 * n, 2 * n);
        for i in 0..n {
            a[(i, n + i)] = 1.0;
            for j in 0..n {
                a[(n + i, j)] = -self.minv_k[i * n + j];
                a[(n + i, n + j)] = -self.minv_c[i * n + j];
            }
        }
        a.complex_eigenvalues().iter().copied().collect()
    }

    /// Quadratic forms for the energy budget: 1/2 v'Mv, 1/2 q'Kq [J].
    pub fn kinetic(&self, v: &[f64]) -> f64 {
        0.5 * quad(&self.mass, v)
    }

    pub fn strain(&self, q: &[f64]) -> f64 {
        0.5 * quad(&self.stiffness, q)
    }

    /// 1'M v [kg m/s].
    pub fn momentum(&self, v: &[f64]) -> f64 {
        (0..self.dof).map(|j| self.mass.column(j).sum() * v[j]).sum()
    }
}

fn quad<T: Real>(a: &DMatrix<T>, x: &[T]) -> T {
    let n = x.len();
    let mut s = T::zero();
    for i in 0..n {
        for j in 0..n {
            s += x[i] * a[(i, j)] * x[j];
        }
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn dps_total_mass_is_device_mass() {
        let p = Params::paper();
        let m = Mechanics::new(&p, Structure::Dps(4)).unwrap();
        let total: f64 = m.mass.iter().sum();
        assert!((total - (p.m1 + p.m2 + p.pe_mass())).abs() < 1e-15);
        // rigid-body motion stores no strain
        assert!(m.strain(&[1.0; 5]).abs() < 1e-6);
    }

    #[test]
    fn lps_mode_matches_analytic_two_mass_frequency() {
        let p = Params::paper();
        let m = Mechanics::new(&p, Structure::Lps).unwrap();
        let w = (p.kp() * (1.0 / p.m1 + 1.0 / p.m2)).sqrt();
        assert!((m.highest_frequency() / w - 1.0).abs() < 1e-12);
        assert!((w / 1.3e4 - 1.0).abs() < 0.03); // MODEL.md: 1.3e4 rad/s
    }

    #[test]
    fn a_massless_multi_element_bar_is_refused_with_the_fix() {
        let mut p = Params::paper();
        p.pe_density = 0.0;
        let err = Mechanics::new(&p, Structure::Dps(4)).unwrap_err();
        assert!(
            err.contains("'pe_density'") && err.contains("'lps'") && err.contains("n_elements = 1"),
            "{err}"
        );
    }

    #[test]
    fn dps_one_massless_element_is_the_lps() {
        let mut p = Params::paper();
        p.pe_density = 0.0;
        let a = Mechanics::new(&p, Structure::Lps).unwrap();
        let b = Mechanics::new(&p, Structure::Dps(1)).unwrap();
        assert_eq!(a.minv_k, b.minv_k);
        assert_eq!(a.minv_c, b.minv_c);
        assert_eq!(a.minv_main, b.minv_main);
    }

    #[test]
    fn every_declared_structure_is_built_by_its_name_and_declares_itself() {
        let drive = || crate::physics::rig::RigDrive::from_name("force", 0.0, 0.0, 0.0, 0.0, 0.0, 0.0);
        for d in STRUCTURES {
            let s = Structure::from_name(d.name, 3, drive).unwrap_or_else(|e| panic!("{}: {e}", d.name));
            assert_eq!(s.declaration(), d);
            assert_eq!(d.elements, matches!(s, Structure::Dps(_)), "{}", d.name);
            assert_eq!(d.idm, !matches!(s, Structure::Rig(_)), "{}", d.name);
        }
        let err = Structure::from_name("fem", 4, drive).unwrap_err();
        assert!(
            STRUCTURES.iter().all(|d| err.contains(&format!("'{}'", d.name))),
            "{err}"
        );
    }
}
