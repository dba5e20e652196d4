"""Before/after performance check of two idm-rs installs, measured in the same run (issue 8).

Two Python interpreters, each with its own installed ``idm_rs`` (typically the previous commit's
wheel and this commit's), are timed on:

* single-trajectory cost [ns/step]: ``simulate()`` of the paper case (Triangle(80 V, 0.5 ms,
  9.5 ms), 10 ms at dt = 1e-8 s, i.e. 10^6 RK4 steps), LPS and DPS with 4 elements;
* sweep throughput [points/s]: the 256-point LPS sweep of ``benches/bench_sweep.py`` (m2/m1 in
  linspace(0.25, 2, 16) x V in linspace(40, 120, 16), 10 ms, 2 threads), RK4 at dt = 5e-8 s and
  dopri5 at rtol = atol = 1e-6 (first step 5e-8 s).

Every measurement runs in a fresh subprocess of the given interpreter (``python -I -c ...``, so
the two installs never meet in one process and the current directory is not on ``sys.path``),
which warms up once (the same call on a tenth of the time span) and then times one end-to-end
call. Before and after alternate (B A B A ... per case, ``--repeats`` times each); the best of
each is kept. The results of the two installs are compared bit for bit: x1(10 ms) of the single
trajectories (as ``float.hex``) and every variable of the sweep Datasets. A bitwise difference in
an RK4 case (both single trajectories and the RK4 sweep) makes the script exit with status 1;
dopri5 differences are reported (max |dx1|) but do not fail.

Printed (and written with ``--out``): a markdown table of case, before, after, after/before and
the same-result check, with the command line, the machine (CPU count, CPU model, load), the date,
each install's ``idm_rs.__version__``, commit, and a hash of its native module, and every sample.

Build the two installs (non-editable wheels, so later rebuilds of the checkout cannot change
them; the release profile of Cargo.toml applies), e.g. for the previous commit::

    git -C /work/main worktree add --detach /work/bench/base <commit>
    python -m venv /work/bench/venv-base
    /work/bench/venv-base/bin/pip install -q maturin
    (cd /work/bench/base && /work/bench/venv-base/bin/maturin build --release -o /work/bench/wheels-base)
    /work/bench/venv-base/bin/pip install /work/bench/wheels-base/*.whl numpy scipy xarray tqdm matplotlib
    git -C /work/bench/base rev-parse HEAD > /work/bench/venv-base/BASE_COMMIT

and the same with another worktree/venv/wheel folder (writing the hash to ``COMMIT`` or
``BASE_COMMIT`` in the venv) for the new commit. The commit of an install is read from that file
in the interpreter's ``sys.prefix``; for an editable install inside a git checkout it is that
checkout's HEAD (marked ``+dirty`` if tracked files are modified). Then::

    python benches/bench_before_after.py --before /work/bench/venv-base/bin/python \\
        --after /work/bench/venv-new/bin/python [--repeats 5] [--out benches/before_after.md]

The script itself needs only the standard library and numpy.
"""

from __future__ import annotations

import argparse
import base64
import datetime
import json
import os
import platform
import shlex
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

T_END = 10e-3  # s
SIM_DT = 1e-8  # s, single trajectories (10^6 steps)
SWEEP_DT = 5e-8  # s, RK4 step / dopri5 first step
SWEEP_THREADS = 2
DOPRI_TOL = 1e-6
TOLERANCE = 0.03  # "within 3 % or faster"
COMMIT_FILES = ("COMMIT", "BASE_COMMIT")
MARK = "@@BEFORE_AFTER@@ "

# Runs in the child interpreter: python -I -c WORKER '<spec json>'. Prints one marked JSON line.
WORKER = r"""
import base64, hashlib, json, os, sys, time
spec = json.loads(sys.argv[1])
import numpy as np
import idm_rs
pkg = os.path.dirname(os.path.abspath(idm_rs.__file__))
sos = sorted(f for f in os.listdir(pkg) if f.startswith("_core") and f.endswith((".so", ".pyd")))
h = hashlib.sha256()
for f in sos:
    with open(os.path.join(pkg, f), "rb") as fh:
        h.update(fh.read())
out = {"version": idm_rs.__version__, "package": pkg, "prefix": sys.prefix,
       "python": sys.version.split()[0], "numpy": np.__version__, "core_sha256": h.hexdigest()[:16]}
wave = idm_rs.Triangle(80.0, 0.5e-3, 9.5e-3)
if spec["kind"] == "simulate":
    def run(t_end):
        return idm_rs.simulate(idm_rs.Params(), wave, t_end=t_end, dt=spec["dt"], model=spec["model"],
                               n_elements=spec["n_elements"], save_every=spec["save_every"])
    run(spec["t_end"] / 10)
    t0 = time.perf_counter()
    r = run(spec["t_end"])
    out["wall_s"] = time.perf_counter() - t0
    out["x1_hex"] = float(r.final_position).hex()
else:
    import xarray  # noqa: F401  (imported before timing: sweep() returns a Dataset)
    grid = {"mass_ratio": np.linspace(0.25, 2.0, 16), "voltage": np.linspace(40, 120, 16)}
    def run(t_end):
        return idm_rs.sweep(idm_rs.Params(), wave, grid, t_end=t_end, progress=False, **spec["kwargs"])
    run(spec["t_end"] / 10)
    t0 = time.perf_counter()
    ds = run(spec["t_end"])
    out["wall_s"] = time.perf_counter() - t0
    out["points"] = int(ds["final_position"].size)
    def raw(a):  # the values' bytes; an object array (the 'reason' strings) by its text, not its pointers
        if a.dtype == object:
            return "\\x00".join(map(str, a.ravel())).encode()
        return np.ascontiguousarray(a).tobytes()
    out["vars"] = {k: [str(v.dtype), list(v.shape), base64.b64encode(raw(v.values)).decode()]
                   for k, v in ds.data_vars.items()}
print("@@BEFORE_AFTER@@ " + json.dumps(out), flush=True)
"""


@dataclass
class Case:
    """One benchmark case: what the child runs and how its time becomes a figure."""

    label: str
    unit: str  # "ns/step" (lower is better) or "points/s" (higher is better)
    spec: dict[str, Any]
    rk4: bool  # results must be bitwise equal between installs
    samples: dict[str, list[float]] = field(default_factory=lambda: {"before": [], "after": []})
    first: dict[str, dict[str, Any]] = field(default_factory=dict)  # first child output per side
    unstable: list[str] = field(default_factory=list)  # a side whose repeats disagreed bitwise

    def value(self, res: dict[str, Any]) -> float:
        if self.unit == "ns/step":
            return res["wall_s"] / round(self.spec["t_end"] / self.spec["dt"]) * 1e9
        return res["points"] / res["wall_s"]

    def best(self, side: str) -> float:
        xs = self.samples[side]
        return min(xs) if self.unit == "ns/step" else max(xs)

    def ratio(self) -> float:
        return self.best("after") / self.best("before")

    def within(self) -> bool:
        r = self.ratio()
        return r <= 1 + TOLERANCE if self.unit == "ns/step" else r >= 1 - TOLERANCE


def cases() -> list[Case]:
    sim = dict(kind="simulate", t_end=T_END, dt=SIM_DT, n_elements=4, save_every=100_000)
    sweep = dict(kind="sweep", t_end=T_END)
    common = dict(dt=SWEEP_DT, model="lps", threads=SWEEP_THREADS)
    return [
        Case("simulate LPS, 1e6 RK4 steps", "ns/step", dict(sim, model="lps"), rk4=True),
        Case("simulate DPS (n = 4), 1e6 RK4 steps", "ns/step", dict(sim, model="dps"), rk4=True),
        Case(f"sweep 256 pts, rk4 dt = {SWEEP_DT:g} s, {SWEEP_THREADS} threads", "points/s",
             dict(sweep, kwargs=dict(common, method="rk4")), rk4=True),
        Case(f"sweep 256 pts, dopri5 rtol = atol = {DOPRI_TOL:g}, {SWEEP_THREADS} threads", "points/s",
             dict(sweep, kwargs=dict(common, method="dopri5", rtol=DOPRI_TOL, atol=DOPRI_TOL)), rk4=False),
    ]


def run_child(python: str, spec: dict[str, Any], cwd: str) -> dict[str, Any]:
    """One measurement in a fresh process of ``python``; returns the child's JSON."""
    env = {k: v for k, v in os.environ.items() if not k.startswith("PYTHON")}
    env.update(OMP_NUM_THREADS="1", OPENBLAS_NUM_THREADS="1", MKL_NUM_THREADS="1")
    p = subprocess.run([python, "-I", "-c", WORKER, json.dumps(spec)], capture_output=True, text=True,
                       cwd=cwd, env=env)
    lines = [ln for ln in p.stdout.splitlines() if ln.startswith(MARK)]
    if p.returncode != 0 or not lines:
        raise RuntimeError(f"{python} failed (exit {p.returncode}) on {spec}:\n{p.stdout}\n{p.stderr}")
    return json.loads(lines[-1][len(MARK):])


def decode(var: list[Any]) -> np.ndarray:
    dtype, shape, b64 = var
    return np.frombuffer(base64.b64decode(b64), dtype=dtype).reshape(shape)


def same_result(a: dict[str, Any], b: dict[str, Any]) -> bool:
    return a["x1_hex"] == b["x1_hex"] if "x1_hex" in a else a["vars"] == b["vars"]


def check(case: Case) -> tuple[bool, str]:
    """(bitwise equal, text) comparing the first before and after results of ``case``."""
    a, b = case.first["before"], case.first["after"]
    if "x1_hex" in a:
        ok = a["x1_hex"] == b["x1_hex"]
        text = f"x1 = {a['x1_hex']} both" if ok else f"**DIFFERS**: x1 {a['x1_hex']} vs {b['x1_hex']}"
    else:
        xa, xb = decode(a["vars"]["final_position"]), decode(b["vars"]["final_position"])
        dmax = float(np.nanmax(np.abs(xa - xb))) if np.isfinite(xa - xb).any() else float("nan")
        differ = [k for k in sorted(set(a["vars"]) | set(b["vars"])) if a["vars"].get(k) != b["vars"].get(k)]
        ok = not differ
        text = (f"all {len(a['vars'])} variables bitwise equal" if ok
                else f"**DIFFERS** in {', '.join(differ)}; max \\|Δx1\\| = {dmax:.3g} m")
    if case.unstable:
        ok = False
        text += f"; **repeats not bitwise reproducible** on {', '.join(case.unstable)}"
    return ok, text


def install_commit(info: dict[str, Any]) -> str:
    """Commit of an install: a COMMIT/BASE_COMMIT file in its venv, else the git checkout holding
    an editable install's package, else 'unknown'."""
    for name in COMMIT_FILES:
        f = Path(info["prefix"]) / name
        if f.is_file():
            return f"{f.read_text().strip()[:12]} (from {f})"
    pkg = info["package"]
    try:
        head = subprocess.run(["git", "-C", pkg, "rev-parse", "HEAD"], capture_output=True, text=True, check=True)
        dirty = subprocess.run(["git", "-C", pkg, "status", "--porcelain", "--untracked-files=no"],
                               capture_output=True, text=True, check=True).stdout.strip()
        top = subprocess.run(["git", "-C", pkg, "rev-parse", "--show-toplevel"], capture_output=True, text=True,
                             check=True).stdout.strip()
        return f"{head.stdout.strip()[:12]}{'+dirty' if dirty else ''} (editable install, git HEAD of {top})"
    except (subprocess.CalledProcessError, FileNotFoundError):
        return "unknown (no COMMIT/BASE_COMMIT file in the venv, not inside a git checkout)"


def cpu_model() -> str:
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine()


def fmt(x: float) -> str:
    return f"{x:.1f}" if x >= 10 else f"{x:.3g}"


def report(cs: list[Case], pythons: dict[str, str], repeats: int, meta: dict[str, Any]) -> str:
    info = {side: cs[0].first[side] for side in ("before", "after")}
    lines = [
        "## Before/after (issue 8)",
        "",
        "```bash",
        meta["command"],
        "```",
        "",
        f"* date: {meta['date']}; took {meta['took_s']:.0f} s",
        f"* machine: {meta['nproc']} CPUs available (nproc), {cpu_model()}, {platform.machine()}; "
        f"load average before {meta['load_before']}, after {meta['load_after']}",
    ]
    for side in ("before", "after"):
        i = info[side]
        lines.append(f"* {side}: `{pythons[side]}` (Python {i['python']}, numpy {i['numpy']}), idm_rs "
                     f"{i['version']}, commit {install_commit(i)}, native module sha256 {i['core_sha256']}, "
                     f"package {i['package']}")
    if info["before"]["core_sha256"] == info["after"]["core_sha256"]:
        lines.append("* note: both interpreters load the same native module (identical build), so this run "
                     "measures noise only")
    lines += [
        "",
        f"Best of {repeats} per side, before and after alternating, each run a fresh process (warm-up, then one "
        f"timed call). ns/step: lower is better; points/s: higher is better; ok = at most {TOLERANCE:.0%} slower.",
        "",
        "| case | before | after | after/before | ok | same result |",
        "|---|---|---|---|---|---|",
    ]
    for c in cs:
        _, text = check(c)
        lines.append(f"| {c.label} [{c.unit}] | {fmt(c.best('before'))} | {fmt(c.best('after'))} | "
                     f"{c.ratio():.3f} | {'yes' if c.within() else '**no**'} | {text} |")
    lines += ["", "All samples (in run order), and spread = worst/best - 1 per side:", ""]
    for c in cs:
        parts = []
        for side in ("before", "after"):
            xs = c.samples[side]
            spread = max(xs) / min(xs) - 1
            parts.append(f"{side} {', '.join(fmt(x) for x in xs)} (spread {spread:.1%})")
        lines.append(f"* {c.label} [{c.unit}]: " + "; ".join(parts))
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--before", required=True, help="Python interpreter with the 'before' idm_rs installed")
    ap.add_argument("--after", required=True, help="Python interpreter with the 'after' idm_rs installed")
    ap.add_argument("--repeats", type=int, default=5, help="timed runs per case and side, best kept (default 5)")
    ap.add_argument("--out", metavar="FILE", help="also write the markdown report to FILE")
    a = ap.parse_args(argv)
    if a.repeats < 1:
        ap.error("--repeats must be at least 1")
    pythons = {"before": a.before, "after": a.after}

    cs = cases()
    load_before = " ".join(f"{x:.2f}" for x in os.getloadavg())
    t0 = time.perf_counter()
    with tempfile.TemporaryDirectory() as cwd:
        for r in range(a.repeats):
            for c in cs:
                for side in ("before", "after"):
                    res = run_child(pythons[side], c.spec, cwd)
                    c.samples[side].append(c.value(res))
                    if side not in c.first:
                        c.first[side] = res
                    elif not same_result(c.first[side], res) and side not in c.unstable:
                        c.unstable.append(side)
                    print(f"[{r + 1}/{a.repeats}] {c.label:<52} {side:<6} {fmt(c.value(res)):>8} {c.unit}",
                          file=sys.stderr, flush=True)
    meta = dict(
        command="python " + shlex.join(sys.argv),
        date=datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds"),
        nproc=len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count(),
        load_before=load_before, load_after=" ".join(f"{x:.2f}" for x in os.getloadavg()),
        took_s=time.perf_counter() - t0,
    )
    md = report(cs, pythons, a.repeats, meta)
    print(md, end="")
    if a.out:
        Path(a.out).write_text(md)
        print(f"wrote {a.out}", file=sys.stderr)

    failed = [c.label for c in cs if c.rk4 and not check(c)[0]]
    if failed:
        print(f"FAIL: RK4 results differ bitwise between before and after (or between repeats): "
              f"{'; '.join(failed)}", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
