"""Parameter sweeps: :func:`~.sweep.sweep` (the user's entry point), its plan (grids, metrics,
durations), the backends behind one protocol (the CPU engine, Dask, the kernel on the CPU and on
CUDA) and the on-disk store. Uses the core layer and the GPU layer's program builder."""
