"""The stepped moving-horizon re-solve (hystid.identify.horizon) on a model of its own.

The model here is a first-order filter ``yhat(k) = a yhat(k-1) + b u(k-1)`` in ``phi = [a, b]``,
written for this test (not a hystid model), with its exact gradient.
"""

import numpy as np
import pytest

from hystid.identify import horizon
from hystid.identify.horizon import SLICE, TRIAL, HorizonSolve, drain, fold_steps, run_steps


def simulate(phi, st, u, y, J, err):
    # st = [yhat(k-1), u(k-1), d yhat(k-1)/da, d yhat(k-1)/db]
    a, b = phi
    for k in range(len(u)):
        yh = a * st[0] + b * st[1]
        da = st[0] + a * st[2]
        db = st[1] + a * st[3]
        J[k] = da, db
        err[k] = y[k] - yh if np.isfinite(y[k]) else np.nan
        st[:] = yh, u[k], da, db


def admissible(trial, phi):
    return abs(trial[0]) < 1.0


def record(n, seed, a=0.9, b=0.5, noise=0.01, outliers=0):
    rng = np.random.default_rng(seed)
    u = np.repeat(rng.uniform(-1, 1, n // 20 + 1), 20)[:n]  # a held random level, not white
    y = np.zeros(n)
    prev = 0.0
    for k in range(1, n):
        prev = a * prev + b * u[k - 1]
        y[k] = prev
    y = y + noise * rng.standard_normal(n)
    if outliers:
        y[rng.choice(n, outliers, replace=False)] = np.nan
    return u, y


def chunks_of(u, y, size):
    return [(u[i:i + size], y[i:i + size]) for i in range(0, len(u), size)]


def job(u, y, start, leaving=0, iterations=8):
    arrival = (np.zeros(2), np.eye(2) * 1e-6)
    return HorizonSolve(simulate, admissible, chunks_of(u, y, 300), np.zeros(4), arrival,
                        [start, np.array([0.5, 0.1])], iterations, leaving=leaving,
                        linearised_at=np.array([0.85, 0.45]) if leaving else None)


def test_the_window_is_solved_to_the_stage_that_made_it():
    u, y = record(3000, seed=1, outliers=30)
    res = job(u, y, np.array([0.3, 1.5]), iterations=30).result()
    np.testing.assert_allclose(res.phi, [0.9, 0.5], atol=0.01)
    # the information is J'J + R_a at the estimate, the state the model's at the window's end
    err, J, st = drain(run_steps(simulate, res.phi, np.zeros(4), u, y))
    seen = np.isfinite(err)
    np.testing.assert_allclose(res.information, J[seen].T @ J[seen] + np.eye(2) * 1e-6,
                               rtol=1e-9)
    np.testing.assert_allclose(res.state, st, rtol=1e-12)
    # better than the static line through the data (a baseline any fit must beat)
    line = np.polyfit(u[seen], y[seen], 1)
    static = np.sqrt(np.mean((y[seen] - np.polyval(line, u[seen])) ** 2))
    assert np.sqrt(np.mean(err[seen] ** 2)) < 0.2 * static


@pytest.mark.parametrize("grant", [1.0, 37.0, float(SLICE), 1e9])
def test_the_estimate_does_not_depend_on_how_the_work_is_granted(grant):
    u, y = record(3000, seed=2)
    feed_u, feed_y = record(700, seed=3)
    whole = job(u, y, np.array([0.2, 1.0]), leaving=2)
    whole.feed(feed_u, feed_y)
    ref = whole.result()
    stepped = job(u, y, np.array([0.2, 1.0]), leaving=2)
    rng = np.random.default_rng(4)
    fed, calls = 0, 0
    while not stepped.solved or fed < len(feed_u):
        m = int(rng.integers(1, 40)) if fed < len(feed_u) else 0
        stepped.feed(feed_u[fed:fed + m], feed_y[fed:fed + m])
        fed += m
        before = stepped.spent
        stepped.advance(grant)
        # a call does at most the work granted and one step more (and the samples fed)
        assert stepped.spent - before <= grant + max(SLICE, TRIAL, m) + 1e-9
        calls += 1
    res = stepped.result()
    for name in ("phi", "state", "information", "start"):
        assert np.array_equal(getattr(res, name), getattr(ref, name)), name
    assert np.array_equal(res.arrival[0], ref.arrival[0]) and res.cost == ref.cost
    assert calls > 1


def test_folding_a_chunk_keeps_what_it_said_about_the_parameters(monkeypatch):
    # the arrival cost after folding the first 1500 samples, with the rest solved, gives the
    # estimate of the whole record solved at once (the model is nearly linear in phi there);
    # both solved to the end (no early stop)
    monkeypatch.setattr(horizon, "RTOL", 0.0)
    u, y = record(3000, seed=5, noise=0.02)
    whole = job(u, y, np.array([0.9, 0.5]), iterations=12).result()
    phi0 = whole.phi
    arrival, st = (np.zeros(2), np.zeros((2, 2))), np.zeros(4)
    for cu, cy in chunks_of(u[:1500], y[:1500], 300):
        arrival, st = drain(fold_steps(simulate, phi0, st, arrival, cu, cy))
    rest = HorizonSolve(simulate, admissible, chunks_of(u[1500:], y[1500:], 300), st, arrival,
                        [phi0], 12).result()
    np.testing.assert_allclose(rest.phi, phi0, rtol=1e-6)


def test_a_start_stops_once_its_steps_gain_next_to_nothing(monkeypatch):
    # from the optimum the first step's predicted gain is below RTOL of the cost: one
    # simulation and the normal equations, no trial simulated; with RTOL = 0 every trial runs
    u, y = record(3000, seed=7)
    opt = job(u, y, np.array([0.2, 1.0]), iterations=40).result().phi
    spent, default = {}, horizon.RTOL
    assert default > 0
    for rtol in (default, 0.0):
        monkeypatch.setattr(horizon, "RTOL", rtol)
        one = HorizonSolve(simulate, admissible, chunks_of(u, y, 300), np.zeros(4),
                           (np.zeros(2), np.eye(2) * 1e-6), [opt], 12)
        res = one.result()
        spent[rtol] = one.spent
        np.testing.assert_allclose(res.phi, opt, rtol=1e-4)
    assert spent[default] < 0.3 * spent[0.0]


def test_leaving_chunks_need_a_point_to_fold_at():
    u, y = record(600, seed=6)
    with pytest.raises(ValueError, match="linearised_at"):
        HorizonSolve(simulate, admissible, chunks_of(u, y, 300), np.zeros(4),
                     (np.zeros(2), np.eye(2)), [np.array([0.5, 0.5])], 4, leaving=1)
