"""The sandwich model: compiled simulation, python-control bridge both ways, bad input."""

import control as ct
import numpy as np
import pytest

from hystid import DuhemSandwich, InitialCondition, Structure
from hystid.reference import PAPER_PARAMS, paper_excitation, reference_model

GENERAL = Structure(n1a=2, n1b=1, n2a=2, n2b=2, q1=1, q2=1, f0=True)
GENERAL_PARAMS = {
    "b21": 0.3, "b22": -0.1, "alpha": 0.6, "f0": 0.05, "f1": 0.14, "b11": 0.4, "g0": 0.01,
    "a11": -0.6, "a12": 0.08, "a21": -1.5, "a22": 0.85,
}


def plain_loop(model: DuhemSandwich, u, past: InitialCondition | None = None):
    """Eqs. (1), (7), (2) transcribed sample by sample, in plain Python."""
    s, p = model.structure, model.params
    P = s.history
    past = past or InitialCondition()
    U = list(past.window("u", P)) + list(u)
    W1, W2, Y = (list(past.window(k, P)) for k in ("w1", "w2", "y"))
    for k in range(P, P + len(u)):
        w1 = U[k - s.q1] + sum(p[f"b1{j}"] * U[k - s.q1 - j] for j in range(1, s.n1b + 1))
        w1 -= sum(p[f"a1{i}"] * W1[k - i] for i in range(1, s.n1a + 1))
        W1.append(w1)
        dw1 = w1 - W1[k - 1]
        f = p.get("f0", 0.0) * np.sign(W1[k - 1]) + p["f1"] * W1[k - 1]
        W2.append(W2[k - 1] + p["alpha"] * (f - W2[k - 1]) * abs(dw1) + p["g0"] * dw1)
        y = W2[k - s.q2] + sum(p[f"b2{j}"] * W2[k - s.q2 - j] for j in range(1, s.n2b + 1))
        y -= sum(p[f"a2{i}"] * Y[k - i] for i in range(1, s.n2a + 1))
        Y.append(y)
    return np.array(W1[P:]), np.array(W2[P:]), np.array(Y[P:])


@pytest.fixture(params=["paper", "general"])
def model(request):
    if request.param == "paper":
        return reference_model()
    return DuhemSandwich(GENERAL_PARAMS, GENERAL, fs=30_000.0)


def _input(n=600, seed=3):
    return paper_excitation(n, seed=seed, ramp_time=0.002)


def test_simulate_matches_plain_loop(model):
    u = _input()
    r = model.simulate(u)
    w1, w2, y = plain_loop(model, u)
    np.testing.assert_allclose(r.w1, w1, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(r.w2, w2, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(r.y, y, rtol=1e-12, atol=1e-12)
    t, yy = r  # unpacks like a python-control response
    assert len(t) == len(u)
    np.testing.assert_array_equal(yy, r.y)


def test_simulate_returns_a_labelled_control_response(model):
    import control as ct
    import matplotlib

    matplotlib.use("Agg")  # the test's own backend choice; the library makes none
    u = _input(200)
    r = model.simulate(u)
    assert isinstance(r, ct.TimeResponseData)
    assert (r.input_labels, r.output_labels, r.state_labels) == (["u"], ["y"], ["w1", "w2"])
    np.testing.assert_array_equal(r.outputs["y"], r.y)
    np.testing.assert_array_equal(r.states["w2"], r.w2)
    np.testing.assert_array_equal(r.inputs, u)
    frame = r.to_pandas()
    assert list(frame.columns) == ["time", "u", "y", "w1", "w2"]
    np.testing.assert_array_equal(frame["w1"], r.w1)
    np.testing.assert_array_equal(frame["time"], r.t)
    cplt = r.plot()
    lines = [line for row in cplt.lines.ravel() for line in row]
    assert len(lines) == 2  # y and u
    np.testing.assert_array_equal(lines[0].get_ydata(), r.y)
    with pytest.raises(AttributeError, match="signals: u, y, w1, w2"):
        _ = r.w3


def _past(model, seed=5):
    rng = np.random.default_rng(seed)
    n = model.structure.history + 2
    return InitialCondition(u=5 + rng.normal(size=n), w1=10 + rng.normal(size=n),
                            w2=1.4 + 0.1 * rng.normal(size=n), y=4.5 + rng.normal(size=n))


@pytest.mark.parametrize("from_rest", [True, False])
def test_control_interconnect_matches_fast_path(model, from_rest):
    x0 = None if from_rest else _past(model)
    u = _input(400) + (0.0 if from_rest else 5.0)
    fast = model.simulate(u, x0)
    w1, w2, y = plain_loop(model, u, x0)
    np.testing.assert_allclose(fast.y, y, rtol=1e-12, atol=1e-12)
    sys = model.to_control()
    assert isinstance(sys, ct.InterconnectedSystem)
    assert sys.input_labels == ["u"] and sys.output_labels == ["y", "w1", "w2"]
    resp = ct.input_output_response(sys, fast.t, u, X0=model.control_state(x0))
    scale = np.max(np.abs(fast.y))
    assert np.max(np.abs(resp.outputs[0] - fast.y)) <= 1e-9 * scale
    assert np.max(np.abs(resp.outputs[1] - fast.w1)) <= 1e-9 * np.max(np.abs(fast.w1))
    assert np.max(np.abs(resp.outputs[2] - fast.w2)) <= 1e-9 * np.max(np.abs(fast.w2))


def test_blocks_are_named_discrete_control_objects(model):
    assert isinstance(model.L1, ct.TransferFunction) and isinstance(model.L2, ct.TransferFunction)
    assert isinstance(model.H, ct.NonlinearIOSystem)
    for sys in (model.L1, model.L2, model.H):
        assert sys.dt == pytest.approx(1 / 30_000.0)
    assert (model.L1.input_labels, model.L1.output_labels) == (["u"], ["w1"])
    assert (model.L2.input_labels, model.L2.output_labels) == (["w2"], ["y"])
    assert (model.H.input_labels, model.H.output_labels) == (["w1"], ["w2"])


def test_paper_stage_gains_match_measured_facts():
    m = reference_model()
    assert ct.dcgain(m.L1) == pytest.approx(1 / (1 - 0.529), rel=1e-12)
    assert ct.dcgain(m.L2) == pytest.approx(3.15, abs=0.005)
    poles = ct.poles(m.L2)
    assert np.abs(poles) == pytest.approx([0.9605, 0.9605], abs=1e-4)
    freq = np.abs(np.angle(poles[0])) * m.fs / (2 * np.pi)
    assert freq == pytest.approx(2780, rel=0.01)


@pytest.mark.parametrize("way", ["blocks", "interconnected"])
def test_model_from_control_objects(model, way):
    if way == "blocks":
        back = DuhemSandwich.from_control(model.L1, model.H, model.L2)
    else:
        back = DuhemSandwich.from_control(model.to_control())
    assert back.structure == model.structure
    np.testing.assert_allclose(back.theta, model.theta, rtol=1e-9, atol=1e-12)
    u = _input(300)
    np.testing.assert_allclose(back.simulate(u).y, model.simulate(u).y, rtol=1e-9, atol=1e-12)


def test_params_override_in_input_output_response():
    m = reference_model()
    changed = DuhemSandwich({**PAPER_PARAMS, "alpha": 0.5})
    u = _input(300)
    resp = ct.input_output_response(m.to_control(), m.simulate(u).t, u, params={"alpha": 0.5})
    np.testing.assert_allclose(resp.outputs[0], changed.simulate(u).y, rtol=1e-9, atol=1e-12)


def test_structure_names_follow_the_paper():
    assert Structure().names == ("alpha", "f1", "g0", "a11", "a21", "a22")
    assert GENERAL.names[:3] == ("b21", "b22", "alpha")
    assert GENERAL.history == 3


@pytest.mark.parametrize(
    "params, match",
    [
        ({**PAPER_PARAMS, "alpha": float("nan")}, "non-finite"),
        ({k: v for k, v in PAPER_PARAMS.items() if k != "g0"}, "missing \\['g0'\\]"),
        ({**PAPER_PARAMS, "b11": 0.1}, "unknown \\['b11'\\]"),
        ([0.1, 0.2], "expected 6 values"),
    ],
)
def test_bad_parameters_are_named(params, match):
    with pytest.raises(ValueError, match=match):
        DuhemSandwich(params)


@pytest.mark.parametrize(
    "u, match", [(np.ones((3, 2)), "1-D"), (np.array([0.0, np.nan, 1.0]), "sample 1")]
)
def test_bad_input_signal_is_named(u, match):
    with pytest.raises(ValueError, match=match):
        reference_model().simulate(u)


def test_bad_structure_is_named():
    with pytest.raises(ValueError, match="n2a"):
        Structure(n2a=-1)


def test_from_control_rejects_non_unit_leading_coefficient():
    m = reference_model()
    with pytest.raises(ValueError, match="b_0 = 1"):
        DuhemSandwich.from_control(2 * m.L1, m.H, m.L2)


def test_stability_check():
    assert reference_model().is_stable()
    assert not DuhemSandwich({**PAPER_PARAMS, "a22": 1.2}).is_stable()
    assert not DuhemSandwich({**PAPER_PARAMS, "alpha": -0.1}).is_stable()


def test_response_signals_can_be_replaced_without_touching_the_simulation(model):
    u = _input(100)
    r = model.simulate(u)
    y0 = r.y.copy()
    r.y = r.y + 1.0  # e.g. sensor noise added afterwards
    np.testing.assert_array_equal(r.y, y0 + 1.0)
    np.testing.assert_array_equal(r.to_pandas()["y"], y0 + 1.0)
    with pytest.raises(ValueError, match="expected 100 samples"):
        r.y = np.zeros(3)
