"""Off-line output-error identification: the reference the on-line methods are measured against."""

import numpy as np
import pytest

from hystid import DuhemSandwich, Structure
from hystid.identify import identify
from hystid.identify.constraints import (
    is_admissible,
    poly_to_reflection,
    project_admissible,
    reflection_to_poly,
)
from hystid.identify.offline import fit_output_error, output_sensitivities
from hystid.reference import PAPER_PARAMS, reference_model, reference_record

TRUTH = np.array(list(PAPER_PARAMS.values()))


def max_rel_error(model) -> float:
    return float(np.max(np.abs(model.theta - TRUTH) / np.abs(TRUTH)))


def test_recovers_reference_stage_to_0p1_percent_from_0p01():
    rec = reference_record(1.0, seed=0, noise=1e-3)  # 30 000 samples, 1 nm noise
    result = fit_output_error(rec, theta0=0.01)
    assert result.model.is_stable()
    assert max_rel_error(result.model) < 1e-3
    assert result.info["rms_residual"] == pytest.approx(1e-3, rel=0.05)  # down to the noise


def test_short_record_recovered_thanks_to_linear_start():
    rec = reference_record(1.0, seed=2, noise=1e-3)[:1000]
    with_start = fit_output_error(rec, offset=False)
    without = fit_output_error(rec, linear_init=False, offset=False)
    assert max_rel_error(with_start.model) < 4e-3
    assert with_start.info["rms_residual"] <= without.info["rms_residual"] + 1e-12
    # the sensor offset estimated besides (the default) costs a little on 1 000 samples
    assert max_rel_error(fit_output_error(rec).model) < 6e-3


def test_identify_entry_point_and_bad_method():
    rec = reference_record(0.05, seed=1)
    assert identify(rec, "batch").method == "batch"
    with pytest.raises(ValueError, match="method"):
        identify(rec, "magic")


def test_sensitivities_match_finite_differences():
    s = Structure(n1a=2, n1b=1, n2a=2, n2b=1, q1=1, q2=1, f0=True)
    theta = np.array([0.2, 0.7, 0.03, 0.13, 0.3, 0.01, -0.5, 0.05, -1.5, 0.85])
    u = reference_record(0.02, seed=4).u
    y, S = output_sensitivities(theta, s, u)
    for p in range(len(theta)):
        h = 1e-6 * max(1.0, abs(theta[p]))
        tp, tm = theta.copy(), theta.copy()
        tp[p] += h
        tm[p] -= h
        fd = (output_sensitivities(tp, s, u)[0] - output_sensitivities(tm, s, u)[0]) / (2 * h)
        np.testing.assert_allclose(S[:, p], fd, rtol=1e-4, atol=1e-6 * np.max(np.abs(fd)) + 1e-9)


def test_reflection_coefficients_round_trip_and_jacobian():
    rng = np.random.default_rng(0)
    k = rng.uniform(-0.95, 0.95, 4)
    c, dc = reflection_to_poly(k)
    np.testing.assert_allclose(poly_to_reflection(c), k, rtol=1e-10)
    assert np.all(np.abs(np.roots(np.r_[1.0, c])) < 1)
    for i in range(4):
        e = np.zeros(4)
        e[i] = 1e-7
        fd = (reflection_to_poly(k + e)[0] - reflection_to_poly(k - e)[0]) / 2e-7
        np.testing.assert_allclose(dc[:, i], fd, rtol=1e-6, atol=1e-9)


def test_projection_makes_an_unstable_vector_admissible():
    s = Structure()
    bad = TRUTH.copy()
    bad[s.names.index("a22")] = 1.3
    bad[s.names.index("alpha")] = -1.0
    assert not is_admissible(bad, s)
    fixed = project_admissible(bad, s)
    assert is_admissible(fixed, s)
    assert DuhemSandwich(fixed).is_stable()
    np.testing.assert_array_equal(project_admissible(TRUTH, s), TRUTH)


def test_reference_stage_output_range_matches_the_paper():
    rec = reference_record(1.0, seed=0, noise=0.0)
    y = rec.y[51:]
    assert 3.0 < np.percentile(y, 1) and np.percentile(y, 99) < 6.5
    assert reference_model().params["alpha"] * reference_model().simulate(rec.u).duhem_margin < 2
