"""Packing sweep points for the kernel, and running it on a GPU (CuPy) or on the CPU (the same
source compiled by the system C compiler, loaded with ctypes)."""

from __future__ import annotations

import ctypes
import hashlib
import os
import shutil
import subprocess
import tempfile
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Optional

import numpy as np
from numpy.typing import NDArray

from .. import engine

SOURCE = Path(__file__).with_name("idm_kernel.cu")
#: outputs per point, in the kernel's order
OUTPUTS = ("final_position", "peak_velocity", "peak_friction", "slip_fraction", "status", "diverged_at")
#: the adaptive kernel's outputs after those: accepted steps, smallest step, crawled (1/0)
ADAPTIVE_EXTRA = 3
#: CUDA threads per block
BLOCK = 128


class GpuUnavailable(RuntimeError):
    """No usable GPU backend here (CuPy missing, no device, or no C compiler for the CPU build)."""


@dataclass
class KernelBatch:
    """The kernel's inputs for P points (C-contiguous). ``method`` "rk4" uses ``dt`` and
    ``steps``; "dopri5" uses ``t_end``, ``rtol``, ``atol`` and ``first_step``."""

    consts: NDArray[np.float64]  #: (P, N_CONSTANTS)
    bt: NDArray[np.float64]  #: (P, max_nb) breakpoint times [s], padded with the last
    bv: NDArray[np.float64]  #: (P, max_nb) breakpoint values [V]
    nb: NDArray[np.int32]  #: (P,) breakpoints per point
    steps: NDArray[np.int64]  #: (P,) RK4 steps
    dt: float
    method: str = "rk4"
    t_end: float = 0.0
    rtol: float = 1e-7
    atol: float = 1e-7
    first_step: float = 1e-8

    @property
    def points(self) -> int:
        return int(self.nb.size)


def prepare(config: Any, params_table: NDArray[np.float64], breakpoints: list[tuple[NDArray[np.float64],
            NDArray[np.float64]]], t_end: float, dt: float, *, method: str = "rk4", rtol: float = 1e-7,
            atol: float = 1e-7, first_step: float = 1e-8) -> KernelBatch:
    """The kernel's inputs: constants from the engine (which refuses what the kernel cannot
    run), breakpoints padded to a common length, and the step count t_end / dt (RK4) or the
    tolerances (``method="dopri5"``)."""
    _check_layout()
    consts = np.ascontiguousarray(engine.kernel_constants(config, np.ascontiguousarray(params_table, dtype=float)))
    p = consts.shape[0]
    max_nb = max(len(b[0]) for b in breakpoints)
    bt = np.empty((p, max_nb))
    bv = np.empty((p, max_nb))
    nb = np.empty(p, dtype=np.int32)
    for i, (t, v) in enumerate(breakpoints):
        k = len(t)
        bt[i, :k], bv[i, :k] = t, v
        bt[i, k:], bv[i, k:] = t[-1], v[-1]
        nb[i] = k
    steps = np.full(p, int(round(t_end / dt)), dtype=np.int64)
    return KernelBatch(consts, bt, bv, nb, steps, float(dt), method, float(t_end), float(rtol), float(atol),
                       float(first_step))


def kernel_source() -> str:
    """The kernel as compiled: the engine's layout header (the constants' offsets by name,
    ``engine.kernel_header()``) in front of ``idm_kernel.cu``."""
    return engine.kernel_header() + SOURCE.read_text()


def _check_layout() -> None:
    """The kernel source must read its constants by the names the engine declares (a source
    from another install that still counts them by hand would read past each point's row)."""
    import re

    if re.search(r"#define IDM_N_SCALARS", SOURCE.read_text()):
        raise GpuUnavailable(f"kernel source ({SOURCE}) defines its own constants' layout instead of the "
                             "engine's: reinstall idm-rs")


def _outputs(raw: NDArray[np.float64]) -> dict[str, NDArray[Any]]:
    out = {name: raw[:, i].copy() for i, name in enumerate(OUTPUTS)}
    out["status"] = out["status"].astype(np.uint8)
    out["diverged_at"] = np.where(out["status"] == 3, out["diverged_at"], np.nan)
    if raw.shape[1] > len(OUTPUTS):  # the adaptive kernel: accepted steps, smallest step, crawled
        out["steps"] = raw[:, 6].astype(np.uint64)
        out["dt_used"] = raw[:, 7].copy()
        out["crawled"] = raw[:, 8] == 1.0
    return out


# --- the CPU build --------------------------------------------------------------------------------


def _cpu_library() -> ctypes.CDLL:
    cc = os.environ.get("CC") or shutil.which("cc") or shutil.which("gcc")
    if cc is None:
        raise GpuUnavailable("no C compiler (cc) to build the kernel for the CPU")
    source = kernel_source()
    tag = hashlib.sha256(source.encode()).hexdigest()[:16]
    lib = Path(tempfile.gettempdir()) / f"idm_kernel_cpu_{tag}.so"
    if not lib.exists():
        tmp = lib.with_suffix(f".{os.getpid()}.so")
        cmd = [cc, "-O2", "-std=c99", "-shared", "-fPIC", "-x", "c", "-", "-o", str(tmp), "-lm"]
        r = subprocess.run(cmd, input=source, capture_output=True, text=True)
        if r.returncode != 0:
            raise GpuUnavailable(f"building the kernel for the CPU failed: {r.stderr.strip()[:500]}")
        os.replace(tmp, lib)
    dll = ctypes.CDLL(str(lib))
    dp = ctypes.POINTER(ctypes.c_double)
    dll.idm_rk4_sweep.argtypes = [dp, dp, dp, ctypes.POINTER(ctypes.c_int), ctypes.c_int, ctypes.c_double,
                                  ctypes.POINTER(ctypes.c_long), ctypes.c_int, dp]
    dll.idm_rk4_sweep.restype = None
    d = ctypes.c_double
    dll.idm_dopri5_sweep.argtypes = [dp, dp, dp, ctypes.POINTER(ctypes.c_int), ctypes.c_int, d, d, d, d,
                                     ctypes.c_int, dp]
    dll.idm_dopri5_sweep.restype = None
    return dll


def run_cpu(batch: KernelBatch) -> dict[str, NDArray[Any]]:
    """The kernel compiled for the CPU (one point after another): the reference the tests hold
    the GPU source to."""
    dll = _cpu_library()
    dp = ctypes.POINTER(ctypes.c_double)
    ptr = lambda a, t=dp: a.ctypes.data_as(t)  # noqa: E731
    common = (ptr(batch.consts), ptr(batch.bt), ptr(batch.bv), ptr(batch.nb, ctypes.POINTER(ctypes.c_int)),
              int(batch.bt.shape[1]))
    if batch.method == "dopri5":
        out = np.zeros((batch.points, len(OUTPUTS) + ADAPTIVE_EXTRA))
        dll.idm_dopri5_sweep(*common, batch.t_end, batch.rtol, batch.atol, batch.first_step, batch.points, ptr(out))
    else:
        out = np.zeros((batch.points, len(OUTPUTS)))
        dll.idm_rk4_sweep(*common, batch.dt, ptr(batch.steps, ctypes.POINTER(ctypes.c_long)), batch.points, ptr(out))
    return _outputs(out)


# --- the GPU --------------------------------------------------------------------------------------

_MODULE: Optional[Any] = None


def run_cuda(batch: KernelBatch) -> dict[str, NDArray[Any]]:
    """The kernel on the GPU: one thread per point, in grid order (neighbouring points share a
    warp), blocks of ``BLOCK`` threads."""
    global _MODULE
    try:
        import cupy as cp
    except ImportError:
        raise GpuUnavailable("backend='cuda' needs CuPy and an NVIDIA GPU: pip install 'idm-rs[cuda]'") from None
    try:
        if cp.cuda.runtime.getDeviceCount() < 1:
            raise GpuUnavailable("backend='cuda': no CUDA device found")
    except cp.cuda.runtime.CUDARuntimeError as exc:
        raise GpuUnavailable(f"backend='cuda': no usable CUDA device ({exc})") from None
    if _MODULE is None:
        _MODULE = cp.RawModule(code=kernel_source(), options=("--std=c++14",))
    d = {name: cp.asarray(getattr(batch, name)) for name in ("consts", "bt", "bv", "nb", "steps")}
    grid = ((batch.points + BLOCK - 1) // BLOCK,)
    common = (d["consts"], d["bt"], d["bv"], d["nb"], np.int32(batch.bt.shape[1]))
    if batch.method == "dopri5":
        out = cp.zeros((batch.points, len(OUTPUTS) + ADAPTIVE_EXTRA), dtype=cp.float64)
        _MODULE.get_function("idm_dopri5_sweep")(grid, (BLOCK,), common + (
            np.float64(batch.t_end), np.float64(batch.rtol), np.float64(batch.atol), np.float64(batch.first_step),
            np.int32(batch.points), out))
    else:
        out = cp.zeros((batch.points, len(OUTPUTS)), dtype=cp.float64)
        _MODULE.get_function("idm_rk4_sweep")(grid, (BLOCK,), common + (
            np.float64(batch.dt), d["steps"], np.int32(batch.points), out))
    return _outputs(cp.asnumpy(out))
