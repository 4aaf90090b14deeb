"""Perturbed stages (physical +-20 % changes at the same static gains) and margins on them."""

import numpy as np
import pytest

import hystid.compensate as hc
from hystid import DuhemSandwich, Structure
from hystid.compensate.robustness import PERTURBABLE, margins_on, perturbed_stage
from hystid.reference import reference_model


@pytest.fixture(scope="module")
def stage():
    return reference_model()


def _slow_triangle(fs: float) -> np.ndarray:
    """A 2 Hz triangle between 3 and 7 V from rest: quasi-static for the flexure and L1."""
    t = np.arange(int(fs)) / fs
    tri = 1 - np.abs(2 * ((2 * t) % 1) - 1)
    return np.clip(t / 0.05, 0, 1) * (3 + 4 * tri)


def test_unit_factors_give_the_same_stage(stage):
    same = perturbed_stage(stage, dict.fromkeys(PERTURBABLE, 1.0))
    np.testing.assert_allclose(same.theta, stage.theta, rtol=1e-9, atol=1e-12)


def test_pole_and_mode_changes_keep_the_static_behaviour(stage):
    moved = perturbed_stage(stage, {"a11": 0.8, "mode frequency": 1.2, "mode damping": 0.8})
    assert not np.allclose(moved.a1, stage.a1) and not np.allclose(moved.a2, stage.a2)
    u = _slow_triangle(stage.fs)
    y0, y1 = stage.simulate(u).y, moved.simulate(u).y
    steady = slice(len(u) // 2, None)
    assert np.max(np.abs(y1[steady] - y0[steady])) < 0.01 * np.ptp(y0[steady])


def test_mode_moves_by_the_factors_and_gain_by_f1(stage):
    f, zeta = hc.flexure_mode(stage)
    moved = perturbed_stage(stage, {"mode frequency": 0.8, "mode damping": 1.2, "f1": 1.2})
    f2, zeta2 = hc.flexure_mode(moved)
    assert f2 == pytest.approx(0.8 * f, rel=1e-6)
    assert zeta2 == pytest.approx(1.2 * zeta, rel=1e-6)
    u = _slow_triangle(stage.fs)
    steady = slice(len(u) // 2, None)
    span0 = np.ptp(stage.simulate(u).y[steady])
    span1 = np.ptp(moved.simulate(u).y[steady])
    assert 1.1 < span1 / span0 < 1.3  # the branch slope f1 is the static gain


def test_margins_on_the_design_model_are_the_designs(stage):
    design = hc.design_feedback(stage)
    m = margins_on(design, stage)
    assert m.stable
    assert m.gain_margin_db == pytest.approx(design.gain_margin_db, rel=1e-6)
    assert m.phase_margin == pytest.approx(design.phase_margin, rel=1e-6)
    lower = margins_on(design, perturbed_stage(stage, {"mode frequency": 0.8}))
    assert lower.gain_margin_db < design.gain_margin_db


@pytest.mark.parametrize("factors, match", [
    ({"beta": 1.1}, "unknown name.*beta"),
    ({"f1": 0.0}, "positive finite.*f1=0.0"),
    ({"alpha": float("nan")}, "positive finite.*alpha=nan"),
])
def test_bad_factors_are_named(stage, factors, match):
    with pytest.raises(ValueError, match=match):
        perturbed_stage(stage, factors)


def test_other_structures_are_refused(stage):
    p = {**stage.params, "a12": 0.1}
    other = DuhemSandwich(p, Structure(n1a=2), fs=stage.fs)
    with pytest.raises(ValueError, match="order 1.*order 2"):
        perturbed_stage(other, {"f1": 1.1})
