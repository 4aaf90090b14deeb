"""The PI sandwich at rest on a branch of its loop (``PISandwich.rest_swing``; issue 21: records
that do not start at the loop's centre).

The state is checked against the virgin model driven through the swing itself, its
sensitivities against central differences, the file and the python-control round trips against
the model; the fit on records of :mod:`hystid.testing`'s stage-A look-alike (Bouc-Wen hysteresis,
a 740 Hz mode: not the model's form) swung up or down before their rest, against the same fit
from the virgin state and both baselines, and on records that are not swung (nothing is
changed there).
"""

import json
import warnings

import numpy as np
import pytest

import hystid
from hystid.baselines import compare
from hystid.identify import identify
from hystid.identify.pi_kernels import pi_output_sensitivities
from hystid.pi import PISandwich, PIStructure, pi_thresholds, rest_plays
from hystid.testing import stage_a_like

N = 10


def _model(swing: float = 0.0, **kw) -> PISandwich:
    params = {"a11": -0.6, "a12": 0.05, "b12": 0.1, "a21": -1.2, "a22": 0.4, "b22": 0.05,
              **{f"mu{i}": 0.4 / (1 + i) for i in range(N)}}
    return PISandwich(params, pi_thresholds((-8.0, 8.0), N), PIStructure(n_operators=N),
                      fs=1_000.0, rest_swing=swing, **kw)


def _record_input(n: int = 1_500, seed: int = 0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    t = np.arange(n) / 1_000.0
    return 5.0 * np.sin(2 * np.pi * 3 * t + rng.uniform(0, 6)) * (1 - np.exp(-t / 0.05)) \
        + 0.5 * rng.standard_normal(n).cumsum() / np.sqrt(n)


@pytest.mark.parametrize("swing", [4.0, -3.0, 20.0])
def test_rest_swing_is_the_state_the_swing_itself_leaves(swing):
    """The virgin model driven up to ``swing`` (held there), back to its rest and held until L1
    and L2 settle, then the record, gives the swung model's response to the record alone."""
    virgin, swung = _model(), _model(swing)
    ramp = np.linspace(0.0, swing, 400)
    before = np.r_[ramp, np.full(300, swing), ramp[::-1], np.zeros(600)]
    u = _record_input()
    y_virgin = virgin.simulate(np.r_[before, u], check=False).y[len(before):]
    y_swung = swung.simulate(u, check=False).y
    assert np.max(np.abs(y_swung - y_virgin)) < 1e-9 * np.ptp(y_virgin)
    assert np.max(np.abs(y_swung - virgin.simulate(u, check=False).y)) > 0.02 * np.ptp(y_virgin)
    assert np.allclose(swung.rest_plays, rest_plays(swing, swung.thresholds))


def test_sensitivities_with_a_swing_match_central_differences():
    model = _model(4.0)
    u = _record_input(800)
    _, J = pi_output_sensitivities(model, u)
    for i, name in enumerate(model.structure.names):
        h = 1e-6 * max(1.0, abs(model.theta[i]))
        up, down = model.theta.copy(), model.theta.copy()
        up[i] += h
        down[i] -= h
        diff = (PISandwich(up, model.thresholds, model.structure, fs=model.fs, rest_swing=4.0)
                .simulate(u, check=False).y
                - PISandwich(down, model.thresholds, model.structure, fs=model.fs,
                             rest_swing=4.0).simulate(u, check=False).y) / (2 * h)
        assert np.allclose(J[:, i], diff, rtol=1e-5, atol=1e-7 * np.max(np.abs(J))), name


def test_the_swing_survives_the_model_file_and_python_control(tmp_path):
    model = _model(-3.0, u_rest=2.0, offset=0.5)
    u = 2.0 + _record_input()
    path = tmp_path / "model.json"
    hystid.save_model(model, path)
    back = hystid.load_model(path)
    assert back.rest_swing == -3.0
    assert np.array_equal(back.simulate(u, check=False).y, model.simulate(u, check=False).y)
    again = PISandwich.from_control(model.to_control())
    assert again.rest_swing == -3.0
    assert np.allclose(again.simulate(u, check=False).y, model.simulate(u, check=False).y,
                       rtol=0, atol=1e-12)


def _fit(kind: str, swing: float, **kw):
    records = {"seconds": 1.0, "swing_before": swing}
    train = stage_a_like(kind, seed=1, **records)
    held = [stage_a_like(k, seed=2, repeat=1, **records) for k in ("prbn", "sine50", "tri50")]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        res = identify(train, model="pi-stage", **kw)
        rows = compare(res.model, train, held).rows
    return res, np.array([[r["model"], r["linear"], r["static_line"]] for r in rows])


@pytest.mark.parametrize("kind,swing", [("prbn", 0.9), ("prbn", -0.9), ("sine50", 0.9)])
def test_the_fit_finds_the_swing_a_record_rests_after(kind, swing):
    """Measured (nm, held out PRBN / sine / triangle): PRBN swung up, from the virgin state 256 /
    286 / 272 (the linear model 261 / 283 / 278), with the swing 33 / 84 / 77; swung down 259
    / 269 / 272 and 38 / 87 / 77; a sine swung up 304 / 255 / 274 and 281 / 22 / 103."""
    virgin, before = _fit(kind, swing, rest_swing=False)
    res, after = _fit(kind, swing)
    assert np.sign(res.model.rest_swing) == np.sign(swing)
    assert res.info["rest_swing_scan"]["kept"]
    assert np.mean(after[:, 0]) < 0.6 * np.mean(before[:, 0]), (after[:, 0], before[:, 0])
    assert np.all(after[:, 0] < np.minimum(after[:, 1], after[:, 2])), after
    assert virgin.model.rest_swing == 0.0


@pytest.mark.parametrize("kind", ["prbn", "tri50"])
def test_a_record_at_the_loop_centre_keeps_the_virgin_fit(kind):
    virgin, before = _fit(kind, 0.0, rest_swing=False)
    res, after = _fit(kind, 0.0)
    assert res.model.rest_swing == 0.0 and not res.info["rest_swing_scan"]["kept"]
    assert np.array_equal(after, before)


def test_a_swing_at_an_end_of_the_input_range_is_not_kept():
    """A swing the scan can only place at an end of the input's range is not determined by the
    record: on the helper's stage s3 (resting at 2.5 V in a 0.7-9.5 V range) the fit took the
    range's end, -1.8 V, and a held-out record resting at 0 V went from 0.23 to 0.57 um. Here a
    model swung 3x past the record's range: the best swing is the range's end, and it is left
    out; inside the range the same scan finds the swing."""
    from hystid.identify.pi_rest_swing import place_rest_swing

    u = 0.3 * _record_input(2_000)  # about +-1.6 around the rest
    scored = np.ones(len(u), bool)
    for swing, kept in ((3.0 * np.max(np.abs(u)), False), (0.8 * np.max(u), True)):
        y = _model(swing).simulate(u, check=False).y
        model = _model()
        placed = place_rest_swing(model, u, y, scored)
        assert (placed is not None) == kept, (swing, placed)
        assert model.rest_swing == (pytest.approx(swing, rel=0.1) if kept else 0.0)


def test_identify_says_the_swing(tmp_path, capsys):
    from hystid.cli import main

    records = {"seconds": 1.0, "swing_before": 0.9}
    stage_a_like("prbn", seed=1, **records).save(tmp_path / "train.csv")
    stage_a_like("tri50", seed=2, repeat=1, **records).save(tmp_path / "val.csv")
    args = ["identify", str(tmp_path / "train.csv"), "--val", str(tmp_path / "val.csv"),
            "--model", "pi-stage"]
    assert main([*args, "--out", str(tmp_path / "out")]) == 0
    out = capsys.readouterr().out
    line = next(x for x in out.splitlines() if x.startswith("rest_swing [V]"))
    assert float(line.split()[-1]) > 20.0  # swung up by 78 V
    report = json.loads((tmp_path / "out" / "report.json").read_text())
    assert report["rest_swing"] > 20.0 and report["units"]["rest_swing"] == "V"
    assert hystid.load_model(tmp_path / "out" / "model.json").rest_swing == report["rest_swing"]


def test_default_online_holds_the_batch_choice_swing():
    """``identify(..., method="online")`` (``model="auto"``) runs the batch choice's member
    on-line, and hands a PI choice's swing to the on-line ``pi-stage`` identifier
    (``_held_state``). Measured on the look-alike's sine swung down (nm, held out PRBN / sine /
    triangle): ``pi-stage`` batch 265 / 26 / 103; on-line from the virgin state 824 / 60 / 256
    (2.2-3.1x, before), holding the swing 229 / 25 / 125 (0.86-1.22x). The choice, on a block
    held out in the middle of the record, now takes the Duhem sandwich there (20.8 against
    21.1 nm on the block; 127 / 20 / 78 nm on the held-out records); its on-line identifier is
    1.27x and 1.36x the batch fit on the PRBN and sine records, above the 1.25x goal (the
    on-line ``pi-stage`` identifier holding the swing is within it)."""
    from hystid.identify import _held_state
    from hystid.identify.members import member

    records = {"seconds": 1.0, "swing_before": -0.9}
    train = stage_a_like("sine50", seed=1, **records)
    held = [stage_a_like(k, seed=2, repeat=1, **records) for k in ("prbn", "sine50", "tri50")]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        batch = identify(train)
        online = identify(train, method="online")
        pi_batch = member("pi-stage").fit(train)
        pi_online = member("pi-stage").fit(train, "online", **_held_state(pi_batch.model))
    assert batch.info["model"] == online.info["model"]
    assert pi_batch.model.rest_swing < 0 and pi_online.model.rest_swing < 0
    assert pi_online.settings["rest_swing"] == pi_batch.model.rest_swing
    for b, o, most in ((batch, online, 1.5), (pi_batch, pi_online, 1.25)):
        for rb, ro in zip(compare(b.model, train, held).rows, compare(o.model, train, held).rows,
                          strict=True):
            assert ro["model"] <= most * rb["model"], (ro, rb)
            assert ro["model"] < min(ro["linear"], ro["static_line"]), ro


@pytest.mark.parametrize("swing", [True, float("nan"), "up"])
def test_the_online_identifier_refuses_a_swing_that_is_not_a_number(swing):
    from hystid.identify.pi_online import PIStageOnline

    with pytest.raises(ValueError, match="rest_swing: expected None .estimated. or a finite swing"):
        PIStageOnline(np.linspace(0.0, 10.0, 5), rest_swing=swing)


def test_the_batch_fit_holds_a_swing_it_is_given():
    """``rest_swing`` a number: the fit is solved with the plays where that swing left them and
    the swing is kept as given (no scan). Measured on the up-swung PRBN record (nm, held out
    PRBN / sine / triangle): virgin 256 / 286 / 272, the swing found (54.2 V) 33 / 84 / 77,
    40 V held 39 / 101 / 80."""
    from hystid.testing import crop_start

    virgin, before = _fit("prbn", 0.9, rest_swing=False)
    res, after = _fit("prbn", 0.9, rest_swing=40.0)
    assert res.model.rest_swing == 40.0 and res.info["rest_swing_scan"] is None
    assert np.mean(after[:, 0]) < 0.6 * np.mean(before[:, 0]), (after[:, 0], before[:, 0])
    assert np.all(after[:, 0] < np.minimum(after[:, 1], after[:, 2])), after
    moving = crop_start(stage_a_like("prbn", seed=1, seconds=1.0, swing_before=0.9), 1.2)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        res = identify(moving, model="pi-stage", rest_swing=40.0)
    assert res.model.rest_swing == 0.0
    assert any("begins in motion" in w for w in res.info["warnings"])
    for bad in ("yes", float("inf")):
        with pytest.raises(ValueError, match="rest_swing: expected True"):
            identify(moving, model="pi-stage", rest_swing=bad)


@pytest.mark.parametrize("kind,swing", [("prbn", 0.9), ("prbn", -0.9), ("tri50", 0.9)])
def test_the_online_identifier_estimates_the_swing_when_the_window_fills(kind, swing):
    """``PIStageOnline(rest_swing=None)`` (the default) estimates the swing once, when its two
    starts are chosen between, as the batch fit does (the output relative to its value at rest,
    as the recursion predicts it). Measured (nm, held out PRBN / sine / triangle; virgin ->
    estimated, the batch fit): swung-up PRBN 325 / 524 / 471 -> 55 / 117 / 121 (58.5 V), 33 /
    84 / 77; swung-down PRBN 103 / 100 / 100 -> 43 / 82 / 78 (-35.6 V), 38 / 88 / 77; swung-up
    triangle 308 / 282 / 254 -> 128 / 69 / 24 (25.9 V), 99 / 25 / 21. With an offset fitted
    beside the weights in the scan (not the recursion's model), the swung-up PRBN kept no
    swing: 325 / 524 / 471."""
    _, virgin = _fit(kind, swing, method="online", rest_swing=0.0)
    _, batch = _fit(kind, swing)
    res, found = _fit(kind, swing, method="online")
    scan = res.info["swing_scan"]
    assert scan["kept"] and np.sign(scan["swing"]) == np.sign(swing)
    assert np.sign(res.model.rest_swing) == np.sign(swing)
    v, b, f = (np.mean(x[:, 0]) for x in (virgin, batch, found))
    assert f < v - 0.75 * (v - b), (found[:, 0], virgin[:, 0], batch[:, 0])  # 3/4 of the gap
    assert np.all(found[:, 0] < np.minimum(found[:, 1], found[:, 2])), found


def test_the_online_identifier_keeps_no_swing_on_measured_stage_a():
    """Measured stage A rests at the loop's centre as far as its records tell: the batch fit
    keeps no swing on any of its six records, and the on-line estimate none either (the best
    swing lowers the residual by under 1 %). A swing estimated from the 0.2 s warm-up alone
    was kept on ``prbn_1``."""
    from pathlib import Path

    from hystid.records import load_record

    path = Path(__file__).resolve().parents[2] / "shared/data/real/stageA/prbn_1.csv"
    if not path.exists():
        pytest.skip(f"{path} is absent (measured stage A in ../shared/data)")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        res = identify(load_record(path), model="pi-stage", method="online")
    scan = res.info["swing_scan"]
    assert scan is not None and not scan["kept"], scan
    assert scan["rms"] > 0.95 * scan["rms_virgin"], scan
    assert res.model.rest_swing == 0.0


def test_the_online_swing_estimate_on_hostile_records():
    """The on-line estimate of the swing on the swung-down PRBN record in other units (mV, nm)
    with five outliers: found with the real swing's sign, in the record's units (about
    -35 600 mV, the volts' -35.6 V), and the model below both baselines held out: measured 43
    / 82 / 78 nm against the linear model's 262 / 285 / 278 and the static line's 333 / 324 /
    340, as in V and um without the outliers. On the same record begun in motion there is no
    rest to swing from: no swing, no scan."""
    from hystid.testing import crop_start, with_outliers, with_units

    def hostile(rec):
        return with_units(rec, u="mV", y="nm")

    records = {"seconds": 1.0, "swing_before": -0.9}
    train = with_outliers(hostile(stage_a_like("prbn", seed=1, **records)), count=5,
                          size=2.0, seed=3)
    held = [hostile(stage_a_like(k, seed=2, repeat=1, **records))
            for k in ("prbn", "sine50", "tri50")]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        res = identify(train, model="pi-stage", method="online")
        rows = compare(res.model, train, held).rows
        moving = identify(crop_start(train, 1.2), model="pi-stage", method="online")
    scan = res.info["swing_scan"]
    assert scan["kept"] and -60_000 < scan["swing"] < -20_000, scan
    assert -60_000 < res.model.rest_swing < -20_000
    for r in rows:
        assert r["model"] < min(r["linear"], r["static_line"]), r
    assert moving.info["swing_scan"] is None and moving.model.rest_swing == 0.0
