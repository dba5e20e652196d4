"""Table 1 and the effect catalogue are declared once, in the Rust core, and everything on the
Python side reads that one declaration: the ``Params`` and ``Effects`` fields and defaults, the
sweep's units, the diagnosis catalogue and its report. (That no import circle exists is
tests/test_layers.py.)"""

from __future__ import annotations

import ast
import math
import re
from dataclasses import fields
from pathlib import Path

import pytest

import idm_rs
from idm_rs.core import engine
from idm_rs.core.declarations import EFFECT_PARAMS, EFFECTS, GRAVITY, TABLE1
from idm_rs.core.params import PARAM_INFO
from idm_rs.diagnosis.catalogue import CATALOGUE, LIBRARY_IDS, by_id

PACKAGE = Path(idm_rs.__file__).parent


def stub_fields(stub: str, cls: str) -> list[str]:
    """Annotated names in the body of class `cls` of a `.pyi` stub, in order."""
    tree = ast.parse((PACKAGE / stub).read_text())
    body = next(n for n in tree.body if isinstance(n, ast.ClassDef) and n.name == cls).body
    return [n.target.id for n in body if isinstance(n, ast.AnnAssign) and isinstance(n.target, ast.Name)]


# --- effects ------------------------------------------------------------------------------------

def test_every_effects_field_is_declared_once_with_a_unit():
    declared = [p.name for e in EFFECTS if e.kind == "term" for p in e.params]
    assert len(declared) == len(set(declared))
    assert [f.name for f in fields(idm_rs.Effects)] == declared == engine.effect_names()
    for p in EFFECT_PARAMS:
        assert p.unit and p.value == 0.0, p.name  # off at its zero value
    for f in fields(idm_rs.Effects):
        assert f.default == 0.0 and f.metadata["unit"] == next(p.unit for p in EFFECT_PARAMS if p.name == f.name)


def test_effects_stub_lists_the_declared_fields():
    assert stub_fields("core/effects.pyi", "Effects") == [f.name for f in fields(idm_rs.Effects)]


def test_effect_domains_reach_the_engine_with_their_rule():
    """The Rust validation reads the declared domain: its message names the parameter and the rule."""
    for name, bad in (("eps", 1.0), ("theta_rad", math.pi / 2), ("tau_amp", -1e-6)):
        decl = next(p for p in EFFECT_PARAMS if p.name == name)
        assert not decl.contains(bad)
        with pytest.raises(ValueError, match=re.escape(f"effect parameter '{name}' must {decl.rule}, got")):
            idm_rs.simulate(idm_rs.Params(), idm_rs.Triangle(10.0, 1e-4, 1e-4), 1e-5, 1e-8,
                            effects=idm_rs.Effects(**{name: bad}))


# --- Table 1 ------------------------------------------------------------------------------------

def test_params_defaults_are_table1_of_the_core():
    resolved = engine.resolve_params({})  # Params::paper() in Rust
    assert [f.name for f in fields(idm_rs.Params)] == [d.name for d in TABLE1] == engine.param_names()
    for f in fields(idm_rs.Params):
        if f.name == "normal_force":
            assert f.default is None  # derived: (m1 + m2 + mPE) g
        else:
            assert f.default == resolved[f.name], f.name
    p = idm_rs.Params()
    assert GRAVITY == 9.81
    assert p.effective_normal_force == resolved["normal_force"] == (p.m1 + p.m2 + p.pe_mass) * GRAVITY


def test_param_info_is_the_declaration():
    assert PARAM_INFO == {d.name: (d.symbol, d.unit, d.meaning) for d in TABLE1}
    assert PARAM_INFO["pe_youngs"] == ("Ep", "N/m^2", "PE Young's modulus")


def test_params_stub_lists_the_declared_fields():
    assert stub_fields("core/params.pyi", "Params") == [f.name for f in fields(idm_rs.Params)]


# --- sweep --------------------------------------------------------------------------------------

def test_sweep_axis_units_of_effects_come_from_the_declaration():
    ds = idm_rs.sweep(idm_rs.Params(), idm_rs.Triangle(80.0, 0.3e-3, 0.7e-3),
                      {"k_ground": [0.0, 1e3], "tau_sensor": [0.0]}, t_end=2e-4, dt=2e-8, model="lps",
                      progress=False, threads=1)
    for axis in ("k_ground", "tau_sensor"):
        assert ds[axis].attrs["units"] == next(p.unit for p in EFFECT_PARAMS if p.name == axis)
    assert ds.attrs["normal_force_rule"] == f"(m1+m2+mPE)*{GRAVITY:g} per point"


# --- diagnosis catalogue and report -------------------------------------------------------------

def test_catalogue_entries_are_the_declared_effects():
    listed = [e for e in EFFECTS if e.id not in LIBRARY_IDS]
    assert [e.id for e in CATALOGUE] == [e.id for e in listed]
    assert {e.id for e in EFFECTS} - {e.id for e in listed} == {"library_force", "library_force_weight"}
    for entry, decl in zip(CATALOGUE, listed):
        assert entry.description == decl.physics and entry.term == decl.term and entry.kind == decl.kind
        assert [(p.name, p.unit) for p in entry.params] == [(d.name, d.unit) for d in decl.params]
        for p, d in zip(entry.params, decl.params):
            # fit bounds within the physical domain
            assert d.contains(p.lower) and d.contains(p.upper), p.name
            assert (p.physical_lower, p.physical_upper) == (d.lower, d.upper)


def test_only_structure_changes_have_no_parameters():
    for e in CATALOGUE:
        assert (not e.params) == (e.kind == "structure"), e.id


def test_stribeck_is_reported_as_friction_coefficients():
    reported = by_id("stribeck").reported({"mu_k": 0.5, "mu_s_excess": 0.2, "d33": 1e-7},
                                          {"mu_k": 1e-3, "mu_s_excess": 0.01})
    assert reported == {"mu_s": (0.5 * 1.2, 0.5 * 0.01), "mu_k": (0.5, None)}
    # an effect whose parameters are its own is reported as fitted
    assert by_id("spring_to_ground").reported({"k_ground": 2e4, "mu_k": 0.5}, {"k_ground": 10.0}) == {
        "k_ground": (2e4, 10.0)}


def test_stribeck_setter_keeps_mu_s_above_mu_k():
    free = by_id("stribeck").params[0].free(0.1)
    params: dict = {"mu_k": 0.4}
    free.setter(params, {}, free.value(0.0))
    assert params["mu_s"] == pytest.approx(0.44)



# --- structures ---------------------------------------------------------------------------------

def test_the_structure_names_in_type_hints_are_the_engines():
    import typing

    from idm_rs.core.declarations import IDM_MODELS, STRUCTURES, Model, StructureName

    assert typing.get_args(Model) == IDM_MODELS and {"lps", "dps"} <= set(IDM_MODELS)
    assert typing.get_args(StructureName) == tuple(s.name for s in STRUCTURES)


def test_structure_labels_and_refusals_come_from_the_declarations():
    from idm_rs.core.declarations import elements_of, structure, structure_label

    assert structure_label("lps", 4) == "LPS" and structure_label("dps", 4) == "DPS (n = 4)"
    assert structure_label("rig", 1) == "rig"
    assert elements_of("dps", 6) == 6 and elements_of("lps", 6) == 1
    from idm_rs.core.declarations import IDM_MODELS, STRUCTURES

    with pytest.raises(ValueError, match=f"'model' must be one of {', '.join(map(repr, IDM_MODELS))}, got 'fem'"):
        structure("fem")
    with pytest.raises(ValueError, match=", ".join(repr(s.name) for s in STRUCTURES)):
        structure("fem", idm_only=False)


def test_the_cli_offers_the_declared_structures():
    import argparse

    from idm_rs.apps.cli_parser import build_parser
    from idm_rs.core.declarations import IDM_MODELS

    parser = build_parser()
    commands = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction)).choices
    for command in ("simulate", "sweep", "characterize"):
        model = next(a for a in commands[command]._actions if "--model" in a.option_strings)
        assert tuple(model.choices) == IDM_MODELS, command


def test_the_method_names_in_type_hints_are_the_engines():
    import typing

    from idm_rs import methods

    assert typing.get_args(methods.MethodName) == methods.METHODS
    # the reference takes dt; the ones after the fixed-step ones choose their steps
    assert methods.METHODS[0] == "rk4" and not methods.is_adaptive("rk4")
    assert {"dopri5", "rodas4", "auto"} <= set(methods.ADAPTIVE) < set(methods.METHODS)
