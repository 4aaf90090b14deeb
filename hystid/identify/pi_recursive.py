"""Identification of the PI sandwich (eqs. 29-31): recursive on-line, and off-line for reference.

The recursive identifier runs the paper's extended recursion (eqs. 15-19) with the paper's PI
settings, ``P(0) = 1e6 I``, ``theta(0) = 0.001`` and the stop index ``epsilon = 1e-4``::

    e(k)      = y(k) - yhat(k | theta(k-1))                                          (15)
    theta(k)  = theta(k-1) + K(k) e(k)                                               (16)
    K(k)      = P(k-1) h(k) / [h(k)' P(k-1) h(k) + mu(k) Lambda^-1(k)]               (17)
    P(k)      = [(I - K h') P(k-1) (I - K h')' + K Lambda^-1 K'] / mu(k)             (18)
    Lambda^-1(k) = Lambda^-1(k-1) + rho(k) [e(k)^2 - Lambda^-1(k-1)]                 (19)

with ``rho(k) = (k+1)^-gamma`` and ``mu(k) = rho(k-1)/rho(k) (1 - rho(k))``; ``P`` is kept in
U-D factored form (Bierman), which the plain update (18) needs at 46 parameters: in floating
point it loses positive definiteness within a few thousand samples.

Regressors ``h(k)`` (``form``):

* ``"output-error"`` (default): the gradient ``d yhat(k) / d theta`` of the *simulated* output,
  by forward sensitivities through eqs. 29-31 along the recursion (``dp_i/dw1`` is 1 while
  operator ``i`` moves, 0 while it holds): a recursive prediction-error method. Sensor noise
  does not enter ``h``.
* ``"key-term"``: the paper-like pseudo-linear regression. With ``w2 = sum mu_i p_i``
  substituted, eq. (31) is linear in ``a2`` and the products ``b2j mu_i`` given the operator
  outputs; the past outputs are the *measured* ones (as the paper's ``h(k)`` holds
  ``-Delta y(k-i)``); L1 enters through the gradient. The products are turned back into
  weights and ``b2`` by :func:`keyterm_to_model`.

Start. The paper's cold start (``P0 = 1e6``, ``theta0 = 0.001``) diverges in both forms (see
``benchmarks/bench_pi_vs_duhem.py``): with a diffuse ``P`` the first samples, where the signals
are of the size of the sensor noise, throw L1 and L2 far off, and the play operators keep the
wrong extrema of ``w1`` in memory. The default therefore warms up: the first samples, until the
input has swept its range, are fitted off-line and the recursion continues from that estimate
with ``P`` set to the inverse information of that fit (with the paper's ``P(0)`` as prior).

Units. The recursion runs on normalised signals, like the off-line fit: the warm-up fit's
input and output scales about zero (:func:`~hystid.identify.prepare.scales` of its samples)
divide ``u``, ``y`` and the thresholds, so that the weights, ``P``, ``Lambda^-1`` and the
settings ``P0`` and ``epsilon`` are dimensionless and the identified model is the same in V or
kV, um or m. Every output (the estimate and its history, the model, :meth:`update`'s return
value, ``e``, ``yhat``, ``K``, ``P``, ``Lambda^-1``) is mapped back to the record's units: only
the weights carry units (output per input). A cold start has no samples to take scales from
and runs in the record's units.

After every update the estimate is kept stable (poles of L1 and L2 inside the unit circle): a
step that would leave that set is halved until it does not (at most 30 times, then dropped).

:func:`fit_pi_output_error` is the off-line reference: output-error least squares
(``scipy.optimize.least_squares``, exact Jacobian, poles kept inside the circle by reflection
coefficients) run like the off-line Duhem fit, on the prepared record's normalised signals
(input less its rest over a quantile, output over its spread) with a sensor offset and several
starts, so that the identified model does not depend on the units. The warm-up fit is the same
on the recursion's terms (at rest at ``u = 0``, no offset). :func:`identify_pi` is the entry
point of ``hystid identify REC --model pi``.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any, NamedTuple

import numpy as np
from numba import njit
from scipy.optimize import least_squares

from ..model import InitialCondition, Structure
from ..pi import N_OPERATORS, PISandwich, PIStructure, pi_thresholds, play
from ..poly import KMAX_STABLE, schur_stable
from ..records import Record
from ..thresholds import RULES
from .base import Estimator, record_signals, sample_arrays
from .constraints import Reflections
from .offline import SCREEN_NFEV, linear_start, triangle_of
from .prepare import prepare, scales
from .result import IdentificationResult, converged_at

__all__ = [
    "PIRecursiveIdentifier",
    "fit_pi_output_error",
    "identify_pi",
    "keyterm_to_model",
    "pi_output_sensitivities",
]

FORMS = ("key-term", "output-error")
#: Starts of the off-line fit polished after the screening (the best ones).
POLISHED = 2
#: Ridge on the weights in the off-line fits: the cost is ``sum r^2 + RIDGE m |mu_n|^2`` on
#: normalised signals (``m`` samples in the cost, ``mu_n`` the weights in normalised units, so
#: the same in any units). Operators that the input moves only once (on the ramp out of rest)
#: have nearly collinear outputs; without it their weights drift along a flat valley of the
#: cost to large alternating values, and where the solver stops there is arbitrary.
RIDGE = 1e-8


# =========================================================================== compiled kernels
@njit(cache=True)
def _l1_step(c, n1a, n1b, q1, U, W1, S1, k):
    # eq. (29) at index k and d w1 / d (a1, b1) with c = [a1 (n1a), b1 (n1b), ...]; returns w1
    w1 = 0.0
    for j in range(n1b):
        w1 += c[n1a + j] * U[k - q1 - j]
    for i in range(n1a):
        w1 -= c[i] * W1[k - 1 - i]
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


@njit(cache=True)
def _operators_step(w1, r, p, SP, S1, k, n1):
    # eq. (30) for every operator with d p_i / d c1: an operator that moves follows w1
    # (dp/dw1 = 1), one that holds keeps its state and its sensitivity
    for i in range(r.shape[0]):
        q = play(w1, p[i], r[i])
        if q != p[i]:
            p[i] = q
            for m in range(n1):
                SP[i, m] = S1[k, m]


@njit(cache=True)
def _layout_offsets(layout):
    # layout = [n1a, n1b, N, n2a, n2b, q1, q2]; full coefficient vector
    # c = [a1 (n1a), b1 (n1b), mu (N), a2 (n2a), b2 (n2b)]
    n1a, n1b, n, n2a = layout[0], layout[1], layout[2], layout[3]
    return 0, n1a, n1a + n1b, n1a + n1b + n, n1a + n1b + n + n2a


@njit(cache=True)
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
            for i in range(n):
                c[imu + i] = theta[t]
                t += 1


@njit(cache=True)
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
            for i in range(n):
                psi[t] = psi_c[imu + i]
                t += 1


@njit(cache=True)
def pi_step_sens(c, layout, r, U, W1, W2, Y, S1, SW2, SY, p, SP, k):
    """Eqs. (29)-(31) at index ``k`` with the sensitivities to the full coefficients ``c``.

    ``U, W1, W2, Y`` are extended signal arrays, ``S1, SW2, SY`` the matching sensitivity rows
    (``d w1 / d c`` etc.); ``p`` and ``SP`` (``d p_i / d c``) hold the operator states at
    ``k-1`` and are updated in place.
    """
    n1a, n1b, n, n2a, n2b, q1, q2 = (layout[0], layout[1], layout[2], layout[3], layout[4],
                                     layout[5], layout[6])
    ia1, ib1, imu, ia2, ib2 = _layout_offsets(layout)
    nc = c.shape[0]
    n1 = n1a + n1b
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
    W2[k] = w2
    # eq. (31)
    y = 0.0
    for j in range(n2b):
        y += c[ib2 + j] * W2[k - q2 - j]
    for i in range(n2a):
        y -= c[ia2 + i] * Y[k - 1 - i]
    Y[k] = y
    for m in range(nc):
        s = 0.0
        for j in range(n2b):
            s += c[ib2 + j] * SW2[k - q2 - j, m]
        for i in range(n2a):
            s -= c[ia2 + i] * SY[k - 1 - i, m]
        SY[k, m] = s
    for i in range(n2a):
        SY[k, ia2 + i] -= Y[k - 1 - i]
    for j in range(n2b):
        SY[k, ib2 + j] += W2[k - q2 - j]


@njit(cache=True)
def pi_sensitivities_into(c, layout, r, U, W1, W2, Y, S1, SW2, SY, p, SP, start):
    """Run :func:`pi_step_sens` from ``start`` to the end of the extended arrays."""
    for k in range(start, U.shape[0]):
        pi_step_sens(c, layout, r, U, W1, W2, Y, S1, SW2, SY, p, SP, k)


@njit(cache=True)
def _admissible(theta, layout, c):
    full_coefficients(theta, layout, c)
    ia1, ib1, imu, ia2, ib2 = _layout_offsets(layout)
    return (schur_stable(c[ia1:ib1], KMAX_STABLE)
            and schur_stable(c[ia2:ib2], KMAX_STABLE))


@njit(cache=True)
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


@njit(cache=True)
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


@njit(cache=True)
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


@njit(cache=True)
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


@njit(cache=True)
def _l1_chain(psi1, n1a, n1b, psi):
    # d/d(free L1 parameters) from d/d(full L1 coefficients): b11 = 1 + sum a1 - sum b1j
    for i in range(n1a):
        psi[i] = psi1[i] + psi1[n1a]
    for j in range(1, n1b):
        psi[n1a + j - 1] = psi1[n1a + j] - psi1[n1a]


@njit(cache=True)
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


@njit(cache=True)
def _rho(n, gamma):
    # convergence factor rho(k) = (k+1)^-gamma, with rho(0) = 1
    return float(n + 1) ** (-gamma)


@njit(cache=True)
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


@njit(cache=True)
def _scratch(npar, nc, n1):
    # work arrays of one recursion step: c, c1, psi_c, psi1, psi, f
    return (np.empty(max(nc, n1)), np.empty(n1), np.empty(nc), np.empty(n1), np.empty(npar),
            np.empty(npar))


@njit(cache=True)
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


@njit(cache=True)
def _shift(a):
    # drop the oldest row of a signal window (a one-row placeholder is left as it is)
    for i in range(a.shape[0] - 1):
        a[i] = a[i + 1]


@njit(cache=True)
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
    return np.array([s.n1a, s.n1b, s.n_operators, s.n2a, s.n2b, s.q1, s.q2], dtype=np.int64)


def _n_full(s: PIStructure) -> int:
    return s.n1a + s.n1b + s.n_operators + s.n2a + s.n2b


def pi_output_sensitivities(
    model: PISandwich, u: np.ndarray, x0: InitialCondition | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """Simulated output and its Jacobian ``d yhat / d theta`` (``N x n_params``) from rest/x0.

    Parameters
    ----------
    model : PISandwich
        The model at the current parameters.
    u : ndarray
        Input samples.
    x0 : InitialCondition, optional
        Past signal values; at rest by default.

    Returns
    -------
    tuple of ndarray
        ``yhat`` (N) and its Jacobian (N x n_params).
    """
    s = model.structure
    x0 = x0 or InitialCondition()
    P = s.history
    u = np.asarray(u, dtype=float)
    n = len(u)
    U, W1, W2, Y = (
        np.concatenate([x0.window(key, P), np.zeros(n)]) for key in ("u", "w1", "w2", "y")
    )
    U[P:] = u
    nc = _n_full(s)
    S1, SW2, SY = (np.zeros((P + n, nc)) for _ in range(3))
    layout = _layout(s)
    c = np.empty(nc)
    full_coefficients(model.theta, layout, c)
    p = model.operator_state(x0)
    SP = np.zeros((s.n_operators, nc))
    pi_sensitivities_into(c, layout, model.thresholds, U, W1, W2, Y, S1, SW2, SY, p, SP, P)
    T = _free_map(layout, len(model.theta), nc)
    return Y[P:], SY[P:] @ T


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


# =========================================================================== recursive
def keyterm_to_model(theta_kt: np.ndarray, structure: PIStructure) -> np.ndarray:
    """Model parameters (unit DC gains) from key-term parameters; rows of a 2-D array too.

    The key-term vector is ``[a1.., b12.., beta, a2..]`` with ``beta[j, i] = b2{j+1} mu_i``.
    With unit DC gain ``sum_j b2j = A2(1) = 1 + sum a2``, so ``mu_i = sum_j beta[j, i] / A2(1)``
    (the well-determined low-frequency combination; at high sampling rates ``p_i(k-1)`` and
    ``p_i(k-2)`` are nearly collinear and the difference of the rows of ``beta`` is poorly
    determined), and ``b2`` is the least-squares factor ``beta mu / |mu|^2`` (whose sum is then
    ``A2(1)``).

    Parameters
    ----------
    theta_kt : ndarray
        Key-term parameters (a vector, or one per row).
    structure : PIStructure
        Orders and delays.

    Returns
    -------
    ndarray
        Model parameters, same leading shape as ``theta_kt``.
    """
    s = structure
    th = np.atleast_2d(np.asarray(theta_kt, dtype=float))
    n, nb = s.n_operators, s.n2b
    i1 = s.n1a + s.n1b - 1
    beta = th[:, i1 : i1 + nb * n].reshape(-1, nb, n)
    a2 = th[:, i1 + nb * n :]
    mu = beta.sum(axis=1) / (1.0 + a2.sum(axis=1))[:, None]
    norm = np.maximum(np.einsum("ri,ri->r", mu, mu), 1e-300)
    b2 = np.einsum("rji,ri->rj", beta, mu) / norm[:, None]
    out = np.hstack([th[:, :i1], mu, a2, b2[:, 1:]])
    return out[0] if np.ndim(theta_kt) == 1 else out


class PIRecursiveIdentifier(Estimator):
    """On-line identification of the PI sandwich by the extended recursion (eqs. 15-19).

    Keeps the estimator contract (:class:`~hystid.identify.base.Estimator`): configuration in
    the constructor, read back as :attr:`settings`; :meth:`update` takes one sample and returns
    theta(k) in the model's parameters (:attr:`names`); :meth:`fit` restarts, and
    :meth:`partial_fit` continues; a non-finite output is skipped (the model is propagated, the
    estimate and ``P`` are left as they are), a non-finite input refused. The intermediates of
    the last update (:attr:`e`, :attr:`yhat`, :attr:`K`) are kept as attributes.

    Parameters
    ----------
    thresholds : array_like, optional
        Play-operator thresholds; needed before the first :meth:`update`. :meth:`fit` places
        them from the record's input range (:func:`hystid.pi.pi_thresholds`) when omitted.
    structure : PIStructure, optional
        Orders and delays; the paper's (eqs. 29, 31) with ``n_operators`` operators by default.
    n_operators : int
        Number of play operators when neither ``thresholds`` nor ``structure`` say (40).
    P0 : float or array_like
        Initial covariance ``P(0) = P0 I`` (the paper's 1e6), or its diagonal, in the
        recursion's units (:attr:`scales`: dimensionless after a warm-up). After a warm-up it
        is the prior of the warm-up fit: ``P = (J'J / s^2 + I / P0)^-1`` on the normalised
        signals.
    theta0 : float or array_like
        Initial estimate in the recursion's coordinates (:attr:`recursion_names`): one value
        for every parameter (the paper's 0.001) or a vector. Used by a cold start only, where
        the recursion's units are the record's.
    epsilon : float
        Stop index (1e-4): the recursion has converged once no parameter changes by more than
        ``epsilon`` relative to its value (see :func:`hystid.identify.result.converged_at`).
    gamma : float
        Exponent of the convergence factor ``rho(k) = (k+1)^-gamma`` of eq. (19).
        ``gamma = 1`` (default) gives ``mu(k) = 1`` (no forgetting); 9/13 (the paper's Duhem
        setting) forgets, which blows ``P`` up along the weights of operators the input no
        longer moves.
    lambda0 : float
        Initial ``Lambda^-1`` (estimated error variance) of a cold start, output units
        squared; a warm-up replaces it by the warm-up fit's residual variance.
    form : {"output-error", "key-term"}
        Regressor ``h(k)``. ``"output-error"`` (default): the gradient of the simulated output
        with respect to the model's own parameters (a recursive prediction-error method).
        ``"key-term"``: the paper-like pseudo-linear regression, eq. (31) with
        ``w2 = sum mu_i p_i`` substituted, linear in ``a2`` and ``b2j mu_i`` given the operator
        outputs, with the *measured* past outputs (as the paper's ``h(k)`` holds
        ``-Delta y(k-i)``); L1 enters through the gradient.
    warmup : int or "sweep"
        Output-error form only: the first ``warmup`` samples are fitted off-line
        (:func:`fit_pi_output_error`) and the recursion continues from that estimate and its
        covariance. ``"sweep"`` (default): at least ``min_warmup`` samples and until the input
        has swept 90 % of the range the thresholds were placed for (``2 r_max N/(N-1)``), so
        that every play operator has moved once, but at most ``max_warmup`` samples. ``0``
        starts cold from ``theta0`` and ``P0`` (the paper's start); the key-term form always
        does.
    min_warmup, max_warmup : int
        Bounds of the ``"sweep"`` warm-up.
    fs : float
        Sampling rate of the data in Hz; records must be sampled at it
        (:func:`identify_pi` passes the record's).

    Attributes
    ----------
    theta : ndarray
        Current estimate in the model's parameters (see :attr:`names`).
    P : ndarray
        Current covariance matrix ``P(k)``, record units.
    K : ndarray
        Gain of the last update, record units.
    e : float
        Prediction error of the last update, ``y(k) - yhat(k)``, output units.
    yhat : float
        Prediction of the last update, output units.
    lam : float
        Current ``Lambda^-1(k)``, output units squared.
    scales : tuple of float
        The recursion's units ``(su, sy)``.
    k : int
        Number of samples processed.

    Notes
    -----
    The paper's start (``warmup=0``, ``P0 = 1e6``, ``theta0 = 0.001``) does not converge on
    this model in either form: with a diffuse ``P`` the first samples, where the signals are
    of the size of the sensor noise, throw L1 and L2 far off, and the play operators keep the
    wrong ``w1`` extrema in memory. The key-term form is also biased by sensor noise at high
    sampling rates (the regressors ``y(k-1)``, ``y(k-2)`` and ``p_i(k-1)``, ``p_i(k-2)`` are
    nearly collinear). See ``benchmarks/bench_pi_vs_duhem.py`` for figures.
    """

    method = "pi-recursive"
    #: Samples per compiled call in :meth:`partial_fit` (between progress reports).
    chunk = 5000

    def __init__(
        self,
        thresholds: np.ndarray | None = None,
        structure: PIStructure | None = None,
        *,
        n_operators: int = N_OPERATORS,
        P0: float | np.ndarray = 1e6,
        theta0: float | np.ndarray = 0.001,
        epsilon: float = 1e-4,
        gamma: float = 1.0,
        lambda0: float = 1.0,
        form: str = "output-error",
        warmup: int | str = "sweep",
        min_warmup: int = 1000,
        max_warmup: int = 20_000,
        fs: float = 30_000.0,
    ) -> None:
        if form not in FORMS:
            raise ValueError(f"form: expected one of {FORMS}, got {form!r}")
        P0 = np.asarray(P0, dtype=float)
        if P0.ndim > 1 or not (np.all(np.isfinite(P0)) and np.all(P0 >= 0) and np.any(P0 > 0)):
            raise ValueError(f"P0: expected a positive number or a non-negative diagonal, got {P0}")
        for label, value in (("epsilon", epsilon), ("gamma", gamma), ("lambda0", lambda0),
                             ("fs", fs), ("n_operators", n_operators)):
            if not (np.isfinite(value) and value > 0):
                raise ValueError(f"{label}: expected a positive finite number, got {value!r}")
        if gamma > 1:
            raise ValueError(f"gamma: expected a value in (0, 1] (mu(k) <= 1), got {gamma!r}")
        if warmup != "sweep" and (isinstance(warmup, str) or int(warmup) != warmup
                                  or warmup < 0):
            raise ValueError(f"warmup: expected 'sweep' or a number of samples, got {warmup!r}")
        if int(min_warmup) != min_warmup or not 50 <= min_warmup <= max_warmup:
            raise ValueError(f"min_warmup, max_warmup: expected 50 <= min <= max, got "
                             f"{min_warmup!r}, {max_warmup!r}")
        if form != "output-error":
            if warmup not in (0, "sweep"):
                raise ValueError("warmup: only the output-error form has a warm-up; use warmup=0")
            warmup = 0
        self.thresholds = thresholds
        self.structure = structure
        self.n_operators = int(n_operators)
        self.P0 = P0
        self.theta0 = theta0
        self.epsilon = float(epsilon)
        self.gamma = float(gamma)
        self.lambda0 = float(lambda0)
        self.form = form
        self.warmup = warmup if warmup == "sweep" else int(warmup)
        self.min_warmup = int(min_warmup)
        self.max_warmup = int(max_warmup)
        self.fs = float(fs)
        self.reset()

    # ----------------------------------------------------------------- configuration
    @property
    def settings(self) -> dict[str, Any]:
        """The constructor's configuration as plain values (JSON-ready)."""
        r = self.thresholds
        return {"P0": self.P0.tolist(), "theta0": np.asarray(self.theta0).tolist(),
                "epsilon": self.epsilon, "gamma": self.gamma, "lambda0": self.lambda0,
                "form": self.form, "warmup": self.warmup, "min_warmup": self.min_warmup,
                "max_warmup": self.max_warmup, "fs": self.fs,
                "n_operators": self._structure().n_operators,
                "thresholds": None if r is None else np.asarray(r, float).ravel().tolist()}

    @property
    def names(self) -> tuple[str, ...]:
        """Names of the model's parameters (the entries of :attr:`theta` and of the history)."""
        return self._structure().names

    @property
    def recursion_names(self) -> tuple[str, ...]:
        """Names of the recursion's own coordinates (``theta0`` and ``P0`` are given in them).

        The model's parameters in the output-error form; ``a1.., b12.., b2j*mu_i, a2..`` in the
        key-term form.
        """
        s = self._structure()
        if self.form == "output-error":
            return s.names
        beta = tuple(f"b2{j + 1}*mu{i}" for j in range(s.n2b) for i in range(s.n_operators))
        return (tuple(f"a1{i}" for i in range(1, s.n1a + 1))
                + tuple(f"b1{j}" for j in range(2, s.n1b + 1)) + beta
                + tuple(f"a2{i}" for i in range(1, s.n2a + 1)))

    @property
    def theta(self) -> np.ndarray:
        """The current estimate in the model's parameters (:attr:`names`)."""
        if not self._ready:
            return self._model_theta(self._theta_start(len(self.recursion_names)))
        return self._to_record(self._model_theta(self._theta))

    def _to_record(self, theta: np.ndarray) -> np.ndarray:
        """Model parameters (a vector or rows) from the recursion's units to the record's."""
        return _scale_weights(theta, self.structure_, self._sy / self._su)

    def _unit_factors(self) -> np.ndarray:
        """Per coordinate of the recursion, its value in record units over its normalised
        value: the weights (``mu_i``, or ``b2j*mu_i`` in the key-term form) carry ``sy/su``,
        the rest none."""
        s = self.structure_
        d = np.ones(len(self._theta))
        if self.form == "output-error":
            d[s.slices()["mu"]] = self._sy / self._su
        else:
            i1 = s.n1a + s.n1b - 1
            d[i1 : i1 + s.n2b * s.n_operators] = self._sy / self._su
        return d

    @property
    def K(self) -> np.ndarray:
        """Gain of the last update in record units (parameter change per unit of ``e``), in
        the recursion's coordinates (:attr:`recursion_names`)."""
        self._require_start()
        return self._unit_factors() * self._K / self._sy

    @property
    def lam(self) -> float:
        """Current ``Lambda^-1(k)``, the estimated error variance in output units squared."""
        self._require_start()
        return float(self._lam[0] * self._sy**2)

    @property
    def scales(self) -> tuple[float, float]:
        """The recursion's units ``(su, sy)``: it runs on ``u / su`` and ``y / sy`` with the
        weights times ``su / sy``. Set by the warm-up fit (quantile scales of its samples,
        :func:`~hystid.identify.prepare.scales` about zero); ``(1, 1)`` before, and on a cold
        start (the record's units)."""
        self._require_start()
        return self._su, self._sy

    def _structure(self) -> PIStructure:
        if self._ready:
            return self.structure_
        if self.structure is not None:
            return self.structure
        n = len(np.ravel(self.thresholds)) if self.thresholds is not None else self.n_operators
        return PIStructure(n_operators=n)

    def reset(self) -> PIRecursiveIdentifier:
        """Forget everything learned: back to ``theta0``, ``P0``, at rest, at sample 0.

        Thresholds placed from a record (none given to the constructor) are forgotten too: the
        next record places them again.

        Returns
        -------
        PIRecursiveIdentifier
            The identifier.
        """
        self._ready = False
        self.k = 0
        self.n_skipped = 0
        self.warm_result_: IdentificationResult | None = None
        self.warmup_seconds_ = 0.0
        self.warmed_up = False
        if self.thresholds is not None:
            self._start(self.thresholds)
        return self

    def _start(self, thresholds: Any) -> None:
        """Allocate the recursion's state for these thresholds (theta0, P0, at rest)."""
        s = self._structure()
        r = np.ascontiguousarray(np.asarray(thresholds, dtype=float).ravel())
        if s.n_operators != len(r):
            raise ValueError(f"thresholds: expected {s.n_operators} values, got {len(r)}")
        names = self.recursion_names
        theta = self._theta_start(len(names))
        PISandwich(self._model_theta(theta), r, s)  # validates thresholds and start
        if self.P0.ndim == 1 and self.P0.shape != (len(names),):
            raise ValueError(f"P0: expected {len(names)} diagonal values, got {self.P0.shape}")
        self.structure_ = s
        self.thresholds_ = r
        self.layout_ = _layout(s)
        self._theta = theta
        self._U = np.eye(len(names))
        self._D = np.array(np.broadcast_to(self.P0, (len(names),)), dtype=float)
        self._K = np.zeros(len(names))
        self.e = 0.0
        self.yhat = 0.0
        self._lam = np.array([self.lambda0])
        # the recursion's units: the record's until a warm-up fit sets its scales
        self._su, self._sy, self._rn = 1.0, 1.0, r
        self._H = max(s.history, s.q2 + s.n2b - 1)
        self._windows = self._arrays(self._H + 1)
        self._buffers = self._arrays(self._H + self.chunk)
        self._p = np.zeros(s.n_operators)
        self._SP = np.zeros((s.n_operators, _n_full(s)))
        self._mode = FORMS.index(self.form)
        self._last = np.zeros(2)  # e, yhat of the last one-sample update
        self._buffer: list[tuple[np.ndarray, np.ndarray]] = []
        self._umin, self._umax = np.inf, -np.inf
        self._ready = True

    def _arrays(self, length: int) -> list[np.ndarray]:
        """Extended arrays U, W1, W2, Y, S1, SW2, SY, PH, SPH of the given length.

        Output-error form: ``S1, SW2, SY`` are the sensitivities. Key-term form: ``PH, SPH``
        hold the operator outputs and their L1 sensitivities.
        """
        s = self.structure_
        nc, n = _n_full(s), s.n_operators
        sig = [np.zeros(length) for _ in range(4)]
        if self.form == "output-error":
            sens = [np.zeros((length, nc)) for _ in range(3)]
            return [*sig, *sens, np.zeros((1, 1)), np.zeros((1, 1, 1))]
        n1 = s.n1a + s.n1b
        return [*sig, np.zeros((length, n1)), np.zeros((1, 1)), np.zeros((1, 1)),
                np.zeros((length, n)), np.zeros((length, n, n1))]

    def _theta_start(self, n: int) -> np.ndarray:
        if np.isscalar(self.theta0):
            return np.full(n, float(self.theta0))
        theta = np.asarray(self.theta0, dtype=float).ravel()
        if theta.shape != (n,) or not np.all(np.isfinite(theta)):
            raise ValueError(f"theta0: expected a scalar or {n} finite values for {self.form!r}")
        return theta.copy()

    def _model_theta(self, theta: np.ndarray) -> np.ndarray:
        if self.form == "key-term":
            return keyterm_to_model(theta, self._structure())
        return np.asarray(theta, dtype=float)

    @property
    def P(self) -> np.ndarray:
        """Current covariance matrix ``P(k) = U diag(D) U'`` (kept factored) in record units,
        in the recursion's coordinates (:attr:`recursion_names`)."""
        self._require_start()
        d = self._unit_factors()
        return d[:, None] * ((self._U * self._D) @ self._U.T) * d[None, :]

    @property
    def model(self) -> PISandwich:
        """The current estimate as a :class:`~hystid.pi.PISandwich`."""
        self._require_start()
        return PISandwich(self.theta, self.thresholds_, self.structure_,
                          fs=self.fs, name="identified PI sandwich")

    def _require_start(self) -> None:
        if not self._ready:
            raise ValueError(
                "thresholds: the identifier needs the play-operator thresholds before the first "
                "update; pass thresholds= (see hystid.pi.pi_thresholds) or call fit(record)"
            )

    # ----------------------------------------------------------------- warm start
    @property
    def warming_up(self) -> bool:
        """True while the samples are still being collected for the warm-up fit."""
        return bool(self.warmup) and not self.warmed_up

    def _warmup_length(self, u: np.ndarray) -> int:
        """Samples of ``u`` that complete the warm-up after those buffered (``len(u)`` if not)."""
        return self._warmup_take(u)[0]

    def _warmup_take(self, u: np.ndarray) -> tuple[int, bool]:
        """Samples of ``u`` the warm-up takes, and whether they complete it.

        ``"sweep"``: at least ``min_warmup`` samples in all and the input has swept 90 % of the
        range the thresholds were placed for, or ``max_warmup`` samples; a number: that many.
        """
        if not self.warming_up or len(u) == 0:
            return 0, False
        n = self.k + np.arange(1, len(u) + 1)
        if self.warmup == "sweep":
            r, N = self.thresholds_, len(self.thresholds_)
            span = 2.0 * r[-1] * N / (N - 1) if N > 1 else 0.0
            swept = (np.maximum(np.maximum.accumulate(u), self._umax)
                     - np.minimum(np.minimum.accumulate(u), self._umin))
            due = (n >= self.max_warmup) | ((n >= self.min_warmup) & (swept >= 0.9 * span))
        else:
            due = n >= self.warmup
        return (int(np.argmax(due)) + 1, True) if due.any() else (len(u), False)

    def _collect(self, u: np.ndarray, y: np.ndarray, history: np.ndarray) -> int:
        """Buffer the warm-up samples at the head of ``u``; fit once they are all there.

        Returns the number of samples taken (the rows of ``history`` filled with ``theta0``).
        """
        w, done = self._warmup_take(u)
        if w == 0:
            return 0
        self._buffer.append((u[:w].copy(), y[:w].copy()))
        self._umin = min(self._umin, float(np.min(u[:w])))
        self._umax = max(self._umax, float(np.max(u[:w])))
        history[:w] = self.theta
        self.k += w
        if done:
            bu, by = (np.concatenate(part) for part in zip(*self._buffer, strict=True))
            self._buffer = []
            t0 = time.perf_counter()
            self._warm_start(bu, by)
            self.warmup_seconds_ = time.perf_counter() - t0
            self.warmed_up = True
            history[w - 1] = self.theta
        return w

    def _warm_start(self, u: np.ndarray, y: np.ndarray) -> None:
        """Fit the first samples off-line, then set the recursion's state as if it had run."""
        s = self.structure_
        fit, su, sy = _fit_normalised_from_zero(u, y, self.thresholds_, s)
        self.warm_result_ = _zero_result(fit, su, sy, self.thresholds_, s, self.fs, len(u))
        self._su, self._sy, self._rn = su, sy, self.thresholds_ / su
        u, y = u / su, y / sy
        theta = fit.theta
        yhat, J = pi_output_sensitivities(PISandwich(theta, self._rn, s), u)
        seen = np.isfinite(y)
        s2 = max(float(np.mean((y[seen] - yhat[seen]) ** 2)), 1e-30)
        prior = 1.0 / np.broadcast_to(self.P0, theta.shape)
        info = J[seen].T @ J[seen] / s2 + np.diag(prior)
        P = np.linalg.inv(info)
        self._U, self._D = _ud_factor(0.5 * (P + P.T))
        # replay the warm-up with the fitted parameters and no update (D = 0) to set the
        # signal windows, operator states and sensitivities
        self._theta = theta.copy()
        arrays = self._arrays(self._H + len(u))
        arrays[0][self._H:] = u
        D, self._D = self._D, np.zeros_like(self._D)
        n = len(u)
        self._run(arrays, self._H, 0, y, np.empty((n, len(theta))), np.empty(n), np.empty(n))
        self._D = D
        self._theta = theta.copy()
        self._lam = np.array([s2])
        for dst, src in zip(self._windows, arrays, strict=True):
            if len(dst) > 1:
                dst[:] = src[-len(dst):]

    # ----------------------------------------------------------------- one sample
    def update(self, u_k: float, y_k: float) -> np.ndarray:
        """Process one sample ``(u(k), y(k))``; returns the estimate theta(k).

        During the warm-up the sample is stored and ``theta0`` is returned; the sample that
        completes it triggers the off-line fit. The prediction error and the prediction of the
        sample are left in :attr:`e` and :attr:`yhat`.

        Parameters
        ----------
        u_k : float
            Input u(k), finite (the operators cannot be propagated otherwise).
        y_k : float
            Measured y(k); when not finite the model runs on and nothing is learned.

        Returns
        -------
        ndarray
            A copy of theta(k), in the order of :attr:`names`.
        """
        if (self._ready and not self.warming_up and isinstance(u_k, float)
                and isinstance(y_k, float) and u_k - u_k == 0.0):  # the real-time path
            return self._update_one(u_k, y_k)
        u, y = sample_arrays(u_k, y_k)
        self._require_start()
        history = np.empty((1, len(self.names)))
        errors, yhats = np.zeros(1), np.zeros(1)
        self._process(u, y, history, errors, yhats)
        return history[0].copy()

    def _update_one(self, u_k: float, y_k: float) -> np.ndarray:
        """One sample after the warm-up: one compiled call on the signal windows, in place."""
        U, W1, W2, Y, S1, SW2, SY, PH, SPH = self._windows
        recursion_one(self._mode, self._theta, self._U, self._D, self._lam, self.gamma, self.k,
                      self.layout_, self._rn, U, W1, W2, Y, S1, SW2, SY, PH, SPH,
                      self._p, self._SP, u_k / self._su, y_k / self._sy, self._K, self._last)
        self.k += 1
        if y_k - y_k != 0.0:
            self.n_skipped += 1
        self.e, self.yhat = float(self._last[0] * self._sy), float(self._last[1] * self._sy)
        return self._to_record(self._model_theta(self._theta))

    def _process(self, u, y, history, errors, yhats, progress=None) -> int:
        """Warm-up and recursion over a block of samples; returns the warm-up samples taken."""
        n = len(u)
        self.n_skipped += int(np.count_nonzero(~np.isfinite(y)))
        w = self._collect(u, y, history)
        errors[:w], yhats[:w] = np.nan, np.nan
        if w == n:
            return w
        H = self._H
        buffers = self._buffers  # one chunk long, allocated once
        same = self.form == "output-error"  # the recursion's coordinates are the model's
        raw = history if same else np.empty((n, len(self._theta)))
        for a in range(w, n, self.chunk):
            b = min(n, a + self.chunk)
            arrays = [x[: H + b - a] for x in buffers]
            for dst, src in zip(arrays, self._windows, strict=True):
                if len(src) > 1:
                    dst[:H] = src[1:]
            arrays[0][H:] = u[a:b] / self._su
            self._run(arrays, H, self.k, y[a:b] / self._sy, raw[a:b], errors[a:b], yhats[a:b])
            self.k += b - a
            for dst, src in zip(self._windows, arrays, strict=True):
                if len(dst) > 1:
                    dst[:] = src[-len(dst):]
            if progress is not None:
                progress(b, n)
        history[w:] = self._to_record(raw[w:] if same else self._model_theta(raw[w:]))
        errors[w:] *= self._sy
        yhats[w:] *= self._sy
        self.e, self.yhat = float(errors[-1]), float(yhats[-1])
        return w

    def _run(self, arrays, start, k0, y, history, errors, yhats) -> None:
        U, W1, W2, Y, S1, SW2, SY, PH, SPH = arrays
        recursion_run(self._mode, self._theta, self._U, self._D, self._lam, self.gamma,
                      k0, self.layout_, self._rn, U, W1, W2, Y, S1, SW2, SY, PH, SPH,
                      self._p, self._SP, start, y, history, errors, yhats, self._K)

    # ----------------------------------------------------------------- a record
    def fit(
        self, record: Record, progress: Callable[[int, int], None] | None = None
    ) -> IdentificationResult:
        """Restart (:meth:`reset`) and run over a whole record, from rest.

        Parameters
        ----------
        record : Record
            Input ``u`` and measured output ``y`` at :attr:`fs`; it must hold more samples than
            the warm-up.
        progress : callable, optional
            Called as ``progress(k, n)`` after each chunk of samples.

        Returns
        -------
        IdentificationResult
            As :meth:`partial_fit`; the same for two calls on the same record.
        """
        u, _, name = record_signals(record, self.fs)
        self.reset()
        self._place(u)
        w, done = self._warmup_take(u)
        if self.warming_up and (not done or w >= len(u)):
            if done or self.warmup != "sweep":
                takes = w if done else self.warmup
                need = f"{takes + 1} samples: the warm-up takes {takes}"
            else:
                need = (f"{self.min_warmup + 1} samples, and an input that sweeps the range "
                        "of the thresholds: the warm-up lasts until it has")
            raise ValueError(f"record {name!r}: {len(u)} samples are too few for the PI "
                             f"recursion (expected at least {need})")
        return self.partial_fit(record, progress=progress)

    def _place(self, u: np.ndarray) -> None:
        """Start with the given thresholds, or with thresholds placed over ``u``'s range."""
        if not self._ready:
            self._start(pi_thresholds(u, self._structure().n_operators))

    def partial_fit(
        self, record: Record, progress: Callable[[int, int], None] | None = None
    ) -> IdentificationResult:
        """Run the recursion over a record from the current state, keeping the history.

        Parameters
        ----------
        record : Record
            Input ``u`` and measured output ``y`` at :attr:`fs`. Without thresholds from the
            constructor or an earlier record they are placed over this record's input range.
        progress : callable, optional
            Called as ``progress(k, n)`` after each chunk of samples.

        Returns
        -------
        IdentificationResult
            ``method="pi-recursive"``; ``history`` has one row per sample in the model's
            parameters (:attr:`names`; ``theta0`` during a warm-up); ``converged_at`` is the
            first sample after which the estimate stays within ``epsilon``; ``info`` holds the
            prediction errors (NaN during the warm-up and at skipped samples) and their RMS
            over the last 10 % of the recursion's samples.
        """
        u, y, _ = record_signals(record, self.fs)
        self._place(u)
        n, before = len(u), self.n_skipped
        history = np.empty((n, len(self.names)))
        errors, yhats = np.zeros(n), np.zeros(n)
        t0, warm_before = time.perf_counter(), self.warmup_seconds_
        w = self._process(u, y, history, errors, yhats, progress)
        self._warn_skipped(before)
        tail = errors[w:][-max(1, (n - w) // 10):]
        tail = tail[np.isfinite(tail)]
        info = {
            "rms_prediction_error_last10": float(np.sqrt(np.mean(tail**2))) if tail.size
            else None,
            "lambda_inv": float(self.lam),
            "thresholds": self.thresholds_.tolist(),
            "prediction_errors": errors,
            "stable": bool(self.model.is_stable()),
            "seconds": time.perf_counter() - t0,
            "warmup_seconds": self.warmup_seconds_ - warm_before,
            "warmup_samples": w,
            "warm_fit": None if self.warm_result_ is None else self.warm_result_.info,
        }
        settings = {**self.settings, "samples": n}
        return IdentificationResult(
            self.model, "pi-recursive", settings, history=history,
            converged_at=converged_at(history, self.epsilon), info=info,
        )


def _ud_factor(P: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``P = U diag(D) U'`` with ``U`` unit upper triangular (Cholesky of the reversed matrix)."""
    L = np.linalg.cholesky(P[::-1, ::-1])
    Ut = L[::-1, ::-1]
    d = np.diag(Ut).copy()
    return Ut / d, d**2


# =========================================================================== off-line
def _scale_weights(theta: np.ndarray, structure: PIStructure, factor: float) -> np.ndarray:
    """``theta`` (a vector, or one per row) with its weights multiplied by ``factor``.

    With unit-DC-gain L1 and L2, ``w1`` is in input units and ``w2`` in output units, so the
    weights alone carry units (output per input): with ``u = s_u un`` and ``y = s_y yn`` the
    thresholds are ``s_u`` times and the weights ``s_y / s_u`` times their normalised values.
    """
    out = np.array(theta, dtype=float)
    out[..., structure.slices()["mu"]] *= factor
    return out


def _weights_given_blocks(theta: np.ndarray, un: np.ndarray, yn: np.ndarray, rows: np.ndarray,
                          r: np.ndarray, structure: PIStructure,
                          fit_offset: bool) -> tuple[np.ndarray, float]:
    """``theta`` with its weights (and the offset) set by linear least squares for its L1 and
    L2: exact, since the output is linear in both."""
    theta = np.array(theta, dtype=float)
    mu = structure.slices()["mu"]
    theta[mu] = 0.0
    _, J = pi_output_sensitivities(PISandwich(theta, r, structure), un)
    A = J[rows][:, mu]
    if fit_offset:
        A = np.column_stack([A, np.ones(len(rows))])
    n = structure.n_operators
    A = np.vstack([A, np.sqrt(RIDGE * len(rows)) * np.eye(n, A.shape[1])])
    coef, *_ = np.linalg.lstsq(A, np.r_[yn[rows], np.zeros(n)], rcond=None)
    theta[mu] = coef[:n]
    return theta, float(coef[-1]) if fit_offset else 0.0


def _arx_blocks(un: np.ndarray, yn: np.ndarray, rows: np.ndarray,
                structure: PIStructure) -> np.ndarray | None:
    """L1 and L2 of the linear sandwich's ARX fit (:func:`hystid.identify.offline.linear_start`,
    its monic numerators rescaled to unit DC gain); None when its roots do not split."""
    s = structure
    duhem = Structure(n1a=s.n1a, n1b=s.n1b - 1, n2a=s.n2a, n2b=s.n2b - 1, q1=s.q1, q2=s.q2)
    filled = np.interp(np.arange(len(yn)), rows, yn[rows])
    lin = linear_start(Record(un, filled, 1.0, name="normalised"), duhem, with_offset=True)
    if lin is None:
        return None
    values = dict(zip(duhem.names, lin[0], strict=True))
    theta = np.zeros(len(s.names))
    for block, na, nb in (("1", s.n1a, s.n1b), ("2", s.n2a, s.n2b)):
        a = np.array([values[f"a{block}{i}"] for i in range(1, na + 1)])
        c = np.array([values[f"b{block}{j}"] for j in range(1, nb)])
        lead = (1.0 + a.sum()) / (1.0 + c.sum())
        for i, v in enumerate(a, start=1):
            theta[s.names.index(f"a{block}{i}")] = v
        for j, v in enumerate(c, start=2):
            theta[s.names.index(f"b{block}{j}")] = lead * v
    return theta if np.isfinite(theta).all() else None


class _NormalisedFit(NamedTuple):
    """An off-line fit on normalised signals (:func:`_solve_normalised`)."""

    theta: np.ndarray
    y0: float
    rms: float
    nfev: int
    message: str
    start: str

    def info(self, r: np.ndarray, u_scale: float, y_scale: float) -> dict[str, Any]:
        """The fit's report in record units (RMS residual, thresholds, scales)."""
        return {"rms_residual": self.rms * y_scale, "nfev": self.nfev, "message": self.message,
                "start": self.start, "thresholds": r.tolist(),
                "scales": {"u": u_scale, "y": y_scale}}


def _solve_normalised(
    un: np.ndarray, yn: np.ndarray, weight: np.ndarray, r: np.ndarray, structure: PIStructure,
    theta0: np.ndarray | None, fit_offset: bool, max_nfev: int, tol: float,
) -> _NormalisedFit:
    """Output-error least squares on normalised signals, from several starts.

    Minimises ``sum (yhat(k) + y0 - yn(k))^2`` over the samples with ``weight`` (``yhat`` the
    free run from rest on ``un``, thresholds ``r`` in normalised input units) with
    :func:`scipy.optimize.least_squares` in reflection coefficients of L1 and L2 and, with
    ``fit_offset``, the normalised sensor offset ``y0``. The starts (:func:`_starts`) are run
    for :data:`SCREEN_NFEV` evaluations each; the :data:`POLISHED` best are polished.

    Returns
    -------
    _NormalisedFit
        Normalised parameters and offset, RMS residual and the solver's report.
    """
    rows = np.flatnonzero(weight)
    problem = _PIOutputError(un, yn, rows, r, structure, fit_offset)
    starts = _starts(un, yn, rows, r, structure, theta0, fit_offset)
    screened = []
    for label, (theta, y0) in starts.items():
        sol = problem.solve(problem.to_z(theta, y0),
                            SCREEN_NFEV if len(starts) > 1 else max_nfev, tol)
        screened.append((sol.cost, label, sol))
    screened.sort(key=lambda item: item[0])
    polished = []
    for _, label, sol in screened[:POLISHED]:
        if len(starts) > 1:
            sol = problem.solve(sol.x, max_nfev, tol)
        polished.append((sol.cost, label, sol))
    _, label, sol = min(polished, key=lambda item: item[0])
    theta, y0 = problem.split(sol.x)
    rms = float(np.sqrt(np.mean(problem.evaluate(sol.x)["data"] ** 2)))
    return _NormalisedFit(theta, y0, rms, int(sol.nfev), str(sol.message), label)


def _starts(un: np.ndarray, yn: np.ndarray, rows: np.ndarray, r: np.ndarray,
            structure: PIStructure, theta0: np.ndarray | None,
            fit_offset: bool) -> dict[str, tuple[np.ndarray, float]]:
    """``theta0`` alone when given; else ``L1 = L2 = z^-1`` and the linear sandwich's ARX
    blocks, each with the weights (and offset) that fit best for its blocks."""
    if theta0 is not None:
        if not PISandwich(theta0, r, structure).is_stable():
            raise ValueError("theta0: the start must have stable L1 and L2")
        return {"theta0": (theta0, 0.0)}
    delay = np.zeros(len(structure.names))
    blocks = {"L1 = L2 = z^-1": delay}
    arx = _arx_blocks(un, yn, rows, structure)
    if arx is not None:
        sl = structure.slices()
        l1 = np.r_[sl["a1"], sl["b1"]]
        blocks["ARX"] = arx
        blocks["L1 = z^-1, ARX L2"] = np.where(np.isin(np.arange(len(arx)), l1), 0.0, arx)
        blocks["ARX L1, L2 = z^-1"] = np.where(np.isin(np.arange(len(arx)), l1), arx, 0.0)
    unique: dict[str, np.ndarray] = {}  # a structure without free L1 terms makes mixtures twins
    for label, theta in blocks.items():
        if not any(np.array_equal(theta, other) for other in unique.values()):
            unique[label] = theta
    return {label: _weights_given_blocks(theta, un, yn, rows, r, structure, fit_offset)
            for label, theta in unique.items()}


class _PIOutputError:
    """The output-error problem on normalised signals, in ``z = [reflection coefficients of
    L1 and L2 | the other parameters | y0 (with an offset)]``."""

    def __init__(self, un: np.ndarray, yn: np.ndarray, rows: np.ndarray, r: np.ndarray,
                 structure: PIStructure, fit_offset: bool) -> None:
        s = self.structure = structure
        self.un, self.r, self.rows, self.target = un, r, rows, yn[rows]
        self.fit_offset = fit_offset
        self.n = len(s.names)
        sl, index = s.slices(), np.arange(self.n)
        self.rp = Reflections([index[sl["a1"]], index[sl["a2"]]], self.n)
        self.ones = np.ones((len(rows), int(fit_offset)))
        self.mu = index[sl["mu"]]
        self.ridge = np.sqrt(RIDGE * len(rows))
        self.ridge_rows = np.zeros((len(self.mu), self.n + int(fit_offset)))
        self.ridge_rows[np.arange(len(self.mu)), self.mu] = self.ridge
        self._cache: dict[str, Any] = {}

    def to_z(self, theta: np.ndarray, y0: float) -> np.ndarray:
        """Search coordinates of a parameter vector and an offset."""
        return np.r_[self.rp.to_z(theta), [y0] * self.fit_offset]

    def split(self, z: np.ndarray) -> tuple[np.ndarray, float]:
        """Parameters and offset of ``z``."""
        return self.rp.to_theta(z[: self.n])[0], float(z[self.n]) if self.fit_offset else 0.0

    def evaluate(self, z: np.ndarray) -> dict[str, Any]:
        """Residuals and Jacobian at ``z``, folded (:func:`_folded`), and the data residuals
        (``data``, unfolded); cached for the last ``z``."""
        if self._cache.get("z") is None or not np.array_equal(self._cache["z"], z):
            theta, dtheta = self.rp.to_theta(z[: self.n])
            with np.errstate(over="ignore", invalid="ignore"):
                yhat, J = pi_output_sensitivities(PISandwich(theta, self.r, self.structure),
                                                  self.un)
            y0 = z[self.n] if self.fit_offset else 0.0
            data = yhat[self.rows] + y0 - self.target
            r = np.r_[data, self.ridge * theta[self.mu]]
            J = np.vstack([np.hstack([J[self.rows] @ dtheta, self.ones]), self.ridge_rows])
            self._cache = {"z": z.copy(), "data": data, **_folded(J, r)}
        return self._cache

    def solve(self, z0: np.ndarray, max_nfev: int, tol: float):
        """``least_squares`` from ``z0`` within the reflection bounds."""
        lo, hi = self.rp.bounds()
        lo = np.r_[lo, [-np.inf] * self.fit_offset]
        hi = np.r_[hi, [np.inf] * self.fit_offset]
        with np.errstate(over="ignore", invalid="ignore"):
            return least_squares(lambda z: self.evaluate(z)["r"], np.clip(z0, lo, hi),
                                 jac=lambda z: self.evaluate(z)["J"], bounds=(lo, hi),
                                 method="trf", ftol=tol, xtol=tol, gtol=tol, max_nfev=max_nfev,
                                 x_scale="jac")


def _folded(J: np.ndarray, r: np.ndarray) -> dict[str, np.ndarray]:
    """``[J | r]`` folded into its QR triangle ``[R | c; 0 | rho]``: the residuals ``[c, rho]``
    and the Jacobian ``[R; 0]`` have the norm, gradient and ``J'J`` of the full problem, so
    ``least_squares`` takes the same steps on a square problem instead of a tall one (its
    SVD per iteration then costs nothing). A non-finite ``[J | r]`` gives non-finite
    residuals of the same length (the solver takes that as a failed step)."""
    A = np.column_stack([J, r])
    width = A.shape[1]
    if not np.all(np.isfinite(A)):
        return {"r": np.full(width, np.nan), "J": np.zeros((width, width - 1))}
    tri = triangle_of(A)
    return {"r": tri[:, -1].copy(), "J": tri[:, :-1].copy()}


def _structure_and_thresholds(
    u: np.ndarray, thresholds: np.ndarray | str | None, structure: PIStructure | None,
    n_operators: int,
) -> tuple[PIStructure, np.ndarray]:
    """The structure and the thresholds (record units): given, or placed over ``u`` by a rule
    of :data:`hystid.thresholds.RULES` (the paper's ``"range"`` when None)."""
    if structure is not None:
        n_operators = structure.n_operators
    if thresholds is None:
        thresholds = "range"
    if isinstance(thresholds, str):
        if thresholds not in RULES:
            raise ValueError(f"thresholds: expected an array or one of {', '.join(RULES)}, "
                             f"got {thresholds!r}")
        r = RULES[thresholds](u, n_operators)
    else:
        r = np.asarray(thresholds, dtype=float).ravel()
    s = structure or PIStructure(n_operators=len(r))
    if len(r) != s.n_operators:
        raise ValueError(f"thresholds: expected {s.n_operators} values for the structure, got "
                         f"{len(r)}")
    return s, r


def fit_pi_output_error(
    record: Record,
    thresholds: np.ndarray | str = "swing",
    structure: PIStructure | None = None,
    *,
    n_operators: int = N_OPERATORS,
    theta0: np.ndarray | None = None,
    offset: bool = True,
    skip: int | None = None,
    max_nfev: int = 200,
    tol: float = 1e-8,
    name: str = "identified PI sandwich",
) -> IdentificationResult:
    """Identify the PI sandwich off-line by output-error least squares (the reference).

    The steps, as in the off-line Duhem fit (:func:`hystid.identify.offline.fit_output_error`):
    :func:`~hystid.identify.prepare.prepare` the record (excitation check, rest level, robust
    scales, outliers and saturation left out of the cost, burn-in when it does not start at
    rest); fit on the input less its rest over its scale and the output over its scale, so that
    the result does not depend on the units; map the weights and thresholds back and place the
    model at the record's rest level, sensor offset, input envelope and units.

    The fit minimises ``sum_k (y(k) - yhat(k | theta) - y0)^2`` of the free run from rest with
    :func:`scipy.optimize.least_squares` (trust-region reflective, exact Jacobian), in the
    off-line Duhem fit's search coordinates (:class:`~hystid.identify.constraints.Reflections`):
    the denominators of L1 and L2 as reflection coefficients inside the unit interval, so the
    model stays stable. A small ridge (:data:`RIDGE`, on the normalised weights) keeps the
    weights of operators the input hardly moves from drifting. The starts: ``L1 = L2 = z^-1``,
    the linear sandwich's ARX blocks and the two mixtures, each with the weights and the offset
    fitted by linear least squares (the output is linear in both); each runs for
    :data:`~hystid.identify.offline.SCREEN_NFEV` evaluations and the :data:`POLISHED` best are
    polished, as in the off-line Duhem fit.

    Parameters
    ----------
    record : Record
        Input ``u`` and measured output ``y``, in any units.
    thresholds : array_like or {"swing", "range"}
        Play-operator thresholds in the record's input units, or the rule that places them
        over the fitted samples (:mod:`hystid.thresholds`): ``"swing"`` (default) within the
        largest swing between two reversals of the input, so that every operator is reversed
        at least once; ``"range"`` the paper's, over the input's range.
    structure : PIStructure, optional
        Orders and delays (the paper's by default).
    n_operators : int
        Number of operators when neither ``thresholds`` nor ``structure`` say.
    theta0 : array_like, optional
        Start vector in record units instead of the default.
    offset : bool
        Estimate the sensor offset (default); without it the output is taken as zero at rest.
    skip : int, optional
        Leading samples simulated but left out of the cost; by default none for a record that
        starts at rest, else until the input has swept its range.
    max_nfev : int
        Maximum number of residual evaluations.
    tol : float
        ``ftol``, ``xtol`` and ``gtol`` of the solver.
    name : str
        Name of the identified model.

    Returns
    -------
    IdentificationResult
        ``method="pi-batch"``; ``info`` holds the RMS residual (record units), the solver's
        message, the scales, the offset and ``warnings`` (what the preparation found).
    """
    prep = prepare(record, skip=skip)
    s, r = _structure_and_thresholds(record.u[prep.fitted], thresholds, structure, n_operators)
    if not offset:
        prep.y_ref, prep.yn = 0.0, record.y / prep.y_scale
    su, sy = prep.u_scale, prep.y_scale
    theta0_n = None if theta0 is None else _scale_weights(
        np.asarray(theta0, dtype=float).ravel(), s, su / sy)
    fit = _solve_normalised(prep.un, prep.yn, prep.weight, r / su, s, theta0_n, offset,
                            max_nfev, tol)
    model = PISandwich(_scale_weights(fit.theta, s, sy / su), r, s, fs=record.fs, name=name,
                       u_rest=prep.u_rest, offset=prep.offset(fit.y0), envelope=prep.envelope,
                       units=record.units)
    info = {**fit.info(r, su, sy), "offset": model.offset, "at_rest": prep.at_rest,
            "skip": prep.skip, "warnings": list(prep.notes)}
    settings = {"n_operators": len(r), "offset": offset, "skip": prep.skip,
                "max_nfev": max_nfev, "tol": tol, "samples": record.n}
    return IdentificationResult(model, "pi-batch", settings, info=info)


def _zero_result(
    fit: _NormalisedFit, su: float, sy: float, r: np.ndarray, structure: PIStructure, fs: float,
    samples: int, *, max_nfev: int = 200, tol: float = 1e-8,
    name: str = "identified PI sandwich",
) -> IdentificationResult:
    """The result of :func:`_fit_normalised_from_zero` in record units (weights mapped back)."""
    model = PISandwich(_scale_weights(fit.theta, structure, sy / su), r, structure, fs=fs,
                       name=name)
    settings = {"n_operators": len(r), "max_nfev": max_nfev, "tol": tol, "samples": samples}
    return IdentificationResult(model, "pi-batch", settings, info=fit.info(r, su, sy))


def _zero_scales(u: np.ndarray, y: np.ndarray) -> tuple[float, float]:
    """Input and output scales about zero (:func:`~hystid.identify.prepare.scales`) of the
    samples with a finite output: the recursion's units."""
    su, _, sy = scales(u, y[np.isfinite(y)], 0.0)
    return su or 1.0, sy


def _fit_normalised_from_zero(
    u: np.ndarray, y: np.ndarray, r: np.ndarray, structure: PIStructure, *,
    max_nfev: int = 200, tol: float = 1e-8,
) -> tuple[_NormalisedFit, float, float]:
    """:func:`_solve_normalised` at rest at ``u = 0`` without offset, on ``u / su`` and
    ``y / sy`` (:func:`_zero_scales`); samples with a non-finite ``y`` are left out of the cost.

    Returns
    -------
    tuple
        The normalised fit, ``su`` and ``sy``.
    """
    u = np.ascontiguousarray(u, dtype=float)
    y = np.ascontiguousarray(y, dtype=float)
    su, sy = _zero_scales(u, y)
    with np.errstate(invalid="ignore"):
        fit = _solve_normalised(u / su, y / sy, np.isfinite(y), r / su, structure, None, False,
                                max_nfev, tol)
    return fit, su, sy


# =========================================================================== entry point
def identify_pi(
    record: Record,
    method: str = "recursive",
    *,
    progress: Callable[[int, int], None] | None = None,
    **settings: Any,
) -> IdentificationResult:
    """Identify the PI sandwich from a record (``hystid identify REC --model pi``).

    Parameters
    ----------
    record : Record
        Input ``u`` and measured output ``y`` (starting at rest for ``"recursive"``).
    method : {"recursive", "batch"}
        ``"recursive"``: :class:`PIRecursiveIdentifier` (on-line, the paper's settings);
        ``"batch"``: :func:`fit_pi_output_error` (off-line reference).
    progress : callable, optional
        ``progress(k, n)`` during the recursive run.
    **settings
        Passed to the identifier's constructor or to :func:`fit_pi_output_error`.

    Returns
    -------
    IdentificationResult
        The model, its parameter history (recursive) and the run's information.
    """
    if method == "recursive":
        settings.setdefault("fs", record.fs)
        return PIRecursiveIdentifier(**settings).fit(record, progress=progress)
    if method == "batch":
        return fit_pi_output_error(record, **settings)
    raise ValueError(f"method: expected 'recursive' or 'batch', got {method!r}")
