"""Compile the kernel with NVRTC as the CUDA backend does, without a GPU (NVRTC is a host
library: the ``nvidia-cuda-nvrtc`` wheel), and read ptxas's resource report: registers, stack
frame and spills per kernel. The test suite uses it to hold every kernel the backend launches to
0 bytes of stack and 0 spills (state in registers)."""

from __future__ import annotations

import ctypes
import glob
import os
import re
import sys
from dataclasses import dataclass
from typing import Optional, Sequence


class NvrtcUnavailable(RuntimeError):
    """No NVRTC library here (``pip install nvidia-cuda-nvrtc``)."""


@dataclass(frozen=True)
class KernelResources:
    """ptxas's report for one entry point: registers, stack frame [bytes], spill stores and
    loads [bytes]."""

    name: str
    registers: int
    stack: int
    spill_stores: int
    spill_loads: int


def _library() -> ctypes.CDLL:
    """libnvrtc from the nvidia-cuda-nvrtc wheel (CUDA 13, then 12), or the system's."""
    roots = [p for p in sys.path if os.path.isdir(p)]
    names = []
    for root in roots:
        for sub in ("nvidia/cu13/lib", "nvidia/cuda_nvrtc/lib"):
            names += sorted(glob.glob(os.path.join(root, sub, "libnvrtc.so*")))
    names += ["libnvrtc.so.13", "libnvrtc.so.12", "libnvrtc.so"]
    for name in names:
        if "builtins" in name:
            continue
        try:
            return ctypes.CDLL(name)
        except OSError:
            continue
    raise NvrtcUnavailable("no NVRTC library: pip install nvidia-cuda-nvrtc")


def compile_report(source: str, arch: str, options: Sequence[str] = (),
                   name: str = "idm_kernel.cu") -> tuple[int, str]:
    """Compile ``source`` for ``arch`` (e.g. "sm_90") with NVRTC and ptxas's verbose report:
    (NVRTC's result, 0 = success; the program log). The options are CuPy's for a RawModule
    (``-ftz=true``, ``--device-as-default-execution-space``, ``-arch=sm_XX``) after ``options``."""
    lib = _library()
    prog = ctypes.c_void_p()
    r = lib.nvrtcCreateProgram(ctypes.byref(prog), source.encode(), name.encode(), 0, None, None)
    if r != 0:
        raise RuntimeError(f"nvrtcCreateProgram failed ({r})")
    opts = [o.encode() for o in (*options, "-ftz=true", f"-arch={arch}", "--device-as-default-execution-space",
                                 "-Xptxas", "-v")]
    try:
        r = lib.nvrtcCompileProgram(prog, len(opts), (ctypes.c_char_p * len(opts))(*opts))
        size = ctypes.c_size_t()
        lib.nvrtcGetProgramLogSize(prog, ctypes.byref(size))
        buf = ctypes.create_string_buffer(size.value)
        lib.nvrtcGetProgramLog(prog, buf)
        return r, buf.value.decode(errors="replace")
    finally:
        lib.nvrtcDestroyProgram(ctypes.byref(prog))


def resources(log: str) -> list[KernelResources]:
    """The entry points' resources in a ptxas -v log."""
    out: list[KernelResources] = []
    current: Optional[str] = None
    stack = stores = loads = 0
    for line in log.splitlines():
        m = re.search(r"Compiling entry function '(\w+)'", line)
        if m:
            current = m.group(1)
            continue
        m = re.search(r"(\d+) bytes stack frame, (\d+) bytes spill stores, (\d+) bytes spill loads", line)
        if m and current is not None:
            stack, stores, loads = (int(g) for g in m.groups())
            continue
        m = re.search(r"Used (\d+) registers", line)
        if m and current is not None:
            out.append(KernelResources(current, int(m.group(1)), stack, stores, loads))
            current = None
    return out
