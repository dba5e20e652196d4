"""The one module that talks to the native core (``idm_rs._core``, Rust through PyO3).

Everything else in the package calls the engine through the names here, so a change of the
binding touches this file only. Arrays cross the boundary as numpy arrays: C-contiguous float64
inputs are read in place (zero copy), outputs are handed over without a copy.
"""

from __future__ import annotations

from .. import _core

__version__: str = _core.__version__
DivergenceError = _core.DivergenceError
BatchRun = _core.BatchRun
#: how to run (structure + method + batch options), checked on construction
RunConfig = _core.RunConfig

simulate = _core.simulate
start_batch = _core.start_batch
check_run = _core.check_run
state_components = _core.state_components
resolve_params = _core.resolve_params
param_names = _core.param_names
metric_columns = _core.metric_columns
effect_names = _core.effect_names
wave_fields = _core.wave_fields
highest_frequency = _core.highest_frequency
rk4_step_limit = _core.rk4_step_limit
kernel_program = _core.kernel_program
kernel_header = _core.kernel_header
kernel_accepts = _core.kernel_accepts
# the engine's own forms: the library's terms along a run, a waveform family's breakpoints
library_columns = _core.library_columns
library_terms = _core.library_terms
wave_breakpoints = _core.wave_breakpoints
#: the vector lanes' instruction set ("scalar", "avx2", "avx512"): results are bitwise the same
simd_level = _core.simd_level
set_simd_level = _core.set_simd_level
# declarations of the model (Table 1, the effect catalogue); typed views in `declarations.py`
param_declarations = _core.param_declarations
effect_declarations = _core.effect_declarations
structure_declarations = _core.structure_declarations
method_declarations = _core.method_declarations
GRAVITY: float = _core.GRAVITY

__all__ = [
    "GRAVITY",
    "BatchRun",
    "DivergenceError",
    "RunConfig",
    "__version__",
    "set_simd_level",
    "simd_level",
    "check_run",
    "effect_declarations",
    "effect_names",
    "highest_frequency",
    "rk4_step_limit",
    "kernel_program",
    "kernel_header",
    "kernel_accepts",
    "library_columns",
    "library_terms",
    "param_declarations",
    "param_names",
    "method_declarations",
    "metric_columns",
    "resolve_params",
    "simulate",
    "start_batch",
    "state_components",
    "structure_declarations",
    "wave_breakpoints",
    "wave_fields",
]
