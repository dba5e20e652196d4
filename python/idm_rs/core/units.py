"""Numbers as people read them: significant digits with an SI prefix and the unit (2.68 µm,
25 fm, 0.558 N), and intervals with as many digits as it takes to tell their ends apart."""

from __future__ import annotations

import math

#: SI prefixes from 1e-15 to 1e9
_PREFIXES = ((1e9, "G"), (1e6, "M"), (1e3, "k"), (1.0, ""), (1e-3, "m"), (1e-6, "µ"), (1e-9, "n"), (1e-12, "p"),
             (1e-15, "f"))

#: units that take no prefix (ratios, counts, angles)
_BARE = ("", "1", "-", "%", "rad")


def si(value: float, unit: str, digits: int = 4) -> str:
    """``value`` [``unit``] with ``digits`` significant digits and the SI prefix that puts it in
    [1, 1000): ``si(-2.68e-6, "m")`` -> ``"-2.68 µm"``, ``si(2.5e-14, "m")`` -> ``"25 fm"``,
    ``si(0, "m")`` -> ``"0 m"``; NaN and infinities as ``"nan m"``."""
    if not math.isfinite(value):
        return f"{value} {unit}".strip()
    if unit in _BARE:
        return f"{value:.{digits}g}" + (f" {unit}" if unit not in ("", "1", "-") else "")
    if value == 0:
        return f"0 {unit}"
    scale, prefix = next(((s, p) for s, p in _PREFIXES if abs(value) >= s * (1 - 1e-12)), _PREFIXES[-1])
    return f"{value / scale:.{digits}g} {prefix}{unit}"


def interval(low: float, high: float, unit: str = "") -> str:
    """``[low, high] unit`` with the digits needed to tell the ends apart (at least 3 significant,
    at most 12), on the SI prefix of the larger end: ``[1.2381e-07, 1.2419e-07]`` reads
    ``[123.81, 124.19] nm``."""
    big = max(abs(low), abs(high))
    if not (math.isfinite(low) and math.isfinite(high)) or unit in _BARE or big == 0:
        digits = next((d for d in range(3, 13) if f"{low:.{d}g}" != f"{high:.{d}g}"), 12)
        u = f" {unit}" if unit not in _BARE else ""
        return f"[{low:.{digits}g}, {high:.{digits}g}]{u}"
    scale, prefix = next(((s, p) for s, p in _PREFIXES if big >= s * (1 - 1e-12)), _PREFIXES[-1])
    a, b = low / scale, high / scale
    digits = next((d for d in range(3, 13) if f"{a:.{d}g}" != f"{b:.{d}g}"), 12)
    return f"[{a:.{digits}g}, {b:.{digits}g}] {prefix}{unit}"
