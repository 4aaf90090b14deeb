"""Gross faults in a record: an input glitch is mended, an output burst is left out, and the fit
is then the clean record's; an input the stage really followed is not taken for a glitch."""

import warnings

import numpy as np
import pytest

from hystid.identify import identify
from hystid.identify.prepare import input_glitches
from hystid.records import Record
from hystid.reference import reference_record


@pytest.fixture(scope="module")
def clean():
    rec = reference_record(0.3, seed=0)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return rec, identify(rec)


def _fit(u, y, rec):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return identify(Record(u, y, rec.fs, name="faulty"))


@pytest.mark.parametrize("width", [1, 3])
def test_an_input_glitch_is_mended_and_said(clean, width):
    rec, base = clean
    u = rec.u.copy()
    u[4000:4000 + width] = 100.0  # recorded wrong: the output never saw it
    res = _fit(u, rec.y, rec)
    np.testing.assert_allclose(res.model.theta, base.model.theta, rtol=1e-3)
    assert any("recording glitch" in w and "sample 4000" in w for w in res.info["warnings"])
    assert rec.u[4000] != 100.0  # the caller's record is untouched


def test_an_output_burst_is_left_out_of_the_batch_fit(clean):
    rec, base = clean
    y = rec.y.copy()
    y[6000:6100] += 5.0
    res = _fit(rec.u, y, rec)
    np.testing.assert_allclose(res.model.theta, base.model.theta, rtol=1e-3)
    assert any("leave those samples out" in w for w in res.info["warnings"])


def test_an_input_the_stage_followed_is_not_a_glitch():
    rng = np.random.default_rng(0)
    u = rng.normal(size=2000).cumsum()
    y = 0.1 * u
    u[1000:1002] += 500.0
    y[1000:1002] += 50.0  # the stage moved with it
    assert input_glitches(u, y)[0] == []
    u2 = u.copy()
    u2[1500:1510] = 500.0  # ten samples: a drive, not a glitch, whatever the output did
    assert [r for r in input_glitches(u2, y)[0] if r[0] == 1500] == []
