//! The library's terms one by one along a run, for the regression discovery makes: each column
//! is the library force with that term's coefficient at 1 and every other at 0, computed by the
//! same code the model integrates (`Effects::library_force_main` / `library_force_weight`), so
//! what is regressed on and what is then simulated cannot differ.

use crate::error::InputError;
use crate::physics::effects::{Effects, LibraryStates, EFFECTS};

/// The wavelength parameter of the periodic terms (not a term of its own).
const WAVELENGTH: &str = "lib_wavelength";

/// The library's terms on the main body (`library_force`'s coefficients) and on the weight
/// (`library_force_weight`'s), as the catalogue declares them.
pub fn library_terms() -> (Vec<&'static str>, Vec<&'static str>) {
    let of = |id: &str| -> Vec<&'static str> {
        EFFECTS
            .iter()
            .filter(|e| e.id == id)
            .flat_map(|e| e.params.iter().map(|p| p.name))
            .filter(|n| *n != WAVELENGTH)
            .collect()
    };
    (of("library_force"), of("library_force_weight"))
}

/// Column `j` of the result (samples x terms, row-major) is term `names[j]`'s force [N] at each
/// of `states` with its coefficient at 1 (the periodic terms at `wavelength` [m]; 0 turns them
/// off); a name that is not a library term is refused, naming the terms.
pub fn library_columns(states: &[LibraryStates<f64>], names: &[&str], wavelength: f64) -> Result<Vec<f64>, InputError> {
    let (main, weight) = library_terms();
    let mut units = Vec::with_capacity(names.len());
    for name in names {
        let on_weight = weight.contains(name);
        if !on_weight && !main.contains(name) {
            return Err(crate::input!(
                "'{name}' is not a library term; the terms are {}",
                main.iter().chain(&weight).copied().collect::<Vec<_>>().join(", ")
            ));
        }
        let mut e = Effects::default();
        e.set(name, 1.0)?;
        e.set(WAVELENGTH, wavelength)?;
        units.push((e, on_weight));
    }
    let mut out = Vec::with_capacity(states.len() * names.len());
    for s in states {
        for (e, on_weight) in &units {
            out.push(if *on_weight {
                e.library_force_weight(s).0
            } else {
                e.library_force_main(s).0
            });
        }
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn state(x1: f64, v1: f64) -> LibraryStates<f64> {
        LibraryStates {
            x1,
            v1,
            x2: 0.3 * x1,
            v2: -0.5 * v1,
            volt: 70.0,
            dvolt: 1e4,
            ff: 1.2,
            t: 2e-3,
            vs: 1e-3,
        }
    }

    #[test]
    fn each_column_is_its_term_and_the_columns_weighted_are_the_library_force() {
        let (main, weight) = library_terms();
        assert_eq!(main.len() + weight.len(), 25);
        assert!(main.contains(&"lib_x1cube") && weight.contains(&"libw_vv") && !main.contains(&WAVELENGTH));
        let states = [state(2e-6, 3e-3), state(-5e-6, -1e-2)];
        let wl = 20e-6;
        let cols = library_columns(&states, &main, wl).unwrap();
        let at = |t: usize, name: &str| cols[t * main.len() + main.iter().position(|n| *n == name).unwrap()];
        let s = states[1];
        assert_eq!(at(1, "lib_x1cube"), s.x1 * s.x1 * s.x1);
        assert_eq!(at(1, "lib_sgn"), (s.v1 / s.vs).tanh());
        assert_eq!(
            at(1, "lib_ff_sin"),
            s.ff * (2.0 * std::f64::consts::PI / wl * s.x1).sin()
        );
        assert_eq!(at(1, "lib_dx"), s.x1 - s.x2);
        // any combination of coefficients is the columns weighted by them (to rounding)
        let mut e = Effects::default();
        e.set(WAVELENGTH, wl).unwrap();
        let coef: Vec<f64> = (0..main.len()).map(|j| 0.1 + 0.37 * j as f64).collect();
        for (n, c) in main.iter().zip(&coef) {
            e.set(n, *c).unwrap();
        }
        for (t, s) in states.iter().enumerate() {
            let sum: f64 = (0..main.len()).map(|j| coef[j] * cols[t * main.len() + j]).sum();
            let f = e.library_force_main(s).0;
            assert!((sum - f).abs() <= 1e-12 * f.abs().max(1.0), "{sum} {f}");
        }
        let w = library_columns(&states, &weight, wl).unwrap();
        assert_eq!(
            w[weight.iter().position(|n| *n == "libw_dx").unwrap()],
            states[0].x2 - states[0].x1
        );
        let err = library_columns(&states, &["lib_wavelength"], wl).unwrap_err();
        assert!(
            err.contains("not a library term") && err.contains("libw_dvolt"),
            "{err}"
        );
    }
}
