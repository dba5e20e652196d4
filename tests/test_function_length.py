"""No function of the engine (rust/src) or of the package (python/idm_rs) is longer than 100
lines unless a comment right above it says why (``// Long: ...`` or ``# Long: ...``): a long
function is a decision, written down, not an accident. A Python function's docstring is not
counted (a Rust function's doc comment stands above its ``fn`` and is not counted either): a
public entry point documents every argument, and that is not length of logic."""

from __future__ import annotations

import ast
import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
LIMIT = 100


def _reason_above(lines: list[str], i: int, marker: str) -> bool:
    """A `marker` comment among the comment, doc and attribute lines directly above line i."""
    j = i - 1
    while j >= 0 and lines[j].strip().startswith(("#[", "//", "#", "@")):
        if lines[j].strip().startswith(marker):
            return True
        j -= 1
    return False


def rust_functions(text: str) -> list[tuple[str, int, int]]:
    """(name, first line index, length in lines) of every `fn` with a body."""
    lines = text.split("\n")
    out, i = [], 0
    while i < len(lines):
        m = re.match(r"\s*(pub(\([a-z]+\))?\s+)?(const\s+)?(unsafe\s+)?fn\s+(\w+)", lines[i])
        if not m:
            i += 1
            continue
        depth, started, j = 0, False, i
        while j < len(lines):
            code = re.sub(r"//.*", "", lines[j])
            depth += code.count("{") - code.count("}")
            started = started or "{" in code
            if (started and depth <= 0) or (not started and code.rstrip().endswith(";")):
                break
            j += 1
        out.append((m.group(5), i, j - i + 1))
        i = j + 1 if started else i + 1
    return out


def python_length(node: ast.FunctionDef | ast.AsyncFunctionDef) -> int:
    """Lines of a Python function, its docstring left out."""
    n = node.end_lineno - node.lineno + 1 if node.end_lineno else 0
    first = node.body[0] if node.body else None
    if (isinstance(first, ast.Expr) and isinstance(first.value, ast.Constant) and isinstance(first.value.value, str)
            and first.end_lineno is not None):
        n -= first.end_lineno - first.lineno + 1
    return n


def test_the_python_measure_leaves_the_docstring_out():
    text = 'def f(a):\n    """one\n    two\n    """\n    return a\n'
    node = ast.parse(text).body[0]
    assert isinstance(node, ast.FunctionDef) and python_length(node) == 2


def test_the_rust_scanner_measures_a_function():
    text = "// Long: why\nfn a() {\n    let x = { 1 };\n}\nfn b();\nfn c() { }\n"
    assert rust_functions(text) == [("a", 1, 3), ("b", 4, 1), ("c", 5, 1)]
    assert _reason_above(text.split("\n"), 1, "// Long:")


def test_no_long_function_without_a_reason():
    long = []
    for path in sorted((ROOT / "rust" / "src").rglob("*.rs")):
        lines = path.read_text().split("\n")
        for name, i, n in rust_functions(path.read_text()):
            if n > LIMIT and not _reason_above(lines, i, "// Long:"):
                long.append(f"{path.relative_to(ROOT)}:{i + 1} {name} ({n} lines)")
    for path in sorted((ROOT / "python" / "idm_rs").rglob("*.py")):
        text = path.read_text()
        lines = text.split("\n")
        for node in ast.walk(ast.parse(text)):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                first = min([node.lineno] + [d.lineno for d in node.decorator_list]) - 1
                n = python_length(node)
                if n > LIMIT and not _reason_above(lines, first, "# Long:"):
                    long.append(f"{path.relative_to(ROOT)}:{node.lineno} {node.name} ({n} lines)")
    assert not long, "split these, or say why above them (`// Long: ...` / `# Long: ...`):\n" + "\n".join(long)


#: lines a file of the engine or the package may have before it must say why it is one file
FILE_LIMIT = 600


def test_no_long_file_without_a_reason():
    """A file over FILE_LIMIT lines holds more than one idea, unless its first lines say why it
    is one (a ``Long:`` line in the module docstring or the leading comments). Test modules in
    their own files (``tests.rs``, ``*_tests.rs``) hold a module's tests, not its ideas."""
    long = []
    for path in sorted([*(ROOT / "rust" / "src").rglob("*.rs"), *(ROOT / "python" / "idm_rs").rglob("*.py")]):
        if path.name == "tests.rs" or path.name.endswith("_tests.rs"):
            continue
        lines = path.read_text().splitlines()
        if len(lines) > FILE_LIMIT and not any("Long:" in line for line in lines[:20]):
            long.append(f"{path.relative_to(ROOT)} ({len(lines)} lines)")
    assert not long, "split these by idea, or say why each is one (a `Long:` line at the top):\n" + "\n".join(long)
