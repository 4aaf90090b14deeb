"""Cases a hostile run of the command line found (each a traceback or a wrong figure before).

Records come from the built-in reference stage (no shared data needed), scaled or spoilt here.
"""

from __future__ import annotations

import json

import numpy as np
import pytest

from hystid import cli
from hystid.baselines import StaticLine
from hystid.metrics import plot_validation
from hystid.records import Record
from hystid.reference import reference_record


def run(args, capsys):
    try:
        code = cli.main([str(a) for a in args])
    except SystemExit as err:
        code = err.code
    out = capsys.readouterr()
    return code, out.out, out.err


@pytest.fixture(scope="module")
def model_file(tmp_path_factory):
    folder = tmp_path_factory.mktemp("model")
    rec = reference_record(0.2, seed=4, noise=1e-3)
    rec.save(folder / "train.csv")
    assert cli.main(["identify", str(folder / "train.csv"), "--model", "duhem", "--quiet",
                     "--out", str(folder / "fit")]) == 0
    return folder / "fit" / "model.json", rec


@pytest.mark.parametrize("scale", [1e9, 1e12])
def test_the_static_line_holds_its_offset_at_any_scale(scale):
    """At 1e12 an unscaled solve dropped the column of ones: offset -4e-16 for -7.2e11."""
    rec = reference_record(0.05, seed=1, noise=1e-3)
    base = StaticLine.fit(rec)
    big = StaticLine.fit(Record(rec.u * scale, (rec.y - 0.7) * scale, rec.fs))
    assert big.gain == pytest.approx(base.gain, rel=1e-6)
    assert big.offset == pytest.approx((base.offset - 0.7) * scale, rel=1e-6)


def test_a_validation_figure_of_a_diverged_model_is_drawn(tmp_path):
    """matplotlib raised "arange: cannot compute length" on a model output of 1e32."""
    t = np.arange(2000) / 1e4
    y = np.sin(2 * np.pi * 50 * t)
    yhat = y.copy()
    yhat[1200:1300] = 1e32
    yhat[1300:] = np.inf
    fig = plot_validation(t, y, yhat, tmp_path / "v.png", u=y)
    assert (tmp_path / "v.png").stat().st_size > 0
    assert "diverged: 800 samples not drawn" in fig.axes[0].get_title()


def test_an_input_far_outside_the_model_is_said_not_traced(model_file, tmp_path, capsys):
    """A record in another scale: the model's rest state there overflows (a traceback from
    InitialCondition before)."""
    path, rec = model_file
    Record((rec.u + 3.0) * 1e6, rec.y * 1e6, rec.fs).save(tmp_path / "big.csv")  # from 3e6
    code, _, err = run(["simulate", "--model", path, "--input", tmp_path / "big.csv",
                        "--out", tmp_path / "s.csv"], capsys)
    assert code == 2 and "--input" in err and "rest state" in err and "Traceback" not in err
    assert not (tmp_path / "s.csv").exists()


@pytest.mark.parametrize("sigma", ["1e300", "1e-200"])
def test_an_rpem_sigma_whose_square_overflows_is_refused(model_file, tmp_path, capsys, sigma):
    path, _ = model_file
    code, _, err = run(["export", path, "--c", tmp_path / "c", "--rpem-sigma", sigma], capsys)
    assert code == 2 and "--rpem-sigma" in err and "1e-150..1e150" in err, err


def test_the_baselines_are_fitted_on_the_record_the_model_saw(tmp_path, capsys):
    """One input sample at 1e6: the fit mends it, the baselines were fitted on it (1.8 um
    where they are 0.2-0.3 um on the clean record)."""
    rec = reference_record(0.2, seed=5, noise=1e-3)
    spoilt = Record(rec.u.copy(), rec.y, rec.fs)
    spoilt.u[1500] = 1e6
    reports = []
    for name, r in (("clean", rec), ("spoilt", spoilt)):
        r.save(tmp_path / f"{name}.csv")
        code, out, _ = run(["identify", tmp_path / f"{name}.csv", "--model", "duhem", "--json"],
                           capsys)
        assert code == 0
        reports.append(json.loads(out)["baselines"]["rows"][0])
    for key in ("static_line", "linear"):
        assert reports[1][key] == pytest.approx(reports[0][key], rel=0.05), (key, reports)


def test_a_model_whose_envelope_gives_no_range_names_the_limits_option(model_file, tmp_path,
                                                                        capsys):
    path, _ = model_file
    doc = json.loads(path.read_text())
    doc["envelope"].update(u_min=1.0, u_max=1.0, slew=0.0)
    (tmp_path / "flat.json").write_text(json.dumps(doc))
    code, _, err = run(["compensate", tmp_path / "flat.json", "--scan", "triangle:50:2",
                        "--out", tmp_path / "c.csv"], capsys)
    assert code == 2 and "--limits" in err and "got None" not in err, err


def test_an_output_that_runs_away_is_diverged_though_finite():
    """--holdout 0.99 on stage A gave a model 7.5e18 um off: reported as a figure before."""
    from hystid.metrics import runaway

    y = np.sin(np.linspace(0.0, 20.0, 1000))
    assert not runaway(y, y + 0.5)
    assert runaway(y, np.r_[y[:-1], 7.5e18]) and runaway(y, np.r_[y[:-1], np.nan])


@pytest.mark.parametrize("case", ["other units", "other scale", "still input"])
def test_an_rpem_record_of_another_scale_or_unit_is_refused(model_file, tmp_path, capsys, case):
    """The export took a record labelled nm for a model in um (its residual floor 1 000x too
    high), one 1e6x the model's input range (a covariance of 4.5e61) and a still input."""
    path, rec = model_file
    if case == "other units":
        np.savetxt(tmp_path / "r.csv", np.column_stack([np.arange(rec.n) / rec.fs, rec.u,
                                                        rec.y * 1e3]),
                   delimiter=",", header="t,u,y [nm]", comments="")
        expected = "y in nm, the model in um"
    elif case == "other scale":
        Record(rec.u * 1e6, rec.y, rec.fs).save(tmp_path / "r.csv")
        expected = "the model was identified on"
    else:
        Record(np.full(rec.n, 1.0), rec.y, rec.fs).save(tmp_path / "r.csv")
        expected = "does not move"
    code, _, err = run(["export", path, "--c", tmp_path / "c", "--rpem-record",
                        tmp_path / "r.csv"], capsys)
    assert code == 2 and "--rpem-record" in err and expected in err, err
    assert not (tmp_path / "c").exists()


def test_a_decimal_comma_gets_a_hint(tmp_path):
    from hystid.records import RecordError, load_record

    (tmp_path / "r.csv").write_text("t;u;y\n0,0;1,5;0,25\n0,0001;1,6;0,26\n")
    with pytest.raises(RecordError, match="line 2.*a decimal comma"):
        load_record(tmp_path / "r.csv")
    (tmp_path / "s.csv").write_text("t,u,y\n0.0,abc,0.25\n")
    with pytest.raises(RecordError) as err:
        load_record(tmp_path / "s.csv")
    assert "decimal comma" not in str(err.value)


def test_swapped_columns_are_suggested_when_the_output_does_not_move():
    """u and y swapped on a record that rests before its excitation: the 'output' (the
    command) is still over the identification part; the error spoke of a saturated sensor
    alone."""
    from hystid.errors import IdentificationDataError
    from hystid.identify import identify

    rec = reference_record(0.3, seed=6, noise=1e-3)
    command = np.r_[np.full(3 * rec.n, rec.u[0]), rec.u]
    response = np.r_[rec.y[0] + 1e-3 * np.random.default_rng(0).standard_normal(3 * rec.n),
                     rec.y]
    with pytest.raises(IdentificationDataError, match="u and y columns swapped"):
        identify(Record(response, command, rec.fs, name="r"), model="duhem")


def test_an_input_excursion_longer_than_a_glitch_is_said():
    """Ten input samples at 1e6 V: not mended (a glitch is at most MAX_GLITCH samples), and the
    model's envelope reached 1e6 V without a word; a one-sample glitch is still mended."""
    from hystid.identify.prepare import MAX_GLITCH, without_input_glitches

    rec = reference_record(0.2, seed=7, noise=1e-3)
    for width, mended in ((10, False), (1, True)):
        u = rec.u.copy()
        u[2500:2500 + width] = 1e6
        out, notes = without_input_glitches(Record(u, rec.y, rec.fs))
        assert len(notes) == 1, notes
        assert ("not mended" in notes[0]) is not mended
        assert bool(np.max(out.u) < 1e3) is mended
        assert width > MAX_GLITCH or mended
