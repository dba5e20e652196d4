"""The layout is the architecture (docs/ARCHITECTURE.md, "The layers"): the Rust core's folders
are layers, each using only the layers below it, with no circle between files; the Python
package has no import circle, counting the imports made inside functions (deferred imports run
too, just later) and leaving out only those under ``if TYPE_CHECKING:``, which never run.

A folder's ``mod.rs`` re-exporting its children (``pub use run::run_batch``) is the folder's public
face, as a Python package's ``__init__`` is, and is not counted as a use (the children use the
folder's own types through ``super::``)."""

from __future__ import annotations

import ast
import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
RUST = ROOT / "rust" / "src"
PYTHON = ROOT / "python" / "idm_rs"

#: the Rust layers, lowest first (a folder, or a file directly under rust/src); a file may use
#: files of its own layer and of the layers before it
RUST_LAYERS: tuple[tuple[str, ...], ...] = (
    ("error",), ("numbers",), ("physics",), ("model",), ("integrate",), ("lanes",), ("drive",),
    ("sensitivity",), ("simulate",), ("batch",), ("gpu",), ("watch",), ("python",),
)


def _layer(module: str) -> int:
    top = module.split("::")[0]
    for i, names in enumerate(RUST_LAYERS):
        if top in names:
            return i
    raise AssertionError(f"rust/src/{top} is in no layer of RUST_LAYERS: add it where it belongs")


def _rust_modules() -> dict[str, Path]:
    """Module path (``physics::friction``) -> file, for every file of the crate but lib.rs."""
    out = {}
    for path in RUST.rglob("*.rs"):
        rel = path.relative_to(RUST).with_suffix("")
        parts = list(rel.parts)
        if parts[-1] == "mod":
            parts = parts[:-1]
        if parts in (["lib"], ["paper_case_tests"]) or parts[-1] == "tests" or parts[-1].endswith("_tests"):
            continue  # a test module in its own file (`#[cfg(test)] mod tests;`) may use any layer
        out["::".join(parts)] = path
    return out


def _outside_tests(text: str) -> str:
    """The file's text before its test module (`#[cfg(test)]` then `mod`)."""
    m = re.search(r"^#\[cfg\(test\)\]\s*\n\s*mod ", text, flags=re.M)
    return text[: m.start()] if m else text


def _rust_uses(module: str, path: Path, modules: dict[str, Path]) -> set[str]:
    """Modules of the crate that `module` uses outside its tests (longest module prefix of each
    `crate::` or `super::` path)."""
    text = _outside_tests(path.read_text())
    # drop comments: doc links name modules without using them
    text = "\n".join(line.split("//")[0] for line in text.splitlines())
    parent = module.rsplit("::", 1)[0] if "::" in module else ""  # `super` of a.rs and of a/mod.rs alike
    paths = re.findall(r"\bcrate((?:::\w+)+)", text)
    paths += [(f"::{parent}" if parent else "") + p for p in re.findall(r"\bsuper((?:::\w+)+)", text)]
    used = set()
    for p in paths:
        segs = p.strip(":").split("::")
        for k in range(len(segs), 0, -1):
            cand = "::".join(segs[:k])
            if cand in modules:
                if cand != module:
                    used.add(cand)
                break
    return used


def test_rust_files_use_only_their_layer_and_the_layers_below():
    modules = _rust_modules()
    wrong = []
    for module, path in modules.items():
        for dep in _rust_uses(module, path, modules):
            if _layer(dep) > _layer(module):
                wrong.append(f"{module} uses {dep} (a layer above)")
    assert not wrong, "\n".join(wrong)


def _circle(graph: dict[str, set[str]]) -> list[str]:
    """One circle of `graph` as a path, or [] when there is none."""
    state: dict[str, str] = {}
    stack: list[str] = []

    def visit(m: str) -> list[str]:
        state[m] = "open"
        stack.append(m)
        for dep in sorted(graph.get(m, ())):
            if state.get(dep) == "open":
                return stack[stack.index(dep):] + [dep]
            if dep not in state:
                found = visit(dep)
                if found:
                    return found
        stack.pop()
        state[m] = "done"
        return []

    for m in sorted(graph):
        if m not in state:
            found = visit(m)
            if found:
                return found
    return []


def test_circle_finder_finds_a_circle():
    assert _circle({"a": {"b"}, "b": {"c"}, "c": {"a"}}) == ["a", "b", "c", "a"]
    assert _circle({"a": {"b"}, "b": {"c"}, "c": set()}) == []


def test_rust_files_import_no_circle():
    modules = _rust_modules()
    graph = {m: _rust_uses(m, p, modules) for m, p in modules.items()}
    assert _circle(graph) == []


def _python_modules() -> dict[str, Path]:
    out = {}
    for path in PYTHON.rglob("*.py"):
        rel = path.relative_to(PYTHON.parent).with_suffix("")
        parts = list(rel.parts)
        if parts[-1] == "__init__":
            parts = parts[:-1]
        out[".".join(parts)] = path
    return out


def _type_checking_nodes(tree: ast.AST) -> set[int]:
    """ids of the statements under `if TYPE_CHECKING:` (never run)."""
    skip: set[int] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.If) and "TYPE_CHECKING" in ast.unparse(node.test):
            for child in node.body:
                skip.update(id(n) for n in ast.walk(child))
    return skip


def _python_imports(name: str, path: Path, modules: dict[str, Path]) -> set[str]:
    """Modules of the package that `name` imports anywhere in its code (at load or deferred)."""
    tree = ast.parse(path.read_text())
    skip = _type_checking_nodes(tree)
    package = name if path.name == "__init__.py" else name.rsplit(".", 1)[0]
    out = set()
    for node in ast.walk(tree):
        if id(node) in skip:
            continue
        targets: list[str] = []
        if isinstance(node, ast.Import):
            targets = [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")
                base = base[: len(base) - (node.level - 1)]
                mod = ".".join(base + ([node.module] if node.module else []))
            else:
                mod = node.module or ""
            # `from pkg import sub` imports the submodule when there is one
            targets = [f"{mod}.{a.name}" if f"{mod}.{a.name}" in modules else mod for a in node.names]
        for t in targets:
            while t and t not in modules:
                t = t.rsplit(".", 1)[0] if "." in t else ""
            if t and t != name:
                out.add(t)
    return out


def test_python_package_imports_no_circle_deferred_imports_included():
    modules = _python_modules()
    graph = {m: _python_imports(m, p, modules) for m, p in modules.items()}
    # a package's __init__ gathers its modules for users; a module reaching a sibling through
    # its package's __init__ is an import of that sibling, so the __init__s are left out
    inits = {m for m, p in modules.items() if p.name == "__init__.py"}
    graph = {m: deps - inits for m, deps in graph.items() if m not in inits}
    assert _circle(graph) == []


#: the Python package's layers, lowest first (a folder of python/idm_rs); a module may import
#: modules of its own layer and of the layers before it (the package's __init__ and __main__,
#: which gather the public names, stand above them all)
PYTHON_LAYERS: tuple[tuple[str, ...], ...] = (
    ("core",), ("io",), ("gpu",), ("sweeps",), ("diagnosis", "rigs"), ("apps",),
)


def _python_layer(module: str) -> int:
    parts = module.split(".")
    if len(parts) < 2 or parts[1] in ("__main__", "_core"):
        return len(PYTHON_LAYERS)
    for i, names in enumerate(PYTHON_LAYERS):
        if parts[1] in names:
            return i
    raise AssertionError(f"python/idm_rs/{parts[1]} is in no layer of PYTHON_LAYERS: put it in the folder of its layer")


def test_python_modules_live_in_a_layer_folder():
    """No module at the package's top but its __init__ and __main__: each lives in its layer."""
    loose = sorted(p.name for p in PYTHON.glob("*.py") if p.name not in ("__init__.py", "__main__.py"))
    assert not loose, f"modules outside a layer folder: {loose}"


def test_python_modules_import_only_their_layer_and_the_layers_below():
    modules = _python_modules()
    wrong = []
    for name, path in modules.items():
        if path.name == "__init__.py" and name == "idm_rs":
            continue
        for dep in _python_imports(name, path, modules):
            if dep == "idm_rs":
                if name != "idm_rs.core.engine":  # the engine imports the extension module, idm_rs._core
                    wrong.append(f"{name} imports the package's __init__ (import the module itself)")
            elif _python_layer(dep) > _python_layer(name):
                wrong.append(f"{name} imports {dep} (a layer above)")
    assert not wrong, "\n".join(wrong)


@pytest.mark.parametrize("module", ["results", "report", "plots"])
def test_the_result_types_and_their_presentation_do_not_import_the_algorithm(module):
    """The report and the figures are functions of a Diagnosis; the result types import neither
    them nor the algorithm that builds them."""
    modules = _python_modules()
    name = f"idm_rs.diagnosis.{module}"
    deps = _python_imports(name, modules[name], modules)
    assert "idm_rs.diagnosis.diagnose" not in deps
    if module == "results":
        assert not {d for d in deps if d.endswith((".report", ".plots"))}, deps
