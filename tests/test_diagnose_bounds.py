"""A fitted effect parameter at the bound of its search range is reported, and the guessed
ranges (not the physical ones) widen."""

import numpy as np

from hystid.diagnose.effects import EFFECTS
from hystid.diagnose.parametrisation import PHYSICAL_BOUNDS, Parametrisation
from hystid.reference import reference_model


def _at(par: Parametrisation, form: str, param: str, side: str) -> np.ndarray:
    lo, hi = par.bounds()
    z = (lo + hi) / 2
    z = np.where(np.isfinite(z), z, 0.0)
    slot = EFFECTS[form].slots[EFFECTS[form].params.index(param)]
    i = par.ntheta + par.slots.index(slot)
    z[i] = hi[i] if side == "upper" else lo[i]
    return z


def test_a_guessed_range_is_reported_at_its_bound_and_widens():
    model = reference_model()
    par = Parametrisation(model, ["mode_series"], 1.0, free_theta=False)
    found = par.at_bound(_at(par, "mode_series", "gain", "upper"))
    assert found == ["mode_series.gain (2 at its upper bound)"]
    assert par.at_bound(_at(par, "mode_series", "gain", "upper") * 0.5) == []
    wide = Parametrisation(model, ["mode_series"], 1.0, free_theta=False, widen=4.0)
    lo, hi = wide.bounds()
    i = wide.slots.index(EFFECTS["mode_series"].slots[0])
    assert (lo[i], hi[i]) == (-4.0, 8.0)
    # the value that sat at the old bound is inside the widened range
    z = _at(par, "mode_series", "gain", "upper")
    assert wide.at_bound(z) == []


def test_a_physical_bound_is_neither_reported_nor_widened():
    model = reference_model()
    par = Parametrisation(model, ["creep"], 1.0, free_theta=False, widen=4.0)
    assert EFFECTS["creep"].slots[0] in PHYSICAL_BOUNDS
    assert par.at_bound(_at(par, "creep", "gain", "lower")) == []
    lo, hi = par.bounds()
    assert (lo[0], hi[0]) == (0.0, 1.0)  # a creep gain is not negative, whatever the factor


def test_the_error_after_turning_points_is_told_apart():
    """An error that appears only after the input's reversals is found there; an error spread
    evenly is not."""
    from hystid.diagnose.where import Segment, _after_turning_points

    fs = 1000.0
    t = np.arange(4000) / fs
    u = np.abs(((t * 5.0) % 2.0) - 1.0)  # a 5 Hz triangle: reversals every 0.1 s
    rng = np.random.default_rng(0)
    even = rng.normal(scale=1e-3, size=len(u))
    after = np.zeros(len(u))
    dist = np.minimum(np.abs(u), np.abs(u - 1.0))  # distance to the nearest extreme
    after[dist < 0.05] = 1e-2
    for e, expect_near in ((even, False), (after, True)):
        seg = Segment(u, e, np.zeros(len(u)), u.copy(), fs, 0.0)
        out = _after_turning_points([seg], noise=0.0)
        assert 0.05 < out["share_samples"] < 0.3
        if expect_near:
            assert out["rms_ratio"] > 3 and out["excess_share"] > 0.5, out
        else:
            assert 0.8 < out["rms_ratio"] < 1.25 and out["excess_share"] < 0.35, out
