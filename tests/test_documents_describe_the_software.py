"""Documents describe the software as it is, not its development: no "session N" anywhere in
the repository (history is dated, in CHANGELOG.md and benches/RESULTS.md's history sections)."""

from __future__ import annotations

import re
import subprocess
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def test_no_session_numbers_in_the_repository():
    try:
        files = subprocess.run(["git", "ls-files"], cwd=ROOT, capture_output=True, text=True, check=True).stdout.split()
    except (OSError, subprocess.CalledProcessError):
        pytest.skip("not a git checkout")
    pattern = re.compile(r"\bsessions? [0-9]", re.IGNORECASE)
    found = []
    for name in files:
        path = ROOT / name
        if path.suffix in (".png", ".so", ".whl", ".nc", ".zarr", ".mat", ".npz") or not path.is_file():
            continue
        try:
            text = path.read_text(encoding="utf-8")
        except (UnicodeDecodeError, OSError):
            continue
        found += [f"{name}:{i}" for i, line in enumerate(text.splitlines(), 1) if pattern.search(line)]
    assert found == [], found[:20]
