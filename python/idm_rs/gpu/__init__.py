"""The GPU sweep backend: one CUDA thread per sweep point running the kernel in
``idm_kernel.cu`` (through CuPy's NVRTC), and a CPU build of the same source that the test
suite checks against the Rust engine (so every CI run verifies the GPU physics without a GPU).

Supported: fixed-step RK4 and adaptive Dormand-Prince (with the engine's step collapse check),
the LPS or the DPS with up to 5 elements, piezo hysteresis on or off, no effects; anything else
is refused with the reason."""

from .backend import GpuUnavailable, KernelBatch, prepare, run_cpu, run_cuda

__all__ = ["GpuUnavailable", "KernelBatch", "prepare", "run_cpu", "run_cuda"]
