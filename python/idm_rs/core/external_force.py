"""A sampled external force on one body of the device: a second input beside the voltage."""

from __future__ import annotations

from typing import Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

Body = Literal["main", "weight"]


class ExternalForce:
    """A force [N] on ``body`` (``"main"``: the main body on the guide; ``"weight"``: the
    weight, the last node) through samples ``(t [s], force [N])``, linear between samples and
    held at the first and last sample outside them.

    Pass it to :func:`idm_rs.simulate` as ``external_force=``. The run lands on every sample
    time as on a voltage breakpoint (with RK4 the sample times must be multiples of ``dt``).
    Its samples can be differentiated like parameters: ``sensitivities=force.knot_names()``
    gives d reading / d force at each sample (``"f_ext[k]"``), which is how
    :func:`idm_rs.diagnosis.discovery.infer_force` estimates an unknown force from a recording.
    """

    t: NDArray[np.float64]  #: sample times [s]
    force: NDArray[np.float64]  #: the force at them [N]
    body: Body  #: "main" or "weight"

    def __init__(self, t: ArrayLike, force: ArrayLike, body: Body = "main") -> None:
        tt = np.ascontiguousarray(t, dtype=float).ravel()
        ff = np.ascontiguousarray(force, dtype=float).ravel()
        if tt.shape != ff.shape:
            raise ValueError(f"external force: {tt.size} times but {ff.size} forces")
        if tt.size < 2:
            raise ValueError(f"external force: give at least two samples, got {tt.size}")
        if body not in ("main", "weight"):
            raise ValueError(f"external force body {body!r}: use 'main' (the main body) or 'weight'")
        tt.flags.writeable = False
        ff.flags.writeable = False
        self.t, self.force, self.body = tt, ff, body

    def __repr__(self) -> str:
        return (f"ExternalForce({self.t.size} samples over [{self.t[0]:g}, {self.t[-1]:g}] s on the {self.body}, "
                f"|F| <= {np.max(np.abs(self.force)):.3g} N)")

    def knot_names(self) -> list[str]:
        """The sensitivity names of the samples, ``f_ext[0]``, ``f_ext[1]``, ..."""
        return [f"f_ext[{k}]" for k in range(self.t.size)]

    def engine_arg(self) -> tuple[NDArray[np.float64], NDArray[np.float64], str]:
        """What the engine takes: (times, forces, body)."""
        return self.t, self.force, self.body
