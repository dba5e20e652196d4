//! `L` independent `f64` lanes as one [`Real`]: the number type on which the physics runs many
//! points at once. Every operation is a loop over the lanes that the compiler turns into vector
//! instructions of the width the processor has (the lane drivers run under `pulp`'s runtime
//! dispatch, `drive/`); each lane's arithmetic is the scalar `f64` operation, so a lane's
//! result is bitwise the scalar model's (no fused multiply-add: Rust does not contract). The one
//! choice is `exp`: the C library's per lane ([`LibmExp`], bitwise) or a vectorised polynomial
//! ([`PolyExp`], within 2 ulp; `numbers/fast_exp.rs`), fixed by the type parameter `E`.

// lane loops index several [f64; L] arrays by the same lane on purpose (the vectorised layout)
#![allow(clippy::needless_range_loop)]

use std::fmt::Debug;
use std::iter::Sum;
use std::marker::PhantomData;
use std::ops::{Add, AddAssign, Div, Mul, Neg, Sub, SubAssign};

use crate::numbers::fast_exp::exp_poly;
use crate::numbers::real::{interpolate_one, Mask, Real};

/// How a lane's `exp` is computed.
pub trait LaneExp: Copy + Send + Sync + Debug + PartialEq + 'static {
    fn exp(x: f64) -> f64;
}

/// The C library's `exp`, one lane at a time: bitwise the scalar model's.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct LibmExp;
impl LaneExp for LibmExp {
    #[inline(always)]
    fn exp(x: f64) -> f64 {
        x.exp()
    }
}

/// A branch-free polynomial `exp` that vectorises (see `fast_exp`).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct PolyExp;
impl LaneExp for PolyExp {
    #[inline(always)]
    fn exp(x: f64) -> f64 {
        exp_poly(x)
    }
}

/// One `f64` per lane.
#[derive(Debug, PartialEq)]
#[repr(transparent)]
pub struct Lanes<const L: usize, E = LibmExp>(pub [f64; L], PhantomData<E>);

// Copy whatever `E` is (a derive would ask `E: Copy`)
impl<const L: usize, E> Clone for Lanes<L, E> {
    #[inline(always)]
    fn clone(&self) -> Self {
        *self
    }
}
impl<const L: usize, E> Copy for Lanes<L, E> {}

/// One `bool` per lane.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LaneMask<const L: usize>(pub [bool; L]);

impl<const L: usize> Mask for LaneMask<L> {
    #[inline(always)]
    fn all(self) -> bool {
        self.0.iter().all(|b| *b)
    }
    #[inline(always)]
    fn any(self) -> bool {
        self.0.iter().any(|b| *b)
    }
    #[inline(always)]
    fn or(self, o: Self) -> Self {
        let mut m = self.0;
        for i in 0..L {
            m[i] |= o.0[i];
        }
        LaneMask(m)
    }
}

impl<const L: usize, E> Lanes<L, E> {
    #[inline(always)]
    pub fn new(x: [f64; L]) -> Self {
        Lanes(x, PhantomData)
    }
    #[inline(always)]
    pub fn splat(x: f64) -> Self {
        Lanes([x; L], PhantomData)
    }
    /// A state stored component by component (`y[j][i]`: component j of lane i, the lane
    /// drivers' layout) seen as one lane number per component, without a copy.
    #[inline(always)]
    pub fn view<const D: usize>(y: &[[f64; L]; D]) -> &[Self; D] {
        // SAFETY: `Lanes` is repr(transparent) over `[f64; L]` (its other field is a zero-sized
        // marker), so `[[f64; L]; D]` and `[Lanes<L, E>; D]` have the same size, alignment and
        // layout, and the borrow is carried over unchanged.
        unsafe { &*(y as *const [[f64; L]; D] as *const [Self; D]) }
    }
    /// [`Lanes::view`] for writing.
    #[inline(always)]
    pub fn view_mut<const D: usize>(y: &mut [[f64; L]; D]) -> &mut [Self; D] {
        // SAFETY: as in `view`; the exclusive borrow is carried over unchanged.
        unsafe { &mut *(y as *mut [[f64; L]; D] as *mut [Self; D]) }
    }
    #[inline(always)]
    fn map(self, f: impl Fn(f64) -> f64) -> Self {
        let mut o = self.0;
        for x in o.iter_mut() {
            *x = f(*x);
        }
        Lanes(o, PhantomData)
    }
    #[inline(always)]
    fn zip(self, b: Self, f: impl Fn(f64, f64) -> f64) -> Self {
        let mut o = self.0;
        for i in 0..L {
            o[i] = f(o[i], b.0[i]);
        }
        Lanes(o, PhantomData)
    }
    #[inline(always)]
    fn test(&self, f: impl Fn(f64) -> bool) -> LaneMask<L> {
        let mut m = [false; L];
        for i in 0..L {
            m[i] = f(self.0[i]);
        }
        LaneMask(m)
    }
}

impl<const L: usize, E> From<f64> for Lanes<L, E> {
    #[inline(always)]
    fn from(x: f64) -> Self {
        Lanes::splat(x)
    }
}

macro_rules! lane_ops {
    ($($tr:ident $f:ident $op:tt;)*) => {$(
        impl<const L: usize, E> $tr for Lanes<L, E> {
            type Output = Self;
            #[inline(always)]
            fn $f(self, b: Self) -> Self {
                self.zip(b, |x, y| x $op y)
            }
        }
        impl<const L: usize, E> $tr<f64> for Lanes<L, E> {
            type Output = Self;
            #[inline(always)]
            fn $f(self, b: f64) -> Self {
                self.map(|x| x $op b)
            }
        }
    )*};
}
lane_ops! {
    Add add +;
    Sub sub -;
    Mul mul *;
    Div div /;
}

impl<const L: usize, E> Neg for Lanes<L, E> {
    type Output = Self;
    #[inline(always)]
    fn neg(self) -> Self {
        self.map(|x| -x)
    }
}

impl<const L: usize, E> AddAssign for Lanes<L, E> {
    #[inline(always)]
    fn add_assign(&mut self, b: Self) {
        *self = *self + b;
    }
}

impl<const L: usize, E> SubAssign for Lanes<L, E> {
    #[inline(always)]
    fn sub_assign(&mut self, b: Self) {
        *self = *self - b;
    }
}

impl<const L: usize, E> Sum for Lanes<L, E> {
    fn sum<I: Iterator<Item = Self>>(iter: I) -> Self {
        // as f64's Sum: from 0.0, left to right
        iter.fold(Lanes::splat(0.0), |a, b| a + b)
    }
}

impl<const L: usize, E: LaneExp> Real for Lanes<L, E> {
    type Value = Self;
    type Mask = LaneMask<L>;

    #[inline(always)]
    fn zero() -> Self {
        Lanes::splat(0.0)
    }
    #[inline(always)]
    fn one() -> Self {
        Lanes::splat(1.0)
    }
    #[inline(always)]
    fn value(&self) -> Self {
        *self
    }
    #[inline(always)]
    fn of_value(v: Self) -> Self {
        v
    }
    #[inline(always)]
    fn abs(self) -> Self {
        self.map(f64::abs)
    }
    #[inline(always)]
    fn exp(self) -> Self {
        // a loop of its own: a library call per lane then has no vector registers live across
        // it to save (PolyExp vectorises either way)
        self.map(E::exp)
    }
    #[inline(always)]
    fn powf(self, e: f64) -> Self {
        self.map(|x| x.powf(e))
    }
    #[inline(always)]
    fn ln(self) -> Self {
        self.map(f64::ln)
    }
    #[inline(always)]
    fn sin(self) -> Self {
        self.map(f64::sin)
    }
    #[inline(always)]
    fn cos(self) -> Self {
        self.map(f64::cos)
    }
    #[inline(always)]
    fn tanh(self) -> Self {
        self.map(f64::tanh)
    }
    #[inline(always)]
    fn pow(self, e: Self) -> Self {
        // Scalar::pow for f64: powf, whose base <= 0 the physics never passes but which is 0 there
        // for the exponents it uses
        self.zip(e, <f64 as Real>::pow)
    }
    #[inline(always)]
    fn is_exactly(&self, x: f64) -> LaneMask<L> {
        self.test(|v| v == x)
    }
    #[inline(always)]
    fn below(&self, x: f64) -> LaneMask<L> {
        self.test(|v| v < x)
    }
    #[inline(always)]
    fn above(&self, x: f64) -> LaneMask<L> {
        self.test(|v| v > x)
    }
    #[inline(always)]
    fn equals(&self, x: f64) -> LaneMask<L> {
        self.test(|v| v == x)
    }
    #[inline(always)]
    fn sign0(&self) -> Self {
        self.map(|v| <f64 as Real>::sign0(&v))
    }
    #[inline(always)]
    fn choose(m: LaneMask<L>, a: impl FnOnce() -> Self, b: impl FnOnce() -> Self) -> Self {
        if m.all() {
            a()
        } else if !m.any() {
            b()
        } else {
            Self::select(m, a(), b())
        }
    }
    #[inline(always)]
    fn select(m: LaneMask<L>, a: Self, b: Self) -> Self {
        let mut o = b.0;
        for i in 0..L {
            if m.0[i] {
                o[i] = a.0[i];
            }
        }
        Lanes::new(o)
    }
    #[inline(always)]
    fn choose_n<const K: usize>(
        m: LaneMask<L>,
        a: impl FnOnce() -> [Self; K],
        b: impl FnOnce() -> [Self; K],
    ) -> [Self; K] {
        if m.all() {
            a()
        } else if !m.any() {
            b()
        } else {
            let (a, b) = (a(), b());
            std::array::from_fn(|k| Lanes::new(std::array::from_fn(|i| if m.0[i] { a[k].0[i] } else { b[k].0[i] })))
        }
    }
    #[inline]
    fn interpolate(values: &[Self], times: &[f64], t: Self) -> (Self, Self) {
        let (mut v, mut s) = ([0.0; L], [0.0; L]);
        let mut one = vec![0.0; values.len()];
        for i in 0..L {
            for (o, x) in one.iter_mut().zip(values) {
                *o = x.0[i];
            }
            (v[i], s[i]) = interpolate_one(&one, times, t.0[i], 0.0);
        }
        (Lanes::new(v), Lanes::new(s))
    }
}

/// A lane type built from its scalar counterpart `S`: every lane a copy of one, then each lane
/// set from its own (the lane drivers put each point's model on its lane this way). Implemented
/// beside each struct of the physics, field by field.
pub trait Lanewise<S>: Sized {
    /// Every lane `src`.
    fn splat(src: &S) -> Self;
    /// Lane `i` from `src` (which has the shape of the others: the lane gate checked it).
    fn set_lane(&mut self, i: usize, src: &S);
}

impl<const L: usize, E> Lanewise<f64> for Lanes<L, E> {
    #[inline(always)]
    fn splat(src: &f64) -> Self {
        Lanes::splat(*src)
    }
    #[inline(always)]
    fn set_lane(&mut self, i: usize, src: &f64) {
        self.0[i] = *src;
    }
}

impl<const L: usize> Lanewise<bool> for LaneMask<L> {
    fn splat(src: &bool) -> Self {
        LaneMask([*src; L])
    }
    fn set_lane(&mut self, i: usize, src: &bool) {
        self.0[i] = *src;
    }
}

impl<S, T: Lanewise<S>, const K: usize> Lanewise<[S; K]> for [T; K] {
    fn splat(src: &[S; K]) -> Self {
        std::array::from_fn(|k| T::splat(&src[k]))
    }
    fn set_lane(&mut self, i: usize, src: &[S; K]) {
        for (a, b) in self.iter_mut().zip(src) {
            a.set_lane(i, b);
        }
    }
}

impl<S, T: Lanewise<S>> Lanewise<Vec<S>> for Vec<T> {
    fn splat(src: &Vec<S>) -> Self {
        src.iter().map(T::splat).collect()
    }
    fn set_lane(&mut self, i: usize, src: &Vec<S>) {
        debug_assert_eq!(self.len(), src.len(), "lanes of one shape");
        for (a, b) in self.iter_mut().zip(src) {
            a.set_lane(i, b);
        }
    }
}

impl<S, T: Lanewise<S>> Lanewise<Option<S>> for Option<T> {
    fn splat(src: &Option<S>) -> Self {
        src.as_ref().map(T::splat)
    }
    fn set_lane(&mut self, i: usize, src: &Option<S>) {
        // the lane gate groups models of one shape: present in every lane or in none
        if let (Some(a), Some(b)) = (self.as_mut(), src.as_ref()) {
            a.set_lane(i, b);
        }
    }
}

impl<S: nalgebra::Scalar, T: nalgebra::Scalar + Lanewise<S>> Lanewise<nalgebra::DMatrix<S>> for nalgebra::DMatrix<T> {
    fn splat(src: &nalgebra::DMatrix<S>) -> Self {
        src.map(|x| T::splat(&x))
    }
    fn set_lane(&mut self, i: usize, src: &nalgebra::DMatrix<S>) {
        for (a, b) in self.iter_mut().zip(src.iter()) {
            a.set_lane(i, b);
        }
    }
}

/// A one-lane number is its own lane (the number types of one lane convert field by field).
impl Lanewise<bool> for bool {
    fn splat(src: &bool) -> Self {
        *src
    }
    fn set_lane(&mut self, _i: usize, src: &bool) {
        *self = *src;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    type L4 = Lanes<4>;

    #[test]
    fn each_lane_is_the_scalar_operation() {
        let x = L4::new([-1.5, 0.0, 2.25, 1e-300]);
        let y = L4::new([3.0, -0.0, -7.5, 2.0]);
        for (i, (a, b)) in x.0.iter().zip(y.0).enumerate() {
            assert_eq!((x * y + 1.0).0[i].to_bits(), (a * b + 1.0).to_bits());
            assert_eq!((x / y - x).0[i].to_bits(), (a / b - a).to_bits());
            assert_eq!(x.abs().exp().0[i].to_bits(), a.abs().exp().to_bits());
            assert_eq!(x.sign0().0[i], <f64 as Real>::sign0(a));
        }
    }

    #[test]
    fn choose_keeps_each_lanes_side_and_skips_a_side_no_lane_takes() {
        let x = L4::new([-1.0, 2.0, 0.0, 3.0]);
        let picked = L4::choose(x.above(0.0), || x * 10.0, || -x);
        assert_eq!(picked.0, [1.0, 20.0, -0.0, 30.0]);
        let only_a = L4::choose(LaneMask([true; 4]), || x, || panic!("no lane takes this side"));
        assert_eq!(only_a, x);
    }

    #[test]
    fn interpolation_is_per_lane() {
        let times = [0.0, 1.0, 2.0];
        let values = [
            L4::new([0.0, 0.0, 1.0, 5.0]),
            L4::new([2.0, 4.0, 1.0, 5.0]),
            L4::new([2.0, 0.0, 3.0, 5.0]),
        ];
        let (v, s) = L4::interpolate(&values, &times, L4::new([0.5, 1.5, -1.0, 9.0]));
        assert_eq!(v.0, [1.0, 2.0, 1.0, 5.0]);
        assert_eq!(s.0, [2.0, -4.0, 0.0, 0.0]);
    }
}
