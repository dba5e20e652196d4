"""The diagnosis's own stages up to the screening on a written case (the noise model learned,
the calibrated null fitted, the held-out experiment set aside), then a probe's report in place
of the rest: what the force-inference probes start from."""

from __future__ import annotations

import importlib
from typing import Any, Callable


def at_screening(case: str, name: str, report: Callable[[Any], None]) -> None:
    """Run `case`'s diagnosis to the screening, call `report` on its state (``cal``, ``pb``,
    ``rec``, ``heldout``, ``nominal``) under the stage name `name`, and stop there."""
    diagnose = importlib.import_module("idm_rs.diagnosis.diagnose")

    class Done(Exception):
        pass

    def stage(s: Any) -> None:
        report(s)
        raise Done

    saved = diagnose.PIPELINE
    diagnose.PIPELINE = saved[:3] + ((name, stage),)
    try:
        diagnose.diagnose(case, progress=False)
    except Done:
        pass
    finally:
        diagnose.PIPELINE = saved
