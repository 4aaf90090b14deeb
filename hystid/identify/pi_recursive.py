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
kV, um or m. The stage's rest (``u_rest``, ``offset``): the recursion runs on the input less the
level the stage rests at and the output less the output there (the first record's first input
value and its output while the input holds it, unless given), as it starts its play operators
and L1, L2 at zero; the model carries both back. Every output (the estimate and its history,
the model, :meth:`update`'s return value, ``e``, ``yhat``, ``K``, ``P``, ``Lambda^-1``) is mapped
back to the record's units: only the weights carry units (output per input). A cold start has
no samples to take scales from and runs in the record's units.

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
from typing import Any

import numpy as np

from ..blas import one_blas_thread
from ..pi import N_OPERATORS, PISandwich, PIStructure, pi_thresholds
from ..records import Record
from .base import Estimator, record_signals, sample_arrays
from .pi_batch import _fit_normalised_from_zero, _scale_weights, _zero_result, fit_pi_output_error
from .pi_kernels import _layout, _n_full, pi_output_sensitivities, recursion_one, recursion_run
from .result import IdentificationResult, converged_at

__all__ = [
    "PIRecursiveIdentifier",
    "fit_pi_output_error",
    "identify_pi",
    "keyterm_to_model",
    "pi_output_sensitivities",
]


FORMS = ("key-term", "output-error")
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
    u_rest, offset : float, optional
        The input level the stage rests at before the first sample, and the output there.
        The recursion runs on ``u - u_rest`` and ``y - offset`` (its operators and filters start
        at zero, at rest) and the model carries them. By default: the first input value the
        identifier sees, and the median of the finite outputs while the input holds that
        value (the first sample's output for :meth:`update`; 0 when none is finite).
        ``thresholds`` are in the input less ``u_rest``.

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
    u_rest_, offset_ : float or None
        The rest level and output at rest in use (None before the first sample).

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
        u_rest: float | None = None,
        offset: float | None = None,
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
        for label, value in (("u_rest", u_rest), ("offset", offset)):
            if value is not None and not np.isfinite(value):
                raise ValueError(f"{label}: expected a finite number or None, got {value!r}")
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
        self.u_rest = None if u_rest is None else float(u_rest)
        self.offset = None if offset is None else float(offset)
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
                "thresholds": None if r is None else np.asarray(r, float).ravel().tolist(),
                "u_rest": self.u_rest, "offset": self.offset}

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
        return _scale_weights(theta, self.structure_, self._sy, self._su)

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
        self.u_rest_: float | None = self.u_rest
        self.offset_: float | None = self.offset
        if self.thresholds is not None:
            self._start(self.thresholds)
        return self

    def _start(self, thresholds: Any) -> None:
        """Allocate the recursion's state for these thresholds (theta0, P0, at rest)."""
        s = self._structure()
        if s.n_poly:
            raise ValueError(f"structure: the paper's PI recursion runs the plays alone; got "
                             f"n_poly={s.n_poly} polynomial terms (identify them off-line, "
                             "method='batch', or on-line in the pi-stage shape: "
                             "hystid.identify.pi_online.PIStageOnline)")
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
                          fs=self.fs, name="identified PI sandwich",
                          u_rest=self.u_rest_ or 0.0, offset=self.offset_ or 0.0)

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
        if (self._ready and not self.warming_up and self.offset_ is not None
                and isinstance(u_k, float) and isinstance(y_k, float)
                and u_k - u_k == 0.0):  # the real-time path
            return self._update_one(u_k, y_k)
        u, y = sample_arrays(u_k, y_k)
        self._require_start()
        u, y = self._relative(u, y)
        history = np.empty((1, len(self.names)))
        errors, yhats = np.zeros(1), np.zeros(1)
        self._process(u, y, history, errors, yhats)
        return history[0].copy()

    def _update_one(self, u_k: float, y_k: float) -> np.ndarray:
        """One sample after the warm-up: one compiled call on the signal windows, in place."""
        U, W1, W2, Y, S1, SW2, SY, PH, SPH = self._windows
        recursion_one(self._mode, self._theta, self._U, self._D, self._lam, self.gamma, self.k,
                      self.layout_, self._rn, U, W1, W2, Y, S1, SW2, SY, PH, SPH, self._p,
                      self._SP, (u_k - self.u_rest_) / self._su,
                      (y_k - self.offset_) / self._sy, self._K, self._last)
        self.k += 1
        if y_k - y_k != 0.0:
            self.n_skipped += 1
        self.e = float(self._last[0] * self._sy)
        self.yhat = float(self._last[1] * self._sy) + self.offset_
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
        yhats[w:] = yhats[w:] * self._sy + self.offset_
        self.e, self.yhat = float(errors[-1]), float(yhats[-1])
        return w

    def _run(self, arrays, start, k0, y, history, errors, yhats) -> None:
        U, W1, W2, Y, S1, SW2, SY, PH, SPH = arrays
        recursion_run(self._mode, self._theta, self._U, self._D, self._lam, self.gamma,
                      k0, self.layout_, self._rn, U, W1, W2, Y, S1, SW2, SY, PH, SPH,
                      self._p, self._SP, start, y, history, errors, yhats, self._K)

    # ----------------------------------------------------------------- a record
    def _restart(self, record: Record) -> None:
        """:meth:`reset`, thresholds placed over the record's range when not given, and a record
        refused that is shorter than the warm-up."""
        u, y, name = record_signals(record, self.fs)
        self.reset()
        u, _ = self._relative(u, y)
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

    def _relative(self, u: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The input less the rest level and the output less the output at rest, both taken
        from these samples when not known yet (the first input value; the median of the
        finite outputs while the input holds it)."""
        if self.u_rest_ is None:
            self.u_rest_ = float(u[0])
        if self.offset_ is None:
            span = float(np.ptp(u)) if len(u) > 1 else 0.0
            moved = np.flatnonzero(np.abs(u - self.u_rest_) > 1e-6 * span)
            head = y[: int(moved[0]) if len(moved) else len(y)]
            head = head[np.isfinite(head)]
            self.offset_ = float(np.median(head)) if head.size else 0.0
        return u - self.u_rest_, y - self.offset_

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
        u, y = self._relative(u, y)
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


# =========================================================================== entry point
@one_blas_thread
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
