"""Replays of the cases the independent hostile-input audit (``benchmarks/audit_independent.py``)
found answered with a traceback, a hang, a silent wrong result or an overwrite: each is now a
clear error naming the file or option, or a result with the warning it deserves.

Every test is fast (records of 0.1-0.2 s) and needs no network.
"""

from __future__ import annotations

import json
import os
import struct
import sys
import warnings

import numpy as np
import pytest

from hystid.cli import main
from hystid.errors import ModelFileError, RecordError
from hystid.records import Record, load_record
from hystid.reference import reference_record

FS = 30_000.0


def cli(args: list[str], capsys) -> tuple[int, str, str]:
    """Run ``hystid ARGS`` in this process: exit status, stdout, stderr."""
    try:
        code = main([str(a) for a in args])
    except SystemExit as stop:  # argparse's refusals
        code = stop.code
    out = capsys.readouterr()
    return code, out.out, out.err


def one_error_line(err: str, *names: str) -> str:
    """The command's error: one line, no traceback, naming each of ``names``."""
    assert "Traceback" not in err
    lines = [ln for ln in err.strip().splitlines() if ": error:" in ln]
    assert len(lines) == 1, err
    for name in names:
        assert name in lines[0], lines[0]
    return lines[0]


@pytest.fixture(scope="module")
def train() -> Record:
    return reference_record(0.1, seed=0, name="train")


@pytest.fixture(scope="module")
def model(train):
    from hystid.identify import identify

    return identify(train, model="duhem").model


@pytest.fixture(scope="module")
def model_file(model, tmp_path_factory):
    from hystid.modelfile import save_model

    path = tmp_path_factory.mktemp("model") / "model.json"
    save_model(model, path)
    return path


def edited_model(model_file, tmp_path, edit=None, raw=None):
    """A copy of the model file after ``edit(doc)`` or ``raw(text)``."""
    text = model_file.read_text()
    if edit is not None:
        doc = json.loads(text)
        edit(doc)
        text = json.dumps(doc)
    if raw is not None:
        text = raw(text)
    path = tmp_path / "m.json"
    path.write_text(text)
    return path


# --------------------------------------------------------------------------- record files
def test_npz_member_claiming_lzma_with_bad_options_is_refused(train, tmp_path):
    path = tmp_path / "r.npz"
    np.savez(path, u=train.u, y=train.y, fs=FS)
    data = bytearray(path.read_bytes())
    for magic, at in ((b"PK\x03\x04", 8), (b"PK\x01\x02", 10)):  # every compression field
        pos = data.find(magic)
        while pos >= 0:
            data[pos + at:pos + at + 2] = struct.pack("<H", 14)
            pos = data.find(magic, pos + 4)
    path.write_bytes(bytes(data))
    with pytest.raises(RecordError, match="r.npz.*not a readable .npz"):
        load_record(path)


def test_h5_soft_links_in_a_loop_are_refused(train, tmp_path):
    h5py = pytest.importorskip("h5py")
    path = tmp_path / "r.h5"
    with h5py.File(path, "w") as fh:
        fh["u"] = h5py.SoftLink("/u")
        fh.create_dataset("y", data=train.y)
        fh.attrs["fs"] = FS
        fh["runs"] = h5py.SoftLink("/runs")
    with pytest.raises(RecordError, match=r"r.h5.*'u' is a link that cannot be followed"):
        load_record(path)
    with pytest.raises(RecordError, match=r"r.h5.*'runs' is a link that cannot be followed"):
        load_record(f"{path}:runs/a")


@pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="named pipes need a POSIX system")
def test_a_fifo_or_a_device_is_not_said_to_be_missing(tmp_path, capsys):
    os.mkfifo(tmp_path / "p.csv")
    with pytest.raises(RecordError, match=r"p.csv: file is not a regular file \(a FIFO"):
        load_record(tmp_path / "p.csv")
    if os.path.exists("/dev/zero"):
        os.symlink("/dev/zero", tmp_path / "z.csv")
        code, _, err = cli(["identify", tmp_path / "z.csv"], capsys)
        assert code == 2
        one_error_line(err, "z.csv", "not a regular file")
    with pytest.raises(RecordError, match="none.csv: file does not exist"):
        load_record(tmp_path / "none.csv")


def test_a_path_of_bytes_is_read_and_other_types_are_named(train, tmp_path):
    train.save(tmp_path / "r.csv")
    assert load_record(os.fsencode(tmp_path / "r.csv")).n == train.n
    for bad in (None, 123):
        with pytest.raises(TypeError, match="path: expected a file name"):
            load_record(bad)


def test_units_with_control_characters_are_refused(train, tmp_path, capsys):
    from hystid.records import parse_units

    with pytest.raises(RecordError, match="control characters"):
        Record(train.u, train.y, FS, units={"u": "V", "y": "um\nt,u,y"})
    with pytest.raises(ValueError, match="control characters"):
        parse_units("u=V\x1b[31m,y=um")
    train.save(tmp_path / "r.csv")
    with pytest.raises(RecordError, match="r.csv.*units="):
        load_record(tmp_path / "r.csv", units={"y": "um\n"})
    np.savez(tmp_path / "r.npz", u=train.u, y=train.y, fs=FS,
             units=np.array(json.dumps({"u": "V", "y": "um\nt,u,y"})))
    with pytest.raises(RecordError, match="control characters"):
        load_record(tmp_path / "r.npz")


def test_a_name_with_a_line_break_keeps_a_written_csv_readable(train, tmp_path):
    rec = Record(train.u, train.y, FS, name="run 1\n# t,u,y\x1b[2J")
    rec.save(tmp_path / "r.csv")
    back = load_record(tmp_path / "r.csv")
    assert back.n == rec.n and "\n" not in back.name and "\x1b" not in back.name


def test_stored_units_hystid_cannot_read_are_refused_unless_given(train, tmp_path):
    np.savez(tmp_path / "r.npz", u=train.u, y=train.y * 1e3, fs=FS, units=np.array("u=V,y=nm"))
    with pytest.raises(RecordError, match=r"r.npz.*'units' entry is 'u=V,y=nm'.*--units"):
        load_record(tmp_path / "r.npz")
    assert load_record(tmp_path / "r.npz", units={"u": "V", "y": "nm"}).units["y"] == "nm"


# --------------------------------------------------------------------------- model files
@pytest.mark.parametrize(("edit", "raw", "said"), [
    (lambda d: d["params"].__setitem__("alpha", True), None, "'alpha' must be a number"),
    (lambda d: d["params"].__setitem__("alpha", "0.8"), None, "'alpha' must be a number"),
    (None, lambda s: s.replace('"alpha": ', '"alpha": ' + "9" * 400 + ', "x": ', 1),
     "'alpha' is an integer of 400 digits"),
    (None, lambda s: s.replace('"fs": ', '"fs": ' + "3" * 400 + ', "x": ', 1),
     "'fs' is an integer of 400 digits"),
    (lambda d: d["envelope"].__setitem__("slew", True), None, "envelope: expected numbers"),
    (lambda d: d["envelope"].__setitem__("u_min", -10**400), None, "envelope: expected numbers"),
    (lambda d: d["units"].__setitem__("y", "um\x1b[2J\nFAKE"), None,
     "the unit of y is .* control characters"),
])
def test_model_file_entries_of_the_wrong_kind_are_refused(model_file, tmp_path, edit, raw,
                                                          said):
    from hystid.modelfile import load_model

    path = edited_model(model_file, tmp_path, edit, raw)
    with pytest.raises(ModelFileError, match=f"m.json: {said}"):
        load_model(path)


def test_list_entries_of_huge_integers_are_refused(tmp_path):
    from hystid.modelfile import _numbers

    with pytest.raises(ModelFileError, match="'rates' holds an integer of hundreds of digits"):
        _numbers({"rates": [10**400, 1.0]}, "rates", "m.json", "rates")
    with pytest.raises(ModelFileError, match="'thresholds' must be a list of numbers"):
        _numbers({"thresholds": [0.1, True]}, "thresholds", "m.json", "thresholds")


# --------------------------------------------------------------------------- identify
def test_a_record_in_1e_minus_300_volts_is_refused_not_divided_by_zero(train):
    from hystid.errors import IdentificationDataError
    from hystid.identify import identify

    tiny = Record(train.u * 1e-300, train.y, FS, name="tiny")
    with pytest.raises(IdentificationDataError, match=r"'tiny'.*input u spreads over .*1e-90"):
        identify(tiny)
    small = identify(Record(train.u, train.y * 1e-300, FS, name="small"),  # linear in y
                     model="duhem").model
    assert np.all(np.isfinite(small.theta)) and small.params["f1"] != 0.0


def test_identify_names_a_bad_progress_and_a_bad_theta0(train):
    from hystid.identify import identify

    with pytest.raises(TypeError, match="progress: expected a callable"):
        identify(train, progress=5)
    for method in ("batch", "online"):
        with pytest.raises(ValueError, match="theta0: expected"):
            identify(train, method, theta0="x")


def test_a_val_or_repeat_record_in_other_units_is_refused(train, tmp_path, capsys):
    train.save(tmp_path / "train.csv")
    nm = Record(train.u, train.y * 1e3, FS, units={"u": "V", "y": "nm"}, name="val")
    nm.save(tmp_path / "vnm.npz")
    code, _, err = cli(["identify", tmp_path / "train.csv", "--val", tmp_path / "vnm.npz"],
                       capsys)
    assert code == 2
    one_error_line(err, "--val", "vnm.npz", "y=nm", "y=um")
    code, _, err = cli(["identify", tmp_path / "train.csv", "--repeat", tmp_path / "vnm.npz"],
                       capsys)
    assert code == 2
    one_error_line(err, "--repeat", "vnm.npz")


def test_validating_on_the_record_itself_is_said(train, tmp_path, capsys):
    train.save(tmp_path / "train.csv")
    code, out, err = cli(["identify", tmp_path / "train.csv", "--val", tmp_path / "train.csv",
                          "--model", "duhem", "--json"], capsys)
    assert code == 0
    assert any("is the identification record itself" in w
               for w in json.loads(out)["warnings"])


def test_a_too_short_val_record_is_named(train, tmp_path, capsys):
    train.save(tmp_path / "train.csv")
    (tmp_path / "v2.csv").write_text("t,u,y\n0,1,1\n3.3333333333333335e-05,2,2\n")
    code, _, err = cli(["identify", tmp_path / "train.csv", "--val", tmp_path / "v2.csv",
                        "--model", "duhem", "--quiet"], capsys)
    assert code == 2
    one_error_line(err, "--val", "v2.csv", "too short")


def test_numeric_noise_of_the_baselines_fits_does_not_leak(tmp_path, capsys):
    """An output of pure noise: the linear baseline's least squares overflows on the way (a
    RuntimeWarning of scipy's); the command says what matters in its own lines only."""
    rng = np.random.default_rng(11)
    for name, seed in (("tr.csv", 0), ("va.csv", 1)):
        rec = reference_record(0.2, seed=seed)
        Record(rec.u, rng.normal(0.0, 1.0, rec.n), FS, name=name[:2]).save(tmp_path / name)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        code, _, err = cli(["identify", tmp_path / "tr.csv", "--val", tmp_path / "va.csv",
                            "--model", "duhem", "--quiet"], capsys)
    assert code == 0 and "does not beat" in err
    assert not [w for w in caught if "encountered" in str(w.message)]


def test_the_drift_check_is_well_conditioned_in_any_time_unit():
    from hystid.records_checks import output_is_drift

    k = np.arange(6000.0)
    y = 0.5 * k / 6000 + np.random.default_rng(3).normal(0.0, 1e-4, k.size)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # numpy's RankWarning for t in steps of 1e300 s
        said = output_is_drift(k * 1e300, y)
    assert said and "straight line in time (8.333e-305 per second)" in said[0]
    assert "(2.5 per second)" in output_is_drift(k / 30_000, y)[0]


def test_a_model_that_beats_its_baselines_yet_explains_little_is_said(model, train):
    from hystid.baselines import compare

    other = reference_record(0.1, seed=1, name="other stage")
    other = Record(other.u, 2.5 * other.y, FS, name="other stage")
    comparison = compare(model, train, [other])
    assert any("explains little" in note and "um" in note for note in comparison.notes)
    same = reference_record(0.1, seed=1, name="same stage")
    assert not any("explains little" in note for note in compare(model, train, [same]).notes)


def test_the_final_model_summary_gives_no_share_of_a_gap_of_nothing():
    from hystid.diagnose.final_model import FinalModel
    from hystid.metrics import gap_closed

    floor, nominal, other = 0.998e-3, 1.011e-3, 0.1228
    rows = [{"candidate": "nominal", "mean_rms": nominal, "gap_closed": 0.0},
            {"candidate": "pi-stage", "mean_rms": other,
             "gap_closed": gap_closed(nominal, other, floor)}]
    text = "\n".join(FinalModel(rows, "nominal", None, floor, "kept").summary_lines("um"))
    assert "no gap to close" in text and "121 x the nominal's RMS" in text
    assert " % of the gap" not in text
    rows[0]["mean_rms"] = 2 * floor  # a real gap: shares of it again
    text = "\n".join(FinalModel(rows, "nominal", None, floor, "kept").summary_lines("um"))
    assert "% of the gap to the floor" in text


# --------------------------------------------------------------------------- export
def test_a_too_short_rpem_record_is_refused_by_name(train, model_file, tmp_path, capsys):
    Record(train.u[:2], train.y[:2], FS, name="r2").save(tmp_path / "r2.csv")
    code, _, err = cli(["export", model_file, "--c", tmp_path / "c", "--rpem-record",
                        tmp_path / "r2.csv"], capsys)
    assert code == 2
    one_error_line(err, "--rpem-record", "r2.csv", "too few")
    code, _, err = cli(["export", model_file, "--c", tmp_path / "c", "--preview=1000000000"],
                       capsys)
    assert code == 2
    one_error_line(err, "--preview:")


# --------------------------------------------------------------------------- compensate
def test_a_scan_too_long_to_make_is_refused(model_file, tmp_path, capsys):
    from hystid.compensate import scan_reference

    code, _, err = cli(["compensate", model_file, "--scan", "triangle:50:2", "--seconds=1e9",
                        "--out", tmp_path / "c.csv"], capsys)
    assert code == 2
    one_error_line(err, "--seconds", "600")
    with pytest.raises(ValueError, match="periods: .* samples"):
        scan_reference("triangle", 50.0, periods=5e10)


def test_a_smoother_longer_than_a_second_is_refused(model, model_file, tmp_path, capsys):
    from hystid.compensate import smoothing_model

    with pytest.raises(ValueError, match="at most 1 s, 29999 samples at 30000 Hz"):
        smoothing_model(1_000_000_001, model.dt)
    assert smoothing_model(29_999, model.dt).dt == model.dt
    code, _, err = cli(["compensate", model_file, "--scan", "triangle:50:2",
                        "--smooth=1000000001", "--out", tmp_path / "c.csv"], capsys)
    assert code == 2
    one_error_line(err, "--smooth")
    code, _, err = cli(["export", model_file, "--c", tmp_path / "c", "--smooth", "1000000001"],
                       capsys)
    assert code == 2
    one_error_line(err, "--smooth")


def test_u_limits_given_as_text_are_named(model, train):
    from hystid.compensate import compensate

    for bad in ("0,5", (0, "a"), 5):
        with pytest.raises(ValueError, match="u_limits: expected two numbers"):
            compensate(model, train.y, u_limits=bad)


# --------------------------------------------------------------------------- fleet
def test_a_local_cluster_of_a_billion_workers_is_refused(tmp_path, capsys):
    pytest.importorskip("distributed")
    from hystid.errors import FleetError
    from hystid.fleet import fleet_client, max_local_workers

    code, _, err = cli(["fleet", "identify", tmp_path, "--out", tmp_path / "res",
                        "--workers", "1000000000"], capsys)
    assert code == 2
    one_error_line(err, "--workers", str(max_local_workers()))
    with pytest.raises(FleetError, match="workers: 1000000000 worker processes"):
        with fleet_client(workers=10**9):
            pass


# --------------------------------------------------------------------------- diagnose
def test_diagnose_refuses_held_out_records_in_other_units_and_bad_rounds(train):
    from hystid.diagnose import DiagnosisError, diagnose

    val = reference_record(0.1, seed=1, name="val")
    nm = Record(val.u, val.y * 1e3, FS, units={"u": "V", "y": "nm"}, name="val nm")
    with pytest.raises(DiagnosisError, match="'val nm': in u=V, y=nm"):
        diagnose(train, nm, progress=False)
    for rounds in (-1, 0, 21, True, 2.5):
        with pytest.raises(DiagnosisError, match="max_rounds: expected"):
            diagnose(train, val, max_rounds=rounds, progress=False)


def test_diagnose_command_refuses_no_effects_and_names_its_options(tmp_path, capsys):
    reference_record(0.2, seed=0, name="train").save(tmp_path / "train.csv")
    code, _, err = cli(["diagnose", tmp_path / "train.csv", "--effects", ""], capsys)
    assert code == 2
    one_error_line(err, "--effects", "names no effect")
    code, _, err = cli(["diagnose", tmp_path / "train.csv", "--train-skip", "1e9"], capsys)
    assert code == 2
    one_error_line(err, "--train-skip")


def test_error_shares_stay_shares_at_the_noise_floor():
    from hystid.diagnose.rounds import describe_unexplained
    from hystid.diagnose.where import Segment, localise
    from hystid.reference import paper_excitation, reference_model

    model = reference_model()
    u = paper_excitation(8000, FS, seed=5)
    sim = model.simulate(u)
    noise = np.random.default_rng(2).normal(0.0, 2e-3, u.size)
    where = localise([Segment(u, sim.y + noise, sim.y, sim.w1, FS)])
    for view, keys in ((where.time, ("mean_fraction", "trend_fraction")),
                       (where.branch, ("width_fraction", "common_fraction"))):
        for key in keys:
            assert 0.0 <= view[key] <= 1.0, (key, view[key])
    left = describe_unexplained(where, where.rms * 2)  # a floor above the error: no excess
    assert "no error above the floor" in " ".join(left["text"])


# --------------------------------------------------------------------------- simulate
def test_simulate_names_a_bad_x0_and_a_bad_p0(model, train):
    from hystid.reference import reference_model

    with pytest.raises(TypeError, match="x0: expected a hystid.InitialCondition"):
        model.simulate(train.u[:100], x0="garbage")
    with pytest.raises(TypeError, match="x0: expected"):
        reference_model().simulate(train.u[:100], x0=[0.0, 1.0])
    from hystid.identify import identify

    pi = identify(train, model="pi-stage").model
    with pytest.raises(ValueError, match="p0: expected 20 finite operator states"):
        pi.simulate(train.u[:100], p0="garbage")


# --------------------------------------------------------------------------- the audit
@pytest.mark.skipif(sys.platform == "win32", reason="the audit runs POSIX commands")
def test_the_audit_lists_its_cases():
    import subprocess
    from pathlib import Path

    script = Path(__file__).resolve().parents[1] / "benchmarks" / "audit_independent.py"
    out = subprocess.run([sys.executable, str(script), "--list", "--quick"], check=True,
                         capture_output=True, text=True).stdout
    assert int(out.strip().splitlines()[-1].split()[0]) >= 40
