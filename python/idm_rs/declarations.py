"""The model's declarations, read once from the Rust core: Table 1 (each parameter's symbol,
unit, meaning, domain and default) and the effect catalogue (each effect's id, physics, the term
it adds, and its parameters). ``Params``, ``Effects``, the sweep's units, the diagnosis catalogue
and its report all read these; none of them repeats a unit, a bound or a term.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Literal, Mapping, Optional

from . import engine

#: standard gravity of the default normal force (m1 + m2 + mPE) g [m/s^2]
GRAVITY: float = float(engine.GRAVITY)

EffectKind = Literal["term", "structure", "parameter"]


@dataclass(frozen=True)
class ParamDecl:
    """One declared quantity (SI). Its domain runs from ``lower`` (included when
    ``lower_closed``) to ``upper`` (excluded); ``rule`` says it in words ("be positive")."""

    name: str
    symbol: str
    unit: str  #: SI unit; "1" for a dimensionless number
    meaning: str
    lower: float
    upper: float
    lower_closed: bool
    rule: str
    #: Table 1's value, or an effect parameter's "no effect" value; None: derived (normal force)
    value: Optional[float]

    def contains(self, v: float) -> bool:
        """Whether ``v`` is physically valid (finite and in the domain)."""
        above = v >= self.lower if self.lower_closed else v > self.lower
        return math.isfinite(v) and above and v < self.upper


@dataclass(frozen=True)
class EffectDecl:
    """One effect of the catalogue. ``kind``: "term" (an extra force or state in the engine, its
    parameters are :class:`~idm_rs.Effects` fields), "structure" (a different structure, no
    parameters) or "parameter" (a part of the paper's model the nominal leaves out)."""

    id: str
    kind: EffectKind
    physics: str  #: the physics in one line
    term: str  #: the term it adds to the nominal equations
    params: tuple[ParamDecl, ...]


def _param(d: Mapping[str, Any]) -> ParamDecl:
    value = d["value"]
    return ParamDecl(str(d["name"]), str(d["symbol"]), str(d["unit"]), str(d["meaning"]), float(d["lower"]),
                     float(d["upper"]), bool(d["lower_closed"]), str(d["rule"]),
                     None if value is None else float(value))


#: Table 1, in field order of :class:`~idm_rs.Params`
TABLE1: tuple[ParamDecl, ...] = tuple(_param(d) for d in engine.param_declarations())

#: the effect catalogue, in the order the diagnosis tries it
EFFECTS: tuple[EffectDecl, ...] = tuple(
    EffectDecl(str(e["id"]), e["kind"], str(e["physics"]), str(e["term"]), tuple(_param(p) for p in e["params"]))
    for e in engine.effect_declarations()
)

#: the parameters of the "term" effects: the fields of :class:`~idm_rs.Effects`, in order
EFFECT_PARAMS: tuple[ParamDecl, ...] = tuple(p for e in EFFECTS if e.kind == "term" for p in e.params)

__all__ = ["EFFECTS", "EFFECT_PARAMS", "GRAVITY", "TABLE1", "EffectDecl", "EffectKind", "ParamDecl"]
