"""Numerical convergence: RK4 order in dt, and the DPS in its element count (MODEL.md).

Findings these tests encode (measured on the paper case, see the report in the docstrings):

* RK4 shows its 4th order cleanly only while the right-hand side is smooth along the
  trajectory. The Leuven/Bouc-Wen friction law has kinks, |v| in dg/dt and |dg/dt| in dFh/dt;
  the first stick-to-slip transition (Fh overshoots the falling Stribeck curve, dg/dt changes
  sign, ~45 µs into the paper case) already costs the clean order, and every later velocity
  reversal does again. Over 1 ms the observed order in x1 is ~1.7 (4e-8 -> 2e-8 s), not 4.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

import idm_rs

PAPER = idm_rs.Params()
#: the paper case's input, with a fast fall so a 1 ms window holds a forward and a backward slip
SHORT_WAVE = idm_rs.Triangle(amplitude=80.0, rise=0.5e-3, fall=0.5e-3)


def final_state(t_end: float, dt: float, model: str = "lps", n_elements: int = 4) -> np.ndarray:
    return idm_rs.simulate(PAPER, SHORT_WAVE, t_end, dt, model=model, n_elements=n_elements,
                           save_every=10**9).final_state


def observed_order(t_end: float, model: str, component: int, dts=(4e-8, 2e-8),
                   ref_dt=1.25e-9) -> tuple[float, float, float]:
    """(order, error at dts[0], error at dts[1]) of state component ``component`` at t_end."""
    ref = final_state(t_end, ref_dt, model)
    e1, e2 = (abs(final_state(t_end, dt, model)[component] - ref[component]) for dt in dts)
    return math.log(e1 / e2) / math.log(dts[0] / dts[1]), e1, e2


# state layout: [q (dof), v (dof), g, Fh, h]; x1 is component 0, Fh is component -2
X1, FH = 0, -2


@pytest.mark.parametrize("model", ["lps", "dps"])
@pytest.mark.parametrize("component,name", [(X1, "x1"), (FH, "Fh")])
@pytest.mark.parametrize("t_end,dts", [(20e-6, (4e-8, 2e-8)), (40e-6, (8e-8, 4e-8))], ids=["20us", "40us"])
def test_rk4_converges_at_fourth_order(model, component, name, t_end, dts):
    """Paper case (80 V, 0.5 ms rise) over its first 20 or 40 µs: the main body is pushed from
    rest through presliding (Fh up to 3.1 and 3.9 N) with v1 > 0 and Fh > 0, where the
    right-hand side is smooth. Errors against a 1.25e-9 s reference: order 4.
    Measured orders 3.86-4.03; errors (x1 ~ 1e-22-4e-21 m, Fh ~ 1e-12-2e-11 N) are >= 90x the
    round-off noise, estimated as the difference between the 1.25e-9 and 2.5e-9 s references.
    (The clean order ends at the first stick-to-slip transition, ~45 µs: see module docstring.)"""
    order, e1, e2 = observed_order(t_end, model, component, dts=dts)
    ref_fine, ref_coarse = final_state(t_end, 1.25e-9, model), final_state(t_end, 2.5e-9, model)
    noise = abs(ref_fine[component] - ref_coarse[component])
    assert e2 > 50 * noise, f"{name}: error {e2:.3e} too close to round-off ({noise:.3e}) for an order estimate"
    assert 3.5 < order < 4.5, f"{model} {name}: observed order {order:.2f} (errors {e1:.3e}, {e2:.3e})"


def test_rk4_error_is_tiny_over_stick_slip_cycles():
    """Over a whole 1 ms stick-slip cycle (forward slip, reversal, backward slip) the error of
    x1 still falls as dt falls and is far below a nanometre: 3.4e-14 m at 4e-8 s, 4.7e-15 m at
    1e-8 s (x1 = -0.81 µm), with an observed order >= 1."""
    ref = final_state(1e-3, 1.25e-9)[X1]
    errs = [abs(final_state(1e-3, dt)[X1] - ref) for dt in (4e-8, 2e-8, 1e-8)]
    assert errs[0] > errs[1] > errs[2], errs
    assert errs[0] < 1e-13 and errs[2] < 1e-14, errs
    assert math.log2(errs[0] / errs[2]) / 2 > 1.0, errs


@pytest.mark.xfail(
    strict=True,
    raises=AssertionError,  # the order assertion, not any error
    reason=(
        "MODEL.md says 'RK4 converges at order 4 in dt'; over 1 ms of the paper-like case "
        "(rise 0.5 ms, fall 0.5 ms) the observed order of x1 between dt = 4e-8 and 2e-8 s is "
        "~1.7 (errors 3.37e-14, 1.06e-14 m vs a 2.5e-9 s reference; 1.17 between 2e-8 and 1e-8 s), "
        "because the friction law "
        "is not smooth (|v|, |dg/dt|) at stick-slip transitions. A property of the model with a "
        "fixed-step method, not a code bug."
    ),
)
def test_rk4_fourth_order_over_a_full_stick_slip_cycle():
    order, e1, e2 = observed_order(1e-3, "lps", X1, ref_dt=2.5e-9)
    assert 3.5 < order < 4.5, f"observed order {order:.2f} (errors {e1:.3e}, {e2:.3e})"


def test_dps_converges_in_element_count(paper_x1):
    """x1(10 ms) of the paper case for n = 1..5 elements (dt = 1e-8 s): the changes shrink with n
    and |x1(4) - x1(5)| < 1e-10 m (paper); MODEL.md's stronger claim, < 1e-12 m beyond n = 3,
    also holds. Measured changes: 5.42e-12, 4.94e-12, 6.73e-13, 3.00e-13 m."""
    xs = np.array([paper_x1("dps", n) for n in range(1, 6)])
    steps = np.abs(np.diff(xs))
    assert np.all(np.diff(steps) < 0), f"changes do not shrink: {steps}"
    assert steps[3] < 1e-10  # |x(4) - x(5)|, the paper's criterion
    assert steps[2] < 1e-12 and steps[3] < 1e-12, steps  # MODEL.md: < 1e-12 m beyond n = 3
    # and every DPS is ~33 nm ahead of the LPS: the element count is not what matters
    assert np.all(np.abs(xs - paper_x1("lps") - 33e-9) < 2e-9)


def test_dps_element_count_converges_at_finer_step(paper_x1):
    """The element-count differences are not a time-step artefact: at dt = 5e-9 s the n = 3..5
    differences agree with those at 1e-8 s to 1e-14 m."""
    fine = np.diff([paper_x1("dps", n, dt=5e-9) for n in (3, 4, 5)])
    coarse = np.diff([paper_x1("dps", n) for n in (3, 4, 5)])
    np.testing.assert_allclose(fine, coarse, rtol=0, atol=1e-14)
