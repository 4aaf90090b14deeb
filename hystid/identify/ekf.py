"""A filterpy baseline: joint state-and-parameter estimation with an extended Kalman filter.

The sandwich (eqs. 1, 7, 2) is written as a nonlinear state-space model whose state is augmented
with the parameter vector theta (eq. 13), modelled as a random walk::

    x(k) = [w1(k) .. w1(k-m1+1), w2(k) .. w2(k-m2+1), y(k) .. y(k-m3+1), theta(k)]
    x(k) = f(x(k-1), u) + v(k),    v ~ N(0, diag(q_state, q_theta))
    y_meas(k) = y(k) + e(k),       e ~ N(0, r)

with ``m1 = max(1, n1a)``, ``m2 = max(1, q2 + n2b)``, ``m3 = max(1, n2a)`` (for the paper's
structure: w1(k), w2(k), y(k), y(k-1) and alpha, f1, g0, a11, a21, a22). The measured input is
a known input of the transition, kept in a window of its last ``q1 + n1b + 1`` samples rather than
in the state (its variance would be zero).

Why the EKF (filterpy's :class:`~filterpy.kalman.ExtendedKalmanFilter`) and not the unscented
filter: the transition is piecewise polynomial in the augmented state, so its Jacobian is exact
and cheap (the sandwich's own step and sensitivity kernels, :func:`hystid.kernels.step` and
:func:`~hystid.kernels.step_sens_row`, seeded with the state windows: ``d|dw1|/dx = sgn(dw1)
d(dw1)/dx`` away from the Duhem block's non-smooth point and ``sgn(0) = 0`` on it, ``d sgn/dx =
0``). The unscented filter needs ``2n + 1`` transitions per sample and a Cholesky factor of P.
Tried on the reference stage with the same state and guards, filterpy's UKF (Merwe sigma points)
ran about 4x slower (4 500 against 18 000 samples/s then) and was not clearly more accurate
(1 nm noise, 3 seeds, before the annealing and the alpha floor below): from a +-20 % start the
final max relative errors after 3 000 samples were 0.04-0.35 % (UKF) and 0.04-1.3 % (EKF); from
the linear bootstrap, 23-115 % (UKF) and 48-89 % (EKF) after 30 000 samples.

Guards: non-finite samples are not used (``n_skipped``); the parameter estimate is projected on
the admissible set (alpha > 0, L1 and L2 stable and minimum phase, Assumption 1) after every
update and alpha is kept above ``alpha_min`` (``n_projections``); a failed step or a non-finite
or exploding covariance or state is detected and the filter restarts from the last good estimate
with the initial covariance (``n_resets``). The random walk of theta starts larger
(``q_anneal``) and decays, which keeps the gain open while the estimate is far off.

Units: the defaults (``r``, the variances, ``alpha_min``, the uninformed start 0.01) are
absolute, tuned on the reference stage's records (volts and micrometres). :func:`hystid.identify.
identify` runs the filter on the record brought to those magnitudes by powers of ten
(:class:`ScaledRun`) and maps the model back, so that a record in mV and nm gives the model it
gives in V and um; :class:`KalmanIdentifier` used directly takes its samples as they come.

This is a baseline: joint EKF estimation converges only locally. Figures on the reference stage
are in ``benchmarks/bench_ekf.py``.
"""

from __future__ import annotations

import warnings
from collections.abc import Callable, Mapping, Sequence
from typing import Any

import numpy as np
from filterpy.kalman import ExtendedKalmanFilter
from numba import njit

from ..kernels import step_sens_row
from ..model import DuhemSandwich, Structure
from ..records import Record
from ..validate import check_plain_duhem
from ._recursive import admissible
from .base import Estimator, as_sample, record_signals
from .constraints import is_admissible, project_admissible
from .offline import initial_theta, linear_start, to_physical
from .prepare import scales
from .result import HistoryRecorder, IdentificationResult

__all__ = ["KalmanIdentifier", "state_sizes", "transition"]

_KMAX = 0.999  # reflection-coefficient bound of the projection
#: Default relative standard deviation of an informed start (vector, dict or bootstrap).
P0_RELATIVE = 0.2


def state_sizes(structure: Structure) -> tuple[int, int, int, int]:
    """Window lengths ``(m1, m2, m3, mu)`` of w1, w2, y in the state and of the input buffer.

    Parameters
    ----------
    structure : Structure
        The model structure.

    Returns
    -------
    tuple of int
        ``(m1, m2, m3, mu)``.
    """
    s = structure
    return max(1, s.n1a), max(1, s.q2 + s.n2b), max(1, s.n2a), s.q1 + s.n1b + 1


@njit(cache=True)
def transition(x, ubuf, layout, m1, m2, m3, xn, F):
    """Augmented transition ``xn = f(x, u)`` and its Jacobian ``F = df/dx`` (eqs. 1, 7, 2).

    ``x`` holds the windows of w1, w2, y (most recent first) and theta; ``ubuf[j] = u(k-j)``.
    Writes ``xn`` and ``F`` in place.

    The sandwich's step is not written here: the windows are laid out as the past of the
    extended signal arrays of :mod:`hystid.kernels` and one :func:`~hystid.kernels.step_sens_row`
    computes w1(k), w2(k), y(k) (by :func:`~hystid.kernels.step`) and their gradients. Its
    sensitivity columns are theta's and then one per window entry: ``theta`` is handed over
    with a zero appended for each window entry (no parameter of the step sits there, so those
    columns get no explicit term) and the past rows are seeded with ``d x_i / d x_i = 1``.
    """
    n = x.shape[0]
    ns = m1 + m2 + m3
    npar = n - ns
    o2, oy = m1, m1 + m2  # where the w2 and y windows start
    mu = ubuf.shape[0]
    # extended arrays: index P is sample k, P - i is k - i (the step reads no further back)
    P = max(max(m1, m2), max(m3, mu - 1))
    U = np.zeros(P + 1)
    W1 = np.zeros(P + 1)
    W2 = np.zeros(P + 1)
    Y = np.zeros(P + 1)
    nc = npar + ns
    S1 = np.zeros((P + 1, nc))
    S2 = np.zeros((P + 1, nc))
    SY = np.zeros((P + 1, nc))
    th = np.zeros(nc)
    th[:npar] = x[ns:]
    for j in range(mu):
        U[P - j] = ubuf[j]
    for start, m, A, S in ((0, m1, W1, S1), (o2, m2, W2, S2), (oy, m3, Y, SY)):
        for i in range(m):
            A[P - 1 - i] = x[start + i]
            S[P - 1 - i, npar + start + i] = 1.0
    step_sens_row(th, layout, U, W1, W2, Y, S1, S2, SY, P, P)

    # new state: the new samples first, the windows shifted by one, theta unchanged
    F[:, :] = 0.0
    for start, m, A, S in ((0, m1, W1, S1), (o2, m2, W2, S2), (oy, m3, Y, SY)):
        xn[start] = A[P]
        for p in range(ns):
            F[start, p] = S[P, npar + p]
        for p in range(npar):
            F[start, ns + p] = S[P, p]
        for i in range(1, m):
            xn[start + i] = x[start + i - 1]
            F[start + i, start + i - 1] = 1.0
    for p in range(ns, n):
        xn[p] = x[p]
        F[p, p] = 1.0


@njit(cache=True)
def _healthy(x, P, p_max):
    """State finite, covariance finite with its diagonal in [0, p_max]."""
    n = P.shape[0]
    for i in range(n):
        if not np.isfinite(x[i, 0]):
            return False
        if not (0.0 <= P[i, i] <= p_max):
            return False
        for j in range(n):
            if not np.isfinite(P[i, j]):
                return False
    return True


class _SandwichEKF(ExtendedKalmanFilter):
    """filterpy's EKF with the sandwich's nonlinear transition in ``predict_x``."""

    def __init__(self, dim_x: int, layout: np.ndarray, sizes: tuple[int, int, int, int]):
        super().__init__(dim_x=dim_x, dim_z=1)
        self.layout = layout
        self.m1, self.m2, self.m3, _ = sizes
        self._xn = np.zeros(dim_x)

    def predict_x(self, u=0):
        # x(k|k-1) = f(x(k-1|k-1), u); F is evaluated at x(k-1|k-1) and used by predict() for P
        transition(self.x[:, 0], u, self.layout, self.m1, self.m2, self.m3, self._xn, self.F)
        self.x = self._xn[:, None].copy()


def _variances(value, n: int, argname: str, positive: bool = False) -> np.ndarray:
    """A scalar or ``n`` variances, checked."""
    arr = np.asarray(value, dtype=float)
    if arr.ndim == 0:
        arr = np.full(n, float(arr))
    if arr.shape != (n,):
        raise ValueError(f"{argname}: expected a scalar or {n} variances, got shape {arr.shape}")
    if not np.all(np.isfinite(arr)) or np.any(arr < 0) or (positive and np.any(arr <= 0)):
        what = "positive" if positive else "non-negative"
        raise ValueError(f"{argname}: expected finite {what} variances, got {value!r}")
    return arr


class KalmanIdentifier(Estimator):
    """Extended-Kalman-filter identifier of the Duhem sandwich (a filterpy baseline).

    Parameters
    ----------
    structure : Structure, optional
        Model structure; the paper's experimental one by default.
    fs : float
        Sampling rate in Hz of the records it will see (stored in the identified model).
    theta0 : float, array, dict or ``"linear"``
        Start of the parameter estimate: one value for every parameter (the paper's 0.01), a
        vector in the order of :attr:`Structure.names`, a dict by name, or ``"linear"``: a
        bootstrap from :func:`~hystid.identify.offline.linear_start` on the first
        ``n_bootstrap`` samples (see :meth:`initialize`).
    P0_theta : float, array or None
        Initial variance of each parameter. By default (None) it follows the start: ``0.01``
        for every parameter after an uninformed start (a scalar ``theta0`` such as the paper's
        0.01, or a failed bootstrap), ``(P0_RELATIVE * |theta_i(0)|)^2`` (at least 1e-8,
        ``P0_RELATIVE = 0.2``) after a vector, a dict or the ``"linear"`` bootstrap.
    P0_state : float or array
        Initial variance of each internal signal in the state (the records start at rest).
    q_theta : float or array
        Random-walk variance per sample of each parameter, in the long run.
    q_anneal : float or array
        Extra random-walk variance at the start, decaying as ``exp(-k / anneal_samples)``: it
        keeps the gain open while the estimate is far from the truth (without it the
        covariance collapses during the first samples and the estimate stalls).
    anneal_samples : float
        Decay time of ``q_anneal`` in samples.
    q_state : float or array
        Process-noise variance per sample of each internal signal.
    r : float
        Variance of the measurement noise on y, in output units squared (1 nm: 1e-6 um^2).
    alpha_min : float
        Lower bound kept on alpha (Assumption: the stage has hysteresis). Measured on the
        reference stage: with only alpha > 0, the estimate often collapses to alpha ~ 0 (a
        linear model, where f1 is no longer identifiable) and stays there; ``0.1`` (an eighth
        of the reference stage's 0.84) removes that failure. Set a small value to disable.
    n_bootstrap : int
        Samples used by the ``"linear"`` bootstrap.
    p_max : float
        A covariance with a diagonal entry above this (or non-finite) triggers a reset.
    epsilon : float
        Stop index for ``converged_at`` (the paper's 1e-4).
    history : {"decimated", "full", "none"}
        Parameter history kept by :meth:`fit` (:class:`~hystid.identify.result.HistoryRecorder`).
    history_rows : int
        Rows kept by ``history="decimated"``.

    Attributes
    ----------
    theta : ndarray
        Current parameter estimate (after :meth:`initialize`, :meth:`update` or :meth:`fit`).
    P : ndarray
        Covariance of the augmented state (internal signals first, then theta).
    K : ndarray
        Last Kalman gain, one entry per state.
    e : float
        Last innovation ``y(k) - yhat(k|k-1)``.
    x : ndarray
        The augmented state (internal-signal windows, then theta).
    k : int
        Number of samples processed.
    n_skipped, n_resets, n_projections : int
        Non-finite samples not used, covariance resets, projections of theta.
    theta_start_ : ndarray
        The start actually used (``theta0`` or the bootstrap's result).
    start_ : str
        ``"uninformed"`` (scalar ``theta0`` or failed bootstrap), ``"theta0"`` or ``"linear"``.

    Examples
    --------
    >>> from hystid.reference import reference_record
    >>> ekf = KalmanIdentifier(theta0="linear")
    >>> result = ekf.fit(reference_record(0.1))  # doctest: +SKIP
    >>> result.model.params  # doctest: +SKIP
    """

    method = "ekf"

    def __init__(
        self,
        structure: Structure | None = None,
        fs: float = 30_000.0,
        theta0: float | str | Sequence[float] | np.ndarray | Mapping[str, float] = 0.01,
        P0_theta: float | Sequence[float] | np.ndarray | None = None,
        P0_state: float | Sequence[float] | np.ndarray = 1e-6,
        q_theta: float | Sequence[float] | np.ndarray = 1e-14,
        q_anneal: float | Sequence[float] | np.ndarray = 1e-10,
        anneal_samples: float = 5000.0,
        q_state: float | Sequence[float] | np.ndarray = 0.0,
        r: float = 1e-6,
        alpha_min: float = 0.1,
        n_bootstrap: int = 300,
        p_max: float = 1e6,
        epsilon: float = 1e-4,
        history: str = "decimated",
        history_rows: int = 100_000,
    ) -> None:
        self.structure = structure or Structure()
        if not isinstance(self.structure, Structure):
            raise ValueError(f"structure: expected a Structure, got {type(structure).__name__}")
        check_plain_duhem(self.structure.layout, "method='ekf' (KalmanIdentifier)")
        if not (np.isscalar(fs) and np.isfinite(fs) and fs > 0):
            raise ValueError(f"fs: expected a positive finite number of Hz, got {fs!r}")
        if not (np.isscalar(r) and np.isfinite(r) and r > 0):
            raise ValueError(f"r: expected a positive finite variance, got {r!r}")
        if int(n_bootstrap) != n_bootstrap or n_bootstrap < 20:
            raise ValueError(f"n_bootstrap: expected an integer >= 20, got {n_bootstrap!r}")
        if not (np.isscalar(alpha_min) and np.isfinite(alpha_min) and alpha_min > 0):
            raise ValueError(f"alpha_min: expected a positive lower bound, got {alpha_min!r}")
        self.alpha_min = float(alpha_min)
        if not (np.isscalar(epsilon) and np.isfinite(epsilon) and epsilon > 0):
            raise ValueError(f"epsilon: expected a positive stop index, got {epsilon!r}")
        self.epsilon = float(epsilon)
        HistoryRecorder(2, 1, 0, history, history_rows)  # validates both
        self.history, self.history_rows = history, int(history_rows)
        if not (np.isscalar(p_max) and p_max > 0):
            raise ValueError(f"p_max: expected a positive number, got {p_max!r}")
        self.fs = float(fs)
        self.theta0 = theta0
        self.r = float(r)
        self.n_bootstrap = int(n_bootstrap)
        self.p_max = float(p_max)
        npar = len(self.structure.names)
        self._sizes = state_sizes(self.structure)
        self._ns = ns = sum(self._sizes[:3])
        self._layout = self.structure.layout
        self._ia = self.structure.names.index("alpha")
        self.P0_theta = None if P0_theta is None else _variances(P0_theta, npar, "P0_theta")
        self.P0_state = _variances(P0_state, ns, "P0_state")
        self.q_theta = _variances(q_theta, npar, "q_theta")
        self.q_anneal = _variances(q_anneal, npar, "q_anneal")
        if not (np.isscalar(anneal_samples) and anneal_samples > 0):
            raise ValueError(f"anneal_samples: expected a positive number of samples, "
                             f"got {anneal_samples!r}")
        self.anneal_samples = float(anneal_samples)
        self.q_state = _variances(q_state, ns, "q_state")
        if isinstance(theta0, str):
            if theta0 != "linear":
                raise ValueError(f"theta0: expected a number, a vector, a dict or 'linear', "
                                 f"got {theta0!r}")
        else:
            self._check_theta0(self._numeric_theta0(theta0))
        self._kf: _SandwichEKF | None = None
        self.k = self.n_skipped = 0
        if not isinstance(theta0, str):
            self.initialize()  # theta, P, model are available at once

    # ------------------------------------------------------------------ set-up
    def _numeric_theta0(self, theta0) -> np.ndarray:
        try:
            return initial_theta(self.structure, dict(theta0) if isinstance(theta0, Mapping)
                                 else theta0)
        except (TypeError, ValueError) as exc:
            raise ValueError(f"theta0: {exc}") from None

    def _check_theta0(self, theta: np.ndarray) -> None:
        if not is_admissible(theta, self.structure):
            raise ValueError(
                "theta0: not admissible (alpha must be > 0 and L1, L2 stable and minimum phase); "
                f"got {dict(zip(self.structure.names, theta.tolist(), strict=True))}"
            )

    def _p0_theta(self, theta: np.ndarray) -> np.ndarray:
        """Initial parameter variances (see ``P0_theta``)."""
        if self.P0_theta is not None:
            return self.P0_theta
        if self.start_ == "uninformed":
            return np.full(len(theta), 0.01)
        return np.maximum((P0_RELATIVE * np.abs(theta)) ** 2, 1e-8)

    @property
    def n_states(self) -> int:
        """Size of the augmented state (internal signals + parameters)."""
        return sum(self._sizes[:3]) + len(self.structure.names)

    def initialize(
        self, record_prefix: Record | None = None
    ) -> KalmanIdentifier:
        """Reset the filter: state at rest, parameters at ``theta0``, covariance at ``P0``.

        Parameters
        ----------
        record_prefix : Record, optional
            Needed when ``theta0 == "linear"``: the start is the linear ARX fit of
            :func:`~hystid.identify.offline.linear_start` on its first ``n_bootstrap`` samples.
            This bootstrap looks at those samples before the filter does (it is not causal over
            them); :meth:`fit` uses the record's own prefix.

        Returns
        -------
        KalmanIdentifier
            ``self``, ready for :meth:`update`.
        """
        s = self.structure
        # what the start is, for the default prior: "uninformed", "theta0" or "linear"
        self.start_ = "theta0"
        if np.isscalar(self.theta0) and not isinstance(self.theta0, str):
            self.start_ = "uninformed"
        if isinstance(self.theta0, str):
            if record_prefix is None:
                raise ValueError("record_prefix: theta0='linear' needs the first samples of the "
                                 "record; call initialize(record[:n_bootstrap]) or fit(record)")
            prefix = record_prefix[: self.n_bootstrap]
            theta = linear_start(prefix, s)
            if theta is None or not np.all(np.isfinite(theta)):
                warnings.warn("theta0='linear': the ARX bootstrap failed; starting from 0.01",
                              RuntimeWarning, stacklevel=2)
                theta = np.full(len(s.names), 0.01)
                self.start_ = "uninformed"
            else:
                self.start_ = "linear"
            theta = project_admissible(theta, s, _KMAX)
        else:
            theta = self._numeric_theta0(self.theta0)
        self.theta_start_ = theta.copy()
        m1, m2, m3, mu = self._sizes
        ns = m1 + m2 + m3
        kf = _SandwichEKF(self.n_states, s.layout, self._sizes)
        kf.x = np.concatenate([np.zeros(ns), theta])[:, None]
        self._P0 = np.diag(np.concatenate([self.P0_state, self._p0_theta(theta)]))
        kf.P = self._P0.copy()
        kf.Q = np.diag(np.concatenate([self.q_state, self.q_theta + self.q_anneal]))
        kf.R = np.array([[self.r]])
        self._H = np.zeros((1, self.n_states))
        self._H[0, m1 + m2] = 1.0  # the measurement is y(k)
        self._kf = kf
        self._ubuf = np.zeros(mu)
        self._u_last = 0.0
        self._good_x = kf.x.copy()
        self.k = 0
        self.n_skipped = 0
        self.n_resets = 0
        self.n_projections = 0
        self.e = 0.0
        self.K = np.zeros(self.n_states)
        self._publish()
        return self

    def _publish(self) -> None:
        kf = self._kf
        self.x = kf.x[:, 0].copy()
        self.theta = self.x[sum(self._sizes[:3]):].copy()
        self.P = kf.P

    # ------------------------------------------------------------------ one sample
    def _hx(self, x: np.ndarray) -> np.ndarray:
        i = self._sizes[0] + self._sizes[1]
        return x[i : i + 1]  # y(k), shape (1, 1)

    def _hjac(self, x: np.ndarray) -> np.ndarray:
        return self._H

    def update(self, u_k: float, y_k: float) -> np.ndarray:
        """Process one sample: predict with ``u_k``, correct with the measurement ``y_k``.

        Constant time and memory. A non-finite ``y_k`` gives a prediction without correction
        (counted in ``n_skipped``); a non-finite ``u_k`` is an error.

        Parameters
        ----------
        u_k : float
            Input at sample k.
        y_k : float
            Measured output at sample k.

        Returns
        -------
        ndarray
            The parameter estimate theta(k) (a copy).
        """
        if self._kf is None:
            self.initialize()
        u_k = as_sample(u_k, "u_k")
        y_k = as_sample(y_k, "y_k")
        if not np.isfinite(u_k):
            raise ValueError(f"u_k: expected a finite input sample, got {u_k!r}")
        skip = not np.isfinite(y_k)
        if skip:
            self.n_skipped += 1
        self._u_last = u_k
        ub = self._ubuf
        ub[1:] = ub[:-1]
        ub[0] = u_k
        kf = self._kf
        ns = self._ns
        # random walk of theta: q_theta + q_anneal exp(-k / anneal_samples)
        decay = np.exp(-self.k / self.anneal_samples)
        kf.Q[ns:, ns:] = np.diag(self.q_theta + self.q_anneal * decay)
        self.e = 0.0
        self.K = np.zeros(self.n_states)
        try:
            kf.predict(ub)
            if not skip:
                kf.update(np.array([[y_k]]), self._hjac, self._hx)
                self.e = float(kf.y[0, 0])
                self.K = kf.K[:, 0].copy()
            kf.P = 0.5 * (kf.P + kf.P.T)
            ok = True
        except (ValueError, np.linalg.LinAlgError):  # a non-finite or singular covariance
            ok = False
        self._guard(ok)
        self.k += 1
        self._publish()
        return self.theta.copy()

    def _guard(self, ok: bool = True) -> None:
        """Project theta on the admissible set; reset on a non-finite or exploding filter."""
        kf = self._kf
        if not (ok and _healthy(kf.x, kf.P, self.p_max)):
            self.n_resets += 1
            kf.x = self._good_x.copy()
            kf.P = self._P0.copy()
            return
        ns = self._ns
        theta = kf.x[ns:, 0]
        # compiled test of Assumption 1 and alpha > 0 (as constraints.is_admissible)
        if not admissible(theta, self._layout, _KMAX):
            kf.x[ns:, 0] = project_admissible(theta, self.structure, _KMAX)
            self.n_projections += 1
        if kf.x[ns + self._ia, 0] < self.alpha_min:
            kf.x[ns + self._ia, 0] = self.alpha_min
            self.n_projections += 1
        self._good_x = kf.x.copy()

    # ------------------------------------------------------------------ batch
    @property
    def model(self) -> DuhemSandwich:
        """The sandwich model of the current estimate."""
        if self._kf is None:
            raise ValueError("model: no estimate yet; call initialize(), update() or fit() first")
        return DuhemSandwich(self.theta, self.structure, fs=self.fs, name="EKF estimate")

    @property
    def settings(self) -> dict[str, Any]:
        """The constructor's configuration as plain values (for reports and JSON)."""
        t0 = self.theta0
        if isinstance(t0, Mapping):
            t0 = {k: float(v) for k, v in t0.items()}
        elif not isinstance(t0, str):
            t0 = np.asarray(t0, float).tolist()
        return {
            "structure": {k: getattr(self.structure, k)
                          for k in ("n1a", "n1b", "n2a", "n2b", "q1", "q2", "f0")},
            "fs": self.fs, "theta0": t0,
            "P0_theta": None if self.P0_theta is None else self.P0_theta.tolist(),
            "P0_state": self.P0_state.tolist(), "q_theta": self.q_theta.tolist(),
            "q_anneal": self.q_anneal.tolist(), "anneal_samples": self.anneal_samples,
            "q_state": self.q_state.tolist(), "r": self.r, "n_bootstrap": self.n_bootstrap,
            "p_max": self.p_max, "alpha_min": self.alpha_min, "epsilon": self.epsilon,
            "history": self.history, "history_rows": self.history_rows,
        }

    def reset(self) -> KalmanIdentifier:
        """Back to the start (:meth:`initialize`; a ``"linear"`` start waits for a record).

        Returns
        -------
        KalmanIdentifier
            ``self``.
        """
        if isinstance(self.theta0, str):
            self._kf = None
            self.k = self.n_skipped = 0
            return self
        return self.initialize()

    def _restart(self, record: Record) -> None:
        """:meth:`initialize`, with the record's prefix for ``theta0="linear"``."""
        record_signals(record, self.fs)
        self.initialize(record if isinstance(self.theta0, str) else None)

    def partial_fit(
        self, record: Record, progress: Callable[[int, int], None] | None = None
    ) -> IdentificationResult:
        """Run the filter over a record from its current state.

        Parameters
        ----------
        record : Record
            Input ``u`` and measured output ``y`` sampled at ``fs``.
        progress : callable, optional
            Called as ``progress(k, n)`` every 1 000 samples and at the end.

        Returns
        -------
        IdentificationResult
            ``method='ekf'``; ``history`` holds theta after each sample (N x n_params, or
            decimated: ``history_index``), ``converged_at`` the stop-index sample; ``info`` the
            counters, the start used and the RMS innovation over the last tenth of the record.
        """
        u, y, _ = record_signals(record, self.fs)
        if self._kf is None:
            self.initialize(record if isinstance(self.theta0, str) else None)
        n = len(u)
        before = self.n_skipped
        rec = HistoryRecorder(n, len(self.structure.names), 0, self.history, self.history_rows,
                              self.epsilon)
        tail = max(1, n // 10)
        innovation = np.zeros(tail)
        block = np.empty((min(n, 1000), len(self.structure.names)))
        for k in range(n):
            block[k % len(block)] = self.update(u[k], y[k])
            if k >= n - tail:
                innovation[k - (n - tail)] = self.e
            if (k + 1) % len(block) == 0 or k + 1 == n:
                rec.add(block[: k % len(block) + 1])
                if progress is not None:
                    progress(k + 1, n)
        self._warn_skipped(before)
        info = {"n_skipped": self.n_skipped, "n_resets": self.n_resets,
                "n_projections": self.n_projections, "start": self.start_,
                "theta_start": self.theta_start_.tolist(),
                "filter": "filterpy.kalman.ExtendedKalmanFilter", "samples": n,
                "rms_innovation": float(np.sqrt(np.mean(innovation ** 2))) if n else None,
                "warnings": []}
        settings = {**self.settings, "samples": n}
        history = None if rec.mode == "none" else rec.history
        index = None if rec.every == 1 else rec.index
        return IdentificationResult(self.model, "ekf", settings, history=history,
                                    converged_at=rec.converged_at, info=info,
                                    history_index=index)


#: The input and output scales (:func:`~hystid.identify.prepare.scales`: the 99.9 % quantile of
#: the input's excursion, half the output's 2-98 % spread) of the reference stage's records, in
#: volts and micrometres (6.7-6.8 and 0.9-2.9 for 0.1-1 s records): the magnitudes the
#: defaults of :class:`KalmanIdentifier` are tuned at.
TUNED_SCALES = (6.8, 1.5)


def decade_factors(record: Record) -> tuple[float, float]:
    """The powers of ten that bring a record's input and output scales nearest to
    :data:`TUNED_SCALES`.

    A change of units (mV for V, nm for um, m for um) is a power of ten, so it changes these
    factors and not the record they give.

    Parameters
    ----------
    record : Record
        A record whose input is relative to its rest level.

    Returns
    -------
    tuple of float
        ``(u_factor, y_factor)``; 1 for a signal without a finite positive scale.
    """
    u, y = record.u[np.isfinite(record.u)], record.y[np.isfinite(record.y)]
    if not (u.size and y.size):
        return 1.0, 1.0
    su, _, sy = scales(u, y, 0.0)
    return tuple(10.0 ** round(np.log10(tuned / scale)) if np.isfinite(scale) and scale > 0
                 else 1.0 for scale, tuned in zip((su, sy), TUNED_SCALES, strict=True))


#: Settings stated in the record's units: when one is given, :class:`ScaledRun` leaves the
#: record as it is.
UNIT_SETTINGS = frozenset({"r", "P0_theta", "P0_state", "q_theta", "q_anneal", "q_state",
                           "alpha_min"})


def stated_in_units(settings: Mapping[str, Any]) -> bool:
    """Whether settings of :class:`KalmanIdentifier` carry the record's units: one of
    :data:`UNIT_SETTINGS`, or a start given as a vector or a dict.

    Parameters
    ----------
    settings : mapping
        Keyword arguments of :class:`KalmanIdentifier`.

    Returns
    -------
    bool
    """
    theta0 = settings.get("theta0")
    return bool(UNIT_SETTINGS & set(settings)) or not (theta0 is None or isinstance(theta0, str)
                                                       or np.isscalar(theta0))


class ScaledRun:
    """A :class:`KalmanIdentifier` run on a record brought to the magnitudes of its defaults.

    :meth:`fit` multiplies the input and output by :func:`decade_factors`, runs the filter and
    maps the model and the parameter history back to the record's units
    (:func:`~hystid.identify.offline.to_physical`): the same model, whatever the units.

    Parameters
    ----------
    estimator : KalmanIdentifier
        The filter, configured.
    record : Record
        The record the factors are read from (input relative to its rest level).
    scale : bool
        False: factors of 1 (settings stated in the record's units, :func:`stated_in_units`).

    Attributes
    ----------
    u_factor, y_factor : float
        The factors applied.
    """

    def __init__(self, estimator: KalmanIdentifier, record: Record, scale: bool = True) -> None:
        self.estimator = estimator
        self.u_factor, self.y_factor = decade_factors(record) if scale else (1.0, 1.0)

    def fit(self, record: Record,
            progress: Callable[[int, int], None] | None = None) -> IdentificationResult:
        """Run the filter over the scaled record; the result in the record's units.

        Parameters
        ----------
        record : Record
            Input and output in any units.
        progress : callable, optional
            As :meth:`KalmanIdentifier.fit`.

        Returns
        -------
        IdentificationResult
            As :meth:`KalmanIdentifier.fit`, with ``info["scaled"]`` the factors.
        """
        cu, cy = self.u_factor, self.y_factor
        scaled = Record(record.u * cu, record.y * cy, record.fs, record.units, record.name)
        result = self.estimator.fit(scaled, progress=progress)
        s, m = self.estimator.structure, result.model
        result.model = DuhemSandwich(to_physical(m.theta, s, 1.0 / cu, 1.0 / cy), s, fs=m.fs,
                                     name=m.name, u_rest=m.u_rest / cu, offset=m.offset / cy)
        if result.history is not None:
            result.history = to_physical(result.history, s, 1.0 / cu, 1.0 / cy)
        if "theta_start" in result.info:
            result.info["theta_start"] = to_physical(np.asarray(result.info["theta_start"]), s,
                                                     1.0 / cu, 1.0 / cy).tolist()
        result.info["scaled"] = {"u": cu, "y": cy}
        return result
