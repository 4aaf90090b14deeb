"""The augmented sandwich's compiled sensitivities (hystid/diagnose/sensitivities.py) against
central differences of the simulation without them, for every effect form, with the nominal
parameters held and free, on a stage-A-like record (hystid.testing: an independent Bouc-Wen
stage); and the folded refit against the forward-difference one."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from hystid.diagnose import refit as refit_mod
from hystid.diagnose.effects import EFFECT_NAMES, EFFECTS
from hystid.diagnose.parametrisation import Parametrisation
from hystid.diagnose.refit import FitData, _Problem, refit, simulate_fit_data
from hystid.identify.offline import fit_output_error
from hystid.model import Structure
from hystid.testing.measured import stage_a_like

#: A structure with every polynomial and delay the kernels read (numerators, f0, q2).
RICH = Structure(n1a=1, n1b=1, n2a=2, n2b=1, q1=1, q2=1, f0=True)


@pytest.fixture(scope="module")
def stage():
    rec = stage_a_like("prbn", seconds=0.3, rest_seconds=0.05)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        model = fit_output_error(rec, RICH, max_nfev=30).model
    u = rec.u - model.u_rest
    phi0 = np.zeros(30)
    phi0[12] = model.offset
    data = FitData(u, rec.y, rec.fs, level=float(np.mean(rec.y[:100])))
    w1 = simulate_fit_data(model, phi0, data)[0].copy()
    scales = float(np.max(np.abs(np.diff(w1)))), float(np.max(np.abs(w1)))
    return rec, model, data, phi0, scales


def _values(form, rec, u, scales):
    step, level = scales
    # the fastest input steps but the last sample's (the record wraps it back to the first)
    du = float(np.max(np.abs(np.diff(u[:-1]))))
    return {
        "creep": {"gain": 0.05, "tau": 0.02},
        "creep_2tau": {"gain": 0.03, "tau": 0.01, "gain2": 0.02, "tau2": 0.05},
        "creep_log": {"gain": 0.05, "tau": 0.002},
        "drift": {"rate": 0.1, "accel": 0.2, "jerk": 0.3},
        "extra_mode": {"gain": 0.1, "freq": 300.0, "zeta": 0.05},
        "mode_series": {"gain": 0.3, "freq": 500.0, "zeta": 0.1},
        "delay": {"samples": 2.3},
        "asymmetry": {"alpha": 0.1, "g0": -0.1, "f1": 0.05},
        "asymmetry_input": {"alpha": 0.1, "g0": -0.1, "f1": 0.05},
        "loop_level": {"alpha": 0.1 / level, "g0": 0.05 / level},
        # rate limits that bind on the fastest samples
        "slew_limit": {"inv_rate": 1.0 / (0.7 * step * rec.fs)},
        "slew_input": {"inv_rate": 1.0 / (0.5 * du * rec.fs)},
        "saturation": {"cubic": 0.1 / level**2},
        "output_curve": {"quadratic": 0.05, "cubic": 0.03, "centre": float(np.mean(rec.y)),
                         "span": float(np.ptp(rec.y))},
        "offset": {},
    }[form]


def _worst_error(problem: _Problem, z: np.ndarray) -> float:
    """Largest relative difference, column by column, of the compiled Jacobian from central
    differences of the residual simulated without sensitivities."""
    J = problem.tall(z)[:-1]
    worst = 0.0
    for i in range(len(z)):
        h = 1e-6 * max(abs(z[i]), 1.0)
        zp, zm = z.copy(), z.copy()
        zp[i] += h
        zm[i] -= h
        fd = (problem(zp)[:-1] - problem(zm)[:-1]) / (2 * h)
        scale = np.linalg.norm(fd)
        assert scale > 0, f"column {i} has no effect on the output"
        worst = max(worst, float(np.linalg.norm(J[:, i] - fd) / scale))
    return worst


@pytest.mark.parametrize("form", EFFECT_NAMES)
@pytest.mark.parametrize("free", [False, True])
def test_sensitivities_match_differences(stage, form, free):
    rec, model, data, phi0, scales = stage
    phi = phi0.copy()
    for p, s in zip(EFFECTS[form].params, EFFECTS[form].slots, strict=True):
        phi[s] = _values(form, rec, data.u, scales).get(p, phi[s])
    par = Parametrisation(model, [form], 0.35, *scales, free_theta=free)
    problem = _Problem(model, data, par, phi)
    z = par.to_z(model.theta, phi)
    ev = problem.evaluate(z)
    # the simulation with sensitivities gives the residual of the one without, bit for bit
    np.testing.assert_array_equal(ev["r"], problem(z))
    assert _worst_error(problem, z) < 1e-6


@pytest.mark.parametrize("form", ["slew_limit", "slew_input"])
def test_rate_limits_bind(stage, form):
    """The rate-limit cases above are not vacuous: the limit holds on some samples."""
    rec, model, data, phi0, scales = stage
    phi = phi0.copy()
    slot = EFFECTS[form].slots[0]
    phi[slot] = _values(form, rec, data.u, scales)["inv_rate"]
    base = simulate_fit_data(model, phi0, data)[2].copy()
    limited = simulate_fit_data(model, phi, data)[2]
    assert np.max(np.abs(limited - base)) > 1e-3 * np.ptp(base)


def test_at_rest_from_zero_and_barrier(stage):
    """No level rule (past at zero), and the barrier's row where condition (8) is over its
    limit: both against central differences."""
    rec, model, data, phi0, scales = stage
    data0 = FitData(data.u, data.y, data.fs, level=None)
    phi = phi0.copy()
    phi[[8, 9, 13]] = 0.1, -0.1, 0.05
    par = Parametrisation(model, ["asymmetry"], 0.35, *scales)
    problem = _Problem(model, data0, par, phi)
    z = par.to_z(model.theta, phi)
    assert _worst_error(problem, z) < 1e-6
    # alpha large enough for the barrier to act
    alpha = par.ialpha
    for factor in (1.0, 4.0, 30.0):
        zb = z.copy()
        zb[alpha] = z[alpha] * factor
        ev = problem.evaluate(zb)
        if ev["r"][-1] > 0:
            break
    assert ev["r"][-1] > 0, "no alpha tried puts condition (8) over its limit"
    J = problem.tall(zb)[-1]
    for i in range(len(zb)):
        h = 1e-7 * max(abs(zb[i]), 1.0)
        zp, zm = zb.copy(), zb.copy()
        zp[i] += h
        zm[i] -= h
        fd = (problem(zp)[-1] - problem(zm)[-1]) / (2 * h)
        assert abs(J[i] - fd) <= 1e-5 * max(np.max(np.abs(J)), 1e-300)


def test_folded_refit_agrees_with_differences(stage, monkeypatch):
    """A refit with the folded sensitivities reaches the cost of the forward-difference one
    (to the solver's tolerance) in fewer simulations."""
    rec, model, data, phi0, scales = stage
    start = phi0.copy()
    start[[0, 1]] = 0.01, 0.02
    out = {}
    for mode in ("2-point", "folded"):
        monkeypatch.setattr(refit_mod, "JACOBIAN", mode)
        out[mode] = refit(model, data, ["creep"], [start], step_scale=scales[0],
                          w1_scale=scales[1])
    fd, fo = out["2-point"], out["folded"]
    assert fd.ok and fo.ok
    assert fo.cost <= fd.cost * (1 + 1e-3)
    assert fo.nfev < fd.nfev


def test_folded_problem_has_the_tall_cost_gradient_and_gauss_newton_matrix(stage):
    """The folded triangle keeps ``|r|^2``, ``J'r`` and ``J'J`` of the rows it reduces, with
    samples out of the cost and a profiled stage."""
    rec, model, data, phi0, scales = stage
    keep = np.ones(len(data.u), bool)
    keep[[0, 5, 17, 400]] = False
    masked = FitData(data.u, data.y, data.fs, data.level, keep)
    phi = phi0.copy()
    phi[[0, 1]] = 0.05, 0.02
    profile = np.linalg.qr(np.random.default_rng(0).standard_normal((keep.sum(), 3)))[0]
    for free, prof in ((True, None), (False, profile)):
        par = Parametrisation(model, ["creep"], 0.35, *scales, free_theta=free)
        z = par.to_z(model.theta, phi)
        tall = _Problem(model, masked, par, phi, prof)
        J, r = tall.tall(z), tall.fun(z)
        folded = _Problem(model, masked, par, phi, prof)
        R, c = folded.folded_jac(z), folded.folded_fun(z)
        np.testing.assert_allclose(c @ c, r @ r, rtol=1e-10)
        np.testing.assert_allclose(R.T @ c, J.T @ r, rtol=1e-8, atol=1e-10 * np.abs(J.T @ r).max())
        np.testing.assert_allclose(R.T @ R, J.T @ J, rtol=1e-8, atol=1e-10 * np.abs(J.T @ J).max())
