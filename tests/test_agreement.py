"""The probe input and the disagreement of two models (hystid.identify.agreement)."""

import numpy as np

from hystid.identify.agreement import disagreement, probe_input
from hystid.model import DuhemSandwich, Structure
from hystid.reference import PAPER_PARAMS, reference_model
from hystid.testing import stage_a_like


def test_the_probe_stays_in_the_range_is_seeded_and_reverses_at_every_size():
    rec = stage_a_like("prbn", seconds=0.5, seed=3)
    u = rec.u
    lo, hi = np.percentile(u, [1, 99])
    probe = probe_input(u, rec.fs, seed=0)
    assert probe[0] == u[0] and len(probe) == int(rec.fs)
    assert probe[1:].min() >= lo - 1e-9 and probe[1:].max() <= hi + 1e-9
    np.testing.assert_array_equal(probe, probe_input(u, rec.fs, seed=0))
    assert not np.array_equal(probe, probe_input(u, rec.fs, seed=1))
    # the reversals: from a hundredth of the range to most of it
    turns = probe[np.flatnonzero(np.diff(np.sign(np.diff(probe))) != 0) + 1]
    swings = np.abs(np.diff(turns)) / (hi - lo)
    assert swings.min() < 0.03 and swings.max() > 0.5


def test_a_model_agrees_with_itself_and_not_with_another():
    u = 5.0 + 4.0 * np.sin(np.linspace(0.0, 20.0, 3000))  # the reference stage's range
    model = reference_model()
    assert disagreement(model, model, u, model.fs) == 0.0
    wider = DuhemSandwich({**PAPER_PARAMS, "alpha": 1.2 * PAPER_PARAMS["alpha"]}, Structure(),
                          fs=model.fs)
    assert disagreement(model, wider, u, model.fs) > 0.0


def test_a_short_record_still_gets_a_probe():
    probe = probe_input(np.array([0.0, 1.0, 2.0, 1.0]), 200.0, seed=0)
    assert len(probe) == 2000 and np.isfinite(probe).all()
