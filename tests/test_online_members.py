"""On-line identification of the ``pi-stage`` member against its batch fit (issue 21, item 3)."""

import warnings
from pathlib import Path

import numpy as np
import pytest

from hystid.baselines import compare, simulate_from_rest
from hystid.identify import identify
from hystid.identify.members import member
from hystid.identify.pi_online import (
    _STATE_ROWS,
    PIStageOnline,
    _run,
    is_stage_structure,
    stage_from_theta,
    theta_from_stage,
)
from hystid.pi import PISandwich
from hystid.records import Record, load_record
from hystid.testing import stage_a_like

STAGE = member("pi-stage").structure
STAGE_A = Path(__file__).resolve().parents[2] / "shared" / "data" / "real" / "stageA"
#: Issue 21's goal: the on-line model within this factor of the batch fit's held-out RMS.
RATIO = 1.25


def _heldout(method: str, train: Record, held: list[Record], **settings) -> np.ndarray:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        res = identify(train, model="pi-stage", method=method, **settings)
        rows = compare(res.model, train, held).rows
    return np.array([r["model"] for r in rows])


def _admissible(model: PISandwich) -> bool:
    return model.is_stable() and np.all(np.cumsum(model.mu) > 0)


def test_stage_coordinates_round_trip_and_predict_as_the_sandwich():
    rng = np.random.default_rng(3)
    phi = np.r_[rng.uniform(0.01, 0.1, 20), 0.4, np.arctanh(0.9995), 1.2, 2.0, -0.3]
    theta = theta_from_stage(phi, 20)
    np.testing.assert_allclose(stage_from_theta(theta, 20), phi, rtol=1e-6, atol=1e-9)
    rows = np.vstack([phi, phi * 1.1, phi * 0.9])  # a row per sample, as the history takes it
    assert np.array_equal(theta_from_stage(rows, 20),
                          np.vstack([theta_from_stage(row, 20) for row in rows]))
    r = np.arange(20) / 20 * 1.5
    model = PISandwich(theta, r, STAGE)
    assert model.is_stable() and is_stage_structure(STAGE)
    u = np.cumsum(rng.normal(0, 0.05, 3000))
    st = np.zeros((_STATE_ROWS, 20))
    yhat, err = np.empty(len(u)), np.empty(len(u))
    _run(phi, np.eye(25), 1.0, 1.0, 1.0, r, 0, u, np.zeros(len(u)), st, False,
         np.zeros((0, 25)), yhat, err, np.zeros((0, 25)), 0)
    y = model.simulate(u).y
    np.testing.assert_allclose(yhat, y, atol=1e-9 * np.max(np.abs(y)))


def test_update_sample_by_sample_is_fit():
    rec = stage_a_like("prbn", seconds=0.25, rest_seconds=0.05, seed=2)
    u = rec.u - rec.u[0]
    r = np.arange(20) / 20 * 0.5 * np.ptp(u[:-1])
    est = PIStageOnline(r, STAGE, warmup=600, window=1000, every=250, fs=rec.fs)
    res = est.fit(Record(u, rec.y - rec.y[0], rec.fs))
    one = PIStageOnline(r, STAGE, warmup=600, window=1000, every=250, fs=rec.fs)
    steps = np.array([one.update(float(a), float(b))
                      for a, b in zip(u, rec.y - rec.y[0], strict=True)])
    np.testing.assert_allclose(steps[-1], res.model.theta, rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(steps, res.history, rtol=1e-9, atol=1e-12)
    assert one.k == rec.n and one.n_resolves == est.n_resolves > 0
    assert res.info["excited_at"] == est.excited_at > 0


def test_the_resolve_rate_bounds_the_work_of_each_update_and_changes_no_estimate():
    """The re-solve runs in steps beside the recursion (hystid.identify.horizon): each
    ``update()`` does at most ``resolve_rate`` simulated samples of its work and one step more,
    except at a chunk boundary where a re-solve not yet solved is finished; the estimates are the
    same whatever the rate."""
    from hystid.identify.horizon import SLICE, TRIAL

    rec = stage_a_like("prbn", seconds=0.25, rest_seconds=0.05, seed=2)
    u, y = rec.u - rec.u[0], rec.y - rec.y[0]
    r = np.arange(20) / 20 * 0.5 * np.ptp(u[:-1])
    settings = dict(warmup=600, window=1000, every=250, fs=rec.fs)
    ref = PIStageOnline(r, STAGE, resolve_rate=np.inf, **settings).fit(Record(u, y, rec.fs))
    slow = PIStageOnline(r, STAGE, resolve_rate=20.0, **settings)
    work, steps, boundary = [], [], []
    for a, b in zip(u, y, strict=True):
        before, resolves = slow.resolve_work_, slow.n_resolves
        steps.append(slow.update(float(a), float(b)))
        work.append(slow.resolve_work_ - before)
        boundary.append(slow.n_resolves - resolves)  # re-solves that took over in this call
    assert np.array_equal(np.array(steps), ref.history)
    work, boundary = np.array(work), np.array(boundary)
    # the call that chooses between the two starts finishes the re-solve launched at its
    # chunk boundary and runs one more (pi_online_horizon.CHOICE_ITERATIONS): three take over
    # in it
    assert boundary.sum() == ref.info["resolves"] > 3 and boundary.max() <= 3
    boundary = boundary > 0
    within = work[~boundary & (np.arange(len(u)) > np.flatnonzero(boundary)[0])]
    assert within.max() <= 20.0 + max(SLICE, TRIAL) + 1
    assert np.mean(within) == pytest.approx(20.0, rel=0.5)  # the rate is used, on average
    # a rate of 20 is too slow for these re-solves: the boundaries finish them
    assert work[boundary].max() > 1000
    with pytest.raises(ValueError, match="resolve_rate"):
        PIStageOnline(r, STAGE, resolve_rate=0.0)


def test_a_copy_or_a_pickle_taken_mid_record_goes_on_as_the_original():
    """The running re-solve is a generator, which neither copy nor pickle can take: it is run
    to its solution first, which changes no estimate."""
    import copy
    import pickle

    rec = stage_a_like("prbn", seconds=0.25, rest_seconds=0.05, seed=2)
    u, y = rec.u - rec.u[0], rec.y - rec.y[0]
    r = np.arange(20) / 20 * 0.5 * np.ptp(u[:-1])
    settings = dict(warmup=600, window=1000, every=250, fs=rec.fs, resolve_rate=20.0)
    ref = PIStageOnline(r, STAGE, **settings).fit(Record(u, y, rec.fs))
    est = PIStageOnline(r, STAGE, **settings)
    first, k = [], 0
    while k < 1500 or est._job is None or est._job.solved:  # on to a re-solve running
        first.append(est.update(float(u[k]), float(y[k])))
        k += 1
    twins = [copy.deepcopy(est), pickle.loads(pickle.dumps(est))]
    for one in [est, *twins]:
        rest = [one.update(float(a), float(b)) for a, b in zip(u[k:], y[k:], strict=True)]
        assert np.array_equal(np.array(first + rest), ref.history)


def test_used_directly_it_takes_the_sensor_offset_off_itself():
    """On a record as measured (a rest level, a sensor offset), the identifier used directly:
    the offset was left in and the fit was 0.5-0.64 um off stage A's records (25-31 nm with
    the rest output taken off by hand). Here on the Bouc-Wen look-alike moved 13 V / 2 um."""
    from hystid.identify.members import short_record_warmup

    train = stage_a_like("prbn", seconds=1.0, seed=0)
    held = [stage_a_like(k, seconds=1.0, seed=1) for k in ("prbn", "sine50", "tri50")]
    r = member("pi-stage").online_estimator(train).thresholds
    warm = short_record_warmup(train.u, 25)
    moved = Record(train.u + 13.0, train.y + 2.0, train.fs)
    start = int(np.flatnonzero(train.u != train.u[0])[0])  # the excitation's first sample
    y_rest = float(np.median(train.y[start - 200:start]))  # the rest the identifier keeps
    rel = Record(train.u - train.u[0], train.y - y_rest, train.fs)
    fits = {}
    for label, rec, offset in (("moved", moved, None), ("relative", rel, 0.0)):
        est = PIStageOnline(r, STAGE, warmup=warm, settle_at_end=True, offset=offset,
                            fs=train.fs)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            fits[label] = est.fit(rec).model
    assert fits["moved"].offset == pytest.approx(2.0 + y_rest, abs=1e-4)
    assert fits["moved"].u_rest == pytest.approx(13.0 + train.u[0])
    shifted = [Record(h.u + 13.0, h.y + 2.0, h.fs) for h in held]
    a = compare(fits["moved"], moved, shifted).rows
    b = compare(fits["relative"], rel, [Record(h.u - train.u[0], h.y, h.fs) for h in held]).rows
    for ra, rb in zip(a, b, strict=True):
        assert ra["model"] == pytest.approx(rb["model"], rel=0.05)
        assert ra["model"] < 0.7 * min(ra["static_line"], ra["linear"]), ra
    with pytest.raises(ValueError, match="offset"):
        PIStageOnline(r, STAGE, offset=np.nan)


def test_settings_are_checked():
    r = np.arange(20) / 20.0
    with pytest.raises(ValueError, match="structure"):
        PIStageOnline(r, member("pi").structure)
    with pytest.raises(ValueError, match="every"):
        PIStageOnline(r, STAGE, window=100, every=200)
    with pytest.raises(ValueError, match="too few"):
        PIStageOnline(r, STAGE, warmup=500).fit(Record(np.r_[np.zeros(100), np.ones(100)],
                                                       np.zeros(200), 10_000.0))


def test_online_is_within_the_goal_of_batch_on_the_look_alike():
    """Trained on a 1 s PRBN record of the Bouc-Wen look-alike of stage A, held out on others."""
    train = stage_a_like("prbn", seconds=1.0, seed=0)
    held = [stage_a_like(kind, seconds=1.0, seed=1) for kind in ("prbn", "sine50", "tri50")]
    batch, online = _heldout("batch", train, held), _heldout("online", train, held)
    assert np.all(np.isfinite(online))
    assert np.max(online / batch) <= RATIO, (online, batch)
    # a window of 0.3 s, shorter than the excitation: the arrival cost carries the rest
    short = _heldout("online", train, held, window=3000)
    assert np.max(short / batch) <= RATIO, (short, batch)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        model = identify(train, model="pi-stage", method="online").model
        rows = compare(model, train, held).rows
    assert _admissible(model)
    # and it beats a static line and a linear model on every held-out record (measured 31 / 56
    # / 63 nm against linear 58 / 124 / 112 nm and static 192-221 nm)
    for r in rows:
        assert r["model"] < 0.7 * min(r["static_line"], r["linear"]), r
    big = stage_a_like("large_sine", seconds=1.0, seed=1)  # beyond the training envelope
    y = simulate_from_rest(model, big.u, check=False)
    assert np.all(np.isfinite(y)) and np.max(np.abs(y)) < 10 * np.ptp(big.y)


@pytest.mark.skipif(not STAGE_A.exists(), reason=f"measured stage A records absent ({STAGE_A})")
def test_online_is_within_the_goal_of_batch_on_stage_a():
    """Issue 21's goal on the measured stage A: trained on prbn_1, the five others held out."""
    names = [f"{i}_{k}" for i in ("prbn", "sine50", "tri50") for k in (1, 2)]
    recs = {n: load_record(STAGE_A / f"{n}.csv") for n in names}
    train, held = recs["prbn_1"], [r for n, r in recs.items() if n != "prbn_1"]
    batch, online = _heldout("batch", train, held), _heldout("online", train, held)
    assert np.all(np.isfinite(online))
    assert np.max(online / batch) <= RATIO, (online, batch)


def test_branch_gradients_are_the_derivatives_of_the_prediction():
    rng = np.random.default_rng(4)
    phi = np.r_[rng.uniform(0.01, 0.1, 20), 0.4, np.arctanh(0.999), 1.2, 2.0, -0.3]
    r = np.arange(20) / 20 * 1.5
    u = np.cumsum(rng.normal(0, 0.05, 2000))

    def run(p):
        J, yhat, err = np.empty((len(u), 25)), np.empty(len(u)), np.empty(len(u))
        _run(p, np.eye(25), 1.0, 1.0, 1.0, r, 0, u, np.zeros(len(u)),
             np.zeros((_STATE_ROWS, 20)), False, J, yhat, err, np.zeros((0, 25)), 0)
        return yhat, J

    _, J = run(phi)
    for j in (0, 7, 20, 21, 22, 23, 24):
        h = 1e-6 * max(1.0, abs(phi[j]))
        fd = (run(phi + h * np.eye(25)[j])[0] - run(phi - h * np.eye(25)[j])[0]) / (2 * h)
        np.testing.assert_allclose(J[:, j], fd, rtol=1e-5, atol=1e-7 * np.max(np.abs(fd)))


def test_auto_online_runs_the_member_the_batch_fit_chooses_on_line():
    """``model="auto", method="online"``: the member the batch default chooses, identified
    on-line over the whole record: the Duhem member on the paper's (Duhem) stage; on the
    Bouc-Wen look-alike of stage A, within the on-line goal of the batch choice."""
    from hystid.reference import reference_record

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        paper = identify(reference_record(0.3, seed=0), model="auto", method="online")
        train = stage_a_like("prbn", seconds=1.0, seed=0)
        held = [stage_a_like(kind, seconds=1.0, seed=1) for kind in ("sine50", "tri50")]
        online = identify(train, model="auto", method="online")
        batch = identify(train, model="auto")
    assert (paper.info["model"], paper.method) == ("duhem", "online")
    assert online.method != "batch" and online.info["model"] in ("duhem", "pi-stage")
    assert online.info["member_selection"]["on_samples"] == train.n
    assert online.info["model"] == batch.info["model"]
    rms_online = np.array([r["model"] for r in compare(online.model, train, held).rows])
    rms_batch = np.array([r["model"] for r in compare(batch.model, train, held).rows])
    assert np.max(rms_online / rms_batch) <= RATIO, (rms_online, rms_batch)


def test_a_window_shorter_than_the_default_chunk_takes_the_window_as_its_chunk():
    r = np.arange(20) / 20.0
    est = PIStageOnline(r, STAGE, window=1000)
    assert est.get_params()["every"] is None and est.settings["every"] is None
    assert est._every == 1000  # a re-solve at every window's end
    assert PIStageOnline(r, STAGE)._every == 2000
    with pytest.raises(ValueError, match=r"every: expected at most window \(1000\), got 1500"):
        PIStageOnline(r, STAGE, window=1000, every=1500)


def test_auto_online_carries_the_warning_that_the_record_does_not_determine_the_model():
    """The Bouc-Wen look-alike of stage A driven by a 50 Hz sine (seed 2): the choice keeps a
    candidate that a plausible other differs from, on an input with reversals of every size,
    by many times their held-out errors (20.6x when this was written); the on-line result says
    it as the batch choice does."""
    rec = stage_a_like("sine50", seconds=1.0, seed=2)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        result = identify(rec, method="online")
    note = result.info["member_selection"]["undetermined"]
    assert note is not None and "does not determine the model" in note
    assert note in result.info["warnings"]
