//! A [`Real`] that records what the physics does with it: every operation appends a node to a
//! tape (one per thread), shared values are recorded once, and the tape is written out as C
//! (`gpu/generate.rs`). Tracing `Model::rhs_impl` over [`Sym`] gives the GPU kernel's right-hand
//! side from the one Rust model: no physics is written twice.
//!
//! Its branches are the lanes' with lanes that disagree: [`Mask::all`] is false and
//! [`Mask::any`] true unless the mask is a known constant, so both sides of a branch are
//! recorded and [`Real::select`] becomes a C ternary. The physics is correct for lanes that
//! disagree, so it is correct here. Constants of the model enter as numbered inputs
//! ([`Sym::input`], read from the point's constants row), so one trace serves every point of one
//! [`crate::model::Shape`].

use std::cell::RefCell;
use std::collections::HashMap;
use std::iter::Sum;
use std::ops::{Add, AddAssign, Div, Mul, Neg, Sub, SubAssign};

use crate::numbers::lane_real::Lanewise;
use crate::numbers::real::{Mask, Real};

/// An operation of the tape. Numbers and truth values share it; each node is one or the other.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Node {
    /// Input `k` of the point's constants row.
    Constant(u32),
    /// A named variable of the generated function: `Var(k)` is `VARS[k]`-like, named by the tracer.
    Var(u32),
    /// A literal.
    Literal(f64),
    Neg(u32),
    Add(u32, u32),
    Sub(u32, u32),
    Mul(u32, u32),
    Div(u32, u32),
    Abs(u32),
    Exp(u32),
    Ln(u32),
    Sin(u32),
    Cos(u32),
    Tanh(u32),
    Pow(u32, u32),
    Sign0(u32),
    /// mask ? a : b
    Select(u32, u32, u32),
    /// a < b, a > b, a == b (truth values)
    Less(u32, u32),
    Greater(u32, u32),
    Equal(u32, u32),
    Or(u32, u32),
    /// a known truth value
    Truth(bool),
}

/// The recorded operations, in order (each refers only to earlier ones), with a table that
/// returns an existing node for an operation recorded before.
#[derive(Default)]
pub struct Tape {
    pub nodes: Vec<Node>,
    seen: HashMap<(u8, u64, u64, u64), u32>,
    /// the value of each constant input, in input order (what a point's row holds)
    pub constants: Vec<f64>,
}

thread_local! {
    static TAPE: RefCell<Tape> = RefCell::new(Tape::default());
}

/// Run `f` on a fresh tape of this thread and return its result with the tape.
pub fn record<R>(f: impl FnOnce() -> R) -> (R, Tape) {
    TAPE.with(|t| *t.borrow_mut() = Tape::default());
    let r = f();
    let tape = TAPE.with(|t| std::mem::take(&mut *t.borrow_mut()));
    (r, tape)
}

fn key(n: Node) -> (u8, u64, u64, u64) {
    let u = |x: u32| x as u64;
    match n {
        Node::Constant(k) => (0, u(k), 0, 0),
        Node::Var(k) => (1, u(k), 0, 0),
        Node::Literal(x) => (2, x.to_bits(), 0, 0),
        Node::Neg(a) => (3, u(a), 0, 0),
        Node::Add(a, b) => (4, u(a), u(b), 0),
        Node::Sub(a, b) => (5, u(a), u(b), 0),
        Node::Mul(a, b) => (6, u(a), u(b), 0),
        Node::Div(a, b) => (7, u(a), u(b), 0),
        Node::Abs(a) => (8, u(a), 0, 0),
        Node::Exp(a) => (9, u(a), 0, 0),
        Node::Ln(a) => (10, u(a), 0, 0),
        Node::Sin(a) => (11, u(a), 0, 0),
        Node::Cos(a) => (12, u(a), 0, 0),
        Node::Tanh(a) => (13, u(a), 0, 0),
        Node::Pow(a, b) => (14, u(a), u(b), 0),
        Node::Sign0(a) => (15, u(a), 0, 0),
        Node::Select(m, a, b) => (16, u(m), u(a), u(b)),
        Node::Less(a, b) => (17, u(a), u(b), 0),
        Node::Greater(a, b) => (18, u(a), u(b), 0),
        Node::Equal(a, b) => (19, u(a), u(b), 0),
        Node::Or(a, b) => (20, u(a), u(b), 0),
        Node::Truth(b) => (21, b as u64, 0, 0),
    }
}

/// Append `n` (or find it recorded before) and return its index.
fn push(n: Node) -> u32 {
    TAPE.with(|t| {
        let mut t = t.borrow_mut();
        let k = key(n);
        if let Some(&i) = t.seen.get(&k) {
            return i;
        }
        let i = t.nodes.len() as u32;
        t.nodes.push(n);
        t.seen.insert(k, i);
        i
    })
}

fn node(i: u32) -> Node {
    TAPE.with(|t| t.borrow().nodes[i as usize])
}

/// A number of the tape.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Sym(pub u32);

/// A truth value of the tape.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SymMask(pub u32);

impl Sym {
    /// The next input of the point's constants row, whose value here is `x`.
    pub fn input(x: f64) -> Sym {
        let k = TAPE.with(|t| {
            let mut t = t.borrow_mut();
            t.constants.push(x);
            t.constants.len() as u32 - 1
        });
        Sym(push(Node::Constant(k)))
    }
    /// Variable `k` of the generated function (a state component, the time, the input).
    pub fn var(k: u32) -> Sym {
        Sym(push(Node::Var(k)))
    }
    /// A literal.
    pub fn literal(x: f64) -> Sym {
        Sym(push(Node::Literal(x)))
    }
    fn literal_value(self) -> Option<f64> {
        match node(self.0) {
            Node::Literal(x) => Some(x),
            _ => None,
        }
    }
}

impl SymMask {
    fn known(self) -> Option<bool> {
        match node(self.0) {
            Node::Truth(b) => Some(b),
            _ => None,
        }
    }
}

impl Mask for SymMask {
    /// True only when known to be true (a recorded branch may take either side).
    fn all(self) -> bool {
        self.known().unwrap_or(false)
    }
    /// False only when known to be false.
    fn any(self) -> bool {
        self.known().unwrap_or(true)
    }
    fn or(self, o: Self) -> Self {
        match (self.known(), o.known()) {
            (Some(true), _) | (_, Some(true)) => SymMask(push(Node::Truth(true))),
            (Some(false), _) => o,
            (_, Some(false)) => self,
            _ => SymMask(push(Node::Or(self.0, o.0))),
        }
    }
}

/// A binary operation, folded where both sides are literals (exactly as f64 computes it) and
/// where the result is one side to the bit (x * 1, x / 1, x - 0): nothing else is rewritten, so
/// the generated code rounds as the engine does.
fn binary(a: Sym, b: Sym, f: fn(f64, f64) -> f64, make: fn(u32, u32) -> Node) -> Sym {
    if let (Some(x), Some(y)) = (a.literal_value(), b.literal_value()) {
        return Sym::literal(f(x, y));
    }
    let probe = make(0, 0);
    let one = |s: Sym| s.literal_value().is_some_and(|v| v.to_bits() == 1.0f64.to_bits());
    let zero = |s: Sym| s.literal_value().is_some_and(|v| v.to_bits() == 0.0f64.to_bits());
    match probe {
        Node::Mul(..) if one(b) => return a,
        Node::Mul(..) if one(a) => return b,
        Node::Div(..) if one(b) => return a,
        Node::Sub(..) if zero(b) => return a,
        _ => {}
    }
    Sym(push(make(a.0, b.0)))
}

fn unary(a: Sym, f: fn(f64) -> f64, make: fn(u32) -> Node) -> Sym {
    match a.literal_value() {
        Some(x) => Sym::literal(f(x)),
        None => Sym(push(make(a.0))),
    }
}

fn compare(a: Sym, b: f64, f: fn(f64, f64) -> bool, make: fn(u32, u32) -> Node) -> SymMask {
    match a.literal_value() {
        Some(x) => SymMask(push(Node::Truth(f(x, b)))),
        None => SymMask(push(make(a.0, Sym::literal(b).0))),
    }
}

macro_rules! sym_binary {
    ($tr:ident, $method:ident, $op:tt, $node:ident) => {
        impl $tr for Sym {
            type Output = Sym;
            fn $method(self, b: Sym) -> Sym {
                binary(self, b, |x, y| x $op y, Node::$node)
            }
        }
        impl $tr<f64> for Sym {
            type Output = Sym;
            fn $method(self, b: f64) -> Sym {
                binary(self, Sym::literal(b), |x, y| x $op y, Node::$node)
            }
        }
    };
}
sym_binary!(Add, add, +, Add);
sym_binary!(Sub, sub, -, Sub);
sym_binary!(Mul, mul, *, Mul);
sym_binary!(Div, div, /, Div);

impl Neg for Sym {
    type Output = Sym;
    fn neg(self) -> Sym {
        unary(self, |x| -x, Node::Neg)
    }
}
impl AddAssign for Sym {
    fn add_assign(&mut self, b: Sym) {
        *self = *self + b;
    }
}
impl SubAssign for Sym {
    fn sub_assign(&mut self, b: Sym) {
        *self = *self - b;
    }
}
impl Sum for Sym {
    fn sum<I: Iterator<Item = Sym>>(iter: I) -> Sym {
        // as f64's Sum: from 0.0, left to right
        iter.fold(Sym::literal(0.0), |a, b| a + b)
    }
}
impl From<f64> for Sym {
    fn from(x: f64) -> Sym {
        Sym::literal(x)
    }
}

impl Real for Sym {
    type Value = Sym;
    type Mask = SymMask;

    fn zero() -> Self {
        Sym::literal(0.0)
    }
    fn one() -> Self {
        Sym::literal(1.0)
    }
    fn value(&self) -> Sym {
        *self
    }
    fn of_value(v: Sym) -> Sym {
        v
    }
    fn abs(self) -> Self {
        unary(self, f64::abs, Node::Abs)
    }
    fn exp(self) -> Self {
        unary(self, f64::exp, Node::Exp)
    }
    fn powf(self, e: f64) -> Self {
        binary(self, Sym::literal(e), f64::powf, Node::Pow)
    }
    fn ln(self) -> Self {
        unary(self, f64::ln, Node::Ln)
    }
    fn sin(self) -> Self {
        unary(self, f64::sin, Node::Sin)
    }
    fn cos(self) -> Self {
        unary(self, f64::cos, Node::Cos)
    }
    fn tanh(self) -> Self {
        unary(self, f64::tanh, Node::Tanh)
    }
    fn pow(self, e: Self) -> Self {
        // f64's `Scalar::pow` is powf: C's pow
        binary(self, e, f64::powf, Node::Pow)
    }
    fn is_exactly(&self, x: f64) -> SymMask {
        compare(*self, x, |a, b| a == b, Node::Equal)
    }
    fn below(&self, x: f64) -> SymMask {
        compare(*self, x, |a, b| a < b, Node::Less)
    }
    fn above(&self, x: f64) -> SymMask {
        compare(*self, x, |a, b| a > b, Node::Greater)
    }
    fn equals(&self, x: f64) -> SymMask {
        compare(*self, x, |a, b| a == b, Node::Equal)
    }
    fn sign0(&self) -> Sym {
        unary(*self, |v| <f64 as Real>::sign0(&v), Node::Sign0)
    }
    fn choose(m: SymMask, a: impl FnOnce() -> Self, b: impl FnOnce() -> Self) -> Self {
        match m.known() {
            Some(true) => a(),
            Some(false) => b(),
            None => Self::select(m, a(), b()),
        }
    }
    fn select(m: SymMask, a: Self, b: Self) -> Self {
        match m.known() {
            Some(true) => a,
            Some(false) => b,
            None if a == b => a,
            None => Sym(push(Node::Select(m.0, a.0, b.0))),
        }
    }
    fn choose_n<const K: usize>(m: SymMask, a: impl FnOnce() -> [Self; K], b: impl FnOnce() -> [Self; K]) -> [Self; K] {
        match m.known() {
            Some(true) => a(),
            Some(false) => b(),
            None => {
                let (a, b) = (a(), b());
                std::array::from_fn(|k| Self::select(m, a[k], b[k]))
            }
        }
    }
    /// The piece holding `t` chosen by comparisons (`interpolate_one`'s pieces: [t_j, t_j+1),
    /// held outside).
    fn interpolate(values: &[Self], times: &[f64], t: Sym) -> (Self, Self) {
        let last = times.len() - 1;
        let (mut v, mut s) = (values[last], Sym::zero());
        for j in (0..last).rev() {
            let span = times[j + 1] - times[j];
            let w = (t - times[j]) / span;
            let (a, b) = (values[j], values[j + 1]);
            let inside = t.below(times[j + 1]);
            v = Self::select(inside, a + (b - a) * w, v);
            s = Self::select(inside, (b - a) / span, s);
        }
        let before = t.below(times[0]).or(t.equals(times[0]));
        (Self::select(before, values[0], v), Self::select(before, Sym::zero(), s))
    }
}

/// A model over [`Sym`] is built from an `f64` model as lanes are: each number becomes the next
/// input of the constants row (its value kept on the tape).
impl Lanewise<f64> for Sym {
    fn splat(src: &f64) -> Self {
        Sym::input(*src)
    }
    fn set_lane(&mut self, _i: usize, _src: &f64) {
        unreachable!("a symbolic model has one lane")
    }
}

/// A truth value of the model (a Stribeck peak or none, n = 1, ...) is a point's value, not the
/// shape's: it becomes the next input of the constants row (1 or 0), tested where it is used.
impl Lanewise<bool> for SymMask {
    fn splat(src: &bool) -> Self {
        let x = Sym::input(if *src { 1.0 } else { 0.0 });
        SymMask(push(Node::Greater(x.0, Sym::literal(0.5).0)))
    }
    fn set_lane(&mut self, _i: usize, _src: &bool) {
        unreachable!("a symbolic model has one lane")
    }
}

/// The tape's value of every node for the inputs `constants` and the variables `vars`, in f64
/// as the engine computes (truth values as 1 or 0): the reference the generated C is held to.
pub fn evaluate(nodes: &[Node], constants: &[f64], vars: &[f64]) -> Vec<f64> {
    let mut v = vec![0.0; nodes.len()];
    let truth = |b: bool| if b { 1.0 } else { 0.0 };
    for (i, n) in nodes.iter().enumerate() {
        let at = |k: u32| v[k as usize];
        v[i] = match *n {
            Node::Constant(k) => constants[k as usize],
            Node::Var(k) => vars[k as usize],
            Node::Literal(x) => x,
            Node::Truth(b) => truth(b),
            Node::Neg(a) => -at(a),
            Node::Add(a, b) => at(a) + at(b),
            Node::Sub(a, b) => at(a) - at(b),
            Node::Mul(a, b) => at(a) * at(b),
            Node::Div(a, b) => at(a) / at(b),
            Node::Abs(a) => at(a).abs(),
            Node::Exp(a) => at(a).exp(),
            Node::Ln(a) => at(a).ln(),
            Node::Sin(a) => at(a).sin(),
            Node::Cos(a) => at(a).cos(),
            Node::Tanh(a) => at(a).tanh(),
            Node::Pow(a, b) => at(a).powf(at(b)),
            Node::Sign0(a) => <f64 as Real>::sign0(&at(a)),
            Node::Select(m, a, b) => {
                if at(m) != 0.0 {
                    at(a)
                } else {
                    at(b)
                }
            }
            Node::Less(a, b) => truth(at(a) < at(b)),
            Node::Greater(a, b) => truth(at(a) > at(b)),
            Node::Equal(a, b) => truth(at(a) == at(b)),
            Node::Or(a, b) => truth(at(a) != 0.0 || at(b) != 0.0),
        };
    }
    v
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn operations_are_recorded_once_and_literals_fold() {
        let ((a, b, c), tape) = record(|| {
            let x = Sym::input(2.0);
            let a = (x * 3.0).exp() + x * 3.0;
            let b = Sym::literal(2.0) * 4.0 - 1.0;
            let c = x * 1.0 - 0.0;
            (a, b, c)
        });
        assert_eq!(tape.constants, vec![2.0]);
        // x, 3, x*3, exp(x*3), + : x*3 recorded once
        assert_eq!(tape.nodes.iter().filter(|n| matches!(n, Node::Mul(..))).count(), 1);
        assert!(matches!(tape.nodes[a.0 as usize], Node::Add(..)));
        assert_eq!(tape.nodes[b.0 as usize], Node::Literal(7.0));
        assert_eq!(tape.nodes[c.0 as usize], Node::Constant(0), "x * 1 - 0 is x to the bit");
    }

    #[test]
    fn a_branch_on_an_unknown_value_records_both_sides_and_a_known_one_only_its_own() {
        let (r, tape) = record(|| {
            let x = Sym::input(-1.0);
            let picked = Sym::choose(x.above(0.0), || x * 2.0, || -x);
            let known = Sym::choose(Sym::literal(1.0).above(0.0), || x, || panic!("not taken"));
            assert_eq!(known, x);
            assert!(!x.above(0.0).all() && x.above(0.0).any());
            picked
        });
        match tape.nodes[r.0 as usize] {
            Node::Select(m, a, b) => {
                assert!(matches!(tape.nodes[m as usize], Node::Greater(..)));
                assert!(matches!(tape.nodes[a as usize], Node::Mul(..)));
                assert!(matches!(tape.nodes[b as usize], Node::Neg(..)));
            }
            n => panic!("{n:?}"),
        }
    }
}
