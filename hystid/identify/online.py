"""An on-line identifier of the sandwich that converges: recursive prediction error (RPEM).

The estimate minimises the simulation (output) error of the whole sandwich, not the equation
error of eq. (12). Each sample:

1. the model runs one step with the current estimate, and the compiled sensitivity recursion
   gives ``psi(k) = d yhat(k) / d theta`` exactly through L1, the Duhem block and L2;
2. the residual ``e(k) = y(k) - yhat(k)`` is clipped at ``clip`` times a running robust scale
   ``sigma(k)`` (a burst of bad samples moves the estimate by a bounded amount);
3. a recursive Gauss-Newton step with forgetting factor ``lambda(k)``::

       K(k)     = P(k-1) psi / (lambda(k) + psi^T P(k-1) psi)
       theta(k) = theta(k-1) + K(k) e(k)
       P(k)     = (P(k-1) - K(k) psi^T P(k-1)) / lambda(k)

   where ``lambda(k)`` rises from ``lambda0`` to ``1 - 1/memory`` and ``trace(P)`` is capped;
4. projection: a step that leaves the admissible set (alpha > 0, L1 and L2 stable and minimum
   phase: Assumption 1; ``alpha |dw1| < 2``: condition 8) is not taken.

Start-up: a cold start from theta = 0.01 is a local minimum for any gradient method (the
measured facts: 400 samples are not enough for a batch fit from there). The identifier therefore
collects the first ``n_start`` samples (a fixed-size buffer) and solves the output-error problem
on them once (Gauss-Newton from theta0 and from the linear ARX start, the better kept), then runs
the recursion from that estimate with ``P`` set to the inverse Gauss-Newton information.

Divergence watch: the short-term residual RMS is compared with its long-term level; when it
exceeds ``diverge_ratio`` times that level for ``diverge_hold`` samples the estimate is declared
diverging, a warning is issued and the identifier restarts from the last estimate that had a
low residual, with ``P`` reset.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
from numba import njit

from ..kernels import offsets, step_sens
from ..model import Structure
from ..records import Record
from ._recursive import RecursiveIdentifier, admissible_into, extended, keep_tail
from .offline import fit_output_error, output_sensitivities

if TYPE_CHECKING:  # pragma: no cover
    from .result import IdentificationResult

__all__ = ["OnlineIdentifier", "DIAGNOSTICS"]

#: Columns of the diagnostics array kept per sample.
DIAGNOSTICS = ("e", "sigma", "lambda", "trace_P", "rms_short", "rms_long")

# scal layout
_K, _LAM, _SIG, _SHORT, _LONG, _NPROJ, _NCLIP, _NREC, _FIRST, _HOLD, _GOODAGE, _NPRESET = range(12)


@njit(cache=True)
def _resync(theta, layout, W1, W2, Yh, Ym, S1, S2, SY, lo, L):
    """After a restart: the model output takes the measured output, w2 follows from inverting
    L2 (eq. 2) on it, non-finite w1 are cleared and the sensitivities restart from zero."""
    n2a, n2b, q2 = layout[2], layout[3], layout[5]
    i_b2, i_a2 = 0, offsets(layout)[7]
    for i in range(lo, L + 1):
        Yh[i] = Ym[i]
        if not np.isfinite(W1[i]):
            W1[i] = 0.0
        S1[i, :] = 0.0
        S2[i, :] = 0.0
        SY[i, :] = 0.0
    for i in range(lo + max(n2a, q2 + n2b), L + 1):
        w2 = Ym[i]
        for j in range(1, n2a + 1):
            w2 += theta[i_a2 + j - 1] * Ym[i - j]
        for j in range(1, n2b + 1):
            w2 -= theta[i_b2 + j - 1] * W2[i - q2 - j]
        W2[i - q2] = w2


@njit(cache=True)
def _covariance_ok(P, trace_max):
    """P is finite, has a positive diagonal, |P_ij|^2 <= P_ii P_jj and trace below the cap."""
    n = P.shape[0]
    tr = 0.0
    for i in range(n):
        if not (P[i, i] > 0.0) or not np.isfinite(P[i, i]):
            return False
        tr += P[i, i]
        for j in range(i):
            if not (P[i, j] * P[i, j] <= P[i, i] * P[j, j]):
                return False
    return tr < trace_max


@njit(cache=True)
def rpem_run(theta, P, scal, theta_good, P_good, layout, U, W1, W2, Yh, Ym, S1, S2, SY, settings,
             u_in, y_in, history, diag):
    """The recursion over a chunk; see the module docstring.

    ``settings = [lambda0, lambda_inf, lambda_rate, clip, trace_max, diverge_ratio,
    diverge_hold, P_reset, kmax, short_rate, long_rate, sigma_rate]``.
    """
    npar = theta.shape[0]
    w = U.shape[0] - u_in.shape[0]
    lam_inf, lam_rate, clip, trace_max = settings[1], settings[2], settings[3], settings[4]
    div_ratio, div_hold, P_reset, kmax = settings[5], settings[6], settings[7], settings[8]
    a_short, a_long, a_sig = settings[9], settings[10], settings[11]
    i_alpha = offsets(layout)[1]
    PH = np.empty(npar)
    cand = np.empty(npar)
    work = np.empty(npar)
    for n in range(u_in.shape[0]):
        L = w + n
        U[L] = u_in[n]
        Ym[L] = y_in[n] if np.isfinite(y_in[n]) else Yh[L - 1]
        # 1. model step with theta(k-1) and the exact sensitivities psi(k)
        step_sens(theta, layout, U, W1, W2, Yh, S1, S2, SY, L)
        psi = SY[L]
        scal[_LAM] = lam_inf - (lam_inf - scal[_LAM]) * lam_rate
        lam = scal[_LAM]
        e = np.nan
        restart = not np.isfinite(Yh[L])
        if np.isfinite(y_in[n]) and not restart:
            e = y_in[n] - Yh[L]
            # 2. clipped residual, robust scale, short- and long-term residual levels
            sig = scal[_SIG]
            ec = e
            if abs(e) > clip * sig:
                ec = clip * sig if e > 0 else -clip * sig
                scal[_NCLIP] += 1.0
            scal[_SIG] = np.sqrt((1.0 - a_sig) * sig * sig + a_sig * ec * ec) + 1e-300
            scal[_SHORT] = (1.0 - a_short) * scal[_SHORT] + a_short * e * e
            alarm = scal[_SHORT] > div_ratio * div_ratio * scal[_LONG]
            if not alarm:
                scal[_LONG] = (1.0 - a_long) * scal[_LONG] + a_long * scal[_SHORT]
            # 3. Gauss-Newton step with forgetting
            hPh = 0.0
            for i in range(npar):
                s = 0.0
                for j in range(npar):
                    s += P[i, j] * psi[j]
                PH[i] = s
                hPh += psi[i] * s
            denom = lam + hPh
            for i in range(npar):
                cand[i] = theta[i] + PH[i] * (ec / denom)
            # 4. projection onto the admissible set (Assumption 1, condition 8)
            dw1 = abs(W1[L] - W1[L - 1])
            if admissible_into(cand, layout, kmax, work) and cand[i_alpha] * dw1 < 2.0:
                theta[:] = cand
            else:
                scal[_NPROJ] += 1.0
            for i in range(npar):
                for j in range(i + 1):
                    v = (P[i, j] - PH[i] * PH[j] / denom) / lam
                    P[i, j] = v
                    P[j, i] = v
            if not _covariance_ok(P, trace_max):
                scal[_NPRESET] += 1.0
                for i in range(npar):
                    for j in range(npar):
                        P[i, j] = P_reset if i == j else 0.0
            # divergence watch
            if alarm:
                scal[_HOLD] += 1.0
            else:
                scal[_HOLD] = 0.0
                if scal[_SHORT] < 4.0 * scal[_LONG]:
                    scal[_GOODAGE] += 1.0
                    if scal[_GOODAGE] > div_hold:
                        theta_good[:] = theta
                        P_good[:, :] = P
                        scal[_GOODAGE] = 0.0
            restart = scal[_HOLD] > div_hold
        if restart:
            scal[_NREC] += 1.0
            if scal[_FIRST] < 0:
                scal[_FIRST] = scal[_K] + 1.0
            theta[:] = theta_good
            P[:, :] = P_good
            _resync(theta, layout, W1, W2, Yh, Ym, S1, S2, SY, max(0, L - w + 1), L)
            scal[_HOLD] = 0.0
            scal[_GOODAGE] = 0.0
            scal[_SHORT] = scal[_LONG]
            scal[_SIG] = np.sqrt(scal[_LONG])
        scal[_K] += 1.0
        history[n, :] = theta
        tr = 0.0
        for i in range(npar):
            tr += P[i, i]
        diag[n, 0] = e
        diag[n, 1] = scal[_SIG]
        diag[n, 2] = lam
        diag[n, 3] = tr
        diag[n, 4] = np.sqrt(scal[_SHORT])
        diag[n, 5] = np.sqrt(scal[_LONG])


#: Default length of the start-up window, in samples.
N_START = 400


class OnlineIdentifier(RecursiveIdentifier):
    """Converging on-line identifier of the Duhem sandwich (recursive prediction error).

    Parameters
    ----------
    structure : Structure, optional
        Orders, delays and the f0 option; the paper's experimental structure by default.
    fs : float
        Sampling rate in Hz.
    theta0 : float, dict or array
        Initial estimate (0.01 for every parameter, as in the paper). An inadmissible start
        (unstable L1/L2, alpha <= 0) is projected onto the admissible set with a warning.
    n_start : int
        Samples collected before the one-off start-up solve (see the module docstring).
    memory : float
        Asymptotic memory in samples: ``lambda -> 1 - 1/memory``. Shorter tracks faster
        parameter changes, longer averages the noise better.
    lambda0 : float
        Forgetting factor right after start-up; rises to ``1 - 1/memory`` with time constant
        ``lambda_time`` samples.
    clip : float
        Residuals beyond ``clip`` running standard deviations are clipped.
    trace_max : float
        Cap on ``trace(P)`` (prevents covariance wind-up when excitation fades).
    diverge_ratio, diverge_hold : float, int
        Divergence is declared when the short-term residual RMS stays above ``diverge_ratio``
        times the long-term RMS for ``diverge_hold`` samples.
    epsilon : float
        Stop index for ``converged_at`` (1e-4).

    Attributes
    ----------
    theta : ndarray
        Current estimate.
    P : ndarray
        Current covariance-like matrix of the Gauss-Newton recursion.
    psi : ndarray
        Last output sensitivity d yhat / d theta.
    e : float
        Last residual y(k) - yhat(k).
    sigma : float
        Running robust residual scale.
    """

    method = "online"
    divergence_reason = "the residual diverged (short-term RMS above diverge_ratio x long-term)"
    n_diagnostics = len(DIAGNOSTICS)

    def __init__(
        self,
        structure: Structure | None = None,
        fs: float = 30_000.0,
        *,
        theta0=0.01,
        n_start: int = N_START,
        memory: float = 100_000.0,
        lambda0: float = 0.9999,
        lambda_time: float = 2_000.0,
        clip: float = 4.0,
        trace_max: float = 1e4,
        diverge_ratio: float = 20.0,
        diverge_hold: int = 200,
        epsilon: float = 1e-4,
    ) -> None:
        if int(n_start) != n_start or n_start < 50:
            raise ValueError(f"n_start: expected an integer >= 50 samples, got {n_start!r}")
        if not (memory > 1):
            raise ValueError(f"memory: expected more than 1 sample, got {memory!r}")
        if not (0 < lambda0 <= 1):
            raise ValueError(f"lambda0: expected a value in (0, 1], got {lambda0!r}")
        for name, value in (("lambda_time", lambda_time), ("clip", clip),
                            ("trace_max", trace_max), ("diverge_ratio", diverge_ratio),
                            ("diverge_hold", diverge_hold)):
            if not (np.isfinite(value) and value > 0):
                raise ValueError(f"{name}: expected a positive number, got {value!r}")
        self.n_start = int(n_start)
        self.memory = float(memory)
        self.lambda0 = float(lambda0)
        self.lambda_time = float(lambda_time)
        self.clip = float(clip)
        self.trace_max = float(trace_max)
        self.diverge_ratio = float(diverge_ratio)
        self.diverge_hold = int(diverge_hold)
        super().__init__(structure, fs, theta0, epsilon)

    # ----------------------------------------------------------------- state
    def _allocate(self) -> None:
        import warnings

        from .constraints import is_admissible, project_admissible

        if not is_admissible(self.theta, self.structure):
            warnings.warn(
                "online: theta0 is outside the admissible set (alpha > 0, stable and "
                "minimum-phase L1, L2); projected onto it", RuntimeWarning, stacklevel=4)
            self.theta = project_admissible(self.theta, self.structure)
        n = len(self.theta)
        w = self.window
        self.P = np.eye(n)
        self._P_good = self.P.copy()
        self._theta_good = self.theta.copy()
        self._scal = np.zeros(12)
        self._scal[_LAM] = self.lambda0
        self._scal[_FIRST] = -1.0
        self._U, self._W1, self._W2, self._Yh, self._Ym = (np.zeros(w) for _ in range(5))
        self._S1, self._S2, self._SY = (np.zeros((w, n)) for _ in range(3))
        self._windows = (self._U, self._W1, self._W2, self._Yh, self._Ym,
                         self._S1, self._S2, self._SY)
        self._buf_u = np.zeros(self.n_start)
        self._buf_y = np.zeros(self.n_start)
        self._diag_last = np.full(len(DIAGNOSTICS), np.nan)
        self.start_info: dict = {}

    @property
    def started(self) -> bool:
        """True once the start-up solve has run."""
        return self.k >= self.n_start

    def _start(self) -> None:
        """The one-off start-up solve on the buffered samples; sets theta, P and the windows."""
        y = self._buf_y.copy()
        bad = ~np.isfinite(y)
        if bad.all():
            raise ValueError("online: every output sample of the start-up window is non-finite")
        if bad.any():  # fill skipped samples by interpolation for the start-up solve only
            idx = np.arange(len(y))
            y[bad] = np.interp(idx[bad], idx[~bad], y[~bad])
        rec = Record(self._buf_u.copy(), y, self.fs, name="start-up window")
        fit = fit_output_error(rec, self.structure, self.theta, max_nfev=100)
        theta = fit.model.theta
        yhat, J = output_sensitivities(theta, self.structure, rec.u)
        r = rec.y - yhat
        sigma = max(float(np.sqrt(np.mean(r**2))), 1e-12)
        info = J.T @ J
        P = np.linalg.pinv(info + 1e-9 * np.trace(info) / len(theta) * np.eye(len(theta)))
        self.theta = theta.copy()
        self._theta_good = theta.copy()
        self.P = P
        self._P_good = P.copy()
        # windows at the end of the buffer, from a simulation with the start estimate
        s = self.structure
        n, w = len(rec.u), self.window
        Pp = s.history
        from ..kernels import sensitivities_into

        U, W1, W2, Y = (np.zeros(Pp + n) for _ in range(4))
        U[Pp:] = rec.u
        S1, S2, SY = (np.zeros((Pp + n, len(theta))) for _ in range(3))
        sensitivities_into(theta, s.layout, U, W1, W2, Y, S1, S2, SY, Pp)
        Ym = np.concatenate([np.zeros(Pp), rec.y])
        for dst, src in zip(self._windows, (U, W1, W2, Y, Ym, S1, S2, SY), strict=True):
            dst[-min(w, len(src)):] = src[-min(w, len(src)):]
        self._scal[_SIG] = sigma
        self._scal[_SHORT] = self._scal[_LONG] = sigma**2
        self.start_info = {"rms_residual": sigma, "start": fit.info["start"],
                           "nfev": fit.info["nfev"]}

    def _run(self, u, y, history, diagnostics) -> None:
        done = 0
        if self.k < self.n_start:  # start-up window: collect, estimate stays at theta0
            take = min(len(u), self.n_start - self.k)
            self._buf_u[self.k:self.k + take] = u[:take]
            self._buf_y[self.k:self.k + take] = y[:take]
            history[:take] = self.theta
            diagnostics[:take] = np.nan
            done = take
            if self.k + take == self.n_start:
                self._start()
                history[take - 1] = self.theta
            self._scal[_K] = self.k + take
        if done < len(u):
            settings = np.array([
                self.lambda0, 1.0 - 1.0 / self.memory, np.exp(-1.0 / self.lambda_time),
                self.clip, self.trace_max, self.diverge_ratio, float(self.diverge_hold),
                min(1.0, self.trace_max / len(self.theta)), 1.0 - 1e-6, 1.0 / 50.0,
                1.0 / 5_000.0, 1.0 / 500.0])
            m = len(u) - done
            arrays = [extended(a, m) for a in self._windows]
            rpem_run(self.theta, self.P, self._scal, self._theta_good, self._P_good,
                     self.structure.layout,
                     *arrays, settings, np.ascontiguousarray(u[done:], float),
                     np.ascontiguousarray(y[done:], float), history[done:], diagnostics[done:])
            for window, ext in zip(self._windows, arrays, strict=True):
                keep_tail(window, ext)
            self._diag_last = diagnostics[-1].copy()
        self.n_recoveries = int(self._scal[_NREC])
        self.first_recovery = int(self._scal[_FIRST]) if self._scal[_FIRST] > 0 else None
        # keep the counter in step with self.k (updated by the caller)
        self._scal[_K] = self.k + len(u)

    # ----------------------------------------------------------------- intermediates
    @property
    def psi(self) -> np.ndarray:
        """Last output sensitivity d yhat(k) / d theta."""
        return self._SY[-1].copy()

    @property
    def e(self) -> float:
        """Last residual y(k) - yhat(k)."""
        return float(self._diag_last[0])

    @property
    def sigma(self) -> float:
        """Running robust residual scale."""
        return float(self._scal[_SIG])

    @property
    def n_projections(self) -> int:
        """Steps refused because they left the admissible set."""
        return int(self._scal[_NPROJ])

    @property
    def n_covariance_resets(self) -> int:
        """Times P lost positive definiteness (or hit the trace cap) and was reset."""
        return int(self._scal[_NPRESET])

    @property
    def n_clipped(self) -> int:
        """Residuals clipped as outliers."""
        return int(self._scal[_NCLIP])

    @property
    def diagnostics(self) -> dict[str, float]:
        """Monitored quantities at the last sample."""
        return dict(zip(DIAGNOSTICS, map(float, self._diag_last), strict=True))

    def result(
        self, history: np.ndarray | None = None, diagnostics: np.ndarray | None = None
    ) -> IdentificationResult:
        """The current estimate as an IdentificationResult (with start-up and guard counts)."""
        res = super().result(history, diagnostics)
        res.info.update({"n_projections": self.n_projections, "n_clipped": self.n_clipped,
                         "n_covariance_resets": self.n_covariance_resets,
                         "start_up": self.start_info})
        return res

    @property
    def settings(self) -> dict:
        """The configuration, JSON-ready."""
        return {**super().settings, "n_start": self.n_start, "memory": self.memory,
                "lambda0": self.lambda0, "lambda_time": self.lambda_time, "clip": self.clip,
                "trace_max": self.trace_max, "diverge_ratio": self.diverge_ratio,
                "diverge_hold": self.diverge_hold}
