"""The catalogue of physics a nominal model may lack (recordings/FORMAT.md), as data: each effect
with a one-line description, the structure change it needs, and its parameters with bounds,
scales and starting values. Adding an effect means adding one entry here (and, if it is new
physics, its term in the Rust engine's effects.rs)."""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Callable, Optional

from .case_model import Structure
from .fitting import FreeParam, Setter, set_effect, set_param


@dataclass(frozen=True)
class EffectParam:
    """A parameter of an effect. `starts`: values tried before the fit (the best is kept)."""

    name: str
    lower: float
    upper: float
    scale: float
    unit: str
    starts: tuple[float, ...] = (0.0,)
    log: bool = False
    setter: Optional[Setter] = None  # default: the Effects field of the same name

    def free(self, start: float) -> FreeParam:
        setter = self.setter or set_effect(self.name)
        x0 = start if not self.log else max(start, self.lower)
        return FreeParam(self.name, x0, self.lower, self.upper, self.scale, setter, self.log, self.unit)


@dataclass(frozen=True)
class Effect:
    """One catalogue entry."""

    id: str
    description: str
    params: tuple[EffectParam, ...]
    #: whether the nominal model can lack it (e.g. `pe_mass` only for an LPS nominal)
    applies: Callable[[Structure, dict], bool]
    #: the structure with the effect in place
    structure: Callable[[Structure], Structure] = lambda s: s


def _stribeck_setter(params: dict, effects: dict, excess: float) -> None:
    # mu_s = mu_k (1 + excess): keeps mu_s >= mu_k whatever mu_k the fit is at
    params["mu_s"] = params["mu_k"] * (1.0 + excess)


CATALOGUE: tuple[Effect, ...] = (
    Effect(
        "pe_mass",
        "the PE has mass: the device is the DPS (4 elements, consistent mass, Rayleigh damping), not the LPS",
        (),
        applies=lambda s, p: s.model == "lps",
        structure=lambda s: replace(s, model="dps", n_elements=4),
    ),
    Effect(
        "piezo_hysteresis",
        "the PE force has Bouc-Wen hysteresis h (amplitude hyst_alpha; hyst_beta, hyst_gamma as nominal)",
        (EffectParam("hyst_alpha", 1e-5, 2.0, 1.0, "1", starts=(1e-4, 1e-3, 1e-2, 0.1), log=True,
                     setter=set_param("hyst_alpha")),),
        applies=lambda s, p: not s.piezo_hysteresis,
        structure=lambda s: replace(s, piezo_hysteresis=True),
    ),
    Effect(
        "stribeck",
        "static friction exceeds kinetic friction (mu_s > mu_k: a Stribeck peak)",
        (EffectParam("mu_s_excess", 0.0, 0.5, 0.01, "1", starts=(0.0, 0.02, 0.1), setter=_stribeck_setter),),
        applies=lambda s, p: p["mu_s"] <= p["mu_k"],
    ),
    Effect(
        "incline",
        "the guide is tilted: gravity along it on the device, normal force times cos(theta)",
        (EffectParam("theta_rad", -0.02, 0.02, 1e-4, "rad"),),
        applies=lambda s, p: True,
    ),
    Effect(
        "spring_to_ground",
        "a spring from the main body to the ground, force -k_ground x1",
        (EffectParam("k_ground", 0.0, 2e5, 1e3, "N/m", starts=(0.0, 2e3, 2e4)),),
        applies=lambda s, p: True,
    ),
    Effect(
        "amplifier_lowpass",
        "the PE voltage lags the command through a first-order amplifier (tau_amp)",
        # log scale from 0.3 us: a lag much shorter than the fit's step would make the state
        # stiff (and is invisible at 10 us sampling anyway)
        (EffectParam("tau_amp", 3e-7, 2e-4, 1.0, "s", starts=(1e-6, 5e-6, 3e-5), log=True),),
        applies=lambda s, p: True,
    ),
    Effect(
        "piezo_creep",
        "the PE creeps: an extra free extension relaxing to kappa d33 V with time constant tau_creep",
        (EffectParam("kappa", 0.0, 0.5, 0.005, "1", starts=(0.01,)),
         EffectParam("tau_creep", 1e-4, 0.2, 1.0, "s", starts=(1e-3, 5e-3, 3e-2), log=True)),
        applies=lambda s, p: True,
    ),
    Effect(
        "weight_friction",
        "viscous drag on the weight, force -c_weight v2",
        (EffectParam("c_weight", 0.0, 100.0, 0.5, "N s/m", starts=(0.0, 1.0, 5.0)),),
        applies=lambda s, p: True,
    ),
    Effect(
        "friction_asymmetry",
        "friction levels depend on the sliding direction: Fc, Fs times (1 + eps sgn v1)",
        (EffectParam("eps", -0.3, 0.3, 1e-3, "1"),),
        applies=lambda s, p: True,
    ),
    Effect(
        "sensor_lowpass",
        "the sensor reads x1 through a first-order low-pass (tau_sensor)",
        (EffectParam("tau_sensor", 3e-7, 2e-4, 1.0, "s", starts=(1e-6, 1e-5, 5e-5), log=True),),
        applies=lambda s, p: True,
    ),
    Effect(
        "thermal_drift",
        "the reading drifts linearly in time (drift_rate)",
        (EffectParam("drift_rate", -1e-4, 1e-4, 1e-7, "m/s"),),
        applies=lambda s, p: True,
    ),
)

#: The nominal parameters calibrated before any physics is blamed: the ones a lab knows least
#: well (friction levels and damping, the piezo constant, the masses).
CALIBRATED: tuple[str, ...] = ("mu_k", "d33", "sigma1", "sigma2", "fric_alpha", "m1", "m2")
#: relative bounds and scale of the calibrated parameters
CALIBRATION_RANGE = (0.6, 1.5)
CALIBRATION_SCALE = 0.05


def by_id(effect_id: str) -> Effect:
    for e in CATALOGUE:
        if e.id == effect_id:
            return e
    raise KeyError(f"no effect {effect_id!r} in the catalogue; known: {[e.id for e in CATALOGUE]}")
