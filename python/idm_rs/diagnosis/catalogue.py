"""The catalogue of physics a nominal model may lack (docs/RECORDINGS.md), as data.

What each effect *is* (id, one-line physics, the term it adds, its parameters with units and
physical bounds) is declared once in the Rust core (``rust/src/physics/effects.rs``) and read here through
:mod:`idm_rs.core.declarations`. This module adds only how the diagnosis *fits* it: per parameter the
fit bounds, scale, starting values and log scaling (:data:`FIT`), and per effect how it enters
the model when it is not a plain engine term (:data:`PLACEMENT`). Adding an effect means
declaring it in Rust (with its term in the engine) and giving its parameters a line in
:data:`FIT`.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Any, Callable, Mapping, Optional

from ..core.batch import Structure
from ..core.declarations import EFFECT_PARAMS, EFFECTS, TABLE1, EffectDecl, EffectKind, ParamDecl
from .fitting import FreeParam, Setter, set_effect, set_param

#: a fitted effect's parameters as reported: (fitted values, their 1-sigma) of every free
#: parameter -> {reported name: (value, 1-sigma or None)}
Reported = Callable[[Mapping[str, float], Mapping[str, float]], dict[str, tuple[float, Optional[float]]]]


@dataclass(frozen=True)
class FitSetting:
    """How the diagnosis fits one parameter: bounds [lower, upper] (within the physical domain),
    the scale of one fit unit, the values tried before the fit (the best is kept), and whether
    it is fitted in log scale. `setter`: how it enters the model; default by where the name
    lives (an Effects field or a Table 1 parameter)."""

    lower: float
    upper: float
    scale: float
    starts: tuple[float, ...] = (0.0,)
    log: bool = False
    setter: Optional[Setter] = None
    #: the readings have a kink at "no effect" (the derivative there is one-sided and may be the
    #: wrong side): the screening score is taken at the starting values too
    kink: bool = False


def _stribeck_setter(params: dict[str, Any], effects: dict[str, float], excess: float) -> None:
    # mu_s = mu_k (1 + excess): keeps mu_s >= mu_k whatever mu_k the fit is at
    params["mu_s"] = params["mu_k"] * (1.0 + excess)


#: fit settings of every declared effect parameter, by name
FIT: dict[str, FitSetting] = {
    "hyst_alpha": FitSetting(1e-5, 2.0, 1.0, starts=(1e-4, 1e-3, 1e-2, 0.1), log=True),
    "mu_s_excess": FitSetting(0.0, 0.5, 0.01, starts=(0.0, 0.02, 0.1), setter=_stribeck_setter, kink=True),
    "theta_rad": FitSetting(-0.02, 0.02, 1e-4),
    "k_ground": FitSetting(0.0, 2e5, 1e3, starts=(0.0, 2e3, 2e4)),
    # log scale from 0.3 us: a lag much shorter than the fit's step would make the state
    # stiff (and is invisible at 10 us sampling anyway)
    "tau_amp": FitSetting(3e-7, 2e-4, 1.0, starts=(1e-6, 5e-6, 3e-5), log=True),
    "kappa": FitSetting(0.0, 0.5, 0.005, starts=(0.01,)),
    "tau_creep": FitSetting(1e-4, 0.2, 1.0, starts=(1e-3, 5e-3, 3e-2), log=True),
    "c_weight": FitSetting(0.0, 100.0, 0.5, starts=(0.0, 1.0, 5.0)),
    "eps": FitSetting(-0.3, 0.3, 1e-3),
    "tau_sensor": FitSetting(3e-7, 2e-4, 1.0, starts=(1e-6, 1e-5, 5e-5), log=True),
    "drift_rate": FitSetting(-1e-4, 1e-4, 1e-7),
}


def _always(s: Structure, p: Mapping[str, Any]) -> bool:
    return True


def _unchanged(s: Structure) -> Structure:
    return s


def _as_fitted(values: Mapping[str, float], std: Mapping[str, float], names: tuple[str, ...]
               ) -> dict[str, tuple[float, Optional[float]]]:
    return {n: (values[n], std.get(n)) for n in names}


def _stribeck_reported(values: Mapping[str, float], std: Mapping[str, float]
                       ) -> dict[str, tuple[float, Optional[float]]]:
    # reported as the friction coefficients themselves, mu_s = mu_k (1 + excess); the 1-sigma of
    # mu_s is mu_k times that of the excess (mu_k's own is the calibration's, not shown here)
    mu_k = values["mu_k"]
    return {"mu_s": (mu_k * (1.0 + values["mu_s_excess"]), mu_k * std["mu_s_excess"]), "mu_k": (mu_k, None)}


@dataclass(frozen=True)
class Placement:
    """How an effect enters the model beyond its parameters: whether the nominal model can lack
    it, the structure with it in place, and how its fitted parameters are reported (None: under
    their own names)."""

    applies: Callable[[Structure, Mapping[str, Any]], bool] = _always
    structure: Callable[[Structure], Structure] = _unchanged
    reported: Optional[Reported] = None


#: effects that are more than an engine term, by id (every other effect: `Placement()`)
PLACEMENT: dict[str, Placement] = {
    "pe_mass": Placement(applies=lambda s, p: s.model == "lps",
                         structure=lambda s: replace(s, model="dps", n_elements=4)),
    "piezo_hysteresis": Placement(applies=lambda s, p: not s.piezo_hysteresis,
                                  structure=lambda s: replace(s, piezo_hysteresis=True)),
    "stribeck": Placement(applies=lambda s, p: p["mu_s"] <= p["mu_k"], reported=_stribeck_reported),
}


@dataclass(frozen=True)
class EffectParam:
    """A parameter of an effect: its declaration's name and unit, the fit bounds
    [lower, upper] and the physical domain they lie in. `starts`: values tried before the fit."""

    name: str
    lower: float
    upper: float
    scale: float
    unit: str
    starts: tuple[float, ...] = (0.0,)
    log: bool = False
    setter: Optional[Setter] = None  # default: the Effects field of the same name
    #: the physical domain (declared): [physical_lower, physical_upper)
    physical_lower: float = float("-inf")
    physical_upper: float = float("inf")
    #: the declared "no effect" value: at it the effect vanishes
    none: float = 0.0
    #: a kink at "no effect" (see FitSetting.kink)
    kink: bool = False

    def free(self, start: float) -> FreeParam:
        setter = self.setter or set_effect(self.name)
        x0 = start if not self.log else max(start, self.lower)
        return FreeParam(self.name, x0, self.lower, self.upper, self.scale, setter, self.log, self.unit)


@dataclass(frozen=True)
class Effect:
    """One catalogue entry: the declaration, its fit settings and its placement."""

    id: str
    description: str  #: the declared physics in one line
    params: tuple[EffectParam, ...]
    #: whether the nominal model can lack it (e.g. `pe_mass` only for an LPS nominal)
    applies: Callable[[Structure, Mapping[str, Any]], bool] = _always
    #: the structure with the effect in place
    structure: Callable[[Structure], Structure] = _unchanged
    term: str = ""  #: the declared term it adds to the nominal equations
    kind: EffectKind = "term"
    reported_as: Optional[Reported] = field(default=None, repr=False)

    def reported(self, values: Mapping[str, float], std: Mapping[str, float]
                 ) -> dict[str, tuple[float, Optional[float]]]:
        """{name: (value, 1-sigma or None)} of the effect as reported, from the fitted values and
        1-sigma of every free parameter of its fit."""
        if self.reported_as is not None:
            return self.reported_as(values, std)
        return _as_fitted(values, std, tuple(p.name for p in self.params))


_TABLE1_NAMES = frozenset(d.name for d in TABLE1)
_FIELD_NAMES = frozenset(d.name for d in EFFECT_PARAMS)


def _default_setter(name: str) -> Setter:
    if name in _FIELD_NAMES:
        return set_effect(name)
    if name in _TABLE1_NAMES:
        return set_param(name)
    raise ValueError(f"effect parameter '{name}' is neither an Effects field nor a Table 1 parameter: "
                     f"give it a setter in diagnosis/catalogue.py FIT")


def _param(effect: str, d: ParamDecl) -> EffectParam:
    s = FIT.get(d.name)
    if s is None:
        raise ValueError(f"parameter '{d.name}' of effect '{effect}' has no fit setting in diagnosis/catalogue.py FIT")
    if not (d.contains(s.lower) and d.contains(s.upper)):
        raise ValueError(f"fit bounds [{s.lower}, {s.upper}] of '{d.name}' leave its physical domain "
                         f"(it must {d.rule})")
    return EffectParam(d.name, s.lower, s.upper, s.scale, d.unit, s.starts, s.log, s.setter or _default_setter(d.name),
                       d.lower, d.upper, 0.0 if d.value is None else float(d.value), s.kink)


def _entry(e: EffectDecl) -> Effect:
    p = PLACEMENT.get(e.id, Placement())
    return Effect(e.id, e.physics, tuple(_param(e.id, d) for d in e.params), p.applies, p.structure, e.term, e.kind,
                  p.reported)


#: the library forces are declared as effects (the engine runs them like any other) but are not
#: catalogue entries: their terms are what discovery (`discovery/`) finds and fits
LIBRARY_IDS = frozenset({"library_force", "library_force_weight"})

CATALOGUE: tuple[Effect, ...] = tuple(_entry(e) for e in EFFECTS if e.id not in LIBRARY_IDS)


def by_id(effect_id: str) -> Effect:
    for e in CATALOGUE:
        if e.id == effect_id:
            return e
    raise KeyError(f"no effect {effect_id!r} in the catalogue; known: {[e.id for e in CATALOGUE]}")
