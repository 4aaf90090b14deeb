"""The Prandtl-Ishlinskii operator (eq. 30): the play operator, compiled, its exact inverse and
both as discrete python-control blocks. The sandwich around it is :mod:`hystid.pi`.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from functools import lru_cache

import control as ct
import numpy as np
from numba import njit

from .signals import finite_signal


# =========================================================================== thresholds
def _check_thresholds(r, name: str = "thresholds") -> np.ndarray:
    r = np.ascontiguousarray(np.asarray(r, dtype=float).ravel())
    if r.size == 0 or not np.all(np.isfinite(r)) or np.any(r < 0):
        raise ValueError(f"{name}: expected finite non-negative thresholds, got {r!r}")
    return r


# =========================================================================== compiled kernels
@njit(cache=True, inline="always")
def play(v, p_prev, r):
    """One step of the play operator, eq. (30): ``p(k) = max{v(k) - r, min[v(k) + r, p(k-1)]}``.

    The one play operator of hystid (the PI block, its inverse, the PI identifier and the
    compensator call it, compiled or not).

    Parameters
    ----------
    v : float
        Input ``v(k)``.
    p_prev : float
        Operator state ``p(k-1)``.
    r : float
        Threshold ``r >= 0``.

    Returns
    -------
    float
        The state and output ``p(k)``.
    """
    return max(v - r, min(v + r, p_prev))


@njit(cache=True, inline="always")
def poly_terms(w, c):
    """The memoryless polynomial beside the plays, ``sum_j c[j] w^(j+2)``, and its slope.

    The one writing of it (the PI sandwich's simulation, its sensitivities and its inverse
    call it).

    Parameters
    ----------
    w : float
        Input ``w1(k)`` from the rest.
    c : ndarray
        Coefficients of ``w^2, w^3, ..`` (empty: none).

    Returns
    -------
    value, slope : float
        The polynomial and its derivative in ``w``.
    """
    value = 0.0
    slope = 0.0
    power = w  # w^(j+1)
    for j in range(c.shape[0]):
        slope += (j + 2) * c[j] * power
        power *= w
        value += c[j] * power
    return value, slope


@njit(cache=True, nogil=True)
def _pi_operator_into(v, r, mu, p, out):
    for k in range(v.shape[0]):
        acc = 0.0
        for i in range(r.shape[0]):
            p[i] = play(v[k], p[i], r[i])
            acc += mu[i] * p[i]
        out[k] = acc


@njit(cache=True, nogil=True)
def _play_operator_into(v, r, p, out):
    for k in range(v.shape[0]):
        for i in range(r.shape[0]):
            p[i] = play(v[k], p[i], r[i])
            out[k, i] = p[i]


@njit(cache=True, nogil=True)
def pi_simulate_into(a1, b1, q1, mu, c, r, a2, b2, q2, U, W1, W2, Y, p, start):
    """Eqs. (29)-(31) from index ``start`` to the end of the extended arrays.

    ``U, W1, W2, Y`` hold the past in their first ``start`` entries (most recent last);
    ``b1[j]`` multiplies ``u(k - q1 - j)`` and ``b2[j]`` multiplies ``w2(k - q2 - j)``;
    ``p`` holds the play-operator states ``p_i(k-1)`` and is updated in place; ``c`` the
    coefficients of the polynomial terms beside the plays (:func:`poly_terms`; empty: none).
    """
    for k in range(start, U.shape[0]):
        # eq. (29)
        w1 = 0.0
        for j in range(b1.shape[0]):
            w1 += b1[j] * U[k - q1 - j]
        for i in range(a1.shape[0]):
            w1 -= a1[i] * W1[k - 1 - i]
        W1[k] = w1
        # eq. (30)
        w2 = 0.0
        for i in range(r.shape[0]):
            p[i] = play(w1, p[i], r[i])
            w2 += mu[i] * p[i]
        W2[k] = w2 + poly_terms(w1, c)[0]
        # eq. (31)
        y = 0.0
        for j in range(b2.shape[0]):
            y += b2[j] * W2[k - q2 - j]
        for i in range(a2.shape[0]):
            y -= a2[i] * Y[k - 1 - i]
        Y[k] = y


def play_operator(
    v: np.ndarray | Sequence[float],
    thresholds: np.ndarray | Sequence[float],
    p0: np.ndarray | Sequence[float] | None = None,
) -> np.ndarray:
    """Outputs of the play operators (eq. 30) on a signal.

    Parameters
    ----------
    v : array_like
        Input samples.
    thresholds : array_like
        ``N`` non-negative thresholds.
    p0 : array_like, optional
        States ``p_i(-1)``; zero (the virgin state) by default.

    Returns
    -------
    ndarray
        Shape ``(len(v), N)``: ``p_i(k)``.
    """
    v = finite_signal(v, "v")
    r = _check_thresholds(thresholds)
    p = _initial_states(p0, len(r))
    out = np.empty((len(v), len(r)))
    _play_operator_into(v, r, p, out)
    return out


def rest_plays(swing: float, thresholds: np.ndarray) -> np.ndarray:
    """The plays' states at rest after one excursion from the rest to ``swing`` and back
    (from the virgin state).

    Parameters
    ----------
    swing : float
        The excursion from the rest, in the plays' input units (signed).
    thresholds : ndarray
        The plays' thresholds.

    Returns
    -------
    ndarray
        ``sign(swing) min(max(|swing| - r_i, 0), r_i)``.
    """
    r = np.asarray(thresholds, dtype=float)
    return np.sign(swing) * np.clip(abs(swing) - r, 0.0, r)


def pi_operator(
    v: np.ndarray | Sequence[float],
    thresholds: np.ndarray | Sequence[float],
    weights: np.ndarray | Sequence[float],
    p0: np.ndarray | Sequence[float] | None = None,
) -> np.ndarray:
    """The PI operator ``sum_i mu_i p_i(k)`` (eq. 30) on a signal, compiled.

    Parameters
    ----------
    v : array_like
        Input samples.
    thresholds, weights : array_like
        ``r_i`` and ``mu_i``, same length ``N``.
    p0 : array_like, optional
        States ``p_i(-1)``; zero by default.

    Returns
    -------
    ndarray
        Output samples, same length as ``v``.
    """
    v = finite_signal(v, "v")
    r = _check_thresholds(thresholds)
    mu = _weights(weights, len(r))
    p = _initial_states(p0, len(r))
    out = np.empty(len(v))
    _pi_operator_into(v, r, mu, p, out)
    return out


# =========================================================================== inverse
def pi_inverse_parameters(
    thresholds: np.ndarray | Sequence[float], weights: np.ndarray | Sequence[float]
) -> tuple[np.ndarray, np.ndarray]:
    """Thresholds and weights of the exact inverse PI operator.

    The forward operator's initial loading curve is piecewise linear with corners at ``r_j``
    and slopes ``W_j = mu_0 + ... + mu_j``; the inverse is the PI operator whose loading curve
    is its inverse function::

        r'_j  = sum_{i<=j} mu_i (r_j - r_i)
        mu'_0 = 1 / mu_0,   mu'_j = -mu_j / (W_j W_{j-1})

    Parameters
    ----------
    thresholds : array_like
        ``0 = r_0 < r_1 < ... < r_{N-1}``.
    weights : array_like
        ``mu_i`` with ``mu_0 > 0`` and every partial sum ``W_j > 0`` (the loading curve is
        increasing, so the operator is invertible).

    Returns
    -------
    r_inv, mu_inv : ndarray
        Thresholds and weights of the inverse operator.
    """
    r = _check_thresholds(thresholds)
    mu = _weights(weights, len(r))
    if r[0] != 0.0 or np.any(np.diff(r) <= 0):
        raise ValueError("thresholds: the inverse needs 0 = r_0 < r_1 < ... (strictly increasing)")
    W = np.cumsum(mu)
    if not mu[0] > 0:
        raise ValueError(f"weights: the inverse needs a positive first weight, got {mu[0]:g}")
    if np.any(W <= 0):
        j = int(np.flatnonzero(W <= 0)[0])
        raise ValueError(
            f"weights: the partial sum mu_0 + ... + mu_{j} = {W[j]:g} is not positive; "
            "the loading curve must be increasing for the inverse to exist"
        )
    r_inv = np.array([np.dot(mu[: j + 1], r[j] - r[: j + 1]) for j in range(len(r))])
    mu_inv = np.empty_like(mu)
    mu_inv[0] = 1.0 / mu[0]
    mu_inv[1:] = -mu[1:] / (W[1:] * W[:-1])
    return r_inv, mu_inv


def pi_inverse_state(weights: np.ndarray | Sequence[float], p: np.ndarray) -> np.ndarray:
    """States of the inverse operator matching forward states ``p`` (both continue as inverses).

    ``p'_j = (mu_0 + ... + mu_j) p_j + sum_{i>j} mu_i p_i``.

    Parameters
    ----------
    weights : array_like
        Forward weights ``mu_0 .. mu_{N-1}``.
    p : ndarray
        Forward play-operator states.

    Returns
    -------
    ndarray
        States ``p'`` of the inverse operator.
    """
    mu = np.asarray(weights, dtype=float).ravel()
    p = np.asarray(p, dtype=float).ravel()
    if p.shape != mu.shape:
        raise ValueError(f"p: expected {len(mu)} operator states, got shape {p.shape}")
    tail = np.concatenate([np.cumsum((mu * p)[::-1])[::-1][1:], [0.0]])
    return np.cumsum(mu) * p + tail


# =========================================================================== python-control
@lru_cache(maxsize=64)
def _keys(prefix: str, n: int) -> tuple[tuple[str, ...], tuple[str, ...]]:
    return (tuple(f"{prefix}_mu{i}" for i in range(n)), tuple(f"{prefix}_r{i}" for i in range(n)))


def _unpack(params: Mapping, prefix: str, n: int) -> tuple[np.ndarray, np.ndarray]:
    kmu, kr = _keys(prefix, n)
    return (np.fromiter((params[k] for k in kmu), float, n),
            np.fromiter((params[k] for k in kr), float, n))


def poly_keys(prefix: str, params: Mapping) -> tuple[str, ...]:
    """The parameter names ``<prefix>_c2, <prefix>_c3, ..`` of a PI block's polynomial terms
    present in ``params`` (consecutive from ``c2``).

    Parameters
    ----------
    prefix : str
        The block's parameter prefix.
    params : mapping
        Its parameters (or an interconnected system's flat ones).

    Returns
    -------
    tuple of str
    """
    keys: list[str] = []
    while f"{prefix}_c{len(keys) + 2}" in params:
        keys.append(f"{prefix}_c{len(keys) + 2}")
    return tuple(keys)


def _make_pi_functions(prefix: str):
    def update(t, x, u, params):
        _, r = _unpack(params, prefix, len(x))
        return np.maximum(u[0] - r, np.minimum(u[0] + r, x))

    def output(t, x, u, params):
        mu, r = _unpack(params, prefix, len(x))
        c = np.array([params[k] for k in poly_keys(prefix, params)], dtype=float)
        w = float(u[0])
        return np.array([mu @ np.maximum(w - r, np.minimum(w + r, x))
                         + poly_terms(w, c)[0]])

    return update, output


def pi_block(
    thresholds: np.ndarray | Sequence[float],
    weights: np.ndarray | Sequence[float],
    *,
    dt: float,
    inputs: str = "w1",
    outputs: str = "w2",
    prefix: str = "pi",
    name: str = "H",
    poly: np.ndarray | Sequence[float] = (),
) -> ct.NonlinearIOSystem:
    """The PI hysteresis operator (eq. 30) as a discrete python-control system.

    Parameters
    ----------
    thresholds, weights : array_like
        ``r_i`` and ``mu_i``, same length ``N``.
    poly : array_like
        Coefficients ``c_2, c_3, ..`` of memoryless terms ``c_j w1^j`` added to the plays'
        sum (:func:`poly_terms`; parameters ``<prefix>_c2 ..``); none by default.
    dt : float
        Sampling period in seconds.
    inputs, outputs, name : str
        Signal and system names.
    prefix : str
        Prefix of the flat parameter names ``<prefix>_mu0 ..`` and ``<prefix>_r0 ..`` (an
        interconnected system has one flat parameter dict over all its blocks).

    Returns
    -------
    control.NonlinearIOSystem
        States ``p0 .. p{N-1}`` (the play operators' ``p_i(k-1)``); direct feed-through from
        ``w1(k)`` to ``w2(k)``; pure update and output functions.
    """
    r = _check_thresholds(thresholds)
    mu = _weights(weights, len(r))
    kmu, kr = _keys(prefix, len(r))
    c = np.asarray(poly, dtype=float).ravel()
    if not np.all(np.isfinite(c)):
        raise ValueError(f"poly: expected finite coefficients, got {c!r}")
    params = {**dict(zip(kmu, map(float, mu), strict=True)),
              **dict(zip(kr, map(float, r), strict=True)),
              **{f"{prefix}_c{j + 2}": float(v) for j, v in enumerate(c)}}
    update, output = _make_pi_functions(prefix)
    return ct.nlsys(
        update, output, inputs=[inputs], outputs=[outputs],
        states=[f"p{i}" for i in range(len(r))], params=params, dt=dt, name=name,
    )


def pi_inverse_block(
    thresholds: np.ndarray | Sequence[float],
    weights: np.ndarray | Sequence[float],
    *,
    dt: float,
    inputs: str = "w2",
    outputs: str = "w1",
    prefix: str = "piinv",
    name: str = "H_inv",
) -> ct.NonlinearIOSystem:
    """The exact inverse PI operator (for compensation) as a discrete python-control system.

    Takes the *forward* thresholds and weights (see :func:`pi_inverse_parameters` for the
    conditions) and returns a :func:`pi_block` with the inverse thresholds and weights, states
    ``p0 .. p{N-1}``. Use :func:`pi_inverse_state` to start it from a non-virgin state.

    Parameters
    ----------
    thresholds, weights : array_like
        Forward thresholds ``r_i`` and weights ``mu_i``.
    dt : float
        Sampling period in seconds.
    inputs, outputs : str
        Signal names (``w2`` in, ``w1`` out by default).
    prefix : str
        Prefix of the parameter names.
    name : str
        System name.

    Returns
    -------
    control.NonlinearIOSystem
        The inverse operator ``w2 -> w1``.
    """
    r_inv, mu_inv = pi_inverse_parameters(thresholds, weights)
    return pi_block(r_inv, mu_inv, dt=dt, inputs=inputs, outputs=outputs, prefix=prefix, name=name)


# =========================================================================== helpers
def _weights(weights, n: int) -> np.ndarray:
    mu = np.ascontiguousarray(np.asarray(weights, dtype=float).ravel())
    if mu.shape != (n,) or not np.all(np.isfinite(mu)):
        raise ValueError(f"weights: expected {n} finite values, got {mu!r}")
    return mu


def _initial_states(p0, n: int) -> np.ndarray:
    if p0 is None:
        return np.zeros(n)
    try:
        p = np.array(p0, dtype=float).ravel()
    except (TypeError, ValueError, OverflowError) as err:
        raise ValueError(f"p0: expected {n} finite operator states, got {p0!r:.60} ({err})") \
            from err
    if p.shape != (n,) or not np.all(np.isfinite(p)):
        raise ValueError(f"p0: expected {n} finite operator states, got shape {p.shape}")
    return p


def admissible_weights(mu: np.ndarray, floor: float = 1e-3) -> np.ndarray:
    """Weights with a positive loading slope: every cumulative sum at least ``floor`` times the
    largest one (those below are raised to it, the others kept).

    Parameters
    ----------
    mu : ndarray
        Weights ``mu_0 .. mu_N-1`` of the play operators, thresholds increasing.
    floor : float
        Smallest cumulative sum kept, relative to the largest.

    Returns
    -------
    ndarray
        The weights, unchanged when already admissible.
    """
    mu = np.asarray(mu, dtype=float)
    c = np.cumsum(mu)
    low = floor * max(float(np.max(c)), float(np.sum(np.abs(mu))), 1e-300)
    if np.all(c >= low):
        return mu.copy()
    return np.diff(np.r_[0.0, np.maximum(c, low)])
