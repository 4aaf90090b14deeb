"""The generalised Duhem block: eq. (7) with a polynomial anhysteretic curve and slope and
direction-dependent coefficients (``Structure(f_order, g_order, directional)``).

The kernels are checked against a transcription written here in another form (rising and
falling rates instead of ``alpha (1 + ad s)``), the sensitivities against finite differences,
and the fits on a stage simulated by :mod:`hystid.testing` (its own Duhem code, with branch
asymmetry and a level-dependent loop width, input in mV with an offset, output offset) against
the plain block and the baselines.
"""

import warnings

import control as ct
import numpy as np
import pytest

from hystid import load_model
from hystid.baselines import compare
from hystid.identify import identify
from hystid.identify.members import MEMBERS
from hystid.identify.offline import output_sensitivities
from hystid.model import DuhemSandwich, Structure
from hystid.records import Record
from hystid.reference import PAPER_PARAMS
from hystid.testing.hysteresis import Duhem
from hystid.testing.stages import paper_excitation, paper_like_stage

FULL = Structure(n1a=1, n1b=1, n2a=2, n2b=1, q1=1, q2=1, f0=True, f_order=3, g_order=2,
                 directional=True)
SHAPE = {"f2": 2e-3, "f3": -4e-4, "g1": 3e-3, "g2": -2e-4, "ad": 0.3, "gd": 0.02}


def full_model(**placement) -> DuhemSandwich:
    values = {**PAPER_PARAMS, "f0": 0.01, "b11": 0.2, "b21": -0.3, **SHAPE}
    return DuhemSandwich(values, FULL, fs=30_000.0, **placement)


def transcription(model: DuhemSandwich, u: np.ndarray) -> np.ndarray:
    """Eqs. (1), (7), (2) from rest, eq. (7) written with a rising and a falling rate."""
    p, s = model.params, model.structure
    up, down = p["alpha"] * (1 + p["ad"]), p["alpha"] * (1 - p["ad"])
    n = len(u)
    P = s.history
    U = np.r_[np.zeros(P), u]
    W1, W2, Y = (np.zeros(P + n) for _ in range(3))
    for k in range(P, P + n):
        W1[k] = U[k - 1] + p["b11"] * U[k - 2] - p["a11"] * W1[k - 1]
        v, d = W1[k - 1], W1[k] - W1[k - 1]
        anhysteretic = p["f0"] * np.sign(v) + p["f1"] * v + p["f2"] * v * v + p["f3"] * v ** 3
        slope = p["g0"] + p["g1"] * v + p["g2"] * v * v
        if d > 0:
            W2[k] = W2[k - 1] + up * (anhysteretic - W2[k - 1]) * d + (slope + p["gd"]) * d
        elif d < 0:
            W2[k] = W2[k - 1] - down * (anhysteretic - W2[k - 1]) * d + (slope - p["gd"]) * d
        else:
            W2[k] = W2[k - 1]
        Y[k] = (W2[k - 1] + p["b21"] * W2[k - 2] - p["a21"] * Y[k - 1] - p["a22"] * Y[k - 2])
    return Y[P:]


def _input(n: int = 1500, seed: int = 0) -> np.ndarray:
    return paper_excitation(n / 30_000.0, seed=seed, ramp_seconds=0.002)


def test_kernel_is_the_generalised_equation():
    model = full_model()
    assert model.structure.names[-6:] == ("f2", "f3", "g1", "g2", "ad", "gd")
    u = _input()
    y = model.simulate(u, check=False).y
    np.testing.assert_allclose(y, transcription(model, u), rtol=1e-11, atol=1e-12)
    # the shape terms matter: the plain block differs
    plain = DuhemSandwich({k: v for k, v in model.params.items() if k not in SHAPE},
                          Structure(1, 1, 2, 1, 1, 1, True), fs=30_000.0)
    assert np.max(np.abs(plain.simulate(u, check=False).y - y)) > 1e-2 * np.ptp(y)


def test_sensitivities_match_finite_differences():
    model = full_model()
    u = _input(900, seed=2)
    theta = model.theta
    _, S = output_sensitivities(theta, FULL, u)
    for p in range(len(theta)):
        h = 1e-6 * max(1.0, abs(theta[p]))
        tp, tm = theta.copy(), theta.copy()
        tp[p] += h
        tm[p] -= h
        fd = (output_sensitivities(tp, FULL, u)[0] - output_sensitivities(tm, FULL, u)[0]) / (2 * h)
        np.testing.assert_allclose(S[:, p], fd, rtol=1e-4, atol=1e-6 * np.max(np.abs(fd)) + 1e-9,
                                   err_msg=FULL.names[p])


def test_python_control_block_and_model_file(tmp_path):
    model = full_model(u_rest=1.5, offset=-0.4)
    u = 1.5 + _input(600, seed=4)
    fast = model.simulate(u, check=False)
    sys = model.to_control()
    resp = ct.input_output_response(sys, fast.t, u, X0=model.control_state())
    assert np.max(np.abs(resp.outputs[0] - fast.y)) <= 1e-9 * np.max(np.abs(fast.y))
    back = DuhemSandwich.from_control(sys)
    assert back.structure == model.structure
    np.testing.assert_allclose(back.theta, model.theta, rtol=1e-9)
    path = model.save(tmp_path / "g.json")
    loaded = load_model(path)
    assert loaded.structure == model.structure
    np.testing.assert_array_equal(loaded.simulate(u, check=False).y, fast.y)
    # the paper's block is written as before, without the shape keys
    plain = DuhemSandwich(PAPER_PARAMS).save(tmp_path / "p.json")
    assert "f_order" not in plain.read_text()


def test_rest_state_follows_the_generalised_block():
    model = full_model()
    x0 = model.rest_state(3.0)
    held = model.simulate(np.full(400, 3.0), x0, check=False).y
    assert np.ptp(held) < 1e-9 * max(1.0, abs(held[0]))  # a rest is a rest


def _record(stage, seed: int, seconds: float) -> Record:
    u = paper_excitation(seconds, 10_000.0, seed=seed, frequency=(150.0, 15.0),
                         ramp_seconds=0.05)
    y = stage.simulate(u, u_rest=0.0)["y"]
    noise = np.random.default_rng(seed + 100).normal(scale=1e-3, size=len(y))
    return Record(1000.0 * u - 300.0, y + 2.0 + noise, 10_000.0, units={"u": "mV", "y": "um"},
                  name=f"asymmetric stage #{seed}")


@pytest.fixture(scope="module")
def asymmetric_stage():
    """A 10 kHz stage whose Duhem loop rises faster than it falls and widens with the level."""
    p = PAPER_PARAMS
    h = Duhem(alpha=p["alpha"], f1=p["f1"], g0=p["g0"], asymmetry=0.4, width_slope=0.3,
              width_centre=11.0, width_scale=5.0)
    stage = paper_like_stage(fs=10_000.0, hysteresis=h)
    return _record(stage, 0, 1.0), [_record(stage, 1, 0.5), _record(stage, 2, 0.5)]


@pytest.mark.parametrize("method", ["batch", "online"])
def test_direction_dependent_block_wins_where_the_stage_needs_it(asymmetric_stage, method):
    train, held = asymmetric_stage
    rows = {}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        for name, s in (("plain", Structure()), ("directional", Structure(directional=True))):
            rows[name] = compare(identify(train, method=method, structure=s).model,
                                 train, held).rows
    for plain, richer in zip(rows["plain"], rows["directional"], strict=True):
        assert richer["model"] < 0.5 * plain["model"], (plain, richer)
        assert richer["model"] < 0.3 * min(richer["linear"], richer["static_line"]), richer


def test_gduhem_member_and_what_it_is_refused_by():
    from hystid.compensate import compensate
    from hystid.export.c import c_sources

    m = MEMBERS["gduhem"]
    assert m.kind == "duhem" and not m.structure.is_plain
    model = full_model()
    u = _input(300)
    # compensation has the block's own inverse (tests/test_compensate_members.py); only
    # without look-ahead
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        assert np.all(np.isfinite(compensate(model, model.simulate(u, check=False).y,
                                             u_limits=(-1.0, 11.0)).u))
    with pytest.raises(ValueError, match="preview: the generalised Duhem block .* without "
                                         "look-ahead"):
        compensate(model, model.simulate(u, check=False).y, u_limits=(-1.0, 11.0), preview=30)
    # the C export writes the model's step, the block's inverse and its on-line identifier
    # (tests/test_export.py runs them against Python); a look-ahead asked for is refused
    notes: list[str] = []
    texts = c_sources(model, notes=notes, compensator={"u_limits": (-1.0, 11.0)})
    head = texts["hystid_model.h"]
    assert "#define HYSTID_DUHEM_GENERALISED 1" in head
    assert "HYSTID_NO_FF" not in head and "HYSTID_NO_RPEM" not in head and not notes
    assert "hx_gd_inverse_step" in texts["hystid_model.c"]
    with pytest.raises(ValueError, match="preview: the generalised Duhem block .* without"):
        c_sources(model, compensator={"u_limits": (-1.0, 11.0), "preview": 30})
    with pytest.raises(ValueError, match="eria.*plain Duhem"):
        identify(Record(u, model.simulate(u, check=False).y, 30_000.0), method="eria",
                 structure=FULL)


@pytest.mark.parametrize("change, message", [
    (lambda d: d["structure"].__setitem__("f_order", 7), "f_order must be an integer from 1 to 3"),
    (lambda d: d["structure"].__setitem__("directional", "yes"),
     "'directional' must be true or false"),
    (lambda d: d["params"].pop("gd"), r"missing \['gd'\]"),
    (lambda d: d["params"].__setitem__("ad", 5.0), r"expected \|ad\| < 1"),
])
def test_a_bad_generalised_model_file_is_refused_by_name(tmp_path, change, message):
    import json

    from hystid.errors import ModelFileError

    doc = json.loads(full_model().save(tmp_path / "g.json").read_text())
    change(doc)
    bad = tmp_path / "bad.json"
    bad.write_text(json.dumps(doc))
    with pytest.raises(ModelFileError, match=message):
        load_model(bad)
