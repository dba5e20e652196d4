"""Type stubs of the private native module (Rust, PyO3). The public API is `idm_rs`."""

from typing import Any, Optional, Sequence

import numpy as np
from numpy.typing import NDArray

__version__: str
#: standard gravity of the default normal force [m/s^2]
GRAVITY: float

class DivergenceError(RuntimeError):
    """The integration left its physical bounds; `t` is the time [s] it happened."""

    t: float

class BatchRun:
    """A batch running on a background thread with its own rayon pool."""

    @property
    def total(self) -> int: ...
    def progress(self) -> int:
        """Points finished so far."""
    def cancel(self) -> None:
        """Ask the workers to stop; finished points are kept."""
    def wait(self, timeout: float) -> bool:
        """Wait up to `timeout` s with the GIL released; True once finished."""
    def result(self) -> dict[str, Any]:
        """Metric arrays (and `traces` when readings were recorded); NaN for points not run."""

def simulate(
    params: dict[str, float],
    effects: dict[str, float],
    wave_t: Sequence[float],
    wave_v: Sequence[float],
    t_end: float,
    dt: float,
    model: str,
    n_elements: int,
    save_every: int,
    piezo_hysteresis: bool,
    energy: bool,
) -> dict[str, NDArray[np.float64]]: ...
def start_batch(
    params: NDArray[np.float64],
    effects: NDArray[np.float64],
    waves: NDArray[np.float64],
    sampled_t: Optional[Sequence[float]],
    sampled_v: Optional[Sequence[float]],
    model: str,
    n_elements: int,
    piezo_hysteresis: bool,
    t_end: float,
    dt: float,
    method: str,
    rtol: float,
    atol: float,
    retries: int,
    threads: int,
    t_ends: Optional[Sequence[float]] = None,
    record_every: int = 0,
) -> BatchRun: ...
def check_plan(
    params: dict[str, float],
    effects: dict[str, float],
    wave_t: Sequence[float],
    wave_v: Sequence[float],
    t_end: float,
    dt: float,
    model: str,
    n_elements: int,
    method: str,
) -> None: ...
def resolve_params(params: dict[str, float]) -> dict[str, float]: ...
def param_names() -> list[str]: ...
def effect_names() -> list[str]: ...
def wave_columns() -> list[str]: ...
def highest_frequency(params: dict[str, float], model: str, n_elements: int) -> float: ...
def param_declarations() -> list[dict[str, Any]]:
    """Table 1: name, symbol, unit, meaning, lower, upper, lower_closed, rule, value (None: derived)."""
def effect_declarations() -> list[dict[str, Any]]:
    """The effect catalogue: id, kind, physics, term, params (as in `param_declarations`)."""
