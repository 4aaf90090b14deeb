"""Where a PI sandwich starts a held-out record: settled at its first input when the record
begins in motion, from its own rest when it begins at rest.

The records come from ``hystid.testing``'s stage B look-alike (a Preisach hysteresis between a
30 Hz lag and a 90 Hz mode, sampled at 200 Hz, written apart from the model code): a 1 Hz sine
with a random phase, so that every record begins in motion somewhere on its swing. Started from
its rest (the training record's first input) and stepped to the record's first input, the
``pi-stage`` model's L2 rang for a second or more (measured: 0.34 / 0.96 / 0.65 / 0.20 um on
four held-out records, against the linear model's 0.53-0.54 on all four); started settled at the
record's mean input level and ramped to its first input, 0.12-0.13 um.
"""

import copy
import dataclasses
import warnings
from pathlib import Path

import numpy as np
import pytest

from hystid.baselines import centring_input, compare, simulate_from_rest
from hystid.identify.members import member
from hystid.identify.prepare import rest_level
from hystid.records import Record
from hystid.testing.measured import stage_b_like

NOISE = 0.1  # um: the look-alike's default 0.02 hides part of it (0.085 / 0.165 um before)


@pytest.fixture(scope="module")
def fitted():
    train = stage_b_like(seconds=4.0, noise_rms=NOISE, seed=0)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        model = member("pi-stage").fit(train).model
    return train, model


@pytest.mark.parametrize("seed", [2, 3])
def test_a_record_that_begins_in_motion_is_predicted_from_its_first_sample_on(fitted, seed):
    train, model = fitted
    held = stage_b_like(seconds=4.0, noise_rms=NOISE, seed=seed)
    assert not rest_level(held.u)[1] and abs(held.u[0] - model.u_rest) > 1.0  # in motion, away
    row = compare(model, train, [held]).rows[0]
    assert row["model"] < 0.2 and row["model"] < 0.3 * row["linear"], row
    assert row["model"] < 0.1 * row["static_line"], row
    # no ringing at the start (measured before: the error's sample-to-sample change 23-27x
    # larger over the first half second than after the first second, 25.9 / 17.7 um off
    # there); what is left is the branch the unknown past left the stage on (the loop's
    # branches are up to 9 um apart), forgotten once the input has swept its range
    e = held.y - simulate_from_rest(model, held.u, check=False)
    e -= np.median(e)
    d = np.diff(e)
    assert np.sqrt(np.mean(d[:100] ** 2)) < 4.0 * np.sqrt(np.mean(d[200:] ** 2))
    assert np.sqrt(np.mean(e[:100] ** 2)) < 2.5
    assert np.sqrt(np.mean(e[200:] ** 2)) < 0.2


def test_a_record_that_begins_at_rest_elsewhere_starts_from_the_model_s_own_rest(fitted):
    # measured stage A's sine records rest at another level than the training record: the
    # model's slow dynamics follow the move there as the stage's did (see simulate_from_rest)
    _, fitted_model = fitted
    model = copy.deepcopy(fitted_model)
    model.envelope = dataclasses.replace(model.envelope, from_rest=True)  # a rest it saw
    u = np.r_[np.full(400, model.u_rest + 1.5), model.u_rest + 1.5 + np.sin(np.arange(400) / 9)]
    assert rest_level(u)[1]
    stepped = model.simulate(u, check=False).y
    np.testing.assert_array_equal(simulate_from_rest(model, u, check=False), stepped)
    settled = model.simulate(u, model.settled_state(u[0]), check=False).y
    assert not np.allclose(settled[:50], stepped[:50])  # the two starts differ here
    # the look-alike's record begins in motion: its model never saw the stage at rest, and
    # starts the record at its loop's centre at u[0] (tests/test_rest_unseen.py)
    assert not fitted_model.envelope.from_rest
    before = centring_input(fitted_model, u[0])
    centred = fitted_model.simulate(np.r_[before, u], check=False).y[len(before):]
    np.testing.assert_array_equal(simulate_from_rest(fitted_model, u, check=False), centred)


def test_the_settled_state_is_the_steady_state_of_a_held_input(fitted):
    # held at u0 from the settled state, the output does not move (L1, L2 at steady state,
    # the plays where the move left them); from the model's rest it moves for a while
    _, model = fitted
    for u0 in (model.u_rest + 3.0, model.u_rest - 0.4):
        u = np.full(300, u0)
        y = model.simulate(u, model.settled_state(u0), check=False).y
        assert np.ptp(y) < 1e-9 * max(1.0, abs(y[0] - model.offset))
        assert np.ptp(model.simulate(u, check=False).y) > 1e-3
        rec = Record(u, y, model.fs)
        assert rec.n == 300


STAGE_A = Path(__file__).resolve().parents[2] / "shared" / "data" / "real" / "stageA"


@pytest.mark.skipif(not STAGE_A.exists(), reason=f"measured stage A not found: {STAGE_A} "
                    "(../shared/data beside the checkout)")
def test_pieces_of_measured_records_cut_mid_motion_start_near_the_stage():
    # cut 1.2 or 1.5 s into stage A's records (a 5 Hz carrier swinging +-60 V): started from
    # its rest and stepped to the first input the identified pi-stage model was 41-116 nm off
    # them; settled at the first input itself, its slow branch (a memory of ~1 s) sat at the
    # level of a carrier's peak: 373-1297 nm; settled at the piece's mean input level and
    # ramped to the first input: 33-86 nm (measured)
    from hystid.identify import identify
    from hystid.records import load_record

    train = load_record(STAGE_A / "prbn_1.csv")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        model = identify(train).model
    pieces = []
    for name in ("prbn_2", "sine50_1", "tri50_1"):
        rec = load_record(STAGE_A / f"{name}.csv")
        pieces += [Record(rec.u[a:], rec.y[a:], rec.fs, units=rec.units, name=f"{name}[{a}:]")
                   for a in (12_000, 15_000)]
    assert not any(rest_level(p.u)[1] for p in pieces)
    rows = compare(model, train, pieces).rows
    for r in rows:
        assert r["model"] < 0.1 and r["model"] < 0.5 * r["static_line"], r
    # the linear model, started alike (settled at the piece's mean level, ramped; it was
    # settled at the first input before, 185-611 nm off), is 74-114 nm: the model beats it on
    # five of the six pieces, and loses on sine50_1[12000:] (86 against 77 nm, measured)
    assert sum(r["model"] < r["linear"] for r in rows) >= 5, rows


@pytest.mark.parametrize("mean", [1.0, 2.6])
@pytest.mark.parametrize("amp", [1.0, 0.8])
def test_a_sine_cut_at_its_sampled_peak_starts_in_motion(fitted, mean, amp):
    # it starts at an end of its range, which the fit takes as a rest (a generator's ramp
    # from rest); stepped from the model's rest the model was 4.1-9.6 um off these records,
    # worse than the static line (2.0-2.5); started as a record in motion, 0.79-2.0 um
    # (measured). At the 1 V level it still loses to the linear model (1.78 / 2.00 um against
    # 1.20 / 1.33) and is level with the static line: the minor loops a PI operator draws
    # from one major loop are not the Preisach stage's
    train, model = fitted
    from hystid.identify.prepare import shows_rest
    from hystid.testing.measured import stage_b

    t = np.arange(800) / 200.0
    u = mean + amp * np.cos(2 * np.pi * t)
    y = stage_b().simulate(u)["y"] - 111.2 + NOISE * np.random.default_rng(5).standard_normal(800)
    held = Record(u, y, 200.0, name=f"sine at {mean} V from its peak")
    assert rest_level(u)[1] and not shows_rest(u)
    row = compare(model, train, [held]).rows[0]
    stepped = model.simulate(u, check=False).y  # from its rest, stepped to u[0]
    assert row["model"] < 0.5 * np.sqrt(np.mean((stepped - y) ** 2)), row
    if mean > 2.0:
        assert row["model"] < 0.7 * row["linear"] and row["model"] < 0.5 * row["static_line"]
