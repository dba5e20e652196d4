"""Type stubs of the private native module (Rust, PyO3; ``rust/src/python/mod.rs``).

The public API is ``idm_rs``; inside the package only ``idm_rs.core.engine`` imports this module.
Arrays cross the boundary as numpy arrays: C-contiguous float64 inputs are read in place (a
strided one is copied), outputs are handed over without a copy. Every run releases the GIL.
Units are SI throughout: times [s], positions [m], velocities [m/s], forces [N], voltages [V].
"""

from typing import Any, Optional

import numpy as np
from numpy.typing import NDArray

__version__: str
#: standard gravity of the default normal force [m/s^2]
GRAVITY: float

class DivergenceError(RuntimeError):
    """The integration left its physical bounds (a step too large, usually); the message says
    where and suggests a smaller step. ``t`` is the time [s] it happened."""

    t: float

class RunConfig:
    """How to run: the model's structure and the integration method, shared by ``simulate`` and
    the batch. Keyword-only; checked on construction (ValueError naming the parameter: a
    ``model`` other than "lps"/"dps"/"rig", ``n_elements`` < 1 for "dps", a ``method`` other than
    "rk4"/"dopri5"/"rodas4", a non-positive ``dt`` for RK4, non-positive ``rtol``/``atol`` or
    ``first_step`` for the adaptive methods). Frozen: the attributes are read-only."""

    def __init__(
        self,
        *,
        model: str = "dps",
        n_elements: int = 4,
        piezo_hysteresis: bool = True,
        method: str = "rk4",
        dt: float = 1e-8,
        rtol: float = 1e-7,
        atol: float = 1e-7,
        first_step: Optional[float] = None,
        retries: int = 2,
        threads: int = 1,
        record_every: int = 0,
        final_states: bool = False,
        skip_cycles: int = 1,
        rig_drive: str = "position",
        rig_stiffness: float = 0.0,
        rig_damping: float = 0.0,
        rig_kp: float = 0.0,
        rig_kv: float = 0.0,
        rig_gain: float = 0.0,
        rig_limit: float = 0.0,
    ) -> None:
        """``first_step`` None = ``dt``; ``threads`` below 1 counts as 1."""

    @property
    def model(self) -> str:
        """"lps" (two lumped masses) or "dps" (the PE as a FEM bar)."""
    @property
    def n_elements(self) -> int:
        """FEM elements of the DPS bar (ignored by "lps")."""
    @property
    def piezo_hysteresis(self) -> bool:
        """Whether the piezo hysteresis state h runs."""
    @property
    def method(self) -> str:
        """"rk4" (fixed step), "dopri5" (adaptive Dormand-Prince 5(4)) or "rodas4" (adaptive
        Rosenbrock 4(3), linearly implicit)."""
    @property
    def dt(self) -> float:
        """RK4 step [s]."""
    @property
    def rtol(self) -> float:
        """Adaptive relative tolerance [-]."""
    @property
    def atol(self) -> float:
        """Adaptive absolute tolerance, in units of each state's natural scale [-]."""
    @property
    def first_step(self) -> float:
        """Adaptive methods' first trial step [s] (``dt`` when not given)."""
    @property
    def retries(self) -> int:
        """Batch: RK4 retries at dt/2, dt/4, ... of a diverging point."""
    @property
    def threads(self) -> int:
        """Batch worker threads (at least 1)."""
    @property
    def record_every(self) -> int:
        """Batch: record the sensor reading every this many RK4 steps (0: none)."""
    @property
    def final_states(self) -> bool:
        """Batch: return each point's final state."""
    @property
    def skip_cycles(self) -> int:
        """Batch: start-up cycles of a sawtooth train left out of the steady-state metrics."""
    @property
    def rig_drive(self) -> str:
        """Model "rig": "position" (a spring to a moving end, the input in m), "force" (the
        input is the force on the body [N]) or "closed_loop" (the input is the reference
        position [m] of a P-P servo loop)."""
    @property
    def rig_stiffness(self) -> float:
        """Model "rig", position drive: spring to the moving end [N/m]."""
    @property
    def rig_damping(self) -> float:
        """Model "rig", position drive: damper in parallel with the spring [N s/m]."""
    @property
    def rig_kp(self) -> float:
        """Model "rig", closed-loop drive: position gain [1/s]."""
    @property
    def rig_kv(self) -> float:
        """Model "rig", closed-loop drive: velocity gain [V s/m]."""
    @property
    def rig_gain(self) -> float:
        """Model "rig", closed-loop drive: actuator constant [N/V]."""
    @property
    def rig_limit(self) -> float:
        """Model "rig", closed-loop drive: controller saturation [V] (0: none)."""

class BatchRun:
    """A batch running on a background thread with its own worker pool (``start_batch``)."""

    @property
    def total(self) -> int:
        """Number of points."""
    def progress(self) -> int:
        """Points finished so far."""
    def cancel(self) -> None:
        """Ask the workers to stop; points already finished are kept."""
    def wait(self, timeout: float) -> bool:
        """Wait up to ``timeout`` [s] with the GIL released; True once the batch has finished."""
    def result(self) -> dict[str, Any]:
        """Join and return the outputs, one entry per point (NaN / status 0 for points not run):
        ``final_position`` [m], ``step_per_cycle`` [m], ``peak_velocity`` [m/s],
        ``peak_friction`` [N], ``slip_fraction`` [-], the steady-state metrics of sawtooth trains
        (``mean_velocity`` [m/s], ``step_mean``, ``step_std``, ``backslip`` [m],
        ``backslip_ratio`` [-], ``direction`` (+1, -1, 0 stalled); NaN for other inputs),
        ``diverged_at`` [s], ``dt_used`` [s] (float64 arrays); ``steps`` (uint64); ``status``
        (uint8: 0 not run, 1 ok, 2 retried at a smaller dt, 3 diverged, 4 invalid point);
        ``reasons`` (a list of str: why each point's status is not ok, empty where it is);
        ``traces`` (a list of float64 arrays, the sensor reading [m]) when readings were recorded;
        ``final_states`` (a list of arrays, one per point, empty where it did not finish) when
        the config asked for them. A second call raises RuntimeError."""

def simulate(
    params: dict[str, float],
    effects: dict[str, float],
    wave_t: NDArray[np.float64],
    wave_v: NDArray[np.float64],
    t_start: float,
    t_end: float,
    config: RunConfig,
    save_every: int,
    energy: bool,
    initial_state: Optional[NDArray[np.float64]] = None,
    sensitivities: Optional[list[str]] = None,
    external_force: Optional[tuple[NDArray[np.float64], NDArray[np.float64], str]] = None,
) -> dict[str, Any]:
    """Simulate one run over [``t_start``, ``t_end``] [s] under the piecewise-linear input
    (``wave_t`` [s], ``wave_v`` [V]), from rest or from ``initial_state`` (the model's state
    size, see ``state_components``). ``params`` and ``effects``: the given values by name
    (missing parameters take Table 1; effects off). Saves every ``save_every`` accepted steps
    plus the first and last state.

    Returns numpy arrays with one entry per saved time: ``t`` [s], ``nodes`` [m] and
    ``velocities`` [m/s] (time x node), ``g`` [m], ``fh`` [N], ``h`` [m], ``friction`` [N],
    ``piezo_force`` [N], ``voltage`` [V], ``reading`` [m]; ``final_state`` (the state at
    ``t_end``) and ``state_components`` (list of (name, unit)); with ``energy`` also
    ``accounting`` (time x 7: works [J] input, friction, damping, external; impulses [N s]
    friction, Rayleigh, external), ``kinetic`` [J], ``strain`` [J], ``momentum`` [kg m/s].
    With ``sensitivities`` (names), also ``sensitivity_names``, ``sensitivities`` (time x
    names: d reading / d name, exact for the discrete run) and ``final_state_sensitivities``
    (state components x names). ``external_force``: (times [s], forces [N], "main" or
    "weight"), a sampled force on that body; its samples are the sensitivity names ``f_ext[k]``.

    Raises ValueError for invalid settings (see ``check_run``) and DivergenceError when the
    integration leaves its bounds."""

def start_batch(
    config: RunConfig,
    t_end: float,
    params: NDArray[np.float64],
    effects: NDArray[np.float64],
    wave_kind: str,
    wave_fields: NDArray[np.float64],
    sampled: Optional[tuple[NDArray[np.float64], NDArray[np.float64]]] = None,
    t_ends: Optional[NDArray[np.float64]] = None,
    t_starts: Optional[NDArray[np.float64]] = None,
    initial_states: Optional[NDArray[np.float64]] = None,
    sensitivities: Optional[list[str]] = None,
    derivatives_only: bool = False,
) -> BatchRun:
    """Start a batch on a background thread. One row per point: ``params`` (P, 24) in
    ``param_names()`` order (NaN ``normal_force`` = derived from the masses), ``effects``
    (P, E) in ``effect_names()`` order, ``wave_fields`` (P, k) in ``wave_fields(wave_kind)``
    order; ``wave_kind`` "triangle", "sawtooth" or "sampled" (then ``sampled`` = the shared
    samples (t [s], V [V])). Optional per point: ``t_ends`` and ``t_starts`` [s] (P,) and
    ``initial_states`` (P, state size). ``t_end`` [s] is the span of points without their own.
    A row that is not a valid point gets status 4 (the others run); tables of the wrong shape
    raise ValueError. ``sensitivities`` (names: Table 1 and effect parameters, initial-state
    components) adds to the result ``sensitivities`` (one (names x samples) array per point:
    d trace / d name) and ``sensitivity_names``; needs recorded readings (``record_every``).
    ``derivatives_only``: the derivative passes alone, for points whose plain run the caller
    already has (finished at the configured step): no traces come back."""

def check_run(
    params: dict[str, float],
    effects: dict[str, float],
    wave_t: NDArray[np.float64],
    wave_v: NDArray[np.float64],
    t_start: float,
    t_end: float,
    config: RunConfig,
    initial_state: Optional[NDArray[np.float64]] = None,
    external_force: Optional[tuple[NDArray[np.float64], NDArray[np.float64], str]] = None,
) -> None:
    """Raise ValueError if a run with these settings would be refused: the parameters or
    effects, the input, the span, the method's settings, the RK4 step plan (breakpoints on the
    step grid, a step stable for the structure), or the initial state (size, finite, |fh| within
    the presliding bound); the message names what is wrong."""

def state_components(
    params: dict[str, float],
    effects: dict[str, float],
    config: RunConfig,
    energy: bool = False,
) -> list[tuple[str, str]]:
    """Name and unit of every state component of the model, in vector order: ``q0..`` nodal
    displacements "m", ``v0..`` nodal velocities "m/s", ``g`` "m", ``fh`` "N", ``h`` "m", then
    the states of effects that are on (``v_pe`` "V", ``x_creep`` "m", ``x_sensor`` "m") and,
    with ``energy``, the accounting states (``w_input``, ``w_friction``, ``w_damping``,
    ``w_external`` "J"; ``i_friction``, ``i_rayleigh``, ``i_external`` "N s")."""

def wave_fields(kind: str) -> list[str]:
    """Per-point waveform fields of a batch of ``kind`` ("triangle": amplitude [V], rise [s],
    fall [s], delay [s]; "sawtooth": amplitude [V], frequency [Hz], cycles, rise [s],
    forward (1/0), delay [s]; "sampled": amplitude scale [-]). ValueError for another kind."""

def highest_frequency(params: dict[str, float], config: RunConfig) -> float:
    """Highest structural natural frequency [rad/s] of the model of ``config``'s structure."""

def rk4_step_limit(params: dict[str, float], config: RunConfig) -> float:
    """The largest RK4 step [s] the damped structure of ``config`` allows: every eigenvalue of
    the first-order system inside RK4's stability region, with the up-front check's margin."""

def kernel_program(config: RunConfig, params: NDArray[np.float64],
                   effects: NDArray[np.float64]) -> tuple[str, str, NDArray[np.float64]]:
    """The GPU kernel's program for points of one shape: the generated layout ``#define``s, the
    right-hand side ``idm_rhs`` (C, traced from the engine's model of the first point) and each
    point's constants row (P, IDM_NC). ``params`` (P, len(param_names())), NaN normal_force =
    derived; ``effects`` (P, len(effect_names())). Refuses, naming the point, a model the kernel
    cannot run (a rig, a sampled force, more than MAX_DOF nodes) or whose state differs from the
    first point's."""

def kernel_accepts() -> dict[str, Any]:
    """What the GPU kernel implements: ``params``, ``effects`` (names), ``waves`` (family ->
    fields), ``structures``, ``metrics``, ``methods`` and ``max_dof``; the kernel backends refuse
    the rest."""

def library_columns(x1: NDArray[np.float64], v1: NDArray[np.float64], x2: NDArray[np.float64],
                    v2: NDArray[np.float64], volt: NDArray[np.float64], dvolt: NDArray[np.float64],
                    ff: NDArray[np.float64], t: NDArray[np.float64], vs: float, wavelength: float,
                    names: list[str]) -> NDArray[np.float64]:
    """Each library term's force [N] at each sample (samples x terms): the engine's library force
    with that term's coefficient at 1 (the periodic terms at ``wavelength`` [m]; 0: off); ``vs``
    [m/s] smooths sgn v. A name that is not a library term raises ValueError."""

def library_terms() -> tuple[list[str], list[str]]:
    """The library's terms on the main body and on the weight, as the catalogue declares them."""

def wave_breakpoints(kind: str, fields: list[float]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """The breakpoints (t [s], V [V]) of a ``kind`` ("triangle", "sawtooth") waveform with its
    fields in ``wave_fields(kind)`` order, as the engine builds its input."""

def kernel_header() -> str:
    """The C ``#define`` lines of the kernel's constants' layout (``IDM_MAX_DOF``,
    ``IDM_N_SCALARS``, ``IDM_C_<NAME>`` offsets) and of the integrators' tableaus (``IDM_RK4_*``,
    ``IDM_DP5_*``), generated by the engine: put in front of the kernel source when it is
    compiled, so source and engine cannot disagree."""

def resolve_params(params: dict[str, float]) -> dict[str, float]:
    """Table 1 overridden by ``params``, with the derived normal force [N] filled in (SI)."""

def metric_columns() -> list[tuple[str, str, str]]:
    """The batch's metric columns: (name, unit, long name), in result order."""

def param_names() -> list[str]:
    """Parameter names in the batch tables' column order."""

def effect_names() -> list[str]:
    """Effect names in the batch tables' column order."""

def param_declarations() -> list[dict[str, Any]]:
    """Table 1: name, symbol, unit, meaning, lower, upper, lower_closed, rule, value (None: derived)."""

def effect_declarations() -> list[dict[str, Any]]:
    """The effect catalogue: id, kind, physics, term, params (as in `param_declarations`)."""

def method_declarations() -> list[dict[str, Any]]:
    """The integration methods: name, adaptive (chooses its own steps), meaning, kernel (the GPU
    kernel backends run it)."""

def structure_declarations() -> list[dict[str, Any]]:
    """The structures (`model` names): name, label, meaning, elements (takes n_elements), idm."""


def simd_level() -> str:
    """The instruction set the lane groups of plain models run on: "scalar", "avx2" or "avx512"."""
    ...

def set_simd_level(level: str) -> None:
    """Choose the lane groups' instruction set: "scalar", "avx2" (the default) or "avx512" (the
    best the processor has at or below it). Results are bitwise the same; only speed differs."""
    ...
