"""One validation for the options the long calls share (counts, threads, retries, start-up
cycles): ``simulate``, ``sweep``, ``characterize``, ``steady_state`` and the CLI refuse the same
value with the same words, naming the parameter and what it accepts."""

from __future__ import annotations

import math
import warnings
from typing import Any, Optional

import numpy as np

from .declarations import STRUCTURES


def count(name: str, value: Any, minimum: int = 1) -> int:
    """``value`` as an int, refused unless it is a whole number >= ``minimum`` (a bool, a
    fraction, NaN, infinity or text is refused by name, not passed on to fail deeper)."""
    try:
        ok = not isinstance(value, (bool, str)) and int(value) == value and value >= minimum
    except (TypeError, ValueError, OverflowError):
        ok = False
    if not ok:
        what = "a positive integer" if minimum == 1 else f"an integer >= {minimum}"
        raise ValueError(f"parameter '{name}' must be {what}, got {value!r}")
    return int(value)


def threads(value: Any) -> Optional[int]:
    """``threads``: None (every core) or a positive count."""
    if value is None:
        return None
    try:
        return count("threads", value)
    except ValueError:
        raise ValueError(f"parameter 'threads' must be a positive integer or None (every core), "
                         f"got {value!r}") from None


def skip_cycles(value: Any, cycles: Optional[int]) -> int:
    """``skip_cycles``: the start-up cycles left out of the steady state, fewer than the train's
    ``cycles`` (the fewest over a sweep's grid; None when the input is not a train)."""
    k = count("skip_cycles", value, minimum=0)
    if cycles is not None and cycles <= k:
        raise ValueError(f"the train has {cycles} cycles and skip_cycles = {k} skips them all (its steady-state "
                         "metrics would be NaN); use more cycles or skip fewer")
    return k


def time(name: str, value: Any) -> float:
    """A time [s] given as a number: refused by name when it is text, None, NaN, infinite or
    not positive (``t_end='10e-3'`` used to fail on an unsupported operand deep inside)."""
    if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise TypeError(f"parameter '{name}' must be a time in seconds (a number), got {value!r}")
    t = float(value)
    if not (t > 0 and math.isfinite(t)):
        raise ValueError(f"parameter '{name}' must be a positive, finite time [s], got {value!r}")
    return t


def elements(model: Any, n_elements: Optional[Any], default: int = 4, say_ignored: bool = False) -> int:
    """The FEM bar's element count for ``model``: ``n_elements`` (None: ``default``) for the DPS;
    1 for a structure declared without elements (the LPS, which has no bar). ``say_ignored``:
    warn, by name, that the LPS ignores a count other than 1 (the command line, where it was typed
    for this run; the API stays quiet, as code that loops over both models passes one count to
    each). Another model (a rig) keeps it."""
    n = default if n_elements is None else count("n_elements", n_elements)
    decl = next((s for s in STRUCTURES if s.idm and s.name == model), None) if isinstance(model, str) else None
    if decl is not None and not decl.elements:
        if say_ignored and n_elements is not None and n != 1:
            warnings.warn(f"--n-elements {n} is for --model dps (the FEM bar); the {decl.label} has none and ignores "
                          "it", UserWarning, stacklevel=3)
        return 1
    return n


def tolerances_for(method: str, rtol: Any, atol: Any) -> None:
    """A tolerance given to RK4 (fixed step) is said to be ignored, by name."""
    given = [n for n, v in (("rtol", rtol), ("atol", atol)) if v is not None]
    if method == "rk4" and given:
        warnings.warn(f"{' and '.join(given)} are for the adaptive methods ('dopri5', 'rodas4', 'auto'); RK4 takes a "
                      "fixed step dt and ignores them", UserWarning, stacklevel=3)
