"""The GPU sweep backend: one CUDA thread per sweep point running the kernel in
``idm_kernel.cu`` (through CuPy's NVRTC), specialised at compile time per structure and
hysteresis, and a CPU build of the same source that the test suite checks against the Rust
engine (so every CI run verifies the GPU physics without a GPU).

What the kernel admits is declared in the engine (``engine.kernel_accepts()``: Table 1
parameters including ``load_force``, no effects, Triangle and Sawtooth inputs, the LPS and the
DPS up to 5 elements, the per-point metrics); the sweep refuses anything else by name."""

from .backend import (
    GpuUnavailable,
    KernelBatch,
    Launched,
    Spec,
    all_specs,
    kernel_source,
    launch_cuda,
    pack,
    prepare,
    run_cpu,
    run_cuda,
    wave_columns,
)

__all__ = ["GpuUnavailable", "KernelBatch", "Launched", "Spec", "all_specs", "kernel_source", "launch_cuda", "pack",
           "prepare", "run_cpu", "run_cuda", "wave_columns"]
