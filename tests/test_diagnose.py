"""Tests of the sim-to-real gap diagnosis (hystid.diagnose)."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np
import pytest

from hystid.cli import diagnose as diagnose_command
from hystid.diagnose import (
    EFFECT_NAMES,
    EFFECTS,
    AugmentedSandwich,
    DiagnosisError,
    diagnose,
    family_of,
    localise,
    noise_floor,
    simulate_with_effect,
)
from hystid.diagnose.diagnosis import DEFAULT_EFFECTS
from hystid.diagnose.screen import compare_losses
from hystid.diagnose.where import Segment, cross_correlation_test
from hystid.model import DuhemSandwich, InitialCondition, Structure
from hystid.records import Record
from hystid.reference import paper_excitation, reference_model

FS = 30_000.0
N = 8_000
NOISE = 2e-3

#: One clearly visible setting per effect (the issue's short synthetic records).
CASES = {
    "creep": {"gain": 0.03, "tau": 0.05},
    "creep_2tau": {"gain": 0.02, "tau": 0.01, "gain2": 0.02, "tau2": 0.1},
    "creep_log": {"gain": 0.04, "tau": 0.001},
    "drift": {"rate": 0.05},
    "extra_mode": {"gain": 0.01, "freq": 5000.0, "zeta": 0.02},
    "mode_series": {"gain": 0.3, "freq": 4000.0, "zeta": 0.03},
    "delay": {"samples": 0.5},
    "asymmetry": {"alpha": 0.1},
    "asymmetry_input": {"alpha": 0.1},
    "loop_level": {"alpha": 0.02, "g0": 0.02},
    "offset": {"y0": 0.01},
    "slew_limit": {"inv_rate": 1.0 / (0.6 * FS)},
    "slew_input": {"inv_rate": 1.0 / (0.25 * FS)},
    "saturation": {"cubic": 3e-4},
    "output_curve": {"quadratic": 0.1, "cubic": 0.0, "centre": 5.0, "span": 2.5},
}


def _steps(n: int, levels: tuple[float, ...]) -> np.ndarray:
    """Level steps every 0.1 s after 0.05 s (creep is told from a drift by them)."""
    out = np.zeros(n)
    for i, lev in enumerate(levels):
        out[int((0.05 + 0.1 * i) * FS):] = lev
    return out


def _records(effect: str, params: dict, n: int = N, noise: float = NOISE):
    model = reference_model()
    u1 = paper_excitation(n, FS, seed=1) + _steps(n, (0.6, -0.4, 0.3))
    u2 = paper_excitation(n, FS, seed=2, offset=4.8) + _steps(n, (-0.5, 0.4, -0.2))
    r1 = simulate_with_effect(model, effect, params, u1, noise=noise, seed=11)
    r2 = simulate_with_effect(model, effect, params, u2, noise=noise, seed=12)
    return Record(u1, r1.y, FS, name="train"), Record(u2, r2.y, FS, name="val")


# --------------------------------------------------------------------------- effects
@pytest.mark.parametrize("name", EFFECT_NAMES)
def test_candidate_reduces_to_nominal_at_zero(name):
    model = reference_model()
    u = paper_excitation(3000, FS, seed=3)
    zero = {p: 0.0 for p in EFFECTS[name].params}
    y_aug = AugmentedSandwich(model, {name: zero}).simulate(u).y
    assert np.max(np.abs(y_aug - model.simulate(u).y)) <= 1e-12


@pytest.mark.parametrize("name", EFFECT_NAMES)
def test_candidate_reduces_to_nominal_general_structure(name):
    # a structure with numerator terms, an L2 delay, f0 and a non-zero past
    s = Structure(n1a=2, n1b=1, n2a=2, n2b=1, q1=1, q2=1, f0=True)
    params = {"b21": 0.2, "alpha": 0.5, "f0": 0.01, "f1": 0.14, "b11": 0.3, "g0": 0.01,
              "a11": -0.5, "a12": 0.06, "a21": -1.6, "a22": 0.92}
    model = DuhemSandwich(params, s, fs=FS)
    x0 = InitialCondition(u=[4.0, 5.0], w1=[8.0, 9.0], w2=[1.0, 1.1], y=[3.0, 3.2])
    u = paper_excitation(3000, FS, seed=4)
    zero = {p: 0.0 for p in EFFECTS[name].params}
    y_aug = AugmentedSandwich(model, {name: zero}).simulate(u, x0).y
    assert np.max(np.abs(y_aug - model.simulate(u, x0).y)) <= 1e-12


@pytest.mark.parametrize("name", EFFECT_NAMES)
def test_candidate_changes_the_output(name):
    model = reference_model()
    u = paper_excitation(6000, FS, seed=3)
    y = simulate_with_effect(model, name, CASES[name], u).y
    assert np.sqrt(np.mean((y - model.simulate(u).y) ** 2)) > 1e-3


def test_effect_parameters_are_checked():
    model = reference_model()
    with pytest.raises(ValueError, match="unknown effect"):
        AugmentedSandwich(model, {"backlash": {"gap": 1.0}})
    with pytest.raises(ValueError, match="unknown parameters"):
        AugmentedSandwich(model, {"creep": {"rate": 1.0}})
    with pytest.raises(ValueError, match="zeta"):
        AugmentedSandwich(model, {"extra_mode": {"gain": 0.1, "freq": 100.0, "zeta": 1.5}})
    with pytest.raises(ValueError, match="effect_name"):
        simulate_with_effect(model, "wobble", {}, np.zeros(10))


# --------------------------------------------------------------------------- where
def test_noise_floor_of_white_noise():
    rng = np.random.default_rng(0)
    e = 3e-3 * rng.standard_normal(20_000)
    nf = noise_floor(e, FS)
    assert abs(nf["rms"] / 3e-3 - 1) < 0.05


def test_cross_correlation_band_is_valid_for_coloured_signals():
    # two independent AR(1) series: a white-noise band would flag many lags, Bartlett's few
    rng = np.random.default_rng(1)
    outside = []
    for _ in range(20):
        x = np.zeros(5000)
        e = np.zeros(5000)
        wx, we = rng.standard_normal(5000), rng.standard_normal(5000)
        for k in range(1, 5000):
            x[k] = 0.95 * x[k - 1] + wx[k]
            e[k] = 0.95 * e[k - 1] + we[k]
        outside.append(cross_correlation_test(x, e, 50)["fraction_outside"])
    assert np.mean(outside) < 0.05


def test_localise_finds_a_slow_trend_and_a_branch_split():
    model = reference_model()
    u = paper_excitation(N, FS, seed=5)
    sim = model.simulate(u)
    rng = np.random.default_rng(2)
    t = np.arange(N) / FS
    drift = 0.05 * t
    seg = Segment(u, sim.y + drift + NOISE * rng.standard_normal(N), sim.y, sim.w1, FS)
    w = localise([seg])
    assert w.time["trend_fraction"] > 0.8
    assert w.time["slope_per_s"] == pytest.approx(0.05, rel=0.1)
    assert w.noise["rms"] == pytest.approx(NOISE, rel=0.1)
    # an error that depends on the direction of w1 only: the loop-width component dominates
    up = np.sign(np.diff(sim.w1, prepend=sim.w1[0]))
    seg2 = Segment(u, sim.y + 0.01 * up + NOISE * rng.standard_normal(N), sim.y, sim.w1, FS)
    w2 = localise([seg2])
    assert w2.branch["width_fraction"] > 0.5 > w2.branch["common_fraction"]


# --------------------------------------------------------------------------- test statistics
def test_loss_test_keeps_its_level_with_coloured_residuals():
    # at the null boundary (both models equally far from the data) with strongly coloured
    # noise, rejections at 5 % stay near 5 %
    rng = np.random.default_rng(3)
    n = 4000
    delta = 0.01 * np.sin(2 * np.pi * np.arange(n) / 700.0)
    rejections = 0
    for _ in range(200):
        w = rng.standard_normal(n)
        eps = np.zeros(n)
        for k in range(1, n):
            eps[k] = 0.9 * eps[k - 1] + 0.01 * w[k]
        e_base = eps + delta / 2
        e_cand = e_base - delta
        rejections += compare_losses([e_base], [e_cand])["p_value"] < 0.05
    assert rejections / 200 < 0.1


def test_loss_test_detects_a_real_improvement():
    rng = np.random.default_rng(4)
    noise = 1e-3 * rng.standard_normal(5000)
    trend = 5e-3 * np.linspace(0, 1, 5000)
    out = compare_losses([noise + trend], [noise])
    assert out["p_value"] < 1e-6
    assert out["rel_reduction"] > 0.5
    same = compare_losses([noise + trend], [noise + trend])
    assert same["p_value"] == 1.0


# --------------------------------------------------------------------------- diagnosis
#: One form per family whose parameters the refit recovers from the short records (the
#: others are checked by family in the withheld-effect benchmark).
RECOVERED = ("creep", "extra_mode", "delay", "asymmetry", "slew_limit", "saturation")


@pytest.mark.parametrize("effect", RECOVERED)
def test_right_effect_ranks_first(effect):
    train, val = _records(effect, CASES[effect])
    res = diagnose(train, val, progress=False)
    assert res.effects[0].family == family_of(effect)
    assert res.families[:1] == [family_of(effect)]
    best = res.effects[0]
    assert best.gap_closed > 0.8
    if best.name == effect:
        # the refit recovers the withheld parameters
        for p, v in CASES[effect].items():
            assert best.params[p] == pytest.approx(v, rel=0.15)


@pytest.fixture(scope="module")
def clean_result():
    train, val = _records("none", {})
    return diagnose(train, val, progress=False)


def test_clean_record_yields_none(clean_result):
    res = clean_result
    assert res.accepted == []
    assert res.best == "none"
    assert res.final["rms_val"] == res.nominal["rms_val"]
    assert res.noise_floor_rms == pytest.approx(NOISE, rel=0.1)
    assert not any(e.accepted for e in res.effects)


def test_json_report_has_the_issue_fields(clean_result):
    d = json.loads(json.dumps(clean_result.to_dict()))
    assert set(d) >= {"noise_floor_rms", "nominal", "where", "effects"}
    assert "rms_val" in d["nominal"]
    assert [e["name"] for e in d["effects"]] == [e.name for e in clean_result.effects]
    assert len(d["effects"]) == len(DEFAULT_EFFECTS)
    for e in d["effects"]:
        assert {"name", "family", "accepted", "rms_val_after", "gap_closed"} <= set(e)
    assert d["floor"]["kind"] == "sensor noise"
    where, effects, accepted = clean_result
    assert where is clean_result.where and accepted == []


def test_progress_lines(capsys):
    train, _ = _records("none", {}, n=5000)
    lines = []
    diagnose(train, effects=["drift"], progress=lines.append)
    assert any("nominal model" in m for m in lines)
    assert any("done" in m for m in lines)
    diagnose(train, effects=["drift"], progress=True, max_rounds=1)
    assert "diagnose:" in capsys.readouterr().err


def test_held_out_tail_without_val():
    train, _ = _records("drift", {"rate": 0.05, "accel": -0.5}, n=12_000)
    res = diagnose(train, holdout=0.4, progress=False)
    assert res.accepted[:1] == ["drift"]
    assert res.settings["val_samples"] == 12_000 - int(round(0.6 * 12_000))


# --------------------------------------------------------------------------- bad input
def test_too_short_records_are_refused():
    train, val = _records("none", {}, n=400)
    with pytest.raises(DiagnosisError, match="too short"):
        diagnose(train, val, progress=False)
    with pytest.raises(DiagnosisError, match="too short"):
        diagnose(train, progress=False)


def test_mismatched_sampling_rates_are_refused():
    train, val = _records("none", {}, n=3000)
    val = Record(val.u, val.y, 20_000.0, name="val")
    with pytest.raises(DiagnosisError, match="sampling rate"):
        diagnose(train, val, progress=False)


def test_constant_input_and_unknown_effect_are_refused():
    y = np.random.default_rng(0).standard_normal(5000)
    with pytest.raises(DiagnosisError, match="constant"):
        diagnose(Record(np.ones(5000), y, FS), progress=False)
    train, val = _records("none", {}, n=3000)
    with pytest.raises(DiagnosisError, match="unknown"):
        diagnose(train, val, effects=["backlash"], progress=False)


def _slow_sine_records():
    model = reference_model()
    t = np.arange(N) / FS
    ramp = 0.5 - 0.5 * np.cos(np.pi * np.clip(t / 0.02, 0, 1))
    recs = []
    for k, phase in enumerate((0.0, 1.0)):
        u = ramp * (5 + 1.5 * np.sin(2 * np.pi * 2 * t + phase))
        r = simulate_with_effect(model, "none", {}, u, noise=NOISE, seed=k)
        recs.append(Record(u, r.y, FS, name=f"slow sine {k}"))
    return recs


def test_record_without_excitation_for_a_candidate(monkeypatch):
    train, val = _slow_sine_records()
    # no form is invisible on these records; ask for more separation than any has
    from hystid.diagnose import screen as screen_module

    monkeypatch.setattr(screen_module, "MIN_SEPARATION", 0.99)
    res = diagnose(train, val, reference_model(), effects=["creep_2tau", "drift"],
                   progress=False)
    creep = next(e for e in res.effects if e.name == "creep_2tau")
    assert creep.status == "not excited"
    assert "level changes" in creep.message
    with pytest.raises(DiagnosisError, match="cannot show"):
        diagnose(train, val, reference_model(), effects=["creep_2tau"],
                 require_excitation=True, progress=False)


# --------------------------------------------------------------------------- command line
def _parse(argv):
    parser = argparse.ArgumentParser(prog="hystid diagnose")
    diagnose_command.configure_parser(parser)
    return parser.parse_args(argv)


def test_command_json_and_figures(tmp_path, capsys):
    train, val = _records("asymmetry", CASES["asymmetry"], n=6000)
    train.save(tmp_path / "train.npz")
    val.save(tmp_path / "val.csv")
    out = tmp_path / "report"
    args = _parse([str(tmp_path / "train.npz"), "--val", str(tmp_path / "val.csv"), "--json",
                   "--quiet", "--out", str(out)])
    assert diagnose_command.run(args) == 0
    report = json.loads(capsys.readouterr().out)
    assert report["effects"][0]["name"] == "asymmetry"
    assert report["effects"][0]["accepted"] is True
    for name in ("error_time.png", "spectrum.png", "branch.png", "gap.png", "report.json"):
        assert (out / name).stat().st_size > 0


def test_command_time_budget_zero_refits_only_each_familys_best_form(tmp_path, capsys):
    train, val = _records("asymmetry", CASES["asymmetry"], n=6000)
    train.save(tmp_path / "train.npz")
    val.save(tmp_path / "val.npz")
    argv = [str(tmp_path / "train.npz"), "--val", str(tmp_path / "val.npz"), "--json",
            "--quiet", "--time-budget", "0"]
    assert diagnose_command.run(_parse(argv)) == 0
    report = json.loads(capsys.readouterr().out)
    refitted = [e for e in report["effects"] if e["status"] in ("accepted", "rejected")]
    families = [e["family"] for e in refitted]
    assert len(families) >= 2
    assert len(families) == len(set(families))  # one form per family, whatever the machine
    with pytest.raises(SystemExit):
        _parse([str(tmp_path / "train.npz"), "--time-budget", "-1"])
    assert "--time-budget" in capsys.readouterr().err


def test_command_bad_input_exit_status(tmp_path, capsys, monkeypatch):
    train, val = _records("none", {}, n=3000)
    train.save(tmp_path / "train.npz")
    Record(val.u, val.y, 10_000.0).save(tmp_path / "val.npz")
    args = _parse([str(tmp_path / "train.npz"), "--val", str(tmp_path / "val.npz"), "--quiet"])
    assert diagnose_command.run(args) == 2
    assert "sampling rate" in capsys.readouterr().err
    short = Record(train.u[:500], train.y[:500], FS)
    short.save(tmp_path / "short.npz")
    assert diagnose_command.run(_parse([str(tmp_path / "short.npz"), "--quiet"])) == 2
    assert "too short" in capsys.readouterr().err
    assert diagnose_command.run(_parse([str(tmp_path / "missing.npz"), "--quiet"])) == 2
    assert "missing.npz" in capsys.readouterr().err
    from hystid.diagnose import screen as screen_module

    monkeypatch.setattr(screen_module, "MIN_SEPARATION", 0.99)
    slow, slow_val = _slow_sine_records()
    slow.save(tmp_path / "slow.npz")
    slow_val.save(tmp_path / "slow_val.npz")
    reference_model().save(tmp_path / "model.json")
    args = _parse([str(tmp_path / "slow.npz"), "--val", str(tmp_path / "slow_val.npz"),
                   "--effects", "creep_2tau", "--model", str(tmp_path / "model.json"),
                   "--quiet"])
    assert diagnose_command.run(args) == 2
    assert "creep_2tau" in capsys.readouterr().err


# --------------------------------------------------------------------------- measured data
PIEZO = Path(__file__).resolve().parents[1] / ".." / "shared" / "data" / "real" / \
    "piezo_sine_150V_1Hz" / "hysteresis_v_150_1hz.csv"


def test_measured_piezo_record():
    """The shared measured record diagnosed with default options (the command's defaults: the
    input in volts as recorded, the last 40 % held out)."""
    if not PIEZO.is_file():
        pytest.skip(f"measured piezo record not found at {PIEZO} (../shared/data is absent)")
    from hystid.records import load_record, parse_columns

    rec = load_record(PIEZO, columns=parse_columns("t=1,u=3,y=2"))
    res = diagnose(rec, progress=False)
    # the sensor noise is about 0.05 um (std at rest 0.049 um)
    assert 0.04 < res.noise_floor_rms < 0.06
    # the nominal model (offset and rest level estimated) is admissible on the held-out part
    assert res.nominal["admissibility"] == []
    assert res.noise_floor_rms < res.nominal["rms_val"] < 0.1
    assert res.where.frequency["harmonics"]["harmonic_fraction"] > 0.5
    # every accepted form passed its own round's test; otherwise the rest is described
    for e in res.effects[: len(res.accepted)]:
        assert e.test["p_value"] < res.rounds[e.round - 1]["test_level"]
    if not res.accepted:
        assert res.final["unexplained"]["periodic"] is not None
        assert "accepted: none" in res.summary()
