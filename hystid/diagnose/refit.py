"""Output-error refit of the sandwich with unmodelled effects switched on.

The nominal parameters are searched in the coordinates of the off-line Duhem fit
(:class:`hystid.identify.offline._Reparam`: reflection coefficients of L1 and L2, so every
iterate is stable and minimum phase, Assumption 1, and ``alpha > 0``); each effect parameter in
a transformed coordinate with bounds (a log scale for time constants and frequencies). The
solver is :func:`scipy.optimize.least_squares` (trust-region reflective, bounds). Each
evaluation is one simulation of the compiled augmented kernel with its exact sensitivities
(:func:`hystid.diagnose.sensitivities.augmented_sens_into`); the rows ``[J | r]`` are reduced to
their QR triangle, so the solver works on a square problem with the full one's cost, gradient
and Gauss-Newton matrix (:data:`JACOBIAN`; forward differences, one simulation per parameter,
remain available for comparison). A refit runs in
two stages: the effect's own parameters with the nominal ones held (a few simulations per step),
then all of them together from there. Condition (8) is kept by a barrier residual: past
``alpha |dw1| = 1.9`` the cost rises steeply.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from functools import lru_cache

import numpy as np
from numba import njit
from scipy.linalg.lapack import dgeqrf
from scipy.optimize import least_squares

from ..model import DuhemSandwich, InitialCondition
from .effects import N_SLOTS, _Workspace
from .parametrisation import NOMINAL_SLOTS, Parametrisation
from .sensitivities import augmented_sens_into

__all__ = [
    "MARGIN_LIMIT",
    "NOMINAL_SLOTS",
    "FitData",
    "RefitResult",
    "duhem_margin",
    "initial_state",
    "refit",
    "simulate_fit_data",
    "simulate_fit_data_sens",
]

#: Two effect-only solutions whose free values agree within this share are one minimum (the
#: screen's starts for a dead time often lead to the same one).
SAME_START = 1e-3
#: Condition (8) asks ``alpha |dw1| < 2``; the refits are held below this value.
MARGIN_LIMIT = 1.9


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
    weight : slice or ndarray of bool
        Samples that enter the least-squares cost (all by default).
    """

    u: np.ndarray
    y: np.ndarray
    fs: float
    level: float | None = None
    weight: slice | np.ndarray = field(default_factory=lambda: slice(None))

    def __post_init__(self) -> None:
        self._ws: dict[int, _Workspace] = {}

    def workspace(self, P: int) -> _Workspace:
        """Reusable kernel arrays for a history of ``P`` samples.

        Parameters
        ----------
        P : int
            Samples of history the kernels read before sample 0.

        Returns
        -------
        _Workspace
            Arrays sized for this record, reused across calls.
        """
        if P not in self._ws:
            self._ws[P] = _Workspace(self.u, P, None)
        return self._ws[P]


@lru_cache(maxsize=64)
def _static_indices(structure) -> tuple[tuple[int, ...], ...]:
    """Indices into theta of b1, a1, b2 and a2 (a refit asks for them at every simulation)."""
    names = structure.names
    return tuple(tuple(names.index(f"{p}{j}") for j in range(1, n + 1))
                 for p, n in (("b1", structure.n1b), ("a1", structure.n1a),
                              ("b2", structure.n2b), ("a2", structure.n2a)))


def initial_state(
    model: DuhemSandwich, level: float | None, u0: float, P: int
) -> InitialCondition | None:
    """Past windows (u, w1, w2, y) for a record starting at rest at output ``level``.

    Parameters
    ----------
    model : DuhemSandwich
        The model simulated.
    level : float or None
        Output level at rest; None: at rest from zero (returns None).
    u0 : float
        Input held at rest.
    P : int
        Length of the past windows.

    Returns
    -------
    InitialCondition or None
        Constant past windows at the static levels.
    """
    if level is None:
        return None
    th = model.theta
    ib1, ia1, ib2, ia2 = _static_indices(model.structure)
    num1 = 1.0 + sum(float(th[i]) for i in ib1)
    den1 = 1.0 + sum(float(th[i]) for i in ia1)
    num2 = 1.0 + sum(float(th[i]) for i in ib2)
    den2 = 1.0 + sum(float(th[i]) for i in ia2)
    w1 = u0 * num1 / den1
    w2 = level * den2 / num2
    return InitialCondition(u=np.full(P, u0), w1=np.full(P, w1), w2=np.full(P, w2),
                            y=np.full(P, level))


def simulate_fit_data(
    model: DuhemSandwich, phi: np.ndarray, data: FitData
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Simulate the augmented model over ``data``; returns ``(w1, w2, y)`` views (copy them to
    keep them past the next call).

    Parameters
    ----------
    model : DuhemSandwich
        Nominal model.
    phi : ndarray
        The effect vector.
    data : FitData
        The record and its initial-state rule.

    Returns
    -------
    tuple of ndarray
        ``w1``, ``w2`` and ``y``.
    """
    ws, _, _ = _started_workspace(model, phi, data)
    return ws.run(model.theta, model.structure.layout, phi, model.dt)


def _started_workspace(model: DuhemSandwich, phi: np.ndarray,
                       data: FitData) -> tuple[_Workspace, int, float | None]:
    """The record's workspace with its past set by the initial-state rule; returns it, the
    history ``P`` and the model's own output at rest (the measured level less the sensor
    offset ``phi[12]``; None without a level)."""
    P = max(model.structure.history, 2)
    ws = data.workspace(P)
    level = None if data.level is None else data.level - phi[12]
    x0 = initial_state(model, level, float(data.u[0]), P)
    if x0 is not None:
        ws.U[:P] = x0.u
        ws.past = {"w1": x0.w1, "w2": x0.w2, "y": x0.y}
    return ws, P, level


def simulate_fit_data_sens(
    model: DuhemSandwich, phi: np.ndarray, data: FitData, cols: np.ndarray, ntc: int,
    sens: list[np.ndarray] | None = None,
) -> tuple[np.ndarray, np.ndarray, list[np.ndarray]]:
    """:func:`simulate_fit_data` with the output's sensitivities (one compiled pass).

    Parameters
    ----------
    model : DuhemSandwich
        Nominal model.
    phi : ndarray
        The effect vector.
    data : FitData
        The record and its initial-state rule.
    cols : ndarray of int
        Column of each effect slot, -1 for a held one
        (:func:`hystid.diagnose.sensitivities.sensitivity_columns`).
    ntc : int
        Leading columns that are the nominal parameters (their count, or 0).
    sens : list of ndarray, optional
        The five sensitivity arrays of a previous call with as many columns, reused (the last,
        ``SY``, may be a view into a caller's matrix).

    Returns
    -------
    tuple
        ``w1``, ``y`` (views, as :func:`simulate_fit_data`'s) and the sensitivity arrays
        ``[S1, S2, SV, SYL, SY]``: the first four of the extended signals (the record's
        samples from row ``P`` on, ``P`` the history; the past's rows hold the level rule's
        dependence on ``theta`` and the sensor offset), ``SY`` of the record's samples:
        ``d y / d (theta, free slots)``.
    """
    ws, P, level = _started_workspace(model, phi, data)
    ncol = ntc + int(np.count_nonzero(cols >= 0))
    if sens is None or sens[0].shape != (len(ws.U), ncol) or sens[4].shape != (ws.n, ncol):
        sens = [np.zeros((len(ws.U), ncol)) for _ in range(4)] + [np.zeros((ws.n, ncol))]
    S1, S2, SV, SYL, SY = sens
    for S in sens[:4]:
        S[:P] = 0.0
    if level is not None:
        th = model.theta
        ib1, ia1, ib2, ia2 = (list(i) for i in _static_indices(model.structure))
        num1, den1 = 1.0 + float(np.sum(th[ib1])), 1.0 + float(np.sum(th[ia1]))
        num2, den2 = 1.0 + float(np.sum(th[ib2])), 1.0 + float(np.sum(th[ia2]))
        u0 = float(data.u[0])
        if ntc:
            S1[:P, ib1] = u0 / den1
            S1[:P, ia1] = -u0 * num1 / den1**2
            S2[:P, ia2] = level / num2
            S2[:P, ib2] = -level * den2 / num2**2
        if cols[12] >= 0:
            S2[:P, cols[12]] = -den2 / num2
            SYL[:P, cols[12]] = -1.0
        SV[:P] = S2[:P]
    UD, W1, W2, V, C, YL, M, Y = ws.start(model.structure.layout)
    augmented_sens_into(model.theta, model.structure.layout, phi, cols, ntc, ws.U, UD, W1, W2,
                        V, C, YL, M, Y, S1, S2, SV, SYL, SY, P, model.dt)
    return W1[P:], Y[P:], sens


def duhem_margin(theta: np.ndarray, structure, phi: np.ndarray, w1: np.ndarray) -> float:
    """Largest ``alpha_k |dw1(k)|`` of eq. (7) over a simulation (condition 8 asks < 2).

    Parameters
    ----------
    theta : ndarray
        Nominal parameters.
    structure : Structure
        Their structure.
    phi : ndarray
        Effect vector (direction- and level-dependent alpha scale ``alpha``).
    w1 : ndarray
        Simulated ``w1``.

    Returns
    -------
    float
        The margin; ``inf`` when ``w1`` is not finite.
    """
    peak = _level_step_peak(np.asarray(w1, float), float(phi[14]))
    if not np.isfinite(peak):
        return float("inf")
    alpha = theta[structure.names.index("alpha")]
    return float(alpha * (1.0 + abs(phi[8]) + abs(phi[27])) * peak)


@njit(cache=True)
def _level_step_peak(w1, l_a):
    """``max_k |1 + l_a w1(k-1)| |w1(k) - w1(k-1)|`` (inf when ``w1`` has a non-finite entry or
    fewer than two): :func:`duhem_margin`'s maximum in one pass, without temporaries (a refit
    asks for it at every simulation)."""
    n = w1.shape[0]
    if n < 2:
        return np.inf
    for k in range(n):
        if not np.isfinite(w1[k]):
            return np.inf
    peak = 0.0
    for k in range(1, n):
        v = abs(1.0 + l_a * w1[k - 1]) * abs(w1[k] - w1[k - 1])
        if v != v:
            return v  # a NaN level: NaN, as numpy's maximum gives
        if v > peak:
            peak = v
    return peak


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
        Simulations (a simulation with sensitivities counts one; with forward differences
        each Jacobian column counts one).
    margin : float
        ``alpha |dw1|`` of condition (8) at the solution.
    at_bound : list of str
        The effect parameters at a bound of their search range
        (:meth:`Parametrisation.at_bound`).
    widen : float
        The factor the guessed search ranges were widened by (1: the default ranges).
    """

    theta: np.ndarray
    phi: np.ndarray
    cost: float
    ok: bool
    message: str
    nfev: int = 0
    margin: float = float("nan")
    at_bound: list[str] = field(default_factory=list)
    widen: float = 1.0


#: How a refit's Jacobian is formed: ``"folded"`` (compiled sensitivities, the rows ``[J | r]``
#: reduced to their QR triangle, so the solver works on a square problem, as
#: :class:`hystid.identify.offline._OutputError` does), ``"sensitivities"`` (the same
#: Jacobian, the tall problem given to the solver) or ``"2-point"`` (forward differences, one
#: simulation per parameter). For measurements; the diagnosis uses the default.
JACOBIAN = "folded"


class _Problem:
    """Residual of one refit: the simulated train output less the measured one, with the
    condition-(8) barrier appended; counts its simulations (a simulation with sensitivities
    counts one)."""

    def __init__(self, model: DuhemSandwich, data: FitData, par: Parametrisation,
                 base_phi: np.ndarray | None, profile: np.ndarray | None = None) -> None:
        self.data, self.par, self.base_phi, self.profile = data, par, base_phi, profile
        self.y = data.y[data.weight]
        self.work = DuhemSandwich(model.theta.copy(), model.structure, fs=model.fs)
        scale = float(np.std(self.y)) or 1.0
        self.barrier = scale * np.sqrt(len(self.y))
        self.calls = 0
        self.cols, self.ntc = par.columns()
        self.sens: list[np.ndarray] | None = None
        self._A: np.ndarray | None = None
        self._last: dict = {}
        n = len(data.u)
        kept = np.zeros(n, bool)
        kept[data.weight] = True
        # samples out of the cost: zero rows of the folded matrix
        self._out = None if kept.all() else np.flatnonzero(~kept)
        if profile is not None:
            self._profile = np.zeros((n, profile.shape[1]))
            self._profile[kept] = profile

    def evaluate(self, z: np.ndarray) -> dict:
        """One simulation with sensitivities at ``z`` (cached for the last ``z``).

        Fills the matrix ``A`` (Fortran order): a row per sample of the record, the output's
        sensitivities in the sensitivity columns then the residual (rows out of the cost
        zero), and a last row for the barrier (its derivative at the sample where condition
        (8)'s margin peaks, zero while the margin is below :data:`MARGIN_LIMIT`). ``D``
        (:meth:`Parametrisation.chain`) maps the sensitivity columns to ``z``.
        """
        if "z" in self._last and np.array_equal(self._last["z"], z):
            return self._last
        theta, phi = self.values(z)
        self.work.theta = theta
        self.calls += 1
        n = len(self.data.u)
        ncol = self.ntc + len(self.par.slots)
        if self._A is None:
            self._A = np.zeros((n + 1, ncol + 1), order="F")
            rows = len(self.data.workspace(max(self.work.structure.history, 2)).U)
            self.sens = [np.zeros((rows, ncol)) for _ in range(4)] + [self._A[:n, :ncol]]
        A = self._A
        with np.errstate(over="ignore", invalid="ignore"):
            w1, yhat, _ = simulate_fit_data_sens(self.work, phi, self.data, self.cols,
                                                 self.ntc, self.sens)
            A[:n, ncol] = yhat - self.data.y
            if self._out is not None:
                A[self._out] = 0.0
            r = A[:n, ncol]
            finite = bool(np.all(np.isfinite(r)))
            if finite and self.profile is not None:
                P_ = self._profile
                A[:n] -= P_ @ (P_.T @ A[:n])
            margin = duhem_margin(theta, self.par.structure, phi, w1) if finite else np.inf
        over = max(0.0, margin - MARGIN_LIMIT) if np.isfinite(margin) else 1e3
        A[n] = 0.0
        A[n, ncol] = self.barrier * over
        if over > 0.0 and np.isfinite(margin):
            P = max(self.work.structure.history, 2)
            A[n, :ncol] = self.barrier * self._margin_gradient(theta, phi, w1,
                                                               self.sens[0][P - 1:])
        self._last = {"z": z.copy(), "blown": not finite, "D": self.par.chain(z),
                      "r": (np.full(len(self.y) + 1, 1e6) if not finite else
                            np.append(r[self.data.weight], A[n, ncol]))}
        return self._last

    def tall(self, z: np.ndarray) -> np.ndarray:
        """The Jacobian of the residuals (barrier last) in ``z``.

        Parameters
        ----------
        z : ndarray
            Search coordinates.

        Returns
        -------
        ndarray
            ``len(residuals) x len(z)``.
        """
        if self._last.get("spent") and np.array_equal(self._last["z"], z):
            self._last = {}
        ev = self.evaluate(z)
        if "J" not in ev:
            n, ncol = len(self.data.u), self._A.shape[1] - 1
            if ev["blown"]:
                ev["J"] = np.zeros((len(ev["r"]), len(z)))
            else:
                rows = np.r_[np.arange(n)[self.data.weight], n]
                ev["J"] = self._A[rows, :ncol] @ ev["D"]
        return ev["J"]

    def _margin_gradient(self, theta, phi, w1, S1) -> np.ndarray:
        """Gradient of :func:`duhem_margin` in the sensitivity columns (``S1``: rows of
        ``w1(k-1)`` .. , the first the sample before ``w1[0]``), at its peak sample."""
        w1 = np.asarray(w1, float)
        l_a = float(phi[14])
        lev = 1.0 + l_a * w1[:-1]
        dw = np.diff(w1)
        k = int(np.argmax(np.abs(lev) * np.abs(dw))) + 1  # the peak: w1[k] - w1[k-1]
        peak = abs(lev[k - 1]) * abs(dw[k - 1])
        a = self.par.ialpha
        alpha = theta[a]
        asym = 1.0 + abs(phi[8]) + abs(phi[27])
        dpeak = (np.sign(lev[k - 1]) * l_a * S1[k] * abs(dw[k - 1])
                 + abs(lev[k - 1]) * np.sign(dw[k - 1]) * (S1[k + 1] - S1[k]))
        g = alpha * asym * dpeak
        if self.ntc:
            g[a] += asym * peak
        c = self.cols
        if c[14] >= 0:
            g[c[14]] += alpha * asym * np.sign(lev[k - 1]) * w1[k - 1] * abs(dw[k - 1])
        if c[8] >= 0:
            g[c[8]] += alpha * np.sign(phi[8]) * peak
        if c[27] >= 0:
            g[c[27]] += alpha * np.sign(phi[27]) * peak
        return g

    def folded(self, z: np.ndarray) -> dict:
        """The rows ``[J | r]`` reduced to their QR triangle ``[R | c; 0 | rho]``: the
        residuals ``[c, rho]`` and the Jacobian ``[R; 0]`` have the full problem's cost,
        gradient and Gauss-Newton matrix (:class:`hystid.identify.offline._OutputError`).
        The sensitivity columns are reduced, then mapped to ``z`` (``J = S D`` folds to
        ``R_S D``)."""
        ev = self.evaluate(z)
        if "tri" not in ev:
            nz = len(z)
            tri = np.zeros((nz + 1, nz + 1))
            if ev["blown"]:
                tri[nz, nz] = 1e6 * np.sqrt(len(ev["r"]))
            else:
                qr_, _, _, info = dgeqrf(self._A, overwrite_a=1)
                ev["spent"] = True
                R = np.triu(qr_[: nz + 1])
                tri[:, :nz] = R[:, :nz] @ ev["D"]
                tri[:, nz] = R[:, nz]
                if info != 0 or not np.all(np.isfinite(tri)):
                    tri[:] = 0.0
                    tri[nz, nz] = 1e6 * np.sqrt(len(ev["r"]))
            ev["tri"] = tri
        return ev

    def folded_fun(self, z: np.ndarray) -> np.ndarray:
        """Folded residuals (see :meth:`folded`)."""
        return self.folded(z)["tri"][:, -1].copy()

    def folded_jac(self, z: np.ndarray, *_) -> np.ndarray:
        """Folded Jacobian (see :meth:`folded`)."""
        return self.folded(z)["tri"][:, :-1].copy()

    def fun(self, z: np.ndarray) -> np.ndarray:
        """Residuals from :meth:`evaluate`."""
        return self.evaluate(z)["r"].copy()

    def jac(self, z: np.ndarray, *_) -> np.ndarray:
        """Jacobian from :meth:`tall`."""
        return self.tall(z).copy()

    def mean_cost(self, z: np.ndarray) -> float:
        """Mean squared residual at ``z``, the barrier left out."""
        r = self(z)[:-1] if not ("z" in self._last and np.array_equal(self._last["z"], z)) \
            else self._last["r"][:-1]
        return float(np.mean(r**2))

    def values(self, z: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        return self.par.to_values(z, self.base_phi)

    def simulate(self, z: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        theta, phi = self.values(z)
        self.work.theta = theta
        self.calls += 1
        with np.errstate(over="ignore", invalid="ignore"):
            w1, _, yhat = simulate_fit_data(self.work, phi, self.data)
        return theta, phi, w1, yhat

    def __call__(self, z: np.ndarray) -> np.ndarray:
        theta, phi, w1, yhat = self.simulate(z)
        r = yhat[self.data.weight] - self.y
        if not np.all(np.isfinite(r)):
            return np.full(len(self.y) + 1, 1e6)
        if self.profile is not None:
            # what the held parameters would absorb, to first order, is left out
            r = r - self.profile @ (self.profile.T @ r)
        margin = duhem_margin(theta, self.par.structure, phi, w1)
        over = max(0.0, margin - MARGIN_LIMIT) if np.isfinite(margin) else 1e3
        return np.append(r, self.barrier * over)


def _solve(problem: _Problem, z0: np.ndarray, max_nfev: int):
    lo, hi = problem.par.bounds()
    pad = 1e-9 * np.minimum(hi - lo, 1.0)
    z0 = np.clip(z0, lo + pad, hi - pad)
    # a dense trust-region step takes an SVD of the tall Jacobian per iteration: far more than
    # the simulations cost here; LSMR on the few columns does not (it needs two or more)
    solver = "lsmr" if len(z0) > 1 else "exact"
    opts = dict(bounds=(lo, hi), method="trf", x_scale="jac", ftol=1e-8, xtol=1e-8,
                gtol=1e-10, max_nfev=max_nfev)
    if JACOBIAN == "folded":
        return least_squares(problem.folded_fun, z0, jac=problem.folded_jac, tr_solver="exact",
                             **opts)
    if JACOBIAN == "sensitivities":
        return least_squares(problem.fun, z0, jac=problem.jac, tr_solver=solver, **opts)
    return least_squares(problem, z0, jac="2-point", tr_solver=solver, **opts)


def _judge(problem: _Problem, z: np.ndarray, message: str) -> RefitResult:
    """The refit's verdict at ``z``: finite, admissible, monotone anhysteretic curve."""
    theta, phi, w1, yhat = problem.simulate(z)
    w1 = w1.copy()
    r = yhat[problem.data.weight] - problem.y
    cost = float(np.mean(r**2)) if np.all(np.isfinite(r)) else np.inf
    margin = duhem_margin(theta, problem.par.structure, phi, w1)
    ok, msg = True, message
    if not (np.isfinite(cost) and np.all(np.isfinite(theta)) and np.all(np.isfinite(phi))):
        ok, msg = False, "the simulation diverges at the solution"
    elif 1 + 3 * phi[11] * np.max(w1**2) <= 0:
        ok, msg = False, "the solution's anhysteretic curve is not monotone (Assumption 2)"
    elif not margin < 2.0:
        ok, msg = False, (f"the solution leaves the Duhem stability condition (8) "
                          f"(alpha |dw1| reaches {margin:.3g}, expected < 2)")
    return RefitResult(theta, phi, cost, ok, msg, problem.calls, margin,
                       problem.par.at_bound(z))


def _distinct(phis: list[np.ndarray], slots: Sequence[int],
              rtol: float = SAME_START) -> list[np.ndarray]:
    """The effect-only solutions less those that found a minimum found before (every free slot
    within ``rtol`` of an earlier solution's): a joint stage from the same minimum twice
    repeats its work."""
    idx = list(slots)
    kept: list[np.ndarray] = []
    for phi in phis:
        a = phi[idx]
        if not any(np.all(np.abs(a - b[idx]) <= rtol * np.maximum(np.abs(a), np.abs(b[idx])))
                   for b in kept):
            kept.append(phi)
    return kept


def refit(
    model: DuhemSandwich,
    data: FitData,
    active: Sequence[str],
    starts: Sequence[np.ndarray],
    *,
    base_phi: np.ndarray | None = None,
    step_scale: float = 1.0,
    w1_scale: float = 1.0,
    max_nfev: int = 20,
    effect_nfev: int = 15,
    joint_starts: int = 1,
    profile: np.ndarray | None = None,
    widen: float = 1.0,
) -> RefitResult:
    """Least-squares refit of the nominal parameters and the active effects' parameters.

    Each start is first refitted in the new effect's parameters alone (the nominal ones and
    the accepted effects held), the best ``joint_starts`` of them then in all parameters
    together; the best admissible solution wins.

    Parameters
    ----------
    model : DuhemSandwich
        Start of the nominal parameters (its ``theta``), structure and sampling rate.
    data : FitData
        The fitting record.
    active : sequence of str
        Forms whose parameters are free (the last one is the new candidate; none for the
        nominal model alone).
    starts : sequence of ndarray
        Effect vectors to start from (each a full effect vector).
    base_phi : ndarray, optional
        Values of the effect slots that are not free (zero by default).
    step_scale : float
        Scale of the slew-limit coordinate (largest ``|dw1|`` of the nominal simulation).
    w1_scale : float
        Scale of the saturation and level coordinates (largest ``|w1|`` of the simulation).
    max_nfev : int
        Residual evaluations of the joint stage (Jacobian columns not counted).
    effect_nfev : int
        Residual evaluations of each start's effect-only stage.
    joint_starts : int
        How many of the best effect-only solutions the joint stage starts from (a dead time's
        cost has a minimum near every whole sample).
    profile : ndarray, optional
        Orthonormal basis (one column per direction, rows the weighted samples of ``data``) of
        the output directions of the parameters held in the effect-only stage, at ``model``
        (:func:`hystid.diagnose.screen.screen` computes it): that stage then fits the residual
        less its projection on them, i.e. with the held parameters' linear response profiled
        out, so that the new effect does not take the place of what they would absorb (a
        creep left alone with the nominal parameters held turns into a slow ramp).
    widen : float
        Factor on the guessed search ranges (see :class:`Parametrisation`).

    Returns
    -------
    RefitResult
        ``ok`` False, with the reason, when the solver failed or its solution is not
        admissible.
    """
    if not starts:
        return RefitResult(model.theta.copy(), np.zeros(N_SLOTS), np.inf, False, "no start given")
    duration = len(data.u) / data.fs
    new = list(active[-1:])
    calls = 0
    messages: list[str] = []
    if new:
        par_e = Parametrisation(model, new, duration, step_scale, w1_scale, free_theta=False,
                                widen=widen)
        found = []
        for phi0 in starts:
            problem = _Problem(model, data, par_e, phi0, profile)
            try:
                sol = _solve(problem, par_e.to_z(model.theta, phi0), effect_nfev)
            except (ValueError, np.linalg.LinAlgError, FloatingPointError) as err:
                messages.append(f"{type(err).__name__}: {err}")
                continue
            finally:
                calls += problem.calls
            found.append((problem.mean_cost(sol.x), par_e.to_values(sol.x, phi0)[1]))
        if not found:
            return RefitResult(model.theta.copy(), np.array(starts[0], float), np.inf, False,
                               "; ".join(messages) or "every start failed", calls)
        found.sort(key=lambda c: c[0])
        joint_from = _distinct([phi for _, phi in found], par_e.slots)[:max(joint_starts, 1)]
    else:
        joint_from = [np.array(starts[0], float)]
    par = Parametrisation(model, active, duration, step_scale, w1_scale, widen=widen)
    best: RefitResult | None = None
    for phi0 in joint_from:
        joint = _Problem(model, data, par, phi0)
        try:
            sol = _solve(joint, par.to_z(model.theta, phi0), max_nfev)
        except (ValueError, np.linalg.LinAlgError, FloatingPointError) as err:
            messages.append(f"{type(err).__name__}: {err}")
            calls += joint.calls
            continue
        res = _judge(joint, sol.x, str(sol.message))
        calls += joint.calls
        if best is None or (res.ok and (not best.ok or res.cost < best.cost)):
            best = res
    if best is None:
        return RefitResult(model.theta.copy(), joint_from[0], np.inf, False,
                           "; ".join(messages), calls)
    best.nfev = calls
    best.widen = widen
    return best
