"""The diagnosis on inputs a user meets: a long leading rest, a model given that runs away.

Found by a hostile run of the command line: ``hystid diagnose`` on measured stage A's
``tri50_1.csv`` stopped with "the input u is constant" (its structure step refitted the first
6 000 samples, all at rest), and a model given with ``g0 = 1e99`` ended in a traceback from
the loss test.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from hystid.cli import main
from hystid.diagnose.refit import FitData
from hystid.diagnose.screen import compare_losses, hac_variance
from hystid.diagnose.structure import HEAD_REST, head
from hystid.reference import reference_model, reference_record


def test_the_head_of_a_record_with_a_long_rest_holds_its_excitation():
    rng = np.random.default_rng(0)
    u = np.r_[np.full(10_001, -5.34), rng.uniform(-80, 70, 9_000)]
    weight = np.ones(len(u), bool)
    weight[12_000:12_100] = False
    data = FitData(u, np.zeros(len(u)), 10_000.0, 0.0, weight)
    part = head(data, 6000)
    assert len(part.u) == 6000 and np.ptp(part.u) > 100.0  # constant before
    assert np.count_nonzero(part.u == -5.34) == HEAD_REST
    moved = 10_001 - HEAD_REST
    np.testing.assert_array_equal(part.weight, weight[moved:moved + 6000])
    # a slice weight (all samples from one on) is carried over as well
    sliced = head(FitData(u, np.zeros(len(u)), 10_000.0, 0.0, slice(9_000, None)), 6000)
    assert sliced.weight.all()


def test_a_loss_test_on_runaway_errors_accepts_nothing():
    big = [np.full(500, 1e200) * np.cos(np.arange(500))]
    other = [big[0] * 0.5]
    assert hac_variance(big[0] * 1e-40, demean=False) == (float("inf"), 0)  # squares overflow
    out = compare_losses(big, other)
    assert out["p_value"] >= 0.5


def test_a_model_given_that_runs_away_on_the_train_record_is_refused(tmp_path, capsys):
    rec = reference_record(0.2, seed=3, noise=1e-3)
    rec.save(tmp_path / "train.csv")
    model = reference_model()
    params = dict(model.params, g0=1e99)
    (tmp_path / "model.json").write_text(json.dumps(
        {"params": params, "structure": {"n1a": 1, "n1b": 0, "n2a": 2, "n2b": 0,
                                         "q1": 1, "q2": 0, "f0": False}}))
    code = main(["diagnose", str(tmp_path / "train.csv"), "--model",
                 str(tmp_path / "model.json"), "--quiet"])
    err = capsys.readouterr().err
    assert code == 2 and "--model" in err and "diverges" in err, err


STAGE_A = Path(__file__).resolve().parents[2] / "shared" / "data" / "real" / "stageA"


@pytest.mark.skipif(not (STAGE_A / "tri50_1.csv").exists(),
                    reason=f"measured stage A not found at {STAGE_A} (../shared/data)")
def test_a_dead_time_scan_at_its_end_is_widened_and_said(capsys):
    """On measured stage A's 50 Hz triangle the linear starts' dead-time scan was best at its
    end (q1 + 24) and nothing said so; it now scans on (to q1 + 96), and a best at that end is
    reported with the candidate, accepted or not."""
    code = main(["diagnose", str(STAGE_A / "tri50_1.csv"), "--effects", "delay", "--quiet"])
    out = capsys.readouterr().out
    assert code == 0
    assert "delay (round 1, not accepted): at a bound of its range: delay.dead time (q1 + 96, " \
        "the end of the widened scan)" in out, out
