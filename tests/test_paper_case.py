"""The paper case (MODEL.md, "The paper case"): Triangle 0 -> 80 V in 0.5 ms, back to 0 V at
10 ms, from rest, Table 1 parameters, fixed-step RK4 with dt = 1e-8 s; x1(10 ms).

MODEL.md's reference values under its conventions are LPS 1.678 µm and DPS(n = 4) 1.711 µm.
The paper itself reports 2.413 µm and 2.459 µm: the text does not reproduce the paper's absolute
values; only the DPS - LPS gap has the paper's sign and size (+33 nm here, +46 nm in the paper).
"""

from __future__ import annotations

import numpy as np

import idm_rs

NM = 1e-9


def test_paper_case_lps_final_position(paper_x1):
    """LPS x1(10 ms) = 1.678 µm within 1 nm (measured 1.678062 µm)."""
    x = paper_x1("lps")
    assert abs(x - 1.678e-6) < 1 * NM, f"LPS x1(10 ms) = {x * 1e6:.6f} µm"


def test_paper_case_dps4_final_position(paper_x1):
    """DPS (n = 4) x1(10 ms) = 1.711 µm within 1 nm (measured 1.710581 µm)."""
    x = paper_x1("dps", 4)
    assert abs(x - 1.711e-6) < 1 * NM, f"DPS4 x1(10 ms) = {x * 1e6:.6f} µm"


def test_dps_minus_lps_gap_has_papers_sign(paper_x1):
    """DPS4 - LPS = +33 nm +- 2 nm (the paper: +46 nm, same sign). Measured +32.52 nm."""
    gap = paper_x1("dps", 4) - paper_x1("lps")
    assert abs(gap - 33 * NM) < 2 * NM, f"DPS4 - LPS = {gap / NM:+.3f} nm"


def test_mass_proportional_damping_carries_the_gap(paper_x1):
    """MODEL.md: almost all of the DPS - LPS gap comes from the mass-proportional damping αc Mp.
    With rayleigh_alpha = 0 the DPS4 - LPS gap drops from +32.5 nm to +1.24 nm (measured), i.e.
    96 % of the gap is αc Mp; the PE's inertia accounts for ~1 nm."""
    lps = paper_x1("lps")
    full_gap = paper_x1("dps", 4) - lps
    no_alpha_gap = paper_x1("dps", 4, rayleigh_alpha=0.0) - lps
    assert abs(no_alpha_gap) < 2 * NM, f"gap without αc = {no_alpha_gap / NM:+.3f} nm"
    assert abs(no_alpha_gap) < 0.1 * abs(full_gap)
    # the LPS has no PE mass, so αc does not enter it at all
    assert paper_x1("lps", rayleigh_alpha=0.0) == lps


def test_paper_case_moves_forward_and_holds(paper_x1):
    """Fast extension, slow contraction steps the main body forward; from 4 to 10 ms the body is
    held in presliding (MODEL.md, Figs. 6c-d) while the PE contracts: |v1| stays far below the
    Stribeck velocity (measured max 1.4e-5 m/s vs vs = 1e-3 m/s), x1 moves by ~1.6 nm
    (< 1 % of the 1.678 µm step), and Fh stays inside the presliding bound (max 3.56 N, which
    is above Fc = 3.45 N but below min(Fs, a/(b+c)) = 4 N, as presliding allows)."""
    p = idm_rs.Params()
    r = idm_rs.simulate(p, idm_rs.Triangle(80.0, 0.5e-3, 9.5e-3), 10e-3, 1e-8, model="lps", save_every=100)
    assert r.final_position == paper_x1("lps")
    assert r.final_position > 0
    late = r.t >= 4e-3
    assert np.abs(r.main_body_velocity[late]).max() < 0.05 * p.stribeck_velocity
    assert np.ptp(r.main_body[late]) < 0.01 * r.final_position
    assert np.abs(r.fh[late]).max() < 4.0
