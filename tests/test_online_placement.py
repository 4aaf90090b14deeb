"""On-line fits placed like the batch fit: the offset and the Duhem state at rest fitted after
the run, and the ``pi-stage`` identifier on short, slow records that do not start at rest
(issue 21, item 3: within 1.25x the batch fit, placed as it places).

The records come from :mod:`hystid.testing`'s independent simulators: the paper's stage brought
to a held level before its record (the stage then sits on one branch of its loop), and a
stage-B look-alike (Preisach hysteresis, 200 Hz, a 1 Hz sine started mid-swing, a -111 um
sensor offset), not from the model the identifiers fit.
"""

import copy
import warnings
from pathlib import Path

import numpy as np
import pytest

from hystid.baselines import compare
from hystid.identify import identify, place_after_run
from hystid.identify.members import WARMUP, member, short_record_warmup
from hystid.identify.prepare import prepare
from hystid.records import load_record
from hystid.testing import as_measured_suite, stage_a_like, stage_b_like

#: Issue 21's goal: the on-line model within this factor of the batch fit's held-out RMS.
RATIO = 1.25


def _fit(train, held, **kw):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        res = identify(train, **kw)
        rows = compare(res.model, train, held).rows
    return res, np.array([r["model"] for r in rows]), np.array([r["linear"] for r in rows])


@pytest.fixture(scope="module")
def held_level():
    suite = {r.name: r for r in as_measured_suite(0, seconds=0.2)}
    return suite["held_level"], [suite["held_level/heldout"]]


def test_duhem_online_places_the_state_held_at_rest(held_level):
    # measured: batch 1.01e-3 um, on-line 1.01e-3 um with the placement (0.459 um without it,
    # no better than the linear model's 0.477 um: the model started at the loop's centre)
    train, held = held_level
    _, batch, linear = _fit(train, held, model="duhem")
    res, online, _ = _fit(train, held, model="duhem", method="online")
    placed = res.info["placement"]
    assert placed["after"] < placed["before"] and placed["rest_memory"] != 0.0
    assert res.model.rest_memory == placed["rest_memory"]
    assert np.all(online <= RATIO * batch), (online, batch)
    assert np.all(online < 0.1 * linear), (online, linear)


def test_placement_does_not_change_a_model_already_placed(held_level):
    train, _ = held_level
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        model = identify(train, model="duhem").model
    before = copy.deepcopy(model)
    placed = place_after_run(model, train, prepare(train))
    # the batch fit placed it already: what is left is round-off
    if placed is not None:
        assert abs(model.offset - before.offset) < 1e-6 * np.ptp(train.y)
        assert abs(model.rest_memory - before.rest_memory) < 1e-6 * np.ptp(train.y)


def test_a_runaway_model_is_not_placed(held_level):
    train, _ = held_level
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        model = identify(train, model="duhem").model
    model.theta[0] = 40.0 / np.ptp(train.u)  # alpha far beyond condition (8)
    offset, memory = model.offset, model.rest_memory
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        assert place_after_run(model, train, prepare(train)) is None
    assert (model.offset, model.rest_memory) == (offset, memory)


def test_warmup_follows_a_short_record():
    n_params = member("pi-stage").n_params
    u_long = np.r_[np.zeros(100), np.sin(np.arange(20_000) / 300.0)]
    assert short_record_warmup(u_long, n_params) == WARMUP
    u_short = np.sin(0.3 + np.arange(800) / 30.0)
    assert short_record_warmup(u_short, n_params) == 399  # half of the 799 after u[0]
    assert short_record_warmup(u_short[:20], n_params) == 5 * n_params


@pytest.mark.parametrize("seed", [0, 3])
def test_pi_stage_online_on_a_short_slow_record_not_at_rest(seed):
    # 800 samples (4 s at 200 Hz) starting mid-swing: the identifier refused such a record
    # (fewer excited samples than its 2000-sample warm-up), and without a zero at the start it
    # ended 3-17 um off (the output's median taken as its zero). Measured: batch 0.069 / 0.076
    # (seed 0), 0.117 / 0.164 um (seed 3); on-line 0.075 / 0.080, 0.083 / 0.085 um; the linear
    # model 0.53 um.
    train = stage_b_like(seed=seed)
    held = [stage_b_like(seed=seed + 1), stage_b_like(seed=seed + 2)]
    _, batch, linear = _fit(train, held, model="auto")
    res, online, _ = _fit(train, held, model="auto", method="online")
    assert res.info["model"] == "pi-stage"
    assert np.all(online <= RATIO * batch), (online, batch)
    assert np.all(online < 0.5 * linear), (online, linear)


@pytest.mark.parametrize("seed", [0, 3])
def test_duhem_online_start_up_spans_a_short_record(seed):
    # The start-up windows (400, 1000, 3000 samples) outran an 800-sample record: its one check
    # failed and no retry came (measured 0.20 / 0.43 um against the batch fit's 0.13). With
    # the last window cut to the record's excitation: 0.112 / 0.114 um (seed 0, batch 0.138 /
    # 0.127) and 0.166 / 0.177 um (seed 3, batch 0.130 / 0.135): 0.8-1.3x, so this member
    # misses issue 21's 1.25x on seed 3 (the default on-line choice, pi-stage, meets it above).
    train = stage_b_like(seed=seed)
    held = [stage_b_like(seed=seed + 1), stage_b_like(seed=seed + 2)]
    _, batch, linear = _fit(train, held, model="duhem")
    res, online, _ = _fit(train, held, model="duhem", method="online")
    assert res.info["start_up"]["checks"][-1]["samples"] <= train.n
    assert len(res.info["start_up"]["checks"]) > 1  # retried on the longer window
    assert np.all(online <= 1.5 * batch), (online, batch)
    assert np.all(online < 0.5 * linear), (online, linear)


STAGE_A = Path(__file__).resolve().parents[2] / "shared" / "data" / "real" / "stageA"


@pytest.mark.skipif(not STAGE_A.exists(), reason=f"measured stage A not found at {STAGE_A}")
def test_duhem_online_stays_admissible_on_measured_stage_a():
    # The recursion checked condition (8) on the current sample's |dw1| only: on prbn_1 it ended
    # at alpha max|dw1| = 6.4 on its own record and ran away on prbn_2 (held-out RMS 2e16 um;
    # 117-131 nm on the others). With alpha capped below 2 / (largest |dw1| seen): 70-81 nm,
    # but from a start-up solve on 3 000 samples in a wrong basin (prbn_2 2.05x the batch
    # fit). With a last start-up window of 10 000 samples (every check fails on a measured
    # stage: its error is far above the sensor noise) it lands where the batch fit does:
    # 40 / 75 / 72 / 78 / 77 nm against 39 / 75 / 72 / 78 / 77 nm (at most 1.02x). Beside the
    # baselines: the static line is 163-194 nm; the linear model 55 / 84 / 73 / 60 / 60 nm,
    # which this member (batch or on-line) does not beat on the triangles (pi-stage does).
    train = load_record(STAGE_A / "prbn_1.csv")
    held = [load_record(STAGE_A / f"{n}.csv")
            for n in ("prbn_2", "sine50_1", "sine50_2", "tri50_1", "tri50_2")]
    _, batch, _ = _fit(train, held, model="duhem")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        res = identify(train, model="duhem", method="online")
        rows = compare(res.model, train, held).rows
    online = np.array([r["model"] for r in rows])
    assert np.all(online < 0.5 * np.array([r["static_line"] for r in rows]))
    assert np.all(online[:3] < np.array([r["linear"] for r in rows[:3]]))
    for rec in [train, *held]:
        assert not [w for w in res.model.admissibility(rec.u) if "condition (8)" in w], rec.name
    assert np.all(online <= RATIO * batch), (online, batch)


PIEZO = (Path(__file__).resolve().parents[2] / "shared" / "data" / "real"
         / "piezo_sine_150V_1Hz" / "hysteresis_v_150_1hz.csv")


@pytest.mark.skipif(not PIEZO.exists(), reason=f"measured piezo record not found: {PIEZO} "
                    "(../shared/data beside the checkout)")
def test_duhem_online_within_ratio_of_batch_on_measured_piezo():
    # +-150 V, 1 Hz, 5 kHz: a step of 87 V out of rest, then 2.7 periods to identify on (the
    # first 60 %), 4 held out. The start-up windows (400 / 1 000 / 3 000 samples: 0.08-0.6 of
    # a period) land in poor basins, and the retries were started from the best of them
    # instead of theta0; their data-driven starts polish into solutions that run away across
    # the step (left out of the cost), which are refused: 0.474 um against the batch fit's
    # 0.0715. Retried from theta0 and the data-driven starts as the batch fit is, the best so
    # far as one more start: 0.0777 um (1.09x), the solve on 10 000 samples from theta0.
    rec = load_record(PIEZO, columns={"t": 1, "u": 3, "y": 2})
    k = int(round(0.6 * rec.n))
    train, held = rec[:k], [(rec, k)]
    _, batch, linear = _fit(train, held, model="duhem")
    res, online, _ = _fit(train, held, model="duhem", method="online")
    # never diverged; the supervisor may roll a wandering recursion back (once, at sample
    # 26 836, since the start keeps the Duhem state the solve fitted at rest)
    assert np.all(np.isfinite(online))
    assert not any("diverged" in w for w in res.info["warnings"]), res.info["warnings"]
    assert np.all(online <= RATIO * batch), (online, batch)
    assert np.all(online < 0.2 * linear), (online, linear)


@pytest.mark.parametrize("shift", [13.0, -50.0])
def test_online_identifier_used_directly_follows_the_rest_level(held_level, shift):
    """``OnlineIdentifier`` fed a record as it comes (not through ``identify``): a stage resting
    at another input level is fitted alike, by ``fit`` and sample by sample by ``update``.

    The recursion's windows hold ``u - u_rest`` like its start-up solve's; they were given raw
    ``u`` before (on the reference stage resting at 13 V: 3.8 um off where 1 nm is the noise).
    """
    from hystid.identify.online import OnlineIdentifier
    from hystid.records import Record

    train, _ = held_level
    moved = Record(train.u + shift, train.y, train.fs, name="moved")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        base, batch, steps = OnlineIdentifier(), OnlineIdentifier(), OnlineIdentifier()
        base.fit(train)
        batch.fit(moved)
        head = moved[: train.n // 2]
        steps.partial_fit(head)
        for u_k, y_k in zip(moved.u[head.n:].tolist(), moved.y[head.n:].tolist(), strict=True):
            steps.update(u_k, y_k)
    assert batch.u_rest_ == pytest.approx(base.u_rest_ + shift)
    for est in (batch, steps):
        assert np.allclose(est.theta, base.theta, rtol=1e-6, atol=1e-9)
    # and the fit is worth having: far below a static line through the record
    yhat = batch.model.simulate(moved.u, check=False).y
    line = np.polyval(np.polyfit(moved.u, moved.y, 1), moved.u)
    tail = slice(moved.n // 2, None)
    rms = float(np.sqrt(np.mean((yhat - moved.y)[tail] ** 2)))
    assert rms < 0.2 * float(np.sqrt(np.mean((line - moved.y)[tail] ** 2)))
    # on the held-out record, moved alike: placed after the run (as its docstring says), it
    # beats a static line and a linear model by far (measured 1.0e-3 against 0.52 / 0.48 um;
    # unplaced 0.46 um, hardly better than the linear model)
    held = held_level[1][0]
    moved_held = Record(held.u + shift, held.y, held.fs, name="moved held-out")
    model = batch.model
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        place_after_run(model, moved, prepare(moved))
        row = compare(model, moved, [moved_held]).rows[0]
    assert row["model"] < 0.05 * min(row["static_line"], row["linear"]), row


@pytest.mark.skipif(not STAGE_A.exists(), reason=f"measured stage A not found at {STAGE_A}")
def test_direct_use_on_stage_a_is_placed_by_place_after_run():
    """``OnlineIdentifier`` used directly returns the recursion's model with the state at rest
    of its start-up solve (its class docstring says so, with these figures: 38 / 88 nm off
    prbn_2 / tri50_1; 129 / 117 nm when it started from the loop's centre); ``place_after_run``
    makes it what ``identify(..., method="online")`` gives (40 / 78 nm)."""
    from hystid.identify.online import OnlineIdentifier

    train = load_record(STAGE_A / "prbn_1.csv")
    held = [load_record(STAGE_A / f"{n}.csv") for n in ("prbn_2", "tri50_1")]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        est = OnlineIdentifier(fs=train.fs)
        est.fit(train)
        model = est.model
        raw = np.array([r["model"] for r in compare(model, train, held).rows])
        place_after_run(model, train, prepare(train))
        placed = np.array([r["model"] for r in compare(model, train, held).rows])
        via = identify(train, model="duhem", method="online").model
        ref = np.array([r["model"] for r in compare(via, train, held).rows])
    assert est.model.rest_memory != 0.0 and np.all(raw < 1.5 * placed), (raw, placed)
    assert np.allclose(placed, ref, rtol=0.05), (placed, ref)


@pytest.mark.parametrize("swing", [0.9, -0.9])
def test_duhem_online_start_keeps_the_branch_the_record_starts_on(swing):
    """A stage-A look-alike (Bouc-Wen, 740 Hz mode) swung up or down before its record rests on
    one branch of its loop. The start-up solve fits that state (``rest_memory``); the recursion
    was started from the loop's centre instead, so the check saw a worse start than the solve
    found and the recursion settled elsewhere. Measured, trained on a 50 Hz sine, held out a
    PRBN, a sine and a triangle (nm): up 334 / 431 / 366 before (the static line 358 / 288 /
    320), 158 / 21 / 100 now; down 209 / 107 / 131 before, 162 / 27 / 99 now."""
    kw = {"seconds": 1.0, "swing_before": swing}
    train = stage_a_like("sine50", seed=1, **kw)
    held = [stage_a_like(kind, seed=2, repeat=1, **kw) for kind in ("prbn", "sine50", "tri50")]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        res = identify(train, model="duhem", method="online")
        rows = compare(res.model, train, held).rows
    online = np.array([r["model"] for r in rows])
    best_baseline = np.array([min(r["linear"], r["static_line"]) for r in rows])
    assert np.all(online < 0.6 * best_baseline), (online, best_baseline)
    assert res.model.rest_memory != 0.0
