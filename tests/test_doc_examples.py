"""Every Python block of the README and of docs/ runs as written: the blocks of one file in
order, in one namespace (as a reader runs them top to bottom), in a scratch directory. Blocks
that diagnose a recording (minutes each) run in the slow suite and are compiled here; a block
that needs a GPU (``backend="cuda"``) runs where CuPy sees one."""

from __future__ import annotations

import re
import textwrap
from pathlib import Path

import matplotlib
import pytest

ROOT = Path(__file__).resolve().parents[1]
DOCS = [ROOT / "README.md", *sorted((ROOT / "docs").rglob("*.md"))]
FENCE = re.compile(r"^([ \t]*)```python\n(.*?)^\1```", re.S | re.M)
SLOW = "idm_rs.diagnose("


def blocks(path: Path) -> list[str]:
    return [textwrap.dedent(m.group(2)) for m in FENCE.finditer(path.read_text(encoding="utf-8"))]


def _gpu() -> bool:
    try:
        import cupy

        return cupy.cuda.runtime.getDeviceCount() > 0
    except Exception:
        return False


def _run(path: Path, tmp_path: Path, monkeypatch, slow: bool) -> int:
    matplotlib.use("Agg")
    monkeypatch.chdir(tmp_path)
    monkeypatch.syspath_prepend(str(ROOT / "tests"))  # the README's offcatalogue example imports from tests/
    namespace: dict = {"__name__": f"doc:{path.name}"}
    ran = 0
    for i, code in enumerate(blocks(path)):
        compiled = compile(code, f"{path.name} block {i}", "exec")
        needs_gpu = 'backend="cuda"' in code
        if (SLOW in code) != slow or (needs_gpu and not _gpu()):
            continue
        exec(compiled, namespace)
        ran += 1
    return ran


@pytest.mark.parametrize("path", DOCS, ids=lambda p: str(p.relative_to(ROOT)))
def test_every_python_block_runs_as_written(path, tmp_path, monkeypatch):
    assert all(compile(b, str(path), "exec") for b in blocks(path))  # every block is Python
    _run(path, tmp_path, monkeypatch, slow=False)


@pytest.mark.slow
@pytest.mark.timeout(3600)  # the README's discovery example alone is 10-20 minutes on 2 cores
@pytest.mark.parametrize("path", [p for p in DOCS if any(SLOW in b for b in blocks(p))],
                         ids=lambda p: str(p.relative_to(ROOT)))
def test_the_diagnosis_examples_run_as_written(path, tmp_path, monkeypatch):
    assert _run(path, tmp_path, monkeypatch, slow=True) > 0


def test_the_readme_has_its_examples():
    """The runner finds the README's blocks (a fence it cannot see would pass unnoticed)."""
    found = blocks(ROOT / "README.md")
    assert len(found) >= 10 and any("client=client" in b for b in found)
