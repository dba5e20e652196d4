"""Which fitted parameters the experiments pin down, and which they do not.

From the fit's exact Jacobian (the Fisher information J'J in noise units, its inverse the
covariance): each parameter's 95 % interval (value ± 1.96 sigma, the Wald interval) and, where
that interval is wider than ``DETERMINED_WITHIN`` of the value, the parameter is said to be not
determined by these experiments — with the partner it trades off against (the largest
correlation) when that correlation is strong, since then a combination of the two is fixed
while each alone is not. Measured on the three creep devices of the unseen set before issue 31:
kappa and tau_creep 28-106 % off the truth with a 1-sigma as large as the value, every other
effect parameter within 10 %; this is the case the words below are for.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Mapping, Optional, Sequence

from ..core import units
from .thresholds import DETERMINED_WITHIN, STRONG_CORRELATION

#: the normal quantile of a two-sided 95 % interval
Z95 = 1.959963984540054


@dataclass(frozen=True)
class ParamStatus:
    """One fitted parameter: its value, 1-sigma and 95 % interval [SI], whether the experiments
    determine it, and the parameter it trades off against (if strongly correlated)."""

    name: str
    value: float
    std: float
    low: float
    high: float
    determined: bool
    partner: Optional[str] = None
    correlation: float = math.nan

    @property
    def relative_halfwidth(self) -> float:
        """Half the 95 % interval over |value| (inf when the value is 0 or sigma unknown)."""
        return Z95 * self.std / abs(self.value) if self.value and math.isfinite(self.std) else math.inf

    def words(self, unit: str = "") -> str:
        u = f" {unit}" if unit and unit != "1" else ""
        interval = f"95 % interval {units.interval(self.low, self.high, unit if unit != '1' else '')}"
        if self.determined:
            return f"{self.name} = {self.value:.4g}{u} ({interval}): determined"
        tail = (f"; it trades off against {self.partner} (correlation {self.correlation:+.2f}): the experiments fix "
                f"a combination of the two, not each" if self.partner else "")
        return (f"{self.name} = {self.value:.4g}{u} ({interval}): NOT determined by these experiments (±"
                f"{100 * self.relative_halfwidth:.0f} % at 95 %){tail}")

    def to_dict(self) -> dict[str, Any]:
        return {"name": self.name, "value": self.value, "std": self.std, "low95": self.low, "high95": self.high,
                "determined": self.determined, "partner": self.partner, "correlation": self.correlation}


def assess(values: Mapping[str, float], std: Mapping[str, float], corr: Mapping[str, Mapping[str, float]],
           names: Sequence[str]) -> list[ParamStatus]:
    """The status of each of `names` (fitted values, their 1-sigma and correlations as a fit
    reports them)."""
    out = []
    for n in names:
        if n not in values:
            continue
        v = float(values[n])
        s = float(std.get(n, math.inf))
        if not math.isfinite(s):
            s = math.inf
        determined = bool(v != 0.0 and math.isfinite(s) and Z95 * s <= DETERMINED_WITHIN * abs(v))
        partner, rho = None, math.nan
        if not determined:
            row = {m: c for m, c in (corr.get(n) or {}).items() if m != n and math.isfinite(c)}
            if row:
                m, c = max(row.items(), key=lambda kv: abs(kv[1]))
                if abs(c) >= STRONG_CORRELATION:
                    partner, rho = m, float(c)
        out.append(ParamStatus(n, v, s, v - Z95 * s, v + Z95 * s, determined, partner, rho))
    return out


def undetermined(statuses: Sequence[ParamStatus]) -> list[ParamStatus]:
    return [p for p in statuses if not p.determined]
