"""The multi-Duhem sandwich: several Duhem operators of eq. (7) in parallel (``mduhem``).

The compiled kernel is checked against a transcription written here with the operators as a
list of dictionaries, the sensitivities against central differences, the python-control
system against ``simulate`` (placed, not at rest), the model file bit for bit, and the member
on a stage simulated by :mod:`hystid.testing` whose hysteresis is a Maxwell-slip block (elasto-
slip elements: a sum of plays, no Duhem operator) against the plain Duhem member and both
baselines.
"""

import json
import warnings

import control as ct
import numpy as np
import pytest

from hystid import load_model
from hystid.baselines import compare
from hystid.identify import identify
from hystid.identify.mduhem_batch import (
    RATE_SLEW,
    fit_mduhem_output_error,
    mduhem_output_sensitivities,
    rate_grid,
)
from hystid.identify.members import MEMBERS
from hystid.mduhem import MultiDuhemSandwich, MultiDuhemStructure, mduhem_block
from hystid.modelfile import ModelFileError
from hystid.operating import AdmissibilityWarning, Envelope
from hystid.records import Record
from hystid.sandwich import InitialCondition
from hystid.testing.stages import paper_excitation, paper_like_stage

FS = 10_000.0
#: A structure that uses every part of the kernel: L1 with a pole, two numerator terms and a
#: delay, L2 third order with zeros and a delay, three operators.
RICH = MultiDuhemStructure(n_operators=3, n1a=1, n1b=2, q1=1, n2a=3, n2b=3, q2=1)
RATES = [0.2, 1.1, 6.0]


def rich_model(**placement) -> MultiDuhemSandwich:
    values = {"a11": -0.4, "b12": 0.15, "f1_0": 0.12, "f1_1": 0.3, "f1_2": 0.08,
              "g0_0": 0.05, "g0_1": 0.1, "g0_2": 0.03, "a21": -1.6, "a22": 0.9, "a23": -0.2,
              "b22": 0.2, "b23": -0.1}
    return MultiDuhemSandwich(values, RATES, RICH, fs=FS, **placement)


def _input(n: int = 1200, seed: int = 0) -> np.ndarray:
    """0 .. about 2 V, a swept sine with PRBS amplitude steps, from rest."""
    return 0.4 * paper_excitation(n / FS, FS, seed=seed, frequency=(300.0, 30.0),
                                  ramp_seconds=0.01)


def transcription(model: MultiDuhemSandwich, u: np.ndarray, p0=None) -> np.ndarray:
    """Free run from rest, every equation written out sample by sample."""
    prm = model.params
    ops = [{"alpha": a, "f1": prm[f"f1_{j}"], "g0": prm[f"g0_{j}"],
            "w2": 0.0 if p0 is None else p0[j]} for j, a in enumerate(model.rates)]
    a11, b12 = prm["a11"], prm["b12"]
    b11 = 1.0 + a11 - b12                               # unit DC gain of L1
    a2 = [prm["a21"], prm["a22"], prm["a23"]]
    b2_rest = [prm["b22"], prm["b23"]]
    b2 = [1.0 + sum(a2) - sum(b2_rest)] + b2_rest       # unit DC gain of L2

    def past(x, k):
        return x[k] if k >= 0 else 0.0

    v = u - model.u_rest
    w1, w2, y = [], [], []
    for k in range(len(u)):
        w1.append(b11 * past(v, k - 1) + b12 * past(v, k - 2) - a11 * past(w1, k - 1))
        step = w1[k] - past(w1, k - 1)
        for op in ops:
            anhysteretic = op["f1"] * past(w1, k - 1)
            op["w2"] += op["alpha"] * (anhysteretic - op["w2"]) * abs(step) + op["g0"] * step
        w2.append(sum(op["w2"] for op in ops))
        y.append(sum(b2[j] * past(w2, k - 1 - j) for j in range(3))
                 - sum(a2[i] * past(y, k - 1 - i) for i in range(3)))
    return np.array(y) + model.offset


def test_kernel_is_the_sum_of_duhem_operators():
    model = rich_model(u_rest=0.3, offset=-0.2)
    u = 0.3 + _input()
    y = model.simulate(u, check=False).y
    np.testing.assert_allclose(y, transcription(model, u), rtol=1e-11, atol=1e-12)
    p0 = [0.01, -0.02, 0.03]
    x0 = InitialCondition(w1=[0.0])
    np.testing.assert_allclose(model.simulate(u, x0, check=False, p0=p0).y,
                               transcription(model, u, p0), rtol=1e-11, atol=1e-12)
    # one operator alone is eq. (7): the others' slopes at zero leave only it
    only = MultiDuhemSandwich({**model.params, "f1_0": 0.0, "g0_0": 0.0, "f1_2": 0.0,
                               "g0_2": 0.0}, RATES, RICH, fs=FS)
    assert np.max(np.abs(only.simulate(u, check=False).y - y)) > 0.05 * np.ptp(y)


def test_sensitivities_match_finite_differences():
    model = rich_model()
    u = _input(900, seed=2)
    _, J = mduhem_output_sensitivities(model, u, rates=True)
    theta, rates = model.theta, model.rates

    def run(t, r):
        return mduhem_output_sensitivities(MultiDuhemSandwich(t, r, RICH, fs=FS), u)[0]

    names = list(RICH.names) + [f"alpha{j}" for j in range(len(rates))]
    for p in range(len(names)):
        h = 1e-6 * max(1.0, abs(np.r_[theta, rates][p]))
        if p < len(theta):
            step = np.eye(len(theta))[p] * h
            fd = (run(theta + step, rates) - run(theta - step, rates)) / (2 * h)
        else:
            step = np.eye(len(rates))[p - len(theta)] * h
            fd = (run(theta, rates + step) - run(theta, rates - step)) / (2 * h)
        np.testing.assert_allclose(J[:, p], fd, rtol=1e-5, atol=1e-6 * np.max(np.abs(fd)) + 1e-10,
                                   err_msg=names[p])


def test_python_control_equals_simulate_placed_and_away_from_rest():
    model = rich_model(u_rest=0.3, offset=-0.2)
    u = 0.3 + 0.2 + _input(700, seed=4)  # starts 0.2 V above the rest, held there before
    x0 = model.rest_state(u[0])
    fast = model.simulate(u, x0, check=False)
    sys = model.to_control()
    assert {"U0", "Y0", "H"} <= {s.name for s in sys.syslist}
    assert sys.nstates == 2 + (1 + 3) + 3  # L1 (delay + lag), H (w1_prev, 3 operators), L2
    resp = ct.input_output_response(sys, fast.t, u, X0=model.control_state(x0))
    assert np.max(np.abs(resp.outputs[0] - fast.y)) <= 1e-9 * np.max(np.abs(fast.y))
    np.testing.assert_allclose(resp.outputs[2], fast.w2, rtol=1e-9, atol=1e-12)
    # held at its start, a model brought there slowly stays there
    held = model.simulate(np.full(300, u[0]), x0, check=False).y
    assert np.ptp(held) < 1e-12 * max(1.0, abs(held[0]))
    # the interconnection reads back to the same model, its placement included
    back = MultiDuhemSandwich.from_control(sys, structure=RICH)
    assert (back.u_rest, back.offset) == (model.u_rest, model.offset)
    np.testing.assert_allclose(back.theta, model.theta, rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(back.rates, model.rates, rtol=1e-12)


def test_block_gains_move_into_the_operators():
    """L1 = g1 L1', L2 = g2 L2' read back as unit-gain blocks with the rates and slopes
    rescaled: the same input-output system."""
    model = rich_model()
    g1, g2 = -2.5, 0.4
    L1 = g1 * model.L1
    L2 = g2 * model.L2
    H = mduhem_block(model.rates / abs(g1), model.f1 / (g1 * g2), model.g0 / (g1 * g2),
                     dt=model.dt)
    back = MultiDuhemSandwich.from_control(L1, H, L2, structure=RICH)
    u = _input(500, seed=5)
    np.testing.assert_allclose(back.simulate(u, check=False).y, model.simulate(u, check=False).y,
                               rtol=1e-9, atol=1e-12)
    with pytest.raises(ValueError, match="H has 2 Duhem operators, the structure 3"):
        MultiDuhemSandwich.from_control(model.L1, mduhem_block([1.0, 2.0], [0.1, 0.1],
                                                               [0.0, 0.0], dt=model.dt),
                                        model.L2, structure=RICH)


def test_model_file_round_trip(tmp_path):
    model = rich_model(u_rest=0.3, offset=-0.2)
    model.envelope = Envelope.of(0.3 + _input())
    model.units = {"u": "mV", "y": "nm"}
    path = model.save(tmp_path / "m.json")
    text = path.read_text()
    assert '"kind": "mduhem"' in text and '"rates"' in text
    loaded = load_model(path)
    assert isinstance(loaded, MultiDuhemSandwich)
    assert loaded.structure == model.structure and loaded.units == model.units
    np.testing.assert_array_equal(loaded.rates, model.rates)
    u = 0.3 + _input(800, seed=6)
    np.testing.assert_array_equal(loaded.simulate(u, check=False).y,
                                  model.simulate(u, check=False).y)
    broken = tmp_path / "broken.json"
    broken.write_text(text.replace('"rates"', '"no_rates"'))
    with pytest.raises(ModelFileError, match="'rates' must be a list of numbers"):
        load_model(broken)
    doc = json.loads(text)
    doc["rates"][0] = -1.0
    broken.write_text(json.dumps(doc))
    with pytest.raises(ModelFileError, match="rates: expected finite positive"):
        load_model(broken)


def test_options_are_checked():
    with pytest.raises(ValueError, match="n_operators must be a positive integer"):
        MultiDuhemStructure(n_operators=0)
    with pytest.raises(ValueError, match="rates: expected 3 values"):
        MultiDuhemSandwich(rich_model().params, [1.0, 2.0, 3.0, 4.0], RICH)
    with pytest.raises(ValueError, match="rates: expected finite positive"):
        MultiDuhemSandwich(rich_model().params, [1.0, 0.0, 3.0], RICH)
    with pytest.raises(TypeError, match="takes the state p0"):
        rich_model().simulate(np.zeros(5), w2=[0.0])
    with pytest.raises(ValueError, match="p0: expected 3 finite"):
        rich_model().simulate(np.zeros(5), p0=[0.0])
    with pytest.raises(ValueError, match="n_operators: expected a positive integer"):
        rate_grid(_input(), 0)
    with pytest.raises(ValueError, match="slew_limit: expected a positive number"):
        rate_grid(_input(), 3, slew_limit=0.0)
    rec = Record(_input(), _input() ** 2, FS)
    with pytest.raises(ValueError, match="method: the mduhem member is identified by 'batch'"):
        identify(rec, model="mduhem", method="online")
    with pytest.raises(ValueError, match="rates: expected 6 positive rates"):
        identify(rec, model="mduhem", rates=[1.0])
    with pytest.raises(ValueError, match=r"100 samples are too few .*\(expected at least 180"):
        identify(rec[:100], model="mduhem")


def test_compensation_has_an_inverse_the_c_export_writes_it():
    from hystid.compensate import compensate
    from hystid.export.c import c_sources

    model = rich_model()
    y = model.simulate(_input(300), check=False).y
    # the operators' own inverse (tests/test_compensate_members.py), without look-ahead
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        assert np.all(np.isfinite(compensate(model, y, u_limits=(-1.0, 3.0)).u))
    with pytest.raises(ValueError, match="preview: the multi-Duhem sandwich .* without "
                                         "look-ahead"):
        compensate(model, y, u_limits=(-1.0, 3.0), preview=30)
    # the C export writes the model's step and this inverse (tests/test_export.py runs them
    # against Python), not an on-line identifier
    texts = c_sources(model, compensator={"u_limits": (-1.0, 3.0)})
    head = texts["hystid_model.h"]
    assert "#define HYSTID_KIND_MDUHEM 1" in head and "hx_md_inverse_step" in texts[
        "hystid_model.c"]
    assert "HYSTID_NO_FF" not in head and "#define HYSTID_NO_RPEM 1" in head


def test_rate_grid_and_condition_8():
    u = _input(3000, seed=7)
    r = rate_grid(u, 5)
    assert np.all(np.diff(r) > 0)
    assert r[-1] * Envelope.of(u).slew <= RATE_SLEW * (1 + 1e-12)  # condition 8 with margin
    np.testing.assert_allclose(rate_grid(1e3 * u - 300.0, 5), r / 1e3, rtol=1e-9)  # mV, offset
    model = rich_model()
    model.envelope = Envelope.of(u)
    assert model.admissibility(u) == []
    dw1 = np.max(np.abs(np.diff(model.simulate(u, check=False).w1)))
    fast = MultiDuhemSandwich(model.params, [0.2, 1.1, 2.5 / dw1], RICH, fs=FS)
    with pytest.warns(AdmissibilityWarning, match=r"condition \(8\) fails"):
        fast.simulate(u)
    assert fast.envelope_bound(Envelope.of(u)) > 2.0 > model.envelope_bound(Envelope.of(u))


# --------------------------------------------------------------------------- the member
def _record(stage, seed: int, seconds: float, *, millivolts: bool = True) -> Record:
    u = paper_excitation(seconds, FS, seed=seed, frequency=(150.0, 15.0), ramp_seconds=0.05)
    y = stage.simulate(u, u_rest=0.0)["y"]
    y = y + 2.0 + np.random.default_rng(seed + 100).normal(scale=1e-3, size=len(y))
    if millivolts:
        return Record(1000.0 * u - 300.0, y, FS, units={"u": "mV", "y": "um"},
                      name=f"Maxwell-slip stage #{seed}")
    return Record(u, y, FS, units={"u": "V", "y": "um"}, name=f"Maxwell-slip stage #{seed}")


@pytest.fixture(scope="module")
def maxwell_stage():
    """The paper-like stage at 10 kHz with a Maxwell-slip block (no Duhem operator in it),
    input in mV with an offset, a sensor offset and noise."""
    stage = paper_like_stage(fs=FS, hysteresis="maxwell")
    return stage, _record(stage, 10, 1.0), [_record(stage, 11, 0.5), _record(stage, 12, 0.5)]


def test_member_beats_the_duhem_member_and_the_baselines(maxwell_stage):
    """When written: held out 51.2 / 50.9 nm against the Duhem member's 59.8 / 60.4 nm, the
    linear model's 95 / 88 nm and the static line's 292 / 294 nm (benchmarks in the report)."""
    _, train, held = maxwell_stage
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        md = identify(train, model="mduhem")
        duhem = identify(train, model="duhem")
        rows_md = compare(md.model, train, held).rows
        rows_d = compare(duhem.model, train, held).rows
    assert isinstance(md.model, MultiDuhemSandwich)
    assert md.model.structure == MEMBERS["mduhem"].structure
    assert md.model.units == train.units and md.model.envelope is not None
    assert md.model.u_rest == pytest.approx(train.u[0])
    for mine, plain in zip(rows_md, rows_d, strict=True):
        assert mine["model"] < 0.95 * plain["model"], (mine, plain)
        assert mine["model"] < 0.7 * min(mine["linear"], mine["static_line"]), mine
    assert md.info["envelope_bound"] < 2.0 and not md.info["warnings"]


def test_member_does_not_depend_on_the_units(maxwell_stage):
    stage, train, held = maxwell_stage
    volts = _record(stage, 10, 1.0, millivolts=False)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        mv = fit_mduhem_output_error(train)
        v = fit_mduhem_output_error(volts)
    np.testing.assert_allclose(mv.model.rates * 1e3, v.model.rates, rtol=1e-9)
    y_mv = mv.model.simulate(held[0].u, check=False).y
    y_v = v.model.simulate((held[0].u + 300.0) / 1000.0, check=False).y
    assert np.max(np.abs(y_mv - y_v)) < 1e-6 * np.ptp(y_v)


def test_fit_recovers_a_multi_duhem_stage_to_its_noise():
    """Data from a known model with its rates given: the default starts reach the noise, and a
    start at the answer stays there."""
    model = rich_model(u_rest=0.3, offset=-0.2)
    noise = 1e-4

    def rec(seed: int, n: int) -> Record:
        u = 0.3 + _input(n, seed)
        y = model.simulate(u, check=False).y
        return Record(u, y + np.random.default_rng(seed).normal(scale=noise, size=n), FS)

    train, held = rec(20, 6000), rec(21, 3000)
    fit = fit_mduhem_output_error(train, RICH, rates=RATES)
    assert fit.info["rms_residual"] < 1.1 * noise
    e = fit.model.simulate(held.u, check=False).y - model.simulate(held.u, check=False).y
    # within the noise; not much less: the slowest operator (0.4 of its state forgotten per
    # sweep of this input, below the grid's rule) keeps a near-constant the offset trades with
    assert np.sqrt(np.mean(e ** 2)) < noise
    assert np.sqrt(np.mean(e[len(e) // 2:] ** 2)) < 0.3 * noise
    warm = fit_mduhem_output_error(train, RICH, rates=RATES, theta0=model.theta)
    assert warm.info["start"] == "theta0" and warm.info["rms_residual"] < 1.1 * noise
    with pytest.raises(ValueError, match="theta0: expected 13 values"):
        fit_mduhem_output_error(train, RICH, rates=RATES, theta0=model.theta[:3])
