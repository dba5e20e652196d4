"""One effect-set device (``bench_effect_sets.py``'s plan) written again, its true model scored
under the diagnosis's own objective, and optionally the diagnosis run with its JSON kept: is a
miss the search's (the truth leaves noise where the fits did not) or the model's or the step's?

    python benches/probe_effect_set_truth.py --seed 1 --id 15 [--dir /tmp/cases] [--diagnose OUT.json]

Prints the truth's chi^2, RMS / noise and lag-1 whiteness z at the fit step, at half of it and
at the writer's step (2e-8 s), with the noise as the diagnosis estimates it and as drawn.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
import sys
import tempfile
import time
import warnings
from pathlib import Path
from typing import Optional

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
sys.path.insert(0, str(HERE.parent / "tests"))
from bench_confusion import _misset, _spec_params, _true_device, _tuned  # noqa: E402
from bench_confusion_beyond import effects_case  # noqa: E402
from bench_effect_sets import SIZE_RANGE, plan  # noqa: E402


def truth_spec(seed: int, i: int):  # type: ignore[no-untyped-def]
    """The true ModelSpec of device `i` of `seed`, drawn exactly as ``effects_case`` draws it."""
    import idm_rs
    from idm_rs.diagnosis.case_model import ModelSpec, Structure

    c = plan(seed)[i]
    rng = np.random.default_rng([seed, 5100 + c["id"]])
    noise = float(rng.uniform(1.0e-9, 2.0e-9))
    rng.integers(0, 2**31)  # the writer's noise seed
    true0 = idm_rs.Params()
    _misset(true0, rng)
    targets = [float(rng.uniform(*SIZE_RANGE)) for _ in c["effects"]]
    p, fields, model = true0, {}, c["device"]
    for e, target in zip(c["effects"], targets):
        m, _ = _tuned(e, c["device"], target, noise)
        pe, eff, model, _ = _true_device(e, m, c["device"])
        if e == "stribeck":
            p = p.replace(mu_s=pe.mu_s)
        if e == "piezo_hysteresis":
            p = p.replace(hyst_alpha=pe.hyst_alpha)
        fields.update({k: v for k, v in dataclasses.asdict(eff).items() if v != getattr(idm_rs.Effects(), k)})
    p = p.replace(normal_force=p.effective_normal_force)
    structure = Structure(model, 4 if model == "dps" else 1, "piezo_hysteresis" in c["effects"])
    return c, noise, ModelSpec(structure, _spec_params(p), dataclasses.asdict(idm_rs.Effects(**fields)))


def main(argv: Optional[list[str]] = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--id", type=int, required=True)
    ap.add_argument("--dir", type=Path, help="where the device is written (default: a temporary directory)")
    ap.add_argument("--diagnose", type=Path, metavar="OUT.json", help="also diagnose it and keep the JSON here")
    args = ap.parse_args(argv)
    from idm_rs.diagnosis.case_model import CaseSimulator
    from idm_rs.diagnosis.fitting import Objective
    from idm_rs.diagnosis.noise import estimate_noise
    from idm_rs.diagnosis.whiteness import whiteness_z
    from idm_rs.io.recording import load_case

    root = args.dir or Path(tempfile.mkdtemp())
    c, drawn, spec = truth_spec(args.seed, args.id)
    directory = root / f"seed{args.seed}_case{args.id:03d}"
    if not (directory / "meta.json").exists():
        effects_case(directory, c["effects"], c["device"], np.random.default_rng([args.seed, 5100 + c["id"]]),
                     SIZE_RANGE)
    rec = load_case(directory)
    sigma = estimate_noise(rec).sigma
    print(f"device {args.id} (seed {args.seed}): {'+'.join(c['effects'])} on the {c['device']}; "
          f"noise drawn {drawn:.3e} m, estimated {sigma:.3e} m")
    for dt in (2e-7, 1e-7, 2e-8):
        obj = Objective(rec, CaseSimulator(rec, dt=dt), sigma)
        res, _ = obj.profiled(obj.predict([spec])[0])
        n = sum(r.size for r in res)
        chi2 = float(sum(np.sum(r * r) for r in res)) / sigma**2
        print(f"  the truth at dt = {dt:g} s: chi^2 {chi2:.0f} over {n} samples, RMS {math.sqrt(chi2 / n):.3f} x "
              f"noise (estimated), {math.sqrt(chi2 / n) * sigma / drawn:.3f} x (drawn), whiteness z "
              f"{whiteness_z(res, obj):.2f}")
    if args.diagnose:
        import idm_rs

        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            t0 = time.perf_counter()
            d = idm_rs.diagnose(directory, progress=False)
        out = d.to_dict()
        out["seconds_wall"] = time.perf_counter() - t0
        args.diagnose.write_text(json.dumps(out, default=str))
        print(f"  diagnosis: {d.verdict} in {out['seconds_wall']:.0f} s ({args.diagnose})")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
