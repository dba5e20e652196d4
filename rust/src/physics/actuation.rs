//! How the input acts on the bodies, the one question that tells the mechanisms apart once their
//! matrices are built (`physics/mechanics.rs` builds them and registers each mechanism's actuation).

use crate::error::InputError;
use crate::numbers::real::Real;
use crate::numbers::scalar::Scalar;
use crate::physics::effects::Effects;
use crate::physics::params::Params;

/// How the input acts on the bodies: what tells the mechanisms apart once their matrices are
/// built. The IDM's piezo element (`physics/piezo.rs`) pushes node 0 forward and the last node back
/// with the piezo force; a rig's drive (`physics/rig.rs`) pushes its one body. The right-hand side and
/// its Jacobian ask only these questions; [`Actuator`](crate::physics::mechanics::Actuator) registers the implementations.
pub trait Actuation {
    /// Refuse effects and switches the mechanism does not have (the message names them).
    fn check(&self, effects: &Effects, piezo_hysteresis: bool) -> Result<(), InputError>;
    /// The mass resting on the guide [kg] (for the incline's pull along it).
    fn supported_mass<T: Scalar>(&self, p: &Params<T>) -> T;
    /// Forces [N] on the main body and on the last node, given the piezo force `fp` [N], the
    /// input `u` rising at `du`, and the main body at `x` [m] moving at `v` [m/s].
    fn forces<T: Real>(&self, fp: T, u: T, du: T, x: T, v: T) -> (T, T);
    /// Partials of [`Actuation::forces`] at fixed du/dt: [d f_main/d fp, d f_last/d fp,
    /// d f_main/du, d f_main/dx, d f_main/dv].
    fn force_partials<T: Scalar>(&self, u: T, x: T, v: T) -> [f64; 5];
    /// Power [W] the actuation puts in, its force on the main body being `f_main` [N], with
    /// the main body and the last node at `v_main`, `v_last` [m/s].
    fn power<T: Real>(&self, f_main: T, v_main: T, v_last: T) -> T;
    /// Partials of [`Actuation::power`]: [d/d f_main, d/d v_main, d/d v_last].
    fn power_partials<T: Scalar>(&self, f_main: T, v_main: T, v_last: T) -> [T; 3];
}
