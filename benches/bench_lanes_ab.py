"""The diagnosis of one recorded case and ``characterize()`` with the batch engine's vector lanes
(AVX2) and forced to scalar dispatch, in one process of one build (AVX2 twice: the first run
pays the warm-up): what the lanes bring to them, and that their results do not change.

    python benches/bench_lanes_ab.py path/to/recordings/dev/dev14 [--json PATH]
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import idm_rs
from idm_rs.apps.actuator import characterize
from idm_rs.core import engine


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("case")
    ap.add_argument("--json", metavar="PATH")
    a = ap.parse_args(argv)
    rows = []
    try:
        for level in ("avx2", "scalar", "avx2"):
            engine.set_simd_level(level)
            t0 = time.perf_counter()
            ds = characterize(progress=False)
            tc = time.perf_counter() - t0
            t0 = time.perf_counter()
            d = idm_rs.diagnose(a.case, progress=False)
            td = time.perf_counter() - t0
            rows.append(dict(level=level, characterize_s=tc, velocity_m_per_s=ds.attrs["velocity_at_design_m_per_s"],
                             stall_force_N=ds.attrs["stall_force_N"], diagnose_s=td, verdict=d.verdict,
                             simulated_runs=d.simulations, rms_after_m=d.rms_after))
            print(json.dumps(rows[-1]), flush=True)
    finally:
        engine.set_simd_level("avx2")
    if a.json:
        Path(a.json).write_text(json.dumps(rows, indent=2) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
