"""Optional physics beyond the paper's model (the catalogue of ``docs/RECORDINGS.md``, declared in
``rust/src/physics/effects.rs``).

Each effect parameter is off at 0. They run inside the Rust engine (extra forces or states),
so fits and sweeps with an effect run at engine speed. The effects and their parameters are
declared once, in the Rust core (``rust/src/physics/effects.rs``); the fields of :class:`Effects` and
their documentation are built from that declaration (``effects.pyi`` gives type checkers the same
fields; a test keeps it in step).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import fields
from typing import Mapping

import numpy as np

from .declarations import EFFECTS, ParamDecl

_DOC = """Effect parameters (SI); all 0 is the paper's model.

    Fields, each ``name`` (its effect): meaning [unit]

"""


class _EffectsBehaviour:
    """What an :class:`Effects` does; its fields come from the effect declarations."""

    def __post_init__(self) -> None:
        for f in fields(self):
            v = getattr(self, f.name)
            if isinstance(v, bool) or not isinstance(v, (int, float, np.floating, np.integer)):
                raise TypeError(f"effect parameter '{f.name}' must be a number, got {v!r}")
            v = float(v)
            if not math.isfinite(v):
                raise ValueError(f"effect parameter '{f.name}' must be finite, got {v}")
            object.__setattr__(self, f.name, v)

    def active(self) -> dict[str, float]:
        """The non-zero parameters."""
        return {f.name: getattr(self, f.name) for f in fields(self) if getattr(self, f.name) != 0.0}


def _field(effect: str, d: ParamDecl) -> tuple[str, type, dataclasses.Field]:
    meta = {"effect": effect, "symbol": d.symbol, "unit": d.unit, "meaning": d.meaning}
    return d.name, float, dataclasses.field(default=d.value, metadata=meta)


#: effect parameters of forces fixed to the bench, not to the device: they change sign in the
#: device's frame when the rig is turned end for end (an experiment's ``orientation:
#: "reversed"``). Gravity along a tilted guide is the one such force; everything else (the
#: contact, the sensor, a load hung from the device) turns with the rig.
BENCH_FIXED: frozenset[str] = frozenset({"theta_rad"})


def oriented(values: Mapping[str, float], reversed_: bool) -> dict[str, float]:
    """Effect parameters as they act in the device's frame: ``values`` with the bench-fixed
    ones (:data:`BENCH_FIXED`) negated when the rig is turned end for end."""
    if not reversed_:
        return dict(values)
    return {k: (-v if k in BENCH_FIXED else v) for k, v in values.items()}


_TERMS = [(e.id, d) for e in EFFECTS if e.kind == "term" for d in e.params]

Effects = dataclasses.make_dataclass(
    "Effects", [_field(eid, d) for eid, d in _TERMS], bases=(_EffectsBehaviour,), frozen=True,
    namespace={"__module__": __name__,
               "__doc__": _DOC + "\n".join(f"    ``{d.name}`` ({eid}): {d.meaning} [{d.unit}]" for eid, d in _TERMS)
               + "\n"},
)

__all__ = ["Effects"]
