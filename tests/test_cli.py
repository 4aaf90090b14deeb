"""The hystid command line, as a user runs it."""

import json
import subprocess
import sys

import numpy as np
import pytest

from hystid.cli import main
from hystid.reference import PAPER_PARAMS


def run(args, capsys):
    code = main(args)
    out = capsys.readouterr()
    return code, out.out, out.err


@pytest.fixture(scope="module")
def records(tmp_path_factory):
    folder = tmp_path_factory.mktemp("recs")
    for name, seed in (("train.csv", 0), ("val.npz", 1)):
        args = ["simulate", "--seconds", "0.1", "--seed", str(seed), "--quiet",
                "--out", str(folder / name)]
        assert main(args) == 0
    return folder


def test_simulate_writes_a_loadable_record(records):
    from hystid.records import load_record

    rec = load_record(records / "train.csv")
    assert rec.n == 3000 and rec.fs == pytest.approx(30_000.0)


@pytest.mark.parametrize("method", ["batch", "online"])
def test_identify_json_recovers_the_stage(records, capsys, method, tmp_path):
    hist = tmp_path / "h.csv"
    args = ["identify", str(records / "train.csv"), "--val", str(records / "val.npz"),
            "--method", method, "--json", "--out", str(tmp_path / "out")]
    if method == "online":
        args += ["--history", str(hist)]
    code, out, _ = run(args, capsys)
    assert code == 0
    report = json.loads(out)
    assert set(report["validation"]) >= {"err_min", "err_max", "rms", "fit_percent"}
    for name, value in PAPER_PARAMS.items():
        assert report["params"][name] == pytest.approx(value, rel=0.02)
    assert report["validation"]["rms"] < 3e-3  # 1 nm noise: the error sits at the noise
    assert (tmp_path / "out" / "report.json").exists()
    assert (tmp_path / "out" / "validation.png").stat().st_size > 1000
    if method == "online":
        assert "converged_at" in report and report["settings"]["n_start"] == 400
        data = np.genfromtxt(hist, delimiter=",", names=True)
        assert data.dtype.names == ("k", *PAPER_PARAMS)
        assert len(data) == 3000


def exit_code(args) -> int:
    """Exit status of ``hystid ARGS``, whether argparse exits or main returns."""
    try:
        return main(args)
    except SystemExit as exc:
        return int(exc.code)


@pytest.mark.parametrize(
    "args, needle",
    [
        (["identify", "missing.csv"], "missing.csv"),
        (["simulate", "--seconds", "-1", "--seed", "0", "--out", "x.csv"], "positive"),
        (["simulate", "--seconds", "0.01", "--seed", "0", "--out", "x.xyz"], ".csv"),
        (["identify", "REC", "--method", "magic"], "invalid choice"),
        (["identify", "REC", "--fs", "abc"], "--fs: expected a number"),
    ],
)
def test_bad_arguments_exit_2_with_a_clear_message(args, needle, capsys, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    assert exit_code(args) == 2
    assert needle in capsys.readouterr().err


def test_bad_csv_is_reported_with_file_and_line(tmp_path, capsys):
    bad = tmp_path / "bad.csv"
    bad.write_text("t,u,y\n0,1,2\n3.3e-5,1,nan\n")
    code, _, err = run(["identify", str(bad)], capsys)
    assert code == 2
    assert "bad.csv" in err and "line 3" in err


def test_mismatched_fs_between_records(records, tmp_path, capsys):
    from hystid.records import load_record

    rec = load_record(records / "val.npz")
    other = type(rec)(rec.u, rec.y, fs=10_000.0, name="slow")
    other.save(tmp_path / "slow.npz")
    code, _, err = run(["identify", str(records / "train.csv"), "--val",
                        str(tmp_path / "slow.npz")], capsys)
    assert code == 2 and "differs" in err


def test_demo_runs_end_to_end(tmp_path):
    out = tmp_path / "demo"
    proc = subprocess.run([sys.executable, "-m", "hystid.cli", "demo", "--seconds", "0.1",
                           "--out", str(out)], capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr
    assert "online" in proc.stdout and "alpha" in proc.stdout
    report = json.loads((out / "report.json").read_text())
    assert report["methods"]["online"]["max_rel_error"] < 0.02
    assert (out / "validation.png").exists() and (out / "convergence.png").exists()
    import hystid

    prov = report["provenance"]
    assert prov["hystid_version"] == hystid.__version__ and prov["seed"] == 0
    assert prov["fs"] == 30_000.0 and prov["structure"]["n2a"] == 2
    assert report["units"]["y"] == "um" and report["units"]["validation"] == "um"


def test_help_loads_neither_control_matplotlib_nor_numba():
    code = ("import sys\nfrom hystid.cli import main\ntry:\n    main(['--help'])\n"
            "except SystemExit:\n    pass\nheavy = [m for m in ('control', 'matplotlib', 'numba')"
            " if m in sys.modules]\nprint('heavy:', heavy)")
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          timeout=120)
    assert "diagnose" in proc.stdout and "fleet" in proc.stdout  # listed, not loaded
    assert "heavy: []" in proc.stdout, proc.stdout + proc.stderr


def test_kernels_cached_tells_a_cold_cache_from_a_warm_one(tmp_path, monkeypatch):
    from hystid.cli import kernels_cached

    (tmp_path / "cli_cold_kernel.py").write_text(
        "from numba import njit\n\n@njit(cache=True)\ndef twice(x):\n    return 2.0 * x\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    import cli_cold_kernel

    named = (("cli_cold_kernel", "twice"),)
    assert not kernels_cached(named)
    assert cli_cold_kernel.twice(1.5) == 3.0  # compiles and writes the cache
    assert kernels_cached(named)


def test_help_for_each_command(capsys):
    for cmd in ("demo", "simulate", "identify"):
        with pytest.raises(SystemExit) as exc:
            main([cmd, "--help"])
        assert exc.value.code == 0
        assert cmd in capsys.readouterr().out


@pytest.mark.parametrize("model", ["duhem", "pi"])
def test_too_short_record_is_refused_not_fitted(tmp_path, capsys, model):
    path = tmp_path / "short.csv"
    path.write_text("u,y\n" + "".join(f"{0.1 * k},{0.01 * k}\n" for k in range(20)))
    code, out, err = run(["identify", str(path), "--fs", "1000", "--model", model, "--json"],
                         capsys)
    assert code == 2 and "Traceback" not in err
    assert "expected at least" in err and out == ""


@pytest.mark.parametrize("method", ["batch", "eria", "online", "ekf"])
def test_identify_refuses_a_record_shorter_than_the_method_needs(method):
    from hystid.identify import identify, min_samples
    from hystid.reference import reference_record

    need = min_samples(method)
    rec = reference_record(0.02, seed=0)[: need - 1]
    with pytest.raises(ValueError, match=f"{need - 1} samples are too few"):
        identify(rec, method=method)


def test_identify_reads_columns_by_position(records, tmp_path, capsys):
    from hystid.records import load_record

    rec = load_record(records / "train.csv")
    path = tmp_path / "headerless.csv"
    np.savetxt(path, np.column_stack([rec.y, np.arange(rec.n), rec.u]), delimiter=",")
    code, out, err = run(["identify", str(path), "--columns", "u=2,y=0", "--fs",
                          str(rec.fs), "--json"], capsys)
    assert code == 0, err
    params = json.loads(out)["params"]
    assert all(abs(params[k] - v) < 0.02 * abs(v) for k, v in PAPER_PARAMS.items())
    assert exit_code(["identify", str(path), "--columns", "u2,y=0"]) == 2


def test_figures_leave_pyplot_and_the_backend_alone():
    # the library draws on Figure objects: the caller's backend and pyplot state are untouched
    code = """
import sys
import numpy as np
from hystid.metrics import plot_convergence, plot_validation
t = np.arange(3000) / 30000.0
u = 5 + np.sin(2 * np.pi * 50 * t)
y = 2 * u + 0.01 * np.cos(2 * np.pi * 50 * t)
fig = plot_validation(t, y, y + 1e-3 * np.sin(t), u=u, skip=51)
fig2 = plot_convergence(np.ones((50, 2)), ["a", "b"], {"a": 1.0, "b": 2.0})
import matplotlib
print("pyplot" if "matplotlib.pyplot" in sys.modules else "no pyplot", len(fig.axes),
      len(fig2.axes))
"""
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          timeout=120)
    assert proc.stdout.split() == ["no", "pyplot", "4", "1"], proc.stdout + proc.stderr


def test_validation_figure_shows_the_error_in_nm_and_zooms_on_the_largest_error():
    from hystid.metrics import error_scale, plot_validation, zoom_window

    assert error_scale("um") == (1e3, "nm") and error_scale("m") == (1e9, "nm")
    assert error_scale("V") == (1.0, "V")
    t = np.arange(6000) / 30000.0
    y = np.sin(2 * np.pi * 10 * t)
    yhat = y.copy()
    yhat[4500] += 0.002  # one 2 nm error in um
    start, stop = zoom_window(t, y - yhat, 0.01)
    assert stop - start == 300 and start <= 4500 < stop
    fig = plot_validation(t, y, yhat, unit="um")
    err_ax = fig.axes[-1]
    assert err_ax.get_ylabel() == "error [nm]"
    np.testing.assert_allclose(np.min(err_ax.lines[0].get_ydata()), -2.0)


def test_convergence_of_many_parameters_is_one_panel_of_families():
    from hystid.metrics import plot_convergence

    names = ["a11", "a12", "b11", "b12"] + [f"mu{i}" for i in range(41)] + ["a21", "a22"]
    history = np.ones((100, len(names)))
    fig = plot_convergence(history, names)
    (ax,) = fig.axes
    labels = [line.get_label() for line in ax.lines]
    assert labels == ["a1 (2 parameters, largest)", "b1 (2 parameters, largest)",
                      "mu (41 parameters, largest)", "a2 (2 parameters, largest)"]
    assert ax.get_xscale() == "log" and ax.get_yscale() == "log"
    truth = {"alpha": 2.0, "f1": 2.0}
    fig = plot_convergence(np.ones((10, 2)), ["alpha", "f1"], truth, samples=np.arange(0, 20, 2))
    ax = fig.axes[0]
    assert ax.lines[0].get_label() == "alpha (true 2)"
    np.testing.assert_allclose(ax.lines[0].get_xdata(), np.arange(1, 21, 2))
    np.testing.assert_allclose(ax.lines[0].get_ydata(), 0.5)


def test_units_label_the_report_and_bad_units_are_refused(records, tmp_path, capsys):
    """A record in other units (here the output in m) says so in the report when --units
    gives them; without --units the default label is V / um."""
    from hystid.records import load_record

    rec = load_record(records / "train.csv")
    path = tmp_path / "si.csv"
    np.savetxt(path, np.column_stack([rec.t, rec.u, rec.y * 1e-6]), delimiter=",",
               header="t,u,y", comments="")
    out_dir = tmp_path / "out"
    code, out, err = run(["identify", str(path), "--units", "u=V,y=m", "--json", "--out",
                          str(out_dir)], capsys)
    assert code == 0, err
    report = json.loads((out_dir / "report.json").read_text())
    assert report["units"]["y"] == "m" and report["units"]["validation"] == "m"
    assert json.loads(out)["validation"]["rms"] < 3e-9  # 1 nm noise, in m
    assert exit_code(["identify", str(path), "--units", "y=m,x=s"]) == 2
    err = capsys.readouterr().err
    assert "--units" in err and "u=UNIT,y=UNIT" in err


def test_diagnose_takes_units_too(records, capsys):
    code = exit_code(["diagnose", str(records / "train.csv"), "--units", "u=V,y"])
    assert code == 2 and "--units" in capsys.readouterr().err


def test_pi_batch_fit_takes_offset_option(records, tmp_path, capsys):
    """--offset reaches the PI sandwich's batch fit: 'none' keeps the offset at 0; by default
    it is estimated (the record is shifted by 2 um, so it must be found)."""
    from hystid.records import load_record

    rec = load_record(records / "train.csv")
    path = tmp_path / "shifted.csv"
    np.savetxt(path, np.column_stack([rec.t, rec.u, rec.y + 2.0]), delimiter=",",
               header="t,u,y", comments="")
    reports = {}
    for offset in ("none", "estimate"):
        out = tmp_path / offset
        code, _, err = run(["identify", str(path), "--model", "pi", "--method", "batch",
                            "--offset", offset, "--quiet", "--out", str(out)], capsys)
        assert code == 0, err
        reports[offset] = json.loads((out / "report.json").read_text())
    assert reports["none"]["offset"] == 0.0
    assert reports["estimate"]["offset"] == pytest.approx(2.0, abs=0.2)


def test_identify_online_chooses_the_member_then_runs_it_on_line(tmp_path, capsys):
    """``hystid identify REC --method online``: the model choice on the record's first half,
    then the chosen member on-line; ``--structure`` takes the generalised block's keys."""
    from hystid.reference import reference_record

    path = tmp_path / "rec.csv"
    reference_record(0.3, seed=0).save(path)
    assert main(["identify", str(path), "--method", "online", "--quiet"]) == 0
    out = capsys.readouterr().out
    assert "chosen" in out and "alpha" in out  # the Duhem member chosen on the paper's stage
    assert main(["identify", str(path), "--structure", "directional=1,f_order=2",
                 "--quiet"]) == 0
    out = capsys.readouterr().out
    assert "ad " in out and "f2 " in out
    assert main(["identify", str(path), "--structure", "g_order=3", "--quiet"]) == 2
    assert "g_order=3 (expected 0..2)" in capsys.readouterr().err


@pytest.mark.parametrize("value", ["inf", "nan", "0", "-5"])
def test_fleet_refuses_a_sampling_rate_that_is_not_a_positive_finite_number(tmp_path, capsys,
                                                                           value):
    with pytest.raises(SystemExit) as err:
        main(["fleet", "identify", str(tmp_path), "--out", str(tmp_path / "out"), "--fs", value])
    assert err.value.code == 2
    assert "--fs: expected a positive finite number" in capsys.readouterr().err


def test_two_files_holding_records_of_one_name_are_told_apart(capsys, tmp_path):
    # Two files whose records carry the same name: a message about the first named the second
    # file (the name -> file map kept the last one loaded).
    from hystid.testing import stage_b_like

    stage_b_like(seed=0, seconds=2.0).save(tmp_path / "b0.csv")  # too short to diagnose
    stage_b_like(seed=1, seconds=2.0).save(tmp_path / "b1.csv")
    code, _, err = run(["diagnose", tmp_path / "b0.csv", "--val", tmp_path / "b1.csv",
                        "--out", tmp_path / "d"], capsys)
    assert code == 2
    assert "b0.csv" in err and "b1.csv" not in err, err


def test_a_validation_record_in_motion_is_drawn_from_where_it_is_scored(tmp_path, capsys,
                                                                         monkeypatch):
    # a --val record that does not start at rest is scored after its burn-in; the figure drew
    # it from sample 0 (an error panel of 866 nm RMS under a reported 121 nm, its zoom on the
    # burn-in): it now gets the sample the figures start at
    from hystid.cli import identify as command
    from hystid.identify.prepare import burn_in, rest_level
    from hystid.testing.measured import stage_b_like

    for name, seed in (("train.csv", 0), ("val.csv", 1)):
        r = stage_b_like(seed=seed, noise_rms=0.1)
        np.savetxt(tmp_path / name, np.column_stack([np.arange(r.n) / r.fs, r.u, r.y]),
                   delimiter=",", header="t,u,y", comments="")
    seen = {}

    def capture(out, report, target, yhat, result, **kw):
        seen.update(kw, n=target.n)

    monkeypatch.setattr(command, "write_outputs", capture)
    code, out, _ = run(["identify", str(tmp_path / "train.csv"), "--val",
                        str(tmp_path / "val.csv"), "--out", str(tmp_path / "rep"), "--json"],
                       capsys)
    assert code == 0
    report = json.loads(out)
    val = stage_b_like(seed=1, noise_rms=0.1)
    k = burn_in(val.u, rest_level(val.u)[1])
    assert k > 0 and report["scored_from"] == k == seen["scored_from"]
    assert f"from sample {k}" in report["validated_on"]
