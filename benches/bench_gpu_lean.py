"""Issue 32, the lean RK4 step: the kernel before (--before: a copy of idm_kernel.cu before it,
e.g. `git show 9c5a4e1:python/idm_rs/gpu/idm_kernel.cu > before.cu`) and after (the installed
idm_kernel.cu) under layout variants, on the same card in one process: kernel-only A/B on the
LPS grid (CUDA events; 512 x 512 points, RK4 over 2 ms, Dormand-Prince over 10 ms), each
variant's outputs against the old kernel's (bit for bit) and its GPU build against its CPU build,
then the full 1,000 x 1,000 sweeps (bench_gpu.gpu_row) of the old kernel and the fastest variant.

    python benches/bench_gpu_lean.py --before before.cu --json lean.json
    python benches/bench_gpu_lean.py --before before.cu --cpu --ab 4 --size 2 --rk4-ms 0.2   # dry run, CPU build

Results (NVIDIA H200): benches/results/gpu_h200_run5_lean.{json,log}, benches/RESULTS.md."""
import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

from idm_rs import engine, methods
from idm_rs.batch import Structure, param_row
from idm_rs.gpu import Spec, backend, pack, wave_columns

HERE = Path(__file__).parent
sys.path.insert(0, str(HERE))
import bench_gpu as bench

ORIG = ""  # set from --before
NEW = backend.SOURCE.read_text()
# each variant sets every switch (Spec.defines() is the shipped default, LPS: all three on)
OFF = "".join(f"#undef {k}\n#define {k} 0\n" for k in ("IDM_WAVE_SHARED", "IDM_METRICS_SHARED"))
WSH = OFF + "#undef IDM_WAVE_SHARED\n#define IDM_WAVE_SHARED 1\n"
MSH = "#undef IDM_METRICS_SHARED\n#define IDM_METRICS_SHARED 1\n"
#: label -> (source, extra defines after Spec.defines(), LPS block or None)
VARIANTS = {
    "orig": (ORIG, "", None),
    "lean": (NEW, OFF, None),
    "lean+wsh b64": (NEW, WSH, 64),
    "lean+wsh+msh": (NEW, WSH + MSH, None),
    "lean+wsh+msh b64": (NEW, WSH + MSH, 64),
    "lean+matreg": (NEW, OFF + "#undef IDM_MAT_REG\n#define IDM_MAT_REG 1\n", None),
    "lean0": (NEW, OFF + "#undef IDM_LEAN\n#define IDM_LEAN 0\n", None),
}
_shipped_source = backend.kernel_source
_shipped_block = backend.Spec.block


def use(label):
    src, extra, blk = VARIANTS[label]
    src = src or ORIG
    backend.kernel_source = lambda spec: engine.kernel_header() + spec.defines() + extra + src
    backend.Spec.block = property(lambda self: blk if (blk and self.nodes == 2) else _shipped_block.fget(self))
    backend._MODULES.clear()
    backend._CPU_LIBS.clear()


def regs():
    m = backend._MODULES.get(Spec(2, True))
    if m is None:
        return {}
    return {n: (m.get_function(n).num_regs, m.get_function(n).local_size_bytes)
            for n in ("idm_rk4_sweep", "idm_dopri5_sweep")}


def gpu_vs_cpu():
    """test_gpu_equals_the_cpu_build for the LPS under the current variant: max |GPU - CPU build|."""
    from idm_rs.gpu import prepare
    rows = np.array([param_row(bench.P.replace(m2=m)) for m in np.linspace(0.1, 0.6, 64)])
    out = {}
    for method in ("rk4", "dopri5"):
        waves = ("triangle", dict(amplitude=np.linspace(40, 120, 64), rise=0.5e-3, fall=1.5e-3, delay=0.0))
        b = prepare(Structure("lps", 1).config(method="rk4", dt=5e-8), rows, waves, 2e-3, 5e-8, method=method,
                    spec=Spec(2, True))
        g, c = backend.run_cuda(b), backend.run_cpu(b)
        out[method] = float(np.max(np.abs(g["final_position"] - c["final_position"])))
    out["pass"] = out["rk4"] <= 1e-12 and out["dopri5"] <= 1e-10
    return out


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--before", required=True, help="the kernel source before (the 'orig' variant)")
    ap.add_argument("--cpu", action="store_true", help="dry run with the CPU build, tiny sizes")
    ap.add_argument("--ab", type=int, default=512)
    ap.add_argument("--size", type=int, default=1000)
    ap.add_argument("--rk4-ms", type=float, default=2.0)
    ap.add_argument("--variants", default="orig,lean,lean+wsh b64,lean+wsh+msh,lean+wsh+msh b64,lean+matreg")
    ap.add_argument("--rows", default="orig:rk4,BEST:rk4,orig:auto,BEST:auto,lean:rk4,lean:auto")
    ap.add_argument("--json", default="out.json")
    a = ap.parse_args()
    global ORIG
    ORIG = Path(a.before).read_text()
    run = backend.run_cpu if a.cpu else backend.run_cuda
    out = {"card": bench.card() if not a.cpu else "cpu", "ab": [], "rows": [], "equal": [], "regs": {},
           "gpu_vs_cpu": {}}
    print(json.dumps(out["card"]), flush=True)

    def save() -> None:
        Path(a.json).write_text(json.dumps(out, indent=1, default=str))

    # kernel only: the LPS grid, hysteresis on (as the sweep), CUDA events
    size = a.ab
    g = bench._grid(size)
    rows = np.array([param_row(bench.P.replace(m2=float(m) * bench.P.m1)) for m in g["mass_ratio"]])
    idx = np.repeat(np.arange(size), size)
    wave = wave_columns("triangle", dict(amplitude=np.tile(g["voltage"], size), rise=0.5e-3, fall=9.5e-3, delay=0.0))
    _, rtol, atol = methods.resolve("auto", 0.0, 0.0)
    cfg = Structure("lps", 1, True).config(method="rk4", dt=5e-8)
    batches = {"rk4": pack(cfg, Spec(2, True), rows, idx, wave, a.rk4_ms * 1e-3, 5e-8),
               "dopri5": pack(cfg, Spec(2, True), rows, idx, wave, bench.T_END, 5e-8, method="dopri5",
                              rtol=rtol, atol=atol, first_step=1e-8)}
    labels = a.variants.split(",")
    res = {}
    for rep in range(2):
        for label in labels:
            use(label)
            for method, b in batches.items():
                if rep == 0 and not a.cpu:
                    backend.launch_cuda(b).result()  # compile + warm
                    try:
                        out["regs"][label] = regs()
                    except Exception as exc:
                        out["regs"][label] = repr(exc)
                if a.cpu:
                    t0 = time.perf_counter()
                    r = run(b)
                    ks = time.perf_counter() - t0
                else:
                    h = backend.launch_cuda(b)
                    r = h.result()
                    ks = h.kernel_s
                res[(label, method)] = r
                row = dict(variant=label, method=method, rep=rep, points=b.points,
                           t_end=b.t_end if method == "dopri5" else b.steps * b.dt,
                           kernel_s=round(ks, 4), points_per_s=round(b.points / ks), ok=int((r["status"] == 1).sum()))
                out["ab"].append(row)
                print(json.dumps(row), flush=True)
            if rep == 0 and not a.cpu:
                try:
                    out["gpu_vs_cpu"][label] = gpu_vs_cpu()
                except Exception as exc:
                    out["gpu_vs_cpu"][label] = repr(exc)
                print(label, "regs", out["regs"].get(label), "gpu_vs_cpu", out["gpu_vs_cpu"][label], flush=True)
        save()
    for label in labels:
        for method in batches:
            r0, r1 = res[("orig", method)], res[(label, method)]
            eq = {k: float(np.nanmax(np.abs(r1[k].astype(float) - r0[k].astype(float))))
                  if r0[k].dtype != bool else int((r0[k] != r1[k]).sum())
                  for k in r0 if k != "diverged_at"}
            bits = int(np.count_nonzero(r1["final_position"].view(np.int64) != r0["final_position"].view(np.int64)))
            row = dict(variant=label, method=method, max_abs_diff_vs_orig=eq, final_position_bits_differ=bits)
            out["equal"].append(row)
            print(json.dumps(row), flush=True)
    save()

    # the full sweeps (wall, host included), as benches/RESULTS.md measures them
    ns = argparse.Namespace(size=a.size, sample=64, dt=5e-8, cpu_points=0, block=1 << 18)
    rate = {}
    for r in out["ab"]:
        if r["method"] == "rk4" and r["variant"] != "orig":
            rate.setdefault(r["variant"], []).append(r["points_per_s"])
    best = max(rate, key=lambda k: np.mean(rate[k]))
    out["best"] = best
    print("BEST", best, {k: int(np.mean(v)) for k, v in rate.items()}, flush=True)
    done = set()
    for item in filter(None, a.rows.split(",")):
        label, method = item.split(":")
        label = best if label == "BEST" else label
        if (label, method) in done:
            continue
        done.add((label, method))
        use(label)
        try:
            row = bench.gpu_row("kernel-cpu" if a.cpu else "cuda", "lps", method, ns)
        except Exception as exc:
            import traceback

            traceback.print_exc()
            row = {"failed": repr(exc)}
        row["variant"] = label
        out["rows"].append(row)
        print(json.dumps(row), flush=True)
        save()
    use("lean")
    backend.kernel_source = _shipped_source
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
