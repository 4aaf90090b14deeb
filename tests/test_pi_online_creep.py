"""The ``pi-stage`` on-line identifier on stages whose creep is slower than its warm-up.

The stages are built here from ``hystid.testing``'s blocks (Maxwell-slip hysteresis, a flexure
mode, a creep written as a lag of part of the DC gain), at 20 kHz, not from the model's own
forms. What went wrong before, each measured on the code before the change:

* a warm-up of 0.1 s cannot place a creep of 0.5 s: the warm-up fit used its slow branch for
  something faster and the re-solves never left that basin (13-33x the batch fit's held-out
  error). A second identifier started from the batch fit's slow-branch start runs beside the
  first until the window is full, and the one whose model runs closer to the output from rest
  is kept (``two_starts``);
* a window of 10 000 samples (0.5 s at 20 kHz) left the creep to the arrival cost (1.3-5.2x);
  the default window is now 1 s;
* a warm-up on a ramp out of rest alone predicted none of the samples after it; the warm-up is
  fitted again on every sample so far, and said;
* on a record as long as the window (1 s) the two starts were chosen between after a few
  re-solves of 4 trials: 1.0-5.3x the batch fit's held-out error, and the slow-branch start's
  weights were those fitted without the branch. Each start now runs one re-solve of 12 trials
  before the choice, and the slow-branch start's weights fit its blocks.
"""


import numpy as np
import pytest
from conftest import quiet
from scipy import signal

from hystid.baselines import compare
from hystid.identify import identify
from hystid.identify.pi_online import PIStageOnline
from hystid.pi import pi_thresholds
from hystid.records import Record
from hystid.testing import Linear, MaxwellSlip, SandwichStage, continuous_linear

FS = 20_000.0


def creep_stage(share: float = 0.1, tau: float = 0.5) -> SandwichStage:
    """A 1.2 kHz mode (damping 0.015) and a creep: ``share`` of the DC gain through a lag of
    ``tau`` seconds, after a Maxwell-slip loop and a 3 kHz amplifier."""
    mode = continuous_linear(FS, mode_hz=1200.0, damping=0.015)
    p = np.exp(-1.0 / (tau * FS))
    lag = np.r_[1.0 - share, -(1.0 - share) * p + share * (1.0 - p)]
    l2 = Linear(tuple(np.convolve(mode.b, lag)), tuple(np.convolve(np.r_[1.0, mode.a],
                                                                   [1.0, -p])[1:]), mode.delay)
    loop = MaxwellSlip(k=1.0, slip_stiffness=0.6, r_max=2.0, r_decay=1.0)
    return SandwichStage(continuous_linear(FS, pole_hz=3000.0, delay=1), loop, l2, FS)


def noise(rng, n: int, corner: float, mean: float = 5.0, amp: float = 4.5) -> np.ndarray:
    b, a = signal.butter(4, corner / (FS / 2))
    x = signal.lfilter(b, a, rng.standard_normal(n + 2000))[2000:]
    return np.clip(mean + amp * x / np.max(np.abs(x)), 0.0, 10.0)


def record(stage, u, rng, name):
    return Record(u, stage.simulate(u)["y"] + 1e-3 * rng.standard_normal(len(u)), FS, name=name)


def creep_records(seconds: float, seed: int = 1) -> tuple[Record, list[Record]]:
    """The creep stage's training record (a rest, then ``seconds`` of noise) and two held-out
    records (a 10 Hz triangle, slower noise)."""
    rng = np.random.default_rng(seed)
    stage = creep_stage()
    n = int(seconds * FS)
    train = record(stage, np.r_[np.zeros(2000), noise(rng, n, 300.0)], rng, "noise")
    t = np.arange(n) / FS
    tri = 5.0 + 4.0 * signal.sawtooth(2 * np.pi * 10 * t, 0.5)
    held = [record(stage, np.r_[np.zeros(1000), np.linspace(0.0, tri[0], 200), tri], rng, "tri"),
            record(stage, np.r_[np.zeros(1000), noise(rng, n, 100.0)], rng, "slow noise")]
    return train, held


def test_a_creep_slower_than_the_warm_up_is_identified_on_line_as_in_the_batch_fit():
    train, held = creep_records(1.5)
    batch = quiet(identify, train, model="pi-stage")
    online = quiet(identify, train, model="pi-stage", method="online")
    rows_b = compare(batch.model, train, held).rows
    rows_o = compare(online.model, train, held).rows
    for b, o in zip(rows_b, rows_o, strict=True):
        assert o["model"] < 1.25 * b["model"], (o, b)  # 13-33x before
        assert o["model"] < 0.2 * o["linear"] and o["model"] < 0.2 * o["static_line"], o
    slow = np.max(np.abs(np.roots(np.r_[1.0, online.model.a2])))
    assert abs(np.log(slow) * FS * 0.5 + 1.0) < 0.3  # the creep's 0.5 s within 30 %


def test_a_warm_up_that_predicts_nothing_is_fitted_again_and_said():
    rng = np.random.default_rng(1)
    stage = creep_stage(share=0.0)
    u = np.r_[np.zeros(2000), np.linspace(0.0, 5.0, 2000), noise(rng, int(FS), 1500.0, 5.0, 4.0)]
    train = record(stage, u, rng, "ramp then noise")
    est = PIStageOnline(pi_thresholds(u, 20), fs=FS, warmup=2000)
    result = quiet(est.fit, train)
    assert est.n_rewarms == 1
    assert any("predicted none of the next 2000 samples" in w for w in result.info["warnings"])
    # the chunk after the warm-up fitted again is predicted (half the spread or more before)
    e = result.info["prediction_errors"][6000:8000]
    assert np.sqrt(np.mean(e ** 2)) < 0.1 * np.std(train.y[6000:8000])


def test_samples_left_out_are_run_but_not_learned_from():
    rng = np.random.default_rng(2)
    stage = creep_stage()
    u = np.r_[np.zeros(500), noise(rng, 6000, 300.0)]
    clean = record(stage, u, rng, "clean")
    spoilt = Record(u, clean.y.copy(), FS, name="spoilt")
    spoilt.y[3000:3400] += 50.0  # a span the caller knows to be bad
    thresholds = pi_thresholds(u, 8)
    make = lambda: PIStageOnline(thresholds, fs=FS, warmup=1000, left_out=[(3000, 3400)])  # noqa: E731
    a, b = quiet(make().fit, clean), quiet(make().fit, spoilt)
    np.testing.assert_allclose(a.model.theta, b.model.theta)
    assert np.isnan(b.info["prediction_errors"][3000:3400]).all()
    with pytest.raises(ValueError, match="left_out"):
        PIStageOnline(thresholds, left_out=[(5, 2)])


def test_identify_leaves_out_of_the_on_line_fit_what_it_leaves_out_of_the_batch_fit():
    rng = np.random.default_rng(3)
    stage = creep_stage()
    u = np.r_[np.zeros(2000), np.full(3000, 8.0), noise(rng, 12000, 300.0)]
    train = record(stage, u, rng, "a jump out of rest")
    online = quiet(identify, train, model="pi-stage", method="online")
    spans = online.settings["left_out"]
    assert spans and spans[0][0] == 2000  # the transient after the jump
    assert any("jumps" in w for w in online.info["warnings"])


def test_the_monotone_bound_is_an_option():
    rng = np.random.default_rng(4)
    stage = creep_stage()
    u = np.r_[np.zeros(500), noise(rng, 8000, 300.0)]
    rec = record(stage, u, rng, "noise")
    thresholds = pi_thresholds(u, 8)
    bound = PIStageOnline(thresholds, fs=FS, warmup=1000, monotone=True)
    result = quiet(bound.fit, rec)
    assert np.min(np.cumsum(result.model.theta[:8])) > 0.0
    assert result.info["loading_slope_min"] > 0.0 and bound.settings["monotone"] is True
    assert PIStageOnline(thresholds, fs=FS).settings["monotone"] is False


def test_the_start_kept_is_said():
    rng = np.random.default_rng(1)
    stage = creep_stage()
    u = np.r_[np.zeros(2000), noise(rng, int(1.5 * FS), 300.0)]
    est = PIStageOnline(pi_thresholds(u, 20), fs=FS, warmup=2000)
    result = quiet(est.fit, record(stage, u, rng, "noise"))
    errors = result.info["start_errors"]
    assert set(errors) == {"warm-up fit", "slow branch"}
    assert result.info["started_from"] == min(errors, key=errors.get) == "slow branch"


@pytest.mark.parametrize("seed", [0, 1])
def test_on_a_record_as_long_as_the_window_the_on_line_model_is_as_good(seed):
    """Before: seed 1 5.3x and 4.5x the batch fit's held-out error (1.0x on seed 0); with the
    slow-branch start's weights alone, seed 0 8.7x and 3.0x."""
    train, held = creep_records(1.0, seed)
    batch = quiet(identify, train, model="pi-stage")
    online = quiet(identify, train, model="pi-stage", method="online")
    rows_b = compare(batch.model, train, held).rows
    for b, o in zip(rows_b, compare(online.model, train, held).rows, strict=True):
        assert o["model"] < 1.25 * b["model"], (o, b)
        assert o["model"] < 0.2 * o["linear"] and o["model"] < 0.2 * o["static_line"], o


def test_the_batch_fit_finds_a_creep_half_as_long_as_its_record():
    """One second of excitation, a creep of 0.5 s: the slow-branch start needs more than the
    40 evaluations the other starts are polished for (113-124 nm off before, against the
    linear model's 207-287)."""
    train, held = creep_records(1.0)
    batch = quiet(identify, train, model="pi-stage")
    assert batch.info["start"] == "ARX mode + slow branch"
    for row in compare(batch.model, train, held).rows:
        assert row["model"] < 0.2 * row["linear"], row
