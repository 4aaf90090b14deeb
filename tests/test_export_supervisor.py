"""The exported on-line identifier with its supervisor: ``hystid_rpem_step`` against the
supervised Python identifier warm-started the same way (:func:`hystid.export.rpem_start`,
:func:`hystid.export.rpem_reference`), to the last bit, where the supervisor rolls back.

The C is compiled as in ``test_export`` (the driver and the helpers are that module's), with
``-ffp-contract=off`` besides (no fused multiply-adds, whatever the compiler's default), and
the trajectories are compared for equality.
"""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
import pytest
from test_export import build, needs_cc, placed_duhem, run
from test_online_supervisor import PIEZO, broadband_then_sine

from hystid.cli import main
from hystid.export import c_sources, rpem_reference, rpem_start
from hystid.identify.online import OnlineIdentifier
from hystid.records import Record, load_piezo_sine_150v

EXACT = ("-ffp-contract=off",)


def supervised_case(model, info: Record, u: np.ndarray, y: np.ndarray, folder: Path,
                    **options) -> OnlineIdentifier:
    """The C step (supervised, warm-started at ``model`` with ``info``'s information) against
    rpem_reference, sample by sample and bit for bit; returns the Python identifier."""
    exe = build(c_sources(model, rpem_record=info, **options), folder, EXACT)
    out = run(exe, "rpem", u, y)
    ident = rpem_start(model, info)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        history = rpem_reference(ident, u, y)
    npar = len(model.theta)
    np.testing.assert_array_equal(out[:, :npar], history)
    assert out[-1, npar] == ident.offset_estimate
    assert out[-1, -1] == ident.n_recoveries
    return ident


def bare_history(model, info: Record, u: np.ndarray, y: np.ndarray) -> np.ndarray:
    ident = rpem_start(model, info, supervise=False)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        return rpem_reference(ident, u, y)


@pytest.fixture(scope="module")
def independent_stage():
    """The broadband-then-sine record of the independent simulator and the supervised
    on-line identifier's estimate on its broadband part (the warm start)."""
    train = broadband_then_sine(0)
    est = OnlineIdentifier()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        est.fit(train[:12_000])
    return train, est.model


@needs_cc
@pytest.mark.parametrize("part", ["whole", "sine"])
def test_supervised_step_equals_python_through_rollbacks_on_an_independent_stage(
        part, independent_stage, tmp_path):
    """Warm-started at the estimate the broadband part gave (its information from that part):
    over the whole record candidates validate and the sine makes the recursion wander (one
    rollback, measured); over the sine alone it diverges again and again (hundreds of
    rollbacks, none validated). The bare recursion ends elsewhere."""
    train, model = independent_stage
    lo = 0 if part == "whole" else 12_000
    u, y = train.u[lo:], train.y[lo:]
    ident = supervised_case(model, train[:12_000], u, y, tmp_path)
    sup = ident._supervisor
    assert sup.n_rollbacks >= 1
    if part == "whole":
        assert sup.n_accepted >= 1 and "wandered" in sup.first_reason
    assert np.max(np.abs(bare_history(model, train[:12_000], u, y)[-1] / ident.theta - 1)) \
        > 1e-3


@needs_cc
@pytest.mark.skipif(not PIEZO.exists(), reason=f"measured piezo record not found: {PIEZO} "
                    "(../shared/data beside the checkout)")
def test_supervised_step_equals_python_through_a_rollback_on_the_measured_piezo(tmp_path):
    """tests/test_online_supervisor.py's pi_vs_duhem split (from sample 16 000): warm-started
    at the on-line identifier's start-up solution on the split's first 400 samples, the
    recursion wanders right after its settling (one rollback, measured), candidates validate
    through the 1 Hz sine and its turning points; the C step follows Python to the end of the
    record (34 000 samples)."""
    rec = load_piezo_sine_150v(PIEZO)
    start, m = 16_000, 400
    u, y = rec.u[start:], rec.y[start:]
    info = Record(u[:m], y[:m], rec.fs, rec.units, name="piezo, start-up window")
    est = OnlineIdentifier(fs=rec.fs, start_retries=())
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        est.fit(info)
    ident = supervised_case(est.model, info, u[m:], y[m:], tmp_path)
    sup = ident._supervisor
    assert sup.n_rollbacks >= 1 and sup.n_accepted >= 1
    assert np.max(np.abs(bare_history(est.model, info, u[m:], y[m:])[-1] / ident.theta - 1)) \
        > 1e-3


@needs_cc
def test_the_bare_recursion_is_a_define_or_an_option_away(tmp_path):
    """``-DHYSTID_RPEM_SUPERVISE=0`` on the default export and ``rpem_supervise=False`` (the
    CLI's ``--rpem-bare``) give the bare recursion; the default header says supervised."""
    model = placed_duhem()
    texts = c_sources(model)
    assert "#define HYSTID_RPEM_SUPERVISE 1" in texts["hystid_model.h"]
    bare = c_sources(model, rpem_supervise=False)
    assert "#define HYSTID_RPEM_SUPERVISE 0" in bare["hystid_model.h"]
    n = 3_000
    u = model.u_rest + 3.0 * np.abs(np.sin(np.arange(n) / 200.0))
    y = model.simulate(u, check=False).y
    y[1_500:1_800] += 30.0  # diverging: the supervised and bare recursions part
    want = bare_history(model, None, u, y)
    for folder, text, extra in (("define", texts, ("-DHYSTID_RPEM_SUPERVISE=0",)),
                                ("option", bare, ())):
        exe = build(text, tmp_path / folder, EXACT + extra)
        np.testing.assert_array_equal(run(exe, "rpem", u, y)[:, :len(model.theta)], want)
    assert not np.array_equal(run(build(texts, tmp_path / "default", EXACT), "rpem", u, y)
                              [:, :len(model.theta)], want)


def test_cli_rpem_bare(tmp_path):
    model = placed_duhem()
    model_file = model.save(tmp_path / "model.json")
    assert main(["export", str(model_file), "--c", str(tmp_path / "out"), "--rpem-bare",
                 "--quiet"]) == 0
    texts = {f: (tmp_path / "out" / f).read_text() for f in ("hystid_model.h", "hystid_model.c")}
    assert texts == c_sources(model, source=str(model_file), rpem_supervise=False)
