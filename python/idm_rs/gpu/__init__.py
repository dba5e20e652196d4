"""The GPU sweep backend: one CUDA thread per sweep point running the kernel in
``idm_kernel.cu`` (through CuPy's NVRTC) with the right-hand side the engine generates from its
model for the points' shape (structure, hysteresis, the effects on), and a CPU build of the
same source that the test suite checks against the Rust engine (so every CI run verifies the
GPU physics without a GPU).

What the kernel admits is declared in the engine (``engine.kernel_accepts()``: Table 1
parameters, every effect and the library forces, Triangle and Sawtooth inputs, the LPS and the
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
    program,
    run_cpu,
    run_cuda,
    spec_of,
    wave_columns,
)

__all__ = ["GpuUnavailable", "KernelBatch", "Launched", "Spec", "all_specs", "kernel_source", "launch_cuda", "pack",
           "prepare", "program", "run_cpu", "run_cuda", "spec_of", "wave_columns"]
