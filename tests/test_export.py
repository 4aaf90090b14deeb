"""``hystid export --c``: the generated C99 against Python, sample by sample.

Every test compiles the export with the system C compiler (``-std=c99 -Wall -Wextra -Werror
-pedantic``) and a small driver that reads samples on stdin and prints ``%.17g``; without a
compiler they are skipped (the generator's own tests still run).
"""

from __future__ import annotations

import shutil
import subprocess
import warnings
from pathlib import Path

import numpy as np
import pytest
from scipy import signal

import hystid.compensate as hc
from hystid import DuhemSandwich, Structure
from hystid.cli import main
from hystid.export import c_sources, export_c, ff_options, ff_plan, rpem_reference, rpem_start
from hystid.identify.online import rpem_run
from hystid.operating import Envelope
from hystid.pi import PISandwich, PIStructure, pi_thresholds
from hystid.reference import paper_excitation, reference_model

CC = shutil.which("cc") or shutil.which("gcc")
needs_cc = pytest.mark.skipif(CC is None, reason="no C compiler (cc or gcc) on PATH")
FLAGS = ["-std=c99", "-Wall", "-Wextra", "-Werror", "-pedantic", "-O2"]
STAGE_A = Path(__file__).resolve().parents[1] / ".." / "shared" / "data" / "real" / "stageA"
RTOL = 1e-9

DRIVER = r"""
#include <stdio.h>
#include <string.h>

#include "hystid_model.h"

int main(int argc, char **argv)
{
    long n, k;
    double u;
    if (argc < 2 || scanf("%ld", &n) != 1) {
        return 2;
    }
    if (strcmp(argv[1], "model") == 0) {
        hystid_model_state s;
        hystid_model_init(&s);
        for (k = 0; k < n; k++) {
            if (scanf("%lf", &u) != 1) {
                return 3;
            }
            printf("%.17g\n", hystid_model_step(&s, u));
        }
#ifndef HYSTID_NO_FF
    } else if (strcmp(argv[1], "ff") == 0) {
        static hystid_ff_state s;
        double c;
        hystid_ff_init(&s);
        for (k = 0; k < n; k++) {
            if (scanf("%lf", &u) != 1) {
                return 3;
            }
            c = hystid_ff_step(&s, u);
            printf("%.17g %.17g %d\n", c, hystid_ff_desired(&s), hystid_ff_status(&s));
        }
#endif
#ifndef HYSTID_NO_RPEM
    } else if (strcmp(argv[1], "rpem") == 0) {
        static hystid_rpem_state s;
        const double *th;
        double y;
        int i;
        hystid_rpem_init(&s);
        for (k = 0; k < n; k++) {
            if (scanf("%lf %lf", &u, &y) != 2) {
                return 3;
            }
            hystid_rpem_step(&s, u, y);
            th = hystid_rpem_theta(&s);
            for (i = 0; i <= HYSTID_RPEM_NPAR; i++) {
                printf(i ? " %.17g" : "%.17g", th[i]);
            }
            printf(" %ld\n", hystid_rpem_restarts(&s));
        }
#endif
    } else {
        return 2;
    }
    return 0;
}
"""


# --------------------------------------------------------------------------- helpers
def build(texts: dict[str, str], folder: Path, extra: tuple[str, ...] = ()) -> Path:
    """Write the export and the driver into ``folder``, compile (``FLAGS`` and ``extra``),
    return the program."""
    folder.mkdir(parents=True, exist_ok=True)
    for name, text in texts.items():
        (folder / name).write_text(text)
    (folder / "driver.c").write_text(DRIVER)
    exe = folder / "driver"
    proc = subprocess.run([CC, *FLAGS, *extra, "-I", str(folder), str(folder / "hystid_model.c"),
                           str(folder / "driver.c"), "-o", str(exe), "-lm"],
                          capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr
    return exe


def run(exe: Path, mode: str, *columns: np.ndarray) -> np.ndarray:
    """Feed the columns to the driver (exact decimal text), parse its rows."""
    rows = np.column_stack(columns)
    text = f"{len(rows)}\n" + "\n".join(" ".join(repr(float(v)) for v in r) for r in rows)
    out = subprocess.run([str(exe), mode], input=text, capture_output=True, text=True,
                         check=True).stdout
    return np.array([[float(v) for v in line.split()] for line in out.splitlines()])


def assert_close(c: np.ndarray, py: np.ndarray, rtol: float = RTOL) -> None:
    """Sample by sample: ``|c - py| <= rtol |py|`` (exact where ``py`` is 0)."""
    assert c.shape == py.shape
    bad = np.abs(c - py) > rtol * np.abs(py)
    assert not bad.any(), (f"{bad.sum()} samples differ, first at {np.argmax(bad)}: "
                           f"{c[bad][:3]} vs {py[bad][:3]}")


def placed_duhem() -> DuhemSandwich:
    ref = reference_model()
    return DuhemSandwich(ref.params, ref.structure, fs=ref.fs, name="placed", u_rest=-5.34,
                         offset=-0.8, rest_memory=0.02, envelope=Envelope(-5.34, 4.7, 0.05),
                         units={"u": "V", "y": "um"})


def pi_model(placed: bool, swing: float = 0.0) -> PISandwich:
    """A PI model; placed, at rest at 1.5 with an offset; with ``swing``, resting on the branch
    an excursion to ``u_rest + swing`` left (the plays not virgin, L2 settled off zero)."""
    n = 12
    params = {"a11": -0.6, "a12": 0.05, "b12": 0.1, "a21": -1.2, "a22": 0.4, "b22": 0.05,
              **{f"mu{i}": 0.3 / (1 + i) for i in range(n)}}
    place = {"u_rest": 1.5, "offset": 0.3, "envelope": Envelope(0.0, 10.0, 0.5)} if placed \
        else {}
    return PISandwich(params, pi_thresholds((0.0, 10.0), n), PIStructure(n_operators=n),
                      fs=10_000.0, rest_swing=swing, **place)


def pi_poly_model() -> PISandwich:
    """:func:`pi_model` (placed) with quadratic and cubic terms beside the plays."""
    base = pi_model(True)
    n = len(base.thresholds)
    s = PIStructure(n_operators=n, n_poly=2)
    params = {**base.params, "c2": 0.004, "c3": -2e-4}
    return PISandwich(params, base.thresholds, s, fs=base.fs, u_rest=base.u_rest,
                      offset=base.offset, envelope=base.envelope)


def stage_a_model() -> DuhemSandwich:
    from hystid.identify import identify
    from hystid.records import load_record

    path = STAGE_A / "prbn_1.csv"
    if not path.exists():
        pytest.skip(f"measured stage A record not found at {path}")
    rec = load_record(path)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return identify(rec, model="duhem").model


def excitation(model, n: int) -> np.ndarray:
    env = model.envelope or Envelope(0.0, 10.0, 0.05)
    u = paper_excitation(n, seed=3)
    u = (u - u.min()) / (u.max() - u.min())
    return model.u_rest + u * (env.u_max - model.u_rest)


# --------------------------------------------------------------------------- the model
MODELS = {
    "duhem": reference_model,
    "duhem-placed": placed_duhem,
    "pi": lambda: pi_model(False),
    "pi-placed": lambda: pi_model(True),
    "pi-swung": lambda: pi_model(True, swing=4.0),
    "pi-poly-placed": pi_poly_model,
}


@needs_cc
@pytest.mark.parametrize("name", list(MODELS))
def test_model_step_matches_simulate(name, tmp_path):
    model = MODELS[name]()
    exe = build(c_sources(model), tmp_path)
    u = excitation(model, 5_000)
    py = model.simulate(u, check=False).y
    c = run(exe, "model", u)[:, 0]
    assert_close(c, py)
    assert np.ptp(py) > 0


@needs_cc
def test_model_and_rpem_match_on_stage_a(tmp_path):
    """A model identified on measured stage A (rest level -5.34 V, a sensor offset): the
    model on two records and the RPEM step warm-started on a record."""
    from hystid.records import load_record

    model = stage_a_model()
    assert model.u_rest != 0 and model.offset != 0 and model.rest_memory != 0
    prbn = load_record(STAGE_A / "prbn_1.csv")
    texts = c_sources(model, rpem_record=prbn)
    exe = build(texts, tmp_path)
    for rec in (prbn, load_record(STAGE_A / "sine50_1.csv")):
        assert_close(run(exe, "model", rec.u)[:, 0], model.simulate(rec.u, check=False).y)
    sine = load_record(STAGE_A / "sine50_1.csv")
    n = 4_000
    ident = rpem_start(model, prbn)  # supervised, as the export by default
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        history = rpem_reference(ident, sine.u[:n], sine.y[:n])
    assert_close(run(exe, "rpem", sine.u[:n], sine.y[:n])[:, :len(model.theta)], history)


# --------------------------------------------------------------------------- compensator
def _ff_case(model, r: np.ndarray, tmp_path: Path, **options) -> hc.Compensation:
    """The C compensator on a reference in record units, fed the reference and then
    ``HYSTID_FF_DELAY`` copies of its last value, against ``compensate(model, r, ...)`` sample
    by sample: the command, the desired output and the status (the first ``HYSTID_FF_DELAY``
    calls return the rest command)."""
    texts = c_sources(model, compensator=options or None)
    exe = build(texts, tmp_path)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        res = hc.compensate(model, r, **ff_options(model, **options), warn=False)
    D = res.preview
    assert f"#define HYSTID_FF_DELAY {D}\n" in texts["hystid_model.h"]
    assert D == ff_plan(model, **options).preview
    out = run(exe, "ff", np.concatenate([r, np.full(D, r[-1])]))
    assert out.shape == (r.size + D, 3)
    assert np.all(out[:D, 0] == out[0, 0])  # the rest command while the preview is read in
    assert_close(out[D:, 0], res.u)
    assert_close(out[D:, 1], res.y_des)
    np.testing.assert_array_equal(out[D:, 2].astype(int), res.status)
    assert np.ptp(res.u) > 0
    return res


def triangle(model, amplitude: float, seconds: float = 0.2, hz: float = 20.0) -> np.ndarray:
    """A triangle scan about the model's output at rest, reached from rest (record units)."""
    from hystid.cli.compensate import scan_for

    return scan_for(model, "triangle", hz, amplitude, seconds)


def own_output(model, n: int, seed: int = 0, noise: float = 0.0) -> np.ndarray:
    """What the model outputs for a smooth input moving from its first sample, with sensor-like
    noise: a reference that moves at once (the pre-actuation a zero outside the circle needs
    falls before it)."""
    env = model.envelope
    rng = np.random.default_rng(seed)
    x = signal.filtfilt(*signal.butter(2, 0.01), rng.standard_normal(n))
    x = np.abs(x - x[0]) / np.max(np.abs(x - x[0]))  # from 0, in 0..1
    wide = env.u_max - model.u_rest if env.u_max - model.u_rest > model.u_rest - env.u_min \
        else env.u_min - model.u_rest
    u = np.clip(model.u_rest + 0.8 * wide * x, env.u_min, env.u_max)
    y = model.simulate(u, check=False).y
    return y + noise * np.ptp(y) * rng.standard_normal(n)


def nmp_duhem() -> DuhemSandwich:
    """The placed Duhem model with a zero of L2 outside the unit circle (at -1.5)."""
    base = placed_duhem()
    return DuhemSandwich({**base.params, "b21": 1.5}, Structure(n2b=1), fs=base.fs,
                         name="nmp", u_rest=base.u_rest, offset=base.offset,
                         rest_memory=base.rest_memory, envelope=base.envelope,
                         units=base.units)


@pytest.fixture(scope="module")
def pi_stage():
    """The pi-stage member identified on a simulated stage A (L2 third order, a zero outside
    the unit circle)."""
    from hystid.identify import identify
    from hystid.testing import stage_a_like

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        model = identify(stage_a_like("prbn", seconds=1.0, rest_seconds=0.5, seed=0),
                         model="pi-stage").model
    assert np.any(np.abs(np.roots(model.b2)) > 1.0)
    return model


@needs_cc
def test_ff_step_matches_compensate_with_reversal_planning(tmp_path):
    model = placed_duhem()
    res = _ff_case(model, triangle(model, 3.0), tmp_path)
    assert res.preview == 300 + model.structure.q1 + model.structure.q2
    assert np.any(res.status & 8) and np.any(res.status == 0)  # far branches taken
    assert res.u_limits == hc.envelope_limits(model)


@needs_cc
def test_ff_step_matches_compensate_while_saturating(tmp_path):
    """The reference stage between 0 and 10 V on a 50 Hz triangle (bench_export's case): the
    command saturates for a third of each period, the state leaves the planner's path."""
    model = reference_model()
    ramp = model.simulate(np.linspace(model.u_rest, 10.0, 5_000), check=False).y
    res = _ff_case(model, triangle(model, 0.6 * abs(ramp[-1] - ramp[0]), 0.1, 50.0), tmp_path,
                   u_limits=(0.0, 10.0))
    assert np.mean((res.status & 4) != 0) > 0.2
    assert np.any(res.status & 8) and np.any(res.status & 1) and np.any(res.status == 0)


@needs_cc
def test_ff_step_matches_with_a_reference_model_and_the_reference_anchor(tmp_path):
    model = placed_duhem()
    r = triangle(model, 3.0) + 0.05  # the sensor zero moved by 50 nm
    res = _ff_case(model, r, tmp_path, reference_model=hc.smoothing_model(31, model.dt),
                   anchor="reference")
    s = model.structure
    assert res.y_rest == r[0] and res.preview == 300 + 15 + s.q1 + s.q2


@needs_cc
def test_ff_step_matches_the_central_line_inverse(tmp_path):
    model = placed_duhem()
    _ff_case(model, triangle(model, 3.0), tmp_path, compensation="linear")


@needs_cc
def test_ff_step_makes_up_the_cut_pre_actuation_like_compensate(tmp_path):
    """L2 with a zero outside the circle and a reference moving at once: the C step makes up
    the pre-actuation before the first sample as compensate does (and the planner runs on it)."""
    model = nmp_duhem()
    r = own_output(model, 3_000)
    res = _ff_case(model, r, tmp_path)
    assert res.settle > 0 and np.ptp(r[:res.settle]) > 1e-3 * np.ptp(r)  # moves within it
    assert np.any(res.status & 8)


@needs_cc
@pytest.mark.parametrize("placed,swing", [(False, 0.0), (True, 0.0), (True, 4.0), (True, -3.0)])
def test_ff_step_matches_for_a_pi_model(placed, swing, tmp_path):
    model = pi_model(placed, swing)
    res = _ff_case(model, triangle(model, 1.5, seconds=0.3), tmp_path, u_limits=(-20.0, 20.0))
    if swing:  # the compensator starts from the plays the swing left: the model follows
        y = model.simulate(res.u, check=False).y
        assert np.sqrt(np.mean((y - res.y_des) ** 2)) < 1e-6 * np.ptp(res.y_des)


@needs_cc
@pytest.mark.parametrize("reference", ["triangle", "measured-like"])
def test_ff_step_matches_for_the_pi_stage(reference, pi_stage, tmp_path):
    model = pi_stage
    if reference == "triangle":
        res = _ff_case(model, triangle(model, 4.0, seconds=0.3), tmp_path)
    else:
        res = _ff_case(model, own_output(model, 4_000, seed=1, noise=2e-4), tmp_path,
                       anchor="reference")
        assert res.settled_relative_error < 1e-9 < res.relative_error
    assert res.settle > 0 and np.all(res.exact)


@needs_cc
@pytest.mark.parametrize("member", ["duhem", "pi-stage"])
def test_ff_step_matches_compensate_on_a_measured_displacement(member, tmp_path):
    """Stage A: the member identified on prbn_1, the reference a displacement measured on
    another record (its sensor zero moved: the rest anchored at its first sample), smoothed as
    the benchmark asks for it, and raw."""
    from hystid.identify import identify
    from hystid.records import load_record

    path = STAGE_A / "prbn_1.csv"
    if not path.exists():
        pytest.skip(f"measured stage A record not found at {path}")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        model = identify(load_record(path), model=member).model
    r = load_record(STAGE_A / "sine50_1.csv").y[:6_000]
    res = _ff_case(model, r, tmp_path / "smooth", anchor="reference",
                   reference_model=hc.smoothing_model(21, model.dt))
    assert not np.all(res.status & 4)  # not simply saturated
    _ff_case(model, r, tmp_path / "raw")


def test_ff_limits_default_to_the_envelope_in_record_units():
    model = placed_duhem()
    env = model.envelope
    pad = 0.1 * (env.u_max - env.u_min)
    low, high = ff_options(model)["u_limits"]
    assert (low, high) == pytest.approx((env.u_min - pad, env.u_max + pad))
    assert ff_options(model, u_limits=(-1.0, 2.0))["u_limits"] == (-1.0, 2.0)
    assert ff_options(model, margin=0.0)["u_limits"] == (env.u_min, env.u_max)
    head = c_sources(model)["hystid_model.h"]
    assert f"#define HYSTID_FF_U_MIN ({low!r})" in head
    with pytest.raises(ValueError, match="unknown"):
        ff_options(model, smoother=3)


def test_a_model_without_envelope_is_exported_without_compensator_unless_limits_given():
    model = reference_model()
    assert model.envelope is None
    notes: list[str] = []
    assert "#define HYSTID_NO_FF 1" in c_sources(model, notes=notes)["hystid_model.h"]
    assert notes and "envelope" in notes[0]
    head = c_sources(model, compensator={"u_limits": (0.0, 10.0)})["hystid_model.h"]
    assert "HYSTID_NO_FF" not in head and "#define HYSTID_FF_U_MAX 10.0" in head


@needs_cc
def test_ff_step_matches_for_a_pi_poly_model(tmp_path):
    """The per-sample inverse of a PI block with polynomial terms (bracket and bisection):
    the C step against compensate(), sample by sample."""
    model = pi_poly_model()
    assert model.is_invertible()
    texts = c_sources(model)
    assert "#define HX_FF_NPOLY 2" in texts["hystid_model.c"]
    assert "hx_pi_poly_inverse" in texts["hystid_model.c"]
    _ff_case(model, triangle(model, 1.5, seconds=0.3), tmp_path, u_limits=(-20.0, 20.0))


def test_pi_without_inverse_is_exported_without_compensator():
    model = pi_model(True)
    model.theta[model.structure.slices()["mu"]] = -0.1
    notes: list[str] = []
    texts = c_sources(model, notes=notes, compensator=None)
    assert "#define HYSTID_NO_FF 1" in texts["hystid_model.h"]
    assert "hystid_ff_step" not in texts["hystid_model.c"]
    assert notes and "no exact inverse" in notes[0]
    with pytest.raises(ValueError, match="no exact inverse"):
        c_sources(model, compensator={"u_limits": (0.0, 10.0)})


def test_a_model_kind_without_c_is_refused_by_name():
    from hystid.baselines import LinearModel

    lin = LinearModel.__new__(LinearModel)
    with pytest.raises(ValueError, match="LinearModel cannot be exported to C .* Duhem, the "
                                         "Prandtl-Ishlinskii and the multi-Duhem sandwiches"):
        c_sources(lin)


# --------------------------------------------------------------------------- gduhem, mduhem
#: Generalised Duhem structures: the gduhem member's (cubic curve, quadratic slope, static
#: L1), the same with directions behind an L1 with a zero, and a quadratic curve with f0, a
#: linear slope and directions behind the paper's L1.
GDUHEM = {
    "gduhem": None,
    "f3-g2-directional": Structure(n1a=1, n1b=1, q1=1, n2a=3, n2b=2, q2=1, f_order=3,
                                   g_order=2, directional=True),
    "f0-f2-g1-directional": Structure(f0=True, f_order=2, g_order=1, directional=True),
}


@pytest.fixture(scope="module")
def members():
    """The gduhem models of :data:`GDUHEM` and the mduhem member, identified on a simulated
    stage A record (10 kHz, rest level -13 V), and one with every shape term (f0, a cubic curve,
    a quadratic slope, strong directions) set by hand on the paper's L1 and L2."""
    from hystid.identify import identify
    from hystid.testing import stage_a_like

    rec = stage_a_like(seconds=0.3, rest_seconds=0.1)
    out = {}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        for name, s in GDUHEM.items():
            out[name] = identify(rec, model="gduhem" if s is None else "duhem",
                                 structure=s).model
        out["mduhem"] = identify(rec, model="mduhem").model
    base = out["f0-f2-g1-directional"]
    p = base.params
    w = 0.5 * (base.envelope.u_max - base.envelope.u_min)  # the input's half span
    out["directional-by-hand"] = DuhemSandwich(
        {**p, "f3": -0.1 * p["f1"] / w**2, "g2": 0.1 * p["g0"] / w**2, "ad": 0.4,
         "gd": -0.5 * p["g0"]}, Structure(f0=True, f_order=3, g_order=2, directional=True),
        fs=base.fs, name="by hand", u_rest=base.u_rest, offset=base.offset,
        rest_memory=base.rest_memory, envelope=base.envelope, units=base.units)
    return out


def unseen_inputs(model, n: int = 6_000, seed: int = 5) -> list[np.ndarray]:
    """Inputs the model was not identified on, inside its envelope: a triangle that starts
    away from the rest level (a jump at the first sample) and a random walk from rest."""
    env = model.envelope
    pad = 0.1 * (env.u_max - env.u_min)
    lo, hi = env.u_min + pad, env.u_max - pad
    phase = (np.arange(n) / 1_500 + 0.4) % 1.0
    tri = lo + (hi - lo) * (1.0 - np.abs(2.0 * phase - 1.0))
    rng = np.random.default_rng(seed)
    x = model.u_rest - lo + np.cumsum(rng.normal(0.0, 0.3 * env.slew, n))
    m = np.mod(x, 2.0 * (hi - lo))  # reflected at lo and hi
    walk = lo + np.where(m > hi - lo, 2.0 * (hi - lo) - m, m)
    assert abs(tri[0] - model.u_rest) > 0.2 * (hi - lo)
    return [tri, walk]


@needs_cc
@pytest.mark.parametrize("name", [*GDUHEM, "directional-by-hand", "mduhem"])
def test_member_model_step_matches_simulate_on_unseen_inputs(name, members, tmp_path):
    """The generalised Duhem block and the multi-Duhem sandwich: the C step against simulate,
    from rest (the remembered Duhem state included), on inputs the fit never saw; exported with
    the compensator (the multi-Duhem without an on-line identifier, saying why)."""
    model = members[name]
    if name == "mduhem":
        assert len(model.rates) == 6
    else:
        s = model.structure
        assert not s.is_plain and model.rest_memory != 0 and model.u_rest != 0
        assert (s.f_order, s.g_order, s.directional) == {
            "gduhem": (3, 2, False), "f0-f2-g1-directional": (2, 1, True)}.get(name, (3, 2, True))
    notes: list[str] = []
    texts = c_sources(model, notes=notes)
    head = texts["hystid_model.h"]
    multi = name == "mduhem"
    assert "HYSTID_NO_FF" not in head and "hystid_ff_step" in texts["hystid_model.c"]
    assert ("#define HYSTID_NO_RPEM 1" in head) == multi
    assert len(notes) == multi
    if multi:
        assert "on-line identifier" in notes[0]
    includes = [line for line in texts["hystid_model.c"].splitlines()
                if line.startswith("#include")]
    assert includes == ["#include <math.h>", '#include "hystid_model.h"']
    exe = build(texts, tmp_path)
    for u in unseen_inputs(model):
        py = model.simulate(u, check=False).y
        assert_close(run(exe, "model", u)[:, 0], py)
        assert np.ptp(py) > 0


@needs_cc
@pytest.mark.parametrize("name", ["gduhem", "mduhem"])
def test_member_central_line_compensator_is_exported_when_asked(name, members, tmp_path):
    """The members' central-line compensator (the uncompensated baseline), asked for; a
    look-ahead, which their inverses have not, is refused."""
    model = members[name]
    with pytest.raises(ValueError, match="preview: the .* without look-ahead"):
        c_sources(model, compensator={"preview": 30})
    _ff_case(model, triangle(model, 3.0, seconds=0.3), tmp_path, compensation="linear")


def output_span(model) -> float:
    """How far the model's output moves from its rest when its input ramps from the rest
    level to either end of its envelope (the narrower side, record units)."""
    env = model.envelope
    rest = model.simulate(np.full(2, model.u_rest), check=False).y[-1]
    ends = [model.simulate(np.linspace(model.u_rest, end, 3_000), check=False).y[-1]
            for end in (env.u_min, env.u_max)]
    return min(abs(y - rest) for y in ends)


def member_reference(model, reference: str) -> tuple[np.ndarray, dict]:
    """A reference the model was not identified on (record units) and the compensator's
    options for it: a triangle inside the model's envelope, the displacement of a stage_a_like
    record of another kind and seed (the rest anchored at its first sample), or a triangle
    larger than the limits let the model reach."""
    from hystid.testing import stage_a_like

    if reference == "triangle":
        return triangle(model, output_span(model), seconds=0.3), {}
    if reference == "measured-like":
        rec = stage_a_like("tri100", seconds=0.3, rest_seconds=0.05, seed=3)
        return rec.y, {"anchor": "reference"}
    return triangle(model, 4.0 * output_span(model), seconds=0.3, hz=30.0), {}


@needs_cc
@pytest.mark.parametrize("reference", ["triangle", "measured-like", "saturating"])
@pytest.mark.parametrize("name", [*GDUHEM, "directional-by-hand", "mduhem"])
def test_ff_step_matches_compensate_for_a_member(name, reference, members, tmp_path):
    """The generalised Duhem block's and the multi-Duhem sandwich's per-sample inverses in C:
    ``hystid_ff_step`` against ``compensate`` sample by sample (command, desired output,
    status) on references the models were not identified on, the saturating one included."""
    model = members[name]
    r, options = member_reference(model, reference)
    res = _ff_case(model, r, tmp_path, **options)
    src = c_sources(model, compensator=options or None)["hystid_model.c"]
    assert ("hx_md_inverse_step" if name == "mduhem" else "hx_gd_inverse_step") in src
    assert "static double hx_plan_memo" not in src  # no look-ahead: no reversal planner
    saturated = np.mean((res.status & hc.SATURATED) != 0)
    if reference == "saturating":
        assert saturated > 0.2
    else:
        assert saturated < 0.01 and np.mean(res.exact) > 0.9


def turning_member(model):
    """The member made unable to reverse in one step after a long branch (the Duhem block's
    curve slope above twice its reversible slope; the operators' reversible slopes cut to
    0.3): its inverse takes the approximate turning step there (status 2)."""
    from hystid.mduhem import MultiDuhemSandwich

    if isinstance(model, MultiDuhemSandwich):
        params = {k: v * (0.3 if k.startswith("g0") else 1.0) for k, v in model.params.items()}
        return MultiDuhemSandwich(params, model.rates, model.structure, fs=model.fs,
                                  name="turning", u_rest=model.u_rest, offset=model.offset,
                                  envelope=model.envelope, units=model.units)
    return DuhemSandwich({**model.params, "f1": 6.0 * model.params["f1"]}, model.structure,
                         fs=model.fs, name="turning", u_rest=model.u_rest, offset=model.offset,
                         rest_memory=model.rest_memory, envelope=model.envelope,
                         units=model.units)


@needs_cc
@pytest.mark.parametrize("name", ["directional-by-hand", "mduhem"])
def test_ff_step_matches_compensate_through_unreachable_reversals(name, members, tmp_path):
    """Members whose reversals cannot be made in one step: the C inverse takes the same
    approximate steps (status 2) and the bound of condition 8 (status 1) as compensate."""
    model = turning_member(members[name])
    res = _ff_case(model, triangle(model, 3.0, seconds=0.3), tmp_path / "triangle")
    assert np.any(res.status & 2) and np.any(res.status & 1)
    r, options = member_reference(model, "measured-like")
    res = _ff_case(model, r, tmp_path / "measured", **options,
                   reference_model=hc.smoothing_model(21, model.dt))
    assert np.any(res.status & 2)


@needs_cc
@pytest.mark.parametrize("name", ["gduhem", "mduhem"])
def test_cli_export_of_a_member(name, members, tmp_path, capsys):
    """``hystid export model.json --c DIR`` for a saved gduhem or mduhem model: the files (the
    compensator in them), the note on what is left out, and the step of the loaded model."""
    from hystid.export import C_FILES
    from hystid.modelfile import load_model

    model_file = members[name].save(tmp_path / "model.json")
    capsys.readouterr()
    assert main(["export", str(model_file), "--c", str(tmp_path / "out")]) == 0
    out, err = capsys.readouterr()
    assert out.startswith("wrote ")
    assert "note: no feed-forward compensator" not in err
    assert ("note: no on-line identifier" in err) == (name == "mduhem")
    texts = {f: (tmp_path / "out" / f).read_text() for f in C_FILES}
    model = load_model(model_file)
    assert texts == c_sources(model, source=str(model_file))
    exe = build(texts, tmp_path / "build")
    u = unseen_inputs(model)[1]
    assert_close(run(exe, "model", u)[:, 0], model.simulate(u, check=False).y)


# --------------------------------------------------------------------------- on-line identifier
@needs_cc
@pytest.mark.parametrize("supervise", [False, True])
def test_rpem_step_matches_the_recursion(supervise, tmp_path):
    """The parameter trajectory of the C step against the recursion (rpem_run; with the
    supervisor, rpem_reference: rollbacks and validated candidates), with clipped outliers, a
    skipped sample and a diverging burst that forces a restart."""
    model = placed_duhem()
    exe = build(c_sources(model, rpem_supervise=supervise), tmp_path)
    n = 3_000
    u = excitation(model, n)
    truth = DuhemSandwich(model.theta * 1.02, model.structure, fs=model.fs,
                          u_rest=model.u_rest, offset=model.offset + 0.01)
    rng = np.random.default_rng(0)
    y = truth.simulate(u, check=False).y + 1e-3 * rng.standard_normal(n)
    y[500] += 5.0
    y[700] = np.nan
    y[1_500:1_800] += 30.0  # a diverging stretch: the recursion restarts (and projects)
    ident = rpem_start(model, supervise=supervise)
    npar = len(model.theta)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        history = rpem_reference(ident, u, y)
    out = run(exe, "rpem", u, y)
    assert_close(out[:, :npar], history)
    assert out[-1, npar] == ident.offset_estimate
    assert out[-1, -1] == ident.n_recoveries >= 1 and ident.n_projections >= 1
    assert np.max(np.abs(history[-1] / model.theta - 1)) > 1e-3  # the estimate moved
    if supervise:
        assert ident._supervisor.n_rollbacks >= 1 and ident._supervisor.n_accepted >= 1
    else:  # rpem_reference without the supervisor is rpem_run on u - u_rest
        bare = rpem_start(model, supervise=False)
        again = np.empty((n, npar))
        rpem_run(bare._buf, bare._ints, np.ascontiguousarray(u - model.u_rest), y, again,
                 np.empty((n, 7)))
        np.testing.assert_array_equal(again, history)


@needs_cc
@pytest.mark.parametrize("supervise", [False, True])
@pytest.mark.parametrize("name", ["gduhem", "f0-f2-g1-directional", "directional-by-hand"])
def test_rpem_step_matches_the_recursion_for_the_generalised_block(name, supervise, members,
                                                                   tmp_path):
    """The generalised block's RPEM: the C trajectory against rpem_run through outliers, a
    skipped sample and a diverging burst, on an input the model was not identified on; the
    stage's hysteresis block 2 % off the model's (its L2, a slow pole near the unit circle,
    kept: 2 % more would make it unstable)."""
    model = members[name]
    exe = build(c_sources(model, rpem_supervise=supervise), tmp_path)
    n = 3_000
    u = unseen_inputs(model, n)[1]
    block = {"alpha", "f0", "f1", "g0", "f2", "f3", "g1", "g2", "ad", "gd"}
    truth = DuhemSandwich({k: v * (1.02 if k in block else 1.0) for k, v in model.params.items()},
                          model.structure, fs=model.fs, u_rest=model.u_rest,
                          offset=model.offset + 0.01, rest_memory=model.rest_memory)
    rng = np.random.default_rng(1)
    y = truth.simulate(u, check=False).y
    span = np.ptp(y)
    y = y + 1e-3 * span * rng.standard_normal(n)
    y[500] += 0.5 * span
    y[700] = np.nan
    y[1_500:1_800] += 3.0 * span  # a diverging stretch: the recursion restarts
    ident = rpem_start(model, supervise=supervise)
    npar = len(model.theta)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        history = rpem_reference(ident, u, y)
    out = run(exe, "rpem", u, y)
    assert_close(out[:, :npar], history)
    assert out[-1, npar] == ident.offset_estimate
    assert out[-1, -1] == ident.n_recoveries >= 1
    assert np.max(np.abs(history[-1] / model.theta - 1)) > 1e-3  # the estimate moved


def test_rpem_is_for_duhem_models_only():
    texts = c_sources(pi_model(False))
    assert "#define HYSTID_NO_RPEM 1" in texts["hystid_model.h"]
    with pytest.raises(ValueError, match="Duhem models only"):
        rpem_start(pi_model(False))


# --------------------------------------------------------------------------- what is written
def test_the_source_needs_only_math_h():
    for model in (placed_duhem(), pi_model(True)):
        texts = c_sources(model)
        includes = [line for line in texts["hystid_model.c"].splitlines()
                    if line.startswith("#include")]
        assert includes == ["#include <math.h>", '#include "hystid_model.h"']
        assert "#include" not in texts["hystid_model.h"]
        assert not any(w in texts["hystid_model.c"] for w in ("malloc", "calloc", "free("))


def test_export_never_overwrites_without_force(tmp_path):
    model = placed_duhem()
    paths = export_c(model, tmp_path / "c")
    assert [p.name for p in paths] == ["hystid_model.h", "hystid_model.c"]
    (tmp_path / "c" / "hystid_model.c").write_text("mine")
    with pytest.raises(ValueError, match="already"):
        export_c(model, tmp_path / "c")
    assert (tmp_path / "c" / "hystid_model.c").read_text() == "mine"
    export_c(model, tmp_path / "c", force=True)
    assert "hystid_model_step" in (tmp_path / "c" / "hystid_model.c").read_text()


# --------------------------------------------------------------------------- the command
def test_cli_export(tmp_path, capsys):
    model_file = placed_duhem().save(tmp_path / "model.json")
    assert main(["export", str(model_file), "--c", str(tmp_path / "out"), "--quiet"]) == 0
    assert sorted(p.name for p in (tmp_path / "out").iterdir()) == ["hystid_model.c",
                                                                    "hystid_model.h"]
    # existing files, no --force: one line, exit 2, the files untouched
    (tmp_path / "out" / "hystid_model.h").write_text("mine")
    capsys.readouterr()
    assert main(["export", str(model_file), "--c", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("hystid export: error:") and "\n" not in err and "--force" in err
    assert (tmp_path / "out" / "hystid_model.h").read_text() == "mine"
    assert main(["export", str(model_file), "--c", str(tmp_path / "out"), "--force",
                 "--quiet"]) == 0
    assert "HYSTID_MODEL_H" in (tmp_path / "out" / "hystid_model.h").read_text()


@pytest.mark.parametrize("case", ["not-a-model", "missing", "unwritable"])
def test_cli_export_bad_input(case, tmp_path, capsys):
    model_file = placed_duhem().save(tmp_path / "model.json")
    out = tmp_path / "out"
    if case == "not-a-model":
        model_file = tmp_path / "record.csv"
        model_file.write_text("t,u,y\n0,0,0\n")
    elif case == "missing":
        model_file = tmp_path / "nothing.json"
    else:
        out = tmp_path / "a-file"
        out.write_text("x")
    assert main(["export", str(model_file), "--c", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("hystid export: error:") and "\n" not in err
    assert not (tmp_path / "out").exists()


def test_cli_export_options(tmp_path, capsys):
    model = placed_duhem()
    model_file = model.save(tmp_path / "model.json")
    rec = tmp_path / "rec.csv"
    u = excitation(model, 3_000)
    y = model.simulate(u, check=False).y
    rec.write_text("t,u,y\n" + "\n".join(f"{k / model.fs!r},{float(a)!r},{float(b)!r}"
                                          for k, (a, b) in enumerate(zip(u, y, strict=True))))
    assert main(["export", str(model_file), "--c", str(tmp_path / "out"), "--u-limits=-6,6",
                 "--preview", "50", "--rpem-record", str(rec), "--quiet"]) == 0
    head = (tmp_path / "out" / "hystid_model.h").read_text()
    assert "#define HYSTID_FF_U_MIN (-6.0)" in head and "#define HYSTID_FF_U_MAX 6.0" in head
    assert "#define HYSTID_FF_PREVIEW 50" in head
    src = (tmp_path / "out" / "hystid_model.c").read_text()
    assert src != c_sources(model, compensator={"u_limits": (-6.0, 6.0), "preview": 50})[
        "hystid_model.c"]  # the record changed the RPEM's starting covariance
    assert main(["export", str(model_file), "--c", str(tmp_path / "smooth"), "--smooth", "21",
                 "--anchor", "reference", "--margin", "0", "--quiet"]) == 0
    src = (tmp_path / "smooth" / "hystid_model.c").read_text()
    head = (tmp_path / "smooth" / "hystid_model.h").read_text()
    plan = ff_plan(model, reference_model=hc.smoothing_model(21, model.dt), anchor="reference",
                   margin=0.0)
    assert "#define HX_FF_ANCHOR_REFERENCE 1" in src and "#define HX_FF_LEAD 10" in src
    assert f"#define HYSTID_FF_DELAY {plan.preview}\n" in head and plan.lead == 10
    assert f"#define HYSTID_FF_U_MAX {model.envelope.u_max!r}" in head
    for bad in (["--u-limits", "6,-6"], ["--preview", "-1"], ["--rpem-sigma", "0"],
                ["--smooth", "4"], ["--margin", "-1"], ["--anchor", "sensor"]):
        with pytest.raises(SystemExit) as exc:
            main(["export", str(model_file), "--c", str(tmp_path / "x"), *bad])
        assert exc.value.code == 2
    assert not (tmp_path / "x").exists()
