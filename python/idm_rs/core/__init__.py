"""The core layer: the engine binding (:mod:`.engine`), the model's inputs (parameters,
effects, waveforms, external forces, states), the solver options, the batch runner and
:func:`~.simulation.simulate`. It imports nothing of the layers above it (io, gpu, sweeps,
diagnosis, rigs, apps)."""
