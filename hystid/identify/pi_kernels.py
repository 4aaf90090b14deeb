"""Compiled kernels of the PI sandwich's identification: eqs. (29)-(31) with their forward
sensitivities, and the steps of the extended recursion (eqs. 15-19) in both regressor forms.

Used by :class:`~hystid.identify.pi_recursive.PIRecursiveIdentifier` (on-line) and
:func:`~hystid.identify.pi_batch.fit_pi_output_error` (off-line).
"""

from __future__ import annotations

import numpy as np
from numba import njit

from ..kernels import filter_output, l2_output_sens
from ..model import InitialCondition
from ..pi import PISandwich, PIStructure
from ..pi_operator import play, poly_terms
from ..poly import KMAX_STABLE, schur_stable

__all__ = [
    "free_gradient",
    "full_coefficients",
    "pi_output_sensitivities",
    "pi_sens_range",
    "pi_sensitivities_into",
    "pi_step_sens",
    "recursion_one",
    "recursion_run",
]



# =========================================================================== compiled kernels
@njit(cache=True, inline="always")
def _l1_step(c, n1a, n1b, q1, U, W1, S1, k):
    # eq. (29) at index k and d w1 / d (a1, b1) with c = [a1 (n1a), b1 (n1b), ...]; returns w1
    w1 = filter_output(c, n1a, n1b, 0, n1a, q1, U, W1, k)
    W1[k] = w1
    for m in range(n1a + n1b):
        s = 0.0
        for i in range(n1a):
            s -= c[i] * S1[k - 1 - i, m]
        S1[k, m] = s
    for i in range(n1a):
        S1[k, i] -= W1[k - 1 - i]
    for j in range(n1b):
        S1[k, n1a + j] += U[k - q1 - j]
    return w1


@njit(cache=True, inline="always")
def _operators_step(w1, r, p, SP, S1, k, n1):
    # eq. (30) for every operator with d p_i / d c1: an operator that moves follows w1
    # (dp/dw1 = 1), one that holds keeps its state and its sensitivity
    for i in range(r.shape[0]):
        q = play(w1, p[i], r[i])
        if q != p[i]:
            p[i] = q
            for m in range(n1):
                SP[i, m] = S1[k, m]


@njit(cache=True, nogil=True)
def _layout_offsets(layout):
    # layout = [n1a, n1b, N, n2a, n2b, q1, q2, n_poly]; full coefficient vector
    # c = [a1 (n1a), b1 (n1b), mu (N), c (n_poly), a2 (n2a), b2 (n2b)]
    n1a, n1b, n, n2a = layout[0], layout[1], layout[2] + layout[7], layout[3]
    return 0, n1a, n1a + n1b, n1a + n1b + n, n1a + n1b + n + n2a


@njit(cache=True, nogil=True)
def full_coefficients(theta, layout, c):
    """Full coefficients ``c`` from the free ``theta`` (unit DC gains: b11, b21 derived)."""
    n1a, n1b, n, n2a, n2b = layout[0], layout[1], layout[2], layout[3], layout[4]
    ia1, ib1, imu, ia2, ib2 = _layout_offsets(layout)
    t = 0
    for blk in range(2):
        na = n1a if blk == 0 else n2a
        nb = n1b if blk == 0 else n2b
        ia = ia1 if blk == 0 else ia2
        ib = ib1 if blk == 0 else ib2
        gain = 1.0
        for i in range(na):
            c[ia + i] = theta[t]
            gain += theta[t]
            t += 1
        for j in range(1, nb):
            c[ib + j] = theta[t]
            gain -= theta[t]
            t += 1
        c[ib] = gain
        if blk == 0:
            for i in range(n + layout[7]):  # the weights, then the polynomial terms'
                c[imu + i] = theta[t]
                t += 1


@njit(cache=True, nogil=True)
def free_gradient(psi_c, layout, psi):
    """Chain rule ``d/dtheta = T' d/dc`` for the unit-DC-gain parametrisation."""
    n1a, n1b, n, n2a, n2b = layout[0], layout[1], layout[2], layout[3], layout[4]
    ia1, ib1, imu, ia2, ib2 = _layout_offsets(layout)
    t = 0
    for blk in range(2):
        na = n1a if blk == 0 else n2a
        nb = n1b if blk == 0 else n2b
        ia = ia1 if blk == 0 else ia2
        ib = ib1 if blk == 0 else ib2
        for i in range(na):
            psi[t] = psi_c[ia + i] + psi_c[ib]
            t += 1
        for j in range(1, nb):
            psi[t] = psi_c[ib + j] - psi_c[ib]
            t += 1
        if blk == 0:
            for i in range(n + layout[7]):
                psi[t] = psi_c[imu + i]
                t += 1


@njit(cache=True, nogil=True)
def pi_step_sens(c, layout, r, U, W1, W2, Y, S1, SW2, SY, p, SP, k):
    """Eqs. (29)-(31) at index ``k`` with the sensitivities to the full coefficients ``c``.

    ``U, W1, W2, Y`` are extended signal arrays, ``S1, SW2, SY`` the matching sensitivity rows
    (``d w1 / d c`` etc.); ``p`` and ``SP`` (``d p_i / d c``) hold the operator states at
    ``k-1`` and are updated in place.
    """
    pi_sens_range(c, layout, r, U, W1, W2, Y, S1, SW2, SY, p, SP, k, k + 1)


@njit(cache=True, nogil=True)
def pi_sens_range(c, layout, r, U, W1, W2, Y, S1, SW2, SY, p, SP, start, stop):
    """:func:`pi_step_sens` for every index ``start <= k < stop``: the one writing of the
    recursion, with what it reads of ``layout`` read once before the loop."""
    n1a, n1b, n, n2a, n2b, q1, q2 = (layout[0], layout[1], layout[2], layout[3], layout[4],
                                     layout[5], layout[6])
    ia1, ib1, imu, ia2, ib2 = _layout_offsets(layout)
    nc = c.shape[0]
    n1 = n1a + n1b
    npoly, ic = layout[7], imu + n
    for k in range(start, stop):
        w1 = _l1_step(c, n1a, n1b, q1, U, W1, S1, k)       # eq. (29)
        _operators_step(w1, r, p, SP, S1, k, n1)            # eq. (30)
        w2 = 0.0
        for m in range(nc):
            SW2[k, m] = 0.0
        for i in range(n):
            w2 += c[imu + i] * p[i]
            SW2[k, imu + i] = p[i]
            for m in range(n1):
                SW2[k, m] += c[imu + i] * SP[i, m]
        if npoly:  # the polynomial terms beside the plays, c_j w1^j
            value, slope = poly_terms(w1, c[ic:ic + npoly])
            w2 += value
            power = w1
            for j in range(npoly):
                power *= w1
                SW2[k, ic + j] = power
            for m in range(n1):
                SW2[k, m] += slope * S1[k, m]
        W2[k] = w2
        # eq. (31)
        l2_output_sens(c, ib2, n2b, ia2, n2a, q2, W2, Y, SW2, SY, k, nc)


@njit(cache=True, nogil=True)
def pi_sensitivities_into(c, layout, r, U, W1, W2, Y, S1, SW2, SY, p, SP, start):
    """Run :func:`pi_step_sens` from ``start`` to the end of the extended arrays."""
    pi_sens_range(c, layout, r, U, W1, W2, Y, S1, SW2, SY, p, SP, start, U.shape[0])


@njit(cache=True, nogil=True)
def _admissible(theta, layout, c):
    full_coefficients(theta, layout, c)
    ia1, ib1, imu, ia2, ib2 = _layout_offsets(layout)
    return (schur_stable(c[ia1:ib1], KMAX_STABLE)
            and schur_stable(c[ia2:ib2], KMAX_STABLE))


@njit(cache=True, nogil=True)
def _eria_update(theta, U, D, lam, rho_prev, rho, psi, e, K, f, ia1, n1a, ia2, n2a):
    """Eqs. (16)-(19) given the regressor ``psi`` and the error ``e``; returns Lambda^-1(k).

    ``P = U diag(D) U'`` is kept in U-D factored form (Bierman's update, O(n^2)) so that it stays
    positive definite in floating point; ``theta``, ``U``, ``D`` and ``K`` are updated in place.
    The gain is eq. (17), ``K = P h / (h' P h + mu Lambda^-1)``; the covariance update is the
    matching rank-one form ``P(k) = [P - K h' P] / mu``, which is eq. (18) when ``mu = 1``
    (for ``mu < 1``, (18) adds ``(1 - mu) Lambda^-1 K K' / mu``). The step is halved while it
    would put a pole of L1 (``theta[ia1:ia1+n1a]``) or L2 (``theta[ia2:ia2+n2a]``) on or outside
    the unit circle (at most 30 times, then it is dropped).
    """
    n = theta.shape[0]
    mu = rho_prev / rho * (1.0 - rho)                  # forgetting factor mu(k)
    lam = lam + rho * (e * e - lam)                     # (19)
    r = mu * lam
    if not r > 0.0:
        r = 1e-300
    # Bierman: f = U' h, v = D f (v stored in K, then turned into the gain)
    for j in range(n):
        s = psi[j]
        for i in range(j):
            s += U[i, j] * psi[i]
        f[j] = s
    alpha = r + D[0] * f[0] * f[0]
    K[0] = D[0] * f[0]
    D[0] = D[0] * r / alpha
    for j in range(1, n):
        vj = D[j] * f[j]
        beta = alpha
        alpha = alpha + vj * f[j]
        lj = -f[j] / beta
        D[j] = D[j] * beta / alpha
        for i in range(j):
            tmp = U[i, j]
            U[i, j] = tmp + K[i] * lj
            K[i] = K[i] + tmp * vj
        K[j] = vj
    for j in range(n):
        K[j] = K[j] / alpha                             # (17)
        D[j] = D[j] / mu                                # (18)
    old = theta.copy()
    step = 1.0
    for _ in range(31):                                 # (16), kept stable
        for a in range(n):
            theta[a] = old[a] + step * K[a] * e
        if (schur_stable(theta[ia1 : ia1 + n1a], KMAX_STABLE)
                and schur_stable(theta[ia2 : ia2 + n2a], KMAX_STABLE)):
            return lam
        step *= 0.5
    theta[:] = old
    return lam


@njit(cache=True, nogil=True)
def _minimal_step(theta, U_, D, lam, rho_prev, rho, layout, r, U, W1, W2, Y, S1, SW2, SY, p, SP,
                  k, y_meas, equation_error, c, psi_c, psi, K, f):
    # regressor: gradient of yhat(k) w.r.t. the model's own (free) parameters
    n1a, n1b, n, n2a = layout[0], layout[1], layout[2], layout[3]
    nc = c.shape[0]
    full_coefficients(theta, layout, c)
    pi_step_sens(c, layout, r, U, W1, W2, Y, S1, SW2, SY, p, SP, k)
    yhat = Y[k]
    for m in range(nc):
        psi_c[m] = SY[k, m]
    free_gradient(psi_c, layout, psi)
    if not np.isfinite(y_meas):                         # skipped: propagated, not learned
        return np.nan, lam, yhat
    e = y_meas - yhat                                   # (15)
    lam = _eria_update(theta, U_, D, lam, rho_prev, rho, psi, e, K, f, 0, n1a,
                       n1a + n1b - 1 + n, n2a)
    if equation_error:
        # past outputs in the regressor are the measured ones (no output recursion)
        Y[k] = y_meas
        for m in range(nc):
            SY[k, m] = 0.0
    return e, lam, yhat


@njit(cache=True, nogil=True)
def _l1_operators(theta, layout, r, U, W1, S1, PH, SPH, p, SP, k, c1):
    # eqs. (29)-(30) at index k with d w1 / d c1 and d p_i / d c1 (c1 = full L1 coefficients);
    # theta starts with the free L1 parameters [a1.., b12..]; b11 gives unit DC gain
    n1a, n1b, n, q1 = layout[0], layout[1], layout[2], layout[5]
    n1 = n1a + n1b
    gain = 1.0
    for i in range(n1a):
        c1[i] = theta[i]
        gain += theta[i]
    for j in range(1, n1b):
        c1[n1a + j] = theta[n1a + j - 1]
        gain -= theta[n1a + j - 1]
    c1[n1a] = gain
    w1 = _l1_step(c1, n1a, n1b, q1, U, W1, S1, k)
    _operators_step(w1, r, p, SP, S1, k, n1)
    for i in range(n):
        PH[k, i] = p[i]
        for m in range(n1):
            SPH[k, i, m] = SP[i, m]


@njit(cache=True, nogil=True)
def _keyterm_regressor(beta, ib, layout, PH, SPH, k, phi, psi1):
    # phi[ib + j N + i] = p_i(k - q2 - j); psi1 = sum_j sum_i beta_ji d p_i(k-q2-j) / d c1;
    # returns sum_j sum_i beta_ji p_i(k - q2 - j)
    n1a, n1b, n, n2b, q2 = layout[0], layout[1], layout[2], layout[4], layout[6]
    n1 = n1a + n1b
    acc = 0.0
    for m in range(n1):
        psi1[m] = 0.0
    for j in range(n2b):
        kk = k - q2 - j
        for i in range(n):
            b = beta[j * n + i]
            acc += b * PH[kk, i]
            phi[ib + j * n + i] = PH[kk, i]
            for m in range(n1):
                psi1[m] += b * SPH[kk, i, m]
    return acc


@njit(cache=True, nogil=True)
def _l1_chain(psi1, n1a, n1b, psi):
    # d/d(free L1 parameters) from d/d(full L1 coefficients): b11 = 1 + sum a1 - sum b1j
    for i in range(n1a):
        psi[i] = psi1[i] + psi1[n1a]
    for j in range(1, n1b):
        psi[n1a + j - 1] = psi1[n1a + j] - psi1[n1a]


@njit(cache=True, nogil=True)
def _keyterm_step(theta, U_, D, lam, rho_prev, rho, layout, r, U, W1, Y, S1, PH, SPH, p, SP, k,
                  y_meas, c1, psi1, psi, K, f):
    # the paper-like regressor: eq. (31) with w2 = sum_i mu_i p_i substituted is linear in a2
    # and beta_ji = b2j mu_i given the operator outputs; past outputs are the measured ones
    n1a, n1b, n, n2a, n2b = layout[0], layout[1], layout[2], layout[3], layout[4]
    ib = n1a + n1b - 1
    ia2 = ib + n2b * n
    _l1_operators(theta, layout, r, U, W1, S1, PH, SPH, p, SP, k, c1)
    yhat = _keyterm_regressor(theta[ib:ia2], ib, layout, PH, SPH, k, psi, psi1)
    for i in range(n2a):
        yhat -= theta[ia2 + i] * Y[k - 1 - i]
        psi[ia2 + i] = -Y[k - 1 - i]
    _l1_chain(psi1, n1a, n1b, psi)
    if not np.isfinite(y_meas):                         # skipped: the prediction stands in
        Y[k] = yhat
        return np.nan, lam, yhat
    e = y_meas - yhat                                   # (15)
    lam = _eria_update(theta, U_, D, lam, rho_prev, rho, psi, e, K, f, 0, n1a, ia2, n2a)
    Y[k] = y_meas
    return e, lam, yhat


@njit(cache=True, nogil=True)
def _rho(n, gamma):
    # convergence factor rho(k) = (k+1)^-gamma, with rho(0) = 1
    return float(n + 1) ** (-gamma)


@njit(cache=True, nogil=True)
def _recursion_step(mode, theta, U_, D, lam, gamma, n, layout, r, U, W1, W2, Y, S1, SW2, SY, PH,
                    SPH, p, SP, k, y_k, K, c, c1, psi_c, psi1, psi, f):
    # one sample at index k, the n-th of the recursion; returns (e, yhat), updates lam[0]
    rho_prev = _rho(n - 1, gamma)
    rho = _rho(n, gamma)
    if mode == 0:
        e, lam[0], yhat = _keyterm_step(theta, U_, D, lam[0], rho_prev, rho, layout, r, U, W1,
                                        Y, S1, PH, SPH, p, SP, k, y_k, c1, psi1, psi, K, f)
    else:
        e, lam[0], yhat = _minimal_step(theta, U_, D, lam[0], rho_prev, rho, layout, r, U, W1,
                                        W2, Y, S1, SW2, SY, p, SP, k, y_k, False, c, psi_c, psi,
                                        K, f)
    return e, yhat


@njit(cache=True, nogil=True)
def _scratch(npar, nc, n1):
    # work arrays of one recursion step: c, c1, psi_c, psi1, psi, f
    return (np.empty(max(nc, n1)), np.empty(n1), np.empty(nc), np.empty(n1), np.empty(npar),
            np.empty(npar))


@njit(cache=True, nogil=True)
def recursion_run(mode, theta, U_, D, lam, gamma, k0, layout, r, U, W1, W2, Y, S1, SW2, SY, PH, SPH,
                  p, SP, start, ymeas, history, errors, yhats, K):
    """Run the recursion from index ``start`` to the end of the extended arrays.

    ``mode`` 0: key-term regressor (measured past outputs); 1: output-error gradient. Row
    ``k - start`` of ``history`` receives theta(k); ``lam[0]`` (Lambda^-1) is updated in place.
    """
    c, c1, psi_c, psi1, psi, f = _scratch(theta.shape[0], SW2.shape[1], layout[0] + layout[1])
    for k in range(start, U.shape[0]):
        n = k0 + k - start + 1  # samples since the start of the recursion (1, 2, ...)
        e, yhat = _recursion_step(mode, theta, U_, D, lam, gamma, n, layout, r, U, W1, W2, Y,
                                  S1, SW2, SY, PH, SPH, p, SP, k, ymeas[k - start], K, c, c1,
                                  psi_c, psi1, psi, f)
        history[k - start, :] = theta
        errors[k - start] = e
        yhats[k - start] = yhat


@njit(cache=True, nogil=True)
def _shift(a):
    # drop the oldest row of a signal window (a one-row placeholder is left as it is)
    for i in range(a.shape[0] - 1):
        a[i] = a[i + 1]


@njit(cache=True, nogil=True)
def recursion_one(mode, theta, U_, D, lam, gamma, k0, layout, r, U, W1, W2, Y, S1, SW2, SY, PH,
                  SPH, p, SP, u_k, y_k, K, out):
    """One sample on the windows themselves: the same step as :func:`recursion_run` on a chunk
    of one sample (the windows shifted by one, ``u_k`` at the end), without the copies.

    ``out`` receives ``(e, yhat)``; ``k0`` is the number of samples before this one.
    """
    _shift(U)
    _shift(W1)
    _shift(W2)
    _shift(Y)
    _shift(S1)
    _shift(SW2)
    _shift(SY)
    _shift(PH)
    _shift(SPH)
    last = U.shape[0] - 1
    U[last] = u_k
    c, c1, psi_c, psi1, psi, f = _scratch(theta.shape[0], SW2.shape[1], layout[0] + layout[1])
    out[0], out[1] = _recursion_step(mode, theta, U_, D, lam, gamma, k0 + 1, layout, r, U, W1,
                                     W2, Y, S1, SW2, SY, PH, SPH, p, SP, last, y_k, K, c, c1,
                                     psi_c, psi1, psi, f)


# =========================================================================== helpers
def _layout(s: PIStructure) -> np.ndarray:
    return np.array([s.n1a, s.n1b, s.n_operators, s.n2a, s.n2b, s.q1, s.q2, s.n_poly],
                    dtype=np.int64)


def _n_full(s: PIStructure) -> int:
    return s.n1a + s.n1b + s.n_operators + s.n_poly + s.n2a + s.n2b


def pi_output_sensitivities(
    model: PISandwich, u: np.ndarray, x0: InitialCondition | None = None,
    chain: np.ndarray | None = None, raw: bool = False,
) -> tuple[np.ndarray, ...]:
    """Simulated output and its Jacobian ``d yhat / d theta`` (``N x n_params``) from rest/x0.

    Parameters
    ----------
    model : PISandwich
        The model at the current parameters.
    u : ndarray
        Input samples.
    x0 : InitialCondition, optional
        Past signal values; at rest by default.
    chain : ndarray, optional
        ``d theta / d z`` (``n_params x n_z``): the Jacobian is then ``d yhat / d z``, formed
        in one product with the sensitivities (a search in other coordinates).
    raw : bool
        Return the sensitivities to the full coefficients (``N x n_full``) and the map from
        them to the Jacobian's columns instead of their product (a caller that reduces the
        rows first multiplies a square matrix instead of a tall one).

    Returns
    -------
    tuple of ndarray
        ``yhat`` (N) and its Jacobian (N x n_params, or N x n_z with ``chain``); with ``raw``,
        ``yhat``, the full sensitivities and the map (their product is the Jacobian).
    """
    s = model.structure
    given = x0 is not None
    x0 = x0 or model.at_rest()
    P = s.history
    u = np.asarray(u, dtype=float)
    n = len(u)
    U, W1, W2, Y = (
        np.concatenate([x0.window(key, P), np.zeros(n)]) for key in ("u", "w1", "w2", "y")
    )
    U[P:] = u
    nc = _n_full(s)
    S1 = np.zeros((P + n, max(s.n1a + s.n1b, 1)))  # d w1 / d (L1's coefficients) alone
    SW2, SY = (np.zeros((P + n, nc)) for _ in range(2))
    layout = _layout(s)
    c = np.empty(nc)
    full_coefficients(model.theta, layout, c)
    p = model.operator_state(x0)
    SP = np.zeros((s.n_operators, nc))
    if not given and model.rest_swing:
        _rest_sensitivities(model, layout, c, SW2, SY, P)
    pi_sensitivities_into(c, layout, model.thresholds, U, W1, W2, Y, S1, SW2, SY, p, SP, P)
    T = _free_map(layout, len(model.theta), nc)
    if raw:
        return Y[P:], SY[P:], T if chain is None else T @ chain
    return Y[P:], SY[P:] @ (T if chain is None else T @ chain)


def _rest_sensitivities(model: PISandwich, layout: np.ndarray, c: np.ndarray, SW2: np.ndarray,
                        SY: np.ndarray, P: int) -> None:
    """The past rows of ``SW2`` and ``SY`` at rest after a swing (:attr:`PISandwich.rest_plays`):
    ``w2 = sum_i mu_i p_i`` there and L2 settled on it, ``y = G w2`` with
    ``G = sum(b2) / (1 + sum(a2))`` (1 at the model's coefficients), so ``d w2 / d mu_i = p_i``,
    ``d y / d mu_i = G p_i``, ``d y / d b2_j = w2 / (1 + sum a2)`` and
    ``d y / d a2_j = -G w2 / (1 + sum a2)``."""
    _, _, imu, ia2, ib2 = _layout_offsets(layout)
    pr = model.rest_plays
    w2 = model.hysteresis_output(0.0, pr)
    a2, b2 = c[ia2:ib2], c[ib2:]
    den = 1.0 + float(np.sum(a2))
    gain = float(np.sum(b2)) / den
    SW2[:P, imu:imu + len(pr)] = pr
    SY[:P, imu:imu + len(pr)] = gain * pr
    SY[:P, ia2:ib2] = -gain * w2 / den
    SY[:P, ib2:] = w2 / den


def _free_map(layout: np.ndarray, npar: int, nc: int) -> np.ndarray:
    """The constant matrix ``dc/dtheta``."""
    T = np.empty((nc, npar))
    psi = np.empty(npar)
    for m in range(nc):
        e = np.zeros(nc)
        e[m] = 1.0
        free_gradient(e, layout, psi)
        T[m] = psi
    return T


