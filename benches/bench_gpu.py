"""GPU sweep throughput: idm-rs's CUDA kernels (one thread per point: RK4 at a fixed step, and
Dormand-Prince as ``method="auto"`` runs it there) on the 1,000 x 1,000 grid (m2/m1 0.25-2 x
V 40-120 V, Table 1 device, Triangle 80 V 0.5/9.5 ms, 10 ms), the DPS (n = 4) row, and the
CPU engine on the same machine's cores for the ratio; each row with points/s, wall time (host
included: packing, transfers, the Dataset), steps per point, the points rerun on the CPU, and
the error against idm-rs RK4 at dt = 1e-8 s on a random sample of points. Also: the card, the
kernels' registers / stack / occupancy as CuPy built them, and the points a stiff grid
(fric_alpha up to 2e11 N/m) hands back to the CPU under ``auto``.

    python benches/bench_gpu.py [--size 1000] [--dt 5e-8] [--rows lps:auto,lps:rk4,dps:auto]
                                [--late-rows dps:rk4] [--sample 256] [--cpu-points 16384]
                                [--stiff 200] [--ab 512] [--json PATH]
    python benches/bench_gpu.py --backend kernel-cpu --size 8 --cpu-points 64 --stiff 4   # the launch path, on the CPU

Rows are ``model:method`` with model ``lps``, ``dps`` (4 elements) or ``dpsN`` (N elements);
``--effect-rows`` runs rows again with ``--effects`` (JSON of Effects fields: by default a
spring to ground, an incline and an amplifier lag) on every point, the kernel then running
the right-hand side generated for those effects.

Runs where CuPy finds a GPU; ``--backend kernel-cpu`` runs the same kernel source compiled for
the CPU (to check the script and the launch code without a GPU; slow).
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import platform
import time
from pathlib import Path

import numpy as np

import idm_rs
from idm_rs.core import engine

P = idm_rs.Params()
W = idm_rs.Triangle(80.0, 0.5e-3, 9.5e-3)
T_END = 10e-3


def _grid(size: int) -> dict[str, np.ndarray]:
    return {"mass_ratio": np.linspace(0.25, 2.0, size), "voltage": np.linspace(40.0, 120.0, size)}


def _model(name: str) -> tuple[str, int]:
    """``lps``, ``dps`` (4 elements) or ``dpsN`` (N elements) -> (model, elements)."""
    if name == "lps":
        return "lps", 1
    return "dps", int(name[3:] or 4)


def _kw(model: str) -> dict:
    m, n = _model(model)
    return dict(t_end=T_END, model=m, n_elements=n, progress=False)


def card() -> dict:
    """The device's name and the host's cores (or the CPU's name for kernel-cpu)."""
    info = {"host_cores": os.cpu_count(), "host": platform.processor() or platform.machine()}
    try:
        import cupy as cp

        props = cp.cuda.runtime.getDeviceProperties(0)
        info.update(gpu=props["name"].decode(), sms=props["multiProcessorCount"],
                    cupy=cp.__version__, cuda_runtime=cp.cuda.runtime.runtimeGetVersion(),
                    driver=cp.cuda.runtime.driverGetVersion())
    except Exception as exc:  # no GPU: the kernel-cpu run
        info["gpu"] = f"none ({type(exc).__name__})"
    return info


def kernel_resources() -> list[dict]:
    """Registers, local (stack) bytes and shared bytes of each kernel as CuPy built it on this
    card (the LPS and the DPS with 4 elements, hysteresis on). Occupancy, pipes and stalls:
    benches/ncu_probe.py under Nsight Compute."""
    import cupy as cp

    from idm_rs.gpu import spec_of
    from idm_rs.gpu.backend import ENTRY, NVRTC_OPTIONS, kernel_source

    rows = []
    for spec in (spec_of("lps", 1, True), spec_of("dps", 4, True)):
        mod = cp.RawModule(code=kernel_source(spec), options=NVRTC_OPTIONS)
        for name in ENTRY.values():
            f = mod.get_function(name)
            row = dict(nodes=spec.nodes, kernel=name, registers=f.num_regs, local_bytes=f.local_size_bytes,
                       shared_bytes=f.shared_size_bytes, block=spec.block)
            rows.append(row)
    return rows


#: layout variants for the A/B: label -> (block for the LPS, block beyond it, extra #defines)
VARIANTS = {
    "default": (None, None, ""),
    "block 64": (64, 64, ""),
    "LPS block 256": (256, None, ""),
    "block 32": (None, 32, ""),
    "wave+metrics shared": (None, None, "#undef IDM_WAVE_SHARED\n#define IDM_WAVE_SHARED 1\n"
                            "#undef IDM_METRICS_SHARED\n#define IDM_METRICS_SHARED 1\n"),
}


def use_variant(label: str) -> None:
    """Compile the kernels with a layout variant from now on (``"default"``: as shipped)."""
    from idm_rs.gpu import backend

    if not hasattr(backend, "_shipped"):
        backend._shipped = (backend.Spec.defines, backend.Spec.block)
    defines, block = backend._shipped
    lps_block, dps_block, extra = VARIANTS[label]

    def new_defines(self):
        d = defines(self)
        return d + extra

    def new_block(self):
        b = lps_block if self.nodes == 2 else dps_block
        return b if b is not None else block.fget(self)

    backend.Spec.defines = new_defines
    backend.Spec.block = property(new_block)
    backend._MODULES.clear()


def kernel_ab(size: int, variants: list[str]) -> list[dict]:
    """The kernels alone (CUDA events, no host work) on size x size points of the grid, for the
    layout variants (VARIANTS) of both structures and methods: measured, not guessed."""
    from idm_rs import methods
    from idm_rs.core.batch import Structure, param_row
    from idm_rs.gpu import launch_cuda, pack, wave_columns

    g = _grid(size)
    rows = np.array([param_row(P.replace(m2=float(m) * P.m1)) for m in g["mass_ratio"]])
    idx = np.repeat(np.arange(size), size)
    wave = wave_columns("triangle", dict(amplitude=np.tile(g["voltage"], size), rise=0.5e-3, fall=9.5e-3, delay=0.0))
    _, rtol, atol = methods.resolve("auto")
    out = []
    for label in variants:
        use_variant(label)
        for model, nodes in (("lps", 2), ("dps", 5), ("dps", 6)):
            cfg = Structure(model, nodes - 1 if model == "dps" else 1, True).config(method="rk4", dt=5e-8)
            for method, t_end in (("rk4", 2e-3), ("dopri5", T_END)):
                kw = dict(method="dopri5", rtol=rtol, atol=atol, first_step=1e-8) if method == "dopri5" else {}
                b = pack(cfg, rows, np.zeros((rows.shape[0], len(engine.effect_names()))), idx, wave, t_end, 5e-8, **kw)
                launch_cuda(b).result()  # compile + warm
                h = launch_cuda(b)
                res = h.result()
                out.append(dict(variant=label, model=model, method=method, t_end=t_end, points=b.points,
                                block=b.spec.block, kernel_s=round(h.kernel_s, 4),
                                points_per_s=round(b.points / h.kernel_s), ok=int((res["status"] == 1).sum())))
                print(json.dumps(out[-1]), flush=True)
    use_variant("default")
    return out


def reference(model: str, i: np.ndarray, j: np.ndarray, g: dict, effects=None) -> np.ndarray:
    """x1 [m] from the CPU engine's RK4 at dt = 1e-8 s on the sampled points."""
    from idm_rs.core.batch import Point, Structure, run

    e = effects or idm_rs.Effects()
    pts = [Point(P.replace(m2=float(g["mass_ratio"][a]) * P.m1), effects=e,
                 waveform=idm_rs.Triangle(float(g["voltage"][b]), 0.5e-3, 9.5e-3)) for a, b in zip(i, j)]
    return run(pts, Structure(*_model(model), True), t_end=T_END, method="rk4", dt=1e-8)["final_position"]


def cpu_rate(model: str, method: str, dt: float, points: int, effects=None) -> float:
    """Points/s of the CPU engine (all cores, rayon) on a sub-grid of the same ranges."""
    side = max(2, int(round(points ** 0.5)))
    step = dict(dt=dt) if method == "rk4" else {}
    t0 = time.perf_counter()
    idm_rs.sweep(P, W, _grid(side), backend="cpu", method=method, effects=effects, **step, **_kw(model))
    return side * side / (time.perf_counter() - t0)


class HostClock:
    """Where a kernel sweep's wall time goes: packing (engine constants, wave columns), the
    launches (uploads), waiting for results (kernel tail + download), the kernels' own time
    (CUDA events; blocks overlap, so their sum can exceed the wait)."""

    def __init__(self) -> None:
        import idm_rs.gpu as gpu
        from idm_rs.gpu import backend

        self.t = {"pack_s": 0.0, "launch_s": 0.0, "wait_s": 0.0, "kernel_s": 0.0}
        self._saved = (gpu.pack, gpu.launch_cuda, backend.Launched.result)

        def timed(name, f):
            def wrapper(*args, **kw):
                t0 = time.perf_counter()
                r = f(*args, **kw)
                self.t[name] += time.perf_counter() - t0
                return r
            return wrapper

        gpu.pack = timed("pack_s", gpu.pack)
        gpu.launch_cuda = timed("launch_s", gpu.launch_cuda)
        result = backend.Launched.result

        def result_timed(launched):
            t0 = time.perf_counter()
            r = result(launched)
            self.t["wait_s"] += time.perf_counter() - t0
            self.t["kernel_s"] += launched.kernel_s
            return r

        backend.Launched.result = result_timed

    def close(self) -> dict:
        import idm_rs.gpu as gpu
        from idm_rs.gpu import backend

        gpu.pack, gpu.launch_cuda, backend.Launched.result = self._saved
        return {k: round(v, 3) for k, v in self.t.items()}


def gpu_row(backend: str, model: str, method: str, a, effects=None) -> dict:
    g = _grid(a.size)
    n = a.size * a.size
    rng = np.random.default_rng(0)
    flat = rng.choice(n, size=min(a.sample, n), replace=False)
    i, j = np.unravel_index(flat, (a.size, a.size))
    step = dict(dt=a.dt) if method == "rk4" else {}
    # warm-up: compiles the kernel (NVRTC) once
    idm_rs.sweep(P, W, {"voltage": [80.0]}, backend=backend, method=method, effects=effects, **step, **_kw(model))
    clock = HostClock() if backend == "cuda" else None
    t0 = time.perf_counter()
    ds = idm_rs.sweep(P, W, g, backend=backend, method=method, block_size=a.block, effects=effects, **step,
                      **_kw(model))
    wall = time.perf_counter() - t0
    split = clock.close() if clock is not None else {}
    t1 = time.perf_counter()
    ref = reference(model, i, j, g, effects)
    ref_s = time.perf_counter() - t1
    err = np.abs(ds["final_position"].values[i, j] - ref)
    reasons = ds["reason"].values.ravel().astype(str)
    rerun = int(np.count_nonzero(np.char.startswith(reasons, "failed on the kernel")))
    cpu_points = a.cpu_points // (4 if model.startswith("dps") else 1)
    cpu = cpu_rate(model, method, a.dt, cpu_points, effects) if cpu_points else float("nan")
    return dict(backend=backend, method=method, model=model, points=n,
                effects={k: v for k, v in dataclasses.asdict(effects).items() if v} if effects else {},
                dt=a.dt if method == "rk4" else None,
                rtol=ds.attrs["rtol"], wall_s=round(wall, 3), points_per_s=round(n / wall), **split,
                steps_per_point=float(ds["steps"].values.mean()), rerun_on_cpu=rerun,
                max_err_m_sampled=float(err.max()), beyond_1nm=int((err > 1e-9).sum()), sample=int(flat.size),
                statuses=np.bincount(ds.status.values.ravel(), minlength=5).tolist(),
                cpu_engine_points_per_s=round(cpu, 1), ratio_to_cpu_engine=round(n / wall / cpu, 2),
                reference_s=round(ref_s, 1))


def stiff_row(backend: str, side: int) -> dict:
    """``auto`` on a stiff grid: fric_alpha 2e10-2e11 N/m x V 40-120 V (LPS): how many points
    the kernel hands to the CPU (their step collapsed), and the wall time with them."""
    g = {"fric_alpha": np.geomspace(2e10, 2e11, side), "voltage": np.linspace(40.0, 120.0, side)}
    t0 = time.perf_counter()
    ds = idm_rs.sweep(P, W, g, backend=backend, method="auto", **_kw("lps"))
    wall = time.perf_counter() - t0
    reasons = ds["reason"].values.ravel().astype(str)
    rerun = int(np.count_nonzero(np.char.startswith(reasons, "failed on the kernel")))
    hi = ds.isel(fric_alpha=slice(side - side // 10, None))
    hi_reasons = hi["reason"].values.ravel().astype(str)
    hi_rerun = int(np.count_nonzero(np.char.startswith(hi_reasons, "failed on the kernel")))
    return dict(backend=backend, grid=f"stiff {side}x{side}: fric_alpha 2e10-2e11 x V 40-120", points=side * side,
                wall_s=round(wall, 3), rerun_on_cpu=rerun, rerun_in_top_decile_of_fric_alpha=hi_rerun,
                statuses=np.bincount(ds.status.values.ravel(), minlength=5).tolist(),
                steps_per_point=float(ds["steps"].values.mean()))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--size", type=int, default=1000)
    ap.add_argument("--dt", type=float, default=5e-8, help="RK4 step [s]")
    ap.add_argument("--rows", default="lps:auto,lps:rk4,dps:auto", help="comma-separated model:method")
    ap.add_argument("--late-rows", default="dps:rk4", help="rows run after the stiff grid and the A/B")
    ap.add_argument("--backend", default="cuda", choices=("cuda", "kernel-cpu"))
    ap.add_argument("--sample", type=int, default=256, help="points checked against RK4 dt = 1e-8")
    ap.add_argument("--cpu-points", type=int, default=16384, help="points of the CPU engine's rate (0: skip)")
    ap.add_argument("--stiff", type=int, default=200, help="side of the stiff grid (0: skip)")
    ap.add_argument("--block", type=int, default=1 << 18, help="points per streamed block")
    ap.add_argument("--ab", type=int, default=0, help="side of the grid for the kernel-only layout A/B (0: skip)")
    ap.add_argument("--variant-rows", default="", help="LABEL=rows: rows again with a layout variant (VARIANTS)")
    ap.add_argument("--ab-variants", default=",".join(VARIANTS), help="comma-separated VARIANTS for --ab")
    ap.add_argument("--effect-rows", default="", help="rows run with --effects on every point")
    ap.add_argument("--effects", default='{"k_ground": 2e3, "theta_rad": 0.05, "tau_amp": 1e-5}',
                    help="JSON of Effects fields for --effect-rows")
    ap.add_argument("--json", metavar="PATH")
    a = ap.parse_args(argv)
    out = {"card": card()}
    print(json.dumps(out["card"]), flush=True)

    def stage(name, f):
        """One part of the run; a failure is printed and the rest still runs."""
        try:
            out[name] = f()
        except Exception:
            import traceback

            traceback.print_exc()
            out[name] = f"failed: {traceback.format_exc(limit=3)}"
        if a.json:
            Path(a.json).write_text(json.dumps(out, indent=2, default=str) + "\n")
        return out[name]

    def rows(spec: str, variant: str = "default", effects=None) -> None:
        if a.backend == "cuda":
            use_variant(variant)
        for item in filter(None, spec.split(",")):
            model, method = item.split(":")
            key = (f"row_{model}_{method}" + ("" if variant == "default" else f" [{variant}]")
                   + (" [effects]" if effects else ""))
            row = stage(key, lambda model=model, method=method: dict(gpu_row(a.backend, model, method, a, effects),
                                                                     variant=variant))
            print(json.dumps(row), flush=True)
        if a.backend == "cuda":
            use_variant("default")

    # in order of what matters most, so a run cut short keeps the main figures
    if a.backend == "cuda":
        for r in stage("kernels", kernel_resources) or []:
            print(json.dumps(r), flush=True)
    rows(a.rows)
    if a.stiff:
        print(json.dumps(stage("stiff", lambda: stiff_row(a.backend, a.stiff))), flush=True)
    if a.backend == "cuda" and a.ab:
        stage("ab", lambda: kernel_ab(a.ab, a.ab_variants.split(",")))
    if a.backend == "cuda" and a.variant_rows:
        label, spec = a.variant_rows.split("=")
        rows(spec, label)
    if a.effect_rows:
        rows(a.effect_rows, effects=idm_rs.Effects(**json.loads(a.effects)))
    rows(a.late_rows)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
