"""Off-line output-error (simulation-error) identification: the reference for on-line methods.

Minimises ``sum_k (y(k) - yhat(k | theta))^2`` where ``yhat`` is the free-run simulation of the
sandwich, with scipy's trust-region least squares. The Jacobian comes from the compiled
forward-sensitivity kernel; the search runs in reflection coefficients so that L1 and L2 stay
stable and minimum phase, and alpha stays positive (Assumption 1).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

import numpy as np
from scipy.linalg import qr
from scipy.optimize import least_squares

from ..blas import one_blas_thread
from ..kernels import jacobian_block, sensitivities_into, simulate_into
from ..model import DuhemSandwich, InitialCondition, Structure
from ..operating import Envelope
from ..records import Record
from ..threads import check_cancelled
from .constraints import Reflections, polynomial_groups
from .prepare import Prepared, prepare
from .result import IdentificationResult

__all__ = ["BOUND_MAX", "fit_output_error", "initial_theta", "linear_start",
           "output_sensitivities", "to_normalised", "to_physical"]


def initial_theta(structure: Structure, theta0: float | dict | np.ndarray) -> np.ndarray:
    """Start vector from a scalar (every parameter, as in the paper), a dict or a vector.

    Parameters
    ----------
    structure : Structure
        The model structure.
    theta0 : float, dict or ndarray
        One value for every parameter, values by name, or the vector.

    Returns
    -------
    ndarray
        The start vector in the order of ``structure.names``.
    """
    names = structure.names
    try:
        if np.isscalar(theta0):
            theta = np.full(len(names), float(theta0))
        elif isinstance(theta0, dict):
            return DuhemSandwich(theta0, structure).theta
        else:
            theta = np.asarray(theta0, dtype=float).ravel()
    except (TypeError, ValueError, OverflowError) as err:
        if str(err).startswith("theta0"):
            raise
        raise ValueError(f"theta0: expected a finite scalar or {len(names)} values "
                         f"{list(names)}, got {theta0!r} ({err})") from err
    if theta.shape != (len(names),) or not np.all(np.isfinite(theta)):
        raise ValueError(f"theta0: expected a finite scalar or {len(names)} values {list(names)}")
    return theta


def output_sensitivities(
    theta: np.ndarray, structure: Structure, u: np.ndarray, x0: InitialCondition | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """Simulated output ``yhat`` and its Jacobian ``d yhat / d theta`` (N x n_params).

    Parameters
    ----------
    theta : ndarray
        Parameter vector in the order of ``structure.names``.
    structure : Structure
        The model structure.
    u : ndarray
        Input samples (relative to the rest).
    x0 : InitialCondition, optional
        Past signal values; at rest by default.

    Returns
    -------
    tuple of ndarray
        ``yhat`` (N) and its Jacobian (N x n_params).
    """
    x0 = x0 or InitialCondition()
    P = structure.history
    n = len(u)
    U, W1, W2, Y = (
        np.concatenate([x0.window(k, P), np.zeros(n)]) for k in ("u", "w1", "w2", "y")
    )
    U[P:] = u
    npar = len(theta)
    S1, S2, SY = (np.zeros((P + n, npar)) for _ in range(3))
    sensitivities_into(np.asarray(theta, float), structure.layout, U, W1, W2, Y, S1, S2, SY, P)
    return Y[P:], SY[P:]


def linear_start(
    record: Record, structure: Structure, alpha: float = 1.0, *, with_offset: bool = False,
    observed: np.ndarray | None = None,
) -> np.ndarray | tuple[np.ndarray, float] | None:
    """A data-driven start: the sandwich's linear part from an ARX fit.

    With ``f1 = g0`` and ``w2`` at rest the Duhem block is the gain ``g0``, so the sandwich is the
    linear model ``y = g0 z^-(q1+q2) B1 B2 / (A1 A2) u``. Its ARX least-squares fit gives the
    product polynomials; the denominator's roots are split between ``A1`` (real roots farthest
    from the unit circle) and ``A2`` (complex pairs, the flexure mode, first), numerator roots
    likewise, and unstable roots are reflected into the unit circle. Returns ``None`` when the
    roots cannot be split into real polynomials of the required orders. With ``with_offset``
    the regression also holds a constant, and ``(theta, offset)`` is returned: the output's
    level at zero input.

    Parameters
    ----------
    record : Record
        The record (input relative to the rest).
    structure : Structure
        Orders and delays of the sandwich.
    alpha : float
        The ``alpha`` given to the start (the linear fit does not see it).
    with_offset : bool
        Fit a constant too and return it.
    observed : ndarray of bool, optional
        Which outputs may be read (the others filled in: a block held out for the model
        choice): a regression row is used only when its output and its past outputs may.
        Regressed on a straight line filled in across 1 800 samples of the reference stage
        held out, the rows put the Duhem fit's every start in one basin, 230 times the
        residual of the fit without the block.

    Returns
    -------
    ndarray, tuple of (ndarray, float), or None
        The start vector, with the offset when ``with_offset``; None when no split exists.
    """
    s = structure
    na, nb, q = s.n1a + s.n2a, s.n1b + s.n2b, s.q1 + s.q2
    u, y = record.u, record.y
    lag = max(na, q + nb, 1)
    if len(y) <= lag + na + nb + 2:
        return None
    width = na + nb + 1 + int(with_offset)
    used = None
    if observed is not None:  # the row of y(k) regresses on y(k - 1) .. y(k - na)
        seen = np.asarray(observed, bool)
        used = seen.copy()
        for i in range(1, na + 1):
            used[i:] &= seen[:-i]
    qr_rows = _RunningQR(width + 1)  # [phi | y] reduced block by block: memory of one block
    for a in range(lag, len(y), SENS_WINDOW):
        b = min(len(y), a + SENS_WINDOW)
        phi = qr_rows.rows(b - a)
        for i in range(1, na + 1):
            np.negative(y[a - i: b - i], out=phi[:, i - 1])
        for j in range(nb + 1):
            phi[:, na + j] = u[a - q - j: b - q - j]
        if with_offset:
            phi[:, width - 1] = 1.0
        phi[:, width] = y[a:b]
        if used is not None:
            phi[~used[a:b]] = 0.0  # a zero row adds nothing to the triangle
    tri = qr_rows.triangle()
    coef = np.linalg.lstsq(tri[:width, :width], tri[:width, width], rcond=None)[0]
    constant = coef[-1] if with_offset else 0.0
    coef = coef[:na + nb + 1]
    den, num = np.r_[1.0, coef[:na]], coef[na:]
    gain = num[0]
    if not np.isfinite(gain) or gain == 0:
        return None
    A1, A2 = _split_roots(np.roots(den), s.n1a)
    B1, B2 = _split_roots(np.roots(num / gain), s.n1b) if nb else (np.zeros(0), np.zeros(0))
    if A1 is None or B1 is None:
        return None
    values = {"alpha": alpha, "f1": gain, "g0": gain, "f0": 0.0}
    for prefix, poly in (("a1", A1), ("a2", A2), ("b1", B1), ("b2", B2)):
        values.update({f"{prefix}{i + 1}": c for i, c in enumerate(poly)})
    theta = np.array([values.get(n, 0.0) for n in s.names])  # a linear start: no shape terms
    if with_offset:
        return theta, float(constant / np.sum(den))
    return theta


def _split_roots(roots: np.ndarray, n_first: int):
    """Split roots into a first polynomial of order ``n_first`` (real roots farthest from the
    unit circle) and a second one (the rest); both monic, real, with roots inside the circle."""
    roots = np.where(np.abs(roots) >= 1.0, 0.999 * roots / np.abs(roots) ** 2, roots)
    real = sorted((r for r in roots if abs(r.imag) < 1e-9), key=lambda r: abs(r))
    if len(real) < n_first:
        return None, None
    first = np.array([r.real for r in real[:n_first]])
    rest = list(roots)
    for r in real[:n_first]:
        rest.remove(r)
    p1 = np.real(np.poly(first))[1:] if n_first else np.zeros(0)
    p2 = np.real(np.poly(rest))[1:] if rest else np.zeros(0)
    return p1, p2


class _Reparam(Reflections):
    """theta <-> z for the Duhem sandwich: its polynomial groups as reflection coefficients,
    alpha kept positive."""

    def __init__(self, structure: Structure):
        self.ialpha = structure.names.index("alpha")
        super().__init__(polynomial_groups(structure), len(structure.names), (self.ialpha,))
        #: entries of z that the envelope bound depends on (alpha, L1's polynomials)
        self.l1_and_alpha = [self.ialpha] + [
            structure.names.index(n) for n in structure.names if n[:2] in ("a1", "b1")
            or n == "ad"]
        #: the generalised block's direction term, kept inside (-AD_MAX, AD_MAX)
        self.iad = structure.names.index("ad") if "ad" in structure.names else None


#: Fits keep the generalised block's direction term ``|ad|`` below this: both rates
#: ``alpha (1 +- ad)`` stay positive (a branch that never settles is not a hysteresis loop).
AD_MAX = 0.95

#: Fits keep ``alpha max |L1| min(2 A sin(w/2), slew)`` (condition 8 over every sine inside the
#: training input's envelope, :meth:`DuhemSandwich.envelope_bound`) below this.
BOUND_MAX = 1.95
#: Fits keep ``alpha`` times the normalised input's span at least this: one sweep of the input
#: forgets all but ``exp(-WIPE_OUT)`` of the hysteresis state it started from (the wiping-out
#: of a piezo's memory by a full stroke). A model with less memory loss carries the unknown
#: initial state through the whole record and cannot be validated on records that start
#: elsewhere.
WIPE_OUT = 1.0
#: Evaluations given to each start before the best ones are polished.
SCREEN_NFEV = 25
#: Samples of sensitivities held at once while the Jacobian rows are formed and reduced.
SENS_WINDOW = 4096


def to_physical(theta_n: np.ndarray, structure: Structure, u_scale: float,
                y_scale: float) -> np.ndarray:
    """Parameters in record units from parameters fitted on normalised signals.

    With ``u = u_scale un`` and ``y = y_scale yn`` eq. (7) keeps its form when ``w1`` scales like
    ``u`` and ``w2`` like ``y``: ``alpha = alpha_n / u_scale``, ``f1 = f1_n y_scale / u_scale``,
    ``g0 = g0_n y_scale / u_scale``, ``f0 = f0_n y_scale``; L1 and L2 (monic) are unchanged.

    Parameters
    ----------
    theta_n : ndarray
        Parameters on normalised signals.
    structure : Structure
        Model structure.
    u_scale, y_scale : float
        The scales.

    Returns
    -------
    ndarray
    """
    return _rescale(theta_n, structure, u_scale, y_scale, inverse=False)


def to_normalised(theta: np.ndarray, structure: Structure, u_scale: float,
                  y_scale: float) -> np.ndarray:
    """The inverse of :func:`to_physical`.

    Parameters
    ----------
    theta : ndarray
        Parameters in record units.
    structure : Structure
        Model structure.
    u_scale, y_scale : float
        The scales.

    Returns
    -------
    ndarray
    """
    return _rescale(theta, structure, u_scale, y_scale, inverse=True)


def _rescale(theta, structure, su, sy, inverse):
    factor = {"alpha": 1.0 / su, "f1": sy / su, "g0": sy / su, "f0": sy,
              # the generalised block: F(w1) and G(w1) dw1 are in w2 units, w1 in u units
              "f2": sy / su**2, "f3": sy / su**3, "g1": sy / su**2, "g2": sy / su**3,
              "gd": sy / su}
    out = np.array(theta, dtype=float)
    for name, f in factor.items():
        if name in structure.names:
            i = structure.names.index(name)
            out[..., i] = out[..., i] / f if inverse else out[..., i] * f
    return out


class _RunningQR:
    """The triangle ``R`` (``R'R = A'A``) of a tall matrix ``A`` given block by block.

    Rows are written into :meth:`rows` views of one Fortran-ordered stack below the triangle
    so far and reduced with ``scipy.linalg.qr``: memory is one block, whatever the height of
    ``A``.
    """

    def __init__(self, width: int, block: int = SENS_WINDOW) -> None:
        self.stack = np.zeros((block + width, width), order="F")
        self.t = 0  # rows of the triangle so far
        self.pending = 0  # rows written below it, not reduced yet

    def rows(self, k: int) -> np.ndarray:
        """A view of the next ``k`` rows (at most one block) to fill; reduced at the next call
        or by :meth:`triangle`."""
        self._reduce()
        self.pending = k
        return self.stack[self.t: self.t + k]

    def _reduce(self) -> None:
        rows, self.pending = self.t + self.pending, 0
        if rows > self.t:
            R = qr(self.stack[:rows], mode="r", check_finite=False)[0]
            self.t = min(rows, self.stack.shape[1])
            self.stack[: self.t] = R[: self.t]

    def triangle(self) -> np.ndarray:
        """The square triangle (zero rows below when ``A`` has fewer rows than columns)."""
        self._reduce()
        width = self.stack.shape[1]
        tri = np.zeros((width, width))
        tri[: self.t] = self.stack[: self.t]
        return tri


def triangle_of(A: np.ndarray) -> np.ndarray:
    """The square QR triangle ``R`` of a tall matrix (``R'R = A'A``), folded block by block.

    Parameters
    ----------
    A : ndarray
        Rows to fold, shape ``(m, width)``.

    Returns
    -------
    ndarray
        Shape ``(width, width)``; zero rows below when ``m < width``.
    """
    folded = _RunningQR(A.shape[1])
    for a in range(0, len(A), SENS_WINDOW):
        block = A[a: a + SENS_WINDOW]
        folded.rows(len(block))[:] = block
    return folded.triangle()


class _OutputError:
    """The output-error problem on a prepared record: residuals and Jacobian in ``z``.

    ``z`` holds the reparametrised model (:class:`_Reparam`), then the normalised sensor offset
    ``y0`` and the hysteresis state at the start ``e0`` (``w2`` off its rest value: a stage at
    rest still remembers how it got there; fitted for records that start at rest, its
    derivative by a finite difference). One extra residual keeps the model admissible over the
    training envelope: it is ``weight * max(0, bound - BOUND_MAX)``.

    Memory does not grow with anything but the signals (see ``benchmarks/bench_memory.py``):
    the solver sees the problem compressed to ``len(z) + 1`` rows. At each ``z`` the rows
    ``[J | r]`` of the Jacobian and the residuals are formed block by block from sensitivity
    windows of :data:`SENS_WINDOW` samples (:func:`hystid.kernels.jacobian_block`) and reduced
    by a running QR factorisation to the triangle ``[R | c; 0 | rho]``; the solver gets the
    residuals ``[c, rho]`` and the Jacobian ``[R; 0]``. Their cost, gradient ``J'r`` and
    Gauss-Newton matrix ``J'J`` are those of the full problem, so the trust-region iterates
    are the same; :meth:`residuals` gives the residuals themselves.
    """

    def __init__(self, prep: Prepared, structure: Structure, x0: InitialCondition,
                 fit_offset: bool, admissible: bool, fit_state: bool = False):
        self.structure, self.prep = structure, prep
        self.rp = _Reparam(structure)
        self.fit_offset, self.admissible = fit_offset, admissible
        self.fit_state = fit_state and prep.at_rest
        P, n, npar = structure.history, len(prep.un), len(structure.names)
        self.P = P
        self.U, self.W1, self.W2, self.Y = (
            np.concatenate([x0.window(k, P), np.zeros(n)]) for k in ("u", "w1", "w2", "y"))
        self.past = [a[:P].copy() for a in (self.W1, self.W2, self.Y)]
        self.U[P:] = prep.un
        self.S1, self.S2, self.SY = (np.zeros((P + SENS_WINDOW, npar)) for _ in range(3))
        self.block = np.zeros((SENS_WINDOW, npar))
        every = bool(np.all(prep.weight))
        self.rows = None if every else np.flatnonzero(prep.weight)
        self.idx = slice(None) if every else self.rows
        self.target = prep.yn[self.idx]
        self.m = len(self.target)
        self.ceiling = 1e6 * (np.max(np.abs(self.target)) + 1.0)
        self.pen_weight = 10.0 * np.sqrt(self.m)
        self._cache: dict[str, Any] = {}
        un = prep.un[prep.skip:]
        self.env_n = Envelope.of(un)
        self.npar = npar

    def bound(self, theta_n: np.ndarray) -> float:
        """Condition (8) over the training envelope (scale-free)."""
        return DuhemSandwich(theta_n, self.structure).envelope_bound(self.env_n)

    def _penalty(self, z: np.ndarray) -> tuple[float, np.ndarray]:
        grad = np.zeros(len(z))
        if not self.admissible:
            return 0.0, grad
        n = self.npar
        theta = self.rp.to_theta(z[:n])[0]
        b = self.bound(theta)
        if b <= BOUND_MAX:
            return 0.0, grad
        for i in self.rp.l1_and_alpha:
            dz = np.zeros(len(z))
            dz[i] = 1e-6 * max(abs(z[i]), 1.0)
            grad[i] = (self.bound(self.rp.to_theta(z[:n] + dz[:n])[0]) - b) / dz[i]
        return self.pen_weight * (b - BOUND_MAX), self.pen_weight * grad

    def _split(self, z: np.ndarray) -> tuple[np.ndarray, np.ndarray, float, float]:
        n = self.npar
        theta, dtheta = self.rp.to_theta(z[:n])
        return (theta, dtheta, z[n] if self.fit_offset else 0.0,
                z[n + 1] if self.fit_state else 0.0)

    def residuals(self, z: np.ndarray) -> np.ndarray:
        """The simulation error at the samples in the cost (normalised units)."""
        theta, _, y0, e0 = self._split(z)
        with np.errstate(over="ignore", invalid="ignore"):
            return self._run(theta, e0) + y0 - self.target

    def evaluate(self, z: np.ndarray) -> dict[str, Any]:
        """The compressed residuals and Jacobian at ``z`` (cached for the last ``z``)."""
        check_cancelled()  # a fit started ahead of a decision that no longer needs it
        if "z" in self._cache and np.array_equal(self._cache["z"], z):
            return self._cache
        theta, dtheta, y0, e0 = self._split(z)
        nz, m = len(z), self.m
        with np.errstate(over="ignore", invalid="ignore"):
            yhat = self._run(theta, e0)
            blown = not np.all(np.isfinite(yhat))
            blown = blown or float(np.max(np.abs(yhat))) > self.ceiling
            de0 = None
            if not blown and self.fit_state:
                h = 1e-6 * max(abs(e0), 1.0)
                de0 = (self._run(theta, e0 + h) - yhat) / h
            tri = None if blown else self._triangle(theta, dtheta, yhat + y0 - self.target,
                                                    de0, z)
        if tri is None:
            # the Duhem recursion left condition (8): a large, flat residual steers back
            # (the norm of 1e6 at every residual, as the full problem would have)
            tri = np.zeros((nz + 1, nz + 1))
            tri[nz, nz] = 1e6 * np.sqrt(m + 1)
        self._cache = {"z": z.copy(), "r": tri[:, nz].copy(), "J": tri[:, :nz].copy()}
        return self._cache

    def _triangle(self, theta: np.ndarray, dtheta: np.ndarray, r: np.ndarray,
                  de0: np.ndarray | None, z: np.ndarray) -> np.ndarray | None:
        """``[R | c; 0 | rho]`` of the rows ``[J | r]``, block by block (None if not finite)."""
        n, nz, P = self.npar, len(z), self.P
        self._set_past(theta, z[n + 1] if self.fit_state else 0.0)
        for S in (self.S1, self.S2, self.SY):
            S[:P] = 0.0
        qr_rows = _RunningQR(nz + 1)
        total = len(self.U) - P
        for a in range(0, total, SENS_WINDOW):
            b = min(total, a + SENS_WINDOW)
            block = self.block[: b - a]
            if not jacobian_block(theta, self.structure.layout, self.U, self.W1, self.W2,
                                  self.Y, self.S1, self.S2, self.SY, P, P + a, dtheta, block):
                return None
            if self.rows is None:
                lo, hi, take = a, b, block
            else:
                lo, hi = np.searchsorted(self.rows, (a, b))
                take = block[self.rows[lo:hi] - a]
            rows = qr_rows.rows(hi - lo)
            rows[:, :n] = take
            rows[:, n] = 1.0 if self.fit_offset else 0.0
            rows[:, n + 1] = de0[lo:hi] if de0 is not None else 0.0
            rows[:, nz] = r[lo:hi]
        pen, dpen = self._penalty(z)
        qr_rows.rows(1)[0] = np.r_[dpen, pen]
        tri = qr_rows.triangle()
        return tri if np.all(np.isfinite(tri)) else None

    def fun(self, z: np.ndarray) -> np.ndarray:
        """Compressed residuals ``[c, rho]`` at ``z`` (norm: that of the full residuals)."""
        return self.evaluate(z)["r"]

    def jac(self, z: np.ndarray) -> np.ndarray:
        """Compressed Jacobian ``[R; 0]`` at ``z``."""
        return self.evaluate(z)["J"]

    def _set_past(self, theta: np.ndarray, e0: float) -> None:
        """The past of the signals, with the Duhem state ``e0`` off rest (L2 settled on it)."""
        P = self.P
        for a, past in zip((self.W1, self.W2, self.Y), self.past, strict=True):
            a[:P] = past
        if e0:
            s = self.structure
            a2 = theta[[s.names.index(f"a2{i}") for i in range(1, s.n2a + 1)]]
            b2 = theta[[s.names.index(f"b2{i}") for i in range(1, s.n2b + 1)]]
            self.W2[:P] += e0
            self.Y[:P] += e0 * (1.0 + np.sum(b2)) / (1.0 + np.sum(a2))

    def _run(self, theta: np.ndarray, e0: float) -> np.ndarray:
        """Simulated output at the samples in the cost (a copy), from the past of ``e0``."""
        P = self.P
        self._set_past(theta, e0)
        simulate_into(theta, self.structure.layout, self.U, self.W1, self.W2, self.Y, P)
        return self.Y[P:][self.idx].copy()

    def solve(self, z0: np.ndarray, max_nfev: int, tol: float):
        lo, hi = self.rp.bounds()
        lo, hi = np.r_[lo, -np.inf, -np.inf], np.r_[hi, np.inf, np.inf]
        if self.admissible:
            lo[self.rp.ialpha] = WIPE_OUT / max(self.env_n.u_max - self.env_n.u_min, 1e-12)
        if self.rp.iad is not None:
            lo[self.rp.iad], hi[self.rp.iad] = -AD_MAX, AD_MAX
        with np.errstate(over="ignore", invalid="ignore"):
            return least_squares(self.fun, np.clip(z0, lo, hi), jac=self.jac,
                                 bounds=(lo, hi), method="trf", ftol=tol, xtol=tol, gtol=tol,
                                 max_nfev=max_nfev, x_scale="jac")


def _starts(prep: Prepared, structure: Structure, theta0: float | dict | np.ndarray,
            linear_init: bool, more: dict | None = None) -> dict[str, np.ndarray]:
    """Data-driven starts on the normalised record, ``[theta_n, y0_n]`` each.

    ``theta0`` (the paper's 0.01 for every parameter, in normalised units when a scalar, in
    record units when a vector or dict), the ``more`` starts given (record units), and from
    the linear sandwich's ARX fit with an offset (:func:`linear_start`): the linear model
    itself (``f1 = g0``) and loops opened around it (``g0`` a half and a fifth of the gain,
    ``alpha`` 1 and 5, a level at which the normalised loop is about as wide as the signals).
    """
    starts = {}
    for label, start in {"theta0": theta0, **(more or {})}.items():
        if np.isscalar(start):
            starts[label] = np.r_[initial_theta(structure, start), 0.0]
        else:
            phys = initial_theta(structure, start)
            starts[label] = np.r_[to_normalised(phys, structure, prep.u_scale, prep.y_scale),
                                  0.0]
    if not linear_init:
        return starts
    fill = np.where(prep.weight, prep.yn, np.nan)
    good = np.flatnonzero(prep.weight)
    fill = np.interp(np.arange(len(fill)), good, prep.yn[good])
    rec = Record(prep.un, fill, prep.record.fs, name=prep.record.name)
    lin = linear_start(rec, structure, with_offset=True,
                       observed=None if prep.held is None else ~prep.held)
    if lin is None:
        return starts
    theta, y0 = lin
    names = structure.names
    ia, i1, ig = names.index("alpha"), names.index("f1"), names.index("g0")
    starts["linear"] = np.r_[theta, y0]
    for alpha in (1.0, 5.0):
        for share in (0.5, 0.2):
            t = theta.copy()
            t[ia], t[ig] = alpha, share * theta[i1]
            starts[f"loop alpha={alpha:g} g0={share:g}f1"] = np.r_[t, y0]
    return starts


@one_blas_thread
def fit_output_error(
    record: Record,
    structure: Structure | None = None,
    theta0: float | dict | np.ndarray = 0.01,
    *,
    x0: InitialCondition | None = None,
    linear_init: bool = True,
    offset: bool = True,
    admissible: bool = True,
    skip: int | None = None,
    left_out: Sequence[tuple[int, int]] = (),
    max_nfev: int = 300,
    tol: float = 1e-12,
    name: str = "identified stage",
    say: Callable[[str], None] | None = None,
    starts: dict[str, np.ndarray] | None = None,
) -> IdentificationResult:
    """Identify the sandwich off-line by output-error least squares.

    The steps: :func:`~hystid.identify.prepare.prepare` the record (excitation check, rest
    level, robust scales, outliers and saturation left out, burn-in when it does not start at
    rest); fit on the normalised signals from several starts (:func:`_starts`), each for
    :data:`SCREEN_NFEV` evaluations; polish the two best; keep the best admissible one; place
    the model at the record's rest level, offset and units.

    Parameters
    ----------
    record : Record
        Measured input ``u`` and output ``y``, in any units.
    structure : Structure, optional
        Model structure; the paper's experimental one by default.
    theta0 : float, dict or array
        A start besides the data-driven ones: one value for every parameter (the paper's 0.01,
        on normalised signals) or a full vector / dict in record units.
    x0 : InitialCondition, optional
        Past of the record in record units; given, the model rests at ``u = 0`` with no
        offset (the behaviour of a record known to start from ``x0``).
    linear_init : bool
        Also start from :func:`linear_start` and the loops opened around it.
    offset : bool
        Estimate the sensor offset (default). Without it the output is taken as zero at rest.
    admissible : bool
        Keep condition (8) over the training input's envelope (:data:`BOUND_MAX`).
    skip : int, optional
        Leading samples simulated but left out of the cost; by default none for a record that
        starts at rest, else until the input has swept its range once.
    left_out : sequence of (int, int)
        Spans ``[first, stop)`` of samples simulated but left out of the cost (the model
        choice's held-out block).
    max_nfev : int
        Evaluations of each polish with ``scipy.optimize.least_squares``.
    tol : float
        ``ftol``, ``xtol`` and ``gtol`` of the solver.
    name : str
        Name of the identified model.
    say : callable, optional
        Called with a progress line as each start is screened and each of the two best is
        polished (a fit of a long record runs for minutes).
    starts : dict of str to ndarray, optional
        Further starts by label, parameter vectors in record units (a previous solution: the
        on-line identifier's start-up solve on a longer window), screened with the others.

    Returns
    -------
    IdentificationResult
        ``method='batch'``; ``info`` holds the RMS residual (record units), the number of
        evaluations, the start kept, the solver status, the envelope bound and ``warnings``.
    """
    structure = structure or Structure()
    prep = prepare(record, skip=skip, left_out=left_out)
    if x0 is not None:
        prep = _pinned_at_zero(prep)
    elif not offset:
        prep.y_ref, prep.yn = 0.0, record.y / prep.y_scale
    x0n = _normalise_past(x0, prep) if x0 is not None else InitialCondition()
    problem = _OutputError(prep, structure, x0n, offset and x0 is None, admissible,
                           fit_state=x0 is None)
    starts = _starts(prep, structure, theta0, linear_init, more=starts)
    screened, say = [], say or (lambda line: None)
    for i, (label, start) in enumerate(starts.items()):
        say(f"batch fit of {record.n} samples: start {i + 1} of {len(starts)} ({label})")
        z0 = np.r_[problem.rp.to_z(start[:-1]), start[-1], 0.0]
        sol = problem.solve(z0, SCREEN_NFEV if len(starts) > 1 else max_nfev, tol)
        screened.append((sol.cost, label, sol))
    screened.sort(key=lambda item: item[0])
    polished = []
    for i, (_, label, sol) in enumerate(screened[:2]):
        if len(starts) > 1:
            say(f"batch fit: polishing the {'best' if i == 0 else 'second best'} start ({label})")
            sol = problem.solve(sol.x, max_nfev, tol)
        polished.append((sol.cost, label, sol))
    cost, label, sol = min(polished, key=lambda item: item[0])
    return _result(prep, structure, problem, sol, label, name,
                   {"theta0": np.atleast_1d(theta0).tolist() if np.isscalar(theta0) else
                    initial_theta(structure, theta0).tolist(),
                    "linear_init": linear_init, "offset": offset, "admissible": admissible,
                    "skip": prep.skip, "max_nfev": max_nfev, "tol": tol, "samples": record.n,
                    "starts": list(starts)})


def _pinned_at_zero(prep: Prepared) -> Prepared:
    """The record's rest at ``u = 0`` and its output reference at 0 (for a given past)."""
    u, y = prep.record.u, prep.record.y
    prep.u_rest, prep.y_ref = 0.0, 0.0
    prep.un, prep.yn = u / prep.u_scale, y / prep.y_scale
    return prep


def _normalise_past(x0: InitialCondition, prep: Prepared) -> InitialCondition:
    return InitialCondition(np.asarray(x0.u, float) / prep.u_scale,
                            np.asarray(x0.w1, float) / prep.u_scale,
                            np.asarray(x0.w2, float) / prep.y_scale,
                            np.asarray(x0.y, float) / prep.y_scale)


def _result(prep: Prepared, structure: Structure, problem: _OutputError, sol, label: str,
            name: str, settings: dict) -> IdentificationResult:
    """Place the fitted model in record units and say what is worth knowing about it."""
    n = problem.npar
    theta_n = problem.rp.to_theta(sol.x[:n])[0]
    y0n = float(sol.x[n]) if problem.fit_offset else 0.0
    e0n = float(sol.x[n + 1]) if problem.fit_state else 0.0
    theta = to_physical(theta_n, structure, prep.u_scale, prep.y_scale)
    rec = prep.record
    model = DuhemSandwich(theta, structure, fs=rec.fs, name=name, u_rest=prep.u_rest,
                          offset=prep.offset(y0n), envelope=prep.envelope, units=rec.units,
                          rest_memory=e0n * prep.y_scale)
    bound = problem.bound(theta_n)
    notes = list(prep.notes)
    if bound >= 2.0:
        notes.append(f"the model is not admissible over its own training envelope "
                     f"(condition 8 bound {bound:.3g} >= 2): it may diverge on inputs like the "
                     "training input")
    train_issues = [w for w in model.admissibility(rec.u) if "condition (8)" in w
                    or "diverged" in w]
    notes += [f"on the training record: {w}" for w in train_issues]
    info = {
        "rms_residual": float(np.sqrt(np.mean(problem.residuals(sol.x) ** 2)) * prep.y_scale),
        "nfev": int(sol.nfev),
        "status": int(sol.status),
        "message": str(sol.message),
        "start": label,
        "envelope_bound": bound,
        "scales": {"u": prep.u_scale, "y": prep.y_scale},
        "at_rest": prep.at_rest,
        "warnings": notes,
    }
    return IdentificationResult(model, "batch", settings, info=info)


