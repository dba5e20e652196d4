"""The noise read off a residual's second differences, two ways, on recorded cases: the
diagnosis's estimate (second differences beyond RESIDUAL_CLIP robust scales left out) and the
largest 0.1 % trimmed (the rule it replaced), both against the rest segments' estimate. The
residual is the nominal model's (every case's worst: a calibration only shrinks it), so a case
whose two figures agree here agrees after the calibration too.

    python benches/probe_residual_noise.py ../shared/recordings/dev/dev0{1,2,3} DIR/case000 ...

Cases of the benches are written with their ``--write-only DIR`` (``bench_discovery_structures.py``).
"""

from __future__ import annotations

import argparse
import math
from typing import Optional, Sequence

import numpy as np
from numpy.typing import NDArray


def trimmed_sigma(residuals: Sequence[NDArray[np.float64]]) -> float:
    """The noise from second differences with the largest 0.1 % left out [m] (the earlier rule)."""
    d = np.concatenate([np.diff(r, 2) for r in residuals if r.size > 2])
    d = d[np.isfinite(d)]
    kept = d[np.abs(d) <= np.quantile(np.abs(d), 0.999)]
    return math.sqrt(float(np.mean(kept * kept)) / 0.98829 / 6.0)


def main(argv: Optional[list[str]] = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("cases", nargs="+")
    args = ap.parse_args(argv)
    from idm_rs.core.batch import Structure
    from idm_rs.diagnosis.case_model import CaseSimulator, ModelSpec
    from idm_rs.diagnosis.fitting import Objective
    from idm_rs.diagnosis.noise import estimate_noise, residual_sigma
    from idm_rs.io.recording import load_case

    print(f"{'case':28s} {'model':5s} {'rest [nm]':>9s} {'nominal RMS':>11s} {'trimmed':>8s} {'clipped':>8s}"
          "   (x the rest's estimate)")
    for path in args.cases:
        rec = load_case(path)
        noise = estimate_noise(rec)
        obj = Objective(rec, CaseSimulator(rec), noise.sigma)
        nom = rec.nominal
        spec = ModelSpec(Structure(nom.model, nom.n_elements, nom.piezo_hysteresis),
                         nom.params.to_dict(resolved=False), {})
        res, _ = obj.profiled(obj.predict([spec])[0])
        rms = math.sqrt(sum(float(np.sum(r * r)) for r in res) / sum(r.size for r in res))
        rest = noise.rest_sigma
        print(f"{path[-28:]:28s} {nom.model:5s} {rest * 1e9:9.3f} {rms / rest:11.1f} "
              f"{trimmed_sigma(res) / rest:8.3f} {residual_sigma(res)[0] / rest:8.3f}", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
