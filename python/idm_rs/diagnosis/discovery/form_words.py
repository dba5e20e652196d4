"""A found form in words: the added term of the equation of motion, and what it means along the
recorded motion (a friction varying with position, a drag at the highest velocity, ...)."""

from __future__ import annotations

import math
from typing import Optional

import numpy as np

from .infer import InferredForce
from .regress import FoundForm


def equation(form: FoundForm, values: dict[str, float]) -> str:
    """The found form as an equation of motion's added term, with its refitted coefficients."""
    lhs = "m1 x1'' +=" if form.body == "main" else "m2 x2'' +="
    parts = []
    for t in form.terms:
        sym = t.symbol.replace("lambda", f"{values.get('lib_wavelength', form.wavelength) * 1e6:.3g} um")
        unit = "" if t.unit == "1" else f" {t.unit}"
        parts.append(f"{values[t.param]:+.4g}{unit} · {sym}")
    return f"{lhs} " + " ".join(parts)


def describe(form: FoundForm, values: dict[str, float], force: InferredForce) -> str:
    """The found term in words, with its size along the recorded motion."""
    wl = values.get("lib_wavelength", form.wavelength)
    where = "on the main body" if form.body == "main" else "on the weight"
    trs = force.trajectories
    ff = np.concatenate([np.abs(t.ff) for t in trs]) if trs else np.zeros(1)
    ff_level = float(np.percentile(ff, 90)) if ff.size else 0.0
    words = []
    names = {t.param for t in form.terms}
    if names & {"lib_ff_sin", "lib_ff_cos"}:
        amp = math.hypot(values.get("lib_ff_sin", 0.0), values.get("lib_ff_cos", 0.0))
        words.append(f"friction varies with position: about ±{100 * amp:.2g} % with a period of {wl * 1e6:.3g} µm")
    if names & {"lib_sin", "lib_cos"}:
        amp = math.hypot(values.get("lib_sin", 0.0), values.get("lib_cos", 0.0))
        words.append(f"a force periodic in position {where}: ±{amp * 1e3:.3g} mN with a period of {wl * 1e6:.3g} µm")
    if "lib_vv" in names:
        v = float(np.percentile(np.concatenate([np.abs(t.v1) for t in trs]), 99)) if trs else 0.0
        words.append(f"quadratic drag {where}: F = {values['lib_vv']:.3g} N s²/m² · v1|v1| "
                     f"({abs(values['lib_vv']) * v * v * 1e3:.3g} mN at {v * 1e3:.3g} mm/s)")
    if "lib_x1cube" in names:
        x = float(np.max(np.concatenate([np.abs(t.x1) for t in trs]))) if trs else 0.0
        kind = "stiffening spring to ground" if values["lib_x1cube"] < 0 else "softening (negative) cubic force"
        words.append(f"a cubic {kind} {where}: F = {values['lib_x1cube']:.3g} N/m³ · x1³ "
                     f"({abs(values['lib_x1cube']) * x**3 * 1e3:.3g} mN at {x * 1e6:.3g} µm)")
    if "lib_x1sq" in names:
        words.append(f"a force quadratic in position {where} ({values['lib_x1sq']:.3g} N/m² · x1²)")
    if "lib_x1" in names:
        words.append(f"a linear spring to ground {where} (k = {-values['lib_x1']:.3g} N/m)")
    if "lib_ff" in names:
        words.append(f"friction {100 * values['lib_ff']:+.2g} % off its calibrated level")
    rest = [t for t in form.terms if t.param not in {"lib_ff_sin", "lib_ff_cos", "lib_sin", "lib_cos", "lib_vv",
                                                      "lib_x1cube", "lib_x1sq", "lib_x1", "lib_ff"}]
    for t in rest:
        words.append(f"a force {values[t.param]:+.3g} {t.unit} · {t.symbol} {where}")
    if ff_level > 0 and not words:
        words.append("no term")
    return "; ".join(words)


def look_alike_note(form: Optional[FoundForm]) -> str:
    """'; on these experiments x1 - x2 cannot be told apart from V (...)' for the form's terms
    that have a look-alike in the library (:attr:`FoundForm.look_alikes`), else ''."""
    if form is None:
        return ""
    kept = {t.symbol for t in form.terms}
    alike = [a for a in form.look_alikes if a[0] in kept]
    if not alike:
        return ""
    return "; on these experiments " + "; ".join(
        f"{a} cannot be told apart from {b} (|cos| = {c:.3f} of their effects on the readings)" for a, b, c in alike)
