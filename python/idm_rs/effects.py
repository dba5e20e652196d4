"""Optional physics beyond the paper's model (the catalogue of ``recordings/FORMAT.md``).

Each effect parameter is off at 0. They run inside the Rust engine (extra forces or states),
so fits and sweeps with an effect run at engine speed.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields


@dataclass(frozen=True)
class Effects:
    """Effect parameters (SI); all 0 is the paper's model.

    ``theta_rad`` [rad]: tilted guide, force −(m1+m2+mPE)·g·sin θ on the main body and normal
    force × cos θ. ``k_ground`` [N/m]: spring from the main body to ground. ``tau_amp`` [s]:
    amplifier lag of the PE voltage. ``kappa`` [-], ``tau_creep`` [s]: piezo creep, an extra free
    extension relaxing to κ·d33·V. ``c_weight`` [N s/m]: viscous drag on the weight. ``eps`` [-]:
    friction levels × (1 + ε sgn v1). ``tau_sensor`` [s]: the sensor reads x1 through a
    first-order lag. ``drift_rate`` [m/s]: the reading drifts linearly in time.
    """

    theta_rad: float = 0.0
    k_ground: float = 0.0
    tau_amp: float = 0.0
    kappa: float = 0.0
    tau_creep: float = 0.0
    c_weight: float = 0.0
    eps: float = 0.0
    tau_sensor: float = 0.0
    drift_rate: float = 0.0

    def __post_init__(self) -> None:
        for f in fields(self):
            v = float(getattr(self, f.name))
            if not math.isfinite(v):
                raise ValueError(f"effect parameter '{f.name}' must be finite, got {v}")
            object.__setattr__(self, f.name, v)

    def active(self) -> dict[str, float]:
        """The non-zero parameters."""
        return {f.name: getattr(self, f.name) for f in fields(self) if getattr(self, f.name) != 0.0}
