"""Every file the command line writes, as a user runs it: nothing the user had is overwritten.

For each output (``identify --out`` and ``--history``, ``diagnose --out``, ``demo --out``) the
cases are: the output is one of the inputs, the two outputs of one command name the same file,
and a write fails midway. In each case the command exits with status 2 and a one-line message
naming the option and the path, and every file that was there is left byte for byte.
"""

import errno
import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from hystid import cli
from hystid.cli import identify as identify_command
from hystid.records import Record

DATA = Path(__file__).resolve().parents[1].parent / "shared" / "data"
MEASURED = DATA / "real" / "piezo_sine_150V_1Hz" / "hysteresis_v_150_1hz.csv"


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
    """Bytes and modification time of every entry below ``folder`` (folders by name only)."""
    return {p: (p.read_bytes(), p.stat().st_mtime_ns) if p.is_file() else "folder"
            for p in sorted(folder.rglob("*"))}


def error_line(err: str) -> str:
    """The one line a refused command prints (no usage block, no progress lines)."""
    lines = [line for line in err.splitlines() if line.strip()]
    assert len(lines) == 1, err
    return lines[0]


@pytest.fixture
def never_fit(monkeypatch):
    """Fail the test if the command gets as far as fitting or simulating."""

    def boom(*args, **kwargs):
        raise AssertionError("work started before the options were checked")

    monkeypatch.setattr(identify_command, "_identify_record", boom)
    monkeypatch.setattr("hystid.identify.identify", boom)
    monkeypatch.setattr("hystid.identify.pi_recursive.identify_pi", boom)


@pytest.fixture(scope="module")
def stage(tmp_path_factory):
    """Two records of the independent simulator's stage (an offset sensor, another input)."""
    from hystid.testing import paper_excitation, paper_stage, record_from, with_noise, with_offset

    folder = tmp_path_factory.mktemp("stage")
    simulator = paper_stage()
    paths = []
    for seed in (3, 4):
        u = paper_excitation(0.1, simulator.fs, seed=seed)
        rec = record_from(simulator.simulate(u, u_rest=0.0), simulator.fs, f"rec{seed}")
        path = folder / f"rec{seed}.csv"
        with_offset(with_noise(rec, 1e-3, seed=seed), 0.4).save(path)
        paths.append(path)
    return paths


# --------------------------------------------------------------------------- --history vs --out
@pytest.mark.parametrize("name", ["report.json", "model.json", "validation.png",
                                  "convergence.png", "."])
@pytest.mark.parametrize("existing", [False, True])
def test_history_into_the_report_folder_is_refused_even_with_force(tmp_path, capsys, never_fit,
                                                                   name, existing):
    rec = tmp_path / "rec.csv"
    rec.write_text("t,u,y\n0,0,0\n")
    out = tmp_path / "report"
    if existing:
        out.mkdir()
        (out / "report.json").write_text("{\"mine\": 1}\n")
        (out / "model.json").write_text("{\"mine\": 2}\n")
    before = snapshot(tmp_path)
    history = out if name == "." else out / "." / name
    for force in ([], ["--force"]):
        code, _, err = run(["identify", rec, "--method", "online", "--out", out,
                            "--history", history, *force], capsys)
        line = error_line(err)
        assert code == 2 and f"--history {history}" in line and "--out" in line, line
    assert snapshot(tmp_path) == before


def test_history_inside_a_new_report_folder_is_written_beside_the_report(stage, tmp_path,
                                                                         capsys):
    out = tmp_path / "new" / "report"
    code, _, err = run(["identify", stage[0], "--method", "online", "--quiet", "--out", out,
                        "--history", out / "history.csv"], capsys)
    assert code == 0, err
    assert sorted(p.name for p in out.iterdir()) == ["convergence.png", "history.csv",
                                                    "model.json", "report.json",
                                                    "validation.png"]
    history = np.genfromtxt(out / "history.csv", delimiter=",", names=True)
    assert history.dtype.names[0] == "k" and len(history) == 1800  # 40 % held out
    report = json.loads((out / "report.json").read_text())
    assert report["method"] == "online"


@pytest.mark.parametrize("role", ["record", "--val", "--repeat"])
def test_history_onto_an_input_record_is_refused_even_with_force(stage, tmp_path, capsys,
                                                                 never_fit, role):
    rec, other = (tmp_path / "rec.csv", tmp_path / "other.csv")
    for src, dst in zip(stage, (rec, other), strict=True):
        dst.write_bytes(src.read_bytes())
    extra = {"record": [], "--val": ["--val", other], "--repeat": ["--repeat", other]}[role]
    target = rec if role == "record" else other
    before = snapshot(tmp_path)
    code, _, err = run(["identify", rec, *extra, "--method", "online", "--force",
                        "--history", target], capsys)
    line = error_line(err)
    assert code == 2 and f"--history {target}" in line and "input file" in line, line
    assert snapshot(tmp_path) == before


def test_diagnose_out_never_replaces_a_repeat_record(stage, tmp_path, capsys):
    out = tmp_path / "diag"
    out.mkdir()
    repeat = out / "summary.txt"  # a record may be a .txt file: the name of diagnose's summary
    repeat.write_bytes(stage[1].read_bytes())
    before = snapshot(tmp_path)
    code, _, err = run(["diagnose", stage[0], "--repeat", repeat, "--out", out, "--force",
                        "--quiet"], capsys)
    line = error_line(err)
    assert code == 2 and "--out" in line and "input file" in line, line
    assert snapshot(tmp_path) == before


def test_history_is_refused_before_the_work_for_a_method_without_one(tmp_path, capsys,
                                                                    never_fit):
    rec = tmp_path / "rec.csv"
    rec.write_text("t,u,y\n0,0,0\n")
    for extra in ([], ["--method", "batch"], ["--model", "pi", "--method", "batch"]):
        code, _, err = run(["identify", rec, *extra, "--history", tmp_path / "h.csv"], capsys)
        line = error_line(err)
        assert code == 2 and "--history" in line and "online" in line, (extra, line)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["rec.csv"]


# --------------------------------------------------------------------------- failing midway
def full_disk(*args, **kwargs):
    raise OSError(errno.ENOSPC, "No space left on device")


@pytest.fixture(scope="module")
def report_folder(stage, tmp_path_factory):
    """A folder written by ``identify --out`` (the run a failing rerun must not spoil)."""
    out = tmp_path_factory.mktemp("previous") / "report"
    assert cli.main(["identify", str(stage[0]), "--quiet", "--out", str(out)]) == 0
    return out


def test_identify_out_failing_midway_leaves_the_previous_report(stage, report_folder, tmp_path,
                                                                capsys, monkeypatch):
    out = tmp_path / "report"
    out.mkdir()
    for path in report_folder.iterdir():
        (out / path.name).write_bytes(path.read_bytes())
    before = snapshot(tmp_path)
    monkeypatch.setattr("hystid.metrics.plot_validation", full_disk)  # after report, model
    code, _, err = run(["identify", stage[1], "--quiet", "--force", "--out", out], capsys)
    assert code == 2 and "No space left" in error_line(err)
    assert snapshot(tmp_path) == before  # report.json and model.json of the previous run kept


def test_identify_out_failing_midway_creates_no_folder(stage, tmp_path, capsys, monkeypatch):
    monkeypatch.setattr("hystid.metrics.plot_validation", full_disk)
    code, _, err = run(["identify", stage[1], "--quiet", "--out", tmp_path / "a" / "report"],
                       capsys)
    assert code == 2 and "No space left" in error_line(err)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a"]
    assert list((tmp_path / "a").iterdir()) == []  # no half report, no staging folder left


def test_diagnose_out_failing_midway_leaves_the_previous_files(stage, report_folder, tmp_path,
                                                               capsys, monkeypatch):
    out = tmp_path / "diag"
    out.mkdir()
    (out / "report.json").write_text("{\"previous\": true}\n")
    (out / "summary.txt").write_text("previous summary\n")
    before = snapshot(tmp_path)
    monkeypatch.setattr("hystid.diagnose.result.plot_diagnosis", full_disk)
    code, _, err = run(["diagnose", stage[1], "--val", stage[0],
                        "--model", report_folder / "model.json", "--effects", "creep",
                        "--time-budget", "0", "--quiet", "--force", "--out", out], capsys)
    assert code == 2 and "--out" in err and "No space left" in err
    assert snapshot(tmp_path) == before


# --------------------------------------------------------------------------- wrong options
@pytest.mark.parametrize("args, needles", [
    (["identify", "REC", "--method", "magic"], ["--method", "invalid choice"]),
    (["identify", "REC", "--fs", "-5"], ["--fs", "positive"]),
    (["identify", "REC", "--holdout", "-0.2"], ["--holdout", ">= 0"]),
    (["identify", "REC", "--crop", "-1:2"], ["--crop", "--crop=VALUE"]),
    (["identify", "REC", "--columns", "u=1,y=1"], ["--columns", "both read column 1"]),
    (["identify", "REC", "--metod", "online"], ["--metod", "unrecognized"]),
    (["identify"], ["record", "required"]),
    (["identify", "REC", "--out", ""], ["--out", "expected a file or folder name"]),
    (["identify", "REC", "--history", " ", "--method", "online"], ["--history", "got ' '"]),
    (["identify", ""], ["record", "expected a file or folder name"]),
    (["simulate", "--seconds", "-1", "--seed", "0", "--out", "x.csv"], ["--seconds"]),
    (["diagnose", "REC", "--time-budget", "-1"], ["--time-budget"]),
    (["fleet", "identify", "REC", "--out", "f", "--workers", "-1"], ["--workers"]),
])
def test_argument_errors_are_one_line(args, needles, tmp_path, monkeypatch, capsys, never_fit):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "REC.csv").write_text("t,u,y\n0,0,0\n")
    code, _, err = run([a if a != "REC" else "REC.csv" for a in args], capsys)
    line = error_line(err)
    assert code == 2 and line.startswith("hystid") and "error:" in line
    assert "usage:" not in err and all(n in line for n in needles), line


@pytest.mark.parametrize("args, needle", [
    (["identify", "DIR"], "DIR: file is a directory"),
    (["identify", "REC", "--val", "DIR"], "--val DIR: file is a directory"),
    (["identify", "REC", "--repeat", "DIR"], "--repeat DIR: file is a directory"),
    (["diagnose", "DIR"], "DIR: file is a directory"),
    (["simulate", "--model", "DIR", "--input", "REC", "--out", "x.csv"], "--model DIR"),
    (["identify", "REC", "--history", "DIR"], "--history DIR: is a folder"),
    (["identify", "REC", "--out", "REC"], "--out REC: is a file"),
])
def test_a_folder_where_a_file_is_expected_is_named(args, needle, tmp_path, monkeypatch, capsys,
                                                    never_fit, stage):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "DIR").mkdir()
    (tmp_path / "REC.csv").write_bytes(stage[0].read_bytes())
    args = [a if a != "REC" else "REC.csv" for a in args]
    code, _, err = run(args + (["--method", "online"] if "--history" in args else []), capsys)
    line = error_line(err)
    assert code == 2 and needle.replace("REC", "REC.csv") in line, line


def test_structure_and_method_are_checked_before_loading(tmp_path, capsys, never_fit,
                                                         monkeypatch):
    def no_load(*args, **kwargs):
        raise AssertionError("a record was loaded before the options were checked")

    monkeypatch.setattr(identify_command, "load", no_load)
    for extra, option in ((["--structure", "order=2"], "--structure"),
                          (["--model", "pi", "--method", "ekf"], "--method ekf"),
                          (["--model", "pi", "--structure", "n2a=1"], "--structure"),
                          (["--method", "online", "--skip", "0.01"], "--skip"),
                          (["--model", "pi", "--offset", "none"], "--offset")):
        code, _, err = run(["identify", tmp_path / "rec.csv", *extra], capsys)
        line = error_line(err)
        assert code == 2 and option in line, (extra, line)
        assert "applies" in line or "expected" in line, line


def test_skip_beyond_the_fitted_part_is_refused_naming_it(stage, capsys, never_fit):
    # 3000 samples at 30 kHz, the last 40 % held out: 0.06 s are fitted
    code, _, err = run(["identify", stage[0], "--skip", "0.0599"], capsys)
    line = error_line(err)
    assert code == 2 and line.startswith("hystid identify: error: --skip 0.0599: leaves 3 of "
                                         "the 1800 samples"), line


def test_numpy_noise_of_a_diverging_candidate_is_not_shown(stage, capsys, monkeypatch):
    real = identify_command._identify_record

    def overflowing_first(*args, **kwargs):  # a candidate overflowing, as a start-up try may
        np.exp(np.float64(1e3))
        return real(*args, **kwargs)

    monkeypatch.setattr(identify_command, "_identify_record", overflowing_first)
    code, out, err = run(["identify", stage[0], "--method", "online", "--quiet"], capsys)
    assert code == 0 and "alpha" in out
    assert "overflow" not in err and "RuntimeWarning" not in err, err


# --------------------------------------------------------------------------- the measured record
@pytest.mark.skipif(not MEASURED.exists(), reason=f"the measured record {MEASURED} is absent")
@pytest.mark.parametrize("extra, needle", [
    (["--columns", "t=1,u=9,y=2"], "needs at least 10"),
    (["--columns", "t=1,u=3"], "'u' and 'y' are required"),
    ([], "missing column 'u'"),
    (["--columns", "t=1,u=3,y=2", "--method", "online", "--history", MEASURED], "input file"),
    (["--columns", "t=1,u=3,y=2", "--crop", "100:200"], "--crop 100:200"),
])
def test_the_measured_record_with_wrong_options(extra, needle, tmp_path):
    """As a user in the field types it: a subprocess, one line on stderr, status 2."""
    proc = subprocess.run([sys.executable, "-m", "hystid", "identify", str(MEASURED), *map(
        str, extra), "--out", str(tmp_path / "x")], capture_output=True, text=True,
        cwd=Path(__file__).resolve().parents[1], timeout=120)
    assert proc.returncode == 2
    line = error_line(proc.stderr)
    assert needle in line and "Traceback" not in proc.stderr, line
    assert list(tmp_path.iterdir()) == []


def test_validation_line_scores_a_record_not_at_rest_as_the_held_out_table(tmp_path, capsys):
    # A validation record that starts mid-swing (a stage-B look-alike's 1 Hz sine): the
    # validation line scored it from sample 0 (3.1 um RMS, the model's start from rest) while
    # the held-out table, from its burn-in, said 0.069 um. Both now score from the burn-in.
    from hystid.testing import stage_b_like

    stage_b_like(seed=0).save(tmp_path / "b0.csv")
    stage_b_like(seed=1).save(tmp_path / "b1.csv")
    out = tmp_path / "rep"
    code, text, _ = run(["identify", tmp_path / "b0.csv", "--val", tmp_path / "b1.csv",
                         "--out", out, "--model", "duhem"], capsys)
    assert code == 0
    report = json.loads((out / "report.json").read_text())
    held = report["baselines"]["rows"][0]["model"]
    assert report["validation"]["rms"] == pytest.approx(held, rel=1e-9)
    assert "from sample" in report["validated_on"] and "burn-in" in text


def test_without_val_the_held_out_end_is_a_share_of_the_excitation(tmp_path, capsys):
    # A stage-A look-alike rests 1 s before 1 s of excitation. Holding out 40 % of all its
    # samples fitted the model on the rest and a fifth of the excitation (and held out an
    # input range the fit never saw); 40 % of the excitation is held out instead.
    from hystid.identify.prepare import held_out_from, rest_level
    from hystid.testing import stage_a_like

    rec = stage_a_like("prbn", seconds=1.0, rest_seconds=1.0, seed=0)
    lead = rest_level(rec.u)[2]
    k = held_out_from(rec.u, 0.4)
    assert lead > 0.4 * rec.n and k == lead + round(0.6 * (rec.n - lead))
    moving = np.sin(np.arange(rec.n) / 30.0)  # no leading rest: a share of all samples
    assert held_out_from(moving, 0.4) == round(0.6 * rec.n)
    rec.save(tmp_path / "a.csv")
    out = tmp_path / "rep"
    code, _, progress = run(["identify", tmp_path / "a.csv", "--out", out, "--model", "duhem"],
                            capsys)
    assert code == 0 and f": {k} samples at" in progress
    report = json.loads((out / "report.json").read_text())
    row = report["baselines"]["rows"][0]
    assert row["model"] < 0.5 * min(row["static_line"], row["linear"])


def test_a_record_too_short_to_choose_on_gets_the_duhem_sandwich_on_the_command_line_too(
        tmp_path, capsys):
    from hystid.testing import stage_a_like

    stage_a_like("prbn", seconds=0.05, rest_seconds=0.005, seed=3).save(tmp_path / "s.csv")
    code, text, err = run(["identify", tmp_path / "s.csv"], capsys)
    assert code == 0 and "the Duhem sandwich is fitted without a choice" in err
    assert "alpha" in text
    code, _, err = run(["identify", tmp_path / "s.csv", "--model", "auto"], capsys)
    assert code == 2 and "--model duhem" in err.splitlines()[-1]


def test_identify_says_when_it_compiles_its_kernels(tmp_path, capsys, monkeypatch):
    from hystid.cli import support
    from hystid.testing import stage_a_like

    assert len(support.IDENTIFY_KERNELS) == 3
    stage_a_like("prbn", seconds=0.1, rest_seconds=0.01, seed=3).save(tmp_path / "s.csv")
    monkeypatch.setattr(identify_command, "kernels_cached", lambda kernels: False)
    code, _, err = run(["identify", tmp_path / "s.csv", "--model", "duhem"], capsys)
    assert code == 0 and "compiling the numba kernels" in err


def test_a_holdout_that_leaves_too_little_to_fit_names_the_option(tmp_path, capsys, never_fit):
    from hystid.testing import stage_a_like

    stage_a_like("prbn", seconds=0.1, rest_seconds=0.0, seed=1).save(tmp_path / "a.csv")
    code, _, err = run(["identify", tmp_path / "a.csv", "--holdout", "0.99"], capsys)
    line = err.splitlines()[-1]
    assert code == 2 and line.startswith("hystid identify: error: --holdout 0.99: leaves")
    assert "expected at least 60 for --method batch" in line


def test_a_holdout_past_a_long_rest_counts_the_excitation_left(tmp_path, capsys, never_fit):
    """A record resting for 1 000 samples: --holdout 0.999 left 15 samples of excitation (and
    the rest) to fit, which the check counted as 1 015 and let through."""
    from hystid.testing import stage_a_like

    stage_a_like("prbn", seconds=0.5, rest_seconds=0.1, seed=1).save(tmp_path / "a.csv")
    code, _, err = run(["identify", tmp_path / "a.csv", "--holdout", "0.999"], capsys)
    line = err.splitlines()[-1]
    assert code == 2 and line.startswith("hystid identify: error: --holdout 0.999: leaves 5 ")
    assert "samples of excitation" in line


def test_a_constant_input_is_refused_as_such_with_a_holdout(tmp_path, capsys, never_fit):
    """It was refused as "too short to hold out a part of it" (its whole input is a rest)."""
    n = 4000
    y = 0.1 + 1e-3 * np.random.default_rng(0).standard_normal(n)
    Record(np.full(n, 5.0), y, 200.0, name="constant").save(tmp_path / "c.csv")
    code, _, err = run(["identify", tmp_path / "c.csv"], capsys)
    line = err.splitlines()[-1]
    assert code == 2 and "the input u is constant (5)" in line and "c.csv" in line


@pytest.mark.parametrize("member", ["pi-stage", "gduhem"])
def test_diagnose_scores_a_pi_model_file_beside_the_diagnosed_model(tmp_path, capsys, member):
    """The default member's model file (pi-stage), or a generalised Duhem one, is diagnosed as
    far as the effects allow: the rounds diagnose a plain Duhem sandwich (the effects extend
    eq. 7), and the model given is a row of the final table, scored like every row, and the
    incumbent there."""
    import warnings

    from hystid.baselines import rest_zero, simulate_from_rest
    from hystid.identify import identify
    from hystid.modelfile import save_model
    from hystid.records import load_record
    from hystid.testing import stage_a_like

    rec = stage_a_like("prbn", seconds=0.2, rest_seconds=0.02, seed=4)
    rec.save(tmp_path / "a.csv")
    stage_a_like("sine50", seconds=0.2, rest_seconds=0.02, seed=5).save(tmp_path / "v.csv")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        model = identify(rec, model=member).model
    save_model(model, tmp_path / "m.json")
    code, out, err = run(["diagnose", tmp_path / "a.csv", "--val", tmp_path / "v.csv",
                          "--model", tmp_path / "m.json", "--out", tmp_path / "d",
                          "--max-rounds", "1"], capsys)
    assert code == 0, err
    assert "the model given is scored beside it" in err + out
    final = json.loads((tmp_path / "d" / "report.json").read_text())["final_model"]
    rows = {r["candidate"]: r for r in final["candidates"]}
    assert "given: m.json" in rows and "nominal" in rows
    val = load_record(tmp_path / "v.csv")
    p = simulate_from_rest(model, val.u, check=False)
    rms = float(np.sqrt(np.mean((p + rest_zero(p, val) - val.y) ** 2)))
    assert rows["given: m.json"]["mean_rms"] == pytest.approx(rms, rel=1e-9)
    # the incumbent: replaced only by a candidate better by the margin
    best = min(final["candidates"], key=lambda r: r["mean_rms"])
    if final["chosen"] != "given: m.json":
        assert best["mean_rms"] < 0.9 * rms and final["chosen"] == best["candidate"]
    assert (tmp_path / "d" / "model.json").is_file()


def test_diagnose_refuses_a_model_file_of_another_rate(tmp_path, capsys):
    import warnings

    from hystid.identify import identify
    from hystid.modelfile import save_model
    from hystid.records import Record
    from hystid.testing import stage_a_like

    rec = stage_a_like("prbn", seconds=0.2, rest_seconds=0.02, seed=4)
    rec.save(tmp_path / "a.csv")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        other = Record(rec.u, rec.y, 2 * rec.fs, rec.units, "fast")
        save_model(identify(other, model="pi-stage").model, tmp_path / "m.json")
    code, _, err = run(["diagnose", tmp_path / "a.csv", "--model", tmp_path / "m.json"], capsys)
    line = err.splitlines()[-1]
    assert code == 2 and "--model" in line and "expected the same rate" in line


def test_a_python_warning_during_a_command_is_said_as_one_line_of_the_command(capsys):
    """An estimator's (or numpy's) warning is the command's own line, not Python's two lines
    with the library's file and source line."""
    import argparse
    import warnings

    from hystid.cli.support import run_command

    def steps(args):
        warnings.warn("eria: the estimate left the admissible set", RuntimeWarning,
                      stacklevel=1)
        return 0

    assert run_command(argparse.Namespace(prog="hystid identify"), steps) == 0
    err = capsys.readouterr().err
    assert err == "hystid identify: warning: eria: the estimate left the admissible set\n"
