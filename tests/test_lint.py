"""The Python code passes the linter and the type checker, as CI runs them: ``ruff check`` on
``python tests benches examples`` and ``mypy`` on the package (``python/idm_rs``), both with
their settings in ``pyproject.toml`` ([tool.ruff], [tool.mypy]). Here so that a change that
breaks either fails the test suite, not only a separate CI step. Both tools are in the ``test``
extra; without them these tests fail (they do not skip), saying what to install."""

from __future__ import annotations

import importlib.util
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
INSTALL = "pip install '.[test]' (the test extra has ruff and mypy)"


def _run(tool: str, *args: str) -> subprocess.CompletedProcess[str]:
    if importlib.util.find_spec(tool) is None:
        pytest.fail(f"{tool} is not installed: {INSTALL}", pytrace=False)
    return subprocess.run([sys.executable, "-m", tool, *args], cwd=ROOT, capture_output=True, text=True,
                          timeout=600)


def test_ruff_finds_nothing():
    r = _run("ruff", "check", "python", "tests", "benches", "examples")
    assert r.returncode == 0, f"ruff check failed:\n{r.stdout}{r.stderr}"


def test_mypy_finds_no_error():
    r = _run("mypy")  # files and settings: [tool.mypy] in pyproject.toml
    assert r.returncode == 0 and "Success: no issues found" in r.stdout, f"mypy failed:\n{r.stdout}{r.stderr}"
