"""The native binding as ``idm_rs.core.engine`` exposes it: ``RunConfig`` checks its settings on
construction and is read-only, and the type stub ``_core.pyi`` declares exactly what the
extension defines, with the same parameter names, kinds and defaults."""

from __future__ import annotations

import ast
import inspect
from pathlib import Path

import pytest

import idm_rs
from idm_rs import _core
from idm_rs.core import engine

STUB = Path(idm_rs.__file__).with_name("_core.pyi")


# --- RunConfig ---------------------------------------------------------------------------------


@pytest.mark.parametrize(
    "kw, name",
    [
        (dict(method="euler"), "'method'"),
        (dict(model="fem"), "'model'"),
        (dict(model="dps", n_elements=0), "'n_elements'"),
        (dict(dt=-1e-8), "'dt'"),
        (dict(dt=float("nan")), "'dt'"),
        (dict(method="dopri5", rtol=0.0), "'rtol'"),
        (dict(method="dopri5", atol=-1.0), "'atol'"),
        (dict(method="dopri5", first_step=0.0), "'first_step'"),
    ],
)
def test_run_config_refuses_invalid_settings_naming_the_parameter(kw, name):
    with pytest.raises(ValueError, match=name):
        engine.RunConfig(**kw)


def test_run_config_defaults():
    c = engine.RunConfig()
    assert (c.model, c.n_elements, c.piezo_hysteresis, c.method) == ("dps", 4, True, "rk4")
    assert (c.dt, c.rtol, c.atol) == (1e-8, 1e-7, 1e-7)
    assert c.first_step == c.dt  # first_step None = dt
    assert (c.retries, c.threads, c.record_every, c.final_states) == (2, 1, 0, False)


def test_run_config_is_keyword_only_and_read_only():
    with pytest.raises(TypeError):
        engine.RunConfig("lps")  # type: ignore[misc]
    c = engine.RunConfig(model="lps", dt=2e-8, threads=0)
    assert c.model == "lps" and c.dt == 2e-8 and c.first_step == 2e-8
    assert c.threads == 1  # below 1 counts as 1
    with pytest.raises(AttributeError):
        c.dt = 1e-8  # type: ignore[misc]


def test_simulate_refuses_an_unknown_model_naming_it():
    with pytest.raises(ValueError, match="'model'"):
        idm_rs.simulate(idm_rs.Params(), idm_rs.Triangle(), t_end=1e-4, model="fem")  # type: ignore[arg-type]


def test_engine_is_the_only_module_importing_the_core():
    pkg = Path(idm_rs.__file__).parent
    importers = []
    for path in sorted(pkg.rglob("*.py")):
        tree = ast.parse(path.read_text())
        for node in ast.walk(tree):
            names = []
            if isinstance(node, ast.ImportFrom):
                names = [node.module or ""] + [a.name for a in node.names]
            elif isinstance(node, ast.Import):
                names = [a.name for a in node.names]
            if any(n == "_core" or n.endswith("._core") for n in names):
                importers.append(path.relative_to(pkg).as_posix())
    assert sorted(set(importers)) == ["core/engine.py"]


# --- the stub ----------------------------------------------------------------------------------


def _stub() -> ast.Module:
    return ast.parse(STUB.read_text())


def _runtime_names() -> set[str]:
    return {n for n in vars(_core) if not n.startswith("_")}


def _stub_names() -> set[str]:
    out = set()
    for node in _stub().body:
        if isinstance(node, (ast.FunctionDef, ast.ClassDef)):
            out.add(node.name)
        elif isinstance(node, ast.AnnAssign) and isinstance(node.target, ast.Name):
            out.add(node.target.id)
    return out - {"__version__"}


def test_stub_declares_exactly_the_extensions_public_names():
    assert _stub_names() == _runtime_names()


def _stub_params(fn: ast.FunctionDef, drop_self: bool = False) -> list[tuple[str, str, bool]]:
    """(name, kind, has default) per parameter, as inspect names the kinds."""
    a = fn.args
    pos = a.posonlyargs + a.args
    defaults = [False] * (len(pos) - len(a.defaults)) + [True] * len(a.defaults)
    out = [(p.arg, "POSITIONAL_OR_KEYWORD", d) for p, d in zip(pos, defaults)]
    out += [(p.arg, "KEYWORD_ONLY", d is not None) for p, d in zip(a.kwonlyargs, a.kw_defaults)]
    return out[1:] if drop_self else out


def _runtime_params(obj) -> list[tuple[str, str, bool]]:
    sig = inspect.signature(obj)
    return [(p.name, p.kind.name, p.default is not inspect.Parameter.empty) for p in sig.parameters.values()
            if p.name != "self"]


def _functions() -> list[ast.FunctionDef]:
    return [n for n in _stub().body if isinstance(n, ast.FunctionDef)]


@pytest.mark.parametrize("fn", _functions(), ids=lambda f: f.name)
def test_stub_function_signature_matches_the_extension(fn):
    assert _stub_params(fn) == _runtime_params(getattr(_core, fn.name))


def test_stub_run_config_constructor_matches_the_extension():
    cls = next(n for n in _stub().body if isinstance(n, ast.ClassDef) and n.name == "RunConfig")
    init = next(n for n in cls.body if isinstance(n, ast.FunctionDef) and n.name == "__init__")
    # the extension's constructor takes keywords (its fields are declared once in python/mod.rs:
    # the struct, its defaults and the keyword parsing come from one list); the stub names each,
    # keyword-only, and the extension refuses any other by name
    stub = _stub_params(init, drop_self=True)
    assert all(kind == "KEYWORD_ONLY" and has_default for _, kind, has_default in stub)
    fields = {n for n, v in vars(_core.RunConfig).items() if type(v).__name__ == "getset_descriptor"}
    assert {name for name, _, _ in stub} == fields
    with pytest.raises(TypeError, match="unexpected keyword argument 'bogus'"):
        _core.RunConfig(bogus=1)
    with pytest.raises(TypeError):
        _core.RunConfig("lps")  # keywords only
    # every constructor keyword is a read-only attribute, declared as a property
    props = {n.name for n in cls.body if isinstance(n, ast.FunctionDef)
             and any(isinstance(d, ast.Name) and d.id == "property" for d in n.decorator_list)}
    assert props == {p.arg for p in init.args.kwonlyargs}
    c = _core.RunConfig()
    for name in props:
        getattr(c, name)


def test_stub_run_config_defaults_match_the_extension():
    cls = next(n for n in _stub().body if isinstance(n, ast.ClassDef) and n.name == "RunConfig")
    init = next(n for n in cls.body if isinstance(n, ast.FunctionDef) and n.name == "__init__")
    c = _core.RunConfig()
    for arg, default in zip(init.args.kwonlyargs, init.args.kw_defaults):
        value = ast.literal_eval(default)
        expected = c.dt if arg.arg == "first_step" and value is None else value
        assert getattr(c, arg.arg) == expected, arg.arg


def test_stub_batch_run_methods_exist():
    cls = next(n for n in _stub().body if isinstance(n, ast.ClassDef) and n.name == "BatchRun")
    declared = {n.name for n in cls.body if isinstance(n, ast.FunctionDef)}
    runtime = {n for n in vars(_core.BatchRun) if not n.startswith("_")}
    assert declared == runtime
