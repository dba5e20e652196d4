"""What discovery found (:class:`Discovery`): the verdict's test, the form, its figures and
every form tried on the way, as the diagnosis's JSON carries them."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Optional

from ..fitting import FitResult, FreeParam
from .infer import InferredForce
from .regress import FoundForm


@dataclass
class Discovery:
    """What discovery found, with the evidence; `discovered` is the verdict's test."""

    discovered: bool
    reason: str
    body: str
    form: Optional[FoundForm]
    forces: dict[str, InferredForce]  #: per body tried
    refit: Optional[FitResult] = None
    #: the refitted library coefficients and their 1-sigma, engine parameter -> (value, std)
    values: dict[str, tuple[float, Optional[float]]] = field(default_factory=dict)
    delta_bic: float = math.nan
    rms_before: float = math.nan  #: the calibrated null's residual RMS [m]
    rms_after: float = math.nan
    #: the refit's residual whiteness (lag-1 z; noise gives |z| < 3)
    whiteness_z: float = math.nan
    heldout_rms_before: float = math.nan
    heldout_rms_after: float = math.nan
    heldout_experiment: str = ""
    description: str = ""  #: the term in words
    equation: str = ""  #: the term in symbols
    seconds: float = 0.0
    #: numerical failures that stopped a step (named, never a verdict)
    failures: list[str] = field(default_factory=list)
    #: the refitted forms that did not stand (each with its evidence), in the order tried
    tried: list["Discovery"] = field(default_factory=list)
    #: the refit's free parameters (the calibrated subset and the library's), centred on its optimum
    free: list[FreeParam] = field(default_factory=list, repr=False)
    #: what refitting each look-alike in the found term's place showed (:func:`_separated`)
    separation: str = ""
    #: a look-alike refitted in the found term's place that fits as well (within BIC_THRESHOLD):
    #: the two the next experiment must tell apart
    look_alike: Optional["Discovery"] = field(default=None, repr=False)
    #: the global search the refit came from (:func:`_searched`'s summary), or ""
    searched: str = ""
    #: each refit of the form in the order run: where it started ("calibrated", "nominal", "the
    #: force's fit", "global search"), the RMS it left in noise units, its evaluations and seconds
    starts: list[dict[str, Any]] = field(default_factory=list)

    def to_dict(self) -> dict[str, Any]:
        return {
            "discovered": self.discovered, "reason": self.reason, "body": self.body,
            "terms": [t.symbol for t in self.form.terms] if self.form else [],
            "variables": self.form.variables if self.form else [],
            "wavelength_m": self.form.wavelength if self.form else 0.0,
            "cv_error": self.form.cv_error if self.form else math.nan,
            "form_source": self.form.source if self.form else "",
            "values": {k: list(v) for k, v in self.values.items()},
            "delta_bic": self.delta_bic, "rms_before": self.rms_before, "rms_after": self.rms_after,
            "whiteness_z": self.whiteness_z,
            "heldout_rms_before": self.heldout_rms_before, "heldout_rms_after": self.heldout_rms_after,
            "heldout_experiment": self.heldout_experiment, "description": self.description,
            "equation": self.equation, "seconds": self.seconds, "failures": self.failures,
            "notes": self.form.notes if self.form else [],
            "look_alikes": [list(a) for a in self.form.look_alikes] if self.form else [],
            "separation": self.separation, "searched": self.searched, "starts": self.starts,
            "tried": [t.summary() for t in self.tried],
            "inferred_force": {b: {"chi2_before": f.chi2_before, "chi2_after": f.chi2_after, "dof": f.dof,
                                   "smoothing": f.smoothing} for b, f in self.forces.items()},
        }

    def summary(self) -> dict[str, Any]:
        """The form tried, in short: body, terms, whether it stood, its figures and refits."""
        return {"body": self.body, "terms": [t.symbol for t in self.form.terms] if self.form else [],
                "discovered": self.discovered, "delta_bic": self.delta_bic, "rms_after": self.rms_after,
                "heldout_rms_after": self.heldout_rms_after, "whiteness_z": self.whiteness_z,
                "searched": bool(self.searched), "starts": self.starts}
