"""What one record says about rates: whether its input runs at one rate only, and how much a
model's output moves when that input runs faster or slower.

Driven at one rate (a sine), a stage shows one loop. Its width can come from the hysteresis
(rate-independent) or from a phase lag of L1 or L2 (rate-dependent), and the record cannot tell
them apart: a model may fit it to the noise and be far off at any other rate or level.
Measured on the stage-B look-alike (:func:`hystid.testing.measured.stage_b_like`: Preisach
hysteresis, 200 Hz, a 1 Hz sine; one-off script), the Duhem sandwich fitted on one record was
5.6-44 um off records of 0.5 and 2 Hz, of another amplitude or mean level, where the static
line is 1.9-3.1 um off and ``pi-stage`` 0.16-1.5 um: its output moved by 0.6-1.1 times the
record's spread when the same input ran at twice the rate, ``pi-stage``'s by 0.015-0.03.

:func:`hystid.records_checks.one_rate` finds such a record (the identification then warns);
:func:`rate_dependence`
measures how much a model's output moves when the record's input runs at twice or half its
rate, which ``model="auto"`` uses on such a record to leave out a member whose loop is made by
its linear dynamics (:func:`hystid.identify.members.select_member`) and the identification
reports for the model it returns.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from ..records_checks import one_rate

__all__ = ["RATE_LIMIT", "rate_dependence", "rate_note", "runs_at_one_rate"]

#: Largest :func:`rate_dependence` of a model taken as the record's own on a record at one rate.
#: Measured (one-off): ``pi-stage`` 0.015-0.03 on stage-B look-alike sines, the Duhem sandwich
#: 0.64-1.13 there; every member 0.07-0.18 on a stage-A look-alike 50 Hz sine (its 740 Hz mode
#: is felt at 100 Hz), below 0.07 on its 2 Hz sine.
RATE_LIMIT = 0.25


def runs_at_one_rate(u: np.ndarray, fs: float) -> bool:
    """Whether a record's input, after its leading rest, is one sine
    (:func:`hystid.records_checks.one_rate`).

    Parameters
    ----------
    u : ndarray
        Input samples.
    fs : float
        Sampling rate in Hz.

    Returns
    -------
    bool
    """
    from .prepare import rest_level

    u = np.asarray(u, dtype=float)
    return len(u) > 0 and one_rate(u[rest_level(u)[2]:], fs) is not None


def rate_dependence(model: Any, u: np.ndarray, y: np.ndarray) -> float:
    """How much a model's output moves when the record's input runs at twice or half its rate.

    The model is simulated from rest on the input, on every second sample of it (twice the
    rate) and on it interpolated to twice as many samples (half the rate); each output is
    compared with the first at the same input samples, over the second half of the record (the
    first half lets the starts settle). The larger RMS difference, over the record output's
    spread: the distance between its 1st and 99th percentiles over ``2 sqrt(2)`` (a sine's
    standard deviation, which one outlier of the output does not move). A rate-independent loop
    between slow linear blocks gives nearly 0.

    Parameters
    ----------
    model : Sandwich
        Any member, placed.
    u, y : ndarray
        The record's input and output (the output's spread is the scale).

    Returns
    -------
    float
        The relative change; inf when a simulation is not finite or the output does not
        spread.
    """
    from ..baselines import simulate_from_rest

    u = np.asarray(u, dtype=float)
    y = np.asarray(y, dtype=float)
    n = len(u)
    seen = y[np.isfinite(y)]
    scale = float(np.subtract(*np.percentile(seen, [99, 1])) / (2 * np.sqrt(2))) if seen.size \
        else 0.0
    if n < 8 or not scale > 0:
        return float("inf")
    half = n // 2
    with np.errstate(all="ignore"):
        base = simulate_from_rest(model, u, check=False)
        fast = simulate_from_rest(model, u[::2], check=False)
        slow = simulate_from_rest(model, np.interp(np.arange(2 * n - 1) / 2.0, np.arange(n), u),
                                  check=False)
        d_fast = np.sqrt(np.mean((fast[half // 2:] - base[::2][half // 2:]) ** 2))
        d_slow = np.sqrt(np.mean((slow[::2][half:] - base[half:]) ** 2))
    worst = max(float(d_fast), float(d_slow)) / scale
    return worst if np.isfinite(worst) else float("inf")


def rate_note(model: Any, u: np.ndarray, y: np.ndarray, fs: float,
              change: float | None = None) -> list[str]:
    """On a record at one rate, what :func:`rate_dependence` says of a model when it exceeds
    :data:`RATE_LIMIT` (empty otherwise, and on any other record).

    Parameters
    ----------
    model : Sandwich
        The identified model.
    u, y : ndarray
        The record's input and output.
    fs : float
        Sampling rate in Hz.
    change : float, optional
        The model's :func:`rate_dependence` on this record when already measured (the
        member choice measures the model it returns).

    Returns
    -------
    list of str
        One sentence, or none.
    """
    if not runs_at_one_rate(u, fs):
        return []
    if change is None:
        change = rate_dependence(model, u, y)
    if change <= RATE_LIMIT:
        return []
    return [f"the model's output moves by {change:.2g} times the record's spread when the same "
            "input runs at twice or half its rate: fitted at one rate, its loop is made by its "
            "linear blocks' lag, not by the hysteresis, and it will be off at other rates"]
