"""Off-line output-error (simulation-error) identification: the reference for on-line methods.

Minimises ``sum_k (y(k) - yhat(k | theta))^2`` where ``yhat`` is the free-run simulation of the
sandwich, with scipy's trust-region least squares. The Jacobian comes from the compiled
forward-sensitivity kernel; the search runs in reflection coefficients so that L1 and L2 stay
stable and minimum phase, and alpha stays positive (Assumption 1).
"""

from __future__ import annotations

import numpy as np
from scipy.optimize import least_squares

from ..kernels import sensitivities_into
from ..model import DuhemSandwich, InitialCondition, Structure
from ..records import Record
from .constraints import ALPHA_MIN, K_MAX, poly_to_reflection, polynomial_groups, reflection_to_poly
from .result import IdentificationResult

__all__ = ["fit_output_error", "initial_theta", "linear_start", "output_sensitivities"]


def initial_theta(structure: Structure, theta0: float | dict | np.ndarray) -> np.ndarray:
    """Start vector from a scalar (every parameter, as in the paper), a dict or a vector."""
    names = structure.names
    if np.isscalar(theta0):
        theta = np.full(len(names), float(theta0))
    elif isinstance(theta0, dict):
        return DuhemSandwich(theta0, structure).theta
    else:
        theta = np.asarray(theta0, dtype=float).ravel()
    if theta.shape != (len(names),) or not np.all(np.isfinite(theta)):
        raise ValueError(f"theta0: expected a finite scalar or {len(names)} values {list(names)}")
    return theta


def output_sensitivities(
    theta: np.ndarray, structure: Structure, u: np.ndarray, x0: InitialCondition | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """Simulated output ``yhat`` and its Jacobian ``d yhat / d theta`` (N x n_params)."""
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


def linear_start(record: Record, structure: Structure, alpha: float = 1.0) -> np.ndarray | None:
    """A data-driven start: the sandwich's linear part from an ARX fit.

    With ``f1 = g0`` and ``w2`` at rest the Duhem block is the gain ``g0``, so the sandwich is the
    linear model ``y = g0 z^-(q1+q2) B1 B2 / (A1 A2) u``. Its ARX least-squares fit gives the
    product polynomials; the denominator's roots are split between ``A1`` (real roots farthest
    from the unit circle) and ``A2`` (complex pairs, the flexure mode, first), numerator roots
    likewise, and unstable roots are reflected into the unit circle. Returns ``None`` when the
    roots cannot be split into real polynomials of the required orders.
    """
    s = structure
    na, nb, q = s.n1a + s.n2a, s.n1b + s.n2b, s.q1 + s.q2
    u, y = record.u, record.y
    lag = max(na, q + nb, 1)
    if len(y) <= lag + na + nb + 2:
        return None
    rows = np.arange(lag, len(y))
    phi = [-y[rows - i] for i in range(1, na + 1)] + [u[rows - q - j] for j in range(nb + 1)]
    coef = np.linalg.lstsq(np.column_stack(phi), y[rows], rcond=None)[0]
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
    return np.array([values[n] for n in s.names])


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


class _Reparam:
    """theta <-> z where the polynomial groups are replaced by reflection coefficients."""

    def __init__(self, structure: Structure):
        self.groups = polynomial_groups(structure)
        self.ialpha = structure.names.index("alpha")
        self.n = len(structure.names)

    def to_z(self, theta: np.ndarray) -> np.ndarray:
        z = np.array(theta, float)
        for g in self.groups:
            z[g] = np.clip(poly_to_reflection(theta[g]), -K_MAX, K_MAX)
        z[self.ialpha] = max(z[self.ialpha], ALPHA_MIN)
        return z

    def to_theta(self, z: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        theta = np.array(z, float)
        dtheta = np.eye(self.n)
        for g in self.groups:
            theta[g], dtheta[np.ix_(g, g)] = reflection_to_poly(z[g])
        return theta, dtheta

    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        lo = np.full(self.n, -np.inf)
        hi = np.full(self.n, np.inf)
        for g in self.groups:
            lo[g], hi[g] = -K_MAX, K_MAX
        lo[self.ialpha] = ALPHA_MIN
        return lo, hi


def fit_output_error(
    record: Record,
    structure: Structure | None = None,
    theta0: float | dict | np.ndarray = 0.01,
    *,
    x0: InitialCondition | None = None,
    linear_init: bool = True,
    max_nfev: int = 300,
    tol: float = 1e-12,
    name: str = "identified stage",
) -> IdentificationResult:
    """Identify the sandwich off-line by output-error least squares.

    Parameters
    ----------
    record : Record
        Measured input ``u`` and output ``y``; the record is assumed to start from ``x0``.
    structure : Structure, optional
        Model structure; the paper's experimental one by default.
    theta0 : float, dict or array
        Start: one value for every parameter (the paper's 0.01) or a full vector / dict.
    x0 : InitialCondition, optional
        Past of the record (at rest by default).
    linear_init : bool
        Also start from :func:`linear_start` and keep the better of the two fits. From
        ``theta0 = 0.01`` alone the search ends in a local minimum on short records.
    max_nfev : int
        Maximum number of residual evaluations of ``scipy.optimize.least_squares``.
    tol : float
        ``ftol``, ``xtol`` and ``gtol`` of the solver.

    Returns
    -------
    IdentificationResult
        ``method='batch'``; ``info`` holds the final RMS residual, the number of evaluations and
        the solver status.
    """
    structure = structure or Structure()
    theta_start = initial_theta(structure, theta0)
    rp = _Reparam(structure)
    u, y = record.u, record.y
    ceiling = 1e6 * (np.max(np.abs(y)) + 1.0)

    def residual_and_jac(z):
        theta, dtheta = rp.to_theta(z)
        with np.errstate(over="ignore", invalid="ignore"):
            yhat, S = output_sensitivities(theta, structure, u, x0)
            blown = not (np.all(np.isfinite(yhat)) and np.all(np.isfinite(S)))
            blown = blown or np.max(np.abs(yhat)) > ceiling
        if blown:
            # the Duhem recursion left condition (8): a large, flat residual steers back
            return np.full(len(y), 1e6), np.zeros((len(y), len(z)))
        return yhat - y, S @ dtheta

    cache: dict = {}

    def fun(z):
        cache["z"] = z.copy()
        cache["r"], cache["J"] = residual_and_jac(z)
        return cache["r"]

    def jac(z):
        if "z" not in cache or not np.array_equal(cache["z"], z):
            fun(z)
        return cache["J"]

    lo, hi = rp.bounds()
    starts = {"theta0": theta_start}
    if linear_init:
        lin = linear_start(record, structure)
        if lin is not None:
            starts["linear"] = lin
    best, best_start = None, None
    for label, start in starts.items():
        cache.clear()
        sol = least_squares(
            fun, rp.to_z(start), jac=jac, bounds=(lo, hi), method="trf",
            ftol=tol, xtol=tol, gtol=tol, max_nfev=max_nfev,
        )
        if best is None or sol.cost < best.cost:
            best, best_start = sol, label
    sol = best
    theta = rp.to_theta(sol.x)[0]
    model = DuhemSandwich(theta, structure, fs=record.fs, name=name)
    info = {
        "rms_residual": float(np.sqrt(np.mean(sol.fun**2))),
        "nfev": int(sol.nfev),
        "status": int(sol.status),
        "message": str(sol.message),
        "start": best_start,
    }
    settings = {"theta0": theta_start.tolist(), "linear_init": linear_init,
                "max_nfev": max_nfev, "tol": tol, "samples": len(u)}
    return IdentificationResult(model, "batch", settings, info=info)
