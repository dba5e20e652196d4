"""Every number the diagnosis is tuned by lives in ``diagnosis/thresholds.py`` with what it
controls, its unit and the measurement that set it: no other module of the diagnosis defines a
numeric constant at module level, and none of the comments names a recording it was tuned on."""

from __future__ import annotations

import ast
import re
from pathlib import Path

import idm_rs

DIAGNOSIS = Path(idm_rs.__file__).parent / "diagnosis"
#: numbers that are not tuning: mathematics (the normal quantile of a two-sided 95 % interval)
#: and the layout of the report and the figures (how many rows a table lists, DPI, the rest
#: samples a figure aligns its curves on)
NOT_TUNING = {"identifiability.py": {"Z95"}, "report.py": {"TOP_LOCATIONS", "TOP_WINDOWS"},
              "plots.py": {"DPI", "MIN_REST_SAMPLES"}}


def _is_number(node: ast.expr) -> bool:
    if isinstance(node, ast.Constant):
        return isinstance(node.value, (int, float)) and not isinstance(node.value, bool)
    if isinstance(node, ast.UnaryOp):
        return _is_number(node.operand)
    if isinstance(node, (ast.Tuple, ast.List)):
        return bool(node.elts) and all(_is_number(e) or (isinstance(e, ast.Constant) and e.value is None)
                                       for e in node.elts)
    if isinstance(node, ast.Call):  # np.logspace(...), dict(method=..., rtol=...)
        return any(_is_number(a) for a in node.args) or any(_is_number(k.value) for k in node.keywords)
    return False


def _numeric_constants(path: Path) -> set[str]:
    out = set()
    for node in ast.parse(path.read_text()).body:
        if isinstance(node, ast.Assign) and _is_number(node.value):
            out |= {t.id for t in node.targets if isinstance(t, ast.Name)}
        elif isinstance(node, ast.AnnAssign) and node.value is not None and _is_number(node.value):
            if isinstance(node.target, ast.Name):
                out.add(node.target.id)
    return out


def test_the_finder_sees_numbers_tuples_and_calls():
    tree = ast.parse("A = 1e-3\nB = (1, 2.5, None)\nC = np.logspace(-8, 2, 41)\nD = 'text'\nE = -4.0\n")
    found = {t.id for n in tree.body if isinstance(n, ast.Assign) and _is_number(n.value) for t in n.targets
             if isinstance(t, ast.Name)}
    assert found == {"A", "B", "C", "E"}


def test_every_tuning_constant_of_the_diagnosis_is_in_thresholds():
    stray = {}
    for path in sorted(DIAGNOSIS.glob("*.py")):
        if path.name == "thresholds.py":
            continue
        names = _numeric_constants(path) - NOT_TUNING.get(path.name, set())
        if names:
            stray[path.name] = sorted(names)
    assert not stray, f"move these to diagnosis/thresholds.py with their unit and measurement: {stray}"


def test_thresholds_documents_every_constant_and_names_no_recording():
    text = (DIAGNOSIS / "thresholds.py").read_text()
    lines = text.splitlines()
    tree = ast.parse(text)
    for node in tree.body:
        if isinstance(node, (ast.Assign, ast.AnnAssign)):
            # its `#:` comment is above it, or above the constant it is listed with
            k = node.lineno - 2
            while k >= 0 and not lines[k].startswith("#:") and re.match(r"^[A-Z_0-9]+\b", lines[k]):
                k -= 1
            assert k >= 0 and lines[k].startswith("#:"), f"line {node.lineno}: no `#:` comment says what it controls"
    # no recording's id (dev05, d2_12, case 3, pair 3): a constant says what was measured, not where
    assert not re.search(r"\b(dev\d\d|d2_\d\d|case \d+|pair \d+)\b", text)
    # and it imports nothing of the package: every module may read it
    assert not any(line.startswith(("from .", "import idm_rs", "from idm_rs")) for line in lines)
