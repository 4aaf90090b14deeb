"""One contract for every on-line estimator (hystid.identify.base.Estimator), checked alike.

The data come from the independently written stage simulator (hystid.testing), not from the
model the estimators assume.
"""

from __future__ import annotations

import json
import warnings
from types import SimpleNamespace

import numpy as np
import pytest

from hystid.identify.base import Estimator
from hystid.identify.ekf import KalmanIdentifier
from hystid.identify.eria import ERIA
from hystid.identify.online import OnlineIdentifier
from hystid.identify.pi_online import PIStageOnline
from hystid.identify.pi_recursive import PIRecursiveIdentifier
from hystid.pi import PIStructure, pi_thresholds
from hystid.records import Record
from hystid.reference import PAPER_PARAMS
from hystid.testing import paper_excitation, paper_stage

NEAR = {k: (1.05 if k.startswith("a2") else 1.1) * v for k, v in PAPER_PARAMS.items()}
NEAR["a22"] = 0.9 * PAPER_PARAMS["a22"]  # a stable L2 near the truth
PI_THRESHOLDS = pi_thresholds(paper_excitation(0.02, seed=3), 8)  # the record's input range
#: The pi-stage shape with the pi-poly member's polynomial terms.
POLY_STAGE = PIStructure(n_operators=8, n1a=0, n1b=1, q1=0, n2a=3, n2b=3, q2=1, n_poly=2)
ESTIMATORS = {
    "online": lambda: OnlineIdentifier(n_start=200, start_retries=(300,)),
    "eria": lambda: ERIA(),
    "ekf": lambda: KalmanIdentifier(theta0=NEAR),
    "pi-recursive": lambda: PIRecursiveIdentifier(PI_THRESHOLDS, warmup=200),
    "pi-stage-online": lambda: PIStageOnline(PI_THRESHOLDS, warmup=200, window=200, every=100,
                                             fs=30_000.0),
    "pi-poly-online": lambda: PIStageOnline(PI_THRESHOLDS, POLY_STAGE, warmup=200, window=200,
                                            every=100, fs=30_000.0),
}


@pytest.fixture(scope="module")
def record() -> Record:
    u = paper_excitation(0.02, seed=3)  # 600 samples
    y = paper_stage().simulate(u)["y"] + 1e-3 * np.random.default_rng(3).standard_normal(len(u))
    return Record(u, y, 30_000.0, name="stage")


def quiet(fn, *args, **kwargs):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        return fn(*args, **kwargs)


@pytest.mark.parametrize("name", ESTIMATORS)
def test_estimator_keeps_the_contract(name, record):
    make = ESTIMATORS[name]
    est = make()
    assert isinstance(est, Estimator)
    n_par = len(est.names)

    # settings: one property, JSON-ready, the stop index among them
    settings = est.settings
    assert "epsilon" in settings and json.loads(json.dumps(settings)) == settings

    # fit restarts: twice on the same record, the same estimate
    first = quiet(est.fit, record)
    again = quiet(est.fit, record)
    np.testing.assert_array_equal(first.model.theta, again.model.theta)
    assert first.history.shape == (record.n, n_par)

    # update returns theta(k), a copy, and equals the fit sample by sample
    est = make()
    steps = np.array([quiet(est.update, u, y) for u, y in zip(record.u, record.y, strict=True)])
    np.testing.assert_allclose(steps, first.history, rtol=1e-10, atol=1e-13)
    theta = quiet(est.update, 5.0, 1.0)
    assert theta.shape == (n_par,)
    theta[:] = 0.0
    assert not np.allclose(est.theta, 0.0)

    # partial_fit continues: two halves give the fit over the whole record
    est = make()
    quiet(est.fit, record[:450])
    rest = quiet(est.partial_fit, record[450:])
    np.testing.assert_allclose(rest.model.theta, first.model.theta, rtol=1e-10, atol=1e-13)

    # non-finite samples: an output is skipped, an input refused
    before = est.n_skipped
    theta = quiet(est.update, 5.0, np.nan)
    assert est.n_skipped == before + 1 and np.all(np.isfinite(theta))
    with pytest.raises(ValueError, match="u_k"):
        est.update(np.inf, 1.0)
    y = record.y.copy()
    y[[500, 510]] = np.nan
    with pytest.warns(RuntimeWarning, match="2 non-finite output samples skipped"):
        make().fit(SimpleNamespace(u=record.u, y=y, fs=record.fs, name="gappy"))
    u = record.u.copy()
    u[7] = np.nan
    with pytest.raises(ValueError, match="sample 7"):
        make().fit(SimpleNamespace(u=u, y=record.y, fs=record.fs, name="bad input"))

    # records: a wrong type or rate is named
    with pytest.raises(TypeError, match="record"):
        make().fit((record.u, record.y))
    with pytest.raises(ValueError, match="fs"):
        make().fit(Record(record.u, record.y, fs=10_000.0))


def _same(a, b) -> bool:
    if isinstance(a, dict) and isinstance(b, dict):
        return a.keys() == b.keys() and all(_same(a[k], b[k]) for k in a)
    if isinstance(a, np.ndarray) or isinstance(b, np.ndarray):
        return np.array_equal(np.asarray(a), np.asarray(b))
    if isinstance(a, list | tuple) and isinstance(b, list | tuple):
        return len(a) == len(b) and all(_same(x, y) for x, y in zip(a, b, strict=True))
    return a == b


@pytest.mark.parametrize("name", ESTIMATORS)
def test_get_params_rebuilds_an_equal_estimator(name, record):
    """scikit-learn's round trip: the parameters come from the constructor's signature, and an
    estimator built from them has the same parameters, settings and result."""
    import inspect

    est = ESTIMATORS[name]()
    params = est.get_params()
    expected = [p for p in inspect.signature(type(est).__init__).parameters if p != "self"]
    assert list(params) == expected
    twin = type(est)(**params)
    assert _same(twin.get_params(), params)
    assert twin.settings == est.settings
    np.testing.assert_array_equal(quiet(twin.fit, record).model.theta,
                                  quiet(est.fit, record).model.theta)
    first = next(iter(params))
    with pytest.raises(ValueError, match="unknown parameter"):
        est.set_params(not_a_setting=1)
    assert est.set_params(**{first: params[first]}) is est


@pytest.mark.parametrize("name", ESTIMATORS)
def test_fit_is_written_once_in_the_base(name):
    """``fit`` is the base's (restart, then ``partial_fit``); an estimator adapts its restart
    (``_restart``), never the whole-record run itself."""
    from hystid.identify.base import Estimator

    cls = type(ESTIMATORS[name]())
    owners = [k.__name__ for k in cls.__mro__ if "fit" in vars(k)]
    assert owners == ["Estimator"], owners
    assert cls.fit is Estimator.fit
