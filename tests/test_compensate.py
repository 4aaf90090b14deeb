"""Hysteresis compensation: the per-sample Duhem inverse, the inverse sandwich as a python-control
system, input limits without windup, the feedback design's margins, the closed loop."""

import control as ct
import numpy as np
import pytest

import hystid.compensate as hc
from hystid import DuhemSandwich, Structure
from hystid.compensate import duhem_inverse as di
from hystid.reference import PAPER_PARAMS, reference_model

A2 = 1.0 + PAPER_PARAMS["a21"] + PAPER_PARAMS["a22"]  # 1 / L2(1) of the reference stage


@pytest.fixture(scope="module")
def stage():
    return reference_model()


@pytest.fixture(scope="module")
def design(stage):
    return hc.design_feedback(stage)


def _smoother(model, frequency):
    # corners of a triangle rounded over about 1/150 of a period (odd length, at least 7)
    n = max(7, int(model.fs / frequency / 150) | 1)
    return hc.smoothing_model(n, model.dt)


# --------------------------------------------------------------------------- eq. (7) inverse
def test_duhem_solutions_satisfy_eq7_and_follow_the_existence_rule():
    rng = np.random.default_rng(0)
    p = PAPER_PARAMS
    alpha, f1, g0 = p["alpha"], p["f1"], p["g0"]
    counts = {0: 0, 1: 0, 2: 0}
    for _ in range(2000):
        w1p = rng.uniform(-5, 20)
        w2p = f1 * w1p + rng.uniform(-0.2, 0.2)
        w2d = w2p + rng.normal(0, 0.01)
        n, near, far = di.duhem_solutions(w2d, w1p, w2p, alpha, 0.0, f1, g0)
        G = f1 * w1p - w2p
        for d in [near, far][:n]:
            assert di.duhem_forward(w1p + d, w1p, w2p, alpha, 0.0, f1, g0) == \
                pytest.approx(w2d, abs=1e-13)
        if n == 2:
            assert abs(near) <= abs(far) and np.sign(near) != np.sign(far)
        # alpha |G| < g0: phi is a bijection, exactly one solution
        expected = 1 if alpha * abs(G) < g0 else (2 if np.sign(w2d - w2p) == np.sign(G) else 0)
        assert n == expected
        counts[n] += 1
    assert min(counts.values()) > 20  # every case was exercised


def test_stage_within_assumption_2_is_inverted_causally_and_exactly():
    # f1 <= 2 g0 (Assumption 2, condition 3): the gap stays in the band, the inverse is unique
    model = DuhemSandwich({**PAPER_PARAMS, "f1": 0.1, "g0": 0.06}, fs=30_000.0)
    ref = hc.scan_reference("sine", 100, periods=3)
    ff = hc.feedforward(model, ref.y, preview=0, reference_model="exact", u_limits=(0, 100),
                        full_output=True)
    y = model.simulate(ff.u).y
    assert np.all(ff.exact)
    assert np.max(np.abs(y - ref.y)) < 1e-9


def test_causal_inverse_cannot_prepare_reversals_on_the_paper_stage(stage):
    ref = hc.scan_reference("sine", 50)
    causal = hc.feedforward(stage, ref.y, preview=0, full_output=True)
    planned = hc.feedforward(stage, ref.y, full_output=True)
    assert np.any(causal.status & di.UNREACHABLE)
    assert np.all(planned.exact)


@pytest.mark.parametrize("f0", [0.0, 0.02])
def test_planner_memo_gives_plan_steps_results_bit_for_bit(f0):
    """plan_memo over a moving window (the state mostly where the last near step put it, at
    times pushed off as a saturated command does, or held) against plan_step from scratch."""
    p = PAPER_PARAMS
    alpha, f1, g0, bound = p["alpha"], p["f1"], p["g0"], hc.DUHEM_BOUND
    rng = np.random.default_rng(1)
    n, steps = 301, 5_000
    t = np.arange(steps + n) / 30_000.0
    w = 1.5 * np.sin(2 * np.pi * 50 * t) + 0.4 * np.sin(2 * np.pi * 170 * t)
    w[2_500:] += np.cumsum(rng.normal(0.0, 0.004, w.size - 2_500))  # fragmented sets
    mi, mf, ms = di.planner_memo(n)
    w1p = w2p = 0.0
    seen = {"far": 0, "unreachable": 0, "bound": 0, "off": 0}
    hold = 0
    for k in range(steps):
        W = w[k:k + n]
        fresh = di.plan_step(W, w1p, w2p, alpha, f0, f1, g0, bound)
        kept = di.plan_memo(W, w1p, w2p, alpha, f0, f1, g0, bound, mi, mf, ms)
        assert kept == fresh, k
        d, status, far = fresh
        seen["far"] += far
        seen["unreachable"] += status == di.UNREACHABLE
        seen["bound"] += status == di.BOUND
        w1 = w1p + d
        if hold or rng.random() < 0.02:  # off the planned path, for a while
            hold = hold - 1 if hold else int(rng.integers(0, 30))
            w1 = w1p + rng.normal(0.0, 0.02) if rng.random() < 0.5 else w1p
            seen["off"] += 1
        w2p = di.duhem_forward(w1, w1p, w2p, alpha, f0, f1, g0)
        w1p = w1
    assert min(seen.values()) > 5, seen


# --------------------------------------------------------------------------- composition
@pytest.mark.parametrize("kind", ["triangle", "sine"])
@pytest.mark.parametrize("frequency", [10, 50, 200])
def test_inverse_composed_with_the_model_reproduces_the_reference(stage, kind, frequency):
    ref = hc.scan_reference(kind, frequency, periods=1.5)
    M = _smoother(stage, frequency) if kind == "triangle" else "exact"
    ff = hc.feedforward(stage, ref.y, reference_model=M, full_output=True)
    sim = stage.simulate(ff.u)
    assert np.all(ff.exact), "limits hit or a step not exact"
    assert np.max(np.abs(sim.y - ff.yd)) < 1e-9
    if M == "exact":
        assert np.max(np.abs(sim.y - ref.y)) < 1e-9
    # condition (8) with the default margin
    assert stage.params["alpha"] * sim.duhem_margin <= hc.DUHEM_BOUND + 1e-12
    # the static-gain inverse of L2 (the default) makes w2 exact
    static = hc.feedforward(stage, ref.y, full_output=True)
    assert np.all(static.exact)
    assert np.max(np.abs(stage.simulate(static.u).w2 - A2 * ref.y)) < 1e-9


def test_python_control_inverse_matches_the_compiled_one(stage):
    ref = hc.scan_reference("triangle", 200, periods=1.2, lead_in=0.004)
    M = _smoother(stage, 200)
    inv = hc.inverse(stage, reference_model=M)
    assert isinstance(inv, ct.NonlinearIOSystem) and inv.isdtime()
    resp = ct.input_output_response(inv, ref.t, inv.reference_input(ref.y),
                                    X0=inv.initial_state(ref.y))
    ff = hc.feedforward(stage, ref.y, reference_model=M, full_output=True)
    assert np.max(np.abs(resp.outputs[0] - ff.u)) < 1e-12
    assert np.max(np.abs(resp.outputs[1] - ff.yd)) < 1e-12
    # composed with the python-control stage: y = yd
    cl = hc.closed_loop(stage, None, True, reference_model=M, noise_input=False)
    out = hc.closed_loop_response(cl, ref.y)
    assert np.all((out.status & hc.NOT_EXACT) == 0)
    assert np.max(np.abs(out.y - out.yd)) < 1e-9


def test_pi_sandwich_inverse_is_exact():
    from hystid.pi import PISandwich, PIStructure, pi_thresholds

    s = PIStructure(n_operators=12)
    p = dict.fromkeys(s.names, 0.0)
    p.update({"a11": -0.529, "b12": 0.1, "a21": -1.6049, "a22": 0.9226, "b22": -0.05})
    mu = np.r_[0.5, 0.06 * np.exp(-np.arange(1, 12) / 4)]
    p.update({f"mu{i}": v for i, v in enumerate(mu)})
    model = PISandwich(p, pi_thresholds((0, 10), 12), s)
    ref = hc.scan_reference("triangle", 50, periods=1.5)
    for M, q2 in ((None, 1), ("exact", 0)):
        ff = hc.feedforward(model, ref.y, reference_model=M, u_limits=(-20, 20),
                            full_output=True)
        sim = model.simulate(ff.u)
        assert np.all(ff.exact) and ff.preview == 0
        if M is None:  # static gain of L2 = 1: w2(k) = y_ref(k + q2)
            assert np.max(np.abs(sim.w2[1:-q2] - ref.y[1 + q2:])) < 1e-9
        else:
            assert np.max(np.abs(sim.y[2:] - ref.y[2:])) < 1e-9


# --------------------------------------------------------------------------- limits
def test_limits_are_respected_and_the_inverse_recovers_at_once(stage):
    # the sine asks for more than the 10 V amplifier gives near its top (about 8.5 um)
    ref = hc.scan_reference("sine", 20, periods=2, high=9.6)
    ff = hc.feedforward(stage, ref.y, full_output=True)
    assert np.all((ff.u >= 0.0) & (ff.u <= 10.0))
    saturated = (ff.status & hc.SATURATED) > 0
    assert saturated.sum() > 100
    w2_error = np.abs(stage.simulate(ff.u).w2 - A2 * ref.y)
    hit = np.r_[False, saturated[:-1]]  # u(k) acts on w1(k+1), w2(k+1) (q1 = 1)
    # no windup: exact again from the first sample after each saturated stretch
    assert np.all(w2_error[~hit] < 1e-9)
    assert np.max(w2_error[hit]) > 0.1


def test_feedback_anti_windup_recovers_after_saturation(stage, design):
    ref = hc.scan_reference("sine", 20, periods=2, high=9.6)
    with_aw = hc.simulate_closed_loop(stage, ref.y, design, feedforward=False)
    plain = hc.simulate_closed_loop(stage, ref.y, design.controller, feedforward=False)
    assert np.all((with_aw.u >= 0.0) & (with_aw.u <= 10.0))
    inside = np.arange(len(ref.y)) >= ref.skip
    inside &= ref.y < 8.0  # within the stroke, after the saturated stretches
    err_aw = np.max(np.abs(with_aw.y - with_aw.yd)[inside])
    err_plain = np.max(np.abs(plain.y - plain.yd)[inside])
    assert err_plain > 5 * err_aw


# --------------------------------------------------------------------------- feedback
@pytest.mark.filterwarnings("ignore:stability_margins:UserWarning")
def test_feedback_design_has_the_stated_margins(stage, design):
    gm, pm, sm, wpc, wgc, _ = ct.stability_margins(design.loop)
    assert design.phase_margin == pytest.approx(pm) and pm >= 60.0
    assert design.gain_margin == pytest.approx(gm) and 20 * np.log10(gm) >= 10.0
    assert design.crossover_hz == pytest.approx(wgc / (2 * np.pi))
    poles = ct.feedback(design.controller * design.plant, 1).poles()
    assert np.max(np.abs(poles)) < 1.0
    assert np.max(np.abs(design.closed_loop_poles)) < 1.0
    # the gain margin is what it says: stable just below it, unstable just above
    for factor, stable in ((0.95, True), (1.05, False)):
        p = ct.feedback(factor * gm * design.loop, 1).poles()
        assert (np.max(np.abs(p)) < 1.0) == stable
    controller, gm_db, pm_deg = design
    assert controller is design.controller and gm_db == design.gain_margin_db


def test_anti_windup_realisation_is_the_controller(design):
    aw = design.anti_windup()
    assert aw.input_labels == ["e", "du"] and aw.output_labels == ["u_fb"]
    z = np.exp(2j * np.pi * np.array([5.0, 300.0, 2500.0]) * design.dt)
    assert np.allclose(ct.ss2tf(aw[0, 0])(z), design.controller(z), rtol=1e-9)


def test_design_without_notch_is_slower_and_infeasible_margins_raise(stage):
    plain = hc.design_feedback(stage, notch=False)
    assert plain.notch is None and plain.gain_margin_db >= 10.0
    with pytest.raises(ValueError, match="no crossover meets"):
        hc.design_feedback(stage, notch=False, phase_margin=89.9, gain_margin=60.0)


# --------------------------------------------------------------------------- closed loop
def test_feedback_holds_while_the_compensator_turns_the_hysteresis(stage):
    # controllers from an identified model (0.1 s of noisy data), driving the true stage
    from hystid.identify import fit_output_error
    from hystid.reference import reference_record

    model = fit_output_error(reference_record(seconds=0.1, seed=0)).model
    design = hc.design_feedback(model)
    ref = hc.scan_reference("sine", 10)
    held = hc.simulate_closed_loop(model, ref.y, design, plant=stage)
    free = hc.simulate_closed_loop(model, ref.y, design, plant=stage, hold_while_turning=False)
    assert np.any(held.status & hc.TURNING)
    assert np.all(held.e[(held.status & hc.TURNING) > 0] == 0.0)
    # an integrator running while the stage's incremental gain is ~0 or negative winds up and
    # releases an overshoot after the turn
    assert free.metrics(ref.skip).max_error > 5 * held.metrics(ref.skip).max_error


def test_compiled_closed_loop_matches_python_control(stage, design):
    ref = hc.scan_reference("triangle", 200, periods=1, lead_in=0.004)
    noise = 2e-3 * np.random.default_rng(1).standard_normal(len(ref.y))
    for ff in (True, False):
        cl = hc.closed_loop(stage, design, ff)
        assert isinstance(cl, ct.InterconnectedSystem)
        slow = hc.closed_loop_response(cl, ref.y, noise=noise)
        fast = hc.simulate_closed_loop(stage, ref.y, design, feedforward=ff, noise=noise)
        for name in ("y", "u", "u_fb", "e"):
            assert np.max(np.abs(getattr(slow, name) - getattr(fast, name))) < 1e-10, name


def test_the_two_closed_loops_agree_on_a_placed_model(stage, design):
    """A model with a rest level and a sensor offset: the python-control loop's stage carried
    the offset into the loop's error (the compensator's desired output does not), and the
    two loops, the same loop, differed by about the offset (an independently simulated
    Bouc-Wen stage: 63 nm against 329). Both now run about the model's rest."""
    import copy

    placed = copy.copy(stage)
    placed.u_rest, placed.offset = 2.0, 0.4
    ref = hc.scan_reference("triangle", 200, periods=1, lead_in=0.004)
    slow = hc.closed_loop_response(hc.closed_loop(placed, design), ref.y)
    fast = hc.simulate_closed_loop(placed, ref.y, design)
    for name in ("y", "u", "e"):
        assert np.max(np.abs(getattr(slow, name) - getattr(fast, name))) < 1e-10, name
    assert abs(slow.y[0]) < 1e-12  # about the rest: the offset is not in the loop
    # the figures in the model's units: a model in metres was shown in nm as if in um
    assert "nm" in str(fast.metrics(50))
    placed.units = {"u": "V", "y": "m"}
    for run in (hc.simulate_closed_loop(placed, ref.y, design),
                hc.closed_loop_response(hc.closed_loop(placed, design), ref.y)):
        shown = str(run.metrics(50))
        assert " m," in shown and "nm" not in shown, shown


def test_feedforward_cuts_the_hysteresis_error_tenfold(stage, design):
    for frequency in (10, 50):
        ref = hc.scan_reference("triangle", frequency)
        M = _smoother(stage, frequency)
        # same inversion of L1 and L2 in both: the difference is the hysteresis
        comp = hc.feedforward(stage, ref.y, reference_model=M, full_output=True)
        base = hc.linear_feedforward(stage, ref.y, reference_model=M, full_output=True)
        e_comp = (stage.simulate(comp.u).y - comp.yd)[ref.skip:]
        e_base = (stage.simulate(base.u).y - base.yd)[ref.skip:]
        ratio_max = np.max(np.abs(e_base)) / max(np.max(np.abs(e_comp)), 1e-15)
        assert ratio_max >= 10.0
        # and with the default (static) L2 inverse, against the raw triangle
        comp = hc.tracking_metrics(ref.y, stage.simulate(hc.feedforward(stage, ref.y)).y,
                                   skip=ref.skip)
        base = hc.tracking_metrics(ref.y, stage.simulate(hc.linear_feedforward(stage, ref.y)).y,
                                   skip=ref.skip)
        assert base.rms_error / comp.rms_error >= 10.0
        assert base.loop_width / comp.loop_width >= 10.0
        # feedback on top keeps it there
        both = hc.simulate_closed_loop(stage, ref.y, design).metrics(ref.skip)
        assert base.rms_error / both.rms_error >= 10.0


# --------------------------------------------------------------------------- metrics, input
def test_tracking_metrics_measure_a_known_loop():
    ref = hc.scan_reference("triangle", 100, periods=3)
    slope = np.gradient(ref.y)
    y = ref.y + 0.25 * np.sign(slope)  # rising branch 0.25 above, falling 0.25 below
    m = hc.tracking_metrics(ref.y, y, skip=ref.skip)
    assert m.max_error == pytest.approx(0.25)
    assert m.rms_error == pytest.approx(0.25, rel=1e-2)  # 0 at the corners
    assert m.loop_width == pytest.approx(0.5)
    assert hc.tracking_metrics(ref.y, ref.y, skip=ref.skip).loop_width == 0.0


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"duhem_bound": 2.0}, "duhem_bound"),
        ({"u_limits": (10, 0)}, "u_limits"),
        ({"preview": -1}, "preview"),
        ({"reference_model": "fast"}, "reference_model"),
        ({"reference_model": ct.tf([1], [1, 0], 1e-3)}, "dt"),
        ({"reference_lead": 3}, "reference_lead"),
    ],
)
def test_bad_settings_are_named(stage, kwargs, match):
    with pytest.raises(ValueError, match=match):
        hc.inverse(stage, **kwargs)


def test_bad_signals_and_models_are_named(stage):
    with pytest.raises(ValueError, match="y_ref.*sample 3"):
        hc.feedforward(stage, [0.0, 0.1, 0.2, np.nan, 0.3])
    not_min_phase = DuhemSandwich({**PAPER_PARAMS, "b21": 1.5},
                                  Structure(n2b=1), fs=30_000.0)
    with pytest.raises(ValueError, match="L2 is not minimum phase"):
        hc.inverse(not_min_phase, reference_model="exact")
    with pytest.raises(ValueError, match="kind"):
        hc.scan_reference("square", 10)
    with pytest.raises(ValueError, match="plant"):
        hc.simulate_closed_loop(stage, [0.0, 0.1], plant=ct.tf([1], [1, 0], stage.dt))


# --------------------------------------------------------------------------- kernel caching
def test_source_stamp_follows_the_kernels_called_in_other_modules(tmp_path, monkeypatch):
    # the cached compensator kernels close over this stamp: it must change when a kernel they
    # reach through another module changes, and only then
    from hystid.compensate.compensator import source_stamp

    (tmp_path / "stamp_leaf.py").write_text(
        "from numba import njit\n\n@njit(cache=True)\ndef leaf(x):\n    return x + 1.0\n")
    (tmp_path / "stamp_mid.py").write_text(
        "from numba import njit\nfrom stamp_leaf import leaf\n\n"
        "@njit(cache=True)\ndef mid(x):\n    return 2.0 * leaf(x)\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    import importlib

    import stamp_mid

    first = source_stamp(stamp_mid.mid)
    assert source_stamp(stamp_mid.mid) == first
    leaf = tmp_path / "stamp_leaf.py"
    leaf.write_text(leaf.read_text().replace("x + 1.0", "x + 2.0"))
    importlib.reload(importlib.import_module("stamp_leaf"))
    importlib.reload(stamp_mid)
    assert source_stamp(stamp_mid.mid) != first


def test_compensator_kernels_are_cached():
    from hystid.compensate import closedloop, compensator

    for kernel in (compensator.chain_step, compensator.chain_run, closedloop._run_loop):
        assert kernel._cache.__class__.__name__ == "FunctionCache", kernel
        assert kernel.py_func.__closure__, "the source stamp is not in the cache key"


def test_closed_loop_response_is_a_labelled_control_response(stage):
    ref = hc.scan_reference("triangle", 200, periods=1)
    out = hc.simulate_closed_loop(stage, ref.y, None)
    assert isinstance(out, ct.TimeResponseData)
    assert out.input_labels == ["y_ref"]
    assert out.output_labels == ["y", "u", "yd", "e", "u_ff", "u_fb", "status"]
    np.testing.assert_array_equal(out.y_ref, ref.y)  # the input, not the output u
    frame = out.to_pandas()
    np.testing.assert_array_equal(frame["u"], out.u)
    np.testing.assert_array_equal(frame["y"], out.y)
    assert out.status.dtype == np.int64 and out.outputs.shape == (7, len(ref.y))
    t, y = out
    np.testing.assert_array_equal(y[0], out.y)  # python-control's layout: signal, time
