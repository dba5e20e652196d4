"""The linear algebra of discovery, which names its failures: a non-finite or rank-deficient
system raises :class:`NumericalFailure` with the stage, never a verdict."""

from __future__ import annotations

from typing import Optional

import numpy as np
from numpy.typing import NDArray

from ..thresholds import (
    RANK_TOLERANCE,
)


class NumericalFailure(RuntimeError):
    """A linear system of discovery that is not finite or cannot be solved. It is named in the
    report as what stopped a step of discovery, never turned into a verdict on the physics."""


def require_finite(stage: str, **arrays: NDArray[np.float64]) -> None:
    for name, a in arrays.items():
        a = np.asarray(a)
        bad = int(a.size - np.count_nonzero(np.isfinite(a)))
        if bad:
            raise NumericalFailure(f"{stage}: {bad} of {a.size} entries of {name} {a.shape} are not finite")


def lstsq(A: NDArray[np.float64], b: NDArray[np.float64], stage: str, cond: Optional[float] = RANK_TOLERANCE
           ) -> tuple[NDArray[np.float64], int]:
    """Least squares by QR with column pivoting (LAPACK gelsy: no SVD iteration that can fail to
    converge), inputs checked finite; returns (solution, numerical rank at `cond`)."""
    import scipy.linalg

    require_finite(stage, A=A, b=b)
    try:
        x, _, rank, _ = scipy.linalg.lstsq(A, b, cond=cond, lapack_driver="gelsy")
    except (np.linalg.LinAlgError, ValueError) as e:
        raise NumericalFailure(f"{stage}: {e}") from e
    return x, int(rank)
