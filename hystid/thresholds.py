"""Where a Prandtl-Ishlinskii operator's play thresholds go.

A play operator of threshold ``r`` moves only where its input travels more than ``2 r`` between
two reversals. A threshold wider than every reversal of the identification input never moves
both ways: its weight is not identified, and it acts as an offset that depends on the voltage a
record starts from (on stage A, thresholds over the input's half range cost 134-326 nm on other
records). Two rules:

* :func:`pi_thresholds` -- the paper's, ``r_i = i/N (max - min)/2``: the whole input range;
* :func:`swing_thresholds` -- ``r_i = i/N s``, ``s`` the largest half swing between two
  consecutive turning points of the input (:func:`largest_half_swing`): every operator is
  reversed at least once by the identification input. The default of the PI fits.

Both depend only on differences of the input: an input offset does not move them, and a change
of units scales them.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from .signals import finite_signal

__all__ = ["RULES", "largest_half_swing", "pi_thresholds", "swing_thresholds", "turning_points"]


def _check_count(n_operators: int) -> int:
    if isinstance(n_operators, bool) or int(n_operators) != n_operators or n_operators < 1:
        raise ValueError(f"n_operators: expected a positive integer, got {n_operators!r}")
    return int(n_operators)


def pi_thresholds(
    u: np.ndarray | Sequence[float] | tuple[float, float], n_operators: int = 40
) -> np.ndarray:
    """Thresholds of the play operators from an input range (the paper's rule).

    The rule: ``r_i = i / N * (max(u) - min(u)) / 2`` for ``i = 0 .. N-1``. The first operator
    (``r_0 = 0``) is the identity, the last one still moves on an input swinging over the whole
    range. With the PI sandwich's unit-DC-gain ``L1`` the input range is the range of ``w1`` in
    steady state.

    Parameters
    ----------
    u : array_like
        Input samples, or a ``(min, max)`` pair.
    n_operators : int
        Number of play operators ``N`` (40 in the paper).

    Returns
    -------
    ndarray
        ``N`` thresholds, strictly increasing from 0.
    """
    n = _check_count(n_operators)
    u = finite_signal(np.ravel(u), "u (input samples or a (min, max) pair)", min_size=1)
    span = float(u.max() - u.min())
    if not span > 0:
        raise ValueError(f"u: the input range is empty (min = max = {u.min():g})")
    return np.arange(n) / n * span / 2.0


def turning_points(u: np.ndarray | Sequence[float]) -> np.ndarray:
    """Indices of the first sample, every reversal of direction and the last sample.

    Flat stretches do not reverse: the direction is that of the last non-zero step.

    Parameters
    ----------
    u : array_like
        A signal.

    Returns
    -------
    ndarray of int
        Increasing indices, the first ``0`` and the last ``len(u) - 1``.
    """
    u = finite_signal(np.ravel(u), "u", min_size=1)
    step = np.sign(np.diff(u))
    moving = np.flatnonzero(step)
    reversals = moving[1:][np.diff(step[moving]) != 0]  # first step of a new direction
    return np.unique(np.r_[0, reversals, len(u) - 1])


def largest_half_swing(u: np.ndarray | Sequence[float]) -> float:
    """Half the largest travel of a signal between two consecutive turning points.

    Parameters
    ----------
    u : array_like
        A signal (at least two samples).

    Returns
    -------
    float
        ``max_j |u(t_{j+1}) - u(t_j)| / 2`` over the :func:`turning_points` ``t_j``.
    """
    u = finite_signal(np.ravel(u), "u", min_size=2)
    return float(np.max(np.abs(np.diff(u[turning_points(u)])))) / 2.0


def swing_thresholds(u: np.ndarray | Sequence[float], n_operators: int = 20) -> np.ndarray:
    """Thresholds that the input reverses: ``r_i = i / N * largest_half_swing(u)``.

    Parameters
    ----------
    u : array_like
        The identification input (the samples fitted: leave out a wrapped last sample).
    n_operators : int
        Number of play operators ``N``.

    Returns
    -------
    ndarray
        ``N`` thresholds, strictly increasing from 0.

    Raises
    ------
    ValueError
        When the input does not move.
    """
    n = _check_count(n_operators)
    s = largest_half_swing(u)
    if not s > 0:
        raise ValueError("u: the input does not move (no swing to place thresholds in)")
    return np.arange(n) / n * s


#: The threshold rules by name (``thresholds=`` of the PI fits).
RULES = {"range": pi_thresholds, "swing": swing_thresholds}
