"""The PI sandwich's off-line output-error fit (the reference for the recursion).

:func:`fit_pi_output_error` prepares the record, places the thresholds, fits on normalised
signals from several starts with exact sensitivities (:mod:`~hystid.identify.pi_kernels`) and
places the model back in the record's units.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from typing import Any, NamedTuple

import numpy as np
from scipy.optimize import least_squares

from ..model import Structure
from ..pi import N_OPERATORS, PISandwich, PIStructure
from ..records import Record
from ..threads import check_cancelled
from ..thresholds import RULES
from .constraints import Reflections
from .offline import SCREEN_NFEV, linear_start, triangle_of
from .pi_kernels import pi_output_sensitivities
from .pi_online_kernels import _KMAX
from .pi_stage_coordinates import is_stage_structure, stage_from_theta, theta_from_stage
from .prepare import prepare, scales
from .result import IdentificationResult

__all__ = ["POLISHED", "RIDGE", "fit_pi_output_error", "with_slow_branch"]


#: Starts of the off-line fit polished after the screening (the best ones), and the slow
#: branch's start (:func:`_slow_branch_start`) besides, when there is one.
POLISHED = 2
#: The slow branch's start: its pole's time constant is this share of the fitted span, and it
#: carries this share of L2's DC gain.
SLOW_START_SPAN = 0.25
SLOW_START_GAIN = 0.5
#: The label of that start.
SLOW_START = "ARX mode + slow branch"
#: That start is polished for this many times the evaluations of the others: its pole moves
#: from a quarter of the span to the creep's. On a Maxwell-slip stage with a 0.5 s creep and a
#: 1 s record (20 kHz, ``tests/test_pi_online_creep.py``'s stage) it lost within 40
#: evaluations: 113-124 nm off held-out records, 21-27 nm with 200.
SLOW_START_NFEV = 5
#: ..but it ends once its cost fell by less than this share over its last iterations, as
#: many as the other starts' polish has evaluations: it has stalled. On measured stage A's
#: triangles it crawled on for 160 evaluations (2 s) and took 0.1 % off the cost. Ended
#: there, the fit takes 2.4 s instead of 4.1 with a residual 0.04 % higher; on 17 records
#: (the creep stage, the stage-A look-alike swung and not, stage A) the residuals and
#: held-out errors are the same within 0.3 nm, but for the triangles' models on the PRBN
#: records: 66-67 nm against 71-74.
STALL_SHARE = 1e-3
#: The fit from that start is kept only when its slowest pole's time constant is at most this
#: many times the excitation it was fitted on (a slower pole is a drift the record cannot tell
#: from creep).
SLOW_START_LONGEST = 2.0
#: Ridge on the weights in the off-line fits: the cost is ``sum r^2 + RIDGE m |mu_n|^2`` on
#: normalised signals (``m`` samples in the cost, ``mu_n`` the weights in normalised units, so
#: the same in any units). Operators that the input moves only once (on the ramp out of rest)
#: have nearly collinear outputs; without it their weights drift along a flat valley of the
#: cost to large alternating values, and where the solver stops there is arbitrary.
RIDGE = 1e-8


def _span(rows: np.ndarray) -> float:
    """Samples from the first fitted sample to the last (at least one)."""
    return max(1.0, float(rows[-1] - rows[0])) if len(rows) else 1.0


def _nuisance(rows: np.ndarray, drift: bool, knot: int | None = None) -> np.ndarray:
    """Columns of the output's nuisance terms on the fitted samples ``rows``: the sensor
    offset (ones) and, with ``drift``, a straight line in time through zero at the middle of
    the fitted span, one output unit from its start to its end (:func:`_span`); with ``knot``,
    a bend every ``knot`` samples after the first (hinges ``max(0, k - k_j)``, each zero at the
    middle too, the last at least half a ``knot`` before the end): a drift that is a straight
    line between bends. The offset's coefficient is the drift's value at the middle."""
    ones = np.ones((len(rows), 1))
    if not drift or not len(rows):
        return ones
    span, mid = _span(rows), 0.5 * (rows[0] + rows[-1])
    cols = [ones, (rows - mid)[:, None] / span]
    if knot:
        for k in np.arange(rows[0] + knot, rows[-1] - 0.5 * knot, knot):
            cols.append((np.maximum(0.0, rows - k) - max(0.0, mid - k))[:, None] / span)
    return np.column_stack(cols)


#: A drift estimated beside the model bends every this many seconds (a straight line between
#: bends; :func:`_nuisance`). A sensor's zero drifts with its temperature, over minutes, and its
#: rate changes; the stages measured respond within a second or two. On a 40 s stage-B
#: look-alike record whose zero drifts at +0.05 um/s for 20 s and at -0.05 um/s after, one
#: straight line left a model 0.22-0.68 um off three held-out records with their means
#: removed and 130 um as placed; with a bend every 10 s the model is the drift-free record's,
#: 0.069-0.081 um (``tests/test_pi_drift.py``).
DRIFT_KNOT_SECONDS = 10.0




# =========================================================================== off-line
def _scale_weights(theta: np.ndarray, structure: PIStructure, y_scale: float,
                   u_scale: float) -> np.ndarray:
    """``theta`` (a vector, or one per row) from normalised units to ``u = u_scale un`` and
    ``y = y_scale yn`` (pass the reciprocals for the other way).

    With unit-DC-gain L1 and L2, ``w1`` is in input units and ``w2`` in output units, so the
    weights alone carry units: the thresholds are ``u_scale`` times and the weights
    ``y_scale / u_scale`` times their normalised values, and the coefficient of a polynomial
    term ``c_j w1^j`` is ``y_scale / u_scale^j`` times its normalised value.
    """
    out = np.array(theta, dtype=float)
    out[..., structure.slices()["mu"]] *= y_scale / u_scale
    out[..., structure.slices()["c"]] *= y_scale / u_scale ** np.arange(2, structure.n_poly + 2)
    return out


def _linear_slice(structure: PIStructure) -> slice:
    """Where the weights and the polynomial terms' coefficients sit in ``theta`` (together:
    the output is linear in them, and both carry the ridge)."""
    sl = structure.slices()
    return slice(sl["mu"].start, sl["c"].stop)


def _weights_given_blocks(theta: np.ndarray, un: np.ndarray, yn: np.ndarray, rows: np.ndarray,
                          r: np.ndarray, structure: PIStructure, fit_offset: bool,
                          drift: bool = False, knot: int | None = None, swing: float = 0.0
                          ) -> tuple[np.ndarray, np.ndarray]:
    """``theta`` with its weights and polynomial terms (and the offset, and the drift) set by
    linear least squares for its L1 and L2 (the plays at rest after ``swing``): exact, since
    the output is linear in them."""
    theta = np.array(theta, dtype=float)
    mu = _linear_slice(structure)
    theta[mu] = 0.0
    _, J = pi_output_sensitivities(PISandwich(theta, r, structure, rest_swing=swing), un)
    A = J[rows][:, mu]
    if fit_offset:
        A = np.column_stack([A, _nuisance(rows, drift, knot)])
    n = structure.n_operators + structure.n_poly
    A = np.vstack([A, np.sqrt(RIDGE * len(rows)) * np.eye(n, A.shape[1])])
    coef, *_ = np.linalg.lstsq(A, np.r_[yn[rows], np.zeros(n)], rcond=None)
    theta[mu] = coef[:n]
    return theta, coef[n:]


def _arx_blocks(un: np.ndarray, yn: np.ndarray, rows: np.ndarray,
                structure: PIStructure) -> np.ndarray | None:
    """L1 and L2 of the linear sandwich's ARX fit (:func:`hystid.identify.offline.linear_start`,
    its monic numerators rescaled to unit DC gain); None when its roots do not split."""
    s = structure
    duhem = Structure(n1a=s.n1a, n1b=s.n1b - 1, n2a=s.n2a, n2b=s.n2b - 1, q1=s.q1, q2=s.q2)
    filled = np.interp(np.arange(len(yn)), rows, yn[rows])
    lin = linear_start(Record(un, filled, 1.0, name="normalised"), duhem, with_offset=True)
    if lin is None:
        return None
    values = dict(zip(duhem.names, lin[0], strict=True))
    theta = np.zeros(len(s.names))
    for block, na, nb in (("1", s.n1a, s.n1b), ("2", s.n2a, s.n2b)):
        a = np.array([values[f"a{block}{i}"] for i in range(1, na + 1)])
        c = np.array([values[f"b{block}{j}"] for j in range(1, nb)])
        lead = (1.0 + a.sum()) / (1.0 + c.sum())
        for i, v in enumerate(a, start=1):
            theta[s.names.index(f"a{block}{i}")] = v
        for j, v in enumerate(c, start=2):
            theta[s.names.index(f"b{block}{j}")] = lead * v
    return theta if np.isfinite(theta).all() else None


class _NormalisedFit(NamedTuple):
    """An off-line fit on normalised signals (:func:`_solve_normalised`)."""

    theta: np.ndarray
    y0: float
    rms: float
    nfev: int
    message: str
    start: str
    drift: float = 0.0  # normalised output units over the fitted span (end less start) ..
    span: float = 1.0  # .. of this many samples (:func:`_span`)
    moved: float = 0.0  # the drift's range over the fitted span (normalised output units)
    pieces: int = 1  # straight pieces of the drift (bends plus one)

    def info(self, r: np.ndarray, u_scale: float, y_scale: float) -> dict[str, Any]:
        """The fit's report in record units (RMS residual, thresholds, scales)."""
        return {"rms_residual": self.rms * y_scale, "nfev": self.nfev, "message": self.message,
                "start": self.start, "thresholds": r.tolist(),
                "scales": {"u": u_scale, "y": y_scale}}


def _solve_normalised(
    un: np.ndarray, yn: np.ndarray, weight: np.ndarray, r: np.ndarray, structure: PIStructure,
    theta0: np.ndarray | None, fit_offset: bool, max_nfev: int, tol: float,
    screen_nfev: int = SCREEN_NFEV, drift: bool = False, knot: int | None = None,
    slow_start: bool = False, swing: float = 0.0,
) -> _NormalisedFit:
    """Output-error least squares on normalised signals, from several starts.

    Minimises ``sum (yhat(k) + y0 - yn(k))^2`` over the samples with ``weight`` (``yhat`` the
    free run from rest on ``un``, thresholds ``r`` in normalised input units) with
    :func:`scipy.optimize.least_squares` in reflection coefficients of L1 and L2 and, with
    ``fit_offset``, the normalised sensor offset ``y0`` (and, with ``drift``, a straight line
    in time beside it: :func:`_nuisance`), the plays at rest after ``swing`` (normalised input
    units, held). The starts (:func:`_starts`) are run for
    ``screen_nfev`` evaluations each; the :data:`POLISHED` best and the slow branch's start
    are polished (``max_nfev`` evaluations).

    Returns
    -------
    _NormalisedFit
        Normalised parameters and offset, RMS residual and the solver's report.
    """
    rows = np.flatnonzero(weight)
    problem = _PIOutputError(un, yn, rows, r, structure, fit_offset, drift and fit_offset, knot,
                             swing)
    starts = _starts(un, yn, rows, r, structure, theta0, fit_offset, drift and fit_offset, knot,
                     slow_start, swing)
    screened = []
    for label, (theta, y0) in starts.items():
        sol = problem.solve(problem.to_z(theta, y0),
                            screen_nfev if len(starts) > 1 else max_nfev, tol)
        screened.append((sol.cost, label, sol))
    screened.sort(key=lambda item: item[0])
    polished = []
    best = list(screened[:POLISHED])
    best += [item for item in screened[POLISHED:] if item[1] == SLOW_START]
    for _, label, sol in best:
        if len(starts) > 1:
            slow = label == SLOW_START
            sol = problem.solve(sol.x, max_nfev * (SLOW_START_NFEV if slow else 1), tol,
                                stall=max_nfev if slow else 0)
        polished.append((sol.cost, label, sol))
    kept = [item for item in polished if item[1] != SLOW_START
            or _slowest_tau(problem.split(item[2].x)[0], structure) <= SLOW_START_LONGEST
            * _excitation_span(un, rows)]
    _, label, sol = min(kept or polished, key=lambda item: item[0])
    return _normalised_fit(problem, sol, label)


def _normalised_fit(problem: _PIOutputError, sol: Any, label: str) -> _NormalisedFit:
    """The fit of a solver's result ``sol`` on ``problem``, started from ``label``."""
    theta, y0 = problem.split(sol.x)
    rms = float(np.sqrt(np.mean(problem.evaluate(sol.x)["data"] ** 2)))
    moved, pieces = problem.moved(sol.x)
    return _NormalisedFit(theta, y0, rms, int(sol.nfev), str(sol.message), label,
                          problem.drift(sol.x), _span(problem.rows), moved, pieces)


def _with_rest_swing(fit: _NormalisedFit, un: np.ndarray, yn: np.ndarray, rows: np.ndarray,
                     r: np.ndarray, structure: PIStructure, fit_offset: bool, drift: bool,
                     knot: int | None, max_nfev: int, tol: float
                     ) -> tuple[_NormalisedFit, float, dict[str, Any]]:
    """The fit with the stage's last excursion before its rest
    (:mod:`~hystid.identify.pi_rest_swing`: scanned with L1 and L2 held, then the problem
    solved again with it held), kept when it lowers the RMS residual by more than
    :data:`~hystid.identify.pi_rest_swing.GAIN` and is not an end of the input's range
    (:func:`~hystid.identify.pi_rest_swing.keeps_swing`); the
    swing (normalised) and the scan's report."""
    from .pi_rest_swing import keeps_swing, scan_rest_swing

    nuisance = _nuisance(rows, drift, knot) if fit_offset else np.ones((len(rows), 0))
    found = scan_rest_swing(fit.theta, un, yn, rows, r, structure, nuisance, RIDGE)
    report = {"swing": found["swing"], "rms_scan": found["rms"], "rms_virgin": fit.rms,
              "at_bound": found["at_bound"], "kept": False}
    if not keeps_swing(found["rms"], fit.rms, found["at_bound"]):
        return fit, 0.0, report
    problem = _PIOutputError(un, yn, rows, r, structure, fit_offset, drift, knot,
                             swing=found["swing"])
    sol = problem.solve(problem.to_z(found["theta"], found["nuisance"]), max_nfev, tol)
    swung = _normalised_fit(problem, sol, f"{fit.start} + rest swing")
    if not keeps_swing(swung.rms, fit.rms, False):
        return fit, 0.0, report
    report["kept"] = True
    return swung, found["swing"], report


def _starts(un: np.ndarray, yn: np.ndarray, rows: np.ndarray, r: np.ndarray,
            structure: PIStructure, theta0: np.ndarray | None,
            fit_offset: bool, drift: bool = False, knot: int | None = None,
            slow_start: bool = False, swing: float = 0.0
            ) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """``theta0`` alone when given; else ``L1 = L2 = z^-1``, the linear sandwich's ARX
    blocks and, for the ``pi-stage`` shape with ``slow_start`` (a record that begins at rest),
    those blocks with a slow branch (:func:`_slow_branch_start`), each with the weights (and
    offset) that fit best for its blocks."""
    if theta0 is not None:
        if not PISandwich(theta0, r, structure).is_stable():
            raise ValueError("theta0: the start must have stable L1 and L2")
        return {"theta0": (theta0, np.zeros(0))}
    delay = np.zeros(len(structure.names))
    blocks = {"L1 = L2 = z^-1": delay}
    arx = _arx_blocks(un, yn, rows, structure)
    if arx is not None:
        sl = structure.slices()
        l1 = np.r_[sl["a1"], sl["b1"]]
        blocks["ARX"] = arx
        blocks["L1 = z^-1, ARX L2"] = np.where(np.isin(np.arange(len(arx)), l1), 0.0, arx)
        blocks["ARX L1, L2 = z^-1"] = np.where(np.isin(np.arange(len(arx)), l1), arx, 0.0)
    unique: dict[str, np.ndarray] = {}  # a structure without free L1 terms makes mixtures twins
    if slow_start and arx is not None and is_stage_structure(structure):
        slow = _slow_branch_start(arx, structure, int(rows[-1] - rows[0] + 1))
        if slow is not None:
            blocks[SLOW_START] = slow
    for label, theta in blocks.items():
        if not any(np.array_equal(theta, other) for other in unique.values()):
            unique[label] = theta
    return {label: _weights_given_blocks(theta, un, yn, rows, r, structure, fit_offset, drift,
                                         knot, swing)
            for label, theta in unique.items()}


def _slowest_tau(theta: np.ndarray, structure: PIStructure) -> float:
    """The time constant of L2's slowest pole, in samples (``inf`` on the unit circle), for
    the ``pi-stage`` shape (a static L1: L2's denominator follows the weights)."""
    n = structure.n_operators + structure.n_poly
    radius = float(np.max(np.abs(np.roots(np.r_[1.0, theta[n:n + structure.n2a]]))))
    return -1.0 / np.log(radius) if 0.0 < radius < 1.0 else float("inf")


def _excitation_span(un: np.ndarray, rows: np.ndarray) -> int:
    """Samples from the first that leaves the first input to the last fitted one."""
    moved = np.flatnonzero(un != un[0])
    return int(rows[-1] - (moved[0] if moved.size else rows[0]) + 1)


def with_slow_branch(phi: np.ndarray, n: int, span: int) -> np.ndarray:
    """Stage coordinates with the slow branch set as the slow-branch start sets it.

    Parameters
    ----------
    phi : ndarray
        Stage coordinates (:mod:`~hystid.identify.pi_stage_coordinates`), weights first.
    n : int
        Number of weights (and polynomial terms) before the slow branch.
    span : int
        Samples the time constant is a share of.

    Returns
    -------
    ndarray
        A copy with :data:`SLOW_START_GAIN` of the DC gain on the slow branch and its time
        constant :data:`SLOW_START_SPAN` of ``span``.
    """
    phi = np.array(phi, dtype=float)
    phi[n] = SLOW_START_GAIN
    phi[n + 1] = np.arctanh(np.exp(-1.0 / (SLOW_START_SPAN * max(span, 1))) / _KMAX)
    return phi


def _slow_branch_start(arx: np.ndarray, structure: PIStructure, span: int) -> np.ndarray | None:
    """The ARX blocks of the ``pi-stage`` shape in its parallel form
    (:mod:`~hystid.identify.pi_stage_coordinates`), the slow branch's pole moved to a time
    constant of :data:`SLOW_START_SPAN` of the fitted ``span`` (in samples) and its share of
    the DC gain set to :data:`SLOW_START_GAIN`; the mode as the ARX fit has it. None when the
    ARX blocks have no real pole.

    The ARX fit (equation error) puts the slow pole of a measured stage's creep at a time
    constant of tens of samples: on measured stage A's ``prbn_1`` with its rest cut to 20 ms
    or 5 ms (0.989 against the 0.99988 of the fit), where the output-error fit from there
    stopped at 43-45 nm of residual and 80-110 nm off the other five records, against 27 nm and
    23-41 nm from this start. Only on a record that begins at rest: on one in motion nothing
    anchors the slow branch (a drift of the sensor's zero is fitted beside it), and with this
    start the on-line model of a paper-like Maxwell-slip stage cut mid-motion was up to
    2.64 um off held-out records (0.062-0.075 without it). And only when the fit from it puts
    L2's slowest time constant within :data:`SLOW_START_LONGEST` times the excitation: on the
    measured piezo's first 60 % (2.7 s of a 1 Hz sine after a rest) the fit from it put the
    pole at 0.99998 (10 s), the member choice then took ``pi-stage`` and the model was 0.45 um
    off the last 40 %, where the Duhem sandwich it keeps otherwise is 0.07. On stage A the
    pole is 0.83 s for 1 s of excitation."""
    n = structure.n_operators + structure.n_poly
    a = arx[n:n + 3]
    roots = np.roots(np.r_[1.0, a])
    if not np.any(np.abs(roots.imag) <= 1e-9 * np.maximum(1.0, np.abs(roots))):
        return None
    theta = theta_from_stage(with_slow_branch(stage_from_theta(arx, n), n, span), n)
    return theta if np.isfinite(theta).all() else None


class _PIOutputError:
    """The output-error problem on normalised signals, in ``z = [reflection coefficients of
    L1 and L2 | the other parameters | y0 (with an offset) | the drift (with it)]``."""

    def __init__(self, un: np.ndarray, yn: np.ndarray, rows: np.ndarray, r: np.ndarray,
                 structure: PIStructure, fit_offset: bool, drift: bool = False,
                 knot: int | None = None, swing: float = 0.0) -> None:
        s = self.structure = structure
        self.swing = swing  # the stage's last excursion before its rest (held)
        self.un, self.r, self.rows, self.target = un, r, rows, yn[rows]
        # the fitted samples as a slice when they are a run (no copy of the Jacobian's rows)
        whole = len(rows) and np.array_equal(rows, np.arange(rows[0], rows[0] + len(rows)))
        self.kept = slice(int(rows[0]), int(rows[0]) + len(rows)) if whole else rows
        self.fit_offset = fit_offset
        self.n = len(s.names)
        sl, index = s.slices(), np.arange(self.n)
        self.rp = Reflections([index[sl["a1"]], index[sl["a2"]]], self.n)
        self.ones = _nuisance(rows, drift, knot) if fit_offset else np.ones((len(rows), 0))
        self.fo = self.ones.shape[1]  # the nuisance terms: offset, drift
        self.mu = index[_linear_slice(s)]
        self.ridge = np.sqrt(RIDGE * len(rows))
        self.ridge_rows = np.zeros((len(self.mu), self.n + self.fo))
        self.ridge_rows[np.arange(len(self.mu)), self.mu] = self.ridge
        self._cache: dict[str, Any] = {}

    def to_z(self, theta: np.ndarray, nuisance: float | np.ndarray) -> np.ndarray:
        """Search coordinates of a parameter vector and its nuisance terms (offset, drift; those
        not given start at zero)."""
        given = np.ravel(nuisance)[: self.fo]
        return np.r_[self.rp.to_z(theta), given, np.zeros(self.fo - len(given))]

    def split(self, z: np.ndarray) -> tuple[np.ndarray, float]:
        """Parameters and offset of ``z``."""
        return self.rp.to_theta(z[: self.n])[0], float(z[self.n]) if self.fit_offset else 0.0

    def drift(self, z: np.ndarray) -> float:
        """The drift of ``z`` over the fitted span, its end less its start (0 without one)."""
        path = self.drift_path(z)
        return float(path[-1] - path[0]) if len(path) else 0.0

    def moved(self, z: np.ndarray) -> tuple[float, int]:
        """The drift's range over the fitted span and its straight pieces."""
        path = self.drift_path(z)
        return (float(np.ptp(path)) if len(path) else 0.0, max(1, self.fo - 1))

    def drift_path(self, z: np.ndarray) -> np.ndarray:
        """The drift of ``z`` at each fitted sample, zero at the middle (empty without one)."""
        if self.fo < 2:
            return np.zeros(0)
        return self.ones[:, 1:] @ z[self.n + 1:]

    def evaluate(self, z: np.ndarray) -> dict[str, Any]:
        """Residuals and Jacobian at ``z``, folded (:func:`_folded`), and the data residuals
        (``data``, unfolded); cached for the last ``z``."""
        check_cancelled()  # a fit started ahead of a decision that no longer needs it
        if self._cache.get("z") is None or not np.array_equal(self._cache["z"], z):
            theta, dtheta = self.rp.to_theta(z[: self.n])
            with np.errstate(over="ignore", invalid="ignore"):
                model = PISandwich(theta, self.r, self.structure, rest_swing=self.swing)
                yhat, S, D = pi_output_sensitivities(model, self.un, chain=dtheta, raw=True)
            data = yhat[self.kept] + self.ones @ z[self.n:] - self.target
            # the data rows [S | 1 | r] (sensitivities to the full coefficients, the offset's
            # ones, the residuals) reduced to their triangle first; its columns then mapped to
            # z (J = S D folds to R_S D: a square product, not a tall one) and folded again
            # with the ridge rows
            m, nc, fo = len(self.rows), S.shape[1], self.fo
            B = np.empty((m, nc + fo + 1))
            B[:, :nc] = S[self.kept]
            B[:, nc:nc + fo] = self.ones
            B[:, -1] = data
            width = self.n + fo
            A = np.empty((nc + fo + 1 + len(self.mu), width + 1))
            if np.all(np.isfinite(B)):
                R = triangle_of(B)
                A[:nc + fo + 1, :self.n] = R[:, :nc] @ D
                A[:nc + fo + 1, self.n:] = R[:, nc:]
            else:
                A[:nc + fo + 1] = np.nan  # a failed step (see _fold)
            A[nc + fo + 1:, :width] = self.ridge_rows
            A[nc + fo + 1:, width] = self.ridge * theta[self.mu]
            self._cache = {"z": z.copy(), "data": data, **_fold(A)}
        return self._cache

    def solve(self, z0: np.ndarray, max_nfev: int, tol: float, stall: int = 0):
        """``least_squares`` from ``z0`` within the reflection bounds; with ``stall``, ended
        when the cost fell by less than :data:`STALL_SHARE` over the last ``stall``
        iterations."""
        lo, hi = self.rp.bounds()
        lo = np.r_[lo, [-np.inf] * self.fo]
        hi = np.r_[hi, [np.inf] * self.fo]
        with np.errstate(over="ignore", invalid="ignore"):
            return least_squares(lambda z: self.evaluate(z)["r"], np.clip(z0, lo, hi),
                                 jac=lambda z: self.evaluate(z)["J"], bounds=(lo, hi),
                                 method="trf", ftol=tol, xtol=tol, gtol=tol, max_nfev=max_nfev,
                                 x_scale="jac", callback=_stall_check(stall) if stall else None)


def _stall_check(window: int) -> Callable[[Any], None]:
    """A ``least_squares`` callback that stops the solver (``StopIteration``, its status -2)
    once the cost fell by less than :data:`STALL_SHARE` over ``window`` iterations."""
    costs: list[float] = []

    def check(intermediate_result: Any) -> None:
        costs.append(float(intermediate_result.cost))
        if len(costs) > window and costs[-1] > (1.0 - STALL_SHARE) * costs[-1 - window]:
            raise StopIteration

    return check


def _folded(J: np.ndarray, r: np.ndarray) -> dict[str, np.ndarray]:
    """``[J | r]`` folded into its QR triangle ``[R | c; 0 | rho]``: the residuals ``[c, rho]``
    and the Jacobian ``[R; 0]`` have the norm, gradient and ``J'J`` of the full problem, so
    ``least_squares`` takes the same steps on a square problem instead of a tall one (its
    SVD per iteration then costs nothing). A non-finite ``[J | r]`` gives non-finite
    residuals of the same length (the solver takes that as a failed step)."""
    return _fold(np.column_stack([J, r]))


def _fold(A: np.ndarray) -> dict[str, np.ndarray]:
    """:func:`_folded` of the rows ``[J | r]`` as one matrix."""
    width = A.shape[1]
    if not np.all(np.isfinite(A)):
        return {"r": np.full(width, np.nan), "J": np.zeros((width, width - 1))}
    tri = triangle_of(A)
    return {"r": tri[:, -1].copy(), "J": tri[:, :-1].copy()}


def _structure_and_thresholds(
    u: np.ndarray, thresholds: np.ndarray | str | None, structure: PIStructure | None,
    n_operators: int,
) -> tuple[PIStructure, np.ndarray]:
    """The structure and the thresholds (record units): given, or placed over ``u`` by a rule
    of :data:`hystid.thresholds.RULES` (the paper's ``"range"`` when None)."""
    if structure is not None:
        n_operators = structure.n_operators
    if thresholds is None:
        thresholds = "range"
    if isinstance(thresholds, str):
        if thresholds not in RULES:
            raise ValueError(f"thresholds: expected an array or one of {', '.join(RULES)}, "
                             f"got {thresholds!r}")
        r = RULES[thresholds](u, n_operators)
    else:
        r = np.asarray(thresholds, dtype=float).ravel()
    s = structure or PIStructure(n_operators=len(r))
    if len(r) != s.n_operators:
        raise ValueError(f"thresholds: expected {s.n_operators} values for the structure, got "
                         f"{len(r)}")
    return s, r


def fit_pi_output_error(
    record: Record,
    thresholds: np.ndarray | str = "swing",
    structure: PIStructure | None = None,
    *,
    n_operators: int = N_OPERATORS,
    theta0: np.ndarray | None = None,
    offset: bool = True,
    drift: bool | None = None,
    skip: int | None = None,
    left_out: Sequence[tuple[int, int]] = (),
    max_nfev: int = 200,
    tol: float = 1e-8,
    name: str = "identified PI sandwich",
    rest_swing: bool | float = True,
) -> IdentificationResult:
    """Identify the PI sandwich off-line by output-error least squares (the reference).

    The steps, as in the off-line Duhem fit (:func:`hystid.identify.offline.fit_output_error`):
    :func:`~hystid.identify.prepare.prepare` the record (excitation check, rest level, robust
    scales, outliers and saturation left out of the cost, burn-in when it does not start at
    rest); fit on the input less its rest over its scale and the output over its scale, so that
    the result does not depend on the units; map the weights and thresholds back and place the
    model at the record's rest level, sensor offset, input envelope and units.

    The fit minimises ``sum_k (y(k) - yhat(k | theta) - y0)^2`` of the free run from rest with
    :func:`scipy.optimize.least_squares` (trust-region reflective, exact Jacobian), in the
    off-line Duhem fit's search coordinates (:class:`~hystid.identify.constraints.Reflections`):
    the denominators of L1 and L2 as reflection coefficients inside the unit interval, so the
    model stays stable. A small ridge (:data:`RIDGE`, on the normalised weights) keeps the
    weights of operators the input hardly moves from drifting. The starts: ``L1 = L2 = z^-1``,
    the linear sandwich's ARX blocks and the two mixtures, and for the ``pi-stage`` shape the
    ARX blocks with a slow branch (:func:`_slow_branch_start`; on a record that begins at
    rest), each with the weights and the offset fitted by linear least squares (the output
    is linear in both); each runs for :data:`~hystid.identify.offline.SCREEN_NFEV`
    evaluations and the :data:`POLISHED` best (and the slow branch's start) are polished, as
    in the off-line Duhem fit.

    Parameters
    ----------
    record : Record
        Input ``u`` and measured output ``y``, in any units.
    thresholds : array_like or {"swing", "range"}
        Play-operator thresholds in the record's input units, or the rule that places them
        over the fitted samples (:mod:`hystid.thresholds`): ``"swing"`` (default) within the
        largest swing between two reversals of the input, so that every operator is reversed
        at least once; ``"range"`` the paper's, over the input's range.
    structure : PIStructure, optional
        Orders and delays (the paper's by default).
    n_operators : int
        Number of operators when neither ``thresholds`` nor ``structure`` say.
    theta0 : array_like, optional
        Start vector in record units instead of the default.
    offset : bool
        Estimate the sensor offset (default); without it the output is taken as zero at rest.
    drift : bool, optional
        Estimate, beside the offset, a drift of the sensor's zero (a straight line in time
        between bends every :data:`DRIFT_KNOT_SECONDS`, one line on a shorter record) that the
        model does not carry: the offset is then the one at the middle of the fitted samples.
        By default on a record that does not start at rest,
        where no rest pins the output's zero and a drift is otherwise fitted as the start
        transient of a slow pole: on the stage-B look-alike with a zero drifting by 0.3 um/s,
        the ``pi-stage`` fit put an 8 s pole there and was 2.5-2.8 um off three held-out
        records (the linear model 0.85-0.93), and with the drift estimated 0.27-0.28. On
        measured stage A (records at rest first) estimating it was worse on four of five
        records (by 3-5 nm), so it stays off there.
    skip : int, optional
        Leading samples simulated but left out of the cost; by default none for a record that
        starts at rest, else until the input has swept its range.
    left_out : sequence of (int, int)
        Spans ``[first, stop)`` of samples simulated but left out of the cost (the model
        choice's held-out block).
    max_nfev : int
        Maximum number of residual evaluations.
    tol : float
        ``ftol``, ``xtol`` and ``gtol`` of the solver.
    name : str
        Name of the identified model.
    rest_swing : bool or float
        On a record that starts at rest, also estimate the stage's last excursion before it
        (:attr:`~hystid.pi.PISandwich.rest_swing`: the stage rests on one branch of its loop;
        :mod:`~hystid.identify.pi_rest_swing`), kept when it lowers the RMS residual by more
        than a tenth (True, the default); start from the virgin state (False); or hold the
        swing given, in input units from the rest (a number: the fit is solved with the plays
        where that swing left them; on a record that begins in motion it does not apply, and
        the warnings say so).

    Returns
    -------
    IdentificationResult
        ``method="pi-batch"``; ``info`` holds the RMS residual (record units), the solver's
        message, the scales, the offset, ``rest_swing`` (input units; ``rest_swing_scan``: the
        best swing found, the RMS residual with it and from the virgin state, whether it was
        kept), ``drift_per_second`` (output units, its mean rate over
        the fitted samples, 0 when not estimated), ``drift_pieces`` (its straight pieces) and
        ``warnings`` (what the preparation found, and a drift larger than
        :data:`DRIFT_SAID` times the RMS residual over the fitted samples).
    """
    if drift and not offset:
        raise ValueError("drift: a drift is estimated beside the offset; pass offset=True or "
                         "drift=False")
    held = _given_swing(rest_swing)
    prep = prepare(record, skip=skip, left_out=left_out)
    if held and not prep.at_rest:
        prep.notes = list(prep.notes) + [
            f"rest_swing: the swing given ({held:.4g}) is the state at a rest; record "
            f"{record.name!r} begins in motion, so the plays start virgin"]
        held = 0.0
    drift = bool(offset and (not prep.at_rest if drift is None else drift))
    s, r = _structure_and_thresholds(record.u[prep.fitted], thresholds, structure, n_operators)
    if not offset:
        prep.y_ref, prep.yn = 0.0, record.y / prep.y_scale
    su, sy = prep.u_scale, prep.y_scale
    theta0_n = None if theta0 is None else _scale_weights(
        np.asarray(theta0, dtype=float).ravel(), s, 1.0 / sy, 1.0 / su)
    knot = max(1, int(round(DRIFT_KNOT_SECONDS * record.fs)))
    swing, scan = (held or 0.0) / su, None
    fit = _solve_normalised(prep.un, prep.yn, prep.weight, r / su, s, theta0_n, offset,
                            max_nfev, tol, drift=drift, knot=knot, slow_start=prep.at_rest,
                            swing=swing)
    if held is None and rest_swing and prep.at_rest:
        fit, swing, scan = _with_rest_swing(fit, prep.un, prep.yn, np.flatnonzero(prep.weight),
                                            r / su, s, offset, drift, knot, max_nfev, tol)
        scan = {**scan, "swing": scan["swing"] * su, "rms_scan": scan["rms_scan"] * sy,
                "rms_virgin": scan["rms_virgin"] * sy}
    model = PISandwich(_scale_weights(fit.theta, s, sy, su), r, s, fs=record.fs, name=name,
                       u_rest=prep.u_rest, offset=prep.offset(fit.y0), envelope=prep.envelope,
                       units=record.units, rest_swing=swing * su)
    info = {**fit.info(r, su, sy), "offset": model.offset, "at_rest": prep.at_rest,
            "skip": prep.skip, "warnings": list(prep.notes) + _drift_note(fit, prep, record)
            + _inverse_note(model)}
    info["rest_swing"], info["rest_swing_scan"] = model.rest_swing, scan
    info["drift_per_second"] = _drift_per_second(fit, prep, record)
    info["drift_pieces"] = fit.pieces if drift else 0
    settings = {"n_operators": len(r), "offset": offset, "drift": drift, "skip": prep.skip,
                "max_nfev": max_nfev, "tol": tol, "samples": record.n, "rest_swing": rest_swing}
    return IdentificationResult(model, "pi-batch", settings, info=info)


def _given_swing(rest_swing: Any) -> float | None:
    """The swing :func:`fit_pi_output_error` holds: None for True or False (estimated, or the
    virgin state), else the number given (input units from the rest), checked finite."""
    if isinstance(rest_swing, (bool, np.bool_)):
        return None
    try:
        value = float(rest_swing)
    except (TypeError, ValueError):
        value = math.nan
    if not math.isfinite(value):
        raise ValueError(f"rest_swing: expected True (estimate it), False (the virgin state) or "
                         f"a finite swing in input units from the rest, got {rest_swing!r}")
    return value


def _inverse_note(model: PISandwich) -> list[str]:
    """What a fit whose PI block has no exact inverse means for compensation (the batch fit
    leaves the weights free: a loading curve that falls somewhere fits some stages best)."""
    if model.is_invertible() or not (model.thresholds[0] == 0
                                     and np.all(np.diff(model.thresholds) > 0)):
        return []
    low = float(np.min(np.cumsum(model.mu)))
    if len(model.poly):
        return [f"the model's PI block has no inverse (its least branch slope "
                f"{model.branch_slope_min():.4g} is not positive): hystid compensate refuses "
                "it; identify with model='pi-stage' to compensate"]
    high = float(np.max(np.cumsum(model.mu)))
    if not high > 0:
        return ["the model's PI operator has no inverse (no partial sum of its weights is "
                "positive: no branch rises): hystid compensate refuses it"]
    return [f"the model's PI operator has no exact inverse (a partial sum of its weights is "
            f"{low / high:.2g} times the largest, not positive: its loading curve falls "
            "somewhere); compensate inverts "
            "the nearest operator whose partial sums are positive and gives the model's output "
            "from that command"]


#: A drift of the sensor's zero estimated beside the model is said when it moves the output by
#: more than this many times the fit's RMS residual over the fitted samples.
DRIFT_SAID = 3.0


def _drift_per_second(fit: _NormalisedFit, prep: Any, record: Record) -> float:
    """The estimated drift in output units per second (its mean rate over the fitted span)."""
    return fit.drift * prep.y_scale * record.fs / fit.span


def _drift_note(fit: _NormalisedFit, prep: Any, record: Record) -> list[str]:
    """A sentence on a drift estimated beside the model, when it is large."""
    return drift_note(_drift_per_second(fit, prep, record), fit.moved * prep.y_scale,
                      fit.rms * prep.y_scale, record.units.get("y", ""), "fitted samples",
                      pieces=fit.pieces)


def drift_note(rate: float, moved: float, rms: float, unit: str, where: str, *,
               pieces: int = 1) -> list[str]:
    """The warning for a drift of the output's zero estimated beside a model.

    Parameters
    ----------
    rate : float
        The drift per second, output units.
    moved : float
        How far it moved the output over ``where``.
    rms : float
        The fit's RMS residual there.
    unit : str
        The output's unit.
    where : str
        The samples it was estimated on, for the sentence.
    pieces : int
        Straight pieces of the drift (``rate`` is then their mean).

    Returns
    -------
    list of str
        One sentence when ``moved`` exceeds :data:`DRIFT_SAID` times ``rms``, else none.
    """
    if not abs(moved) > DRIFT_SAID * rms:
        return []
    how = (f"by {rate:.3g} {unit}/s" if pieces <= 1 else
           f"by {rate:.3g} {unit}/s on average, in {pieces} straight pieces,")
    return [f"the output's zero drifts {how} ({abs(moved):.3g} {unit} over "
            f"the {where}), estimated beside the model and not part of it: records taken "
            "later will be offset by the drift since"]


def _zero_result(
    fit: _NormalisedFit, su: float, sy: float, r: np.ndarray, structure: PIStructure, fs: float,
    samples: int, *, max_nfev: int = 200, tol: float = 1e-8,
    name: str = "identified PI sandwich",
) -> IdentificationResult:
    """The result of :func:`_fit_normalised_from_zero` in record units (weights mapped back)."""
    model = PISandwich(_scale_weights(fit.theta, structure, sy, su), r, structure, fs=fs,
                       name=name)
    settings = {"n_operators": len(r), "max_nfev": max_nfev, "tol": tol, "samples": samples}
    return IdentificationResult(model, "pi-batch", settings, info=fit.info(r, su, sy))


def _zero_scales(u: np.ndarray, y: np.ndarray) -> tuple[float, float]:
    """Input and output scales about zero (:func:`~hystid.identify.prepare.scales`) of the
    samples with a finite output: the recursion's units."""
    su, _, sy = scales(u, y[np.isfinite(y)], 0.0)
    return su or 1.0, sy


def _fit_normalised_from_zero(
    u: np.ndarray, y: np.ndarray, r: np.ndarray, structure: PIStructure, *,
    max_nfev: int = 200, tol: float = 1e-8, screen_nfev: int = SCREEN_NFEV,
    offset: bool = False, drift: bool = False, swing: float = 0.0,
) -> tuple[_NormalisedFit, float, float]:
    """:func:`_solve_normalised` at rest at ``u = 0`` (with an offset when ``offset``, and a
    drift beside it when ``drift``; the plays at rest after ``swing``, in the units of ``u``),
    on ``u / su`` and ``y / sy`` (:func:`_zero_scales`); samples with a non-finite ``y`` are
    left out of the cost.

    Returns
    -------
    tuple
        The normalised fit, ``su`` and ``sy``.
    """
    u = np.ascontiguousarray(u, dtype=float)
    y = np.ascontiguousarray(y, dtype=float)
    su, sy = _zero_scales(u, y)
    with np.errstate(invalid="ignore"):
        fit = _solve_normalised(u / su, y / sy, np.isfinite(y), r / su, structure, None, offset,
                                max_nfev, tol, screen_nfev, drift=drift, swing=swing / su)
    return fit, su, sy


