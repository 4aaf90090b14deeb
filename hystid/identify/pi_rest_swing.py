"""The PI sandwich's state at rest: the stage's last excursion before the record.

A stage brought back to its rest level after earlier work rests on one branch of its loop, not
at the loop's centre; the play operators then start where that excursion left them
(:attr:`hystid.pi.PISandwich.rest_swing`, :attr:`~hystid.pi.PISandwich.rest_plays`). A fit
that starts them virgin reads the branch gap as an offset that appears when the stage first
moves: on the stage-A look-alike swung by 90 % of its half-range before a 50 Hz sine record,
the ``pi-stage`` fit was 260 nm off its own record and lost to the static line on three held-out
records. The swing is one number, found in two steps once the fit from the virgin state is done:

1. **scan**: for each swing on a grid over the input's range about the rest (:data:`GRID`
   points, then :data:`REFINE` between the best's neighbours), the output is linear in the
   weights, the polynomial terms and the offset given L1 and L2: the play operators run from
   the swing's state on ``w1``, L2 filters each from its settled past, and one least-squares
   solve sets them;
2. **polish**: when the best swing lowers the RMS residual by more than :data:`GAIN` (a share)
   and is not an end of the input's range (a swing there stands in for something else),
   the output-error problem is solved again from there with the swing held, and kept when it
   stays lower.

On a record where the state at rest is not seen (measured stage A's records: the best swing
changes the residual by under 1 %) the virgin fit is kept as it was.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np
from scipy import linalg, signal

from ..pi import PISandwich, PIStructure
from ..pi_operator import play_operator, rest_plays

__all__ = ["GAIN", "GRID", "REFINE", "best_swing", "keeps_swing", "place_rest_swing",
           "scan_rest_swing"]

#: Swings on the first grid, over the input's range about the rest (a stage is driven inside
#: its range: on the helper's stage s3, resting at 2.5 V in a 0.7-9.5 V range, a scan of -7..7
#: V took -6.9 V, and a held-out record resting at 0 V went from 0.23 to 0.76 um).
GRID = 17
#: Swings between the best grid point's neighbours.
REFINE = 6
#: The swing is taken only when it lowers the RMS residual by more than this share.
GAIN = 0.1


class _Regressors:
    """The columns the output is linear in, for one swing: each play filtered by L2 from its
    settled past, the polynomial terms filtered by L2 (the same for every swing)."""

    def __init__(self, theta: np.ndarray, un: np.ndarray, r: np.ndarray,
                 structure: PIStructure) -> None:
        model = PISandwich(theta, r, structure)
        self.w1 = np.ascontiguousarray(model.simulate(un, check=False).w1)
        self.r = r
        self.num = np.r_[np.zeros(structure.q2), model.b2]
        self.den = np.r_[1.0, model.a2]
        self.zi = signal.lfilter_zi(self.num, self.den)
        powers = [self.w1 ** (j + 2) for j in range(structure.n_poly)]
        self.poly = [signal.lfilter(self.num, self.den, p) for p in powers]

    def columns(self, swing: float, relative: bool = False) -> np.ndarray:
        start = rest_plays(swing, self.r)
        plays = play_operator(self.w1, self.r, start)
        filtered, _ = signal.lfilter(self.num, self.den, plays, axis=0,
                                     zi=np.outer(self.zi, start))
        if relative:  # each column from its value at rest
            filtered -= start
        return np.column_stack([filtered, *self.poly])


def _solve(A: np.ndarray, target: np.ndarray, nuisance: np.ndarray,
           ridge: float) -> tuple[np.ndarray, np.ndarray, float]:
    """Weights (ridge on them) and nuisance coefficients by least squares; the RMS residual.

    Solved from the normal equations (a scan's many small solves: 3x faster than a QR of the
    tall matrix on 20 000 samples); the ridge keeps them well posed, and the swing found is
    polished by the output-error fit afterwards."""
    n = A.shape[1]
    M = np.column_stack([A, nuisance])
    G = M.T @ M
    G[np.arange(n), np.arange(n)] += ridge * len(A)
    coef = linalg.solve(G, M.T @ target, assume_a="pos", check_finite=False)
    resid = M @ coef - target
    return coef[:n], coef[n:], float(np.sqrt(np.mean(resid ** 2)))


def keeps_swing(rms: float, rms_virgin: float, at_bound: bool) -> bool:
    """The rule every fit keeps a swing by: it lowers the RMS residual by more than
    :data:`GAIN` of the virgin state's, and it is not an end of the input's range about the
    rest (a swing there stands in for something else).

    Parameters
    ----------
    rms, rms_virgin : float
        The RMS residual with the swing and from the virgin state.
    at_bound : bool
        Whether the swing is an end of the input's range.

    Returns
    -------
    bool
    """
    return not at_bound and rms < (1.0 - GAIN) * rms_virgin


def _range_about_rest(v: np.ndarray) -> tuple[float, float]:
    """The least and largest of ``v`` (input from the rest), the rest itself included."""
    return min(float(np.min(v, initial=0.0)), 0.0), max(float(np.max(v, initial=0.0)), 0.0)


def best_swing(rms_of: Callable[[float], float], low: float, high: float) -> float:
    """The swing of least ``rms_of(swing)``: a grid of :data:`GRID` over ``low..high``,
    then :data:`REFINE` points between the best one's neighbours.

    Parameters
    ----------
    rms_of : callable
        The RMS residual with a swing.
    low, high : float
        The input's range about the rest (``low <= 0 <= high``).

    Returns
    -------
    float
    """
    grid = np.linspace(low, high, GRID)
    scores = [rms_of(float(s)) for s in grid]
    i = int(np.argmin(scores))
    lo, hi = grid[max(i - 1, 0)], grid[min(i + 1, GRID - 1)]
    candidates = [(scores[i], float(grid[i]))]
    candidates += [(rms_of(float(s)), float(s)) for s in np.linspace(lo, hi, REFINE + 2)[1:-1]]
    return min(candidates)[1]


def place_rest_swing(model: PISandwich, u: np.ndarray, y: np.ndarray,
                     scored: np.ndarray) -> dict[str, float] | None:
    """Set a model's swing before its rest with its parameters held (a recursive fit's model:
    its estimate is what it is; the batch fit scans with the weights re-solved instead).

    Each swing's free run from rest is scored on the ``scored`` samples with the offset that
    fits them best; the best swing is kept when it lowers that RMS by more than :data:`GAIN`
    and is not an end of the input's range.

    Parameters
    ----------
    model : PISandwich
        The model (its ``rest_swing`` set in place).
    u, y : ndarray
        The record it was identified on.
    scored : ndarray of bool
        The samples the fit scores.

    Returns
    -------
    dict or None
        ``rest_swing`` (input units), ``before`` and ``after`` (RMS, offset refitted); None
        when no swing lowers the RMS enough.
    """
    held = model.rest_swing

    def rms_of(swing: float) -> float:
        model.rest_swing = swing
        with np.errstate(all="ignore"):
            e = (y - model.simulate(u, check=False).y)[scored]
        e = e - np.mean(e)
        r = float(np.sqrt(np.mean(e ** 2)))
        return r if np.isfinite(r) else np.inf

    before = rms_of(held)
    low, high = _range_about_rest(u[scored] - model.u_rest)
    swing = best_swing(rms_of, low, high)
    after = rms_of(swing)
    if not keeps_swing(after, before, swing in (low, high)):
        model.rest_swing = held
        return None
    model.rest_swing = swing
    return {"rest_swing": swing, "before": before, "after": after}


def scan_rest_swing(theta: np.ndarray, un: np.ndarray, yn: np.ndarray, rows: np.ndarray,
                    r: np.ndarray, structure: PIStructure, nuisance: np.ndarray,
                    ridge: float, relative: bool = False) -> dict[str, Any]:
    """The swing that fits the record best with L1 and L2 of ``theta`` held (step 1).

    Parameters
    ----------
    theta : ndarray
        A fit from the virgin state (normalised signals).
    un, yn : ndarray
        Normalised input (from the rest) and output.
    rows : ndarray
        The fitted samples.
    r : ndarray
        Thresholds (normalised input units).
    structure : PIStructure
        The structure of ``theta``.
    nuisance : ndarray
        The nuisance columns on ``rows`` (the offset, a drift).
    ridge : float
        The fit's ridge on the weights.
    relative : bool
        The output relative to its value at rest (each play's column less its state at rest),
        as the on-line identifier predicts it; the output's offset then is not a nuisance.

    Returns
    -------
    dict
        ``swing``, ``theta`` (its weights and polynomial terms set), ``nuisance`` (their
        coefficients), ``rms``, ``rms_virgin`` (the same solve at swing 0) and ``at_bound``
        (the swing is an end of the input's range: not determined by the record, not kept).
    """
    regs = _Regressors(theta, un, r, structure)
    target = yn[rows]

    def fit(swing: float) -> tuple[float, np.ndarray, np.ndarray]:
        w, nu, rms = _solve(regs.columns(swing, relative)[rows], target, nuisance, ridge)
        return rms, w, nu

    low, high = _range_about_rest(regs.w1[rows])
    swing = best_swing(lambda s: fit(s)[0], low, high)
    rms, w, nu = fit(swing)
    virgin = fit(0.0)[0]
    out = np.array(theta, dtype=float)
    sl = structure.slices()
    out[sl["mu"].start:sl["c"].stop] = w
    return {"swing": swing, "theta": out, "nuisance": nu, "rms": rms, "rms_virgin": virgin,
            "at_bound": swing in (low, high)}
