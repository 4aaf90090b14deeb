"""The multi-Duhem sandwich's off-line output-error fit.

:func:`fit_mduhem_output_error` prepares the record (:func:`~hystid.identify.prepare.prepare`),
places the operators' rates on a log grid scaled to the training input (:func:`rate_grid`),
fits on normalised signals from several starts with the compiled sensitivities
(:mod:`hystid.mduhem_kernels`) and places the model back in the record's units, as the PI and
Duhem batch fits do.

With the rates fixed the output is linear in every ``f1_j, g0_j`` and the offset: each start
gets those by linear least squares for its L1 and L2, and :func:`scipy.optimize.least_squares`
then moves everything but the rates together (L1 and L2 denominators as reflection
coefficients, so they stay stable). ``fit_rates=True`` frees the rates too, in a last polish
in ``log alpha_j`` bounded by condition (8) over the training envelope.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

import numpy as np
from scipy.optimize import least_squares

from ..blas import one_blas_thread
from ..mduhem import MultiDuhemSandwich, MultiDuhemStructure
from ..operating import Envelope
from ..records import Record
from ..thresholds import largest_half_swing
from .constraints import Reflections
from .offline import SCREEN_NFEV, triangle_of
from .prepare import prepare
from .result import IdentificationResult

__all__ = ["POLISHED", "RATE_HIGH", "RATE_LOW", "RATE_SLEW", "RIDGE", "fit_mduhem_output_error",
           "mduhem_output_sensitivities", "rate_grid"]

#: The slowest operator's rate times the span of the training input: one sweep of the range
#: forgets all but ``exp(-RATE_LOW)`` of the state an operator started from (the wiping-out
#: of :data:`hystid.identify.offline.WIPE_OUT`). A slower operator carries the unknown state
#: it started from through the record, like a play threshold wider than the input's swings.
RATE_LOW = 1.0
#: The fastest operator's rate times the input's largest half swing: it saturates over a
#: ``1 / RATE_HIGH`` share of the swing (the corner of a loop, and minor loops that small).
RATE_HIGH = 30.0
#: Largest ``alpha_j |dw1|`` at the training input's slew (:class:`~hystid.operating.Envelope`):
#: below 1 the recursion never steps past its anhysteretic line (condition 8 asks < 2).
RATE_SLEW = 1.0
#: Ridge on the normalised ``f1_j, g0_j``: the cost is ``sum r^2 + RIDGE n |w_n|^2`` (``n``
#: samples in the cost). Operators of neighbouring rates have nearly collinear outputs; without
#: it their slopes drift to large opposite values along a flat valley of the cost (on stage A
#: with six operators, 1e-8 left them there: 51-88 nm held out on the sines and triangles
#: against 28-36 nm with 1e-6).
RIDGE = 1e-6
#: Starts polished after the screening (the best ones).
POLISHED = 2


def rate_grid(u: np.ndarray, n_operators: int, *, low: float = RATE_LOW,
              high: float = RATE_HIGH, slew_limit: float = RATE_SLEW) -> np.ndarray:
    """The operators' rates: a log grid scaled to the input's span and swings.

    ``alpha_j`` from ``low / span`` (the slowest operator forgets its start over one sweep of
    the input's range) to ``high / s`` (``s`` the largest half swing between two turning
    points, :func:`hystid.thresholds.largest_half_swing`: the fastest bends over a ``1 / high``
    share of it), the top kept at ``slew_limit / slew`` (``slew`` the envelope's, so
    ``alpha_j |du| <= slew_limit`` on the training input and condition 8 holds with a margin).
    With a unit-gain L1 ``w1`` moves like the input less its rest, so the grid depends only on
    differences of the input: an offset does not move it and a change of units scales it.

    Parameters
    ----------
    u : ndarray
        The identification input (the samples fitted).
    n_operators : int
        Number of operators ``m``.
    low : float
        The slowest rate times the input's span.
    high : float
        The fastest rate times the input's largest half swing.
    slew_limit : float
        Largest ``alpha_j`` times the input's slew.

    Returns
    -------
    ndarray
        ``m`` increasing rates (all equal when the top falls below the bottom), in inverse input
        units.

    Raises
    ------
    ValueError
        When the input does not move, or an option is not a positive number.
    """
    if isinstance(n_operators, bool) or int(n_operators) != n_operators or n_operators < 1:
        raise ValueError(f"n_operators: expected a positive integer, got {n_operators!r}")
    for key, value in (("low", low), ("high", high), ("slew_limit", slew_limit)):
        if not (np.isfinite(value) and value > 0):
            raise ValueError(f"{key}: expected a positive number, got {value!r}")
    u = np.asarray(u, dtype=float)
    s = largest_half_swing(u)
    if not s > 0:
        raise ValueError("u: the input does not move (no swing to scale the rates to)")
    top = high / s
    slew = Envelope.of(u).slew
    if slew > 0:
        top = min(top, slew_limit / slew)
    bottom = min(low / float(np.ptp(u)), top)
    return np.geomspace(bottom, top, int(n_operators))


def _coefficient_map(structure: MultiDuhemStructure) -> np.ndarray:
    """``T = d c / d theta``: the full kernel coefficients (:mod:`hystid.mduhem_kernels`) are
    affine in the free parameters; the derived ``b11, b21`` make the rows that are not one
    entry (``b_1 = 1 + sum a - sum b_rest``). The rates' rows are zero."""
    from ..mduhem_kernels import coefficient_offsets

    s = structure
    sl = s.slices()
    index = np.arange(len(s.names))
    ia1, ib1, ial, if1, ig0, ia2, ib2, nc = coefficient_offsets(s.layout)
    T = np.zeros((nc, len(s.names)))
    for a, b, ia, ib in (("a1", "b1", ia1, ib1), ("a2", "b2", ia2, ib2)):
        for i, t in enumerate(index[sl[a]]):
            T[ia + i, t] = 1.0
            T[ib, t] = 1.0
        for j, t in enumerate(index[sl[b]]):
            T[ib + 1 + j, t] = 1.0
            T[ib, t] = -1.0
    for key, start in (("f1", if1), ("g0", ig0)):
        for j, t in enumerate(index[sl[key]]):
            T[start + j, t] = 1.0
    return T


def mduhem_output_sensitivities(model: MultiDuhemSandwich, u: np.ndarray,
                                rates: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """Free run from rest of a model relative to its rest (``u`` less ``u_rest``, no offset)
    and the Jacobian of its output.

    Parameters
    ----------
    model : MultiDuhemSandwich
        The model (its placement is ignored).
    u : ndarray
        Input samples relative to the rest.
    rates : bool
        Append the columns ``d y / d alpha_j``.

    Returns
    -------
    yhat : ndarray
        The output, ``N`` samples.
    J : ndarray
        ``d yhat / d theta`` (``N x len(theta)``), then ``d yhat / d alpha`` with ``rates``.
    """
    from ..mduhem_kernels import coefficient_offsets, mduhem_sensitivities_into

    s = model.structure
    lay = s.layout
    c = model.coefficients
    nc = len(c)
    P, n = s.history, len(u)
    U = np.r_[np.zeros(P), np.asarray(u, dtype=float)]
    W1, W2, Y = (np.zeros(P + n) for _ in range(3))
    S1, SW2, SY = (np.zeros((P + n, nc)) for _ in range(3))
    SP = np.zeros((s.n_operators, s.n1a + s.n1b + 3))
    p = np.zeros(s.n_operators)
    mduhem_sensitivities_into(c, lay, U, W1, W2, Y, p, S1, SW2, SY, SP, P)
    T = _coefficient_map(s)
    J = SY[P:] @ T
    if rates:
        ial = coefficient_offsets(lay)[2]
        J = np.hstack([J, SY[P:, ial:ial + s.n_operators]])
    return Y[P:], J


def _folded(J: np.ndarray, r: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``[J | r]`` folded into its square QR triangle: residuals and Jacobian of the same norm,
    gradient and ``J'J`` (non-finite rows give non-finite residuals: a failed step)."""
    A = np.column_stack([J, r])
    if not np.all(np.isfinite(A)):
        return np.full(A.shape[1], np.nan), np.zeros((A.shape[1], A.shape[1] - 1))
    tri = triangle_of(A)
    return tri[:, -1].copy(), tri[:, :-1].copy()


class _Problem:
    """The output-error problem on normalised signals in ``z = [theta with L1's and L2's
    denominators as reflection coefficients | log alpha_j (with free rates) | y0]``."""

    def __init__(self, un: np.ndarray, yn: np.ndarray, rows: np.ndarray,
                 structure: MultiDuhemStructure, rates: np.ndarray, fit_offset: bool,
                 free_rates: bool = False, rate_bounds: tuple[float, float] | None = None):
        s = self.structure = structure
        self.un, self.rows, self.target = un, rows, yn[rows]
        self.rates, self.fit_offset, self.free_rates = rates, fit_offset, free_rates
        self.rate_bounds = rate_bounds
        self.n = len(s.names)
        self.m = s.n_operators
        sl, index = s.slices(), np.arange(self.n)
        self.rp = Reflections([index[sl["a1"]], index[sl["a2"]]], self.n)
        self.weights = np.r_[index[sl["f1"]], index[sl["g0"]]]
        self.ridge = np.sqrt(RIDGE * len(rows))
        self.nz = self.n + (self.m if free_rates else 0) + int(fit_offset)
        self.ridge_rows = np.zeros((len(self.weights), self.nz))
        self.ridge_rows[np.arange(len(self.weights)), self.weights] = self.ridge
        self._cache: dict[str, Any] = {}

    def to_z(self, theta: np.ndarray, y0: float, rates: np.ndarray | None = None) -> np.ndarray:
        """Search coordinates of parameters, an offset and (with free rates) the rates."""
        z = [self.rp.to_z(theta)]
        if self.free_rates:
            z.append(np.log(self.rates if rates is None else rates))
        return np.concatenate(z + [[y0] * self.fit_offset])

    def split(self, z: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
        """Parameters, rates and offset of ``z``."""
        theta = self.rp.to_theta(z[: self.n])[0]
        rates = np.exp(z[self.n: self.n + self.m]) if self.free_rates else self.rates
        return theta, rates, float(z[-1]) if self.fit_offset else 0.0

    def model(self, theta: np.ndarray, rates: np.ndarray) -> MultiDuhemSandwich:
        """The normalised model of ``theta`` and ``rates``."""
        return MultiDuhemSandwich(theta, rates, self.structure, fs=1.0)

    def evaluate(self, z: np.ndarray) -> dict[str, Any]:
        """Folded residuals and Jacobian at ``z`` and the data residuals (``data``); cached for
        the last ``z``."""
        if self._cache.get("z") is not None and np.array_equal(self._cache["z"], z):
            return self._cache
        theta, dtheta = self.rp.to_theta(z[: self.n])
        _, rates, y0 = self.split(z)
        with np.errstate(over="ignore", invalid="ignore"):
            yhat, J = mduhem_output_sensitivities(self.model(theta, rates), self.un,
                                                  self.free_rates)
            data = yhat[self.rows] + y0 - self.target
            cols = [J[self.rows, : self.n] @ dtheta]
            if self.free_rates:
                cols.append(J[self.rows, self.n:] * rates)  # d / d log alpha
            if self.fit_offset:
                cols.append(np.ones((len(self.rows), 1)))
            Jz = np.vstack([np.hstack(cols), self.ridge_rows])
            r = np.r_[data, self.ridge * theta[self.weights]]
        res, jac = _folded(Jz, r)
        self._cache = {"z": z.copy(), "data": data, "r": res, "J": jac}
        return self._cache

    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """Lower and upper bounds of ``z`` (a first-order L1's pole on ``[0, 1)``: a lag)."""
        lo, hi = self.rp.bounds()
        if self.structure.n1a == 1:
            hi[self.structure.slices()["a1"].start] = 0.0
        if self.free_rates:
            a, b = self.rate_bounds or (-np.inf, np.inf)
            lo, hi = np.r_[lo, np.full(self.m, np.log(a))], np.r_[hi, np.full(self.m, np.log(b))]
        extra = int(self.fit_offset)
        return np.r_[lo, [-np.inf] * extra], np.r_[hi, [np.inf] * extra]

    def solve(self, z0: np.ndarray, max_nfev: int, tol: float):
        """``least_squares`` from ``z0`` within :meth:`bounds`."""
        lo, hi = self.bounds()
        with np.errstate(over="ignore", invalid="ignore"):
            return least_squares(lambda z: self.evaluate(z)["r"], np.clip(z0, lo, hi),
                                 jac=lambda z: self.evaluate(z)["J"], bounds=(lo, hi),
                                 method="trf", ftol=tol, xtol=tol, gtol=tol, max_nfev=max_nfev,
                                 x_scale="jac")


def _weights_given_blocks(theta: np.ndarray, problem: _Problem) -> tuple[np.ndarray, float]:
    """``theta`` with its ``f1_j, g0_j`` (and the offset) set by linear least squares for its
    L1 and L2 and the problem's rates: exact, since the output is linear in them."""
    theta = np.array(theta, dtype=float)
    w = problem.weights
    theta[w] = 0.0
    with np.errstate(over="ignore", invalid="ignore"):
        _, J = mduhem_output_sensitivities(problem.model(theta, problem.rates), problem.un)
    A = J[problem.rows][:, w]
    if not np.all(np.isfinite(A)):
        raise ValueError("rates: the operators' recursion diverges on the record (condition 8, "
                         "max_j alpha_j |dw1| < 2, fails); expected smaller rates")
    if problem.fit_offset:
        A = np.column_stack([A, np.ones(len(problem.rows))])
    k = len(w)
    A = np.vstack([A, problem.ridge * np.eye(k, A.shape[1])])
    coef, *_ = np.linalg.lstsq(A, np.r_[problem.target, np.zeros(k)], rcond=None)
    theta[w] = coef[:k]
    return theta, float(coef[-1]) if problem.fit_offset else 0.0


def _arx_blocks(problem: _Problem, yn: np.ndarray) -> np.ndarray | None:
    """L1 and L2 of the linear sandwich's ARX fit (unit DC gains), as the PI fit starts."""
    from ..pi import PIStructure
    from .pi_batch import _arx_blocks as pi_arx_blocks

    s = problem.structure
    pis = PIStructure(n_operators=1, n1a=s.n1a, n1b=s.n1b, n2a=s.n2a, n2b=s.n2b, q1=s.q1,
                      q2=s.q2)
    blocks = pi_arx_blocks(problem.un, yn, problem.rows, pis)
    if blocks is None:
        return None
    values = dict(zip(pis.names, blocks, strict=True))
    return np.array([values.get(n, 0.0) for n in s.names])


def _starts(problem: _Problem, yn: np.ndarray,
            theta0: np.ndarray | None) -> dict[str, tuple[np.ndarray, float]]:
    """``theta0`` alone when given; else ``L1 = 1, L2 = z^-q2`` (every free coefficient zero),
    the linear sandwich's ARX L2 with ``L1 = 1`` and, when L1 has free coefficients, its ARX
    L1 too; each with the slopes and offset that fit best for its blocks."""
    if theta0 is not None:
        if not problem.model(theta0, problem.rates).is_stable():
            raise ValueError("theta0: the start must have stable L1 and L2")
        theta, y0 = np.asarray(theta0, dtype=float), 0.0
        if problem.fit_offset:  # the offset that fits best for the start as it is
            yhat = mduhem_output_sensitivities(problem.model(theta, problem.rates),
                                               problem.un)[0]
            y0 = float(np.mean(problem.target - yhat[problem.rows]))
        return {"theta0": (theta, y0)}
    blocks = {"unit blocks": np.zeros(problem.n)}
    arx = _arx_blocks(problem, yn)
    if arx is not None:
        sl = problem.structure.slices()
        l1 = np.isin(np.arange(problem.n), np.r_[np.arange(problem.n)[sl["a1"]],
                                                 np.arange(problem.n)[sl["b1"]]])
        blocks["ARX L2"] = np.where(l1, 0.0, arx)
        lo, hi = problem.bounds()
        both = np.clip(problem.rp.to_z(arx), lo[: problem.n], hi[: problem.n])
        if l1.any():
            blocks["ARX L1 and L2"] = problem.rp.to_theta(both)[0]
    unique: dict[str, np.ndarray] = {}
    for label, theta in blocks.items():
        if not any(np.array_equal(theta, other) for other in unique.values()):
            unique[label] = theta
    return {label: _weights_given_blocks(theta, problem) for label, theta in unique.items()}


def _scale(theta: np.ndarray, structure: MultiDuhemStructure, factor: float) -> np.ndarray:
    """``theta`` with its slopes ``f1_j, g0_j`` times ``factor`` (output per input units)."""
    out = np.array(theta, dtype=float)
    sl = structure.slices()
    out[sl["f1"]] *= factor
    out[sl["g0"]] *= factor
    return out


@one_blas_thread
def fit_mduhem_output_error(
    record: Record,
    structure: MultiDuhemStructure | None = None,
    *,
    rates: np.ndarray | None = None,
    fit_rates: bool = False,
    theta0: np.ndarray | None = None,
    offset: bool = True,
    skip: int | None = None,
    left_out: Sequence[tuple[int, int]] = (),
    max_nfev: int = 100,
    tol: float = 1e-8,
    name: str = "identified multi-Duhem sandwich",
    say: Callable[[str], None] | None = None,
) -> IdentificationResult:
    """Identify the multi-Duhem sandwich off-line by output-error least squares.

    The steps, as in the PI batch fit (:func:`hystid.identify.pi_batch.fit_pi_output_error`):
    :func:`~hystid.identify.prepare.prepare` the record; place the rates over the fitted
    input (:func:`rate_grid`) unless given; fit on the input less its rest over its scale and
    the output over its scale (so that nothing depends on the units); map the rates and slopes
    back and place the model at the record's rest level, sensor offset, input envelope and
    units.

    The fit minimises ``sum_k (y(k) - yhat(k) - y0)^2 + RIDGE n |w|^2`` over the free run from
    rest (``w`` the normalised slopes, :data:`RIDGE`) with :func:`scipy.optimize.least_squares`
    and the compiled Jacobian, L1's and L2's denominators as reflection coefficients. The
    starts (``L1 = 1, L2 = z^-q2`` and the linear sandwich's ARX blocks, each with its best
    slopes and offset by linear least squares) run for
    :data:`~hystid.identify.offline.SCREEN_NFEV` evaluations; the :data:`POLISHED` best are
    polished.

    Parameters
    ----------
    record : Record
        Input ``u`` and measured output ``y``, in any units.
    structure : MultiDuhemStructure, optional
        Orders, delays and the number of operators (the default structure by default).
    rates : array_like, optional
        The operators' rates in inverse input units instead of :func:`rate_grid`'s.
    fit_rates : bool
        Free the rates in a last polish (``log alpha_j``, between a tenth of the grid's
        lowest and the rate at which condition 8 holds with :data:`RATE_SLEW` on the training
        input's slew).
    theta0 : array_like, optional
        Start vector in record units (with ``rates``) instead of the default starts.
    offset : bool
        Estimate the sensor offset (default); without it the output is taken as zero at rest.
    skip : int, optional
        Leading samples simulated but left out of the cost; by default none for a record that
        starts at rest, else until the input has swept its range.
    left_out : sequence of (int, int)
        Spans ``[first, stop)`` of samples simulated but left out of the cost (the model
        choice's held-out block).
    max_nfev : int
        Evaluations of each polish.
    tol : float
        ``ftol``, ``xtol`` and ``gtol`` of the solver.
    name : str
        Name of the identified model.
    say : callable, optional
        Called with a progress line at each stage of the fit.

    Returns
    -------
    IdentificationResult
        ``method="mduhem-batch"``; ``info`` holds the RMS residual (record units), the solver's
        message, the start kept, the rates, the scales, the offset, the condition-8 bound over
        the training envelope and ``warnings`` (what the preparation found, and whether the
        model is admissible on the record).

    Raises
    ------
    ValueError
        For a record shorter than ten samples per parameter, rates that do not match the
        structure or a ``theta0`` of another length.
    """
    s = structure or MultiDuhemStructure()
    if not isinstance(s, MultiDuhemStructure):
        raise TypeError(f"structure: expected a MultiDuhemStructure, got {type(s).__name__}")
    from . import SAMPLES_PER_PARAMETER

    need = SAMPLES_PER_PARAMETER * len(s.names)
    if record.n < need:
        raise ValueError(f"record {record.name!r}: {record.n} samples are too few for the "
                         f"multi-Duhem fit (expected at least {need}: {SAMPLES_PER_PARAMETER} "
                         f"per parameter)")
    say = say or (lambda line: None)
    prep = prepare(record, skip=skip, left_out=left_out)
    if not offset:
        prep.y_ref, prep.yn = 0.0, record.y / prep.y_scale
    su, sy = prep.u_scale, prep.y_scale
    fitted_un = prep.un[prep.fitted]
    if rates is None:
        rates_n = rate_grid(fitted_un, s.n_operators)
    else:
        rates_n = np.asarray(rates, dtype=float).ravel() * su
        if rates_n.shape != (s.n_operators,) or not np.all(np.isfinite(rates_n) & (rates_n > 0)):
            raise ValueError(f"rates: expected {s.n_operators} positive rates (one per "
                             f"operator), got {rates!r}")
    theta0_n = None
    if theta0 is not None:
        theta0 = np.asarray(theta0, dtype=float).ravel()
        if theta0.shape != (len(s.names),):
            raise ValueError(f"theta0: expected {len(s.names)} values {list(s.names)}, got "
                             f"shape {theta0.shape}")
        theta0_n = _scale(theta0, s, su / sy)
    rows = np.flatnonzero(prep.weight)
    problem = _Problem(prep.un, prep.yn, rows, s, rates_n, offset)
    starts = _starts(problem, prep.yn, theta0_n)
    screened = []
    for i, (label, (theta, y0)) in enumerate(starts.items()):
        say(f"multi-Duhem fit of {record.n} samples: start {i + 1} of {len(starts)} ({label})")
        sol = problem.solve(problem.to_z(theta, y0), SCREEN_NFEV if len(starts) > 1
                            else max_nfev, tol)
        screened.append((sol.cost, label, sol))
    screened.sort(key=lambda item: item[0])
    polished = []
    for _, label, sol in screened[:POLISHED]:
        if len(starts) > 1:
            say(f"multi-Duhem fit: polishing the start {label}")
            sol = problem.solve(sol.x, max_nfev, tol)
        polished.append((sol.cost, label, sol))
    _, label, sol = min(polished, key=lambda item: item[0])
    theta_n, _, y0n = problem.split(sol.x)
    nfev = sum(int(item[2].nfev) for item in polished)
    env_n = Envelope.of(fitted_un)
    if fit_rates:
        say("multi-Duhem fit: freeing the rates")
        top = RATE_SLEW / env_n.slew if env_n.slew > 0 else 10.0 * np.max(rates_n)
        free = _Problem(prep.un, prep.yn, rows, s, rates_n, offset, free_rates=True,
                        rate_bounds=(0.1 * np.min(rates_n), max(top, np.max(rates_n))))
        sol = free.solve(free.to_z(theta_n, y0n), max_nfev, tol)
        theta_n, rates_n, y0n = free.split(sol.x)
        problem, nfev = free, nfev + int(sol.nfev)
    data = problem.evaluate(sol.x)["data"]
    model = MultiDuhemSandwich(_scale(theta_n, s, sy / su), rates_n / su, s, fs=record.fs,
                               name=name, u_rest=prep.u_rest, offset=prep.offset(y0n),
                               envelope=prep.envelope, units=record.units)
    bound = model.envelope_bound()
    notes = list(prep.notes)
    if bound >= 2.0:
        notes.append(f"the model is not admissible over its own training envelope "
                     f"(condition 8 bound {bound:.3g} >= 2): it may diverge on inputs like the "
                     "training input")
    notes += [f"on the training record: {w}" for w in model.admissibility(record.u)
              if "condition (8)" in w or "diverged" in w]
    info = {"rms_residual": float(np.sqrt(np.mean(data ** 2)) * sy), "nfev": nfev,
            "message": str(sol.message), "start": label, "rates": model.rates.tolist(),
            "envelope_bound": bound, "scales": {"u": su, "y": sy}, "offset": model.offset,
            "at_rest": prep.at_rest, "skip": prep.skip, "warnings": notes}
    settings = {"n_operators": s.n_operators, "fit_rates": fit_rates, "offset": offset,
                "skip": prep.skip, "max_nfev": max_nfev, "tol": tol, "samples": record.n,
                "starts": list(starts)}
    return IdentificationResult(model, "mduhem-batch", settings, info=info)
