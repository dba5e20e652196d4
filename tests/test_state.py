"""``idm_rs.State``: the model's state vector with the name and unit of each component, what
``SimulationResult.final_state`` is and what ``initial_state`` takes; and the checks a hand-built
initial state goes through (size, finite, presliding force within its bound)."""

from __future__ import annotations

import numpy as np
import pytest

import idm_rs
from idm_rs import State

P = idm_rs.Params()
WAVE = idm_rs.Triangle(80.0, 0.3e-3, 0.7e-3)
LPS_NAMES = ["q0", "q1", "v0", "v1", "g", "fh", "h"]


def presliding_bound(p: idm_rs.Params) -> float:
    """min(Fs, a/(b+c)) [N], the bound on |Fh| (MODEL.md invariant)."""
    fs = max(p.mu_s, p.mu_k) * p.effective_normal_force
    return min(fs, p.fric_alpha / (p.fric_beta + p.fric_gamma))


@pytest.fixture(scope="module")
def lps_result() -> idm_rs.SimulationResult:
    return idm_rs.simulate(P, WAVE, t_end=1e-3, dt=1e-8, model="lps")


def test_state_is_exported_from_the_package():
    assert idm_rs.State is State
    assert "State" in idm_rs.__all__


def test_final_state_is_a_named_state_at_t_end(lps_result):
    s = lps_result.final_state
    assert isinstance(s, State) and isinstance(s, np.ndarray)
    assert s.dtype == np.float64 and s.shape == (7,)
    assert [n for n, _ in s.components] == LPS_NAMES
    assert s.t == 1e-3 == lps_result.t[-1]


def test_final_state_components_read_the_last_saved_values(lps_result):
    s, r = lps_result.final_state, lps_result
    assert s["q0"] == r.final_position == r.nodes[-1, 0]
    assert s["q1"] == r.nodes[-1, 1]
    assert s["v0"] == r.velocities[-1, 0]
    assert s["fh"] == r.fh[-1] and s["g"] == r.g[-1] and s["h"] == r.h[-1]
    np.testing.assert_array_equal(s.nodes, r.nodes[-1])
    np.testing.assert_array_equal(s.velocities, r.velocities[-1])
    assert s.to_dict()["fh"] == s["fh"]


def test_final_state_units(lps_result):
    s = lps_result.final_state
    assert s.unit("fh") == "N"
    assert s.unit("q0") == "m" and s.unit("v1") == "m/s"
    assert s.unit("g") == "m" and s.unit("h") == "m"


def test_unknown_component_name_is_a_key_error(lps_result):
    with pytest.raises(KeyError, match="x_sensor"):
        lps_result.final_state["x_sensor"]
    with pytest.raises(KeyError, match="nope"):
        lps_result.final_state.unit("nope")


@pytest.mark.parametrize(
    "model, n_elements, effects, energy, size, last",
    [
        ("lps", 4, None, False, 7, "h"),  # 2 nodes: 2 q + 2 v + g, fh, h
        ("dps", 4, None, False, 13, "h"),  # 5 nodes
        ("dps", 3, idm_rs.Effects(tau_sensor=2e-5), False, 12, "x_sensor"),
        ("dps", 3, idm_rs.Effects(tau_amp=1e-5, tau_creep=1e-3, tau_sensor=1e-5), False, 14, "x_sensor"),
        ("lps", 4, None, True, 14, "i_external"),  # + 7 accounting states
    ],
)
def test_at_rest_has_the_model_size_and_is_zero(model, n_elements, effects, energy, size, last):
    s = State.at_rest(P, model=model, n_elements=n_elements, effects=effects, energy=energy)
    assert s.shape == (size,)
    assert s.components[-1][0] == last
    assert np.all(np.asarray(s) == 0.0)
    assert s.t == 0.0


def test_effect_states_come_in_their_order_with_units():
    s = State.at_rest(P, model="lps", effects=idm_rs.Effects(tau_amp=1e-5, tau_creep=1e-3, tau_sensor=1e-5))
    assert s.components[7:] == (("v_pe", "V"), ("x_creep", "m"), ("x_sensor", "m"))


def test_build_sets_named_components_and_leaves_the_rest_at_zero():
    s = State.build(P, {"q0": 1e-6, "v1": 2.0, "fh": 0.1}, model="lps", t=1e-3)
    assert s.t == 1e-3
    assert s["q0"] == 1e-6 and s["v1"] == 2.0 and s["fh"] == 0.1
    assert s[0] == 1e-6 and s[3] == 2.0 and s[5] == 0.1
    assert np.count_nonzero(np.asarray(s)) == 3
    np.testing.assert_array_equal(s.nodes, [1e-6, 0.0])
    np.testing.assert_array_equal(s.velocities, [0.0, 2.0])


def test_build_refuses_an_unknown_name():
    with pytest.raises(KeyError, match="zz"):
        State.build(P, {"zz": 1.0}, model="lps")


def test_a_state_of_the_wrong_size_is_refused_naming_the_components():
    comps = State.at_rest(P, model="lps").components
    with pytest.raises(ValueError, match=r"3 values but 7 components.*fh"):
        State(np.zeros(3), comps)


def test_arithmetic_keeps_names_and_time():
    s = State.build(P, {"fh": 0.1}, model="lps", t=2e-3)
    d = s * 2
    assert isinstance(d, State) and d["fh"] == 0.2 and d.t == 2e-3


def test_a_hand_built_state_starts_a_run():
    """A state with the main body displaced by 1 um and at rest otherwise: the body stays put
    until the input moves it (the friction holds it), so x1 starts from 1 um."""
    s = State.build(P, {"q0": 1e-6, "q1": 1e-6}, model="lps")
    r = idm_rs.simulate(P, WAVE, t_end=1e-5, dt=1e-8, model="lps", initial_state=s)
    assert r.nodes[0, 0] == 1e-6
    assert abs(r.final_position - 1e-6) < 1e-7


def test_presliding_force_beyond_its_bound_is_refused_naming_fh():
    bound = presliding_bound(P)
    s = State.build(P, {"fh": 2.0 * bound}, model="lps")
    with pytest.raises(ValueError, match="'fh'") as exc:
        idm_rs.simulate(P, WAVE, t_end=1e-4, dt=1e-8, model="lps", initial_state=s)
    assert "bound" in str(exc.value)


def test_presliding_force_at_its_bound_is_accepted():
    bound = presliding_bound(P)
    s = State.build(P, {"fh": bound}, model="lps")
    r = idm_rs.simulate(P, WAVE, t_end=1e-5, dt=1e-8, model="lps", initial_state=s, save_every=1)
    # accepted, and the run starts from it: Fh at its bound at t = 0 and within it after
    assert r.fh[0] == bound
    assert np.all(np.abs(r.fh) <= bound * (1 + 1e-9)) and np.isfinite(r.final_position)


def test_initial_state_of_the_wrong_length_is_refused_naming_the_components():
    with pytest.raises(ValueError, match=r"5 components but this model has 7 \(q0, q1, v0, v1, g, fh, h\)"):
        idm_rs.simulate(P, WAVE, t_end=1e-4, dt=1e-8, model="lps", initial_state=np.zeros(5))


def test_a_dps_state_is_refused_by_the_lps_model():
    s = State.at_rest(P, model="dps", n_elements=4)
    with pytest.raises(ValueError, match="13 components but this model has 7"):
        idm_rs.simulate(P, WAVE, t_end=1e-4, dt=1e-8, model="lps", initial_state=s)


def test_non_finite_initial_state_is_refused_naming_the_component():
    y0 = np.zeros(7)
    y0[4] = np.nan
    with pytest.raises(ValueError, match="'g'"):
        idm_rs.simulate(P, WAVE, t_end=1e-4, dt=1e-8, model="lps", initial_state=y0)


# --- defects found in review, fixed: slices, reductions --------------------------------------


def test_a_slice_does_not_claim_the_whole_states_names():
    s = State.build(P, {"q0": 1e-6, "v0": 3.0}, model="lps")
    tail = s[2:]
    assert not isinstance(tail, State) or len(tail.components) == tail.size


def test_repr_of_a_reduction_does_not_raise():
    s = State.build(P, {"fh": 0.1}, model="lps")
    assert "0.1" in repr(s.sum())
