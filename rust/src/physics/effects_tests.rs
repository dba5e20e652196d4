//! The effect catalogue's declarations, setters and forces.

use super::*;

#[test]
fn incline_pulls_backward_for_positive_tilt() {
    let e = Effects {
        theta_rad: 0.01,
        ..Default::default()
    };
    assert!((e.incline_force(1.0) + GRAVITY * 0.01f64.sin()).abs() < 1e-15);
    assert!(e.normal_scale() < 1.0);
}

#[test]
fn bad_effect_values_are_named() {
    assert!(Effects::from_pairs(&[("tau_amp", -1.0)])
        .unwrap_err()
        .contains("'tau_amp'"));
    assert!(Effects::from_pairs(&[("eps", 1.5)]).unwrap_err().contains("'eps'"));
    assert!(Effects::from_pairs(&[("wind", 1.0)]).unwrap_err().contains("'wind'"));
}

#[test]
fn every_field_is_declared_once_with_a_unit() {
    let mut e = Effects::default();
    for (i, d) in EFFECT_PARAMS.iter().enumerate() {
        assert_eq!(EFFECT_NAMES[i], d.name);
        assert!(!d.unit.is_empty(), "{}", d.name);
        assert_eq!(d.value, 0.0, "{}: off at 0", d.name);
        let owners: Vec<&str> = EFFECTS
            .iter()
            .filter(|x| x.params.iter().any(|p| p.name == d.name))
            .map(|x| x.id)
            .collect();
        assert_eq!(owners.len(), 1, "{} declared by {owners:?}", d.name);
        e.set(d.name, (i + 1) as f64).unwrap();
    }
    // set and get reach the field of the same name, and nothing else
    assert_eq!(e.k_ground, 2.0);
    assert_eq!(e.drift_rate, N_EFFECT_PARAMS as f64);
    for (i, n) in EFFECT_NAMES.iter().enumerate() {
        assert_eq!(e.get(n), Some((i + 1) as f64));
    }
    assert_eq!(Effects::default().values(), [0.0; N_EFFECT_PARAMS]);
}

#[test]
fn catalogue_ids_are_unique_and_only_terms_have_fields() {
    for (i, x) in EFFECTS.iter().enumerate() {
        assert!(EFFECTS[..i].iter().all(|y| y.id != x.id), "{}", x.id);
        let fields = x.params.iter().filter(|p| EFFECT_NAMES.contains(&p.name)).count();
        let expect = if x.kind == EffectKind::Term { x.params.len() } else { 0 };
        assert_eq!(fields, expect, "{}", x.id);
        assert!(!x.term.is_empty() && !x.physics.is_empty(), "{}", x.id);
    }
    let hyst = EFFECTS.iter().find(|x| x.id == "piezo_hysteresis").unwrap();
    assert_eq!(hyst.params[0].unit, table1("hyst_alpha").unit);
}
