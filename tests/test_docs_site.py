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
    # what users look up: every result attribute, the numpydoc sections, diagnose as a function
    assert "x1(t_end) [m]" in api and "False when Ctrl-C stopped the run" in api
    assert "diagnose a measured friction rig" in api.lower() and "partial_result" in api
    assert 'id="idm_rs.diagnosis.diagnose.diagnose"' in api
    assert "DivergenceError" in api and "Raises" in api and "Examples" in api
    bench = (tmp_path / "site" / "BENCHMARKS" / "index.html").read_text(encoding="utf-8")
    assert "idm-rs / numba" in bench  # the current figures, on the site
    params = (tmp_path / "site" / "PARAMETERS" / "index.html").read_text(encoding="utf-8")
    assert "k_ground" in params and "main body mass" in params
    assert (tmp_path / "site" / "guide" / "getting-started" / "index.html").exists()
    shutil.rmtree(tmp_path / "site")


def test_the_parameter_tables_are_the_declarations():
    """docs/PARAMETERS.md is written from the declarations the engine reads; regenerate it with
    `python -m idm_rs.apps.reference_tables > docs/PARAMETERS.md` when a parameter changes."""
    from idm_rs.apps.reference_tables import markdown

    assert (ROOT / "docs" / "PARAMETERS.md").read_text(encoding="utf-8") == markdown()
