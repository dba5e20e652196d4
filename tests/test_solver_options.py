"""One solver-options object (``idm_rs.Solver``) for every entry point: the same run as the flat
keywords, bit for bit; a disagreement between the two refused by name; a bad setting refused
when the Solver is made."""

from __future__ import annotations

import numpy as np
import pytest

import idm_rs
from idm_rs import Solver
from idm_rs.core.batch import Point, Structure, run

P = idm_rs.Params()
W = idm_rs.Triangle(80.0, 0.5e-3, 1.5e-3)


def test_simulate_with_a_solver_is_the_run_with_the_keywords():
    for solver, flat in [(Solver("rk4", dt=2e-8), dict(method="rk4", dt=2e-8)),
                         (Solver("dopri5", rtol=1e-8, atol=1e-8), dict(method="dopri5", rtol=1e-8, atol=1e-8))]:
        a = idm_rs.simulate(P, W, 2e-3, model="lps", solver=solver)
        b = idm_rs.simulate(P, W, 2e-3, model="lps", **flat)
        np.testing.assert_array_equal(a.nodes, b.nodes)
        assert a.final_position == b.final_position


def test_sweep_and_batch_with_a_solver_are_the_runs_with_the_keywords():
    grid = {"voltage": [60.0, 120.0]}
    kw = dict(t_end=2e-3, model="lps", progress=False)
    a = idm_rs.sweep(P, W, grid, solver=Solver("rk4", dt=5e-8, retries=0), **kw)
    b = idm_rs.sweep(P, W, grid, method="rk4", dt=5e-8, retries=0, **kw)
    np.testing.assert_array_equal(a.final_position.values, b.final_position.values)
    pts = [Point(P, idm_rs.Effects(), W)]
    s = Structure("lps", 1)
    c = run(pts, s, t_end=2e-3, solver=Solver("dopri5", rtol=1e-8))
    d = run(pts, s, t_end=2e-3, method="dopri5", rtol=1e-8)
    assert c["final_position"][0] == d["final_position"][0]
    assert c["final_position"][0] != run(pts, s, t_end=2e-3, method="dopri5", rtol=1e-4)["final_position"][0]


def test_a_keyword_that_disagrees_with_the_solver_is_refused_by_name():
    with pytest.raises(ValueError, match=r"'method' is given as 'dopri5' and as solver.method = 'rk4'"):
        idm_rs.simulate(P, W, 1e-4, model="lps", method="dopri5", solver=Solver("rk4", dt=1e-8))
    with pytest.raises(ValueError, match=r"sweep: 'dt' is given as 1e-08 and as solver.dt = 2e-08"):
        idm_rs.sweep(P, W, {"voltage": [80.0]}, t_end=1e-4, dt=1e-8, model="lps", progress=False,
                     solver=Solver("rk4", dt=2e-8))
    with pytest.raises(ValueError, match=r"simulate takes no 'retries'"):
        idm_rs.simulate(P, W, 1e-4, model="lps", solver=Solver("rk4", dt=1e-8, retries=1))
    with pytest.raises(ValueError, match=r"diagnose fits with RK4"):
        idm_rs.diagnose("no/such/case", solver=Solver("dopri5"))
    with pytest.raises(TypeError, match="'solver' must be an idm_rs.Solver"):
        idm_rs.simulate(P, W, 1e-4, model="lps", solver={"method": "rk4"})  # type: ignore[arg-type]


@pytest.mark.parametrize("kw, needle", [
    (dict(method="rk45"), "parameter 'method' must be one of"),
    (dict(dt=-1e-8), "'dt' must be a positive finite number"),
    (dict(method="auto", rtol=float("nan")), "'rtol' must be a positive finite number"),
    (dict(method="dopri5", dt=1e-8), "chooses its own steps and takes no 'dt'"),
    (dict(retries=-1), "'retries' must be a non-negative integer"),
])
def test_a_bad_solver_is_refused_when_made(kw, needle):
    with pytest.raises(ValueError, match=needle):
        Solver(**kw)


def test_characterize_takes_a_solver_for_every_curve(monkeypatch):
    """Every sweep and batch characterize runs gets the Solver's settings (recorded here by
    standing in for the engine's batch start)."""
    import idm_rs.core.batch as batch

    seen = []
    real = batch.start

    def spy(*args, **kwargs):
        seen.append((kwargs.get("method"), kwargs.get("rtol")))
        return real(*args, **kwargs)

    monkeypatch.setattr(batch, "start", spy)
    from idm_rs.apps.actuator import characterize

    ds = characterize(model="lps", frequencies=[200.0], voltages=[80.0], step_voltages=[80.0], loads=3,
                      cycles=3, skip_cycles=1, progress=False, solver=Solver("dopri5", rtol=2e-7))
    assert ds["mean_velocity"].size == 1
    assert seen and all(m == "dopri5" and r == 2e-7 for m, r in seen), seen
