"""The state the exported on-line identifier starts from: the recursion warm-started at a model.

:class:`~hystid.identify.online.OnlineIdentifier` starts with a batch solve on its first
samples and sets ``P`` to the inverse Gauss-Newton information of that solution. The exported
step starts at a saved model instead, and :func:`rpem_start` builds that start the same way:
``P`` is the inverse information of the model's output sensitivities (and the offset's) on a
record, and the residual scale the RMS of the model's error there. Without a record the
information is taken on the paper's excitation scaled into the model's input envelope (the
model's own output: no residual, so the scale is a thousandth of the output span).

The supervisor (:mod:`hystid.identify.online_supervisor`) starts as it does after the
identifier's start-up solve: the warm start is the first validated estimate, the recursion
settles from it for ``n_start`` samples, and the residual floor is ``1e-9`` of the output's
standard deviation on the starting information's samples. :func:`rpem_reference` runs the
identifier so started, supervised or bare, as the exported step does.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from ..model import DuhemSandwich

if TYPE_CHECKING:  # pragma: no cover
    from ..identify.online import OnlineIdentifier
    from ..records import Record

__all__ = ["INFORMATION_SAMPLES", "rpem_reference", "rpem_start", "warm_information"]

#: Samples of a record (or of the synthetic input) the starting information is taken on.
INFORMATION_SAMPLES = 2_000


def warm_information(
    model: DuhemSandwich, u: np.ndarray, y: np.ndarray | None = None
) -> tuple[np.ndarray, float | None]:
    """Inverse Gauss-Newton information of a model on a record, as the on-line start sets it.

    Parameters
    ----------
    model : DuhemSandwich
        The model; simulated from its rest on ``u``.
    u : ndarray
        Input samples (record units).
    y : ndarray, optional
        Measured output (record units); non-finite samples are left out.

    Returns
    -------
    P : ndarray
        ``pinv(J^T J + 1e-9 trace/n I)`` with ``J`` the output sensitivities to the parameters
        and (last column, ones) the offset.
    sigma : float or None
        RMS of ``y`` less the model's output (None without ``y``).
    """
    from ..kernels import sensitivities_into

    s = model.structure
    u = np.asarray(u, dtype=float)
    n, npar, h = len(u), len(model.theta), s.history
    rest = model.at_rest()
    U, W1, W2, Y = (np.concatenate([rest.window(k, h), np.zeros(n)])
                    for k in ("u", "w1", "w2", "y"))
    U[h:] = u - model.u_rest
    S1, S2, SY = (np.zeros((h + n, npar)) for _ in range(3))
    with np.errstate(all="ignore"):
        sensitivities_into(model.theta, s.layout, U, W1, W2, Y, S1, S2, SY, h)
    ok = np.all(np.isfinite(SY[h:]), axis=1) & np.isfinite(Y[h:])
    sigma = None
    if y is not None:
        y = np.asarray(y, dtype=float)
        ok &= np.isfinite(y)
        r = (y - Y[h:] - model.offset)[ok]
        sigma = max(float(np.sqrt(np.mean(r**2))), 1e-12) if len(r) else None
    J = np.column_stack([SY[h:][ok], np.ones(int(ok.sum()))])
    info = J.T @ J
    P = np.linalg.pinv(info + 1e-9 * np.trace(info) / len(info) * np.eye(len(info)))
    return P, sigma


def _synthetic_input(model: DuhemSandwich, n: int) -> np.ndarray | None:
    from ..reference import paper_excitation

    env = model.envelope
    if env is None or not env.u_max > model.u_rest:
        return None
    e = paper_excitation(n, model.fs, seed=0)
    return model.u_rest + e * (env.u_max - model.u_rest) / float(np.max(e))


def _default_sigma(model: DuhemSandwich) -> float:
    env = model.envelope
    if env is None:
        return 1e-3
    gain = model.params["f1"] * (1.0 + np.sum(model.b1)) / (1.0 + np.sum(model.a1)) \
        * model._l2_gain()
    value = 1e-3 * abs(gain) * (env.u_max - env.u_min)
    return float(value) if np.isfinite(value) and value > 0 else 1e-3


def _largest_dw1(model: DuhemSandwich, record: Record | None, ident: OnlineIdentifier) -> float:
    """The largest ``|dw1|`` the model makes on the starting information's input (the
    record's first samples, else the paper's excitation in the envelope): where the
    recursion's condition (8) cap starts (0: set by the first samples it sees)."""
    u = (record.u[:INFORMATION_SAMPLES] if record is not None
         else _synthetic_input(model, INFORMATION_SAMPLES))
    if u is None or len(u) < 2:
        return 0.0
    w1 = model.simulate(u, check=False).w1
    value = float(np.max(np.abs(np.diff(w1))))
    return value if np.isfinite(value) else 0.0


def _output_spread(model: DuhemSandwich, record: Record | None) -> float:
    """Standard deviation of the output on the starting information's samples (the record's,
    else the model's own on the paper's excitation in its envelope; 0 without either)."""
    if record is not None:
        y = np.asarray(record.y[:INFORMATION_SAMPLES], dtype=float)
        y = y[np.isfinite(y)]
    else:
        u = _synthetic_input(model, INFORMATION_SAMPLES)
        y = np.zeros(0) if u is None else model.simulate(u, check=False).y
        y = y[np.isfinite(y)]
    return float(np.std(y)) if len(y) else 0.0


#: A record whose input span is this many times the model's identified span (or less than
#: its inverse), or that lies that many spans away, is in other units or of another stage.
SPAN_RATIO = 10.0


def _check_record_like(model: DuhemSandwich, record: Record) -> None:
    """Refuse a record in other units than the model's, at another scale, or with an input
    that does not move (``hystid export --rpem-record`` took one whose header said nm for a
    model in um, which set the residual floor 1 000x too high)."""
    for key in ("u", "y"):
        mine, theirs = (model.units or {}).get(key), (record.units or {}).get(key)
        if mine and theirs and mine != theirs:
            raise ValueError(f"record {record.name!r}: {key} in {theirs}, the model in {mine} "
                             "(expected a record of the model's stage in the model's units)")
    u = record.u[np.isfinite(record.u)]
    span = float(np.ptp(u)) if u.size else 0.0
    if span == 0.0:
        raise ValueError(f"record {record.name!r}: its input does not move (expected a record "
                         "that excites the stage)")
    env = getattr(model, "envelope", None)
    if env is None or env.u_max <= env.u_min:
        return
    known = env.u_max - env.u_min
    centre = 0.5 * (env.u_max + env.u_min)
    far = abs(float(np.median(u)) - centre) > SPAN_RATIO * known
    if not (1.0 / SPAN_RATIO <= span / known <= SPAN_RATIO) or far:
        raise ValueError(f"record {record.name!r}: its input spans {float(u.min()):.4g} .. "
                         f"{float(u.max()):.4g}, the model was identified on {env.u_min:.4g} .. "
                         f"{env.u_max:.4g} (expected a record of the model's stage, in its "
                         "units)")


def rpem_start(
    model: DuhemSandwich, record: Record | None = None, sigma: float | None = None,
    supervise: bool = True,
) -> OnlineIdentifier:
    """The on-line identifier warm-started from a model: the state ``hystid_rpem_init`` sets.

    The recursion (:func:`hystid.identify.online.rpem_run`) starts at the model's parameters
    and sensor offset, its signal windows at the model's rest, ``P`` from
    :func:`warm_information` (on the first :data:`INFORMATION_SAMPLES` samples of ``record``,
    or of the paper's excitation scaled into the model's envelope; without either, the
    identifier's covariance reset ``min(1, trace_max / (npar + 1)) I``) and the other settings
    :class:`~hystid.identify.online.OnlineIdentifier`'s defaults. Its input is
    ``u - model.u_rest``.

    Parameters
    ----------
    model : DuhemSandwich
        The model to start from.
    record : Record, optional
        A record of the stage for the starting information and residual scale, of at least
        the identifier's ``n_start`` samples.
    sigma : float, optional
        Initial residual scale (output units; step 2 clips at ``clip`` times it); by default
        the model's RMS error on ``record``, else a thousandth of the output span the model's
        static line gives over its input envelope (``1e-3`` without an envelope).
    supervise : bool
        With the supervisor (as ``OnlineIdentifier`` by default), started as after the
        start-up solve: the warm start is the validated estimate, the recursion settles for
        ``n_start`` samples, the residual floor is ``1e-9`` of the output's standard deviation
        on the starting information's samples.

    Returns
    -------
    OnlineIdentifier
        Running (its start-up solve skipped), ready for :func:`rpem_reference` (or, bare,
        ``rpem_run(ident._buf, ident._ints, u - u_rest, y, ...)``, the compiled recursion
        taking the input relative to the rest).
    """
    from ..identify import online_kernels as on
    from ..identify.online import OnlineIdentifier

    if not isinstance(model, DuhemSandwich):
        raise ValueError("the on-line identifier (RPEM) is exported for Duhem models only")
    ident = OnlineIdentifier(model.structure, model.fs, supervise=supervise)
    npar = len(model.theta)
    if record is not None:
        if not np.isclose(float(record.fs), model.fs, rtol=1e-9):
            raise ValueError(f"record: sampled at {float(record.fs):g} Hz, the model at "
                             f"{model.fs:g} Hz")
        if record.n < ident.n_start:
            raise ValueError(f"record {record.name!r}: {record.n} samples are too few for the "
                             f"identifier's starting covariance (expected at least "
                             f"{ident.n_start}, the samples its own start-up solve takes; "
                             f"{INFORMATION_SAMPLES} are used)")
        _check_record_like(model, record)
        m = INFORMATION_SAMPLES
        P, measured = warm_information(model, record.u[:m], record.y[:m])
    else:
        u = _synthetic_input(model, INFORMATION_SAMPLES)
        P, measured = (warm_information(model, u) if u is not None else (None, None))
    if P is None or not np.all(np.isfinite(P)):
        preset = ident._sett[on._S_PRESET]
        P = np.diag([preset] * npar + [preset * ident._sett[on._S_TRACK]])
    if sigma is None:
        sigma = measured if measured is not None else _default_sigma(model)
    if not (np.isfinite(sigma) and 1e-150 < sigma < 1e150):  # its square is kept too
        raise ValueError(f"sigma: expected a positive residual scale within 1e-150..1e150 "
                         f"(output units), got {sigma!r}")
    ident._est[:npar] = model.theta
    ident._est[npar] = model.offset
    ident.P[:] = P
    ident._est_good[:] = ident._est
    ident._P_good[:] = ident.P
    ident._scal[on._SIG] = sigma
    ident._scal[on._SHORT] = ident._scal[on._LONG] = sigma**2
    ident._scal[on._DW1MAX] = _largest_dw1(model, record, ident)
    w = ident.window
    rest = model.at_rest()
    U, W1, W2, Yh, Ym = ident._windows[:5]
    U[:w] = 0.0
    W1[:w] = 0.0
    W2[:w] = rest.window("w2", 1)[0]
    Yh[:w] = Ym[:w] = rest.window("y", 1)[0]
    ident._ints[on._I_POS] = w
    ident._running = True
    ident._verify_at = None
    ident.u_rest_ = model.u_rest
    if ident._supervisor is not None:  # the warm start is the first validated estimate
        ident._supervisor.floor = 1e-9 * max(_output_spread(model, record), 1e-300)
        ident._supervisor.reset(ident, ident.n_start)
    return ident


def rpem_reference(ident: OnlineIdentifier, u: np.ndarray, y: np.ndarray) -> np.ndarray:
    """The exported ``hystid_rpem_step`` in Python: the identifier from :func:`rpem_start`
    over samples, its supervisor (when it has one) included.

    Parameters
    ----------
    ident : OnlineIdentifier
        From :func:`rpem_start`; advanced in place (``ident.k`` counts the samples).
    u, y : ndarray
        Recorded input and measured output (record units; a non-finite ``y`` is skipped).

    Returns
    -------
    ndarray
        ``(n, npar)``: the estimate after each sample (after a rollback where one happened),
        as ``hystid_rpem_theta`` gives it.
    """
    u = np.ascontiguousarray(u, dtype=float)  # the identifier takes off u_rest_ itself
    y = np.ascontiguousarray(y, dtype=float)
    history = np.empty((len(u), len(ident.theta)))
    ident._process(u, y, history, np.empty((len(u), ident.n_diagnostics)))
    return history
