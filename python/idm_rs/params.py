"""IDM parameters: the paper's Table 1 as defaults, names as in ``MODEL.md`` (SI units)."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, fields
from typing import Any, Mapping, Optional

from . import engine

GRAVITY = 9.81  # m/s^2, as in MODEL.md's default normal force

#: symbol, unit and meaning of each parameter (for docs, xarray attributes and reports)
PARAM_INFO: dict[str, tuple[str, str, str]] = {
    "m1": ("m1", "kg", "main body mass"),
    "m2": ("m2", "kg", "weight mass"),
    "pe_area": ("Ap", "m^2", "PE cross-section"),
    "pe_youngs": ("Ep", "N/m^2", "PE Young's modulus"),
    "pe_length": ("l", "m", "PE length"),
    "pe_density": ("rho_p", "kg/m^3", "PE density"),
    "d33": ("d33", "m/V", "piezoelectric constant"),
    "rayleigh_alpha": ("alpha_c", "1/s", "mass-proportional Rayleigh damping"),
    "rayleigh_beta": ("beta_c", "s", "stiffness-proportional Rayleigh damping"),
    "hyst_alpha": ("a_p", "1", "Bouc-Wen piezo hysteresis amplitude"),
    "hyst_beta": ("b_p", "1/V", "Bouc-Wen piezo hysteresis shape"),
    "hyst_gamma": ("c_p", "1/V", "Bouc-Wen piezo hysteresis shape"),
    "fric_alpha": ("a", "N/m", "presliding stiffness"),
    "fric_beta": ("b", "1/m", "presliding hysteresis shape"),
    "fric_gamma": ("c", "1/m", "presliding hysteresis shape"),
    "fric_n": ("n", "1", "Leuven transition-curve exponent"),
    "stribeck_velocity": ("v_s", "m/s", "Stribeck velocity"),
    "stribeck_exponent": ("delta", "1", "Stribeck exponent"),
    "mu_k": ("mu_k", "1", "kinetic (Coulomb) friction coefficient"),
    "mu_s": ("mu_s", "1", "static friction coefficient"),
    "sigma1": ("sigma1 (r1)", "N s/m", "presliding damping"),
    "sigma2": ("sigma2 (r2)", "N s/m", "viscous friction"),
    "normal_force": ("F_n", "N", "normal force on the guide; default (m1+m2+mPE) g"),
}


@dataclass(frozen=True)
class Params:
    """IDM parameters in SI units; defaults are the paper's Table 1.

    ``normal_force`` [N] defaults to ``None``: the weight of the whole device,
    (m1 + m2 + mPE)·g, recomputed from the masses (see :attr:`effective_normal_force`).
    Validated on construction: every value finite, masses, lengths, moduli and areas positive
    (``pe_density`` may be 0: a massless PE); each error names the parameter.
    """

    m1: float = 0.4  #: main body mass [kg]
    m2: float = 0.3  #: weight mass [kg]
    pe_area: float = 2.5e-5  #: PE cross-section Ap [m^2]
    pe_youngs: float = 2.216e10  #: PE Young's modulus Ep [N/m^2]
    pe_length: float = 2e-2  #: PE length l [m]
    pe_density: float = 8000.0  #: PE density rho_p [kg/m^3]
    d33: float = 1.24e-7  #: piezoelectric constant [m/V]
    rayleigh_alpha: float = 4e3  #: alpha_c [1/s]
    rayleigh_beta: float = 5e-7  #: beta_c [s]
    hyst_alpha: float = 0.4297  #: a_p [-]
    hyst_beta: float = 3.438e-2  #: b_p [1/V]
    hyst_gamma: float = -2.865e-3  #: c_p [1/V]
    fric_alpha: float = 2e10  #: a [N/m]
    fric_beta: float = 0.2e10  #: b [1/m]
    fric_gamma: float = 0.3e10  #: c [1/m]
    fric_n: float = 1.0  #: n [-]
    stribeck_velocity: float = 1e-3  #: v_s [m/s]
    stribeck_exponent: float = 2.0  #: delta [-]
    mu_k: float = 0.5  #: kinetic friction coefficient [-]
    mu_s: float = 0.6  #: static friction coefficient [-]
    sigma1: float = 100.0  #: presliding damping sigma1 [N s/m]
    sigma2: float = 0.4  #: viscous friction sigma2 [N s/m]
    normal_force: Optional[float] = None  #: F_n [N]; None: (m1+m2+mPE) g

    def __post_init__(self) -> None:
        for f in fields(self):
            v = getattr(self, f.name)
            if v is None and f.name == "normal_force":
                continue
            if isinstance(v, bool) or not isinstance(v, (int, float)):
                try:
                    v = float(v)  # numpy scalars
                except (TypeError, ValueError):
                    raise TypeError(f"parameter '{f.name}' must be a number, got {v!r}") from None
            object.__setattr__(self, f.name, float(v))
        engine.resolve_params(self._given())  # raises ValueError naming the parameter

    def _given(self) -> dict[str, float]:
        d = {f.name: getattr(self, f.name) for f in fields(self)}
        if d["normal_force"] is None:
            del d["normal_force"]
        return d

    @classmethod
    def from_dict(cls, values: Mapping[str, Any]) -> "Params":
        """Build from a mapping; unknown names are refused with a ValueError naming them."""
        known = {f.name for f in fields(cls)}
        unknown = sorted(set(values) - known)
        if unknown:
            raise ValueError(f"unknown parameter(s) {unknown}; known: {sorted(known)}")
        return cls(**dict(values))

    def replace(self, **changes: Any) -> "Params":
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
