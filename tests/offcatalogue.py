"""An independent simulator of the IDM (LPS and DPS, with or without piezo hysteresis), for
recordings with physics the engine lacks.

Nothing here calls the idm_rs engine: the equations below are written out from docs/MODEL.md
(checked term by term against rust/src/physics/friction.rs, physics/mechanics.rs and model/mod.rs ``rhs_impl``) and
integrated with ``scipy.integrate.solve_ivp`` (LSODA, analytic Jacobian). Its purpose is to
write ``idm-recording/1`` cases of devices whose physics is OUTSIDE the engine's effect
catalogue, so that a "discovery" feature can be tested on answers it could not have been
tuned to. ``tests/test_offcatalogue_simulator.py`` checks it against the engine with no extra
mechanism, on every structure.

The LPS without hysteresis (:class:`_Rhs`; state y = [x1, x2, v1, v2, Fh] (+ [xb, vb])):

    kp = Ep Ap / l,  cp = betac kp  (rayleigh_beta; the LPS has no mass-proportional damping)
    Fp = kp d33 V(t)                          pushes the main body (+) and the weight (-)
    m1 x1'' = Fp - kp (x1 - x2) - cp (v1 - v2) - Ff + F_load (+ extra forces)
    m2 x2'' = -Fp + kp (x1 - x2) + cp (v1 - v2)
    Fn = normal_force, or (m1 + m2 + rho_p Ap l) g with g = 9.81 when None / absent
    S(v) = Fn [mu_k + (mu_s - mu_k) exp(-(|v|/vs)^delta)]        (Stribeck curve)
    dg/dt = v - |v| sgn(Fh) |Fh / S(v)|^n                          (v = v1, or v1 - vb)
    dFh/dt = a dg/dt - b |dg/dt| Fh - c dg/dt |Fh|
    Ff = Fh + sigma2 v + sigma1 dg/dt                              (acts against the main body)

Every other structure (:class:`_BarRhs`; state y = [Q (n+1 nodes), Q', Fh, h] (+ [xb, vb])):
the PE as n two-node bar elements, element mass rho_p Ap le / 6 [[2,1],[1,2]] and stiffness
Ep Ap / le [[1,-1],[-1,1]] (le = l / n), m1 added at node 0 (the main body), m2 at node n (the
weight), Rayleigh damping alpha_c Mp + beta_c Kp on the PE's matrices only:

    (Mp + diag(m1, 0, ..., 0, m2)) Q'' + (alpha_c Mp + beta_c Kp) Q' + Kp Q
        = {Fp - Ff + F_load (+ extra forces), 0, ..., 0, -Fp (+ forces on the weight)}
    Fp = kp (d33 V - h),  dh/dt = ap d33 V' - bp |V'| h - cp V' |h|   (Bouc-Wen; h = 0 without)

The LPS with hysteresis is n = 1 with a massless PE (alpha_c Mp = 0).

The sensor reads x1 (relative to ground). g itself feeds nothing back, so it is not a state.

Extra mechanisms (``extra``: one of the dataclasses below, or a list of them), none of them in
the engine's effect catalogue (rust/src/physics/effects.rs):

* :class:`PeriodicFriction` (``"periodic_friction"``): friction varying along the guide,
  m(x1) = 1 + a sin(2 pi x1 / wavelength + phase). ``mode="force"`` (default): the whole
  friction force on the main body is m(x1) Ff. ``mode="normal"``: the normal force varies,
  Fc and Fs (the Stribeck curve, hence the presliding bound) are scaled by m(x1), sigma1 and
  sigma2 are not. Depends on x1. (Mode "force" is what the engine's ``library_force`` term
  ``lib_ff_sin`` = -a writes; the test checks the two agree to < 0.01 nm.)
* :class:`CubicSpring` (``"cubic_spring"``): a hardening spring from the main body to ground,
  force -k3 x1^3 on m1. Depends on x1.
* :class:`QuadraticDrag` (``"quadratic_drag"``): force -c2 v1 |v1| on m1. Depends on v1.
* :class:`CompliantBase` (``"compliant_base"``): the guide is a mass mb on a spring kb and
  damper cb to ground, state xb, vb: the friction law sees v1 - vb, and
  mb xb'' = +Ff - kb xb - cb vb (the friction's reaction); the sensor reads x1. The normal
  force is unchanged. Depends on "base" (a hidden state).
* :class:`QuadraticSpring` (``"quadratic_spring"``): -k2 x1^2 on m1 (library term x1^2).
  :class:`LinearDrag` (``"linear_drag"``): -c1 v1 on m1 (library term v1).
* :class:`VoltageForce` (``"voltage_force"``): c V(t) on m1 (library term V). :class:`FrictionGradient`
  (``"friction_gradient"``): friction times 1 + slope x1. :class:`WeightFriction`
  (``"weight_dry_friction"``): -fw tanh(v2/vs) on m2 (library term sgn v2). :class:`Vibration`
  (``"vibration"``): A sin(2 pi f t + phase) on m1 — no library term represents it.

Numerics: the run is integrated segment by segment between the waveform's breakpoints (the
input's kinks are never stepped over), in each with ``solve_ivp(method="LSODA")`` (switches to
BDF where the state is stiff: while the main body slides, d(dFh/dt)/dFh ~ -1e8 1/s) with the
analytic Jacobian, rtol = 1e-9, atol = (1e-13 m, 1e-13 m, 1e-10 m/s, 1e-10 m/s, 1e-9 N) and
max_step 1e-5 s. Radau and BDF give the same x1 but were 12x and 7x slower (Radau: 15.5 s for
a 42 ms run, 690 k function calls). Self-convergence: x1 moves by < 0.005 nm at rtol 1e-11
with atol / 100, for every mechanism below.

Measured (this machine, one core, Python 3.11.7, scipy 1.17.1, dev10 parameters): a 42 ms
experiment (80 V 100 Hz, 4 cycles) takes 1.3-1.5 s, the 62 ms one (100 V 50 Hz, 3 cycles)
1.7-1.9 s, with or without an extra mechanism; a full 4-experiment case ~6 s, a short one
(2 cycles each) ~3.5 s. Against the engine (RK4, dt = 2e-7 s) without an extra mechanism x1
agrees to 0.025 nm over 42 ms (tests/test_offcatalogue_simulator.py).
"""

from __future__ import annotations

import json
import math
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any, Mapping, Optional, Sequence, Union

import numpy as np
from scipy.integrate import solve_ivp

GRAVITY = 9.81
FORMAT_ID = "idm-recording/1"
HEADER = ("t", "voltage", "x")
META = "meta.json"
OFFSET_RANGE_M = 2e-6

#: dev10's nominal parameters (/work/shared/recordings/dev/dev10/meta.json), copied here so
#: that writing a case reads no shared file; used with model "lps" and no piezo hysteresis
DEV10_PARAMS: dict[str, float] = {
    "m1": 0.4,
    "m2": 0.3,
    "pe_area": 2.5e-05,
    "pe_youngs": 22160000000.0,
    "pe_length": 0.02,
    "pe_density": 8000.0,
    "d33": 1.2437e-07,
    "rayleigh_alpha": 4000.0,
    "rayleigh_beta": 5e-07,
    "hyst_alpha": 0.4297,
    "hyst_beta": 0.03438,
    "hyst_gamma": -0.002865,
    "fric_alpha": 20000000000.0,
    "fric_beta": 2000000000.0,
    "fric_gamma": 3000000000.0,
    "fric_n": 1.0,
    "stribeck_velocity": 0.001,
    "stribeck_exponent": 2.0,
    "mu_k": 0.4888,
    "mu_s": 0.4888,
    "sigma1": 100.0,
    "sigma2": 0.382,
    "normal_force": 6.90624,
    "load_force": 0.0,
}

#: the four experiments of an off-catalogue case (rest 2 ms, edge 0.5 ms)
CASE_EXPERIMENTS: tuple[dict[str, Any], ...] = (
    {"direction": "forward", "amplitude_V": 80, "frequency_Hz": 100, "cycles": 4},
    {"direction": "backward", "amplitude_V": 80, "frequency_Hz": 100, "cycles": 4},
    {"direction": "forward", "amplitude_V": 100, "frequency_Hz": 50, "cycles": 3},
    {"direction": "backward", "amplitude_V": 100, "frequency_Hz": 100, "cycles": 4},
)
REST_S = 0.002
EDGE_S = 0.0005


# --------------------------------------------------------------------------------------------
# the extra mechanisms
# --------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class PeriodicFriction:
    """Friction times m(x1) = 1 + amplitude sin(2 pi x1 / wavelength + phase) [-, m, rad].
    mode "force": Ff on the main body -> m(x1) Ff; mode "normal": Fc, Fs -> m(x1) Fc, m(x1) Fs."""

    amplitude: float = 0.05
    wavelength: float = 12e-6
    phase: float = 0.0
    mode: str = "force"
    name: str = "periodic_friction"

    def __post_init__(self) -> None:
        if self.mode not in ("force", "normal"):
            raise ValueError(f"PeriodicFriction.mode must be 'force' or 'normal', got {self.mode!r}")
        if not (self.wavelength > 0 and abs(self.amplitude) < 1):
            raise ValueError("PeriodicFriction needs wavelength > 0 and |amplitude| < 1")


@dataclass(frozen=True)
class CubicSpring:
    """Force -k3 x1^3 [N] on the main body; k3 [N/m^3]."""

    k3: float
    name: str = "cubic_spring"


@dataclass(frozen=True)
class QuadraticSpring:
    """Force -k2 x1^2 [N] on the main body (a spring to ground that only pushes back, growing
    with the square of the stroke); k2 [N/m^2]."""

    k2: float
    name: str = "quadratic_spring"


@dataclass(frozen=True)
class LinearDrag:
    """Viscous drag -c1 v1 [N] on the main body (air, a lubricant film); c1 [N s/m]."""

    c1: float
    name: str = "linear_drag"


@dataclass(frozen=True)
class QuadraticDrag:
    """Force -c2 v1 |v1| [N] on the main body; c2 [N s^2/m^2]."""

    c2: float
    name: str = "quadratic_drag"


@dataclass(frozen=True)
class CompliantBase:
    """The guide as a mass mb [kg] on a spring kb [N/m] and damper cb [N s/m] to ground."""

    mb: float
    kb: float
    cb: float
    name: str = "compliant_base"

    @property
    def frequency_Hz(self) -> float:
        """Undamped base resonance sqrt(kb/mb) / 2 pi [Hz]."""
        return math.sqrt(self.kb / self.mb) / (2 * math.pi)


@dataclass(frozen=True)
class VoltageForce:
    """Force c V(t) [N] on the main body (an electrostatic or cable force); c [N/V]."""

    c: float
    name: str = "voltage_force"


@dataclass(frozen=True)
class FrictionGradient:
    """The friction force on the main body times 1 + slope x1 (wear along the stroke); slope [1/m]."""

    slope: float
    name: str = "friction_gradient"


@dataclass(frozen=True)
class WeightFriction:
    """Dry friction on the weight, -fw tanh(v2 / vs) [N] (vs the Stribeck velocity); fw [N]."""

    fw: float
    name: str = "weight_friction_dry"


@dataclass(frozen=True)
class Vibration:
    """A floor vibration: force amplitude sin(2 pi frequency t + phase) [N] on the main body
    (no library term can represent it)."""

    amplitude: float
    frequency: float
    phase: float = 0.0
    name: str = "vibration"


Extra = Union[PeriodicFriction, CubicSpring, QuadraticSpring, LinearDrag, QuadraticDrag, CompliantBase, VoltageForce,
              FrictionGradient, WeightFriction, Vibration]
_KINDS = {"periodic_friction": PeriodicFriction, "cubic_spring": CubicSpring, "quadratic_spring": QuadraticSpring,
          "linear_drag": LinearDrag, "quadratic_drag": QuadraticDrag,
          "compliant_base": CompliantBase, "voltage_force": VoltageForce, "friction_gradient": FrictionGradient,
          "weight_friction_dry": WeightFriction, "vibration": Vibration}


def _as_extras(extra: Any) -> list[Extra]:
    """None, one mechanism, a dict {"name": kind, ...fields}, or a list of these."""
    if extra is None:
        return []
    if isinstance(extra, (list, tuple)):
        return [e for x in extra for e in _as_extras(x)]
    if isinstance(extra, Mapping):
        d = dict(extra)
        kind = d.pop("name", None)
        if kind not in _KINDS:
            raise ValueError(f"unknown extra mechanism {kind!r}; known: {sorted(_KINDS)}")
        return [_KINDS[kind](**d)]
    if isinstance(extra, tuple(_KINDS.values())):
        return [extra]
    raise TypeError(f"extra must be a mechanism, a dict or a list of them, got {type(extra).__name__}")


def _describe(extras: Sequence[Extra]) -> list[dict[str, Any]]:
    return [asdict(e) for e in extras]


# --------------------------------------------------------------------------------------------
# the model
# --------------------------------------------------------------------------------------------
def _resolve(params: Mapping[str, Any]) -> dict[str, float]:
    p = dict(params)
    missing = [k for k in DEV10_PARAMS if k not in p and k not in ("normal_force", "load_force")]
    if missing:  # fill Table 1 defaults (values only; no physics comes from the engine)
        from idm_rs.core.params import Params

        defaults = Params().to_dict(resolved=False)
        for k in missing:
            p[k] = defaults[k]
    p.setdefault("load_force", 0.0)
    if p.get("normal_force") is None:
        pe_mass = p["pe_density"] * p["pe_area"] * p["pe_length"]
        p["normal_force"] = (p["m1"] + p["m2"] + pe_mass) * GRAVITY
    return {k: float(v) for k, v in p.items()}


def _sgn(x: float) -> float:
    return 1.0 if x > 0 else (-1.0 if x < 0 else 0.0)


class _Rhs:
    """Right-hand side and Jacobian of one run (the input's segment set by :meth:`segment`)."""

    def __init__(self, p: Mapping[str, float], extras: Sequence[Extra]) -> None:
        self.m1, self.m2 = p["m1"], p["m2"]
        self.kp = p["pe_youngs"] * p["pe_area"] / p["pe_length"]
        self.cp = p["rayleigh_beta"] * self.kp
        self.d33 = p["d33"]
        fn = p["normal_force"]
        self.fc = p["mu_k"] * fn
        self.dfs = (p["mu_s"] - p["mu_k"]) * fn
        self.vs, self.delta, self.n = p["stribeck_velocity"], p["stribeck_exponent"], p["fric_n"]
        self.a, self.b, self.c = p["fric_alpha"], p["fric_beta"], p["fric_gamma"]
        self.s1, self.s2 = p["sigma1"], p["sigma2"]
        self.load = p["load_force"]
        self.periodic: list[PeriodicFriction] = [e for e in extras if isinstance(e, PeriodicFriction)]
        self.k3 = sum(e.k3 for e in extras if isinstance(e, CubicSpring))
        self.c2 = sum(e.c2 for e in extras if isinstance(e, QuadraticDrag))
        self.k2 = sum(e.k2 for e in extras if isinstance(e, QuadraticSpring))
        self.c1 = sum(e.c1 for e in extras if isinstance(e, LinearDrag))
        self.cv = sum(e.c for e in extras if isinstance(e, VoltageForce))
        self.grad = sum(e.slope for e in extras if isinstance(e, FrictionGradient))
        self.fw = sum(e.fw for e in extras if isinstance(e, WeightFriction))
        self.vibrations = [e for e in extras if isinstance(e, Vibration)]
        bases = [e for e in extras if isinstance(e, CompliantBase)]
        if len(bases) > 1:
            raise ValueError("at most one CompliantBase")
        self.base = bases[0] if bases else None
        self.dim = 7 if self.base else 5
        self.v0, self.slope, self.t0 = 0.0, 0.0, 0.0

    def segment(self, t0: float, v0: float, slope: float) -> None:
        self.t0, self.v0, self.slope = t0, v0, slope

    def voltage(self, t: float) -> float:
        return self.v0 + self.slope * (t - self.t0)

    def _modulation(self, x1: float) -> tuple[float, float, float, float]:
        """(force scale, its d/dx1, Stribeck scale, its d/dx1)."""
        fs, dfs, ss, dss = 1.0, 0.0, 1.0, 0.0
        for e in self.periodic:
            k = 2 * math.pi / e.wavelength
            m = 1.0 + e.amplitude * math.sin(k * x1 + e.phase)
            dm = e.amplitude * k * math.cos(k * x1 + e.phase)
            if e.mode == "force":
                fs, dfs = fs * m, dfs * m + fs * dm
            else:
                ss, dss = ss * m, dss * m + ss * dm
        if self.grad:
            fs, dfs = fs * (1.0 + self.grad * x1), dfs * (1.0 + self.grad * x1) + fs * self.grad
        return fs, dfs, ss, dss

    def _stribeck(self, v: float) -> tuple[float, float]:
        """S0(v) and dS0/dv (without the position scale)."""
        if self.dfs == 0.0:
            return self.fc, 0.0
        x = abs(v) / self.vs
        e = math.exp(-(x ** self.delta))
        s = self.fc + self.dfs * e
        if v == 0.0:
            return s, 0.0
        return s, -self.dfs * e * self.delta * x ** (self.delta - 1.0) / self.vs * _sgn(v)

    def _friction(self, x1: float, vr: float, fh: float):
        """Ff on the main body (scaled), dFh/dt, and the partials of both w.r.t. (x1, vr, Fh)."""
        fsc, dfsc, ssc, dssc = self._modulation(x1)
        s0, ds0 = self._stribeck(vr)
        s, ds = ssc * s0, ssc * ds0
        r = fh / s
        av = abs(vr)
        if self.n == 1.0:
            pw, pw1 = abs(r), 1.0
        else:
            pw, pw1 = abs(r) ** self.n, self.n * abs(r) ** (self.n - 1.0)
        gd = vr - av * _sgn(fh) * pw
        dg_dfh = -av * pw1 / s
        dg_dv = 1.0 - pw * _sgn(vr) * _sgn(fh) + av * pw1 * fh * ds / (s * s)
        # S = ssc(x1) S0: d(dg/dt)/dx1 = |v| n |r|^(n-1) r dssc / ssc
        dg_dx = av * pw1 * r * dssc / ssc if dssc != 0.0 else 0.0
        fhd = self.a * gd - self.b * abs(gd) * fh - self.c * gd * abs(fh)
        outer = self.a - self.b * _sgn(gd) * fh - self.c * abs(fh)
        dfhd = (outer * dg_dx, outer * dg_dv, outer * dg_dfh - self.b * abs(gd) - self.c * gd * _sgn(fh))
        ff0 = fh + self.s2 * vr + self.s1 * gd
        dff0 = (self.s1 * dg_dx, self.s2 + self.s1 * dg_dv, 1.0 + self.s1 * dg_dfh)
        ff = fsc * ff0
        dff = (fsc * dff0[0] + dfsc * ff0, fsc * dff0[1], fsc * dff0[2])
        return ff, fhd, dff, dfhd

    def _extra_force(self, x1: float, v1: float, t: float = 0.0) -> tuple[float, float, float]:
        """Extra force on the main body and its d/dx1, d/dv1."""
        f = -self.k3 * x1 ** 3 - self.c2 * v1 * abs(v1) + self.cv * self.voltage(t)
        for e in self.vibrations:
            f += e.amplitude * math.sin(2 * math.pi * e.frequency * t + e.phase)
        if self.k2 or self.c1:  # (a separate sum: the other mechanisms' numbers as they were)
            f += -self.k2 * x1 * x1 - self.c1 * v1
            return f, -3.0 * self.k3 * x1 * x1 - 2.0 * self.k2 * x1, -2.0 * self.c2 * abs(v1) - self.c1
        return f, -3.0 * self.k3 * x1 * x1, -2.0 * self.c2 * abs(v1)

    def _weight_force(self, v2: float) -> tuple[float, float]:
        """Extra force on the weight and its d/dv2."""
        if not self.fw:
            return 0.0, 0.0
        th = math.tanh(v2 / self.vs)
        return -self.fw * th, -self.fw * (1.0 - th * th) / self.vs

    def fun(self, t: float, y: np.ndarray) -> list[float]:
        x1, x2, v1, v2, fh = y[0], y[1], y[2], y[3], y[4]
        vb = y[6] if self.base else 0.0
        ff, fhd, _, _ = self._friction(x1, v1 - vb, fh)
        fe, _, _ = self._extra_force(x1, v1, t)
        fw, _ = self._weight_force(v2)
        inner = self.kp * (x1 - x2) + self.cp * (v1 - v2)
        fp = self.kp * self.d33 * self.voltage(t)
        out = [v1, v2, (fp - inner - ff + self.load + fe) / self.m1, (inner - fp + fw) / self.m2, fhd]
        if self.base:
            b = self.base
            out += [vb, (ff - b.kb * y[5] - b.cb * vb) / b.mb]
        return out

    def jac(self, t: float, y: np.ndarray) -> np.ndarray:
        x1, v1, fh = y[0], y[2], y[4]
        vb = y[6] if self.base else 0.0
        _, _, (ffx, ffv, fff), (fhx, fhv, fhf) = self._friction(x1, v1 - vb, fh)
        _, fex, fev = self._extra_force(x1, v1, t)
        _, fwv = self._weight_force(y[3])
        kp, cp, m1, m2 = self.kp, self.cp, self.m1, self.m2
        J = np.zeros((self.dim, self.dim))
        J[0, 2] = J[1, 3] = 1.0
        J[2, :5] = [(-kp - ffx + fex) / m1, kp / m1, (-cp - ffv + fev) / m1, cp / m1, -fff / m1]
        J[3, :4] = [kp / m2, -kp / m2, cp / m2, (-cp + fwv) / m2]
        J[4, 0], J[4, 2], J[4, 4] = fhx, fhv, fhf
        if self.base:
            b = self.base
            J[2, 6] = ffv / m1
            J[4, 6] = -fhv
            J[5, 6] = 1.0
            J[6, 0], J[6, 2], J[6, 4] = ffx / b.mb, ffv / b.mb, fff / b.mb
            J[6, 5], J[6, 6] = -b.kb / b.mb, (-ffv - b.cb) / b.mb
        return J

    def friction_force(self, y: np.ndarray) -> float:
        vb = y[6] if self.base else 0.0
        return self._friction(y[0], y[2] - vb, y[4])[0]


class _BarRhs(_Rhs):
    """Right-hand side and Jacobian of any structure: the PE as ``n`` two-node bar elements
    (consistent mass, Rayleigh damping alpha Mp + beta Kp on the PE only) between the main body
    (node 0) and the weight (node n), with Bouc-Wen piezo hysteresis h where ``hysteresis``.
    The LPS is n = 1 with a massless PE (then alpha Mp = 0: no mass-proportional damping).
    State y = [Q (n+1 nodes), Q' (n+1), Fh, h (, xb, vb)]; the extra mechanisms as :class:`_Rhs`."""

    def __init__(self, p: Mapping[str, float], extras: Sequence[Extra], n: int, distributed: bool,
                 hysteresis: bool) -> None:
        super().__init__(p, extras)
        if n < 1:
            raise ValueError(f"n_elements must be >= 1, got {n}")
        nodes = n + 1
        le = p["pe_length"] / n
        rho = p["pe_density"] if distributed else 0.0
        me = rho * p["pe_area"] * le / 6.0 * np.array([[2.0, 1.0], [1.0, 2.0]])
        ke = p["pe_youngs"] * p["pe_area"] / le * np.array([[1.0, -1.0], [-1.0, 1.0]])
        mp, kp = np.zeros((nodes, nodes)), np.zeros((nodes, nodes))
        for e in range(n):
            mp[e: e + 2, e: e + 2] += me
            kp[e: e + 2, e: e + 2] += ke
        mass = mp.copy()
        mass[0, 0] += p["m1"]
        mass[-1, -1] += p["m2"]
        self.nodes = nodes
        self.minv = np.linalg.inv(mass)
        self.K = kp
        self.C = p["rayleigh_alpha"] * mp + p["rayleigh_beta"] * kp
        self.hysteresis = hysteresis
        self.ap_d33 = p["hyst_alpha"] * p["d33"]
        self.bp, self.cph = p["hyst_beta"], p["hyst_gamma"]
        self.fh_i, self.h_i = 2 * nodes, 2 * nodes + 1
        self.dim = 2 * nodes + 2 + (2 if self.base else 0)

    def _hysteresis(self, h: float) -> tuple[float, float]:
        """dh/dt and its d/dh (zero without hysteresis)."""
        if not self.hysteresis:
            return 0.0, 0.0
        dv = self.slope
        return (self.ap_d33 * dv - self.bp * abs(dv) * h - self.cph * dv * abs(h),
                -self.bp * abs(dv) - self.cph * dv * _sgn(h))

    def fun(self, t: float, y: np.ndarray) -> np.ndarray:
        N = self.nodes
        q, v = y[:N], y[N: 2 * N]
        fh, h = y[self.fh_i], y[self.h_i]
        vb = y[self.h_i + 2] if self.base else 0.0
        ff, fhd, _, _ = self._friction(q[0], v[0] - vb, fh)
        fe, _, _ = self._extra_force(q[0], v[0], t)
        fw, _ = self._weight_force(v[-1])
        fp = self.kp * (self.d33 * self.voltage(t) - h)
        f = -(self.C @ v) - self.K @ q
        f[0] += fp - ff + self.load + fe
        f[-1] += fw - fp
        out = np.empty(self.dim)
        out[:N] = v
        out[N: 2 * N] = self.minv @ f
        out[self.fh_i] = fhd
        out[self.h_i] = self._hysteresis(h)[0]
        if self.base:
            b = self.base
            out[self.h_i + 1] = vb
            out[self.h_i + 2] = (ff - b.kb * y[self.h_i + 1] - b.cb * vb) / b.mb
        return out

    def jac(self, t: float, y: np.ndarray) -> np.ndarray:
        N = self.nodes
        q, v = y[:N], y[N: 2 * N]
        fh, h = y[self.fh_i], y[self.h_i]
        vb = y[self.h_i + 2] if self.base else 0.0
        _, _, (ffx, ffv, fff), (fhx, fhv, fhf) = self._friction(q[0], v[0] - vb, fh)
        _, fex, fev = self._extra_force(q[0], v[0], t)
        _, fwv = self._weight_force(v[-1])
        m0, mN = self.minv[:, 0], self.minv[:, -1]
        J = np.zeros((self.dim, self.dim))
        J[:N, N: 2 * N] = np.eye(N)
        J[N: 2 * N, :N] = -self.minv @ self.K
        J[N: 2 * N, 0] += m0 * (fex - ffx)
        J[N: 2 * N, N: 2 * N] = -self.minv @ self.C
        J[N: 2 * N, N] += m0 * (fev - ffv)
        J[N: 2 * N, 2 * N - 1] += mN * fwv
        J[N: 2 * N, self.fh_i] = -m0 * fff
        J[N: 2 * N, self.h_i] = self.kp * (mN - m0)
        J[self.fh_i, 0], J[self.fh_i, N], J[self.fh_i, self.fh_i] = fhx, fhv, fhf
        J[self.h_i, self.h_i] = self._hysteresis(h)[1]
        if self.base:
            b, xb_i, vb_i = self.base, self.h_i + 1, self.h_i + 2
            J[N: 2 * N, vb_i] = m0 * ffv
            J[self.fh_i, vb_i] = -fhv
            J[xb_i, vb_i] = 1.0
            J[vb_i, 0], J[vb_i, N], J[vb_i, self.fh_i] = ffx / b.mb, ffv / b.mb, fff / b.mb
            J[vb_i, xb_i], J[vb_i, vb_i] = -b.kb / b.mb, (-ffv - b.cb) / b.mb
        return J

    def friction_force(self, y: np.ndarray) -> float:
        N = self.nodes
        vb = y[self.h_i + 2] if self.base else 0.0
        return self._friction(y[0], y[N] - vb, y[self.fh_i])[0]


def sawtooth_breakpoints(amplitude_V: float, frequency_Hz: float, cycles: int, edge_s: float,
                         direction: str, rest_s: float) -> tuple[np.ndarray, np.ndarray]:
    """Breakpoints (t [s], V [V]) of the sawtooth docs/RECORDINGS.md describes: 0 V for rest_s,
    then ``cycles`` periods; forward rises in edge_s and falls over the rest of the period,
    backward rises over (period - edge_s) and falls in edge_s."""
    if direction not in ("forward", "backward"):
        raise ValueError(f"direction must be 'forward' or 'backward', got {direction!r}")
    period = 1.0 / frequency_Hz
    peak = edge_s if direction == "forward" else period - edge_s
    t, v = [0.0] + ([rest_s] if rest_s > 0 else []), [0.0] + ([0.0] if rest_s > 0 else [])
    for k in range(int(cycles)):
        t += [rest_s + k * period + peak, rest_s + (k + 1) * period]
        v += [float(amplitude_V), 0.0]
    return np.asarray(t), np.asarray(v)


def simulate_lps(params: Mapping[str, Any], wave_t: Sequence[float], wave_v: Sequence[float], t_end: float,
                 sample_times: Sequence[float], extra: Any = None, rtol: float = 1e-9,
                 atol: Optional[Sequence[float]] = None, max_step: float = 1e-5,
                 method: str = "LSODA") -> dict[str, np.ndarray]:
    """Integrate the LPS (plus ``extra``) from rest at t = 0 to ``t_end`` [s].

    ``params``: Table 1 names (as meta.json's "params"; missing ones take Table 1's defaults,
    ``normal_force`` None or absent = (m1 + m2 + mPE) g). ``wave_t``, ``wave_v``: the input's
    breakpoints (piecewise linear; the first value before, the last after). ``sample_times``
    (within [0, t_end], strictly increasing): where the states are returned. ``atol``: per state
    component [x1, x2, v1, v2, Fh (, xb, vb)], default 1e-13 m, 1e-10 m/s, 1e-9 N.
    Returns dict(t, x1, v1, x2, v2, ff [N], fh [N], xb, vb (zeros without a base), nfev, njev).
    """
    rhs = _Rhs(_resolve(params), _as_extras(extra))
    if atol is None:
        atol = [1e-13, 1e-13, 1e-10, 1e-10, 1e-9] + ([1e-13, 1e-10] if rhs.base else [])
    out, ts, nfev, njev = _integrate(rhs, wave_t, wave_v, t_end, sample_times, rtol, atol, max_step, method)
    ff = np.array([rhs.friction_force(row) for row in out])
    res = {"t": ts, "x1": out[:, 0], "x2": out[:, 1], "v1": out[:, 2], "v2": out[:, 3], "fh": out[:, 4], "ff": ff,
           "xb": out[:, 5] if rhs.base else np.zeros(ts.size), "vb": out[:, 6] if rhs.base else np.zeros(ts.size),
           "nfev": np.array(nfev), "njev": np.array(njev)}
    return res


def simulate_device(params: Mapping[str, Any], wave_t: Sequence[float], wave_v: Sequence[float], t_end: float,
                    sample_times: Sequence[float], model: str = "lps", n_elements: int = 4,
                    piezo_hysteresis: bool = False, extra: Any = None, rtol: float = 1e-9,
                    max_step: float = 1e-5, method: str = "LSODA") -> dict[str, np.ndarray]:
    """Integrate any structure (plus ``extra``) from rest at t = 0 to ``t_end`` [s]: ``model``
    "lps" (two masses; ``n_elements`` ignored) or "dps" (``n_elements`` bar elements), with or
    without Bouc-Wen ``piezo_hysteresis``. The LPS without hysteresis is :func:`simulate_lps`
    (the same numbers); the rest runs :class:`_BarRhs`. Arguments and result as
    :func:`simulate_lps` (plus h [m]; x2, v2 are the weight's node)."""
    if model not in ("lps", "dps"):
        raise ValueError(f"model must be 'lps' or 'dps', got {model!r}")
    if model == "lps" and not piezo_hysteresis:
        res = simulate_lps(params, wave_t, wave_v, t_end, sample_times, extra=extra, rtol=rtol, max_step=max_step,
                           method=method)
        res["h"] = np.zeros(res["t"].size)
        return res
    rhs = _BarRhs(_resolve(params), _as_extras(extra), 1 if model == "lps" else int(n_elements), model == "dps",
                  piezo_hysteresis)
    N = rhs.nodes
    atol = [1e-13] * N + [1e-10] * N + [1e-9, 1e-13] + ([1e-13, 1e-10] if rhs.base else [])
    out, ts, nfev, njev = _integrate(rhs, wave_t, wave_v, t_end, sample_times, rtol, atol, max_step, method)
    ff = np.array([rhs.friction_force(row) for row in out])
    zeros = np.zeros(ts.size)
    return {"t": ts, "x1": out[:, 0], "x2": out[:, N - 1], "v1": out[:, N], "v2": out[:, 2 * N - 1],
            "fh": out[:, rhs.fh_i], "h": out[:, rhs.h_i], "ff": ff,
            "xb": out[:, rhs.h_i + 1] if rhs.base else zeros, "vb": out[:, rhs.h_i + 2] if rhs.base else zeros,
            "nfev": np.array(nfev), "njev": np.array(njev)}


def _integrate(rhs: _Rhs, wave_t: Sequence[float], wave_v: Sequence[float], t_end: float,
               sample_times: Sequence[float], rtol: float, atol: Sequence[float], max_step: float,
               method: str) -> tuple[np.ndarray, np.ndarray, int, int]:
    """(states at the samples, the sample times, function and Jacobian evaluations): ``rhs`` from
    rest, segment by segment between the input's breakpoints (its kinks never stepped over)."""
    ts = np.asarray(sample_times, dtype=float)
    if ts.ndim != 1 or (ts.size and (ts[0] < 0 or ts[-1] > t_end * (1 + 1e-12) or np.any(np.diff(ts) <= 0))):
        raise ValueError("sample_times must increase strictly and lie within [0, t_end]")
    bt, bv = np.asarray(wave_t, dtype=float), np.asarray(wave_v, dtype=float)
    atol_a = np.asarray(atol, dtype=float)
    edges = np.unique(np.concatenate([[0.0], bt[(bt > 0) & (bt < t_end)], [t_end]]))
    y = np.zeros(rhs.dim)
    out = np.full((ts.size, rhs.dim), np.nan)
    nfev = njev = 0
    for ta, tb in zip(edges[:-1], edges[1:]):
        mid = 0.5 * (ta + tb)
        i = int(np.searchsorted(bt, mid, side="right")) - 1
        if i < 0:
            v0, slope = bv[0], 0.0
        elif i + 1 >= bt.size:
            v0, slope = bv[-1], 0.0
        else:
            slope = (bv[i + 1] - bv[i]) / (bt[i + 1] - bt[i])
            v0 = bv[i] + slope * (ta - bt[i])
        rhs.segment(ta, v0, slope)
        sel = np.flatnonzero((ts >= ta - 1e-15) & (ts <= tb + 1e-15))
        t_eval = np.clip(ts[sel], ta, tb)
        if not t_eval.size or t_eval[-1] < tb:  # tb last: the state the next segment starts from
            t_eval = np.append(t_eval, tb)
        sol = solve_ivp(rhs.fun, (ta, tb), y, method=method, jac=rhs.jac, rtol=rtol, atol=atol_a,
                        max_step=min(max_step, tb - ta), t_eval=t_eval)
        if not sol.success:
            raise RuntimeError(f"solve_ivp failed on [{ta:g}, {tb:g}] s: {sol.message}")
        nfev += sol.nfev
        njev += sol.njev
        if sel.size:
            out[sel] = sol.y[:, : sel.size].T
        y = sol.y[:, -1].copy()
    return out, ts, nfev, njev


# --------------------------------------------------------------------------------------------
# writing a case
# --------------------------------------------------------------------------------------------
def _fmt_number(v: float) -> Union[int, float]:
    """Integers as JSON integers (80, not 80.0), as idm_rs.io.synthetic writes them."""
    return int(v) if float(v).is_integer() and abs(v) < 2**53 else float(v)


def experiment_file_name(index: int, direction: str, amplitude_V: float, frequency_Hz: float) -> str:
    """``exp{index}_{direction}_{A}V_{f}Hz.csv`` (index from 1), the name load_case recognises."""
    return f"exp{index}_{direction}_{_fmt_number(amplitude_V):g}V_{_fmt_number(frequency_Hz):g}Hz.csv"


def write_case(out_dir: Union[str, Path], nominal: Mapping[str, Any], true_params: Mapping[str, Any],
               experiments: Sequence[Mapping[str, Any]], extra: Any = None, noise_rms: float = 1.5e-9,
               resolution: float = 2.5e-10, sample_rate: float = 1e5, seed: int = 0,
               truth: Optional[Mapping[str, Any]] = None, write_noise_rms: bool = False) -> Path:
    """Simulate the true device (``true_params`` + ``extra``, the structure ``nominal`` declares)
    and write an ``idm-recording/1`` case: meta.json, one CSV per experiment, and truth.json (the
    answer).

    ``nominal``: meta.json's "nominal" ({"model": "lps" or "dps", "n_elements": n (dps),
    "piezo_hysteresis": bool, "params": {...}}).
    ``experiments``: dicts with direction, amplitude_V, frequency_Hz, cycles and optionally
    rest_s (default 0.002), edge_s (0.0005) and file. As idm_rs.io.synthetic.make_case: all
    randomness from ``numpy.random.default_rng(seed)`` (first the per-file offsets, uniform in
    ±2 µm, then each file's white noise of RMS ``noise_rms`` [m]); x rounded to multiples of
    ``resolution`` [m]; CSV "%.10g". ``truth``: extra entries for truth.json.
    """
    nominal = dict(nominal)
    model, hysteresis = nominal.get("model"), bool(nominal.get("piezo_hysteresis", False))
    if model not in ("lps", "dps"):
        raise ValueError(f"nominal['model'] must be 'lps' or 'dps', got {model!r}")
    n_elements = int(nominal.get("n_elements", 4)) if model == "dps" else None
    nominal_params = _resolve(nominal["params"])
    truep = _resolve(true_params)
    extras = _as_extras(extra)
    rng = np.random.default_rng(seed)
    offsets = rng.uniform(-OFFSET_RANGE_M, OFFSET_RANGE_M, size=len(experiments))
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    meta_exps = []
    for i, e in enumerate(experiments):
        rest = float(e.get("rest_s", REST_S))
        edge = float(e.get("edge_s", EDGE_S))
        amp, freq = float(e["amplitude_V"]), float(e["frequency_Hz"])
        cycles, direction = int(e["cycles"]), e["direction"]
        bt, bv = sawtooth_breakpoints(amp, freq, cycles, edge, direction, rest)
        duration = rest + cycles / freq
        n = int(round(duration * sample_rate)) + 1
        t = np.arange(n) / sample_rate
        if abs(t[-1] - duration) > 1e-9 / sample_rate:
            raise ValueError(f"experiments[{i}]: the duration {duration:g} s is not a multiple of the sample step")
        sim = simulate_device(truep, bt, bv, t[-1], t, model=model, n_elements=n_elements or 1,
                              piezo_hysteresis=hysteresis, extra=extras)
        x = sim["x1"] + offsets[i]
        if noise_rms > 0:
            x = x + rng.normal(0.0, noise_rms, size=n)
        if resolution > 0:
            x = np.round(x / resolution) * resolution
        v = np.interp(t, bt, bv)
        name = e.get("file") or experiment_file_name(i + 1, direction, amp, freq)
        np.savetxt(out / name, np.column_stack([t, v, x]), fmt="%.10g", delimiter=",", header=",".join(HEADER),
                   comments="")
        meta_exps.append({"file": name, "waveform": "sawtooth", "amplitude_V": _fmt_number(amp),
                          "frequency_Hz": _fmt_number(freq), "direction": direction, "cycles": cycles,
                          "rest_s": rest, "edge_s": edge})
    nom: dict[str, Any] = {"model": model, **({"n_elements": n_elements} if n_elements else {}),
                           "piezo_hysteresis": hysteresis, "params": nominal_params}
    meta: dict[str, Any] = {"format": FORMAT_ID, "nominal": nom, "experiments": meta_exps,
                            "sensor": {"sample_rate_Hz": float(sample_rate), "resolution_m": float(resolution)}}
    if write_noise_rms:
        meta["sensor"]["noise_rms_m"] = float(noise_rms)
    (out / META).write_text(json.dumps(meta, indent=2) + "\n", encoding="utf-8")
    misset = {k: truep[k] / nominal_params[k] - 1.0 for k in truep
              if k in nominal_params and truep[k] != nominal_params[k] and nominal_params[k] != 0}
    key: dict[str, Any] = {
        "effect": "+".join(x.name for x in extras) if extras else "none",
        "off_catalogue": bool(extras),
        "expected_verdict": "unexplained" if extras else "none",
        "extra": _describe(extras),
        "true_nominal_params": truep,
        "true_structure": {"model": model, "n_elements": n_elements, "piezo_hysteresis": hysteresis},
        "misset_in_meta": misset,
        "noise_rms_m": float(noise_rms),
        "quantisation_m": float(resolution),
        "offsets_m": [float(o) for o in offsets],
        "seed": int(seed),
        "simulator": f"tests/offcatalogue.py: independent {model.upper()}{' + hysteresis' if hysteresis else ''}, "
                     "scipy solve_ivp LSODA, rtol 1e-9",
    }
    key.update(truth or {})
    (out / "truth.json").write_text(json.dumps(key, indent=2) + "\n", encoding="utf-8")
    return out


# --------------------------------------------------------------------------------------------
# the off-catalogue cases
# --------------------------------------------------------------------------------------------
#: name -> (extra, description, the variable the term depends on). Sizes measured on the four
#: CASE_EXPERIMENTS with DEV10_PARAMS (kinetic friction mu_k Fn = 3.376 N, median slip speed
#: 4-12 mm/s, peak 17 mm/s). RMS change of x1 [nm] that the mechanism makes, per experiment
#: (fwd 80 V 100 Hz, bwd 80 V 100 Hz, fwd 100 V 50 Hz, bwd 100 V 100 Hz):
#:
#:   full (4/4/3/4 cycles; travel 14.5, -15.6, 12.7, -20.0 um):
#:     periodic_friction 7.4 19.8 37.4 11.1 | cubic_spring 32.9 13.3 36.1 35.4
#:     quadratic_drag 138 92 196 122        | compliant_base 36.9 69.4 155 50.2
#:   short (2 cycles each; travel 6.8, -7.9, 8.5, -10.1 um):
#:     periodic_friction 8.9 9.9 44.9 12.9  | cubic_spring 3.4 0.5 9.9 0.9 (weak: x1 stays small)
#:     quadratic_drag 78 36 136 37          | compliant_base 40.2 11.3 73.1 11.0
#:
#: i.e. 0.05-1.6 % of the travel: above the 1.5 nm noise, far below what a mis-set parameter
#: of a few % does (m2 +0.1 % alone moves x1 by 28 nm).
OFF_CATALOGUE_CASES: dict[str, tuple[Extra, str, str]] = {
    "periodic_friction": (
        PeriodicFriction(amplitude=0.05, wavelength=12e-6, phase=0.0, mode="force"),
        "friction force times 1 + 0.05 sin(2 pi x1 / 12 um): a guide whose friction varies with position",
        "x1",
    ),
    "cubic_spring": (
        CubicSpring(k3=3e13),
        "hardening spring -k3 x1^3 to ground, k3 = 3e13 N/m^3 (0.10 N = 3 % of mu_k Fn at 15 um)",
        "x1",
    ),
    "quadratic_drag": (
        QuadraticDrag(c2=1e3),
        "quadratic drag -c2 v1|v1| on the main body, c2 = 1e3 N s^2/m^2 (0.1 N = 3 % of mu_k Fn at 10 mm/s)",
        "v1",
    ),
    "compliant_base": (
        CompliantBase(mb=2.0, kb=5e9, cb=1e4),
        "the guide is a 2 kg mass on a 5e9 N/m spring and 1e4 N s/m damper to ground "
        "(7.96 kHz, damping ratio 0.05); friction acts on v1 - vb, its reaction on the base",
        "base",
    ),
}

#: devices like those on which discovery failed before issue 31 (the sizes of that report):
#: friction periodic within one slip, a voltage-proportional force, friction growing along the
#: stroke, dry friction on the weight, and a floor vibration no library term represents
ISSUE31_CASES: dict[str, tuple[Extra, str, str]] = {
    "periodic_friction_3um": (
        PeriodicFriction(amplitude=0.046, wavelength=3e-6, phase=0.4, mode="force"),
        "friction force times 1 + 0.046 sin(2 pi x1 / 3 um + 0.4): varies within one slip",
        "x1",
    ),
    "periodic_friction_5um": (
        PeriodicFriction(amplitude=0.011, wavelength=5e-6, phase=1.0, mode="force"),
        "friction force times 1 + 0.011 sin(2 pi x1 / 5 um + 1.0): small and within one slip",
        "x1",
    ),
    "periodic_friction_60um": (
        PeriodicFriction(amplitude=0.03, wavelength=60e-6, phase=0.0, mode="force"),
        "friction force times 1 + 0.03 sin(2 pi x1 / 60 um)",
        "x1",
    ),
    "voltage_force": (
        VoltageForce(c=1.25e-3),
        "a force 1.25e-3 N/V x V on the main body (0.1 N = 3 % of mu_k Fn at 80 V)",
        "V",
    ),
    "friction_gradient": (
        FrictionGradient(slope=2500.0),
        "friction force times 1 + 2500 /m x1 (+5 % over 20 um of stroke)",
        "x1",
    ),
    "weight_dry_friction": (
        WeightFriction(fw=0.05),
        "dry friction 0.05 N tanh(v2 / vs) on the weight",
        "v2",
    ),
    "vibration": (
        Vibration(amplitude=0.05, frequency=137.0, phase=0.3),
        "a floor vibration: 0.05 N sin(2 pi 137 Hz t + 0.3) on the main body (no library term)",
        "t",
    ),
}


def case_experiments(short: bool = False) -> list[dict[str, Any]]:
    """The four experiments (2 cycles each with ``short``), rest 2 ms, edge 0.5 ms."""
    return [dict(e, cycles=2 if short else e["cycles"], rest_s=REST_S, edge_s=EDGE_S) for e in CASE_EXPERIMENTS]


def make_offcatalogue_case(name: str, out_dir: Union[str, Path], seed: int = 0, short: bool = False) -> Path:
    """Write the case ``name`` (a key of :data:`OFF_CATALOGUE_CASES` or :data:`ISSUE31_CASES`, or "none" for no extra
    mechanism) to ``out_dir``: nominal = dev10's parameters with model "lps", true = nominal."""
    if name == "none":
        extra, description, depends = None, "no extra mechanism", ""
    elif name in OFF_CATALOGUE_CASES or name in ISSUE31_CASES:
        extra, description, depends = {**OFF_CATALOGUE_CASES, **ISSUE31_CASES}[name]
    else:
        raise ValueError(f"unknown off-catalogue case {name!r}; known: "
                         f"{sorted(OFF_CATALOGUE_CASES) + sorted(ISSUE31_CASES)} or 'none'")
    nominal = {"model": "lps", "piezo_hysteresis": False, "params": dict(DEV10_PARAMS)}
    return write_case(out_dir, nominal, dict(DEV10_PARAMS), case_experiments(short), extra=extra, seed=seed,
                      truth={"case": name, "description": description, "depends_on": depends})
