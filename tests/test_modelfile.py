"""The model file: identify -> save -> load -> simulate, bit for bit, and clear refusals."""

import hashlib
import json
import subprocess
import sys
import warnings

import numpy as np
import pytest

import hystid
from hystid.model import DuhemSandwich, Structure
from hystid.modelfile import ModelFileError, load_model, make_provenance, save_model
from hystid.operating import AdmissibilityWarning, Envelope
from hystid.records import Record


def as_measured(seed: int = 0, n: int = 1200, fs: float = 10_000.0) -> Record:
    """A stage unlike the sandwich: a Bouc-Wen loop on a first-order lag, a 900 Hz mode, the
    input in mV around a 250 mV rest, the output in nm with a -700 nm sensor offset."""
    rng = np.random.default_rng(seed)
    k = np.arange(n)
    levels = np.repeat(rng.uniform(-1, 1, n // 50 + 1), 50)[:n]
    u = 250.0 + np.minimum(k / 300, 1) * (180 * np.sin(2 * np.pi * 35 * k / fs) + 40 * levels)
    v, z, x = np.zeros(n), np.zeros(n), np.zeros(n)
    for i in range(1, n):
        v[i] = 0.8 * v[i - 1] + 0.2 * (u[i - 1] - 250.0)
        dv = v[i] - v[i - 1]
        z[i] = z[i - 1] + 0.9 * dv - 0.004 * abs(dv) * z[i - 1] - 0.002 * dv * abs(z[i - 1])
    w = 0.6 * v + z
    r, th = 0.97, 2 * np.pi * 900 / fs
    a1, a2 = -2 * r * np.cos(th), r * r
    for i in range(2, n):
        x[i] = -a1 * x[i - 1] - a2 * x[i - 2] + (1 + a1 + a2) * w[i]
    y = 8.0 * x - 700.0 + rng.normal(0, 0.5, n)
    return Record(u, y, fs, units={"u": "mV", "y": "nm"}, name=f"as measured {seed}")


@pytest.fixture(scope="module")
def record(tmp_path_factory):
    rec = as_measured()
    path = tmp_path_factory.mktemp("rec") / "stage.csv"
    rec.save(path)
    return rec, path


def _simulate(model, u):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", AdmissibilityWarning)
        return model.simulate(u)


def _round_trip(model, path, u):
    model.save(path)
    loaded = load_model(path)
    assert type(loaded) is type(model)
    assert loaded.structure == model.structure
    assert np.array_equal(loaded.theta, model.theta)
    assert (loaded.fs, loaded.u_rest, loaded.offset, loaded.units) == \
        (model.fs, model.u_rest, model.offset, model.units)
    assert loaded.envelope == model.envelope
    assert getattr(loaded, "rest_memory", 0.0) == getattr(model, "rest_memory", 0.0)
    a, b = _simulate(model, u), _simulate(loaded, u)
    assert np.array_equal(a.y, b.y) and np.array_equal(a.w2, b.w2)
    return loaded


def test_identified_duhem_sandwich_round_trips_bit_for_bit(record, tmp_path):
    from hystid.identify import identify

    rec, path = record
    result = identify(rec, method="batch", model="duhem")
    other = as_measured(seed=1)
    loaded = _round_trip(result.model, tmp_path / "duhem.json", other.u)
    assert loaded.params == result.model.params


def test_identified_pi_sandwich_round_trips_bit_for_bit(record, tmp_path):
    from hystid.identify.pi_recursive import identify_pi

    rec, _ = record
    result = identify_pi(rec, method="recursive")
    loaded = _round_trip(result.model, tmp_path / "pi.json", as_measured(seed=2).u)
    assert np.array_equal(loaded.thresholds, result.model.thresholds)


def test_placement_envelope_units_and_structure_survive(tmp_path):
    structure = Structure(n1a=2, n1b=1, n2a=2, n2b=1, q1=2, q2=1, f0=True)
    rng = np.random.default_rng(3)
    params = {name: 0.05 * rng.standard_normal() for name in structure.names}
    params.update(alpha=0.3, f1=0.2, g0=0.01)
    model = DuhemSandwich(params, structure, fs=5_000.0, name="odd", u_rest=1 / 3,
                          offset=-0.7000000000000001, envelope=Envelope(-0.5, 1.5, 0.02),
                          units={"u": "mV", "y": "nm"})
    u = 1 / 3 + 0.4 * np.sin(np.arange(2000) / 37.0)
    _round_trip(model, tmp_path / "odd.json", u)


def test_provenance_names_the_record_by_hash(record, tmp_path):
    rec, path = record
    model = DuhemSandwich({"alpha": 0.5, "f1": 0.1, "g0": 0.01, "a11": -0.5, "a21": -1.0,
                           "a22": 0.5})
    prov = make_provenance("batch", path, {"theta0": 0.01, "callback": print,
                                           "bad": float("nan")})
    save_model(model, tmp_path / "m.json", provenance=prov)
    saved = json.loads((tmp_path / "m.json").read_text())["provenance"]
    assert saved["record_sha256"] == hashlib.sha256(path.read_bytes()).hexdigest()
    assert saved["method"] == "batch" and saved["hystid_version"] == hystid.__version__
    assert saved["date"].endswith("Z") and saved["settings"] == {"theta0": 0.01}
    assert load_model(tmp_path / "m.json").provenance == saved


def _document(tmp_path):
    model = DuhemSandwich({"alpha": 0.5, "f1": 0.1, "g0": 0.01, "a11": -0.5, "a21": -1.0,
                           "a22": 0.5})
    model.save(tmp_path / "ok.json")
    return json.loads((tmp_path / "ok.json").read_text())


@pytest.mark.parametrize("change, needle", [
    ({"version": 2}, "version 2 is not supported"),
    ({"version": "1"}, "version '1' is not supported"),
    ({"kind": "preisach"}, "unknown model kind 'preisach'"),
    ({"format": "something"}, "'format'"),
    ({"structure": {"n1a": 1}}, "missing"),
    ({"structure": {"n1a": 1.5, "n1b": 0, "n2a": 2, "n2b": 0, "q1": 1, "q2": 0, "f0": False}},
     "'n1a' must be an integer"),
    ({"structure": {"n1a": 1, "n1b": 0, "n2a": 2, "n2b": 0, "q1": 1, "q2": 0, "f0": 2}},
     "'f0' must be true or false"),
    ({"params": {"alpha": 0.5}}, "missing"),
    ({"fs": "fast"}, "'fs' must be a number"),
    ({"fs": -1.0}, "fs must be a positive"),
    ({"envelope": {"u_min": 2, "u_max": 1, "slew": 0}}, "envelope"),
    ({"units": ["V"]}, "'units'"),
])
def test_bad_model_files_are_clear_errors(tmp_path, change, needle):
    doc = _document(tmp_path)
    doc.update(change)
    path = tmp_path / "bad.json"
    path.write_text(json.dumps(doc))
    with pytest.raises(ModelFileError, match="bad.json") as err:
        load_model(path)
    assert needle in str(err.value)


def test_non_json_and_nan_are_refused(tmp_path):
    path = tmp_path / "nan.json"
    path.write_text(json.dumps(_document(tmp_path)).replace("0.5", "NaN", 1))
    with pytest.raises(ModelFileError, match="NaN is not a JSON number"):
        load_model(path)
    (tmp_path / "text.json").write_text("alpha = 1")
    with pytest.raises(ModelFileError, match="not a JSON model file"):
        load_model(tmp_path / "text.json")
    with pytest.raises(ModelFileError, match="does not exist"):
        load_model(tmp_path / "missing.json")


def test_save_never_replaces_a_file_unless_forced(tmp_path):
    model = DuhemSandwich({"alpha": 0.5, "f1": 0.1, "g0": 0.01, "a11": -0.5, "a21": -1.0,
                           "a22": 0.5})
    path = tmp_path / "keep.json"
    path.write_text("mine")
    with pytest.raises(ModelFileError, match="exists"):
        model.save(path)
    assert path.read_text() == "mine"
    link = tmp_path / "link.json"
    link.symlink_to(path)
    with pytest.raises(ModelFileError, match="symbolic link"):
        model.save(link, force=True)
    assert path.read_text() == "mine"
    model.save(path, force=True)
    assert load_model(path).params == model.params
    with pytest.raises(ModelFileError, match="expected a DuhemSandwich, a PISandwich or a Multi"):
        save_model(object(), tmp_path / "x.json")


def test_import_hystid_stays_light():
    code = ("import sys, hystid; hystid.load_model; "
            "print(sorted(m for m in ('control', 'matplotlib') if m in sys.modules))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True)
    assert out.stdout.strip() == "[]"
