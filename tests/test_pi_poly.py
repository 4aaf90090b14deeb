"""The PI block with polynomial terms (``PIStructure(n_poly=...)``, the ``pi-poly`` member).

``w2 = sum_i mu_i p_i(w1) + c_2 w1^2 + c_3 w1^3``: a sum of plays makes point-symmetric loops
only. Checked here: the compiled simulation against the python-control blocks, the
sensitivities against finite differences, the model file, the per-sample inverse of the
compensator, the refusal of an exact inverse PI operator and, on records from
:mod:`hystid.testing`'s independent stage-A look-alike (Bouc-Wen hysteresis, a 740 Hz mode),
the batch and the on-line fits against ``pi-stage`` and both baselines, with and without a
curved sensor (a square law on the measured displacement: a form the member does not have).
"""

from __future__ import annotations

import warnings

import control as ct
import numpy as np
import pytest

import hystid.compensate as hc
from hystid.baselines import compare
from hystid.compensate.member_inverse import pi_poly_inverse
from hystid.identify import identify
from hystid.identify.pi_kernels import pi_output_sensitivities
from hystid.modelfile import load_model, save_model
from hystid.operating import Envelope
from hystid.pi import PISandwich, PIStructure, pi_thresholds
from hystid.pi_operator import play, poly_terms
from hystid.records import Record
from hystid.testing.measured import stage_a_like

RICH = PIStructure(n_operators=6, n1a=1, n1b=2, n2a=2, n2b=2, q1=1, q2=1, n_poly=2)
VALUES = {"a11": -0.5, "b12": 0.1, "mu0": 0.8, "mu1": 0.3, "mu2": -0.1, "mu3": 0.2, "mu4": 0.1,
          "mu5": 0.05, "c2": 0.03, "c3": -0.004, "a21": -1.2, "a22": 0.5, "b22": 0.2}


def rich_model(**values: float) -> PISandwich:
    """A placed PI sandwich with polynomial terms, dynamic L1 and L2."""
    return PISandwich({**VALUES, **values}, pi_thresholds((-2.0, 2.0), 6), RICH, fs=1000.0,
                      u_rest=0.5, offset=-0.3, envelope=Envelope(-1.5, 2.5, 1.0))


def wander(n: int, seed: int, low: float = -1.4, high: float = 2.4) -> np.ndarray:
    """An input that reverses at many levels inside ``[low, high]``."""
    rng = np.random.default_rng(seed)
    return np.clip(0.5 + np.cumsum(rng.normal(0.0, 0.15, n)), low, high)


def _quiet(fn, *args, **kwargs):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return fn(*args, **kwargs)


# --------------------------------------------------------------------------- the model
def test_names_and_slices_put_the_terms_after_the_weights():
    assert RICH.names[:8] == ("a11", "b12", "mu0", "mu1", "mu2", "mu3", "mu4", "mu5")
    assert RICH.names[8:10] == ("c2", "c3")
    assert RICH.slices()["c"] == slice(8, 10)
    assert PIStructure().slices()["c"] == slice(43, 43)  # a11, a12, b12, 40 weights
    with pytest.raises(ValueError, match="n_poly must be a non-negative integer"):
        PIStructure(n_poly=-1)


def test_simulate_is_the_python_control_system():
    model = rich_model()
    u = wander(400, 0)
    own = model.simulate(u, check=False)
    t = np.arange(len(u)) * model.dt
    out = ct.input_output_response(model.to_control(), t, u)
    assert np.max(np.abs(out.outputs[0] - own.y)) < 1e-12
    # the terms matter: without them the output differs by far more than round-off
    plain = rich_model(c2=0.0, c3=0.0).simulate(u, check=False)
    assert np.max(np.abs(plain.y - own.y)) > 1e-2


def test_from_control_moves_block_gains_into_the_terms():
    model = rich_model()
    L1, L2 = 2.0 * model.L1, 0.5 * model.L2
    L1.dt = L2.dt = model.dt
    # the same stage with L1 twice and L2 half as large: H on w1' = 2 w1 must give twice the
    # output, so thresholds 2 r_i (a play is homogeneous), weights mu_i, c_j 2 / 2^j
    H = model.H
    H.params.update({f"pi_r{i}": 2.0 * r for i, r in enumerate(model.thresholds)})
    H.params.update({"pi_c2": model.poly[0] * 2.0 / 4.0, "pi_c3": model.poly[1] * 2.0 / 8.0})
    back = PISandwich.from_control(L1, H, L2)
    assert back.structure.n_poly == 2
    # read back with unit-gain L1 and L2: the model's own coefficients and output
    assert np.allclose(back.poly, model.poly) and np.allclose(back.mu, model.mu)
    assert (back.u_rest, back.offset) == (model.u_rest, model.offset)  # carried by H
    u = wander(300, 1)
    assert np.max(np.abs(back.simulate(u, check=False).y
                         - model.simulate(u, check=False).y)) < 1e-9


def test_sensitivities_are_the_finite_differences():
    model = rich_model()
    u = wander(300, 2) - model.u_rest
    y, J = pi_output_sensitivities(model, u)
    theta, h = model.theta, 1e-6
    for i, name in enumerate(RICH.names):
        up, down = theta.copy(), theta.copy()
        up[i] += h
        down[i] -= h
        fd = (pi_output_sensitivities(PISandwich(up, model.thresholds, RICH), u)[0]
              - pi_output_sensitivities(PISandwich(down, model.thresholds, RICH), u)[0]) / (2 * h)
        scale = np.max(np.abs(J[:, i]))
        assert scale > 0, name
        assert np.max(np.abs(fd - J[:, i])) < 1e-6 * scale, name


def test_model_file_keeps_the_terms(tmp_path):
    model = rich_model()
    save_model(model, tmp_path / "m.json")
    back = load_model(tmp_path / "m.json")
    assert back.structure == RICH and np.array_equal(back.poly, model.poly)
    u = wander(200, 3)
    assert np.array_equal(back.simulate(u, check=False).y, model.simulate(u, check=False).y)
    # the plays alone write the file as before (no n_poly key)
    plain = PISandwich(np.zeros(len(PIStructure(n_operators=3).names)), [0.0, 0.5, 1.0])
    save_model(plain, tmp_path / "p.json")
    assert "n_poly" not in (tmp_path / "p.json").read_text()


# --------------------------------------------------------------------------- the inverse
def test_per_sample_inverse_meets_the_wanted_output():
    model = rich_model()
    r, mu, c = model.thresholds, model.mu, model.poly
    rng = np.random.default_rng(4)
    p = np.zeros(len(r))
    w1 = 0.0
    for _ in range(300):
        w2d = model.hysteresis_output(w1, p) + rng.normal(0.0, 0.2)
        w1_new, status = pi_poly_inverse(w2d, w1, p, r, mu, c)
        p = np.array([play(w1_new, p[i], r[i]) for i in range(len(r))])
        assert status == 0
        assert abs(float(mu @ p) + poly_terms(w1_new, c)[0] - w2d) < 1e-12 * (1 + abs(w2d))
        w1 = w1_new


def test_the_least_slope_is_found_where_the_slope_turns():
    # slope 2 c2 w + 3 c3 w^2 with c2 = c3 = 1: least at w = -1/3, inside the span, -1/3
    model = rich_model(c2=1.0, c3=1.0)
    assert model.w1_span() == (-2.0, 2.0)
    assert model.poly_slope_min() == pytest.approx(-1.0 / 3.0, abs=1e-12)
    assert model.branch_slope_min() == pytest.approx(
        np.min(np.cumsum(model.mu)) - 1.0 / 3.0, abs=1e-12)
    # with c3 < 0 the slope 2 w - 3 w^2 is least at an end of the span: -16 at w = -2
    assert rich_model(c2=1.0, c3=-1.0).poly_slope_min() == pytest.approx(-16.0, abs=1e-12)


def test_the_paper_recursion_refuses_the_terms_and_says_where_to_go():
    from hystid.identify.pi_recursive import PIRecursiveIdentifier

    with pytest.raises(ValueError, match="plays alone.*PIStageOnline"):
        PIRecursiveIdentifier(pi_thresholds((-2.0, 2.0), 6), structure=RICH, warmup=200)


def test_compensation_follows_a_reachable_reference():
    model = rich_model()
    assert model.is_invertible()
    y = model.simulate(wander(2000, 5), check=False).y
    exact = _quiet(hc.compensate, model, y, anchor="reference", warn=False)
    assert np.all(exact.exact)
    assert exact.settled_relative_error < 1e-9


def test_a_falling_branch_is_refused_by_the_compensator():
    model = rich_model(c2=-0.6)  # slope 0.05 + 2 c2 w1 + .. < 0 near the envelope's top
    assert not model.is_invertible() and model.poly_slope_min() < -1.0
    with pytest.raises(ValueError, match="polynomial terms has no inverse"):
        hc.compensate(model, np.zeros(100), warn=False)
    with pytest.raises(ValueError, match="no inverse PI operator"):
        _ = rich_model().H_inverse


# --------------------------------------------------------------------------- the fit
def curved(rec: Record, k: float) -> Record:
    """The record with a curved sensor: ``y + k (y - median y)^2``."""
    y = rec.y + k * (rec.y - np.median(rec.y)) ** 2
    return Record(u=rec.u, y=y, fs=rec.fs, units=rec.units, name=f"{rec.name} curved {k:g}")


@pytest.fixture(scope="module")
def scores():
    """Held-out RMS (um) of pi-stage and pi-poly, fitted on a PRBN record of the look-alike,
    on a triangle and a sine of another seed; the baselines beside them; with and without a
    curved sensor."""
    out = {}
    for k in (0.0, 0.08):
        train = curved(stage_a_like("prbn", seed=1), k)
        held = [curved(stage_a_like(kind, seed=2), k) for kind in ("tri50", "sine50")]
        for name in ("pi-stage", "pi-poly", "pi-poly/online"):
            member, _, method = name.partition("/")
            model = _quiet(identify, train, model=member, method=method or "batch").model
            rows = compare(model, train, held).rows
            out[k, name] = np.array([r["model"] for r in rows])
            out[k, "baselines"] = np.array([min(r["static_line"], r["linear"]) for r in rows])
    return out


def test_terms_cut_the_error_where_the_sensor_is_curved(scores):
    poly, stage = scores[0.08, "pi-poly"], scores[0.08, "pi-stage"]
    # measured: 0.087 / 0.079 um against 0.17 / 0.19 (0.23 / 0.29 before pi-stage fitted a swing
    # before the rest: a 31 V swing, which the record does not have, stands in for the curve)
    assert np.all(poly < 0.6 * stage)
    assert np.all(poly < 0.5 * scores[0.08, "baselines"])


@pytest.mark.parametrize("k", [0.0, 0.08])
def test_online_identifier_runs_the_terms(scores, k):
    # measured: 0.085 / 0.077 um against the batch fit's 0.087 / 0.079 (curved); 1.04x (not)
    assert np.all(scores[k, "pi-poly/online"] < 1.25 * scores[k, "pi-poly"])
    if k:
        assert np.all(scores[k, "pi-poly/online"] < 0.5 * scores[k, "pi-stage"])


def test_terms_cost_little_where_the_loop_is_symmetric(scores):
    poly, stage = scores[0.0, "pi-poly"], scores[0.0, "pi-stage"]
    # measured: 0.077 / 0.079 um against 0.075 / 0.078
    assert np.all(poly < 1.1 * stage)
    assert np.all(poly < 0.7 * scores[0.0, "baselines"])


# --------------------------------------------------------------------------- diagnosis
def test_diagnose_tries_the_members_asked_for(tmp_path, capsys):
    from hystid.cli import main
    from hystid.testing.measured import stage_b_like

    for name, seed in (("b1.csv", 1), ("b2.csv", 2)):
        stage_b_like(seed=seed).save(tmp_path / name)
    base = ["diagnose", str(tmp_path / "b1.csv"), "--val", str(tmp_path / "b2.csv"), "--quiet"]
    assert main([*base, "--members", "pi-stage,bogus", "--out", str(tmp_path / "x")]) == 2
    assert "--members: expected names of" in capsys.readouterr().err
    assert not (tmp_path / "x").exists()  # refused before anything is written
    assert main([*base, "--members", " , ", "--out", str(tmp_path / "y")]) == 2
    assert "--members ' , ': names no member" in capsys.readouterr().err
    assert main([*base, "--members", "pi-stage,pi-poly", "--out", str(tmp_path / "d")]) == 0
    table = (tmp_path / "d" / "summary.txt").read_text()
    assert "  pi-stage " in table and "  pi-poly " in table
    kept = load_model(tmp_path / "d" / "model.json")
    assert isinstance(kept, PISandwich) and kept.structure.n_poly in (0, 2)


def test_the_fit_does_not_depend_on_the_units():
    from hystid.testing.measured import with_units

    rec = curved(stage_a_like("prbn", seconds=0.6, rest_seconds=0.2, seed=3), 0.08)
    other = with_units(rec, u="kV", y="nm")  # the values converted
    assert np.allclose(other.u, rec.u * 1e-3) and np.allclose(other.y, rec.y * 1e3)
    a = _quiet(identify, rec, model="pi-poly").model
    b = _quiet(identify, other, model="pi-poly").model
    # the terms' coefficients carry output / input^j: c_j scales by 1e3 / 1e-3^j
    assert np.allclose(b.poly, a.poly * 1e3 / 1e-3 ** np.array([2, 3]), rtol=1e-3)
    ya = a.simulate(rec.u, check=False).y
    yb = b.simulate(other.u, check=False).y
    assert np.max(np.abs(yb * 1e-3 - ya)) < 1e-4 * np.ptp(ya)


def test_a_record_that_begins_in_motion():
    """The stage-B look-alike (Preisach, 200 Hz, a 1 Hz sine of random phase, a large sensor
    offset): both of the member's identifiers, with the offset the warm-up corrects on-line."""
    from hystid.testing.measured import stage_b_like

    train = stage_b_like(seed=0)
    held = [stage_b_like(seed=s) for s in (1, 2, 3)]
    rows = {m: compare(_quiet(identify, train, model="pi-poly", method=m).model, train,
                       held).rows for m in ("batch", "online")}
    # measured: 0.070-0.079 um batch, 0.071-0.085 on-line; the linear model 0.52-0.53
    for batch, online in zip(rows["batch"], rows["online"], strict=True):
        assert online["model"] < 1.25 * batch["model"]
        assert batch["model"] < 0.3 * batch["linear"] and online["model"] < 0.3 * batch["linear"]
