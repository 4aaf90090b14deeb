"""The paper's extended recursive identification algorithm (ERIA), eqs. (12)-(19), as published.

Key-term separation (eq. 12) writes the incremental sandwich as ``dy(k) = h(k|theta)^T theta``
(eq. 13). The regressor ``h`` is built from internal signals ``w1_hat, w2_hat`` simulated with
the previous estimate, and the estimate follows

    e(k)        = dy(k) - h^T theta(k-1)                                      (15)
    theta(k)    = theta(k-1) + K(k) e(k)                                      (16)
    K(k)        = P(k-1) h / (h^T P(k-1) h + mu(k) Lambda^-1(k))              (17)
    P(k)        = [(I - K h^T) P(k-1) (I - K h^T)^T + K Lambda^-1(k) K^T] / mu(k)   (18)
    Lambda^-1(k) = Lambda^-1(k-1) + rho(k) [e(k)^2 - Lambda^-1(k-1)]          (19)

with ``rho(k) = (k+1)^(-9/13)`` and ``mu(k) = rho(k-1)/rho(k) (1 - rho(k))``.

Two readings had to be chosen where the printed text is ambiguous:

* the regressor entries of ``f1``, ``b1j`` and ``a1i`` follow eq. (7), where ``f`` is evaluated
  at ``w1(k-1)``: ``f1`` multiplies ``alpha |dw1(k-q2)| u(k-q2-q1-1)`` (the printed index
  ``u(k-q1-q2)`` does not reproduce ``dy``); with the true internal signals this regression is
  exact;
* eq. (19) is read as ``Lambda^-1(k) = Lambda^-1(k-1) + ...`` and updated before eq. (17).

Theorem 1's conditions are monitored: ``lambda_max(P)``, ``cond(P)``, ``Delta_1(k)`` and, when
the true parameters are given, ``beta(k) = h^T (theta - theta(k-1)) / e(k)``.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from ..kernels import offsets, step
from ..model import Structure
from ..validate import check_plain_duhem
from ._recursive import RecursiveIdentifier, admissible, extended, keep_tail

__all__ = ["ERIA", "DIAGNOSTICS"]

#: Columns of the diagnostics array kept per sample.
DIAGNOSTICS = ("e", "lambda_inv", "rho", "mu", "lambda_max", "cond_P", "delta1", "beta")


@njit(cache=True)
def regressor(theta, layout, U, W1, W2, Ym, L, h):
    """h(k | theta(k-1)) of eq. (13) at window index ``L`` (= sample k); fills ``h``."""
    n1a, n1b, n2a, n2b, q1, q2 = layout[0], layout[1], layout[2], layout[3], layout[4], layout[5]
    i_b2, i_alpha, i_f0, i_f1, i_b1, i_g0, i_a1, i_a2 = offsets(layout)
    alpha, f1, g0 = theta[i_alpha], theta[i_f1], theta[i_g0]
    kk = L - q2
    ad = abs(W1[kk] - W1[kk - 1])  # |dw1_hat(k - q2)|
    for j in range(1, n2b + 1):
        h[i_b2 + j - 1] = W2[kk - j] - W2[kk - j - 1]
    h[i_alpha] = -ad * W2[kk - 1]
    if i_f0 >= 0:
        w = W1[kk - 1]
        h[i_f0] = alpha * ad * (1.0 if w > 0 else (-1.0 if w < 0 else 0.0))
    h[i_f1] = alpha * ad * U[kk - 1 - q1]
    for j in range(1, n1b + 1):
        h[i_b1 + j - 1] = f1 * alpha * ad * U[kk - 1 - q1 - j] + g0 * (
            U[kk - q1 - j] - U[kk - q1 - j - 1])
    h[i_g0] = U[kk - q1] - U[kk - q1 - 1]
    for i in range(1, n1a + 1):
        h[i_a1 + i - 1] = -(f1 * alpha * ad * W1[kk - 1 - i] + g0 * (W1[kk - i] - W1[kk - i - 1]))
    for i in range(1, n2a + 1):
        h[i_a2 + i - 1] = -(Ym[L - i] - Ym[L - i - 1])


@njit(cache=True)
def eria_run(theta, P, scal, theta_good, layout, U, W1, W2, Yh, Ym, h, K, truth, theta_int,
             settings, u_in, y_in, history, diag):
    """ERIA over a chunk. ``scal = [k, lambda_inv, n_recoveries, first_recovery]``;
    ``settings = [P0, lambda_inv0, rho_exponent, kmax, recover, has_truth, mu_const,
    lambda_inv_min, fixed_internal]``."""
    npar = theta.shape[0]
    w = U.shape[0] - u_in.shape[0]
    P0, lam0, rexp, kmax = settings[0], settings[1], settings[2], settings[3]
    recover, has_truth = settings[4] > 0, settings[5] > 0
    mu_const, lam_min, fixed_internal = settings[6], settings[7], settings[8] > 0
    i_alpha = offsets(layout)[1]
    PH = np.empty(npar)
    for n in range(u_in.shape[0]):
        k = scal[0] + 1.0  # 1-based sample counter of the recursion
        L = w + n
        U[L] = u_in[n]
        Ym[L] = y_in[n] if np.isfinite(y_in[n]) else Ym[L - 1]
        # internal signals with theta(k-1) (or with a fixed vector, for experiments)
        step(theta_int if fixed_internal else theta, layout, U, W1, W2, Yh, L)
        regressor(theta_int if fixed_internal else theta, layout, U, W1, W2, Ym, L, h)
        # (15)
        dy = Ym[L] - Ym[L - 1]
        e = dy
        for i in range(npar):
            e -= h[i] * theta[i]
        rho = (k + 1.0) ** (-rexp)
        rho_prev = k ** (-rexp)
        mu = rho_prev / rho * (1.0 - rho) if mu_const <= 0 else mu_const
        beta = np.nan
        if has_truth and e != 0.0:
            beta = 0.0
            for i in range(npar):
                beta += h[i] * (truth[i] - theta[i])
            beta /= e
        if np.isfinite(y_in[n]):
            # (19), then (17)
            scal[1] = max(scal[1] + rho * (e * e - scal[1]), lam_min)
            hPh = 0.0
            for i in range(npar):
                s = 0.0
                for j in range(npar):
                    s += P[i, j] * h[j]
                PH[i] = s
                hPh += h[i] * s
            denom = hPh + mu * scal[1]
            for i in range(npar):
                K[i] = PH[i] / denom if denom != 0.0 else 0.0
            # (16)
            for i in range(npar):
                theta[i] += K[i] * e
            # (18): Joseph form with R = Lambda^-1, divided by mu
            A = np.eye(npar)
            for i in range(npar):
                for j in range(npar):
                    A[i, j] -= K[i] * h[j]
            Pn = A @ P @ A.T
            for i in range(npar):
                for j in range(npar):
                    P[i, j] = (Pn[i, j] + K[i] * scal[1] * K[j]) / mu
            delta1 = 1.0 - hPh / denom if denom != 0.0 else np.nan
        else:
            delta1 = np.nan
        finite = True
        for i in range(npar):
            finite = finite and np.isfinite(theta[i])
            for j in range(npar):
                finite = finite and np.isfinite(P[i, j])
        ok = finite and admissible(theta, layout, kmax)
        ok = ok and theta[i_alpha] * abs(W1[L] - W1[L - 1]) < 2.0
        if ok:
            theta_good[:] = theta
        elif recover or not finite:
            # divergence: report it and restart from the last admissible estimate
            scal[2] += 1.0
            if scal[3] < 0:
                scal[3] = k
            theta[:] = theta_good
            P[:, :] = P0 * np.eye(npar)
            scal[1] = lam0
            for a in (W1, W2, Yh):
                for i in range(max(0, L - w), L + 1):
                    if not np.isfinite(a[i]):
                        a[i] = 0.0
        scal[0] = k
        history[n, :] = theta
        ev = np.linalg.eigvalsh(0.5 * (P + P.T))
        diag[n, 0] = e
        diag[n, 1] = scal[1]
        diag[n, 2] = rho
        diag[n, 3] = mu
        diag[n, 4] = ev[-1]
        diag[n, 5] = ev[-1] / ev[0] if ev[0] > 0 else np.inf
        diag[n, 6] = delta1
        diag[n, 7] = beta


class ERIA(RecursiveIdentifier):
    """The paper's extended recursive identification algorithm (eqs. 12-19), as published.

    Parameters
    ----------
    structure : Structure, optional
        Orders, delays and the f0 option; the paper's experimental structure by default.
    fs : float
        Sampling rate in Hz.
    theta0 : float, dict or array
        Initial estimate; 0.01 for every parameter as in the paper.
    P0 : float
        Initial covariance ``P(0) = P0 I`` (the paper's 1e6).
    lambda_inv0 : float
        Initial ``Lambda^-1(0)`` (not given in the paper).
    rho_exponent : float
        ``rho(k) = (k+1)^(-rho_exponent)``; the paper's 9/13.
    epsilon : float
        Stop index for :attr:`IdentificationResult.converged_at` (the paper's 1e-4).
    recover : bool
        When the estimate leaves the admissible set (non-finite, alpha <= 0, unstable or
        non-minimum-phase L1/L2, condition 8 violated), restart from the last admissible
        estimate with ``P = P0 I`` and warn. With ``False`` the estimate is kept as it is,
        except that it never becomes NaN: non-finite values still trigger the restart.
    truth : dict or array, optional
        True parameters, to monitor ``beta(k)`` of Theorem 1 (reference stage).
    mu : float, optional
        Constant forgetting factor instead of the paper's ``mu(k)`` (for experiments).
    lambda_inv_min : float
        Floor on ``Lambda^-1(k)`` (0 in the paper).
    internal : dict or array, optional
        Fixed parameters for the internal signals and the products in ``h`` instead of
        theta(k-1): the true ones isolate the estimate/internal-signal loop (experiments).

    Attributes
    ----------
    theta : ndarray
        Current estimate theta(k) (paper's order, :attr:`Structure.names`).
    P : ndarray
        Covariance matrix P(k).
    K : ndarray
        Last gain vector K(k).
    h : ndarray
        Last regressor h(k | theta(k-1)).
    e : float
        Last modelling error e(k).
    lambda_inv : float
        Lambda^-1(k), the running estimate of the error's second moment.
    """

    method = "eria"
    divergence_reason = "the estimate left the admissible set (Assumption 1, condition 8)"
    n_diagnostics = len(DIAGNOSTICS)

    def __init__(
        self,
        structure: Structure | None = None,
        fs: float = 30_000.0,
        *,
        theta0=0.01,
        P0: float = 1e6,
        lambda_inv0: float = 1.0,
        rho_exponent: float = 9 / 13,
        epsilon: float = 1e-4,
        recover: bool = True,
        truth=None,
        mu: float | None = None,
        lambda_inv_min: float = 0.0,
        internal=None,
    ) -> None:
        for name, value in (("P0", P0), ("lambda_inv0", lambda_inv0),
                            ("rho_exponent", rho_exponent)):
            if not (np.isfinite(value) and value > 0):
                raise ValueError(f"{name}: expected a positive number, got {value!r}")
        self.P0 = float(P0)
        self.lambda_inv0 = float(lambda_inv0)
        self.rho_exponent = float(rho_exponent)
        self.recover = bool(recover)
        self.truth = truth
        if mu is not None and not (0 < mu <= 1):
            raise ValueError(f"mu: expected a forgetting factor in (0, 1], got {mu!r}")
        if not (np.isfinite(lambda_inv_min) and lambda_inv_min >= 0):
            raise ValueError(f"lambda_inv_min: expected a non-negative number, got "
                             f"{lambda_inv_min!r}")
        self.mu = mu
        self.lambda_inv_min = float(lambda_inv_min)
        self.internal = internal
        super().__init__(structure, fs, theta0, epsilon)
        check_plain_duhem(self.structure.layout, "method='eria'")

    def _allocate(self) -> None:
        from .offline import initial_theta

        n = len(self.theta)
        w = self.window
        self.P = self.P0 * np.eye(n)
        self.K = np.zeros(n)
        self.h = np.zeros(n)
        self._theta_good = self.theta.copy()
        self._scal = np.array([0.0, self.lambda_inv0, 0.0, -1.0])
        self._U, self._W1, self._W2, self._Yh, self._Ym = (np.zeros(w) for _ in range(5))
        self._truth_vec = (initial_theta(self.structure, self.truth)
                           if self.truth is not None else np.zeros(n))
        self._internal_vec = (initial_theta(self.structure, self.internal)
                              if self.internal is not None else np.zeros(n))
        self._diag_last = np.full(len(DIAGNOSTICS), np.nan)

    def _run(self, u, y, history, diagnostics) -> None:
        settings = np.array([self.P0, self.lambda_inv0, self.rho_exponent, 1.0 - 1e-9,
                             float(self.recover), float(self.truth is not None),
                             self.mu or 0.0, self.lambda_inv_min,
                             float(self.internal is not None)])
        windows = (self._U, self._W1, self._W2, self._Yh, self._Ym)
        arrays = [extended(a, len(u)) for a in windows]
        eria_run(self.theta, self.P, self._scal, self._theta_good, self.structure.layout,
                 *arrays, self.h, self.K, self._truth_vec, self._internal_vec, settings,
                 np.ascontiguousarray(u, float), np.ascontiguousarray(y, float), history,
                 diagnostics)
        for window, ext in zip(windows, arrays, strict=True):
            keep_tail(window, ext)
        self.n_recoveries = int(self._scal[2])
        self.first_recovery = int(self._scal[3]) if self._scal[3] > 0 else None
        self._diag_last = diagnostics[-1].copy()

    @property
    def e(self) -> float:
        """Last modelling error e(k) (eq. 15)."""
        return float(self._diag_last[0])

    @property
    def lambda_inv(self) -> float:
        """Lambda^-1(k) (eq. 19)."""
        return float(self._scal[1])

    @property
    def diagnostics(self) -> dict[str, float]:
        """Theorem 1's monitored quantities at the last sample."""
        return dict(zip(DIAGNOSTICS, map(float, self._diag_last), strict=True))

    @property
    def settings(self) -> dict:
        """The configuration, JSON-ready."""
        return {**super().settings, "P0": self.P0, "lambda_inv0": self.lambda_inv0,
                "rho": f"(k+1)^-{self.rho_exponent:.6g}", "rho_exponent": self.rho_exponent,
                "recover": self.recover,
                "mu": self.mu or "rho(k-1)/rho(k) (1 - rho(k))",
                "lambda_inv_min": self.lambda_inv_min,
                "internal": "estimate" if self.internal is None else "fixed"}
