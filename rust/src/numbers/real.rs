//! The number the physics is written over: one `f64` (the plain engine), a forward-mode dual
//! number (the sensitivities; `numbers/scalar.rs`), or a vector of `L` independent `f64` lanes (many
//! points at once; `numbers/lane_real.rs`). The right-hand side (`model/mod.rs`, `physics/friction.rs`, `physics/piezo.rs`,
//! `physics/effects.rs`, `physics/mechanics.rs`, `physics/rig.rs`) is written once over [`Real`].
//!
//! Branches of the physics (|v|, sgn v, saturations, the Stribeck shortcut) are decided on the
//! *value* ([`Real::Value`]: the `f64` of a scalar or of a dual's real part, one value per lane
//! for lanes) and taken with [`Real::choose`]: for a scalar the branch it names is the only one
//! evaluated (the plain engine's code, bit for bit); for lanes both sides are evaluated where the
//! lanes disagree and each lane keeps its own, so a lane's result is bitwise the scalar model's.

use std::fmt::Debug;
use std::iter::Sum;
use std::ops::{Add, AddAssign, Div, Mul, Neg, Sub, SubAssign};

use crate::numbers::scalar::Scalar;

/// A truth value per lane (one `bool` for a scalar).
pub trait Mask: Copy + Send + Sync + Debug + 'static {
    /// Every lane true.
    fn all(self) -> bool;
    /// Some lane true.
    fn any(self) -> bool;
    /// Per lane: either.
    fn or(self, o: Self) -> Self;
}

impl Mask for bool {
    #[inline(always)]
    fn all(self) -> bool {
        self
    }
    #[inline(always)]
    fn any(self) -> bool {
        self
    }
    #[inline(always)]
    fn or(self, o: bool) -> bool {
        self || o
    }
}

/// A real number for the physics: arithmetic, the few functions the model uses, and branches
/// as [`Real::choose`] on a [`Mask`] decided on the value.
pub trait Real:
    Copy
    + Send
    + Sync
    + Debug
    + 'static
    + Add<Output = Self>
    + Sub<Output = Self>
    + Mul<Output = Self>
    + Div<Output = Self>
    + Neg<Output = Self>
    + Add<f64, Output = Self>
    + Sub<f64, Output = Self>
    + Mul<f64, Output = Self>
    + Div<f64, Output = Self>
    + Add<Self::Value, Output = Self>
    + Sub<Self::Value, Output = Self>
    + Mul<Self::Value, Output = Self>
    + Div<Self::Value, Output = Self>
    + AddAssign
    + SubAssign
    + Sum
    + From<f64>
{
    /// What branches are decided on: `f64` for a scalar or a dual number (its real part), the
    /// lanes themselves for lanes.
    type Value: Real<Value = Self::Value, Mask = Self::Mask>;
    /// A truth value per lane.
    type Mask: Mask;

    fn zero() -> Self;
    fn one() -> Self;
    /// The value (a dual's derivative parts dropped).
    fn value(&self) -> Self::Value;
    /// A value as a number with no derivative parts.
    fn of_value(v: Self::Value) -> Self;

    fn abs(self) -> Self;
    fn exp(self) -> Self;
    fn powf(self, e: f64) -> Self;
    fn ln(self) -> Self;
    fn sin(self) -> Self;
    fn cos(self) -> Self;
    fn tanh(self) -> Self;
    /// `self^e` for a base >= 0 (the Stribeck and Leuven exponents; see `Scalar::pow`).
    fn pow(self, e: Self) -> Self;

    /// Exactly `x` with no derivative part, per lane (a term that vanishes identically may then
    /// be skipped without losing a derivative).
    fn is_exactly(&self, x: f64) -> Self::Mask;
    /// The value is below `x`, per lane.
    fn below(&self, x: f64) -> Self::Mask;
    /// The value is above `x`, per lane.
    fn above(&self, x: f64) -> Self::Mask;
    /// The value equals `x`, per lane.
    fn equals(&self, x: f64) -> Self::Mask;
    /// The sign of the value, 0 at 0 (`f64::signum` gives +1 there).
    fn sign0(&self) -> Self::Value;

    /// `a()` where the mask is true, `b()` where it is false. A scalar evaluates only the side
    /// it takes; lanes evaluate a side only when some lane takes it.
    fn choose(m: Self::Mask, a: impl FnOnce() -> Self, b: impl FnOnce() -> Self) -> Self;
    /// `a` where the mask is true, `b` where it is false, both already computed. The physics
    /// writes a branch whose one side is costly as `if m.all() { a } else { select(m, a, b) }`
    /// with the costly side in `b` and plain code on both sides, not closures: the lane drivers
    /// compile the right-hand side for the processor's vector width only where every call in it
    /// is inlined, and a closure the compiler declines to inline runs as baseline code (measured:
    /// a third of the lane step in the Stribeck closure).
    fn select(m: Self::Mask, a: Self, b: Self) -> Self;
    /// [`Real::choose`] for `K` numbers decided together.
    fn choose_n<const K: usize>(
        m: Self::Mask,
        a: impl FnOnce() -> [Self; K],
        b: impl FnOnce() -> [Self; K],
    ) -> [Self; K];

    /// Linear interpolation through samples `values` at `times` (increasing) at time `t` [s],
    /// held outside them: (value, slope per second; 0 outside). Per lane for lanes.
    fn interpolate(values: &[Self], times: &[f64], t: Self::Value) -> (Self, Self);
}

/// The piecewise-linear interpolation of one lane (see [`Real::interpolate`]).
#[inline]
pub(crate) fn interpolate_one<
    T: Copy + Add<Output = T> + Sub<Output = T> + Mul<f64, Output = T> + Div<f64, Output = T>,
>(
    values: &[T],
    times: &[f64],
    t: f64,
    zero: T,
) -> (T, T) {
    let last = times.len() - 1;
    if t <= times[0] {
        return (values[0], zero);
    }
    if t >= times[last] {
        return (values[last], zero);
    }
    // the piece [ts[j], ts[j+1]) holding t
    let j = times.partition_point(|&x| x <= t) - 1;
    let span = times[j + 1] - times[j];
    let w = (t - times[j]) / span;
    let (a, b) = (values[j], values[j + 1]);
    (a + (b - a) * w, (b - a) / span)
}

/// The branch methods of a [`Real`] of one lane (`Value = f64`, `Mask = bool`): decided on the
/// value, a scalar evaluating only the side it takes. Shared by the scalars (below) and
/// `tangent::Tangent`.
macro_rules! one_lane_branches {
    () => {
        #[inline(always)]
        fn below(&self, x: f64) -> bool {
            Real::value(self) < x
        }
        #[inline(always)]
        fn above(&self, x: f64) -> bool {
            Real::value(self) > x
        }
        #[inline(always)]
        fn equals(&self, x: f64) -> bool {
            Real::value(self) == x
        }
        #[inline(always)]
        fn sign0(&self) -> f64 {
            crate::numbers::scalar::sign0(Real::value(self))
        }
        #[inline(always)]
        fn choose(m: bool, a: impl FnOnce() -> Self, b: impl FnOnce() -> Self) -> Self {
            if m {
                a()
            } else {
                b()
            }
        }
        #[inline(always)]
        fn select(m: bool, a: Self, b: Self) -> Self {
            if m {
                a
            } else {
                b
            }
        }
        #[inline(always)]
        fn choose_n<const M: usize>(
            m: bool,
            a: impl FnOnce() -> [Self; M],
            b: impl FnOnce() -> [Self; M],
        ) -> [Self; M] {
            if m {
                a()
            } else {
                b()
            }
        }
        #[inline]
        fn interpolate(values: &[Self], times: &[f64], t: f64) -> (Self, Self) {
            $crate::numbers::real::interpolate_one(values, times, t, <Self as Real>::zero())
        }
    };
}
pub(crate) use one_lane_branches;

/// Every scalar (f64 and the dual numbers) is a [`Real`] of one lane, its branches decided on
/// its value; each method is the one the physics called before it was written over `Real`.
impl<T: Scalar> Real for T {
    type Value = f64;
    type Mask = bool;

    #[inline(always)]
    fn zero() -> Self {
        <T as num_traits::Zero>::zero()
    }
    #[inline(always)]
    fn one() -> Self {
        <T as num_traits::One>::one()
    }
    #[inline(always)]
    fn value(&self) -> f64 {
        Scalar::value(self)
    }
    #[inline(always)]
    fn of_value(v: f64) -> Self {
        <T as From<f64>>::from(v)
    }
    #[inline(always)]
    fn abs(self) -> Self {
        num_traits::Signed::abs(&self)
    }
    #[inline(always)]
    fn exp(self) -> Self {
        num_dual::DualNum::exp(&self)
    }
    #[inline(always)]
    fn powf(self, e: f64) -> Self {
        num_dual::DualNum::powf(&self, e)
    }
    #[inline(always)]
    fn ln(self) -> Self {
        num_dual::DualNum::ln(&self)
    }
    #[inline(always)]
    fn sin(self) -> Self {
        num_dual::DualNum::sin(&self)
    }
    #[inline(always)]
    fn cos(self) -> Self {
        num_dual::DualNum::cos(&self)
    }
    #[inline(always)]
    fn tanh(self) -> Self {
        num_dual::DualNum::tanh(&self)
    }
    #[inline(always)]
    fn pow(self, e: Self) -> Self {
        Scalar::pow(self, e)
    }
    #[inline(always)]
    fn is_exactly(&self, x: f64) -> bool {
        Scalar::is_exactly(self, x)
    }
    one_lane_branches!();
}
