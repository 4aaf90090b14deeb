"""Hostile inputs and faults, replayed through the command line and the API.

For each case: exit status 2 with a message naming the file or option, or a sound result; never
a traceback; no file the user had is changed (bytes and modification times compared).
"""

import errno
import io
import json
import os
import subprocess
import sys
import tracemalloc
import zipfile
from pathlib import Path

import numpy as np
import pytest

from hystid import cli
from hystid.cli import identify as identify_command
from hystid.records import Record, RecordError, load_record
from hystid.safeio import OutputError, check_output, dumps_strict, write_json


# --------------------------------------------------------------------------- helpers
def run(args, capsys):
    """``hystid ARGS`` in-process: (status, stdout, stderr), argparse exits included."""
    try:
        code = cli.main([str(a) for a in args])
    except SystemExit as exc:
        code = int(exc.code)
    out = capsys.readouterr()
    assert "Traceback" not in out.err
    return code, out.out, out.err


def snapshot(folder: Path) -> dict:
    """Bytes and modification time of every file below ``folder``."""
    return {p: (p.read_bytes(), p.stat().st_mtime_ns) for p in sorted(folder.rglob("*"))
            if p.is_file() and not p.is_symlink()}


def small_record(n: int = 600, fs: float = 1000.0) -> Record:
    k = np.arange(n)
    u = np.sin(2 * np.pi * 7 * k / fs) + 0.3 * np.sin(2 * np.pi * 31 * k / fs)
    y = np.tanh(1.5 * u) + 0.05 * np.cos(k / 9.0)
    return Record(u, y, fs, name="small")


@pytest.fixture(scope="module")
def simulated(tmp_path_factory):
    """A record of the built-in stage and the folder written by ``identify --out``."""
    folder = tmp_path_factory.mktemp("hostile")
    rec = folder / "train.csv"
    assert cli.main(["simulate", "--seconds", "0.05", "--seed", "4", "--quiet",
                     "--out", str(rec)]) == 0
    assert cli.main(["identify", str(rec), "--quiet", "--out", str(folder / "report")]) == 0
    return rec, folder / "report"


@pytest.fixture
def never_fit(monkeypatch):
    """Fail the test if the command gets as far as fitting or simulating."""

    def boom(*args, **kwargs):
        raise AssertionError("work started before the outputs were checked")

    monkeypatch.setattr(identify_command, "_identify_record", boom)
    monkeypatch.setattr("hystid.reference.reference_record", boom)
    monkeypatch.setattr("hystid.identify.identify", boom)


# --------------------------------------------------------------------------- outputs first
def test_history_onto_the_record_is_refused_before_work(tmp_path, capsys, never_fit):
    path = tmp_path / "mydata.csv"
    small_record().save(path)
    before = snapshot(tmp_path)
    code, _, err = run(["identify", path, "--method", "online", "--history", path], capsys)
    assert code == 2 and "--history" in err and "input file" in err
    code, _, err = run(["identify", path, "--val", path, "--history",
                        tmp_path / "." / "mydata.csv"], capsys)
    assert code == 2 and "input file" in err
    assert snapshot(tmp_path) == before


def test_existing_outputs_are_kept_without_force(tmp_path, capsys, never_fit):
    rec = tmp_path / "rec.csv"
    small_record().save(rec)
    old = tmp_path / "old.csv"
    old.write_text("precious\n")
    (tmp_path / "rep").mkdir()
    (tmp_path / "rep" / "report.json").write_text("{}")
    before = snapshot(tmp_path)
    cases = [
        (["simulate", "--seconds", "0.01", "--seed", "0", "--out", old], "--force"),
        (["identify", rec, "--fs", "1000", "--history", old], "--force"),
        (["identify", rec, "--out", tmp_path / "rep"], "report.json"),
        (["identify", rec, "--out", old], "is a file"),
        (["demo", "--out", tmp_path / "rep"], "--force"),
        (["diagnose", rec, "--out", tmp_path / "rep"], "--force"),
        (["identify", rec, "--out", old / "sub"], "not a folder"),
        (["simulate", "--seconds", "0.01", "--seed", "0", "--out", tmp_path / "no" / "x.csv"],
         "does not exist"),
    ]
    for args, needle in cases:
        code, _, err = run(args, capsys)
        assert code == 2, args
        assert needle in err and str(args[-1]) in err, (args, err)
    assert snapshot(tmp_path) == before


def test_symlinks_are_not_followed(tmp_path, capsys):
    target = tmp_path / "target.csv"
    target.write_text("keep me\n")
    link = tmp_path / "link.csv"
    link.symlink_to(target)
    before = snapshot(tmp_path)
    code, _, err = run(["simulate", "--seconds", "0.01", "--seed", "0", "--force",
                        "--out", link], capsys)
    assert code == 2 and "symbolic link" in err
    assert snapshot(tmp_path) == before and link.is_symlink()


def test_force_replaces_an_output_and_only_that(tmp_path, capsys):
    old = tmp_path / "old.npz"
    old.write_bytes(b"stale")
    other = tmp_path / "other.txt"
    other.write_text("untouched")
    code, _, err = run(["simulate", "--seconds", "0.01", "--seed", "0", "--quiet", "--force",
                        "--out", old], capsys)
    assert code == 0, err
    assert load_record(old).n == 300 and other.read_text() == "untouched"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["old.npz", "other.txt"]


def test_unwritable_folder_is_refused(tmp_path, monkeypatch, capsys, never_fit):
    locked = tmp_path / "locked"
    locked.mkdir()
    real_access = os.access

    def access(path, mode, **kwargs):  # a folder without write permission, even for root
        if Path(path) == locked and mode & os.W_OK:
            return False
        return real_access(path, mode, **kwargs)

    monkeypatch.setattr(os, "access", access)
    with pytest.raises(OutputError, match="permission denied"):
        check_output(locked / "x.csv", option="--out")
    code, _, err = run(["simulate", "--seconds", "0.01", "--seed", "0",
                        "--out", locked / "x.csv"], capsys)
    assert code == 2 and "permission denied" in err and "--out" in err
    code, _, err = run(["identify", "rec.csv", "--out", locked / "report"], capsys)
    assert code == 2 and "permission denied" in err
    assert list(locked.iterdir()) == []


# --------------------------------------------------------------------------- atomic writes
@pytest.mark.parametrize("suffix", [".csv", ".npz", ".mat", ".h5"])
def test_disk_full_leaves_the_previous_file(tmp_path, monkeypatch, suffix):
    path = tmp_path / f"rec{suffix}"
    small_record(200).save(path)
    before = snapshot(tmp_path)

    def full(fd):
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(os, "fsync", full)
    with pytest.raises(OSError, match="No space left"):
        small_record(400).save(path)
    assert snapshot(tmp_path) == before
    assert load_record(path).n == 200


def test_a_writer_failing_midway_leaves_the_previous_file(tmp_path, monkeypatch):
    path = tmp_path / "rec.csv"
    small_record(200).save(path)
    before = snapshot(tmp_path)

    def half(out, data, **kwargs):
        out.write("0,1,2\n0,1")
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(np, "savetxt", half)
    with pytest.raises(OSError):
        small_record(400).save(path)
    assert snapshot(tmp_path) == before


def test_disk_full_through_the_command_line(tmp_path, monkeypatch, capsys):
    out = tmp_path / "sim.csv"
    out.write_text("previous\n")

    def full(fd):
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(os, "fsync", full)
    code, _, err = run(["simulate", "--seconds", "0.01", "--seed", "0", "--quiet", "--force",
                        "--out", out], capsys)
    assert code == 2 and "No space left" in err and "left as they were" in err
    assert out.read_text() == "previous\n"
    assert [p.name for p in tmp_path.iterdir()] == ["sim.csv"]


def test_reports_are_strict_json(tmp_path):
    doc = {"fit": float("nan"), "rms": np.float64(np.inf), "values": np.array([1.0, -np.inf]),
           "notes": ["kept"]}
    write_json(tmp_path / "r.json", doc)
    text = (tmp_path / "r.json").read_text()
    parsed = json.loads(text, parse_constant=lambda name: pytest.fail(f"{name} in the report"))
    assert parsed["fit"] is None and parsed["values"] == [1.0, None]
    assert parsed["notes"][0] == "kept" and len(parsed["notes"]) == 4
    assert "$.fit was nan" in parsed["notes"][1]
    with pytest.raises(TypeError, match=r"\$.obj"):
        dumps_strict({"obj": object()})


# --------------------------------------------------------------------------- hostile files
def _h5(path, build):
    import h5py

    with h5py.File(path, "w") as f:
        build(f)
        f.attrs["fs"] = 1000.0


def _hostile_files(folder: Path) -> dict[str, str]:
    """Write the hostile record files; return file name -> expected words of the message."""
    import h5py
    from scipy.io import savemat

    n = 1000
    ones = np.ones(n)
    _h5(folder / "huge.h5", lambda f: [f.create_dataset(k, shape=(50_000_000,), dtype="f8")
                                       for k in "uy"])
    _h5(folder / "unwritten.h5", lambda f: (f.create_dataset("u", shape=(n,), dtype="f8"),
                                            f.create_dataset("y", data=ones)))
    with h5py.File(folder / "secret.h5", "w") as f:
        f.create_dataset("data", data=np.arange(float(n)))
    _h5(folder / "extlink.h5", lambda f: (f.__setitem__("u", h5py.ExternalLink("secret.h5",
                                                                                 "/data")),
                                          f.create_dataset("y", data=ones)))
    (folder / "secret.bin").write_bytes(np.arange(float(n)).tobytes())
    _h5(folder / "extstore.h5", lambda f: (
        f.create_dataset("u", shape=(n,), dtype="<f8", external=[("secret.bin", 0, 8 * n)]),
        f.create_dataset("y", data=ones)))
    with zipfile.ZipFile(folder / "bomb.npz", "w", zipfile.ZIP_DEFLATED) as z:
        for key in "uy":
            with z.open(f"{key}.npy", "w", force_zip64=True) as member:
                np.lib.format.write_array_header_1_0(
                    member, {"descr": "<f8", "fortran_order": False, "shape": (40_000_000,)})
                block = bytes(1 << 20)
                for _ in range(320):
                    member.write(block)
    Record(np.sin(np.arange(n) / 10.0), ones, 1000.0).save(folder / "good.npz")
    data = (folder / "good.npz").read_bytes()
    (folder / "truncated.npz").write_bytes(data[: len(data) // 2])
    header = io.BytesIO()
    np.save(header, np.zeros(10))
    with zipfile.ZipFile(folder / "lying.npz", "w") as z:
        z.writestr("u.npy", header.getvalue().replace(b"(10,), ", b"(9999,),"))
        z.writestr("y.npy", header.getvalue())
        z.writestr("fs.npy", header.getvalue())
    savemat(folder / "bomb.mat", {"u": np.zeros(30_000_000), "y": np.zeros(30_000_000),
                                  "fs": 1000.0}, do_compression=True)
    Record(np.sin(np.arange(n) / 10.0), ones, 1000.0).save(folder / "good.mat")
    data = (folder / "good.mat").read_bytes()
    (folder / "truncated.mat").write_bytes(data[: len(data) // 2])
    Record(np.sin(np.arange(n) / 10.0), ones, 1000.0).save(folder / "good.h5")
    data = (folder / "good.h5").read_bytes()
    (folder / "truncated.h5").write_bytes(data[: len(data) - 3000])
    (folder / "empty.npz").write_bytes(b"")
    return {
        "huge.h5": "declares 400,000,000 bytes",
        "unwritten.h5": "unwritten or truncated",
        "extlink.h5": "external link to secret.h5",
        "extstore.h5": "external files ['secret.bin']",
        "bomb.npz": "decompression bomb",
        "truncated.npz": "not a readable .npz",
        "lying.npz": "declares shape (9999,)",
        "bomb.mat": "decompression bomb",
        "truncated.mat": "truncated",
        "truncated.h5": "not a readable HDF5",
        "empty.npz": "not a readable .npz",
    }


@pytest.fixture(scope="module")
def hostile(tmp_path_factory):
    folder = tmp_path_factory.mktemp("files")
    return folder, _hostile_files(folder)


def test_hostile_files_are_refused_with_bounded_memory(hostile):
    folder, cases = hostile
    for name, needle in cases.items():
        tracemalloc.start()
        try:
            with pytest.raises(RecordError) as err:
                load_record(folder / name)
            peak = tracemalloc.get_traced_memory()[1]
        finally:
            tracemalloc.stop()
        assert name in str(err.value) and needle in str(err.value), (name, str(err.value))
        assert peak < 20e6, (name, peak)


def test_hostile_files_through_the_command_line(hostile, capsys):
    folder, cases = hostile
    before = snapshot(folder)
    for name in cases:
        code, out, err = run(["identify", folder / name, "--quiet"], capsys)
        assert code == 2 and name in err and out == "", (name, err)
    assert snapshot(folder) == before


def test_the_good_files_still_load(hostile):
    folder, _ = hostile
    for name in ("good.npz", "good.mat", "good.h5"):
        assert load_record(folder / name).n == 1000


# --------------------------------------------------------------------------- columns
def test_output_column_equal_to_the_input_column_is_refused(tmp_path, capsys):
    path = tmp_path / "rec.csv"
    small_record().save(path)
    for columns in ("u=y,y=y", "u=y", "t=u", "u=1,y=1"):
        code, _, err = run(["identify", path, "--columns", columns], capsys)
        assert code == 2 and "--columns" in err and "both read column" in err, (columns, err)
        code, _, err = run(["diagnose", path, "--columns", columns], capsys)
        assert code == 2 and "--columns" in err, (columns, err)
    with pytest.raises(RecordError, match="u and y both read column 'Y'"):
        load_record(path, columns={"u": "y", "y": "Y"})


# --------------------------------------------------------------------------- options
@pytest.mark.parametrize("args, option", [
    (["simulate", "--seconds", "inf", "--seed", "0", "--out", "x.csv"], "--seconds"),
    (["simulate", "--seconds", "nan", "--seed", "0", "--out", "x.csv"], "--seconds"),
    (["simulate", "--seconds", "1e9", "--seed", "0", "--out", "x.csv"], "--seconds"),
    (["simulate", "--seconds", "0.1", "--seed", "-1", "--out", "x.csv"], "--seed"),
    (["simulate", "--seconds", "0.1", "--seed", "0", "--noise", "inf", "--out", "x.csv"],
     "--noise"),
    (["simulate", "--seed", "0", "--out", "x.csv"], "--seconds"),
    (["simulate", "--seconds", "0.1", "--seed", "0", "--input", "REC", "--out", "x.csv"],
     "--input"),
    (["simulate", "--model", "m.json", "--out", "x.csv"], "--input"),
    (["demo", "--seconds", "-inf"], "--seconds"),
    (["identify", "REC", "--fs", "inf"], "--fs"),
    (["identify", "REC", "--fs", "0"], "--fs"),
    (["diagnose", "REC", "--crop", "nan:0.1"], "--crop"),
    (["diagnose", "REC", "--crop", "0.2:0.1"], "--crop"),
    (["diagnose", "REC", "--crop", "1:2:3"], "--crop"),
    (["diagnose", "REC", "--structure", "q1=100000"], "--structure"),
    (["diagnose", "REC", "--structure", "f0=2"], "--structure"),
    (["diagnose", "REC", "--structure", "n2a=-1"], "--structure"),
    (["diagnose", "REC", "--structure", "order=2"], "--structure"),
    (["diagnose", "REC", "--train-skip", "nan"], "--train-skip"),
    (["diagnose", "REC", "--max-rounds", "0"], "--max-rounds"),
    (["diagnose", "REC", "--holdout", "nan"], "--holdout"),
    (["diagnose", "REC", "--u-scale", "inf"], "--u-scale"),
])
def test_every_option_is_validated(args, option, tmp_path, monkeypatch, capsys, never_fit):
    monkeypatch.chdir(tmp_path)
    small_record().save(tmp_path / "REC.csv")
    args = [a if a != "REC" else "REC.csv" for a in args]
    code, _, err = run(args, capsys)
    assert code == 2 and option in err, err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["REC.csv"]


def test_compensator_preview_is_bounded():
    import hystid.compensate as hc
    from hystid.reference import reference_model

    model = reference_model()
    for preview in (10**7, float("nan"), -1, 2.5):
        with pytest.raises(ValueError, match="preview: expected a whole number of samples"):
            hc.inverse(model, preview=preview)


# --------------------------------------------------------------------------- saved models
def test_identify_out_writes_a_model_that_simulate_replays(simulated, tmp_path, capsys):
    import hashlib

    from hystid.modelfile import load_model

    rec_path, report = simulated
    model = load_model(report / "model.json")
    prov = json.loads((report / "model.json").read_text())["provenance"]
    assert prov["record_sha256"] == hashlib.sha256(rec_path.read_bytes()).hexdigest()
    assert prov["method"] == "batch"
    out = tmp_path / "replay.csv"
    code, _, err = run(["simulate", "--model", report / "model.json", "--input", rec_path,
                        "--quiet", "--out", out], capsys)
    assert code == 0, err
    replay = load_record(out)
    rec = load_record(rec_path)
    assert np.array_equal(replay.u, rec.u)
    assert np.array_equal(replay.y, model.simulate(rec.u, check=False).y)
    with open(report / "report.json") as src:
        json.load(src, parse_constant=lambda name: pytest.fail(name))


def test_simulate_model_refuses_bad_pairs(simulated, tmp_path, capsys):
    rec_path, report = simulated
    slow = tmp_path / "slow.csv"
    rec = load_record(rec_path)
    Record(rec.u, rec.y, 10_000.0).save(slow)
    doc = json.loads((report / "model.json").read_text())
    doc["version"] = 99
    future = tmp_path / "future.json"
    future.write_text(json.dumps(doc))
    before = snapshot(tmp_path)
    cases = [
        (["--model", report / "model.json", "--input", slow], "10000 Hz"),
        (["--model", future, "--input", rec_path], "version 99"),
        (["--model", tmp_path / "none.json", "--input", rec_path], "does not exist"),
        (["--model", report / "model.json", "--input", rec_path, "--seconds", "1"],
         "--seconds"),
        (["--model", report / "model.json", "--input", rec_path, "--out", rec_path, "--force"],
         "input file"),
    ]
    for extra, needle in cases:
        args = ["simulate", *extra]
        if "--out" not in extra:
            args += ["--out", tmp_path / "sim.csv"]
        code, _, err = run(args, capsys)
        assert code == 2 and needle in err, (extra, err)
    assert snapshot(tmp_path) == before


def test_diagnose_reads_the_saved_model(simulated, tmp_path, capsys):
    from hystid.cli import diagnose as diagnose_command

    rec_path, report = simulated
    parser = cli.build_parser()
    args = parser.parse_args(["diagnose", str(rec_path), "--model", str(report / "model.json")])
    model = diagnose_command._model(args.model, 30_000.0)
    from hystid.modelfile import load_model

    assert model.params == load_model(report / "model.json").params
    old = tmp_path / "old.json"
    old.write_text(json.dumps({"params": model.params}))
    code, _, err = run(["diagnose", rec_path, "--model", old, "--quiet"], capsys)
    assert code == 2 and "no 'structure'" in err


def test_python_m_hystid_reports_without_traceback(tmp_path):
    out = tmp_path / "x.csv"
    out.write_text("mine")
    proc = subprocess.run([sys.executable, "-m", "hystid", "simulate", "--seconds", "0.01",
                           "--seed", "0", "--out", str(out)], capture_output=True, text=True,
                          cwd=Path(__file__).resolve().parents[1], timeout=120)
    assert proc.returncode == 2 and "--force" in proc.stderr
    assert "Traceback" not in proc.stderr and out.read_text() == "mine"


def test_simulate_replays_a_saved_pi_sandwich(simulated, tmp_path, capsys):
    from hystid.pi import PISandwich, PIStructure, pi_thresholds

    rec_path, _ = simulated
    rec = load_record(rec_path)
    structure = PIStructure(n_operators=5)
    params = dict.fromkeys(structure.names, 0.0)
    params.update(a11=-0.5, a21=-0.9, a22=0.2, mu0=0.8, mu1=0.1, mu2=0.05)
    model = PISandwich(params, pi_thresholds(rec.u, 5), structure, fs=rec.fs, offset=0.25)
    model.save(tmp_path / "pi.json")
    out = tmp_path / "pi.h5"
    code, _, err = run(["simulate", "--model", tmp_path / "pi.json", "--input", rec_path,
                        "--quiet", "--out", out], capsys)
    assert code == 0, err
    assert np.array_equal(load_record(out).y, model.simulate(rec.u).y)
