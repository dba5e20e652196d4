"""One validation for the options the long calls share (counts, threads, retries, start-up
cycles): ``simulate``, ``sweep``, ``characterize``, ``steady_state`` and the CLI refuse the same
value with the same words, naming the parameter and what it accepts."""

from __future__ import annotations

from typing import Any, Optional


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
