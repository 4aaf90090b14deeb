"""The model family: threshold placement, the members, and the choice by held-out error.

Data from hystid.testing's independent simulators (a Bouc-Wen stage with a flexure mode, an
offset and a rest level; the paper's Duhem stage) and, where present, measured stage A.
"""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
import pytest

from hystid.baselines import compare, rest_zero, simulate_from_rest
from hystid.identify import identify
from hystid.identify.members import (
    AUTO_CANDIDATES,
    MEMBERS,
    member,
    select_member,
)
from hystid.pi import PISandwich, play_operator
from hystid.records import Record, load_record
from hystid.reference import reference_record
from hystid.testing import stage_a_like, with_units
from hystid.thresholds import largest_half_swing, swing_thresholds, turning_points

STAGE_A = Path(__file__).resolve().parents[2] / "shared" / "data" / "real" / "stageA"


# --------------------------------------------------------------------------- thresholds
def test_turning_points_and_the_largest_swing():
    u = np.array([0.0, 1.0, 2.0, 2.0, 1.0, 0.0, 0.0, 3.0])
    assert turning_points(u).tolist() == [0, 3, 6, 7]
    assert largest_half_swing(u) == pytest.approx(1.5)


def test_swing_thresholds_ignore_an_offset_and_scale_with_the_units():
    u = stage_a_like("prbn", seconds=0.3, rest_seconds=0.1, seed=3).u[:-1]
    r = swing_thresholds(u, 20)
    assert np.allclose(swing_thresholds(u + 1e4, 20), r, rtol=1e-9)
    assert np.allclose(swing_thresholds(u * 1e-3, 20), r * 1e-3, rtol=1e-12)
    with pytest.raises(ValueError, match="does not move"):
        swing_thresholds(np.ones(10), 5)
    with pytest.raises(ValueError, match="n_operators"):
        swing_thresholds(u, 0)


def test_every_swing_threshold_is_reversed_by_the_input_it_was_placed_on():
    """The point of the rule: each play operator moves both ways on the training input (a
    threshold over the input's half range, the paper's rule on a one-sided input, does not)."""
    u = stage_a_like("prbn", seconds=0.5, rest_seconds=0.1, seed=4).u[:-1]
    u = u - u[0]
    for r in (swing_thresholds(u, 20),):
        p = play_operator(u, r)
        dp = np.diff(p, axis=0)
        assert np.all((dp > 0).any(axis=0) & (dp < 0).any(axis=0))


# --------------------------------------------------------------------------- members
def test_members_and_the_identify_entry_point():
    assert tuple(MEMBERS) == ("duhem", "gduhem", "pi", "pi-stage", "pi-poly", "mduhem")
    assert set(AUTO_CANDIDATES) <= set(MEMBERS)
    from hystid.cli.identify import MODEL_NAMES

    assert MODEL_NAMES == tuple(MEMBERS)  # the parser's list, kept without importing models
    with pytest.raises(ValueError, match="model: expected 'auto' or one of duhem, gduhem, pi"):
        member("bouc")
    rec = reference_record(0.05, seed=0)
    with pytest.raises(ValueError, match="structure: applies to model='duhem' only"):
        identify(rec, model="pi", structure=MEMBERS["duhem"].structure)
    with pytest.raises(ValueError, match="model='auto' chooses on batch fits"):
        identify(rec, model="auto", method="ekf")
    with pytest.raises(ValueError, match="PI sandwich is identified by 'batch' or 'online'"):
        identify(rec, model="pi-stage", method="ekf")
    with pytest.raises(ValueError, match="holdout"):
        select_member(rec, holdout=0.9)


def test_the_default_model_is_the_choice_unless_the_call_is_tied_to_the_duhem_sandwich():
    from hystid.identify import default_model

    assert default_model("batch") == default_model("online") == "auto"  # as hystid identify
    assert default_model("batch", settings={"offset": False, "skip": 10}) == "auto"
    assert default_model("batch", MEMBERS["duhem"].structure) == "duhem"
    assert default_model("batch", "auto") == "duhem"  # a structure choice is the Duhem one's
    assert default_model("eria") == default_model("ekf") == "duhem"
    assert default_model("online", settings={"theta0": np.ones(6)}) == "duhem"


def test_a_record_too_short_to_choose_on_gets_the_duhem_sandwich_and_says_so():
    """ten samples per parameter of pi-stage (25) cannot be fitted on 70 % of 300 samples:
    the default fits the Duhem sandwich (60 samples suffice) with a note; asked for the
    choice, it is refused with the figures."""
    rec = stage_a_like("prbn", seconds=0.03, rest_seconds=0.0, seed=2)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        result = identify(rec)
    assert result.info["model"] == "duhem"
    assert any("fitted without a choice" in w for w in result.info["warnings"])
    with pytest.raises(ValueError, match=r"leave \d+ to fit the candidates on.*expected at "
                                         r"least 250.*model='duhem'"):
        identify(rec, model="auto")


@pytest.fixture(scope="module")
def bouc_wen_stage():
    """A stage-A look-alike (Bouc-Wen hysteresis, a 740 Hz mode, 10 kHz, offset -0.7 um, rest
    at -13 V, wrapped last sample): none of the members' forms."""
    train = stage_a_like("prbn", seconds=1.0, rest_seconds=0.5, seed=0)
    held = [stage_a_like(k, seconds=1.0, rest_seconds=0.5, seed=1)
            for k in ("sine50", "tri100", "large_sine")]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        result = identify(train, model="auto")
    return train, held, result


def test_auto_reports_every_candidate_and_beats_both_baselines(bouc_wen_stage):
    train, held, result = bouc_wen_stage
    sel = result.info["member_selection"]
    assert [c["member"] for c in sel["candidates"]] == list(AUTO_CANDIDATES)
    assert sum(c["chosen"] for c in sel["candidates"]) == 1
    chosen = next(c for c in sel["candidates"] if c["chosen"])
    assert result.info["model"] == chosen["member"]
    best = min(c["heldout_rms"] for c in sel["candidates"])
    assert chosen["heldout_rms"] <= (1 + sel["margin"]) * best
    assert sel["beats_baselines"]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        rows = compare(result.model, train, held).rows
    for row in rows:
        assert row["model"] < 0.5 * min(row["static_line"], row["linear"]), row


@pytest.mark.skipif(not STAGE_A.exists(), reason=f"measured stage A records absent ({STAGE_A})")
def test_on_stage_a_with_a_short_rest_the_whole_record_fit_finds_the_slow_pole():
    """prbn_1 with its 1 s rest cut to 0.1 s: the head fit (70 % of the excitation) put the
    ``pi-stage`` slow pole at 0.9993, and the whole-record fit started from it stayed there:
    51 nm of residual and 73-103 nm off the other five records (measured). Fitted from the
    member's own starts as well, the better of the two is the whole record's optimum (26 nm,
    the pole at 0.99987): as good as identified on the whole record (25-30 nm)."""
    full = load_record(STAGE_A / "prbn_1.csv")
    others = [load_record(STAGE_A / f"{n}.csv")
              for n in ("prbn_2", "sine50_1", "sine50_2", "tri50_1", "tri50_2")]
    rec = Record(full.u[9000:], full.y[9000:], full.fs, units=full.units, name="prbn_1[9000:]")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        result = identify(rec)
        fresh = MEMBERS[result.info["model"]].fit(rec)
        rows = compare(result.model, rec, others).rows
    assert result.info["model"] == "pi-stage"
    assert result.info["rms_residual"] <= fresh.info["rms_residual"] * (1 + 1e-9)
    for row in rows:
        assert row["model"] < 0.045 and row["model"] < 0.6 * row["linear"], row


@pytest.mark.skipif(not STAGE_A.exists(), reason=f"measured stage A not found at {STAGE_A} "
                    "(../shared/data beside the checkout)")
@pytest.mark.parametrize("rest", [200, 50])
def test_on_stage_a_with_a_very_short_rest_pi_stage_finds_the_slow_pole(rest):
    """prbn_1 with its 1 s rest cut to 20 ms or 5 ms: the ARX start put ``pi-stage``'s slow
    pole at 0.989 and the output-error fit stopped there from every start, 43-45 nm of residual
    and 80-110 nm off the other five records (measured). From the slow branch's start it finds
    the pole (0.99988): 27 nm of residual, 23-41 nm held out."""
    full = load_record(STAGE_A / "prbn_1.csv")
    others = [load_record(STAGE_A / f"{n}.csv")
              for n in ("prbn_2", "sine50_1", "sine50_2", "tri50_1", "tri50_2")]
    k = 10_001 - rest
    rec = Record(full.u[k:], full.y[k:], full.fs, units=full.units, name=f"prbn_1[{k}:]")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        fit = member("pi-stage").fit(rec)
        rows = compare(fit.model, rec, others).rows
    assert fit.info["rms_residual"] < 0.03
    assert max(np.abs(np.roots(np.r_[1.0, fit.model.a2]))) > 0.9995
    for row in rows:
        assert row["model"] < 0.05 and row["model"] < 0.7 * row["linear"], row


PIEZO = STAGE_A.parent / "piezo_sine_150V_1Hz" / "hysteresis_v_150_1hz.csv"


@pytest.mark.skipif(not PIEZO.exists(), reason=f"measured piezo not found at {PIEZO} "
                    "(../shared/data beside the checkout)")
def test_the_slow_branch_start_is_not_kept_for_a_pole_slower_than_the_record():
    """The measured piezo's first 60 % (3.3 s of rest, 2.7 s of a 1 Hz sine): from the slow
    branch's start the ``pi-stage`` fit put L2's pole at 0.99998 (10 s), the choice then took
    ``pi-stage`` and the model was 0.45 um off the last 40 %, where the Duhem sandwich is
    0.07 (measured). A fit whose slowest time constant exceeds twice the excitation is not
    kept from that start."""
    rec = load_record(PIEZO, columns={"t": 1, "u": 3, "y": 2})
    k = int(round(0.6 * rec.n))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        fit = member("pi-stage").fit(rec[:k])
        result = identify(rec[:k])
    assert fit.info["start"] != "ARX mode + slow branch"
    assert max(np.abs(np.roots(np.r_[1.0, fit.model.a2]))) < 0.99995
    y = simulate_from_rest(result.model, rec.u, check=False)
    e = (y - rec.y)[k:]
    assert float(np.sqrt(np.mean(e ** 2))) < 0.15  # um


def test_the_chosen_model_is_placed_like_every_model(bouc_wen_stage):
    train, _, result = bouc_wen_stage
    m = result.model
    assert m.units == train.units and m.envelope is not None
    assert m.u_rest == pytest.approx(train.u[0])
    y = simulate_from_rest(m, train.u, check=False)
    assert abs(np.median(y[:100] - train.y[:100])) < 0.02  # the offset placed, in um


@pytest.mark.parametrize("seed", [0, 1])
def test_auto_keeps_the_plain_duhem_model_on_a_duhem_stage(seed):
    """On the paper's stage (a Duhem sandwich) a richer member earns nothing: the choice keeps
    the plain model (benchmarks/bench_members.py runs 20 seeds)."""
    rec = reference_record(0.2, seed=seed)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        result = identify(rec, model="auto")
    assert result.info["model"] == "duhem"
    assert result.model.theta.shape == (len(MEMBERS["duhem"].structure.names),)


def test_pi_members_do_not_depend_on_an_input_offset_or_the_units():
    train = stage_a_like("prbn", seconds=0.4, rest_seconds=0.1, seed=5)
    held = stage_a_like("sine50", seconds=0.3, rest_seconds=0.1, seed=6)
    outs = []
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        for shift, units in ((0.0, ("V", "um")), (100.0, ("V", "um")), (0.0, ("kV", "nm"))):
            t = with_units(Record(train.u + shift, train.y, train.fs, train.units, train.name),
                           u=units[0], y=units[1])
            h = with_units(Record(held.u + shift, held.y, held.fs, held.units, held.name),
                           u=units[0], y=units[1])
            res = identify(t, model="pi-stage")
            assert isinstance(res.model, PISandwich)
            y = simulate_from_rest(res.model, h.u, check=False)
            outs.append(y * (1e-3 if units[1] == "nm" else 1.0))
    for y in outs[1:]:
        assert np.max(np.abs(y - outs[0])) <= 1e-6 * np.max(np.abs(outs[0]))


def test_rest_zero_reads_the_record_s_own_rest_output():
    rec = stage_a_like("tri50", seconds=0.2, rest_seconds=0.1, seed=2)
    shifted = Record(rec.u, rec.y + 0.05, rec.fs, rec.units, rec.name)
    assert rest_zero(rec.y, shifted) == pytest.approx(0.05)
    short = Record(np.r_[0.0, np.sin(np.arange(999) / 50)], np.zeros(1000), rec.fs)
    assert rest_zero(np.ones(1000), short) == 0.0  # one sample is no rest


# --------------------------------------------------------------------------- measured stage A
@pytest.mark.skipif(not STAGE_A.exists(), reason=f"measured stage A not found at {STAGE_A} "
                    "(../shared/data beside the checkout)")
def test_on_measured_stage_a_the_default_choice_wins_by_far():
    """Identified on prbn_1 with the defaults (``identify(train)``: model="auto"), run free
    on the other five records: well below the linear model and under 50 nm everywhere
    (benchmarks/bench_stage_a.py has the table with the NARX; today's figures are 25-30 nm
    against 42-70 nm for the NARX)."""
    recs = {p.stem: load_record(p) for p in sorted(STAGE_A.glob("*.csv"))}
    train = recs.pop("prbn_1")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        result = identify(train)
        rows = compare(result.model, train, list(recs.values())).rows
    assert result.info["model"] == "pi-stage"
    assert "member_selection" in result.info
    # the two differ on the probe by 4.7x their held-out errors (the block): under the limit
    assert result.info["member_selection"]["undetermined"] is None
    for row in rows:
        assert row["model"] < 0.05, row  # um
        assert row["model"] < 0.6 * row["linear"], row


@pytest.mark.skipif(not STAGE_A.exists(), reason=f"measured stage A not found at {STAGE_A} "
                    "(../shared/data beside the checkout)")
def test_identified_on_a_triangle_record_the_default_says_the_record_does_not_determine_it():
    """Identified on tri50_1 (a 5 Hz carrier with a 50 Hz triangle on it), the held-out end
    repeats the triangle, which cannot tell the Duhem sandwich from pi-stage; the Duhem
    sandwich is 453-455 nm off the PRBN records, pi-stage 66-72, where the linear model fitted
    on the same record is 67-72 (measured). The two differ by several times their held-out
    errors on an input with reversals of every size: the warning says so. (The default kept
    the Duhem sandwich until pi-stage's fit gained its slow-branch start; it now takes
    pi-stage, within the warning's plausible pair.)"""
    recs = {p.stem: load_record(p) for p in sorted(STAGE_A.glob("*.csv"))}
    train = recs.pop("tri50_1")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        result = identify(train)
        rows = compare(result.model, train, [recs["prbn_1"], recs["prbn_2"]]).rows
    said = [w for w in result.info["warnings"] if "does not determine the model" in w]
    assert len(said) == 1 and "validate the model on another input" in said[0]
    assert said[0] == result.info["member_selection"]["undetermined"]
    # what the warning is about: the plausible members disagree far off the training input
    other = "duhem" if result.info["model"] == "pi-stage" else "pi-stage"
    assert other in said[0]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        rival = compare(member(other).fit(train).model, train,
                        [recs["prbn_1"], recs["prbn_2"]]).rows
    ratio = [max(a["model"], b["model"]) / min(a["model"], b["model"])
             for a, b in zip(rows, rival, strict=True)]
    assert min(ratio) > 3.0, (rows, rival)


def test_the_warning_that_the_record_does_not_determine_the_model_ignores_units_and_offsets():
    """The Bouc-Wen look-alike of stage A driven by a 50 Hz sine (seed 2) is warned (20.6x when
    this was written); in mV and nm with a 2.5 um sensor offset, and in kV and mm, the same
    ratio, each in its own units."""
    import re

    from hystid.testing import with_offset

    rec = stage_a_like("sine50", seconds=1.0, seed=2)
    other = {"nm": with_offset(with_units(rec, u="mV", y="nm"), 2500.0),
             "mm": with_units(rec, u="kV", y="mm")}
    said = {}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        for unit, r in [("um", rec), *other.items()]:
            said[unit] = identify(r).info["member_selection"]["undetermined"]
    assert all(s is not None for s in said.values()), said
    ratio = {u: float(re.search(r"\(([\d.]+)x\)", s).group(1)) for u, s in said.items()}
    assert ratio["um"] > 3.0 and ratio["nm"] == ratio["um"] == ratio["mm"], ratio
    for unit, s in said.items():
        assert f" {unit} off its held-out block" in s and f" {unit} (" in s, s


@pytest.mark.parametrize("hysteresis", ["preisach", "maxwell"])
def test_auto_beats_both_baselines_on_other_hysteresis_operators(hysteresis):
    """The paper-like stage with a Preisach or a Maxwell-slip loop (written unlike any member),
    a sensor offset, records cropped so that they do not start at rest: whatever the default
    chooses beats the static line and the linear model on a record of another seed (on the
    Maxwell-slip stage by about 40 % only: 61 against 98 nm when this was written)."""
    from hystid.testing import crop_start, simulate_stage, with_offset

    recs = []
    for seed in (7, 8):
        u = paper_excitation_like(seed)
        sim = simulate_stage(u, 30_000.0, hysteresis=hysteresis, seed=seed)
        y = sim["y"] + 1e-3 * np.random.default_rng(seed).standard_normal(len(u))
        recs.append(crop_start(with_offset(Record(u, y, 30_000.0, name=f"{hysteresis} {seed}"),
                                           -0.7), 0.02))
    train, held = recs
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        result = identify(train, model="auto")
        row = compare(result.model, train, [held]).rows[0]
    assert result.info["model"] in AUTO_CANDIDATES
    assert row["beats"], row
    assert row["model"] < 0.8 * min(row["static_line"], row["linear"]), row


def paper_excitation_like(seed: int) -> np.ndarray:
    """0.2 s of the paper's excitation around 5.3 V, ramped up from rest."""
    from hystid.reference import paper_excitation

    return paper_excitation(6000, 30_000.0, seed=seed)
