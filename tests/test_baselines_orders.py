"""The linear baseline a sandwich is compared with has a fair size.

``compare`` fitted its linear model with the sandwich's own orders: for the paper's Duhem
structure (no numerator terms) an all-pole model, which a forced ``--model duhem`` fit beat on
every stage-A record while a linear model with a numerator beats it on two of five.
"""

from __future__ import annotations

import warnings
from pathlib import Path

import pytest

from hystid.baselines import baseline_orders, compare
from hystid.identify import identify
from hystid.records import load_record
from hystid.testing import stage_a_like

STAGE_A = Path(__file__).resolve().parents[2] / "shared" / "data" / "real" / "stageA"


def _duhem(train):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return identify(train, model="duhem").model


def _linear(model, train, held, orders=None):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return [r["linear"] for r in compare(model, train, held, orders=orders).rows]


def test_the_numerator_is_as_long_as_the_denominator():
    train = stage_a_like("prbn", seconds=1.0, seed=0)
    model = _duhem(train)
    s = model.structure
    na, nb, q = baseline_orders(s)
    assert (na, q) == (s.n1a + s.n2a, s.q1 + s.q2)
    assert nb == max(s.n1b + s.n2b, na) and nb > s.n1b + s.n2b  # the paper's has none


def test_the_default_linear_baseline_is_no_weaker_than_the_all_pole_one():
    # the Bouc-Wen look-alike of stage A (hystid.testing, written apart from the model code)
    train = stage_a_like("prbn", seconds=1.0, seed=0)
    held = [stage_a_like(k, seconds=1.0, seed=1) for k in ("prbn", "sine50", "tri50")]
    model = _duhem(train)
    s = model.structure
    fair = _linear(model, train, held)
    all_pole = _linear(model, train, held, (s.n1a + s.n2a, s.n1b + s.n2b, s.q1 + s.q2))
    assert all(f <= 1.05 * a for f, a in zip(fair, all_pole, strict=True)), (fair, all_pole)


@pytest.mark.skipif(not STAGE_A.exists(), reason=f"measured stage A absent: {STAGE_A}")
def test_on_stage_a_a_forced_duhem_fit_meets_a_fair_yardstick():
    recs = {p.stem: load_record(p) for p in sorted(STAGE_A.glob("*.csv"))}
    train = recs.pop("prbn_1")
    held = list(recs.values())
    model = _duhem(train)
    s = model.structure
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        rows = compare(model, train, held).rows
    all_pole = _linear(model, train, held, (s.n1a + s.n2a, s.n1b + s.n2b, s.q1 + s.q2))
    fair = [r["linear"] for r in rows]
    # the all-pole model was 1.3-2.3x worse: measured 112-150 nm against 55-84
    assert all(a > 1.3 * f for f, a in zip(fair, all_pole, strict=True)), (fair, all_pole)
    # and the forced Duhem fit does not beat the fair one everywhere: the table says so
    assert not all(r["beats"] for r in rows)
