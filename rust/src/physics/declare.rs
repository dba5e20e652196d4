//! The shape of a declaration: a named quantity with its symbol, unit, meaning, domain of
//! validity and value, and an effect as a list of them. `physics/params.rs` declares Table 1 and
//! `physics/effects.rs` the effect catalogue in these terms; validation, name lookup and the Python
//! side (units in sweeps, the diagnosis catalogue, the report) all read those tables.

use crate::error::InputError;

/// Where a value is physically meaningful. Every value must also be finite.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Domain {
    /// any finite value
    Finite,
    /// v > 0
    Positive,
    /// v >= 0
    NonNegative,
    /// lower < v < upper; `text` writes the interval in messages, e.g. "(-pi/2, pi/2)"
    Open { lower: f64, upper: f64, text: &'static str },
}

impl Domain {
    /// Smallest allowed value (itself excluded unless [`Domain::lower_closed`]).
    pub const fn lower(&self) -> f64 {
        match self {
            Domain::Finite => f64::NEG_INFINITY,
            Domain::Positive | Domain::NonNegative => 0.0,
            Domain::Open { lower, .. } => *lower,
        }
    }

    /// Largest allowed value (always excluded: every upper end is open or infinite).
    pub const fn upper(&self) -> f64 {
        match self {
            Domain::Open { upper, .. } => *upper,
            _ => f64::INFINITY,
        }
    }

    /// Whether the lower end itself is allowed.
    pub const fn lower_closed(&self) -> bool {
        matches!(self, Domain::NonNegative)
    }

    /// The rule in words, as validation messages write it after "must ".
    pub fn rule(&self) -> String {
        match self {
            Domain::Finite => "be finite".into(),
            Domain::Positive => "be positive".into(),
            Domain::NonNegative => "be non-negative".into(),
            Domain::Open { text, .. } => format!("lie in {text}"),
        }
    }

    /// Whether a finite `v` lies in the domain.
    pub fn contains(&self, v: f64) -> bool {
        match self {
            Domain::Finite => true,
            Domain::Positive => v > 0.0,
            Domain::NonNegative => v >= 0.0,
            Domain::Open { lower, upper, .. } => *lower < v && v < *upper,
        }
    }
}

/// One declared quantity (SI).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ParamDecl {
    /// name in code, files and the Python API, e.g. "pe_youngs"
    pub name: &'static str,
    /// the paper's symbol, e.g. "Ep"
    pub symbol: &'static str,
    /// SI unit; "1" for a dimensionless number
    pub unit: &'static str,
    /// what it is, in a few words
    pub meaning: &'static str,
    pub domain: Domain,
    /// Table 1's value, or an effect parameter's "no effect" value; NaN: derived from other
    /// parameters (the normal force, see `Params::paper`)
    pub value: f64,
}

/// What an effect changes in the model.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum EffectKind {
    /// an extra force or state in the engine; its parameters are fields of `Effects`
    Term,
    /// a different structure (LPS -> DPS); no parameters
    Structure,
    /// a part of the paper's own model that the nominal model leaves out (its parameters are
    /// Table 1 values or a reparametrisation of them)
    Parameter,
}

impl EffectKind {
    pub const fn name(&self) -> &'static str {
        match self {
            EffectKind::Term => "term",
            EffectKind::Structure => "structure",
            EffectKind::Parameter => "parameter",
        }
    }
}

/// What an effect acts on. A mechanism runs the effects whose parts it has (a friction rig:
/// the main body and the reading; no piezo element, no weight), refusing the others by name.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Part {
    /// the main body (a force on it, or its friction)
    Main,
    /// the weight (a force on it)
    Weight,
    /// the piezo element or its voltage
    Piezo,
    /// the sensor's reading only
    Reading,
}

impl Part {
    pub fn name(self) -> &'static str {
        match self {
            Part::Main => "main body",
            Part::Weight => "weight",
            Part::Piezo => "piezo element",
            Part::Reading => "reading",
        }
    }
}

/// One effect of the catalogue (docs/RECORDINGS.md).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct EffectDecl {
    /// catalogue id, e.g. "spring_to_ground"
    pub id: &'static str,
    pub kind: EffectKind,
    /// the physics in one line
    pub physics: &'static str,
    /// the term it adds to the nominal equations, as text
    pub term: &'static str,
    /// the parts of the device it acts on
    pub acts_on: &'static [Part],
    pub params: &'static [ParamDecl],
}

/// Check `values` (in the order of `decls`) against their domains. Finiteness comes first, then
/// each kind of domain in turn (positive, non-negative, open interval), so a value set with
/// several errors is named as the hand-written checks named it. `what` starts the message:
/// "parameter" or "effect parameter".
pub fn check_domains(what: &str, decls: &[ParamDecl], values: &[f64]) -> Result<(), InputError> {
    debug_assert_eq!(decls.len(), values.len());
    for (d, &v) in decls.iter().zip(values) {
        if !v.is_finite() {
            return Err(crate::input!("{what} '{}' must be finite, got {v}", d.name));
        }
    }
    let passes: [fn(&Domain) -> bool; 3] = [
        |d| matches!(d, Domain::Positive),
        |d| matches!(d, Domain::NonNegative),
        |d| matches!(d, Domain::Open { .. }),
    ];
    for pass in passes {
        for (d, &v) in decls.iter().zip(values) {
            if pass(&d.domain) && !d.domain.contains(v) {
                return Err(crate::input!("{what} '{}' must {}, got {v}", d.name, d.domain.rule()));
            }
        }
    }
    Ok(())
}

/// Byte-wise string equality, usable in `const` items.
pub const fn same_name(a: &str, b: &str) -> bool {
    let (a, b) = (a.as_bytes(), b.as_bytes());
    if a.len() != b.len() {
        return false;
    }
    let mut i = 0;
    while i < a.len() {
        if a[i] != b[i] {
            return false;
        }
        i += 1;
    }
    true
}

#[cfg(test)]
mod tests {
    use super::*;

    const DECLS: [ParamDecl; 2] = [
        ParamDecl {
            name: "a",
            symbol: "a",
            unit: "1",
            meaning: "",
            domain: Domain::Open {
                lower: -1.0,
                upper: 1.0,
                text: "(-1, 1)",
            },
            value: 0.0,
        },
        ParamDecl {
            name: "b",
            symbol: "b",
            unit: "s",
            meaning: "",
            domain: Domain::NonNegative,
            value: 0.0,
        },
    ];

    #[test]
    fn domains_name_the_value_and_the_rule() {
        assert!(check_domains("x", &DECLS, &[0.5, 0.0]).is_ok());
        assert_eq!(
            check_domains("x", &DECLS, &[1.0, 0.0]).unwrap_err().0,
            "x 'a' must lie in (-1, 1), got 1"
        );
        // non-negative is checked before open intervals, whatever the order of declaration
        assert!(check_domains("x", &DECLS, &[2.0, -1.0])
            .unwrap_err()
            .contains("'b' must be non-negative"));
        assert!(check_domains("x", &DECLS, &[2.0, f64::NAN])
            .unwrap_err()
            .contains("'b' must be finite"));
    }

    #[test]
    fn names_compare_in_const_context() {
        const SAME: bool = same_name("kappa", "kappa");
        assert!(SAME && !same_name("kappa", "kapa") && !same_name("eps", "epx"));
    }
}
