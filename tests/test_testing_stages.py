"""The independent stage simulator: the paper stage, effects, transforms, look-alikes."""

import numpy as np
import pytest

from hystid.records import Record
from hystid.testing import (
    EFFECTS,
    PAPER,
    as_measured_suite,
    coloured_variations,
    crop_start,
    list_effects,
    make_hysteresis,
    paper_excitation,
    paper_like_stage,
    paper_stage,
    paper_stage_loop,
    repeats,
    simulate_at_rate,
    simulate_stage,
    stage_a_like,
    stage_b_like,
    with_end_glitch,
    with_noise,
    with_offset,
    with_outliers,
    with_units,
)

RAMP = 600  # 10 ms ramp plus 10 ms of settling at 30 kHz


@pytest.fixture(scope="module")
def paper_run():
    u = paper_excitation(1.0, seed=0)
    return u, paper_stage().simulate(u, u_rest=0.0)


def test_paper_stage_matches_literal_equations(paper_run):
    u, sim = paper_run
    lit = paper_stage_loop(u)
    np.testing.assert_allclose(sim["y"], lit["y"], rtol=0, atol=1e-12)
    like = paper_like_stage(30_000.0, "duhem").simulate(u, u_rest=0.0)
    np.testing.assert_allclose(like["y"], lit["y"], rtol=0, atol=1e-9)


def test_paper_output_span_and_stability(paper_run):
    u, sim = paper_run
    y = sim["y"][RAMP:]
    assert 3.5 < y.min() < 3.9
    assert 5.8 < y.max() < 6.2
    # condition (8): alpha |dw1| < 2 everywhere
    assert PAPER["alpha"] * np.abs(np.diff(sim["w1"])).max() < 1.0


def test_paper_branches_about_0157_apart(paper_run):
    _, sim = paper_run
    e = sim["w2"] - PAPER["f1"] * sim["w1"]
    dw = np.diff(sim["w1"])
    rising, falling = e[1:][dw > 0], e[1:][dw < 0]
    assert rising.min() == pytest.approx(-0.157, abs=0.006)
    assert falling.max() == pytest.approx(0.157, abs=0.006)


def test_static_gains_of_paper_stage():
    st = paper_stage()
    assert st.l1.dc_gain == pytest.approx(2.12, abs=0.01)
    assert st.l2.dc_gain == pytest.approx(3.15, abs=0.01)


def test_delayed_higher_order_stage_keeps_gains_and_delays_response():
    u = paper_excitation(0.05, seed=1)
    base = paper_stage().simulate(u, u_rest=0.0)["y"]
    st = paper_stage(n1=2, n2=3, q1=4, q2=1)
    assert st.l1.dc_gain == pytest.approx(paper_stage().l1.dc_gain)
    y = st.simulate(u, u_rest=0.0)["y"]
    assert np.all(y[:4] == 0.0)  # nothing arrives before q1 + q2 samples
    assert np.abs(y[-300:] - base[-300:]).max() > 0.01  # but it is another stage


def test_same_seed_is_bit_identical_other_seed_differs():
    a, b = paper_excitation(0.1, seed=3), paper_excitation(0.1, seed=3)
    assert np.array_equal(a, b)
    assert not np.array_equal(a, paper_excitation(0.1, seed=4))
    r1, r2 = stage_a_like("prbn", seconds=0.3, rest_seconds=0.1, seed=5), \
        stage_a_like("prbn", seconds=0.3, rest_seconds=0.1, seed=5)
    assert np.array_equal(r1.u, r2.u) and np.array_equal(r1.y, r2.y)
    s1 = simulate_stage(paper_excitation(0.05), effect="drift", form="walk", seed=9)
    s2 = simulate_stage(paper_excitation(0.05), effect="drift", form="walk", seed=9)
    s3 = simulate_stage(paper_excitation(0.05), effect="drift", form="walk", seed=10)
    assert np.array_equal(s1["y"], s2["y"]) and not np.array_equal(s1["y"], s3["y"])


@pytest.mark.parametrize("kind", ["bouc_wen", "preisach", "maxwell"])
def test_other_hysteresis_forms_are_paper_like_but_not_duhem(kind, paper_run):
    u, sim = paper_run
    y = paper_like_stage(30_000.0, kind).simulate(u, u_rest=0.0)["y"][RAMP:]
    ref = sim["y"][RAMP:]
    assert 1.5 < np.ptp(y) < 5.0  # about the paper's 2.3 um span
    assert abs(np.mean(y) - np.mean(ref)) < 1.0
    assert np.std(y - ref) > 0.05  # genuinely another stage


def test_bouc_wen_rate_dependence_widens_loops():
    t = np.arange(3000) / 30_000.0
    slow = 5.3 + np.sin(2 * np.pi * 20 * t)
    fast = 5.3 + np.sin(2 * np.pi * 500 * t)
    h = make_hysteresis("bouc_wen", rate=2.0)
    w_slow = h.response(2.12 * slow, 30_000.0, 2.12 * 5.3)
    w_fast = h.response(2.12 * fast, 30_000.0, 2.12 * 5.3)
    # residual from the best straight line measures the loop's opening
    def opening(x, w):
        c = np.polyfit(x[1500:], w[1500:], 1)
        return np.std(w[1500:] - np.polyval(c, x[1500:]))
    assert opening(fast, w_fast) > 1.2 * opening(slow, w_slow)


def test_effect_none_is_nominal_and_every_effect_changes_output():
    u = paper_excitation(0.1, seed=2)
    none = simulate_stage(u, effect=None)
    np.testing.assert_array_equal(none["y"], none["y_nominal"])
    assert len(list_effects()) >= 16
    for effect, forms in EFFECTS.items():
        assert len(forms) >= 2, effect
    for effect, form in list_effects():
        r = simulate_stage(u, effect=effect, form=form, seed=1)
        assert np.abs(r["y"] - r["y_nominal"]).max() > 1e-3, (effect, form)
        np.testing.assert_array_equal(r["y_nominal"], none["y"])


@pytest.mark.parametrize("form", ["walk", "poly", "thermal"])
def test_drift_reaches_its_strength(form):
    r = simulate_stage(paper_excitation(0.05), effect="drift", form=form, strength=0.04, seed=3)
    d = r["y"] - r["y_nominal"]
    assert np.abs(d).max() == pytest.approx(0.04, rel=1e-9)
    assert d[0] == 0.0


def test_offset_asymmetry_and_pure_delay_are_exact():
    u = paper_excitation(0.05, seed=1)
    r = simulate_stage(u, effect="asymmetry", form="offset", strength=0.1)
    np.testing.assert_allclose(r["y"] - r["y_nominal"], 0.1, atol=1e-9)
    r = simulate_stage(u, effect="delay", form="pure", strength=5)
    np.testing.assert_allclose(r["y"][5:], r["y_nominal"][:-5], atol=1e-12)


def test_lag_creep_settles_at_its_fraction():
    u = np.concatenate([np.linspace(0, 5, 300), np.full(90_000, 5.0)])  # 3 s, creep of 0.5 s lag
    r = simulate_stage(u, effect="creep", form="lags", strength=0.05, u_rest=0.0)
    assert r["y"][-1] / r["y_nominal"][-1] - 1 == pytest.approx(0.05, rel=0.02)
    log = simulate_stage(u, effect="creep", form="log", strength=0.01, u_rest=0.0)
    # log creep keeps growing: about 0.01 per decade of time
    grow = (log["y"][-1] - log["y"][-60_000]) / log["y_nominal"][-1]
    assert grow == pytest.approx(0.01 * np.log10(3.0), rel=0.1)


def test_saturation_forms_reduce_extremes_by_strength():
    u = paper_excitation(0.1, seed=0)
    r = simulate_stage(u, effect="saturation", form="clip", strength=0.1)
    span = np.ptp(r["y_nominal"])
    assert r["y"].max() == pytest.approx(r["y_nominal"].max() - 0.1 * span)
    r = simulate_stage(u, effect="saturation", form="tanh", strength=0.1)
    assert np.ptp(r["w2"]) == pytest.approx(0.9 * np.ptp(paper_stage().simulate(u)["w2"]),
                                            rel=1e-6)


def test_unit_transforms_scale_exactly():
    rec = Record(u=np.array([1.0, -2.0, 3.5]), y=np.array([0.5, 1.0, -4.0]), fs=10.0)
    r = with_units(rec, u="kV", y="nm")
    np.testing.assert_array_equal(r.u, rec.u * 1e-3)
    np.testing.assert_array_equal(r.y, rec.y * 1e3)
    assert r.units == {"u": "kV", "y": "nm"}
    back = with_units(r, u="V", y="um")
    np.testing.assert_allclose(back.u, rec.u, rtol=1e-15)
    np.testing.assert_array_equal(with_units(rec, u="V/100").u, rec.u / 100)
    np.testing.assert_array_equal(with_units(rec, y="m").y, rec.y * 1e-6)
    np.testing.assert_array_equal(with_offset(rec, -0.7).y, rec.y - 0.7)


def test_end_glitch_and_outlier_touch_one_sample():
    rec = Record(u=np.linspace(1, 2, 200), y=np.zeros(200), fs=100.0)
    g = with_end_glitch(rec)
    assert np.flatnonzero(g.u != rec.u).tolist() == [199] and g.u[-1] == rec.u[0]
    o = with_outliers(rec, 1, 2.0, seed=1)
    assert np.count_nonzero(o.y != rec.y) == 1 and np.abs(o.y).max() == 2.0
    assert crop_start(rec, 0.5).n == 150
    assert np.std(with_noise(rec, 0.01, seed=0).y) == pytest.approx(0.01, rel=0.2)


def test_decimated_stage_follows_fast_one():
    u10 = paper_excitation(0.1, 10_000.0, seed=0)
    sim = simulate_at_rate(paper_stage(), u10, 10_000.0, u_rest=0.0)
    assert sim["y"].size == u10.size
    # the anti-alias filter removes the ringing above 4 kHz, nothing else
    d = (sim["y"] - sim["y_fast"][::3])[50:-50]
    assert np.sqrt(np.mean(d**2)) < 0.08 and abs(np.mean(d)) < 0.005


def test_repeats_differ_by_requested_rms():
    var = coloured_variations(5000, 4, 0.027, 10_000.0, seed=1)
    for i in range(4):
        for j in range(i):
            assert np.sqrt(np.mean((var[i] - var[j]) ** 2)) == pytest.approx(0.027, rel=1e-9)
    # slow, not white: most of the power well below 50 Hz
    spec = np.abs(np.fft.rfft(var[0])) ** 2
    f = np.fft.rfftfreq(5000, 1e-4)
    assert spec[f < 50].sum() > 0.9 * spec.sum()
    u = paper_excitation(0.1, seed=0)
    recs = repeats(paper_stage(), u, count=3, rms=0.027, noise_rms=1e-3, seed=2)
    d = recs[0].y - recs[1].y
    assert np.sqrt(np.mean(d**2)) == pytest.approx(0.027, rel=0.05)
    assert np.array_equal(recs[0].u, recs[2].u)


@pytest.mark.parametrize("kind", ["prbn", "sine50", "sine100", "tri50", "tri100", "large_sine"])
def test_stage_a_like_matches_facts(kind):
    r = stage_a_like(kind, seconds=1.0, seed=0)
    assert r.fs == 10_000.0 and r.n == 20_000
    assert r.u.min() >= -100.0 and r.u.max() <= 74.0
    assert r.y.min() > -4.4 and r.y.max() < 2.4
    rest = slice(100, 9_000)  # rests about 1 s at a non-zero level
    assert np.ptp(r.u[rest]) == 0.0 and r.u[0] != 0.0
    assert r.u[-1] == r.u[0]
    if kind == "large_sine":
        assert r.u.min() < -99 and r.u.max() > 73
        assert r.y.min() == pytest.approx(-4.2, abs=0.2) and r.y.max() == pytest.approx(2.2,
                                                                                        abs=0.2)


def test_stage_a_repeats_and_noise():
    r0 = stage_a_like("sine50", seconds=0.5, repeat=0)
    r1 = stage_a_like("sine50", seconds=0.5, repeat=1)
    assert np.array_equal(r0.u, r1.u)
    assert np.sqrt(np.mean((r0.y - r1.y) ** 2)) == pytest.approx(0.027, rel=0.05)
    quiet = np.diff(r0.y[2000:9000])  # at rest: sensor noise plus the slow variation
    assert 0.3e-3 < np.std(quiet) / np.sqrt(2) < 0.8e-3


def test_stage_a_flexure_mode_gain():
    from hystid.testing import stage_a

    st = stage_a()
    a = np.r_[1.0, st.l2.a]

    def gain(f):
        z = np.exp(2j * np.pi * f / st.fs)
        return abs(st.l2.b[0] / np.polyval(a, z) * z ** (a.size - 1))

    assert gain(740.0) / gain(50.0) == pytest.approx(19.0, rel=0.1)


def test_stage_b_like_matches_facts():
    r = stage_b_like(seed=0)
    assert r.fs == 200.0
    assert r.u.min() >= 0.0 and r.u.max() <= 3.6 and np.ptp(r.u) > 3.5
    assert r.y.min() == pytest.approx(-123.0, abs=1.5) and r.y.max() == pytest.approx(-74.0,
                                                                                      abs=2.0)
    train, test = stage_b_like(seed=0), stage_b_like(seed=1)
    c = np.polyfit(train.u, train.y, 1)
    rms = np.sqrt(np.mean((test.y - np.polyval(c, test.u)) ** 2))
    assert 2.0 < rms < 3.2


def test_suite_covers_cases_with_heldout_pairs():
    suite = as_measured_suite(0)
    names = [r.name for r in suite]
    for case in ["offset", "units", "mid_motion", "held_level", "10kHz", "outlier", "end_glitch"]:
        assert case in names and f"{case}/heldout" in names
    by = {r.name: r for r in suite}
    assert by["units"].units == {"u": "kV", "y": "nm"}
    assert by["10kHz"].fs == 10_000.0
    assert by["end_glitch"].u[-1] == by["end_glitch"].u[0] != by["end_glitch"].u[-2]
    assert by["mid_motion"].u[0] > 3.0 and by["held_level"].u[0] == 5.3
    assert not np.array_equal(by["offset"].u, by["offset/heldout"].u)
    assert np.median(by["offset"].y) < np.median(by["outlier"].y) - 0.5
