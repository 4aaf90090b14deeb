"""Identification on records as they come, made by an independent simulator (hystid.testing).

Every fit is compared with a static line and a linear model of the same orders, validated on
the same held-out records (issue: real records).
"""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
import pytest

from hystid.baselines import compare, repeat_floor
from hystid.identify import identify
from hystid.identify.prepare import IdentificationDataError
from hystid.operating import AdmissibilityWarning
from hystid.records import Record, load_record
from hystid.testing import as_measured_suite, paper_excitation, paper_stage, repeats, with_units

DATA = Path(__file__).resolve().parents[1].parent / "shared" / "data"
PIEZO = DATA / "real" / "piezo_sine_150V_1Hz" / "hysteresis_v_150_1hz.csv"


@pytest.fixture(scope="module")
def suite() -> dict[str, Record]:
    return {r.name: r for r in as_measured_suite(0, seconds=0.2)}


CASES = ["offset", "units", "mid_motion", "held_level", "10kHz", "outlier", "end_glitch"]


@pytest.mark.parametrize("case", CASES)
def test_default_identify_beats_both_baselines_on_held_out_record(suite, case):
    train, held_out = suite[case], suite[f"{case}/heldout"]
    with warnings.catch_warnings():
        warnings.simplefilter("error", AdmissibilityWarning)
        result = identify(train)
    assert np.all(np.isfinite(result.model.theta))
    comparison = compare(result.model, train, [held_out])
    row = comparison.rows[0]
    assert row["beats"], comparison.summary()
    # and by a wide margin, except where the held-out record rests at a level reached in a way
    # the model cannot know (its hysteresis state at the start is a guess: 0.18 vs 0.23 um)
    margin = 1.0 if case == "held_level" else 3.0
    assert row["model"] < min(row["static_line"], row["linear"]) / margin, comparison.summary()


def test_sensor_offset_is_estimated(suite):
    result = identify(suite["offset"], model="duhem")
    assert result.model.offset == pytest.approx(-0.7, abs=5e-3)


def test_records_that_do_not_start_at_rest_and_outliers_are_said(suite):
    notes = " ".join(identify(suite["mid_motion"], model="duhem").info["warnings"])
    assert "does not start at rest" in notes
    notes = " ".join(identify(suite["outlier"], model="duhem").info["warnings"])
    assert "left out of the fit" in notes
    notes = " ".join(identify(suite["end_glitch"], model="duhem").info["warnings"])
    assert "last sample" in notes


@pytest.mark.parametrize("u_unit,y_unit", [("kV", "nm"), ("V/100", "m"), ("V", "nm")])
def test_identified_output_does_not_depend_on_units(suite, u_unit, y_unit):
    base = suite["offset"]
    other = with_units(base, u=u_unit, y=y_unit)
    ku = float(np.median(other.u[base.u != 0] / base.u[base.u != 0]))
    ky = float(np.median(other.y[base.y != 0] / base.y[base.y != 0]))
    held = suite["offset/heldout"]
    y1 = identify(base, model="duhem").model.simulate(held.u).y
    y2 = identify(other, model="duhem").model.simulate(held.u * ku).y / ky
    assert np.max(np.abs(y2 - y1)) <= 1e-6 * np.max(np.abs(y1))


def test_outliers_do_not_wreck_the_fit(suite):
    clean = suite["offset"]
    y = clean.y.copy()
    y[1234] = 1e12
    y[3000:3100] += 1000.0  # a +1000 um burst
    dirty = Record(clean.u, y, clean.fs, clean.units, "with outliers")
    a, b = identify(clean, model="duhem").model, identify(dirty, model="duhem").model
    assert np.max(np.abs(b.theta - a.theta) / np.abs(a.theta)) < 0.05
    assert b.offset == pytest.approx(a.offset, abs=1e-3)


def test_saturated_sensor_is_detected(suite):
    rec = suite["offset"]
    top = np.quantile(rec.y, 0.9)
    clipped = Record(rec.u, np.minimum(rec.y, top), rec.fs, rec.units, "clipped")
    notes = " ".join(identify(clipped, model="duhem").info["warnings"])
    assert "saturated" in notes


@pytest.mark.parametrize("u,reason", [
    (np.full(3000, 2.0), "constant"),
    (np.r_[np.zeros(1000), np.full(2000, 3.0)], "single step"),
])
def test_inputs_that_cannot_identify_a_stage_are_refused(u, reason):
    rec = Record(u, np.sin(np.arange(len(u)) / 50.0), 30_000.0, name="bad input")
    with pytest.raises(IdentificationDataError, match=reason):
        identify(rec)


def test_output_equal_to_input_is_refused(suite):
    rec = suite["offset"]
    with pytest.raises(IdentificationDataError, match="equals the input"):
        identify(Record(rec.u, rec.u, rec.fs, name="u twice"))


def test_simulating_outside_the_envelope_warns(suite):
    model = identify(suite["offset"], model="duhem").model
    assert model.envelope is not None
    assert model.envelope_bound() < 2.0  # admissible over its own training envelope
    with pytest.warns(AdmissibilityWarning, match="outside the identified range"):
        model.simulate(3.0 * suite["offset/heldout"].u)


def test_structure_auto_finds_a_longer_delay():
    stage = paper_stage(q1=3)
    u = paper_excitation(0.15, seed=3)
    sim = stage.simulate(u)
    rng = np.random.default_rng(3)
    rec = Record(u, sim["y"] + 1e-3 * rng.standard_normal(len(u)), 30_000.0, name="delay 3")
    result = identify(rec, structure="auto")
    assert result.model.structure.q1 == 3, result.info["structure_selection"]


def test_repeat_floor_matches_the_repeat_to_repeat_variation():
    stage = paper_stage()
    u = paper_excitation(0.3, seed=1)
    recs = repeats(stage, u, count=3, rms=0.027, seed=1)
    assert repeat_floor(recs) == pytest.approx(0.027, rel=0.15)


@pytest.mark.skipif(not PIEZO.exists(), reason=f"measured record not found: {PIEZO} "
                    "(../shared/data beside the checkout)")
def test_measured_piezo_with_no_options_beats_both_baselines_on_held_out_end():
    rec = load_record(PIEZO, columns={"t": 1, "u": 3, "y": 2})
    k = int(round(0.6 * rec.n))
    result = identify(rec[:k])
    comparison = compare(result.model, rec[:k], [(rec, k)])
    row = comparison.rows[0]
    assert row["beats"], comparison.summary("um")
    assert row["model"] < 0.1  # um; the static line is ~2 um, the linear model ~0.9 um
    # the record starts with 3.2 s at rest: the model keeps the Duhem state it fitted there, so
    # simulating it on its own record from rest reproduces the rest (was ~1.2 um off without)
    rest = int(3.0 * rec.fs)
    e = result.model.simulate(rec.u[:rest], check=False).y - rec.y[:rest]
    line = comparison.static_line.predict(rec.u[:rest]) - rec.y[:rest]
    assert np.sqrt(np.mean(e**2)) < 0.25 * np.sqrt(np.mean(line**2))
    assert np.sqrt(np.mean(e**2)) < 0.1
