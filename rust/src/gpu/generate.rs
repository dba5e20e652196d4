//! The GPU kernel's right-hand side, generated from the one Rust model: `Model::rhs_impl` traced
//! over [`Sym`] (`numbers/symbolic.rs`) for a model's [`Shape`] and written out as a C function
//! `idm_rhs` with the layout `#define`s the kernel's integrators read. Every catalogue effect
//! and the library forces are in the trace; what it cannot hold (a rig, a sampled external
//! force, more than `MAX_DOF` nodes) is refused by name.
//!
//! A point's constants row is the model's numbers in the order the trace read them (only those
//! the right-hand side uses), then [`HOST_SCALARS`]: packed by [`Generated::constants`] for every
//! model of the traced shape.

use std::fmt::Write;

use crate::gpu::kernel::MAX_DOF;
use crate::model::{Model, ScaleKind, Shape};
use crate::numbers::lane_real::Lanewise;
use crate::numbers::real::Real;
use crate::numbers::symbolic::{record, Node, Sym, Tape};
use crate::physics::mechanics::Actuator;

/// The numbers after the traced constants, which the integrators (not the right-hand side) read:
/// the |Fh| bound [N] (divergence), the slip-fraction threshold [m/s], and the error norm's
/// parts (`Model::scale_parts`: stroke per volt [m/V], the LPS frequency [rad/s], Fs [N]).
pub const HOST_SCALARS: [&str; 5] = ["FH_BOUND", "SLIP_V", "STROKE_PER_V", "OMEGA", "FS"];

/// A traced right-hand side: its C source and which of the model's numbers it reads.
#[derive(Clone, Debug)]
pub struct Generated {
    /// the layout `#define`s (nodes, state size, indices, error scales, the constants row)
    pub layout: String,
    /// the C function `idm_rhs`
    pub rhs: String,
    /// the shape every model it runs must have
    pub shape: Shape,
    /// the indices, among the numbers a symbolic model reads in order, of those the right-hand
    /// side uses (a point's row, in this order)
    used: Vec<usize>,
}

/// Why the kernel cannot run `model`, or nothing.
pub fn refusal(model: &Model) -> Option<String> {
    let n = model.layout.dof;
    if n > MAX_DOF {
        return Some(format!(
            "the GPU kernel holds at most {MAX_DOF} nodes (DPS with {} elements); got {n}",
            MAX_DOF - 1
        ));
    }
    if matches!(model.actuator, Actuator::Rig(_)) {
        return Some("the GPU kernel runs the IDM, not a rig".into());
    }
    if model.external.is_some() {
        return Some("the GPU kernel has no sampled external force (use the CPU backend)".into());
    }
    if model.layout.accounting.is_some() {
        return Some("the GPU kernel keeps no energy accounting (use the CPU backend)".into());
    }
    None
}

/// `model`'s right-hand side on a tape: (dy, Ff) over the variables y (0..dim), t (dim), the
/// voltage (dim + 1) and its rate (dim + 2).
fn record_rhs(model: &Model) -> ((Vec<Sym>, Sym), Tape) {
    let dim = model.layout.dim;
    record(|| {
        let m = <Model<Sym> as Lanewise<Model>>::splat(model);
        let y: Vec<Sym> = (0..dim as u32).map(Sym::var).collect();
        let (t, volt, dvolt) = (Sym::var(dim as u32), Sym::var(dim as u32 + 1), Sym::var(dim as u32 + 2));
        let mut dy = vec![Sym::zero(); dim];
        let (ff, _) = m.rhs_impl::<0, true>(t, volt, dvolt, &y, &mut dy);
        (dy, ff)
    })
}

/// The numbers a symbolic model built from `model` reads, in order.
fn model_numbers(model: &Model) -> Vec<f64> {
    record(|| {
        let _ = <Model<Sym> as Lanewise<Model>>::splat(model);
    })
    .1
    .constants
}

impl Generated {
    /// Trace `model`'s right-hand side (the same for every model of its shape).
    pub fn trace(model: &Model) -> Result<Generated, String> {
        if let Some(why) = refusal(model) {
            return Err(why);
        }
        let dim = model.layout.dim;
        let ((dy, ff), tape) = record_rhs(model);
        let (rhs, used) = emit(&tape.nodes, &dy, ff, dim);
        Ok(Generated {
            layout: header(model, used.len()),
            rhs,
            shape: model.shape(),
            used,
        })
    }

    /// Number of constants per point: the traced ones, then [`HOST_SCALARS`].
    pub fn row_len(&self) -> usize {
        self.used.len() + HOST_SCALARS.len()
    }

    /// `model`'s constants row, or why it cannot share this trace.
    pub fn constants(&self, model: &Model) -> Result<Vec<f64>, String> {
        if let Some(why) = refusal(model) {
            return Err(why);
        }
        if model.shape() != self.shape {
            return Err(
                "its state differs from the other points' (an effect that adds a state, such as a lag, \
                 is on at some points and off at others): split the sweep there or use the CPU backend"
                    .into(),
            );
        }
        let all = model_numbers(model);
        let mut row: Vec<f64> = self.used.iter().map(|&k| all[k]).collect();
        let (stroke_per_v, omega, fs) = model.scale_parts();
        row.extend([
            model.presliding_bound(),
            crate::batch::slip_velocity(model),
            stroke_per_v,
            omega,
            fs,
        ]);
        Ok(row)
    }
}

/// The layout `#define`s of `model`'s shape: nodes, state size, the indices the integrators
/// read, the error norm's kind of each component, the constants row.
fn header(model: &Model, traced: usize) -> String {
    let l = &model.layout;
    let mut h =
        String::from("/* generated by idm-rs (rust/src/gpu/generate.rs): Model::rhs_impl traced for one shape */\n");
    let _ = writeln!(h, "#define IDM_N {}\n#define IDM_DIM {}", l.dof, l.dim);
    let _ = writeln!(h, "#define IDM_IG {}\n#define IDM_IFH {}", l.g, l.fh);
    let kinds = model.state_scale_kinds();
    let code = |k: &ScaleKind| match k {
        ScaleKind::Excluded => 0,
        ScaleKind::Stroke => 1,
        ScaleKind::Velocity => 2,
        ScaleKind::Force => 3,
        ScaleKind::Voltage => 4,
    };
    let list: Vec<String> = kinds.iter().map(|k| code(k).to_string()).collect();
    let _ = writeln!(h, "#define IDM_SCALE_KINDS {{{}}}", list.join(", "));
    let in_norm = kinds.iter().filter(|k| **k != ScaleKind::Excluded).count().max(1);
    let _ = writeln!(h, "#define IDM_IN_NORM {in_norm}");
    let _ = writeln!(h, "#define IDM_NK {traced}");
    for (i, name) in HOST_SCALARS.iter().enumerate() {
        let _ = writeln!(h, "#define IDM_H_{name} (IDM_NK + {i})");
    }
    let _ = writeln!(h, "#define IDM_NC (IDM_NK + {})", HOST_SCALARS.len());
    h
}

/// A literal as C reads it, to the bit.
fn literal(x: f64) -> String {
    if x.is_nan() {
        "IDM_NAN".into()
    } else if x.is_infinite() {
        if x > 0.0 { "IDM_INF" } else { "(-IDM_INF)" }.into()
    } else if x < 0.0 || (x == 0.0 && x.is_sign_negative()) {
        format!("(-{:?})", -x)
    } else {
        format!("{x:?}")
    }
}

/// The C function `idm_rhs` computing `dy` and returning `ff`, and the constants it reads (their
/// indices among the tape's inputs, in the order of the row it reads them from).
///
/// A value used once is written into the expression that uses it, so a side of a branch is
/// computed only where it is taken (C's `?:` evaluates one side: the Stribeck exponential and
/// the `pow`s of the friction law run only at the points whose law needs them, as in the engine);
/// a value used more than once is computed once into a `const` ahead of its first use.
fn emit(nodes: &[Node], dy: &[Sym], ff: Sym, dim: usize) -> (String, Vec<usize>) {
    let mut uses = vec![0u32; nodes.len()];
    for s in dy.iter().chain([&ff]) {
        uses[s.0 as usize] += 1;
    }
    // from the last node back: a node is live when something live reads it
    for i in (0..nodes.len()).rev() {
        if uses[i] > 0 {
            for a in operands(nodes[i]) {
                uses[a as usize] += 1;
            }
        }
    }
    let mut e = Emitter {
        nodes,
        uses: &uses,
        dim,
        slot: vec![None; nodes.len()],
        named: vec![false; nodes.len()],
        used: Vec::new(),
        body: String::new(),
    };
    // the constants are read where first needed (they were recorded first, with the model)
    for i in 0..nodes.len() {
        if uses[i] > 1
            && !matches!(
                nodes[i],
                Node::Var(_) | Node::Literal(_) | Node::Truth(_) | Node::Constant(_)
            )
        {
            e.declare(i);
        }
    }
    let outputs: Vec<String> = dy.iter().map(|s| e.expr(s.0 as usize)).collect();
    let ret = e.expr(ff.0 as usize);
    let mut f = String::from(
        "/* dy/dt of the state at time t [s], the commanded voltage volt [V] rising at dvolt [V/s];\n \
         * returns the friction force Ff [N]. c: the point's constants row. */\n\
         IDM_HD double idm_rhs(const double *c, double t, double volt, double dvolt, const double *y, double *dy) {\n\
         \x20   (void)c; (void)t; (void)volt; (void)dvolt;\n",
    );
    f += &e.body;
    for (i, o) in outputs.iter().enumerate() {
        let _ = writeln!(f, "    dy[{i}] = {o};");
    }
    let _ = writeln!(f, "    return {ret};\n}}");
    (f, e.used)
}

/// The writer of [`emit`]: each node as an expression, or as the name of the `const` that holds it.
struct Emitter<'a> {
    nodes: &'a [Node],
    uses: &'a [u32],
    dim: usize,
    /// each constant input's place in the row, once read
    slot: Vec<Option<usize>>,
    /// whether a node is held in a `const` already written
    named: Vec<bool>,
    used: Vec<usize>,
    body: String,
}

impl Emitter<'_> {
    /// Write node `i` into a `const` (what it reads written first).
    fn declare(&mut self, i: usize) {
        let rhs = self.value(i);
        let ty = if is_truth(self.nodes[i]) { "int" } else { "double" };
        let _ = writeln!(self.body, "    const {ty} s{i} = {rhs};");
        self.named[i] = true;
    }

    /// Node `i` where it is used: its name, or its expression when used once.
    fn expr(&mut self, i: usize) -> String {
        if self.named[i] {
            return format!("s{i}");
        }
        match self.nodes[i] {
            Node::Var(_) | Node::Literal(_) | Node::Truth(_) => self.value(i),
            Node::Constant(_) if self.uses[i] == 1 => self.value(i),
            _ if self.uses[i] > 1 => {
                self.declare(i);
                format!("s{i}")
            }
            _ => format!("({})", self.value(i)),
        }
    }

    /// The C expression of node `i` over its operands.
    fn value(&mut self, i: usize) -> String {
        match self.nodes[i] {
            Node::Constant(k) => {
                let j = *self.slot[i].get_or_insert_with(|| {
                    self.used.push(k as usize);
                    self.used.len() - 1
                });
                format!("IDM_CK(c, {j})")
            }
            Node::Var(k) => match k as usize {
                k if k < self.dim => format!("y[{k}]"),
                k if k == self.dim => "t".into(),
                k if k == self.dim + 1 => "volt".into(),
                _ => "dvolt".into(),
            },
            Node::Literal(x) => literal(x),
            Node::Truth(b) => (b as i32).to_string(),
            Node::Neg(x) => format!("-{}", self.expr(x as usize)),
            Node::Add(x, y) => self.infix(x, "+", y),
            Node::Sub(x, y) => self.infix(x, "-", y),
            Node::Mul(x, y) => self.infix(x, "*", y),
            Node::Div(x, y) => self.infix(x, "/", y),
            Node::Less(x, y) => self.infix(x, "<", y),
            Node::Greater(x, y) => self.infix(x, ">", y),
            Node::Equal(x, y) => self.infix(x, "==", y),
            Node::Or(x, y) => self.infix(x, "||", y),
            Node::Abs(x) => format!("fabs({})", self.expr(x as usize)),
            Node::Exp(x) => format!("exp({})", self.expr(x as usize)),
            Node::Ln(x) => format!("log({})", self.expr(x as usize)),
            // the kernel's own sin and cos (see idm_kernel.cu: no stack on the GPU)
            Node::Sin(x) => format!("IDM_SIN({})", self.expr(x as usize)),
            Node::Cos(x) => format!("IDM_COS({})", self.expr(x as usize)),
            Node::Tanh(x) => format!("tanh({})", self.expr(x as usize)),
            Node::Pow(x, y) => {
                let (a, b) = (self.expr(x as usize), self.expr(y as usize));
                format!("pow({a}, {b})")
            }
            Node::Sign0(x) => {
                let a = self.expr(x as usize);
                format!("{a} > 0.0 ? 1.0 : ({a} < 0.0 ? -1.0 : 0.0)")
            }
            Node::Select(m, x, y) => {
                let c = self.expr(m as usize);
                // each side's own values are written inside it: computed only where taken
                let (a, b) = (self.expr(x as usize), self.expr(y as usize));
                format!("{c} ? {a} : {b}")
            }
        }
    }

    fn infix(&mut self, x: u32, op: &str, y: u32) -> String {
        let (a, b) = (self.expr(x as usize), self.expr(y as usize));
        format!("{a} {op} {b}")
    }
}

fn is_truth(n: Node) -> bool {
    matches!(
        n,
        Node::Less(..) | Node::Greater(..) | Node::Equal(..) | Node::Or(..) | Node::Truth(_)
    )
}

/// The nodes `n` reads.
fn operands(n: Node) -> Vec<u32> {
    match n {
        Node::Constant(_) | Node::Var(_) | Node::Literal(_) | Node::Truth(_) => vec![],
        Node::Neg(a)
        | Node::Abs(a)
        | Node::Exp(a)
        | Node::Ln(a)
        | Node::Sin(a)
        | Node::Cos(a)
        | Node::Tanh(a)
        | Node::Sign0(a) => vec![a],
        Node::Add(a, b)
        | Node::Sub(a, b)
        | Node::Mul(a, b)
        | Node::Div(a, b)
        | Node::Pow(a, b)
        | Node::Less(a, b)
        | Node::Greater(a, b)
        | Node::Equal(a, b)
        | Node::Or(a, b) => vec![a, b],
        Node::Select(m, a, b) => vec![m, a, b],
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::physics::effects::{Effects, EFFECT_NAMES};
    use crate::physics::mechanics::Structure;
    use crate::physics::params::Params;

    fn model(e: Effects, s: Structure, hyst: bool) -> Model {
        Model::new(Params::paper(), e, s, hyst, false).unwrap()
    }

    #[test]
    fn the_paper_lps_traces_to_a_function_of_its_constants() {
        let g = Generated::trace(&model(Effects::default(), Structure::Lps, true)).unwrap();
        assert!(g.layout.contains("#define IDM_N 2\n") && g.layout.contains("#define IDM_DIM 7\n"));
        assert!(g.rhs.contains("IDM_HD double idm_rhs(") && g.rhs.contains("exp("));
        let m = model(Effects::default(), Structure::Lps, true);
        let row = g.constants(&m).unwrap();
        // the friction law's branches are the point's: n = 1 is read from the row, not traced in
        let mut p = Params::paper();
        p.fric_n = 2.0;
        let n2 = Model::new(p, Effects::default(), Structure::Lps, true, false).unwrap();
        assert_eq!(Generated::trace(&n2).unwrap().rhs, g.rhs);
        assert_ne!(g.constants(&n2).unwrap(), row);
        assert_eq!(row.len(), g.row_len());
        assert!(row.iter().all(|x| x.is_finite()));
        assert_eq!(row[g.used.len()], m.presliding_bound());
        // a different point of the same shape shares the trace; its row differs
        let mut p = Params::paper();
        p.m2 *= 2.0;
        let other = Model::new(p, Effects::default(), Structure::Lps, true, false).unwrap();
        assert_ne!(g.constants(&other).unwrap(), row);
        assert_eq!(Generated::trace(&other).unwrap().rhs, g.rhs);
    }

    #[test]
    fn every_effect_is_traced_and_a_different_state_is_refused() {
        let plain = Generated::trace(&model(Effects::default(), Structure::Dps(4), false)).unwrap();
        for name in EFFECT_NAMES {
            let mut e = Effects::default();
            let v = if name.starts_with("tau") { 1e-4 } else { 0.1 };
            if e.set(name, v).is_err() {
                continue;
            }
            if name == "kappa" {
                e.set("tau_creep", 1e-3).unwrap();
            }
            let m = model(e, Structure::Dps(4), false);
            let g = Generated::trace(&m).unwrap_or_else(|why| panic!("{name}: {why}"));
            assert!(g.constants(&m).is_ok(), "{name}");
            if m.shape() != plain.shape {
                assert!(plain.constants(&m).unwrap_err().contains("split the sweep"), "{name}");
            }
        }
    }

    /// The tape, evaluated in f64, is the engine's right-hand side to the bit, for every effect
    /// and library term on the DPS with hysteresis, at states on both sides of every branch
    /// (sliding both ways, stuck, |Fh| near its bound) and for a point with other values than the
    /// traced one (its branches taken the other way: n != 1, delta != 2, no Stribeck peak).
    #[test]
    fn the_trace_is_the_engines_right_hand_side_to_the_bit() {
        use crate::numbers::symbolic::evaluate;
        let mut cases: Vec<Effects> = vec![Effects::default()];
        for name in EFFECT_NAMES {
            let mut e = Effects::default();
            let v = if name.starts_with("tau") {
                1e-4
            } else if name.starts_with("lib") {
                0.3
            } else {
                0.05
            };
            e.set(name, v).unwrap();
            if name == "kappa" {
                e.set("tau_creep", 1e-3).unwrap();
            }
            cases.push(e);
        }
        let mut other = Params::paper();
        (other.fric_n, other.stribeck_exponent, other.mu_s) = (1.7, 1.3, other.mu_k);
        for e in cases {
            for (p, s) in [(Params::paper(), Structure::Dps(3)), (other, Structure::Lps)] {
                let traced = Model::new(Params::paper(), e, s, true, false).unwrap();
                let m = Model::new(p, e, s, true, false).unwrap();
                let ((dy, ff), _) = record_rhs(&traced);
                let tape = record_rhs(&m).1; // the same nodes, this point's constants
                let dim = m.layout.dim;
                for (k, (v1, fh)) in [
                    (0.02, 0.3),
                    (-0.015, -0.8),
                    (0.0, 0.1),
                    (1e-7, 0.999 * m.presliding_bound()),
                ]
                .into_iter()
                .enumerate()
                {
                    let mut y: Vec<f64> = (0..dim).map(|i| 1e-7 * (i as f64 + 1.0) * (k as f64 - 1.5)).collect();
                    (y[m.layout.dof], y[m.layout.fh]) = (v1, fh);
                    let (t, volt, dvolt) = (1.3e-3, 73.0, -2.1e5 * (k as f64 - 1.0));
                    let mut want = vec![0.0; dim];
                    let (ff_want, _) = m.rhs_impl::<0, true>(t, volt, dvolt, &y, &mut want);
                    let vars: Vec<f64> = y.iter().copied().chain([t, volt, dvolt]).collect();
                    let v = evaluate(&tape.nodes, &tape.constants, &vars);
                    for i in 0..dim {
                        assert_eq!(
                            v[dy[i].0 as usize].to_bits(),
                            want[i].to_bits(),
                            "{e:?} dy[{i}] state {k}"
                        );
                    }
                    assert_eq!(v[ff.0 as usize].to_bits(), ff_want.to_bits(), "Ff, state {k}");
                }
            }
        }
    }

    #[test]
    fn literals_read_back_to_the_bit() {
        for x in [0.1, -2.5e-300, 1e22, 3.0, -0.0, f64::MIN_POSITIVE, 0.3 * 3.0, 5e-324] {
            let s = literal(x);
            let t = s.trim_start_matches("(-").trim_end_matches(')');
            let back: f64 = t.parse().unwrap();
            let back = if s.starts_with("(-") { -back } else { back };
            assert_eq!(back.to_bits(), x.to_bits(), "{s}");
        }
    }
}
