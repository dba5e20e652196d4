"""The hypothesis seed a run prints is the seed every pytest-xdist worker drew from: a failure in
CI is replayed from the printed line (tests/conftest.py)."""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

PROBE = '''
import os
from pathlib import Path

def test_{name}():
    from hypothesis import core
    Path(os.environ["SEED_PROBE_DIR"], "{name}").write_text(str(core.global_force_seed))
'''


def test_every_worker_draws_from_the_printed_seed(tmp_path: Path) -> None:
    for name in ("a", "b", "c"):
        (tmp_path / f"test_{name}.py").write_text(PROBE.format(name=name))
    tests = Path(__file__).resolve().parent
    env = {**os.environ, "SEED_PROBE_DIR": str(tmp_path),
           "PYTHONPATH": os.pathsep.join([str(tests), os.environ.get("PYTHONPATH", "")])}
    env.pop("IDM_RS_HYPOTHESIS_SEED", None)
    # the project's conftest as a plugin, no ini file (no addopts): two workers, a file each
    run = subprocess.run([sys.executable, "-m", "pytest", "-q", "-c", os.devnull, "--rootdir", str(tmp_path),
                          "-p", "conftest", "-p", "no:cacheprovider", "-n", "2", "--dist", "loadfile", str(tmp_path)],
                         capture_output=True, text=True, env=env, timeout=300)
    assert run.returncode == 0, run.stdout + run.stderr
    printed = re.search(r"hypothesis seed (\d+)", run.stdout)
    assert printed is not None, run.stdout
    drawn = {(tmp_path / n).read_text() for n in ("a", "b", "c")}
    assert drawn == {printed.group(1)}
