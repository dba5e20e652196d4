"""The misfit of a recorded case against one parameter, single shooting (one offset per
experiment) against multiple shooting by translation (one offset per drive-cycle segment), the
other nominal values at their truth from KEY.json. Writes docs/img/misfit_landscape.png.

    python benches/plot_misfit_landscape.py ../shared/recordings dev2/d2_07:m2 dev2/d2_14:mu_k
"""

from __future__ import annotations

import json
import sys
import warnings
from pathlib import Path

import numpy as np


def landscape(root: Path, case: str, name: str, span: float = 0.2, points: int = 61):
    from idm_rs.core.batch import Structure
    from idm_rs.diagnosis.case_model import CaseSimulator, ModelSpec
    from idm_rs.diagnosis.fitting import Objective
    from idm_rs.diagnosis.noise import estimate_noise
    from idm_rs.io.recording import load_case

    s, c = case.split("/")
    key = json.loads((root / s / "KEY.json").read_text())[c]
    rec = load_case(root / case)
    sim, sigma = CaseSimulator(rec), estimate_noise(rec).sigma
    nom = rec.nominal
    p = nom.params.to_dict(resolved=False)
    p.update({k: key["true_nominal_params"][k] for k in key.get("misset_in_meta", {})})
    p["normal_force"] = None
    truth = key["true_nominal_params"][name]
    grid = np.linspace(1 - span, 1 + span, points)
    specs = [ModelSpec(Structure(nom.model, nom.n_elements, nom.piezo_hysteresis), {**p, name: g * truth}, {})
             for g in grid]
    ms, ss = Objective(rec, sim, sigma), Objective(rec, sim, sigma, segmented=False)
    preds = ms.predict(specs)
    single = np.array([float(np.sum(ss.vector(x) ** 2)) / ss.n for x in preds])
    multi = np.array([float(np.sum(ms.vector(x) ** 2)) / ms.n for x in preds])
    return grid, single, multi


def main() -> int:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    warnings.simplefilter("ignore")
    root = Path(sys.argv[1])
    cases = [a.split(":") for a in sys.argv[2:]]
    fig, axes = plt.subplots(1, len(cases), figsize=(5.5 * len(cases), 4), squeeze=False)
    for ax, (case, name) in zip(axes[0], cases):
        g, single, multi = landscape(root, case, name)
        ax.semilogy(g, single, label="single shooting (offset per experiment)")
        ax.semilogy(g, multi, label="multiple shooting by translation (offset per cycle)")
        ax.set_xlabel(f"{name} / true value")
        ax.set_ylabel("mean squared residual / noise variance")
        ax.set_title(f"{case}: misfit against {name}")
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=8)
    fig.tight_layout()
    out = Path(__file__).resolve().parents[1] / "docs" / "img" / "misfit_landscape.png"
    fig.savefig(out, dpi=120)
    print(f"wrote {out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
