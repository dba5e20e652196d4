//! A forward-mode number for derivative passes: a value and `K` derivatives held inline
//! (`[f64; K]`), with no `Option` and no generality to pay for.
//!
//! Why it exists: num-dual's `DualSVec64<K>` keeps its derivatives in an `Option` of a static
//! vector, and a pass over 8 names cost 5-8 plain runs on one lane and 7-11 plain predictions
//! on the vector lanes the diagnosis's predictions use (benches/RESULTS.md §7, §18) — the passes
//! were about a quarter of a diagnosis. `Tangent` is a [`Real`] (branches decided on the value), so the one
//! right-hand side (`Model::rhs_impl`) runs on it as it runs on f64, duals and lanes.
//!
//! Every operation is num-dual's formula for `DualVec`, term for term and in its order (the
//! product rule `a' b + b' a`, the quotient `(a' b - b' a) / b / b` through `1/b`, `powf` through
//! `x^(n-3) x x x`, `tanh` as `sinh / cosh`), so values and derivatives are those of a
//! `DualSVec64<K>` pass bit for bit; the one difference is that a derivative num-dual holds as
//! "none" is 0 here, which can only turn a -0.0 into +0.0 (tested against num-dual's passes).

use std::iter::Sum;
use std::ops::{Add, AddAssign, Div, Mul, Neg, Sub, SubAssign};

use num_dual::DualSVec64;

use crate::numbers::lane_real::Lanewise;
use crate::numbers::real::Real;

/// A value and `K` derivatives [unit of the value per unit of each seed].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Tangent<const K: usize> {
    pub re: f64,
    pub eps: [f64; K],
}

impl<const K: usize> Tangent<K> {
    /// A constant: no derivative parts.
    #[inline(always)]
    pub const fn constant(re: f64) -> Self {
        Tangent { re, eps: [0.0; K] }
    }

    /// `x` seeded: derivative 1 with respect to seed `index`.
    pub fn seed(x: f64, index: usize) -> Self {
        let mut t = Tangent::constant(x);
        t.eps[index] = 1.0;
        t
    }

    /// The value and each derivative times `f1` (num-dual's `chain_rule` for first derivatives).
    #[inline(always)]
    fn chain(&self, f0: f64, f1: f64) -> Self {
        let mut eps = self.eps;
        for d in eps.iter_mut() {
            *d *= f1;
        }
        Tangent { re: f0, eps }
    }

    #[inline(always)]
    fn sinh(self) -> Self {
        self.chain(self.re.sinh(), self.re.cosh())
    }

    #[inline(always)]
    fn cosh(self) -> Self {
        self.chain(self.re.cosh(), self.re.sinh())
    }
}

/// A num-dual number's parts as a `Tangent` (a derivative it holds as "none" is 0).
impl<const K: usize> Lanewise<DualSVec64<K>> for Tangent<K> {
    fn splat(src: &DualSVec64<K>) -> Self {
        let mut t = Tangent::constant(src.re);
        if let Some(e) = &src.eps.0 {
            t.eps.copy_from_slice(e.as_slice());
        }
        t
    }
    fn set_lane(&mut self, _i: usize, src: &DualSVec64<K>) {
        *self = Lanewise::splat(src);
    }
}

impl<const K: usize> From<f64> for Tangent<K> {
    #[inline(always)]
    fn from(x: f64) -> Self {
        Tangent::constant(x)
    }
}

impl<const K: usize> Add for Tangent<K> {
    type Output = Self;
    #[inline(always)]
    fn add(mut self, o: Self) -> Self {
        self += o;
        self
    }
}

impl<const K: usize> Sub for Tangent<K> {
    type Output = Self;
    #[inline(always)]
    fn sub(mut self, o: Self) -> Self {
        self -= o;
        self
    }
}

impl<const K: usize> AddAssign for Tangent<K> {
    #[inline(always)]
    fn add_assign(&mut self, o: Self) {
        self.re += o.re;
        for k in 0..K {
            self.eps[k] += o.eps[k];
        }
    }
}

impl<const K: usize> SubAssign for Tangent<K> {
    #[inline(always)]
    fn sub_assign(&mut self, o: Self) {
        self.re -= o.re;
        for k in 0..K {
            self.eps[k] -= o.eps[k];
        }
    }
}

impl<const K: usize> Mul for Tangent<K> {
    type Output = Self;
    /// a' b + b' a
    #[inline(always)]
    // both operands' eps indexed by the same k: num-dual's formula term for term
    #[allow(clippy::needless_range_loop)]
    fn mul(self, o: Self) -> Self {
        let mut eps = [0.0; K];
        for k in 0..K {
            eps[k] = self.eps[k] * o.re + o.eps[k] * self.re;
        }
        Tangent {
            re: self.re * o.re,
            eps,
        }
    }
}

impl<const K: usize> Div for Tangent<K> {
    type Output = Self;
    /// (a' b - b' a) / b / b, through inv = 1/b
    #[inline(always)]
    // both operands' eps indexed by the same k: num-dual's formula term for term
    #[allow(clippy::needless_range_loop)]
    fn div(self, o: Self) -> Self {
        let inv = o.re.recip();
        let mut eps = [0.0; K];
        for k in 0..K {
            eps[k] = (self.eps[k] * o.re - o.eps[k] * self.re) * inv * inv;
        }
        Tangent { re: self.re * inv, eps }
    }
}

impl<const K: usize> Neg for Tangent<K> {
    type Output = Self;
    #[inline(always)]
    fn neg(self) -> Self {
        let mut eps = self.eps;
        for d in eps.iter_mut() {
            *d = -*d;
        }
        Tangent { re: -self.re, eps }
    }
}

impl<const K: usize> Add<f64> for Tangent<K> {
    type Output = Self;
    #[inline(always)]
    fn add(mut self, x: f64) -> Self {
        self.re += x;
        self
    }
}

impl<const K: usize> Sub<f64> for Tangent<K> {
    type Output = Self;
    #[inline(always)]
    fn sub(mut self, x: f64) -> Self {
        self.re -= x;
        self
    }
}

impl<const K: usize> Mul<f64> for Tangent<K> {
    type Output = Self;
    #[inline(always)]
    fn mul(self, x: f64) -> Self {
        self.chain(self.re * x, x)
    }
}

impl<const K: usize> Div<f64> for Tangent<K> {
    type Output = Self;
    #[inline(always)]
    fn div(mut self, x: f64) -> Self {
        self.re /= x;
        for d in self.eps.iter_mut() {
            *d /= x;
        }
        self
    }
}

impl<const K: usize> Sum for Tangent<K> {
    fn sum<I: Iterator<Item = Self>>(iter: I) -> Self {
        iter.fold(Tangent::constant(0.0), |acc, c| acc + c)
    }
}

impl<const K: usize> Real for Tangent<K> {
    type Value = f64;
    type Mask = bool;

    #[inline(always)]
    fn zero() -> Self {
        Tangent::constant(0.0)
    }
    #[inline(always)]
    fn one() -> Self {
        Tangent::constant(1.0)
    }
    #[inline(always)]
    fn value(&self) -> f64 {
        self.re
    }
    #[inline(always)]
    fn of_value(v: f64) -> Self {
        Tangent::constant(v)
    }
    /// num-traits' `Signed::abs` of a dual: the number where its value's sign bit is clear
    #[inline(always)]
    fn abs(self) -> Self {
        if self.re.is_sign_positive() {
            self
        } else {
            -self
        }
    }
    #[inline(always)]
    fn exp(self) -> Self {
        let f = self.re.exp();
        self.chain(f, f)
    }
    #[inline(always)]
    fn powf(self, n: f64) -> Self {
        if n == 0.0 {
            Tangent::constant(1.0)
        } else if n == 1.0 {
            self
        } else if (n - 1.0 - 1.0).abs() < f64::EPSILON {
            self * self
        } else {
            let n3 = n - 1.0 - 1.0 - 1.0;
            let pow3 = self.re.powf(n3);
            self.chain(pow3 * self.re * self.re * self.re, pow3 * self.re * self.re * n)
        }
    }
    #[inline(always)]
    fn ln(self) -> Self {
        let rec = self.re.recip();
        self.chain(self.re.ln(), rec)
    }
    #[inline(always)]
    fn sin(self) -> Self {
        let (s, c) = self.re.sin_cos();
        self.chain(s, c)
    }
    #[inline(always)]
    fn cos(self) -> Self {
        let (s, c) = self.re.sin_cos();
        self.chain(c, -s)
    }
    #[inline(always)]
    fn tanh(self) -> Self {
        self.sinh() / self.cosh()
    }
    /// As `Scalar::pow`: 0 for a base <= 0; through `powf` when the exponent has no derivative.
    #[inline(always)]
    fn pow(self, e: Self) -> Self {
        if self.re <= 0.0 {
            Tangent::constant(0.0)
        } else if e.is_exactly(e.re) {
            self.powf(e.re)
        } else {
            (self.ln() * e).exp()
        }
    }
    #[inline(always)]
    fn is_exactly(&self, x: f64) -> bool {
        self.re == x && self.eps.iter().all(|d| *d == 0.0)
    }
    crate::numbers::real::one_lane_branches!();
}

#[cfg(test)]
mod tests {
    use super::*;
    use num_dual::DualNum;

    type D = DualSVec64<3>;

    fn dual(re: f64, eps: [f64; 3]) -> D {
        let mut d = D::from(re);
        for (k, e) in eps.iter().enumerate() {
            d += D::from(0.0).derivative(k) * *e;
        }
        d
    }

    fn same(t: Tangent<3>, d: D) {
        let from_dual: Tangent<3> = Lanewise::splat(&d);
        assert_eq!(t.re.to_bits(), from_dual.re.to_bits(), "value {t:?} vs {d:?}");
        for k in 0..3 {
            // a derivative num-dual holds as "none" may be a -0.0 here
            assert!(t.eps[k] == from_dual.eps[k], "derivative {k}: {t:?} vs {d:?}");
            assert!(
                t.eps[k] == 0.0 || t.eps[k].to_bits() == from_dual.eps[k].to_bits(),
                "{t:?} vs {d:?}"
            );
        }
    }

    #[test]
    fn every_operation_is_num_duals_bit_for_bit() {
        let pairs = [([0.7, 1.3, 0.0], [-0.2, 0.5, 2.0]), ([3.1, 0.0, -1.0], [1.0, 0.0, 0.0])];
        for (re_a, re_b) in [(1.7, -0.3), (0.2, 2.9), (-4.0, 1e-3)] {
            for (ea, eb) in pairs {
                let (da, db) = (dual(re_a, ea), dual(re_b, eb));
                let (ta, tb): (Tangent<3>, Tangent<3>) = (Lanewise::splat(&da), Lanewise::splat(&db));
                same(ta + tb, da + db);
                same(ta - tb, da - db);
                same(ta * tb, da * db);
                same(ta / tb, da / db);
                same(-ta, -da);
                same(ta * 1.3, da * 1.3);
                same(ta / 1.3, da / 1.3);
                same(ta + 0.4, da + 0.4);
                same(ta - 0.4, da - 0.4);
                same(Real::abs(ta), num_traits::Signed::abs(&da));
                same(Real::exp(ta), DualNum::exp(&da));
                same(Real::sin(ta), DualNum::sin(&da));
                same(Real::cos(ta), DualNum::cos(&da));
                same(Real::tanh(ta), DualNum::tanh(&da));
                same([ta, tb, ta].into_iter().sum(), [da, db, da].into_iter().sum());
                let pos = Real::abs(ta) + 0.1;
                let dpos = num_traits::Signed::abs(&da) + 0.1;
                same(Real::ln(pos), DualNum::ln(&dpos));
                for n in [0.0, 1.0, 2.0, 1.5, 0.6, 3.7] {
                    same(Real::powf(pos, n), DualNum::powf(&dpos, n));
                }
                same(Real::pow(pos, tb), crate::numbers::scalar::Scalar::pow(dpos, db));
                same(
                    Real::pow(pos, Tangent::constant(1.8)),
                    crate::numbers::scalar::Scalar::pow(dpos, D::from(1.8)),
                );
            }
        }
    }

    #[test]
    fn a_seed_carries_its_own_derivative_only() {
        let x = Tangent::<3>::seed(2.0, 1);
        let y = Real::exp(x * x);
        assert_eq!(y.eps[0], 0.0);
        assert_eq!(y.eps[2], 0.0);
        assert!((y.eps[1] - 4.0 * 4f64.exp()).abs() < 1e-12 * 4f64.exp());
        assert!(Tangent::<3>::constant(1.5).is_exactly(1.5) && !x.is_exactly(2.0));
    }
}
