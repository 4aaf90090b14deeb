"""The hostile cases of issue 20, replayed through the command line and the API.

Each case is answered by one clear line and exit status 2 (CLI), a ValueError or TypeError
naming what was expected (API), or a sound result with the warning it deserves.
"""

import json
import os
import warnings
from pathlib import Path

import numpy as np
import pytest

from hystid import cli
from hystid.cli import identify as identify_command
from hystid.identify import identify
from hystid.model import DuhemSandwich, Structure
from hystid.modelfile import ModelFileError, load_model
from hystid.operating import AdmissibilityWarning
from hystid.records import Record, RecordError, load_record
from hystid.records_checks import output_bursts, output_is_drift
from hystid.reference import reference_model, reference_record
from hystid.safeio import OutputError, check_output, folder_lock, write_text
from hystid.validate import MAX_BATCH_SAMPLES, MAX_RECURSIVE_SAMPLES


def run(args, capsys):
    """``hystid ARGS`` in-process: (status, stdout, stderr), argparse exits included."""
    try:
        code = cli.main([str(a) for a in args])
    except SystemExit as exc:
        code = int(exc.code)
    out = capsys.readouterr()
    assert "Traceback" not in out.err
    return code, out.out, out.err


def error_line(err: str) -> str:
    lines = [ln for ln in err.splitlines() if "error:" in ln]
    assert len(lines) == 1, err
    return lines[0]


@pytest.fixture(scope="module")
def folder(tmp_path_factory):
    """A record of the reference stage and a model file identified on it."""
    home = tmp_path_factory.mktemp("audit")
    rec = reference_record(0.1, seed=2, noise=1e-3, name="rec")
    rec.save(home / "rec.csv")
    reference_model().save(home / "model.json")
    return home


def model_doc(folder: Path, **changes) -> dict:
    doc = json.loads((folder / "model.json").read_text())
    for key, value in changes.items():
        target = doc
        *path, last = key.split(".")
        for part in path:
            target = target[part]
        target[last] = value
    return doc


# --------------------------------------------------------------------------- options
@pytest.mark.parametrize(("args", "needle"), [
    (["identify", "{rec}", "--crop", "0:1e308"], "--crop"),
    (["identify", "{rec}", "--crop", "1e308:2e308"], "--crop"),
    (["simulate", "--seconds", "1e-9", "--seed", "0", "--out", "{tmp}/s.csv"], "--seconds"),
    (["demo", "--seconds", "0.001", "--out", "{tmp}/demo"], "--seconds"),
    (["fleet", "identify", "{rec}", "--seed=-1", "--out", "{tmp}/fleet"], "--seed"),
    (["fleet", "identify", "{rec}", f"--seed={2**70}", "--out", "{tmp}/fleet"], "--seed"),
])
def test_options_out_of_range_are_one_line(folder, tmp_path, capsys, args, needle):
    args = [a.format(rec=folder / "rec.csv", tmp=tmp_path) for a in args]
    code, _, err = run(args, capsys)
    assert code == 2
    assert needle in error_line(err)
    assert list(tmp_path.iterdir()) == []


def test_crop_error_names_the_file(folder, capsys):
    code, _, err = run(["identify", folder / "rec.csv", "--crop", "0:1e308"], capsys)
    assert code == 2 and str(folder / "rec.csv") in err


# --------------------------------------------------------------------------- record files
def _flagged(src: Path, dst: Path, flags: int = 0, method: int | None = None) -> Path:
    data = bytearray(src.read_bytes())
    for sig, flag_at, method_at in ((b"PK\x03\x04", 6, 8), (b"PK\x01\x02", 8, 10)):
        i = data.find(sig)
        while i >= 0:
            data[i + flag_at] |= flags
            if method is not None:
                data[i + method_at:i + method_at + 2] = method.to_bytes(2, "little")
            i = data.find(sig, i + 4)
    dst.write_bytes(bytes(data))
    return dst


@pytest.mark.parametrize(("flags", "method"), [(1, None), (0, 99)])
def test_npz_encrypted_or_unknown_compression(tmp_path, capsys, flags, method):
    src = tmp_path / "rec.npz"
    reference_record(0.01, seed=0).save(src)
    bad = _flagged(src, tmp_path / "bad.npz", flags, method)
    with pytest.raises(RecordError, match="not a readable .npz"):
        load_record(bad)
    code, _, err = run(["identify", bad], capsys)
    assert code == 2 and str(bad) in error_line(err)


# --------------------------------------------------------------------------- model files
_REFUSED = [
    ({"provenance": "hello"}, "'provenance' must be a mapping"),
    ({"provenance": 3}, "'provenance' must be a mapping"),
    ({"provenance": [1, 2]}, "'provenance' must be a mapping"),
    ({"params.a21": 0.0, "params.a22": 1.0}, "L2 has a pole of radius 1"),
    ({"params.a21": -2.0, "params.a22": 1.0}, "L2 has a pole of radius 1"),
    ({"params.a21": -2.02, "params.a22": 1.0201}, "L2 has a pole of radius 1.01"),
    ({"params.a21": -2.1, "params.a22": 1.1025}, "L2 has a pole of radius 1.05"),
    ({"params.alpha": -0.5}, "alpha > 0"),
    ({"params.g0": 1e200}, "'g0' is 1e+200"),
    ({"offset": 1e308}, "'offset' is 1e+308"),
    ({"envelope": {"u_min": 0.0, "u_max": 1e308, "slew": 1.0}}, "envelope 'u_max' is 1e+308"),
    ({"structure.q1": 10**9}, "q1=1000000000"),
    ({"structure.n2a": 10000}, "n2a=10000"),
]


@pytest.mark.parametrize(("changes", "needle"), _REFUSED)
def test_unsound_model_files_are_refused_on_load(folder, tmp_path, capsys, changes, needle):
    path = tmp_path / "m.json"
    path.write_text(json.dumps(model_doc(folder, **changes)))
    with pytest.raises(ModelFileError, match=needle.replace("(", r"\(").replace("+", r"\+")):
        load_model(path)
    code, _, err = run(["simulate", "--model", path, "--input", folder / "rec.csv", "--out",
                        tmp_path / "s.csv"], capsys)
    assert code == 2 and needle in error_line(err) and str(path) in err
    assert not (tmp_path / "s.csv").exists()


def test_deeply_nested_provenance(folder, tmp_path):
    text = json.dumps(model_doc(folder, provenance=0))
    deep = tmp_path / "deep.json"
    deep.write_text(text.replace('"provenance": 0', '"provenance": ' + "[" * 100000
                                 + "]" * 100000))
    with pytest.raises(ModelFileError, match="nested too deeply"):
        load_model(deep)
    nested: dict = {}
    cur = nested
    for _ in range(200):
        cur["x"] = cur = {}
    (tmp_path / "n.json").write_text(json.dumps(model_doc(folder, provenance=nested)))
    with pytest.raises(ModelFileError, match="nests deeper"):
        load_model(tmp_path / "n.json")


def test_a_sound_model_file_still_loads(folder):
    model = load_model(folder / "model.json")
    assert model.is_stable() and model.params["alpha"] > 0


@pytest.mark.parametrize("kind", ["fifo", "dev_zero", "huge"])
def test_model_file_must_be_a_plain_small_file(tmp_path, capsys, folder, kind):
    path = tmp_path / "m.json"
    if kind == "fifo":
        os.mkfifo(path)
        needle = "not a regular file"
    elif kind == "dev_zero":
        path.symlink_to("/dev/zero")
        needle = "not a regular file"
    else:
        with open(path, "wb") as out:
            out.truncate(17 << 20)  # sparse: no disk used
        needle = "at most"
    with pytest.raises(ModelFileError, match=needle):
        load_model(path)
    code, _, err = run(["simulate", "--model", path, "--input", folder / "rec.csv", "--out",
                        tmp_path / "s.csv"], capsys)
    assert code == 2 and needle in error_line(err)


def test_delays_longer_than_the_input_record(folder, tmp_path, capsys):
    path = tmp_path / "m.json"
    path.write_text(json.dumps(model_doc(folder, **{"structure.q1": 900})))
    short = tmp_path / "short.csv"
    reference_record(0.05, seed=0, name="short").save(short)  # 1500 samples
    code, _, err = run(["simulate", "--model", path, "--input", short, "--out",
                        tmp_path / "s.csv"], capsys)
    assert code == 2 and "900 samples into the past" in error_line(err)


def test_simulate_warns_on_an_unsound_model():
    model = DuhemSandwich([0.8, 0.1, 0.004, -0.5, -2.1, 1.1025])  # L2 poles at 1.05
    with pytest.warns(AdmissibilityWarning, match="pole of radius 1.05"):
        resp = model.simulate(np.sin(np.arange(3000) / 50.0))
    assert any("not sound" in w for w in resp.warnings)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        reference_model().simulate(np.sin(np.arange(300) / 50.0))  # a sound one: no warning


# --------------------------------------------------------------------------- API misuse
def test_identify_refuses_what_is_not_a_record(folder):
    with pytest.raises(TypeError, match="expected a hystid.records.Record, got NoneType"):
        identify(None)
    with pytest.raises(TypeError, match="load_record"):
        identify(str(folder / "rec.csv"))
    with pytest.raises(TypeError, match=r"array of shape \(100, 2\)"):
        identify(np.zeros((100, 2)))
    rec = load_record(folder / "rec.csv")
    with pytest.raises(TypeError, match="structure: expected a hystid.Structure"):
        identify(rec, structure=3)
    with pytest.raises(ValueError, match="method"):
        identify(rec, method=7)


def test_delays_are_bounded():
    with pytest.raises(ValueError, match=r"q1=1000000000 \(expected a delay"):
        Structure(q1=10**9)
    rec = reference_record(0.02, seed=0)  # 600 samples
    with pytest.raises(ValueError, match="half the record"):
        identify(rec, structure=Structure(q1=400))


@pytest.mark.parametrize(("method", "n", "needle"), [
    ("batch", MAX_BATCH_SAMPLES + 1, "--method online"),
    ("online", MAX_RECURSIVE_SAMPLES + 1, "decimate"),
    ("eria", MAX_RECURSIVE_SAMPLES + 1, "decimate"),
])
def test_long_records_are_refused_before_the_fit(tmp_path, capsys, monkeypatch, method, n,
                                                 needle):
    k = np.arange(n)
    rec = Record(np.sin(k / 300.0) + 1.0, np.sin(k / 300.0 - 0.1), 30000.0, name="long")
    path = tmp_path / "long.npz"
    rec.save(path)
    del rec

    def boom(*args, **kwargs):
        raise AssertionError("the fit started")

    monkeypatch.setattr("hystid.identify.identify", boom)
    code, _, err = run(["identify", path, "--holdout", "0", "--method", method], capsys)
    assert code == 2 and needle in error_line(err) and str(path) in err


# --------------------------------------------------------------------------- input offset
@pytest.mark.parametrize("method,model", [("batch", "duhem"), ("online", "duhem"),
                                          ("batch", None)])
def test_an_input_offset_does_not_change_the_predictions(method, model):
    train = reference_record(0.1, seed=3, noise=1e-3)
    val = reference_record(0.1, seed=4, noise=1e-3)
    predictions = []
    for shift in (0.0, 100.0, 1e4):
        rec = Record(train.u + shift, train.y, train.fs, train.units, train.name)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            result = identify(rec, method=method, model=model)
        assert not any("rest" in w for w in result.info.get("warnings", []))
        assert result.model.u_rest == pytest.approx(shift)
        predictions.append(result.model.simulate(val.u + shift).y)
    scale = np.max(np.abs(predictions[0]))
    for other in predictions[1:]:
        assert np.max(np.abs(other - predictions[0])) <= 1e-6 * scale
    assert np.sqrt(np.mean((predictions[0] - val.y) ** 2)) < 0.01  # and the fit is good


# --------------------------------------------------------------------------- overwrites
def test_a_file_appearing_at_a_new_output_is_kept(tmp_path, capsys, monkeypatch):
    out = tmp_path / "s.csv"
    from hystid import reference

    real = reference.reference_record

    def meanwhile(*args, **kwargs):
        out.write_text("written by the other run\n")
        return real(*args, **kwargs)

    monkeypatch.setattr(reference, "reference_record", meanwhile)
    code, _, err = run(["simulate", "--seconds", "0.01", "--seed", "0", "--quiet", "--out",
                        out], capsys)
    assert code == 2 and "appeared while the command ran" in error_line(err)
    assert out.read_text() == "written by the other run\n"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["s.csv"]


def test_a_report_appearing_in_out_during_a_fit_is_kept(folder, tmp_path, capsys,
                                                        monkeypatch):
    out = tmp_path / "rep"
    real = identify_command._identify_record

    def meanwhile(*args, **kwargs):
        out.mkdir()
        (out / "report.json").write_text("mine\n")
        return real(*args, **kwargs)

    monkeypatch.setattr(identify_command, "_identify_record", meanwhile)
    code, _, err = run(["identify", folder / "rec.csv", "--quiet", "--out", out], capsys)
    assert code == 2 and "report.json: appeared" in error_line(err)
    assert (out / "report.json").read_text() == "mine\n"
    assert sorted(p.name for p in out.iterdir()) == ["report.json"]


def test_force_still_replaces_at_commit_time(tmp_path):
    out = tmp_path / "x.txt"
    check_output(out, option="--out", force=True)
    out.write_text("old\n")
    write_text(out, "new\n")
    assert out.read_text() == "new\n"
    check_output(tmp_path / "y.txt", option="--out")
    (tmp_path / "y.txt").write_text("theirs\n")
    with pytest.raises(OutputError, match="appeared"):
        write_text(tmp_path / "y.txt", "mine\n")
    assert (tmp_path / "y.txt").read_text() == "theirs\n"


def test_a_second_fleet_in_the_same_folder_fails(folder, tmp_path, capsys):
    out = tmp_path / "fleet"
    out.mkdir()
    with folder_lock(out):
        code, _, err = run(["fleet", "identify", folder / "rec.csv", "--workers", "1",
                            "--quiet", "--out", out], capsys)
        assert code == 2 and "another hystid run" in error_line(err)
        with pytest.raises(OutputError, match="another hystid run"), folder_lock(out):
            pass
    assert list(out.iterdir()) == []
    (out / ".hystid.lock").write_text("999999999")  # left by a process that ended
    with folder_lock(out) as lock:
        assert lock.read_text() == str(os.getpid())
    assert not (out / ".hystid.lock").exists()


# --------------------------------------------------------------------------- newcomer
def test_val_help_says_the_end_is_held_out(capsys):
    with pytest.raises(SystemExit):
        cli.main(["identify", "--help"])
    text = " ".join(capsys.readouterr().out.split())
    assert "validate on the record itself" not in text
    assert "the last --holdout share of the record" in text


def test_missing_column_hint_in_cli_syntax(tmp_path, capsys):
    path = tmp_path / "noheader.csv"
    path.write_text("".join(f"{k},{np.sin(k / 5):.4f},{np.cos(k / 5):.4f}\n"
                            for k in range(200)))
    code, _, err = run(["identify", path], capsys)
    line = error_line(err)
    assert code == 2 and "--columns u=1,y=2" in line and "columns={" not in line
    with pytest.raises(RecordError, match=r"columns=\{'u': 1, 'y': 2\}"):  # Python's own
        load_record(path)


@pytest.mark.parametrize("args", [
    ["diagnose", "{csv}"],
    ["compensate", "{model}", "--reference", "{csv}", "--out", "{tmp}/u.csv"],
])
def test_missing_column_hint_in_cli_syntax_where_the_command_has_columns(folder, tmp_path,
                                                                         capsys, args):
    path = tmp_path / "noheader.csv"
    path.write_text("".join(f"{k},{np.sin(k / 5):.4f},{np.cos(k / 5):.4f}\n"
                            for k in range(200)))
    argv = [a.format(csv=path, model=folder / "model.json", tmp=tmp_path) for a in args]
    code, _, err = run(argv, capsys)
    line = error_line(err)
    assert code == 2 and "--columns u=1,y=2" in line and "columns={" not in line, line


def test_missing_column_hint_stays_python_where_the_command_has_no_columns(folder, tmp_path,
                                                                           capsys):
    path = tmp_path / "noheader.csv"
    path.write_text("".join(f"{k},{np.sin(k / 5):.4f},{np.cos(k / 5):.4f}\n"
                            for k in range(200)))
    code, _, err = run(["export", folder / "model.json", "--c", tmp_path / "c", "--rpem-record",
                        path], capsys)
    line = error_line(err)
    assert code == 2 and "--columns" not in line and "columns={'u': 1, 'y': 2}" in line, line


def test_printed_figures_carry_units(folder, capsys):
    code, out, _ = run(["identify", folder / "rec.csv", "--quiet"], capsys)
    assert code == 0
    assert "RMS " in out and " um, fit" in out and "u_rest [V]" in out and "offset [um]" in out


# --------------------------------------------------------------------------- record faults
def test_output_burst_and_drift_are_warned_about():
    rec = reference_record(0.2, seed=1, noise=1e-3)
    y = rec.y.copy()
    y[2000:2100] += 5.0
    assert "leaps by +4.99" in " ".join(output_bursts(rec.u, y))
    assert output_bursts(rec.u, rec.y) == []
    drift = np.linspace(0.0, 3.0, rec.n) + 1e-3 * np.random.default_rng(1).standard_normal(rec.n)
    assert output_is_drift(rec.t, drift)
    assert output_is_drift(rec.t, rec.y) == []
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        result = identify(Record(rec.u, drift, rec.fs), method="online", model="duhem")
    assert any("straight line in time" in w for w in result.info["warnings"])


def test_compare_refuses_a_record_at_another_rate_or_in_other_units():
    """A 10 kHz model scored on a 200 Hz record, or metres beside micrometres, gave figures
    without a word."""
    from hystid.baselines import compare
    from hystid.testing import stage_a_like, with_units

    train = stage_a_like("prbn", seconds=0.3, rest_seconds=0.05, seed=2)
    held = stage_a_like("sine50", seconds=0.3, rest_seconds=0.05, seed=3)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        model = identify(train, model="duhem").model
    slow = Record(held.u[::50], held.y[::50], held.fs / 50, units=held.units, name="slow")
    with pytest.raises(ValueError, match=r"record 'slow': sampled at 200 Hz, the model at 10000"):
        compare(model, train, [slow])
    with pytest.raises(ValueError, match=r"y in m, the training record .* in um"):
        compare(model, train, [with_units(held, y="m")])
    assert len(compare(model, train, [held]).rows) == 1


def test_an_unknown_setting_and_an_empty_input_are_named():
    """``identify(rec, foo=1)`` raised a TypeError naming an internal function, and
    ``model.simulate([])`` an error from inside numpy's reductions."""
    from hystid.testing import stage_a_like

    rec = stage_a_like("prbn", seconds=0.2, rest_seconds=0.05, seed=1)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        for kwargs in ({"model": "duhem"}, {"model": "pi-stage"},
                       {"method": "online", "model": "duhem"}):
            with pytest.raises(ValueError, match=r"^foo: not a setting of method="):
                identify(rec, foo=1, **kwargs)
        model = identify(rec, model="duhem").model
    with pytest.raises(ValueError, match=r"u is empty \(expected at least 1 sample\)"):
        model.simulate(np.array([]))


def test_a_time_column_in_milliseconds_is_said(tmp_path, capsys):
    """A 5 kHz record whose ``t`` column is in milliseconds read as 5 Hz without a word."""
    from hystid.testing import stage_a_like

    rec = stage_a_like("prbn", seconds=0.3, rest_seconds=0.05, seed=2)
    path = tmp_path / "ms.csv"
    np.savetxt(path, np.c_[1e3 * rec.t, rec.u, rec.y], delimiter=",", header="t,u,y",
               comments="")
    code, _, err = run(["identify", path, "--model", "duhem", "--quiet"], capsys)
    assert code == 0
    said = [line for line in err.splitlines() if "sampled at 10 Hz" in line]
    assert len(said) == 1 and "milliseconds" in said[0]
    code, _, err = run(["identify", folder_of(rec, tmp_path), "--model", "duhem", "--quiet"],
                       capsys)
    assert code == 0 and "sampled at" not in err


def folder_of(rec: Record, tmp_path: Path) -> Path:
    """The record saved as it is (t in seconds)."""
    rec.save(tmp_path / "s.csv")
    return tmp_path / "s.csv"


def test_the_drift_check_is_not_decided_by_a_few_wild_samples():
    rec = reference_record(0.2, seed=1, noise=1e-3)
    spiked = rec.y.copy()
    spiked[3000] = 1e6  # one wild sample made the stage's output look flat beside it
    assert output_is_drift(rec.t, spiked) == []
    drift = np.linspace(0.0, 3.0, rec.n) + 1e-3 * np.random.default_rng(1).standard_normal(rec.n)
    drift[3000], drift[100] = 1e6, np.nan  # nor do they hide a drift (a gap made it silent)
    said = output_is_drift(rec.t, drift)
    assert said and f"({3.0 / (rec.t[-1] - rec.t[0]):.4g} per second)" in said[0]


def test_records_of_huge_values_are_refused(tmp_path, capsys):
    k = np.arange(2000)
    rec = Record(np.sin(k / 50.0) * 1e300, np.sin(k / 50.0 - 0.2) * 1e299, 1000.0, name="huge")
    with pytest.raises(ValueError, match="u reaches 1e\\+300"):
        identify(rec)
    path = tmp_path / "huge.npz"
    rec.save(path)
    for args in (["identify", path], ["identify", path, "--model", "pi"], ["diagnose", path]):
        code, _, err = run(args, capsys)
        assert code == 2 and "at most 1e+100" in error_line(err) and str(path) in err


def test_diagnose_refuses_a_record_longer_than_the_batch_cap(tmp_path, capsys, monkeypatch):
    n = MAX_BATCH_SAMPLES + 1
    rec = Record(np.sin(np.arange(n) / 300.0), np.cos(np.arange(n) / 300.0), 30000.0)
    path = tmp_path / "long.npz"
    rec.save(path)

    def boom(*args, **kwargs):
        raise AssertionError("the diagnosis started")

    monkeypatch.setattr("hystid.diagnose.diagnosis.diagnose", boom)
    code, _, err = run(["diagnose", path, "--quiet"], capsys)
    line = error_line(err)
    assert code == 2 and "--crop" in line and "--method online" not in line
