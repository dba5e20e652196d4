//! The number the physics is written over: `f64` for plain runs, a forward-mode dual number
//! (num-dual's `DualSVec64<N>`: a value and its derivatives with respect to N seeded inputs)
//! when derivatives are asked for. The right-hand side, its Jacobian and the integrators are
//! written once over [`Scalar`]; the `f64` instantiation is the plain engine, bit for bit.
//!
//! Branches of the physics (|v|, sgn v, saturations) are decided on the value ([`Scalar::re`]);
//! a derivative through them is the derivative of the branch taken (one-sided at a kink).

use nalgebra::{ComplexField, Const};
use num_dual::{Dual64, DualNum, DualSVec64, DualStruct, DualVec};

/// A real number with optional forward-mode derivative parts.
pub trait Scalar: DualNum<Primitive = f64> + Copy + Send + Sync + 'static {
    /// The value (the derivative parts dropped).
    #[inline(always)]
    fn value(&self) -> f64 {
        DualStruct::re(self)
    }

    /// Set the value, keeping the derivative parts (a derivative pass pinned to the states of
    /// the plain run it follows).
    fn set_value(&mut self, v: f64);

    /// True when the number is exactly `x` with no derivative part: a term that vanishes
    /// identically may then be skipped without losing a derivative.
    fn is_exactly(&self, x: f64) -> bool;

    /// `self^e` for a base >= 0 (the Stribeck and Leuven exponents). A base of 0 gives 0 with
    /// zero derivatives (the one-sided limit for exponents above 1); the exponent's derivative
    /// is taken through the log only when it has one.
    #[inline(always)]
    fn pow(self, e: Self) -> Self {
        if self.value() <= 0.0 {
            Self::from(0.0)
        } else if e.is_exactly(e.value()) {
            self.powf(e.value())
        } else {
            (self.ln() * e).exp()
        }
    }

    /// The derivative parts, into `out` (length N; nothing for `f64`).
    fn derivatives(&self, out: &mut [f64]);
}

impl Scalar for f64 {
    // the plain engine's hot path: no call across crates, whatever the inliner decides
    #[inline(always)]
    fn value(&self) -> f64 {
        *self
    }

    #[inline(always)]
    fn set_value(&mut self, v: f64) {
        *self = v;
    }

    #[inline(always)]
    fn is_exactly(&self, x: f64) -> bool {
        *self == x
    }

    #[inline(always)]
    fn pow(self, e: f64) -> f64 {
        self.powf(e)
    }

    fn derivatives(&self, _out: &mut [f64]) {}
}

impl<const N: usize> Scalar for DualSVec64<N> {
    #[inline(always)]
    fn set_value(&mut self, v: f64) {
        self.re = v;
    }

    #[inline(always)]
    fn is_exactly(&self, x: f64) -> bool {
        self.re == x && self.eps.0.is_none_or(|e| e.iter().all(|d| *d == 0.0))
    }

    fn derivatives(&self, out: &mut [f64]) {
        match &self.eps.0 {
            Some(e) => out.copy_from_slice(e.as_slice()),
            None => out.fill(0.0),
        }
    }
}

impl Scalar for Dual64 {
    #[inline(always)]
    fn set_value(&mut self, v: f64) {
        self.re = v;
    }

    #[inline(always)]
    fn is_exactly(&self, x: f64) -> bool {
        self.re == x && self.eps == 0.0
    }

    fn derivatives(&self, out: &mut [f64]) {
        out[0] = self.eps;
    }
}

/// A dual number a forward-mode pass can seed: `WIDTH` derivatives, input `index` set to 1.
/// `Dual64` (one derivative, no storage overhead) for one name; `DualSVec64<N>` for several.
pub trait Seedable: Scalar + ComplexField {
    const WIDTH: usize;
    fn seed(x: f64, index: usize) -> Self;
}

impl Seedable for Dual64 {
    const WIDTH: usize = 1;
    #[inline(always)]
    fn seed(x: f64, _index: usize) -> Self {
        Dual64::new(x, 1.0)
    }
}

impl<const N: usize> Seedable for DualSVec64<N> {
    const WIDTH: usize = N;
    #[inline(always)]
    fn seed(x: f64, index: usize) -> Self {
        DualVec::<f64, Const<N>>::from_re(x).derivative(index)
    }
}

/// Sign that is 0 at 0 (f64::signum gives +1 there), decided on the value.
#[inline(always)]
pub fn sign0<T: Scalar>(x: T) -> f64 {
    let v = x.value();
    if v > 0.0 {
        1.0
    } else if v < 0.0 {
        -1.0
    } else {
        0.0
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn dual_pow_carries_both_derivatives() {
        let x = DualSVec64::<2>::seed(1.7, 0);
        let e = DualSVec64::<2>::seed(1.3, 1);
        let y = x.pow(e);
        let mut d = [0.0; 2];
        y.derivatives(&mut d);
        assert!((y.re - 1.7f64.powf(1.3)).abs() < 1e-14);
        assert!((d[0] - 1.3 * 1.7f64.powf(0.3)).abs() < 1e-13);
        assert!((d[1] - 1.7f64.powf(1.3) * 1.7f64.ln()).abs() < 1e-13);
        assert_eq!(DualSVec64::<2>::from(0.0).pow(e).re, 0.0);
        assert!(!e.is_exactly(1.3) && DualSVec64::<2>::from(1.3).is_exactly(1.3));
    }
}
