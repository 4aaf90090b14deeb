"""The diagnosis ends in a model: ``hystid diagnose --out`` writes ``model.json``.

Records from hystid.testing's independent simulators (effects written apart from the
diagnosis' own forms, other hysteresis operators).
"""

from __future__ import annotations

import argparse
import json

import numpy as np
import pytest

from hystid import testing
from hystid.cli import diagnose as diagnose_command
from hystid.diagnose.effects import AugmentedSandwich
from hystid.diagnose.final_model import _scores
from hystid.modelfile import ModelFileError, load_model, save_model
from hystid.records import Record
from hystid.reference import paper_excitation, reference_model

FS = 30_000.0
N = 6000


def _records(effect: str | None, form: str | None, strength: float | None, seed: int,
             hysteresis: str = "duhem") -> tuple[Record, Record]:
    rng = np.random.default_rng(seed)
    recs = []
    for label in ("train", "val"):
        u = paper_excitation(N, FS, seed=int(rng.integers(1 << 30)),
                             offset=rng.uniform(4.8, 5.6))
        sim = testing.simulate_stage(u, FS, effect=effect, form=form, strength=strength,
                                     hysteresis=hysteresis, seed=int(rng.integers(1 << 30)))
        recs.append(Record(u, sim["y"] + 1e-3 * rng.standard_normal(N), FS, name=label))
    return recs[0], recs[1]


def _run(tmp_path, train: Record, val: Record) -> tuple[dict, object]:
    train.save(tmp_path / "train.npz")
    val.save(tmp_path / "val.npz")
    out = tmp_path / "diag"
    parser = argparse.ArgumentParser(prog="hystid diagnose")
    diagnose_command.configure_parser(parser)
    args = parser.parse_args([str(tmp_path / "train.npz"), "--val", str(tmp_path / "val.npz"),
                              "--json", "--quiet", "--out", str(out)])
    assert diagnose_command.run(args) == 0
    report = json.loads((out / "report.json").read_text())
    return report, load_model(out / "model.json")


def test_the_written_model_reproduces_the_report_s_final_error(tmp_path, capsys):
    """Branch-dependent Duhem coefficients, simulated apart from the diagnosis: the model file,
    reloaded, gives the report's final held-out error to round-off, and it is at least as good
    as the nominal model."""
    train, val = _records("asymmetry", "branch", 0.3, seed=2)
    report, model = _run(tmp_path, train, val)
    capsys.readouterr()
    final = report["final_model"]
    assert final["chosen"] in [c["candidate"] for c in final["candidates"]]
    again = float(np.mean(_scores(model, [(val, 0)])))
    assert again == pytest.approx(final["heldout_rms"], rel=1e-9)
    nominal = next(c for c in final["candidates"] if c["candidate"] == "nominal")
    assert final["heldout_rms"] <= nominal["mean_rms"]
    if report["accepted"] and final["chosen"].startswith("nominal +"):
        assert isinstance(model, AugmentedSandwich)
        assert set(model.effects) == set(report["accepted"])


def test_another_hysteresis_operator_is_tried_as_the_hysteresis_itself(tmp_path, capsys):
    """A Bouc-Wen stage (not a Duhem loop): the members are candidates beside the effects and
    the report says which one the diagnosis ends in and how much of the gap it closes."""
    train, val = _records(None, None, None, seed=3, hysteresis="bouc_wen")
    report, model = _run(tmp_path, train, val)
    capsys.readouterr()
    final = report["final_model"]
    names = [c["candidate"] for c in final["candidates"]]
    assert "nominal" in names and "pi-stage" in names
    best = min(c["mean_rms"] for c in final["candidates"])
    chosen = next(c for c in final["candidates"] if c["candidate"] == final["chosen"])
    assert chosen["mean_rms"] <= 1.12 * best  # the margin keeps a simpler one within 10 %
    assert final["verdict"]
    assert float(np.mean(_scores(model, [(val, 0)]))) == pytest.approx(final["heldout_rms"],
                                                                      rel=1e-9)


def test_a_model_with_effects_survives_its_file(tmp_path):
    aug = AugmentedSandwich(reference_model(), {"asymmetry": {"alpha": 0.2},
                                                "creep": {"gain": 0.05, "tau": 0.02}})
    path = save_model(aug, tmp_path / "m.json")
    back = load_model(path)
    u = paper_excitation(3000, FS, seed=4)
    assert isinstance(back, AugmentedSandwich)
    assert np.max(np.abs(back.simulate(u).y - aug.simulate(u).y)) <= 1e-12
    doc = json.loads(path.read_text())
    for bad, message in (({"warp": {"x": 1.0}}, "unknown effect"),
                         ({"creep": {"gain": "big"}}, "finite numbers"),
                         ({"creep": {"gian": 1.0}}, "'effects'"),
                         ({"creep": [1, 2]}, "finite numbers")):
        doc["effects"] = bad
        (tmp_path / "bad.json").write_text(json.dumps(doc))
        with pytest.raises(ModelFileError, match=message):
            load_model(tmp_path / "bad.json")


def test_the_summary_ends_in_one_final_figure_the_model_file_s():
    """One 'final' line: the model written to model.json and its held-out RMS as the final
    table scores it (the rounds' own figure is labelled as theirs)."""
    from hystid.diagnose.final_model import FinalModel

    rows = [{"candidate": "nominal", "what": "", "rms": [0.112], "mean_rms": 0.112,
             "gap_closed": 0.0},
            {"candidate": "pi-stage", "what": "", "rms": [0.0252], "mean_rms": 0.0252,
             "gap_closed": 0.797}]
    lines = FinalModel(rows, "pi-stage", None, 0.003, "verdict").summary_lines("um")
    finals = [line for line in lines if line.startswith("final:")]
    assert finals == [lines[-1]]
    assert "pi-stage" in finals[0] and "0.0252 um" in finals[0] and "80 %" in finals[0]
