"""Beyond the catalogue: find a force the model lacks in the data, name its form, model it.

When no catalogue effect explains a systematic residual, three steps (docs/DIAGNOSIS.md,
"Discovery"):

1. **The missing force, inferred** (:func:`infer_force`). With the calibrated model, an additive
   force on the main body (and, as the second hypothesis, on the weight) as a piecewise-linear
   function of time (knots every 1/``KNOTS_PER_CYCLE`` of a drive cycle), fitted through the
   simulator: Gauss-Newton on the engine's exact derivatives of the readings with respect to
   the force at every knot (``ExternalForce``, sensitivities ``f_ext[k]``), with a penalty on
   the force's second differences whose weight generalised cross-validation chooses at every
   iteration.
2. **Its form, found** (:func:`find_terms`). Sparse regression (scikit-learn's orthogonal
   matching pursuit) of the inferred force on a library of candidate functions of the
   simulated states and the input, in the metric of the data: the inferred force's effect on
   the readings against each library term's, both exact derivatives of the readings at the
   inferred force's run (the term's coefficient seeded in the engine's ``library_force``), so
   a term is judged by the readings it would explain, at the engine's full resolution (the
   friction force jumps within a slip, faster than the knots), not by the force where the
   readings cannot see it (a stuck body hides the force on it). The number of terms and the
   wavelength of the periodic terms are chosen by cross-validation across experiments (leave
   one experiment out).
3. **The term, modelled** (:func:`discover`). The found terms become the engine's
   ``library_force`` (or ``library_force_weight``) effect with their coefficients free; the
   whole model (calibrated subset too) is refitted on exact Jacobians; the verdict is
   ``discovered`` only when the refit improves BIC over the calibrated null by the catalogue's
   threshold and the held-out experiment's prediction improves.

The stages, one module each: :mod:`.infer` (step 1), :mod:`.library` and :mod:`.regress`
(step 2), :mod:`.refit` (step 3) with what it found in :mod:`.found`; :mod:`.linalg` names
numerical failures."""

from .found import Discovery
from .infer import InferredForce, direct_force, infer_force
from .library import MAIN_TERMS, WEIGHT_TERMS, Term, Trajectory, library_columns
from .linalg import NumericalFailure
from .refit import discover
from .regress import FoundForm, find_terms

__all__ = ["MAIN_TERMS", "WEIGHT_TERMS", "Discovery", "FoundForm", "InferredForce", "NumericalFailure", "Term",
           "Trajectory", "direct_force", "discover", "find_terms", "infer_force", "library_columns"]
