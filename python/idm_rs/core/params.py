"""IDM parameters: the paper's Table 1 as defaults, names as in ``docs/MODEL.md`` (SI units).

Table 1 is declared once, in the Rust core (``rust/src/physics/params.rs``); the fields of
:class:`Params`, their defaults and :data:`PARAM_INFO` are built from that declaration
(``params.pyi`` gives type checkers the same fields; a test keeps it in step).
"""

from __future__ import annotations

import dataclasses
import warnings
from dataclasses import fields
from typing import Any, Mapping, Optional

import numpy as np

from . import engine
from .declarations import GRAVITY, TABLE1, ParamDecl

#: symbol, unit and meaning of each parameter (for docs, xarray attributes and reports)
PARAM_INFO: dict[str, tuple[str, str, str]] = {d.name: (d.symbol, d.unit, d.meaning) for d in TABLE1}

_DOC = """IDM parameters in SI units; defaults are the paper's Table 1.

    ``normal_force`` [N] defaults to ``None``: the weight of the whole device,
    (m1 + m2 + mPE)·g, recomputed from the masses (see :attr:`effective_normal_force`).
    Validated on construction: every value finite, masses, lengths, moduli and areas positive
    (``pe_density`` may be 0: a massless PE); each error names the parameter.

    Fields (symbol, meaning [unit], default):

"""


class _ParamsBehaviour:
    """What a :class:`Params` does; its fields come from Table 1's declaration."""

    def __post_init__(self) -> None:
        for f in fields(self):
            v = getattr(self, f.name)
            if v is None and f.name == "normal_force":
                continue
            if isinstance(v, (bool, np.bool_)):
                raise TypeError(f"parameter '{f.name}' must be a number, got the boolean {v!r}")
            if not isinstance(v, (int, float)):
                try:
                    v = float(v)  # numpy scalars
                except (TypeError, ValueError):
                    raise TypeError(f"parameter '{f.name}' must be a number, got {v!r}") from None
            object.__setattr__(self, f.name, float(v))
        engine.resolve_params(self._given())  # raises ValueError naming the parameter
        if self.mu_s < self.mu_k:
            warnings.warn(f"mu_s = {self.mu_s:g} is below mu_k = {self.mu_k:g}: the Stribeck curve then rises with "
                          "speed (no breakaway peak); the presliding bound uses max(mu_s, mu_k)", RuntimeWarning,
                          stacklevel=4)

    def _given(self) -> dict[str, float]:
        d = {f.name: getattr(self, f.name) for f in fields(self)}
        if d["normal_force"] is None:
            del d["normal_force"]
        return d

    @classmethod
    def from_dict(cls, values: Mapping[str, Any]) -> Any:
        """Build from a mapping; unknown names are refused with a ValueError naming them."""
        known = {f.name for f in fields(cls)}
        unknown = sorted(set(values) - known)
        if unknown:
            raise ValueError(f"unknown parameter(s) {unknown}; known: {sorted(known)}")
        return cls(**dict(values))

    def replace(self, **changes: Any) -> Any:
        """A copy with some values changed (validated)."""
        unknown = sorted(set(changes) - {f.name for f in fields(self)})
        if unknown:
            raise ValueError(f"unknown parameter(s) {unknown}")
        return dataclasses.replace(self, **changes)

    @property
    def pe_mass(self) -> float:
        """PE mass rho_p Ap l [kg]."""
        return self.pe_density * self.pe_area * self.pe_length

    @property
    def kp(self) -> float:
        """PE stiffness Ep Ap / l [N/m]."""
        return self.pe_youngs * self.pe_area / self.pe_length

    @property
    def effective_normal_force(self) -> float:
        """The normal force used [N]: as set, or (m1 + m2 + mPE) g."""
        if self.normal_force is not None:
            return self.normal_force
        return (self.m1 + self.m2 + self.pe_mass) * GRAVITY

    def to_dict(self, resolved: bool = True) -> dict[str, float]:
        """All parameters; with ``resolved`` the derived normal force is filled in."""
        return dict(engine.resolve_params(self._given())) if resolved else self._given()


def _field(d: ParamDecl) -> tuple[str, Any, Any]:
    meta = {"symbol": d.symbol, "unit": d.unit, "meaning": d.meaning}
    if d.value is None:  # derived unless set (the normal force)
        return d.name, Optional[float], dataclasses.field(default=None, metadata=meta)
    return d.name, float, dataclasses.field(default=d.value, metadata=meta)


def _doc_line(d: ParamDecl) -> str:
    default = "derived" if d.value is None else repr(d.value)
    return f"    ``{d.name}``: {d.symbol}, {d.meaning} [{d.unit}] = {default}"


Params = dataclasses.make_dataclass(
    "Params", [_field(d) for d in TABLE1], bases=(_ParamsBehaviour,), frozen=True,
    namespace={"__module__": __name__, "__doc__": _DOC + "\n".join(_doc_line(d) for d in TABLE1) + "\n"},
)

__all__ = ["GRAVITY", "PARAM_INFO", "Params"]
