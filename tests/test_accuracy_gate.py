"""The accuracy gate: fixed-seed accuracy figures against benchmarks/accuracy_baseline.json.

The figures are computed by ``benchmarks/gate.py`` (about a minute on two cores); a figure
worse than its baseline by more than the tolerance written in the baseline file fails, naming
the figure, the baseline and the change. The test never writes the baseline: improving a
figure is a deliberate ``python benchmarks/gate.py --update`` in the same commit.
"""

from __future__ import annotations

import sys
from pathlib import Path

import pytest

BENCHMARKS = Path(__file__).resolve().parents[1] / "benchmarks"
sys.path.insert(0, str(BENCHMARKS))

import gate  # noqa: E402


def _baseline_entry(value: float, better: str, rtol: float = 0.1, atol: float = 0.0) -> dict:
    return {"value": value, "better": better, "rtol": rtol, "atol": atol}


def test_check_flags_a_regression_beyond_tolerance_only():
    baseline = {"err": _baseline_entry(1.0, "lower", rtol=0.1, atol=0.05),
                "top1": _baseline_entry(0.8, "higher", rtol=0.0, atol=0.0)}
    status = {f.name: f.status for f in gate.check({"err": 1.09, "top1": 0.8}, baseline)}
    assert status == {"err": "ok", "top1": "ok"}
    found = {f.name: f for f in gate.check({"err": 1.2, "top1": 0.6}, baseline)}
    assert found["err"].status == "regressed" and found["top1"].status == "regressed"
    message = found["err"].message()
    assert "baseline 1" in message and "now 1.2" in message and "+0.2" in message
    improved = {f.name: f.status for f in gate.check({"err": 0.5, "top1": 1.0}, baseline)}
    assert improved == {"err": "improved", "top1": "improved"}


def test_check_flags_missing_and_uncomputable_figures():
    baseline = {"err": _baseline_entry(1.0, "lower"), "gone": _baseline_entry(2.0, "lower")}
    found = {f.name: f.status for f in gate.check({"err": None, "extra": 3.0}, baseline)}
    assert found == {"err": "regressed", "gone": "missing", "extra": "new"}


def test_a_broken_baseline_file_is_named(tmp_path):
    path = tmp_path / "baseline.json"
    path.write_text('{"figures": {"x": {"value": 1}}}')
    with pytest.raises(ValueError, match="baseline.json.*'x'.*better"):
        gate.load_baseline(path)
    path.write_text("{not json")
    with pytest.raises(ValueError, match="line 1"):
        gate.load_baseline(path)


def test_every_gate_figure_has_a_baseline_with_a_tolerance():
    baseline = gate.load_baseline()
    assert sorted(baseline) == sorted(s.name for s in gate.SPECS)
    for name, entry in baseline.items():
        assert entry["rtol"] >= 0 and entry["atol"] >= 0, name


def _check_figures(shared: bool) -> None:
    names = [s.name for s in gate.SPECS if (s.group in gate.NEEDS_SHARED_DATA) == shared]
    baseline_text = gate.BASELINE.read_text()
    baseline = {k: v for k, v in gate.load_baseline().items() if k in names}
    findings = gate.check(gate.compute(names), baseline)
    assert gate.BASELINE.read_text() == baseline_text  # never written by the test
    bad = [f.message() for f in findings if f.status in ("regressed", "missing", "new")]
    assert not bad, "accuracy regressed (python benchmarks/gate.py --update to accept a " \
        "deliberate change):\n" + "\n".join(bad)
    improved = [f.message() for f in findings if f.status == "improved"]
    if improved:
        import warnings

        warnings.warn("figures improved beyond their tolerance; update the baseline with "
                      "'python benchmarks/gate.py --update':\n" + "\n".join(improved),
                      stacklevel=2)


@pytest.mark.slow
def test_accuracy_figures_hold_their_baseline():
    _check_figures(shared=False)


@pytest.mark.slow
@pytest.mark.skipif(not gate.figures.STAGE_A.exists(),
                    reason=f"measured stage A not found at {gate.figures.STAGE_A} "
                    "(../shared/data beside the checkout)")
def test_measured_stage_a_figures_hold_their_baseline():
    _check_figures(shared=True)
