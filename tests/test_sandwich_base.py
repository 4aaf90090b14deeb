"""One sandwich base: every member inherits placement, python-control bridge and simulate.

The members supply their hysteresis block only; these tests drive each member through the
base's paths (placed simulate against python-control's own simulation of ``to_control``, the
``from_control`` round trip with placement, admissibility) so a member that diverged from the
others would fail here.
"""

import control as ct
import numpy as np
import pytest

from hystid.mduhem import MultiDuhemSandwich, MultiDuhemStructure
from hystid.model import DuhemSandwich, InitialCondition, Structure
from hystid.operating import AdmissibilityWarning, Envelope
from hystid.pi import PISandwich, PIStructure
from hystid.reference import PAPER_PARAMS
from hystid.sandwich import Sandwich
from hystid.thresholds import swing_thresholds

FS = 10_000.0


def _input(n: int, seed: int) -> np.ndarray:
    """A band-limited random input that starts next to the rest level, not on it."""
    rng = np.random.default_rng(seed)
    u = np.cumsum(rng.normal(scale=0.6, size=n + 14))
    u = np.convolve(u, np.ones(15) / 15, mode="valid")
    u = u - u[0] + 0.05  # a small step out of the rest level 12.5 (not at rest)
    return 12.5 + 3.0 * u / np.max(np.abs(u))


def duhem_member() -> DuhemSandwich:
    s = Structure(n1a=1, n1b=1, n2a=2, n2b=1, q1=1, q2=1)
    p = {**PAPER_PARAMS, "b11": 0.2, "b21": -0.3}
    return DuhemSandwich(p, s, fs=FS, name="d", u_rest=12.5, offset=-0.8)


def pi_member() -> PISandwich:
    s = PIStructure(n_operators=6, n1a=0, n1b=1, q1=0, n2a=3, n2b=3, q2=1)
    r = swing_thresholds(_input(4000, 1) - 12.5, 6)
    values = {"b22": 0.1, "b23": -0.05, "a21": -1.2, "a22": 0.5, "a23": -0.1}
    values.update({f"mu{i}": 0.9 / (i + 1) for i in range(6)})
    return PISandwich(values, r, s, fs=FS, name="p", u_rest=12.5, offset=-0.8)


def mduhem_member() -> MultiDuhemSandwich:
    s = MultiDuhemStructure(n_operators=3)
    values = {"a11": -0.3, "f1_0": 0.2, "f1_1": 0.3, "f1_2": 0.1, "g0_0": 0.1, "g0_1": 0.05,
              "g0_2": 0.02, "a21": -1.2, "a22": 0.5, "a23": -0.1, "b22": 0.1, "b23": -0.05}
    return MultiDuhemSandwich(values, [0.1, 0.5, 2.0], s, fs=FS, name="m", u_rest=12.5,
                              offset=-0.8)


MEMBERS = {"duhem": duhem_member, "pi": pi_member, "mduhem": mduhem_member}
#: What each member's constructor takes after the parameters (its fixed block constants).
FIXED = {"pi": lambda m: (m.thresholds,), "mduhem": lambda m: (m.rates,)}


@pytest.mark.parametrize("kind", MEMBERS)
def test_members_supply_only_their_block(kind):
    model = MEMBERS[kind]()
    assert isinstance(model, Sandwich)
    for shared in ("simulate", "to_control", "control_state", "from_control", "L1", "L2",
                   "admissibility", "save", "params", "dt"):
        assert shared not in vars(type(model)), f"{type(model).__name__} redefines {shared}"


@pytest.mark.parametrize("kind", MEMBERS)
def test_placed_simulate_equals_python_control(kind):
    model = MEMBERS[kind]()
    u = _input(1500, 2)
    fast = model.simulate(u, check=False)
    sys = model.to_control()
    assert {"U0", "Y0"} <= {s.name for s in sys.syslist}
    resp = ct.input_output_response(sys, fast.t, u, X0=model.control_state())
    scale = np.max(np.abs(fast.y))
    assert np.max(np.abs(resp.outputs[0] - fast.y)) <= 1e-9 * scale
    # the offset is in the output and the rest level in the input, as the record has them
    assert abs(model.simulate(np.full(50, model.u_rest), check=False).y[-1] - model.offset) \
        < 1e-12


@pytest.mark.parametrize("kind", MEMBERS)
def test_from_control_keeps_parameters_and_placement(kind):
    model = MEMBERS[kind]()
    options = {"structure": model.structure} if kind == "pi" else {}
    back = type(model).from_control(model.to_control(), **options)
    assert (back.u_rest, back.offset) == (model.u_rest, model.offset)
    u = _input(800, 3)
    np.testing.assert_allclose(back.simulate(u, check=False).y, model.simulate(u, check=False).y,
                               rtol=1e-9, atol=1e-12)


@pytest.mark.parametrize("kind", MEMBERS)
def test_admissibility_is_one_test_for_every_member(kind):
    model = MEMBERS[kind]()
    u = _input(1000, 4)
    model.envelope = Envelope.of(u)
    assert model.admissibility(u) == []
    wide = model.u_rest + 3.0 * (u - model.u_rest)
    with pytest.warns(AdmissibilityWarning, match="envelope|range"):
        model.simulate(wide)
    # an unstable L2 is refused by every member, not only by the Duhem sandwich
    theta = model.theta.copy()
    names = list(model.structure.names)
    theta[names.index("a21")] = -2.5
    bad = type(model)(theta, *FIXED.get(kind, lambda m: ())(model), model.structure, fs=FS)
    assert any("not sound" in m for m in bad.admissibility(u[:200]))


def test_initial_condition_is_shared():
    x0 = InitialCondition(u=[1.0, 2.0], w1=[0.5])
    assert list(x0.window("u", 3)) == [0.0, 1.0, 2.0]
    with pytest.raises(TypeError, match="p0"):
        duhem_member().simulate(np.zeros(5), p0=[0.0])



def test_a_prefix_of_the_identification_input_stays_inside_the_envelope():
    """A 200 Hz training input: a 3.5 V step out of rest, then a triangle with three level
    steps of 1.5-1.9 V. Its first 4 000 of 4 200 samples read a 99.9 % slew of about 1.5 V
    per sample against the whole record's and were warned about (the quantile of four
    isolated steps moves with the record's length); an input faster throughout still is."""
    t = np.arange(4001) / 200.0
    u = np.r_[np.zeros(199), 3.5 + 2.0 * np.abs(((t + 0.25) % 1.0) - 0.5) * 2.0]
    for k, jump in ((1800, 1.91), (2600, 1.56), (3400, 1.55)):
        u[k:] += jump
    env = Envelope.of(u)
    old = Envelope.of(u[:4000]).slew > 1.1 * env.slew  # what the quantile alone said
    assert old and env.violations(u[:4000]) == [] and env.violations(u) == []
    faster = u[::4]  # the same input, four times as fast
    assert any("slews" in v for v in env.violations(faster))
