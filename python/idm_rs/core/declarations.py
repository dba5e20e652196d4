"""The model's declarations, read once from the Rust core: Table 1 (each parameter's symbol,
unit, meaning, domain and default), the effect catalogue (each effect's id, physics, the term
it adds, and its parameters) and the structures (each ``model`` name, its label, whether it
takes ``n_elements``). ``Params``, ``Effects``, the sweep's units, the diagnosis catalogue and
its report, the CLI's choices and every figure's label read these; none of them repeats a unit,
a bound, a term or a structure's name.
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



@dataclass(frozen=True)
class StructureDecl:
    """One structure the engine runs (the ``model`` argument): its label in figures and reports,
    what it is, whether it takes ``n_elements`` (a FEM bar), and whether it is an IDM (a piezo
    element between two bodies) rather than a friction rig."""

    name: str
    label: str
    meaning: str
    elements: bool
    idm: bool

    def label_with(self, n_elements: int) -> str:
        """The label with the element count where the structure has one ("DPS (n = 4)")."""
        return f"{self.label} (n = {n_elements})" if self.elements else self.label


#: every structure, in the engine's order
STRUCTURES: tuple[StructureDecl, ...] = tuple(
    StructureDecl(str(s["name"]), str(s["label"]), str(s["meaning"]), bool(s["elements"]), bool(s["idm"]))
    for s in engine.structure_declarations()
)
#: the IDM's structures: the ``model`` choices of simulate, sweep, the recordings and the CLI
IDM_MODELS: tuple[str, ...] = tuple(s.name for s in STRUCTURES if s.idm)
#: the type of an IDM ``model`` argument; spelled out for the type checker, and held equal to
#: IDM_MODELS by tests/test_declarations.py
Model = Literal["lps", "dps"]
#: the type of any structure's name (the rig included), held equal to STRUCTURES likewise
StructureName = Literal["lps", "dps", "rig"]


def structure(name: str, what: str = "model", idm_only: bool = True) -> StructureDecl:
    """The declaration of structure `name`; a ValueError naming parameter `what` and the choices
    (the IDM's only, unless `idm_only` is False) when there is none."""
    choices = [s for s in STRUCTURES if s.idm or not idm_only]
    for s in choices:
        if s.name == name:
            return s
    raise ValueError(f"parameter '{what}' must be one of {', '.join(repr(s.name) for s in choices)}, got {name!r}")


def structure_label(model: str, n_elements: int) -> str:
    """A structure's label for figures and reports: "LPS", "DPS (n = 4)", "rig"."""
    return structure(model, idm_only=False).label_with(int(n_elements))


def elements_of(model: str, n_elements: int) -> int:
    """The element count a run of `model` has: `n_elements` for a bar, else 1."""
    return int(n_elements) if structure(model, idm_only=False).elements else 1


__all__ = ["EFFECTS", "EFFECT_PARAMS", "GRAVITY", "IDM_MODELS", "STRUCTURES", "TABLE1", "EffectDecl", "EffectKind",
           "Model", "ParamDecl", "StructureDecl", "StructureName", "elements_of", "structure", "structure_label"]
