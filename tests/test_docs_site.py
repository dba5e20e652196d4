"""The documentation site builds with warnings as errors: a page missing from the navigation, a
broken link between pages or a reference the API pages cannot resolve fails here (and so in CI)."""

import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def test_the_site_builds_strict(tmp_path):
    pytest.importorskip("mkdocs")
    pytest.importorskip("mkdocstrings")
    proc = subprocess.run([sys.executable, "-m", "mkdocs", "build", "--strict", "-f", str(ROOT / "mkdocs.yml"),
                           "-d", str(tmp_path / "site")], capture_output=True, text=True, timeout=600,
                          env={"NO_MKDOCS_2_WARNING": "1", "PATH": "/usr/bin:/bin", "HOME": str(tmp_path)})
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-3000:]
    api = (tmp_path / "site" / "api" / "index.html").read_text(encoding="utf-8")
    for name in ("simulate", "sweep", "characterize", "diagnose", "rig_fit", "STARTUP_CYCLES"):
        assert name in api, name  # the API reference is generated from the docstrings
    for page in ("guide/simulate", "guide/sweep", "guide/characterize", "guide/gpu", "DIAGNOSIS", "REALDATA"):
        assert (tmp_path / "site" / page / "index.html").exists(), page
    shutil.rmtree(tmp_path / "site")
