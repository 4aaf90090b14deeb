"""Creep against a record's own drift: the comparison gives the drift no advantage from being
fitted on the samples it is scored on, and the refit does not turn a creep into a slow ramp.

Records come from the independent stage simulator (:mod:`hystid.testing`), whose creep and
drift forms differ from the candidates' parametrisations.
"""

from __future__ import annotations

import numpy as np
import pytest

from hystid.diagnose import diagnose
from hystid.diagnose.rounds import _drift_fit, _drift_out_of_sample
from hystid.records import Record
from hystid.reference import paper_excitation

FS = 30_000.0
N = 9_000
NOISE = 2e-3

testing = pytest.importorskip("hystid.testing", reason="needs the independent stage simulator")


def _rms(x: np.ndarray) -> float:
    return float(np.sqrt(np.mean(x**2)))


def _records(effect: str, form: str, strength: float, seed: int) -> tuple[Record, Record]:
    """Train and held-out records of the paper's excitation from rest (no level steps: the
    slow error after the start is all that tells creep from drift)."""
    rng = np.random.default_rng(seed)
    recs = []
    for label in ("train", "val"):
        u = paper_excitation(N, FS, seed=int(rng.integers(1 << 30)),
                             offset=rng.uniform(4.8, 5.6))
        sim = testing.simulate_stage(u, FS, effect=effect, form=form, strength=strength,
                                     seed=int(rng.integers(1 << 30)))
        recs.append(Record(u, sim["y"] + NOISE * rng.standard_normal(N), FS, name=label))
    return recs[0], recs[1]


# --------------------------------------------------------------------------- the drift's score
def test_drift_scored_out_of_sample_extends_a_slow_trend():
    rng = np.random.default_rng(0)
    t = np.arange(6000) / FS
    noise = 1e-3 * rng.standard_normal(len(t))
    # a thermal-like drift (part of a slow sine: not the cubic the drift is fitted with)
    e = 0.02 * np.sin(2 * np.pi * t / 1.5 + 0.4) - 0.02 * np.sin(0.4) + noise
    inside = _rms(e - _drift_fit(t, e))
    outside = _rms(e - _drift_out_of_sample(t, e))
    assert inside < outside < 1.5 * _rms(noise)


def test_drift_scored_out_of_sample_cannot_follow_a_transient():
    rng = np.random.default_rng(1)
    t = np.arange(6000) / FS
    noise = 1e-3 * rng.standard_normal(len(t))
    # a creep-like transient after the start: fitted in place, a cubic follows much of it
    e = 0.03 * (1.0 - np.exp(-t / 0.02)) + noise
    inside = _rms(e - _drift_fit(t, e))
    outside = _rms(e - _drift_out_of_sample(t, e))
    assert outside > 2.0 * inside
    # each block is predicted from the others only: changing one block changes nothing there
    e2 = e.copy()
    e2[:1500] += 0.05
    assert np.allclose(_drift_out_of_sample(t, e2)[:1500], _drift_out_of_sample(t, e)[:1500])
    assert not np.allclose(_drift_out_of_sample(t, e2)[1500:], _drift_out_of_sample(t, e)[1500:])


@pytest.mark.parametrize("blocks", [2, 4, 7])
def test_drift_out_of_sample_is_exact_on_its_own_form(blocks):
    t = np.arange(3000) / FS
    e = 0.1 * t - 2.0 * t**2 + 5.0 * t**3
    assert np.allclose(_drift_out_of_sample(t, e, blocks), e, atol=1e-12)


# --------------------------------------------------------------------------- diagnoses
@pytest.fixture(scope="module")
def creep_result():
    return diagnose(*_records("creep", "lags", 0.05, seed=11), progress=False)


def test_creep_after_the_start_is_named_creep_not_drift(creep_result):
    res = creep_result
    assert res.best == "creep"
    assert "drift" not in res.families
    assert res.final["gap_closed"] > 0.8


def test_the_order_of_creep_and_drift_is_explained(creep_result):
    orders = [r["drift_order"] for r in creep_result.rounds if "drift_order" in r]
    if not orders:
        pytest.fail("the drift and the creep both passed round 1 on this record, so their "
                    "order must be reported")
    order = orders[0]
    assert not order["drift_first"]
    assert order["form"] in creep_result.accepted
    # like with like: the drift scored out of sample does worse than fitted in place
    assert order["rms_drift_out_of_sample"] > order["rms_drift"]
    text = creep_result.summary()
    assert "goes before the drift" in text


def test_a_drift_of_its_own_is_still_named_drift_with_its_reason():
    res = diagnose(*_records("drift", "thermal", 0.05, seed=12), progress=False)
    assert res.families[:1] == ["drift"]
    assert not any(f == "creep" for f in res.families)
    for r in res.rounds:
        if "drift_order" in r:
            assert r["drift_order"]["drift_first"]
            assert "the drift goes before" in res.summary()
