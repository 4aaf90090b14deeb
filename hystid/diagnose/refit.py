"""Output-error refit of the sandwich with unmodelled effects switched on.

The nominal parameters are searched in reflection coefficients (stable, minimum-phase L1 and L2,
Assumption 1) and ``alpha > 0``, as in :func:`hystid.identify.offline.fit_output_error`; each
effect parameter in a transformed coordinate with bounds (a log scale for time constants and
frequencies). The Jacobian is taken by finite differences over the compiled augmented kernel
(:func:`hystid.diagnose.effects.augmented_into`), which costs one simulation per parameter.
The solver is a bounded Levenberg-Marquardt iteration on the scaled normal equations (the
problems are tall and thin: tens of thousands of samples, about ten parameters).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np

from ..identify.constraints import (
    ALPHA_MIN,
    K_MAX,
    poly_to_reflection,
    polynomial_groups,
    reflection_to_poly,
)
from ..model import DuhemSandwich, InitialCondition
from .effects import EFFECTS, MAX_DELAY, N_SLOTS, _Workspace

__all__ = [
    "FitData",
    "LMSolution",
    "Parametrisation",
    "RefitResult",
    "initial_state",
    "levenberg_marquardt",
    "refit",
    "simulate_fit_data",
]


@dataclass
class FitData:
    """A record prepared for simulation: input, measured output and the initial state rule.

    Attributes
    ----------
    u, y : ndarray
        Input and measured output.
    fs : float
        Sampling rate in Hz.
    level : float or None
        When set, the record starts at rest with this output level (the Duhem state ``w2`` is
        set so that L2's static output equals it); at rest from zero otherwise.
    weight : slice
        Samples that enter the least-squares cost (all by default).
    """

    u: np.ndarray
    y: np.ndarray
    fs: float
    level: float | None = None
    weight: slice = field(default_factory=lambda: slice(None))

    def __post_init__(self) -> None:
        self._ws: dict[int, _Workspace] = {}

    def workspace(self, P: int) -> _Workspace:
        """Reusable kernel arrays for a history of ``P`` samples."""
        if P not in self._ws:
            self._ws[P] = _Workspace(self.u, P, None)
        return self._ws[P]


def initial_state(
    model: DuhemSandwich, level: float | None, u0: float, P: int
) -> InitialCondition | None:
    """Past windows (u, w1, w2, y) for a record starting at rest at output ``level``."""
    if level is None:
        return None
    th = model.params
    s = model.structure
    num1 = 1.0 + sum(th[f"b1{j}"] for j in range(1, s.n1b + 1))
    den1 = 1.0 + sum(th[f"a1{i}"] for i in range(1, s.n1a + 1))
    num2 = 1.0 + sum(th[f"b2{j}"] for j in range(1, s.n2b + 1))
    den2 = 1.0 + sum(th[f"a2{i}"] for i in range(1, s.n2a + 1))
    w1 = u0 * num1 / den1
    w2 = level * den2 / num2
    return InitialCondition(u=np.full(P, u0), w1=np.full(P, w1), w2=np.full(P, w2),
                            y=np.full(P, level))


def simulate_fit_data(
    model: DuhemSandwich, phi: np.ndarray, data: FitData
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Simulate the augmented model over ``data``; returns ``(w1, w2, y)`` views (copy them to
    keep them past the next call)."""
    P = max(model.structure.history, 2)
    ws = data.workspace(P)
    # the model's own output at rest is the measured level less the sensor offset
    level = None if data.level is None else data.level - phi[12]
    x0 = initial_state(model, level, float(data.u[0]), P)
    if x0 is not None:
        ws.U[:P] = x0.u
        ws.past = {"w1": x0.w1, "w2": x0.w2, "y": x0.y}
    return ws.run(model.theta, model.structure.layout, phi, model.dt)


class Parametrisation:
    """``z`` <-> (theta, phi) for the nominal parameters and a set of active effects.

    Parameters
    ----------
    model : DuhemSandwich
        Gives the structure and the sampling rate.
    active : sequence of str
        Names of the effects whose parameters are free.
    duration : float
        Length of the fitting record in seconds (bounds of the time constants).
    step_scale : float
        Largest input-driven change of ``w1`` per sample (scale of the slew limit).
    w1_scale : float
        Largest ``|w1|`` (scale of the saturation's cubic coefficient).
    """

    def __init__(self, model: DuhemSandwich, active: Sequence[str], duration: float,
                 step_scale: float = 1.0, w1_scale: float = 1.0) -> None:
        self.structure = model.structure
        self.fs = model.fs
        self.active = tuple(active)
        self.groups = polynomial_groups(self.structure)
        self.ialpha = self.structure.names.index("alpha")
        self.ntheta = len(self.structure.names)
        self.duration = float(duration)
        self.step_scale = float(max(step_scale, 1e-12))
        self.w1_scale = float(max(w1_scale, 1e-12))
        self.slots = [s for name in self.active for s in EFFECTS[name].slots]
        self.n = self.ntheta + len(self.slots)

    # transformed coordinates of the effect slots
    def _fwd(self, slot: int, v: float) -> float:
        if slot == 1:
            return float(np.log(max(v, 0.5 / self.fs, 5e-3)))
        if slot in (5, 6):
            return float(np.log(max(v, 1e-6)))
        if slot == 10:
            return float(np.log(max(v * self.fs * self.step_scale, 1e-6)))
        if slot == 11:
            return float(v * self.w1_scale**2)
        return float(v)

    def _inv(self, slot: int, z: float) -> float:
        if slot in (1, 5, 6):
            return float(np.exp(z))
        if slot == 10:
            return float(np.exp(z) / (self.fs * self.step_scale))
        if slot == 11:
            return float(z / self.w1_scale**2)
        return float(z)

    def _bounds(self, slot: int) -> tuple[float, float]:
        table = {
            # creep goes on in the direction of the drive (gain >= 0) and is slow (tau >= 5 ms)
            0: (0.0, 1.0),
            1: (np.log(max(0.5 / self.fs, 5e-3)), np.log(100.0 * self.duration)),
            4: (-2.0, 2.0),
            5: (np.log(max(5.0 / self.duration, 20.0)), np.log(0.49 * self.fs)),
            6: (np.log(1e-3), np.log(0.3)),
            7: (0.0, MAX_DELAY - 1.0),
            8: (-0.95, 0.95),
            9: (-0.95, 0.95),
            10: (np.log(0.3), np.log(1e3)),
            # f stays monotone (Assumption 2) while 1 + 3 c w1^2 > 0
            11: (-0.3, 3.0),
        }
        return table.get(slot, (-np.inf, np.inf))

    def to_z(self, theta: np.ndarray, phi: np.ndarray) -> np.ndarray:
        """Search coordinates of a parameter pair."""
        z = np.array(theta, float)
        for g in self.groups:
            z[g] = np.clip(poly_to_reflection(theta[g]), -K_MAX, K_MAX)
        z[self.ialpha] = max(z[self.ialpha], ALPHA_MIN)
        ze = [self._fwd(s, phi[s]) for s in self.slots]
        z = np.concatenate([z, ze])
        lo, hi = self.bounds()
        return np.clip(z, lo, hi)

    def to_values(
        self, z: np.ndarray, base_phi: np.ndarray | None = None
    ) -> tuple[np.ndarray, np.ndarray]:
        """``(theta, phi)`` from search coordinates; inactive slots keep ``base_phi``."""
        theta = np.array(z[: self.ntheta], float)
        for g in self.groups:
            theta[g] = reflection_to_poly(z[g])[0]
        phi = np.zeros(N_SLOTS) if base_phi is None else np.array(base_phi, float)
        for s, v in zip(self.slots, z[self.ntheta:], strict=True):
            phi[s] = self._inv(s, v)
        return theta, phi

    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """Lower and upper bounds of ``z``."""
        lo = np.full(self.ntheta, -np.inf)
        hi = np.full(self.ntheta, np.inf)
        for g in self.groups:
            lo[g], hi[g] = -K_MAX, K_MAX
        lo[self.ialpha] = ALPHA_MIN
        eb = [self._bounds(s) for s in self.slots]
        lo = np.concatenate([lo, [b[0] for b in eb]])
        hi = np.concatenate([hi, [b[1] for b in eb]])
        return lo, hi


@dataclass
class RefitResult:
    """Outcome of one refit.

    Attributes
    ----------
    theta, phi : ndarray
        Nominal parameters and effect vector found.
    cost : float
        Mean squared train error at the solution.
    ok : bool
        False when the solver failed or the solution is not finite / leaves condition (8).
    message : str
        Solver message or the reason of the failure.
    nfev : int
        Residual evaluations (Jacobian columns not counted).
    """

    theta: np.ndarray
    phi: np.ndarray
    cost: float
    ok: bool
    message: str
    nfev: int = 0


def refit(
    model: DuhemSandwich,
    data: FitData,
    active: Sequence[str],
    starts: Sequence[np.ndarray],
    *,
    base_phi: np.ndarray | None = None,
    step_scale: float = 1.0,
    w1_scale: float = 1.0,
    max_nfev: int = 60,
) -> RefitResult:
    """Least-squares refit of the nominal parameters and the active effects' parameters.

    Parameters
    ----------
    model : DuhemSandwich
        Start of the nominal parameters (its ``theta``), structure and sampling rate.
    data : FitData
        The fitting record.
    active : sequence of str
        Effects whose parameters are free.
    starts : sequence of ndarray
        Effect vectors to start from (each a full effect vector); the best final cost wins.
    base_phi : ndarray, optional
        Values of the effect slots that are not free (zero by default).
    step_scale : float
        Scale of the slew-limit coordinate (largest ``|dw1|`` of the nominal simulation).
    w1_scale : float
        Scale of the saturation coordinate (largest ``|w1|`` of the nominal simulation).
    max_nfev : int
        Iterations allowed per start.

    Returns
    -------
    RefitResult
        The best of the starts; ``ok`` False when every start failed.
    """
    n = len(data.u)
    par = Parametrisation(model, active, n / data.fs, step_scale, w1_scale)
    lo, hi = par.bounds()
    y = data.y[data.weight]
    work = DuhemSandwich(model.theta.copy(), model.structure, fs=model.fs, name=model.name)

    def residual(z):
        theta, phi = par.to_values(z, base_phi)
        work.theta = theta
        yhat = simulate_fit_data(work, phi, data)[2][data.weight]
        r = yhat - y
        if not np.all(np.isfinite(r)):
            return np.full(len(y), 1e6)
        return r

    best: RefitResult | None = None
    messages = []
    for phi0 in starts:
        z0 = par.to_z(model.theta, phi0)
        pad = 1e-9 * np.minimum(hi - lo, 1.0)
        z0 = np.clip(z0, lo + pad, hi - pad)
        try:
            sol = levenberg_marquardt(residual, z0, lo, hi, max_iter=max_nfev)
        except (ValueError, np.linalg.LinAlgError, FloatingPointError) as err:
            messages.append(f"{type(err).__name__}: {err}")
            continue
        theta, phi = par.to_values(sol.x, base_phi)
        cost = float(np.mean(sol.fun**2))
        ok = bool(np.all(np.isfinite(theta)) and np.all(np.isfinite(phi)) and cost < 1e11)
        msg = str(sol.message) if ok else "the simulation diverged at the solution"
        if ok:
            work.theta = theta
            w1 = simulate_fit_data(work, phi, data)[0]
            margin = theta[par.ialpha] * (1 + abs(phi[8])) * np.max(np.abs(np.diff(w1)))
            if 1 + 3 * phi[11] * np.max(w1**2) <= 0:
                ok, msg = False, "the solution's anhysteretic curve is not monotone"
            if ok and not margin < 2.0:
                ok, msg = False, f"the solution leaves the Duhem stability condition (8) " \
                                 f"(alpha |dw1| reaches {margin:.3g})"
        res = RefitResult(theta, phi, cost, ok, msg, int(sol.nfev))
        if best is None or (res.ok and (not best.ok or res.cost < best.cost)):
            best = res
    if best is None:
        return RefitResult(model.theta.copy(), np.zeros(N_SLOTS), np.inf, False,
                           "; ".join(messages) or "no start given")
    return best


@dataclass
class LMSolution:
    """Result of :func:`levenberg_marquardt`: solution ``x``, residual ``fun``, evaluations,
    iterations and a message."""

    x: np.ndarray
    fun: np.ndarray
    nfev: int
    nit: int
    message: str


def levenberg_marquardt(
    fun: Callable[[np.ndarray], np.ndarray],
    x0: np.ndarray,
    lo: np.ndarray,
    hi: np.ndarray,
    *,
    max_iter: int = 60,
    ftol: float = 1e-10,
    xtol: float = 1e-10,
) -> LMSolution:
    """Bounded Levenberg-Marquardt with a forward-difference Jacobian.

    Minimises ``||fun(x)||^2`` over the box ``lo <= x <= hi``: each iteration builds the
    Jacobian column by column (one evaluation per parameter, stepping inwards at an upper
    bound), solves ``(J^T J + lam D) dx = -J^T r`` with ``D`` the diagonal of ``J^T J`` and
    projects the step onto the box; ``lam`` shrinks after a successful step and grows otherwise.

    Parameters
    ----------
    fun : callable
        ``fun(x) -> residual vector``.
    x0, lo, hi : ndarray
        Start and bounds.
    max_iter : int
        Iterations at most.
    ftol, xtol : float
        Stop when the cost or the step changes relatively less than this.
    """
    x = np.clip(np.asarray(x0, float), lo, hi)
    r = fun(x)
    cost = float(r @ r)
    nfev, lam, message = 1, 1e-3, "maximum number of iterations reached"
    nit = 0
    for nit in range(1, max_iter + 1):
        h = 1e-6 * np.maximum(1.0, np.abs(x))
        J = np.empty((len(r), len(x)))
        for i in range(len(x)):
            xi = x.copy()
            xi[i] = x[i] + h[i] if x[i] + h[i] <= hi[i] else x[i] - h[i]
            J[:, i] = (fun(xi) - r) / (xi[i] - x[i])
        nfev += len(x)
        g = J.T @ r
        H = J.T @ J
        d = np.sqrt(np.diag(H))
        d[d == 0] = 1.0
        Hs = H / np.outer(d, d)
        gs = g / d
        improved = False
        for _ in range(12):
            try:
                step = -np.linalg.solve(Hs + lam * np.eye(len(x)), gs) / d
            except np.linalg.LinAlgError:
                lam *= 10
                continue
            x_new = np.clip(x + step, lo, hi)
            r_new = fun(x_new)
            nfev += 1
            c_new = float(r_new @ r_new)
            if np.isfinite(c_new) and c_new < cost:
                rel = (cost - c_new) / max(cost, 1e-300)
                small = np.max(np.abs(x_new - x) / np.maximum(np.abs(x), 1.0)) < xtol
                x, r, cost = x_new, r_new, c_new
                lam = max(lam / 3.0, 1e-12)
                improved = True
                if rel < ftol or small:
                    return LMSolution(x, r, nfev, nit, "converged")
                break
            lam *= 4.0
        if not improved:
            message = "converged (no further decrease)"
            break
    return LMSolution(x, r, nfev, nit, message)
