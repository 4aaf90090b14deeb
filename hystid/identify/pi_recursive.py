"""Identification of the PI sandwich (eqs. 29-31): recursive on-line, and off-line for reference.

The recursive identifier runs the paper's extended recursion (eqs. 15-19) with the paper's PI
settings, ``P(0) = 1e6 I``, ``theta(0) = 0.001`` and the stop index ``epsilon = 1e-4``::

    e(k)      = y(k) - yhat(k | theta(k-1))                                          (15)
    theta(k)  = theta(k-1) + K(k) e(k)                                               (16)
    K(k)      = P(k-1) h(k) / [h(k)' P(k-1) h(k) + mu(k) Lambda^-1(k)]               (17)
    P(k)      = [(I - K h') P(k-1) (I - K h')' + K Lambda^-1 K'] / mu(k)             (18)
    Lambda^-1(k) = Lambda^-1(k-1) + rho(k) [e(k)^2 - Lambda^-1(k-1)]                 (19)

with ``rho(k) = (k+1)^-gamma`` and ``mu(k) = rho(k-1)/rho(k) (1 - rho(k))``. The PI model is
not linear in its parameters (L1 acts through the play operators), so ``h(k)`` is the gradient
``d yhat(k) / d theta`` computed along the recursion with the current estimates (forward
sensitivities through eqs. 29-31; ``dp_i/dw1`` is 1 while operator ``i`` moves, 0 while it
holds). Two predictors are offered:

* ``predictor="output-error"`` (default): ``yhat`` and its gradient come from the model's own
  past outputs (a recursive prediction-error method). Sensor noise does not enter ``h``.
* ``predictor="equation-error"``: the paper-like regressor, whose L2 part holds the *measured*
  past outputs ``-y(k-1), -y(k-2)`` (as the paper's ``h(k)`` holds ``-Delta y(k-i)``).

After every update the estimate is kept stable (poles of L1 and L2 inside the unit circle): a
step that would leave that set is halved until it does not (at most 30 times, then dropped).

:func:`fit_pi_output_error` is the off-line reference: output-error least squares (scipy, exact
Jacobian, poles kept inside the circle by reflection coefficients) started from a linear fit of
the weights. :func:`identify_pi` is the entry point of ``hystid identify REC --model pi``.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from numba import njit
from scipy.optimize import least_squares

from ..model import InitialCondition
from ..pi import N_OPERATORS, PISandwich, PIStructure, pi_thresholds
from ..records import Record
from .constraints import K_MAX, poly_to_reflection, reflection_to_poly
from .result import IdentificationResult, converged_at

__all__ = [
    "PIRecursiveIdentifier",
    "fit_pi_output_error",
    "identify_pi",
    "pi_output_sensitivities",
]

PREDICTORS = ("output-error", "equation-error")


# =========================================================================== compiled kernels
@njit(cache=True, inline="always")
def _play(v, p_prev, r):
    return max(v - r, min(v + r, p_prev))


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
    # eq. (29) and d w1 / d (a1, b1)
    w1 = 0.0
    for j in range(n1b):
        w1 += c[ib1 + j] * U[k - q1 - j]
    for i in range(n1a):
        w1 -= c[ia1 + i] * W1[k - 1 - i]
    W1[k] = w1
    for m in range(n1):
        s = 0.0
        for i in range(n1a):
            s -= c[ia1 + i] * S1[k - 1 - i, m]
        S1[k, m] = s
    for i in range(n1a):
        S1[k, ia1 + i] -= W1[k - 1 - i]
    for j in range(n1b):
        S1[k, ib1 + j] += U[k - q1 - j]
    # eq. (30): an operator that moves follows w1 (dp/dw1 = 1), one that holds keeps its state
    w2 = 0.0
    for m in range(nc):
        SW2[k, m] = 0.0
    for i in range(n):
        lo = w1 - r[i]
        hi = w1 + r[i]
        if lo > p[i]:
            p[i] = lo
            for m in range(n1):
                SP[i, m] = S1[k, m]
        elif hi < p[i]:
            p[i] = hi
            for m in range(n1):
                SP[i, m] = S1[k, m]
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
def _is_stable_poly(a):
    # Schur-Cohn step-down: 1 + a_1 z^-1 + ... stable iff every |k_m| < 1
    n = a.shape[0]
    c = a.copy()
    for m in range(n, 0, -1):
        km = c[m - 1]
        if not abs(km) < 1.0:
            return False
        if m > 1:
            d = 1.0 - km * km
            tmp = np.empty(m - 1)
            for i in range(m - 1):
                tmp[i] = (c[i] - km * c[m - 2 - i]) / d
            c[: m - 1] = tmp
    return True


@njit(cache=True)
def _admissible(theta, layout, c):
    full_coefficients(theta, layout, c)
    ia1, ib1, imu, ia2, ib2 = _layout_offsets(layout)
    return _is_stable_poly(c[ia1:ib1]) and _is_stable_poly(c[ia2:ib2])


@njit(cache=True)
def rpem_step(theta, P, lam, rho_prev, rho, layout, r, U, W1, W2, Y, S1, SW2, SY, p, SP, k,
              y_meas, equation_error, c, psi_c, psi, K, Ph):
    """One sample of the extended recursion (eqs. 15-19) on the PI sandwich.

    Updates ``theta``, ``P`` in place (``K`` too) and returns ``(e, Lambda^-1, yhat)``.
    """
    npar = theta.shape[0]
    nc = c.shape[0]
    full_coefficients(theta, layout, c)
    pi_step_sens(c, layout, r, U, W1, W2, Y, S1, SW2, SY, p, SP, k)
    yhat = Y[k]
    for m in range(nc):
        psi_c[m] = SY[k, m]
    free_gradient(psi_c, layout, psi)
    e = y_meas - yhat                                                    # (15)
    mu = rho_prev / rho * (1.0 - rho)
    lam = lam + rho * (e * e - lam)                                      # (19)
    hPh = 0.0
    for a in range(npar):
        s = 0.0
        for b in range(npar):
            s += P[a, b] * psi[b]
        Ph[a] = s
        hPh += psi[a] * s
    den = hPh + mu * lam
    if not den > 0.0:
        den = 1e-300
    for a in range(npar):
        K[a] = Ph[a] / den                                               # (17)
    # (18), Joseph form: (I - K h') P (I - K h')' + K lam K' = P - K Ph' - Ph K' + hPh K K' + ...
    for a in range(npar):
        for b in range(a, npar):
            v = (P[a, b] - K[a] * Ph[b] - Ph[a] * K[b] + (hPh + lam) * K[a] * K[b]) / mu
            P[a, b] = v
            P[b, a] = v
    # (16) with the step halved while it would leave the stable set
    step = 1.0
    old = theta.copy()
    for _ in range(31):
        for a in range(npar):
            theta[a] = old[a] + step * K[a] * e
        if _admissible(theta, layout, c):
            break
        step *= 0.5
    else:
        theta[:] = old
    if equation_error:
        # the paper-like regressor: past outputs are the measured ones (no output recursion)
        Y[k] = y_meas
        for m in range(nc):
            SY[k, m] = 0.0
    return e, lam, yhat


@njit(cache=True)
def rpem_run(theta, P, lam, gamma, k0, layout, r, U, W1, W2, Y, S1, SW2, SY, p, SP, start,
             ymeas, equation_error, history, errors, yhats):
    """Run :func:`rpem_step` from index ``start`` to the end; rows of ``history`` get theta."""
    npar = theta.shape[0]
    nc = S1.shape[1]
    c = np.empty(nc)
    psi_c = np.empty(nc)
    psi = np.empty(npar)
    K = np.empty(npar)
    Ph = np.empty(npar)
    for k in range(start, U.shape[0]):
        n = k0 + k - start + 1  # sample count since the start of the recursion (1, 2, ...)
        rho_prev = 1.0 if n == 1 else float(n) ** (-gamma)
        rho = float(n + 1) ** (-gamma)
        e, lam, yhat = rpem_step(theta, P, lam, rho_prev, rho, layout, r, U, W1, W2, Y, S1,
                                 SW2, SY, p, SP, k, ymeas[k - start], equation_error, c, psi_c,
                                 psi, K, Ph)
        history[k - start, :] = theta
        errors[k - start] = e
        yhats[k - start] = yhat
    return lam


# =========================================================================== helpers
def _layout(s: PIStructure) -> np.ndarray:
    return np.array([s.n1a, s.n1b, s.n_operators, s.n2a, s.n2b, s.q1, s.q2], dtype=np.int64)


def _n_full(s: PIStructure) -> int:
    return s.n1a + s.n1b + s.n_operators + s.n2a + s.n2b


def pi_output_sensitivities(
    model: PISandwich, u: np.ndarray, x0: InitialCondition | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """Simulated output and its Jacobian ``d yhat / d theta`` (``N x n_params``) from rest/x0."""
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


def _record_thresholds(record: Record, n_operators: int) -> np.ndarray:
    return pi_thresholds(record.u, n_operators)


# =========================================================================== recursive
class PIRecursiveIdentifier:
    """On-line identification of the PI sandwich by the extended recursion (eqs. 15-19).

    Configuration in the constructor, one sample per :meth:`update`, a record per :meth:`fit`;
    the intermediates of the last update are kept as attributes.

    Parameters
    ----------
    thresholds : array_like, optional
        Play-operator thresholds; needed before the first :meth:`update`. :meth:`fit` places
        them from the record's input range (:func:`hystid.pi.pi_thresholds`) when omitted.
    structure : PIStructure, optional
        Orders and delays; the paper's (eqs. 29, 31) with ``n_operators`` operators by default.
    n_operators : int
        Number of play operators when neither ``thresholds`` nor ``structure`` say (40).
    P0 : float
        Initial covariance ``P(0) = P0 I`` (the paper's 1e6).
    theta0 : float or array_like
        Initial estimate: one value for every parameter (the paper's 0.001) or a vector.
    epsilon : float
        Stop index (1e-4): the recursion has converged once no parameter changes by more than
        ``epsilon`` relative to its value (see :func:`hystid.identify.result.converged_at`).
    gamma : float
        Exponent of the convergence factor ``rho(k) = (k+1)^-gamma``: the paper's 9/13 forgets
        (``mu(k) < 1``); ``gamma = 1`` gives ``mu(k) = 1`` (no forgetting).
    lambda0 : float
        Initial ``Lambda^-1`` (estimated error variance, output units squared).
    predictor : {"output-error", "equation-error"}
        Where the past outputs in the regressor come from (see the module docstring).
    fs : float
        Sampling rate of the data in Hz (for the model); :meth:`fit` takes the record's.

    Attributes
    ----------
    theta : ndarray
        Current estimate.
    P : ndarray
        Current covariance matrix ``P(k)``.
    K : ndarray
        Gain of the last update.
    e : float
        Prediction error of the last update, ``y(k) - yhat(k)``.
    yhat : float
        Prediction of the last update.
    lam : float
        Current ``Lambda^-1(k)``.
    k : int
        Number of samples processed.
    """

    def __init__(
        self,
        thresholds: np.ndarray | None = None,
        structure: PIStructure | None = None,
        *,
        n_operators: int = N_OPERATORS,
        P0: float = 1e6,
        theta0: float | np.ndarray = 0.001,
        epsilon: float = 1e-4,
        gamma: float = 9.0 / 13.0,
        lambda0: float = 1.0,
        predictor: str = "output-error",
        fs: float = 30_000.0,
    ) -> None:
        if predictor not in PREDICTORS:
            raise ValueError(f"predictor: expected one of {PREDICTORS}, got {predictor!r}")
        for label, value in (("P0", P0), ("epsilon", epsilon), ("gamma", gamma),
                             ("lambda0", lambda0), ("fs", fs)):
            if not (np.isfinite(value) and value > 0):
                raise ValueError(f"{label}: expected a positive finite number, got {value!r}")
        if gamma > 1:
            raise ValueError(f"gamma: expected a value in (0, 1] (mu(k) <= 1), got {gamma!r}")
        self.thresholds = thresholds
        self.structure = structure
        self.n_operators = n_operators
        self.P0 = float(P0)
        self.theta0 = theta0
        self.epsilon = float(epsilon)
        self.gamma = float(gamma)
        self.lambda0 = float(lambda0)
        self.predictor = predictor
        self.fs = float(fs)
        self._ready = False

    # ----------------------------------------------------------------- state
    @property
    def settings(self) -> dict:
        """The configuration, for reports."""
        return {"P0": self.P0, "theta0": np.asarray(self.theta0).tolist(),
                "epsilon": self.epsilon, "gamma": self.gamma, "lambda0": self.lambda0,
                "predictor": self.predictor, "n_operators": self.structure_.n_operators
                if self._ready else self.n_operators}

    def reset(self, thresholds: np.ndarray | None = None) -> PIRecursiveIdentifier:
        """Start over from ``theta0``, ``P0`` at rest (optionally with new thresholds)."""
        if thresholds is not None:
            self.thresholds = thresholds
        if self.thresholds is None:
            raise ValueError(
                "thresholds: the identifier needs the play-operator thresholds before the first "
                "update; pass thresholds= (see hystid.pi.pi_thresholds) or call fit(record)"
            )
        r = np.ascontiguousarray(np.asarray(self.thresholds, dtype=float).ravel())
        s = self.structure or PIStructure(n_operators=len(r))
        if s.n_operators != len(r):
            raise ValueError(f"thresholds: expected {s.n_operators} values, got {len(r)}")
        # validates the thresholds and the start vector
        start = PISandwich(self._theta_start(s), r, s, fs=self.fs)
        self.structure_ = s
        self.thresholds_ = start.thresholds
        self.layout_ = _layout(s)
        npar, nc = len(s.names), _n_full(s)
        self.theta = start.theta.copy()
        self.P = self.P0 * np.eye(npar)
        self.K = np.zeros(npar)
        self.e = 0.0
        self.yhat = 0.0
        self.lam = self.lambda0
        self.k = 0
        self._H = s.history
        # signal windows: H past samples + the current one
        w = self._H + 1
        self._U, self._W1, self._W2, self._Y = (np.zeros(w) for _ in range(4))
        self._S1, self._SW2, self._SY = (np.zeros((w, nc)) for _ in range(3))
        self._p = np.zeros(len(r))
        self._SP = np.zeros((len(r), nc))
        self._c = np.empty(nc)
        self._psi_c = np.empty(nc)
        self._psi = np.empty(npar)
        self._Ph = np.empty(npar)
        self._ready = True
        return self

    def _theta_start(self, s: PIStructure) -> np.ndarray:
        n = len(s.names)
        if np.isscalar(self.theta0):
            return np.full(n, float(self.theta0))
        theta = np.asarray(self.theta0, dtype=float).ravel()
        if theta.shape != (n,):
            raise ValueError(f"theta0: expected a scalar or {n} values, got shape {theta.shape}")
        return theta

    @property
    def model(self) -> PISandwich:
        """The current estimate as a :class:`~hystid.pi.PISandwich`."""
        if not self._ready:
            raise ValueError("no estimate yet: call update() or fit() first")
        return PISandwich(self.theta, self.thresholds_, self.structure_, fs=self.fs,
                          name="identified PI sandwich")

    # ----------------------------------------------------------------- one sample
    def update(self, u_k: float, y_k: float) -> float:
        """Process one sample ``(u(k), y(k))``; returns the prediction error ``e(k)``."""
        if not self._ready:
            self.reset()
        u_k, y_k = float(u_k), float(y_k)
        if not (np.isfinite(u_k) and np.isfinite(y_k)):
            raise ValueError(f"update: non-finite sample u={u_k!r}, y={y_k!r}")
        for arr in (self._U, self._W1, self._W2, self._Y, self._S1, self._SW2, self._SY):
            arr[:-1] = arr[1:]
        self._U[-1] = u_k
        self.k += 1
        n = self.k
        rho_prev = 1.0 if n == 1 else float(n) ** (-self.gamma)
        rho = float(n + 1) ** (-self.gamma)
        self.e, self.lam, self.yhat = rpem_step(
            self.theta, self.P, self.lam, rho_prev, rho, self.layout_, self.thresholds_,
            self._U, self._W1, self._W2, self._Y, self._S1, self._SW2, self._SY, self._p,
            self._SP, self._H, y_k, self.predictor == "equation-error", self._c, self._psi_c,
            self._psi, self.K, self._Ph,
        )
        return self.e

    # ----------------------------------------------------------------- a record
    def fit(
        self, record: Record, *, progress: Callable[[int, int], None] | None = None,
        chunk: int = 5000,
    ) -> IdentificationResult:
        """Run the recursion over a record (from rest), keeping the parameter history.

        Parameters
        ----------
        record : Record
            Input ``u`` and measured output ``y``.
        progress : callable, optional
            Called as ``progress(k, n)`` after each chunk of samples.
        chunk : int
            Samples per compiled call between progress reports.

        Returns
        -------
        IdentificationResult
            ``method="pi-recursive"``; ``history`` has one row per sample; ``converged_at``
            is the first sample after which the estimate stays within ``epsilon``;
            ``info`` holds the prediction errors' RMS over the last 10 % and the final
            ``Lambda^-1``.
        """
        if not hasattr(record, "u") or not hasattr(record, "y"):
            raise ValueError(f"record: expected a hystid Record with u and y, got {record!r}")
        u = np.ascontiguousarray(record.u, dtype=float)
        y = np.ascontiguousarray(record.y, dtype=float)
        if len(u) < 2 or not (np.all(np.isfinite(u)) and np.all(np.isfinite(y))):
            raise ValueError("record: expected at least 2 finite samples of u and y")
        self.fs = float(record.fs)
        self.reset(self.thresholds if self.thresholds is not None
                   else _record_thresholds(record, self.structure.n_operators
                                           if self.structure else self.n_operators))
        n, H = len(u), self._H
        nc = _n_full(self.structure_)
        U = np.concatenate([np.zeros(H), u])
        W1, W2, Y = (np.zeros(H + n) for _ in range(3))
        S1, SW2, SY = (np.zeros((H + n, nc)) for _ in range(3))
        history = np.empty((n, len(self.theta)))
        errors = np.empty(n)
        yhats = np.empty(n)
        for a in range(0, n, chunk):
            b = min(n, a + chunk)
            self.lam = rpem_run(
                self.theta, self.P, self.lam, self.gamma, a, self.layout_, self.thresholds_,
                U[: H + b], W1[: H + b], W2[: H + b], Y[: H + b], S1[: H + b], SW2[: H + b],
                SY[: H + b], self._p, self._SP, H + a, y[a:b],
                self.predictor == "equation-error", history[a:b], errors[a:b], yhats[a:b],
            )
            if progress is not None:
                progress(b, n)
        self.k = n
        self.e, self.yhat = float(errors[-1]), float(yhats[-1])
        # leave the on-line windows where the batch ended, so update() can continue
        for dst, src in ((self._U, U), (self._W1, W1), (self._W2, W2), (self._Y, Y),
                         (self._S1, S1), (self._SW2, SW2), (self._SY, SY)):
            dst[:] = src[-(H + 1):]
        tail = errors[-max(1, n // 10):]
        info = {
            "rms_prediction_error_last10": float(np.sqrt(np.mean(tail**2))),
            "lambda_inv": float(self.lam),
            "thresholds": self.thresholds_.tolist(),
            "prediction_errors": errors,
        }
        settings = {**self.settings, "samples": n}
        return IdentificationResult(
            self.model, "pi-recursive", settings, history=history,
            converged_at=converged_at(history, self.epsilon), info=info,
        )


# =========================================================================== off-line
def _weights_by_linear_ls(model: PISandwich, u: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Weights minimising the output error for fixed L1, L2 (y is linear in the weights)."""
    _, J = pi_output_sensitivities(model, u)
    sl = model.structure.slices()["mu"]
    A = J[:, sl]
    # the contribution of the weights is exactly A @ mu (L1, L2 fixed, from rest)
    mu, *_ = np.linalg.lstsq(A, y, rcond=None)
    return mu


def fit_pi_output_error(
    record: Record,
    thresholds: np.ndarray | None = None,
    structure: PIStructure | None = None,
    *,
    n_operators: int = N_OPERATORS,
    theta0: np.ndarray | None = None,
    max_nfev: int = 200,
    tol: float = 1e-10,
    name: str = "identified PI sandwich",
) -> IdentificationResult:
    """Identify the PI sandwich off-line by output-error least squares (the reference).

    Minimises ``sum_k (y(k) - yhat(k | theta))^2`` of the free-run simulation from rest with
    ``scipy.optimize.least_squares`` (trust region, exact Jacobian). The denominators of L1 and
    L2 are searched as reflection coefficients in (-1, 1), so the model stays stable. The
    default start is ``L1 = L2 = z^-1`` with the weights fitted by linear least squares (the
    output is linear in the weights).

    Parameters
    ----------
    record : Record
        Input ``u`` and measured output ``y``, starting at rest.
    thresholds : array_like, optional
        Play-operator thresholds; from the record's input range by default.
    structure : PIStructure, optional
        Orders and delays (the paper's by default).
    n_operators : int
        Number of operators when neither ``thresholds`` nor ``structure`` say.
    theta0 : array_like, optional
        Start vector instead of the default.
    max_nfev : int
        Maximum number of residual evaluations.
    tol : float
        ``ftol``, ``xtol`` and ``gtol`` of the solver.

    Returns
    -------
    IdentificationResult
        ``method="pi-batch"``; ``info`` holds the RMS residual and the solver's status.
    """
    u = np.ascontiguousarray(record.u, dtype=float)
    y = np.ascontiguousarray(record.y, dtype=float)
    if structure is not None:
        n_operators = structure.n_operators
    r = np.asarray(thresholds, float) if thresholds is not None else _record_thresholds(
        record, n_operators)
    s = structure or PIStructure(n_operators=len(r))
    names = s.names
    sl = s.slices()
    if theta0 is None:
        theta = np.zeros(len(names))
        start = PISandwich(theta, r, s, fs=record.fs)
        theta[sl["mu"]] = _weights_by_linear_ls(start, u, y)
    else:
        theta = np.asarray(theta0, dtype=float).ravel()
    model = PISandwich(theta, r, s, fs=record.fs, name=name)
    if not model.is_stable():
        raise ValueError("theta0: the start must have stable L1 and L2")
    groups = [np.arange(len(names))[sl["a1"]], np.arange(len(names))[sl["a2"]]]
    groups = [g for g in groups if len(g)]

    def to_theta(z):
        theta = np.array(z, float)
        dtheta = np.eye(len(z))
        for g in groups:
            theta[g], dtheta[np.ix_(g, g)] = reflection_to_poly(z[g])
        return theta, dtheta

    z0 = model.theta.copy()
    for g in groups:
        z0[g] = np.clip(poly_to_reflection(model.theta[g]), -K_MAX, K_MAX)
    lo = np.full(len(z0), -np.inf)
    hi = np.full(len(z0), np.inf)
    for g in groups:
        lo[g], hi[g] = -K_MAX, K_MAX
    cache: dict = {}

    def fun(z):
        theta, dth = to_theta(z)
        m = PISandwich(theta, r, s, fs=record.fs)
        yhat, J = pi_output_sensitivities(m, u)
        cache["z"], cache["J"] = z.copy(), J @ dth
        return yhat - y

    def jac(z):
        if "z" not in cache or not np.array_equal(cache["z"], z):
            fun(z)
        return cache["J"]

    sol = least_squares(fun, z0, jac=jac, bounds=(lo, hi), method="trf", ftol=tol, xtol=tol,
                        gtol=tol, max_nfev=max_nfev, x_scale="jac")
    theta = to_theta(sol.x)[0]
    model = PISandwich(theta, r, s, fs=record.fs, name=name)
    info = {"rms_residual": float(np.sqrt(np.mean(sol.fun**2))), "nfev": int(sol.nfev),
            "status": int(sol.status), "message": str(sol.message),
            "thresholds": r.tolist()}
    settings = {"n_operators": len(r), "max_nfev": max_nfev, "tol": tol, "samples": len(u)}
    return IdentificationResult(model, "pi-batch", settings, info=info)


# =========================================================================== entry point
def identify_pi(
    record: Record,
    method: str = "recursive",
    *,
    progress: Callable[[int, int], None] | None = None,
    **settings,
) -> IdentificationResult:
    """Identify the PI sandwich from a record (``hystid identify REC --model pi``).

    Parameters
    ----------
    record : Record
        Input ``u`` and measured output ``y``, starting at rest.
    method : {"recursive", "batch"}
        ``"recursive"``: :class:`PIRecursiveIdentifier` (on-line, the paper's settings);
        ``"batch"``: :func:`fit_pi_output_error` (off-line reference).
    progress : callable, optional
        ``progress(k, n)`` during the recursive run.
    **settings
        Passed to the identifier's constructor or to :func:`fit_pi_output_error`.
    """
    if method == "recursive":
        return PIRecursiveIdentifier(**settings).fit(record, progress=progress)
    if method == "batch":
        return fit_pi_output_error(record, **settings)
    raise ValueError(f"method: expected 'recursive' or 'batch', got {method!r}")
