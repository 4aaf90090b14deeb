"""What one record says about rates: whether its input runs at one rate only, and how a model's
gain on a slow ramp compares with the record's.

Driven at one rate (a sine), a stage shows one loop. Its width can come from the hysteresis
(rate-independent) or from a phase lag of L1 or L2 (rate-dependent), and the record cannot tell
them apart: a model may fit it to the noise and be far off at any other rate or level.
Measured on the stage-B look-alike (:func:`hystid.testing.measured.stage_b_like`: Preisach
hysteresis, 200 Hz, a 1 Hz sine; one-off script), the Duhem sandwich fitted on one record was
5.6-44 um off records of 0.5 and 2 Hz, of another amplitude or mean level, where the static
line is 1.9-3.1 um off and ``pi-stage`` 0.16-1.5 um: its output moved by 0.6-1.1 times the
record's spread when the same input ran at twice the rate, ``pi-stage``'s by 0.015-0.03.

:func:`one_rate` finds such a record (the identification then warns); :func:`rate_dependence`
measures how much a model's output moves when the record's input runs at twice or half its
rate, which ``model="auto"`` uses on such a record to leave out a member whose loop is made by
its linear dynamics (:func:`hystid.identify.members.select_member`) and the identification
reports for the model it returns.
"""

from __future__ import annotations

from typing import Any

import numpy as np

__all__ = ["ONE_RATE_SHARE", "RATE_LIMIT", "one_rate", "one_rate_note", "rate_dependence",
           "rate_note"]

#: Share of the excited input's variance within the band of its strongest frequency from which
#: a record is driven at one rate: the rest carries less than 1 % of its RMS. A sine gives
#: 0.99999-1.0 (the stage-B look-alike, stage-A look-alike sines); measured stage A's records
#: 0.9970-0.9987 (a 5 Hz carrier, the PRBN, 50 Hz sine or triangle on it: 3.6-5.5 % of the
#: RMS), the measured piezo's 1 Hz sine 0.9993 (its distortion), a triangle 0.986 (its
#: harmonics), the paper's excitation and the Bouc-Wen multisine below 0.05. Only an input
#: that is one sine is caught.
ONE_RATE_SHARE = 0.9999
#: Half-width of the strongest frequency's band, relative to it (at least three bins).
BAND = 0.02
#: Largest :func:`rate_dependence` of a model taken as the record's own on a record at one rate.
#: Measured (one-off): ``pi-stage`` 0.015-0.03 on stage-B look-alike sines, the Duhem sandwich
#: 0.64-1.13 there; every member 0.07-0.18 on a stage-A look-alike 50 Hz sine (its 740 Hz mode
#: is felt at 100 Hz), below 0.07 on its 2 Hz sine.
RATE_LIMIT = 0.25


def one_rate(u: np.ndarray, fs: float) -> tuple[float, float] | None:
    """Whether an input runs at one rate: its fundamental and the share of its variance there.

    The input after its leading rest, its mean removed and a Hann window applied: the share of
    its power within :data:`BAND` of its strongest frequency.

    Parameters
    ----------
    u : ndarray
        Input samples.
    fs : float
        Sampling rate in Hz.

    Returns
    -------
    tuple of float or None
        ``(f0, share)`` in Hz and as a fraction when the share is at least
        :data:`ONE_RATE_SHARE`; None otherwise (or for fewer than 16 excited samples).
    """
    from .prepare import rest_level  # prepare warns with this module's note

    u = np.asarray(u, dtype=float)
    x = u[rest_level(u)[2]:] if len(u) else u
    if len(x) < 16 or not np.ptp(x) > 0:
        return None
    x = (x - np.mean(x)) * np.hanning(len(x))
    power = np.abs(np.fft.rfft(x)) ** 2
    power[0] = 0.0
    total = float(power.sum())
    if not total > 0:
        return None
    df = fs / len(x)
    f = np.arange(len(power)) * df
    k0 = int(np.argmax(power))
    f0 = f[k0]
    if f0 <= 0:
        return None
    near = np.abs(f - f0) <= max(BAND * f0, 3.0 * df)
    share = float(power[near].sum() / total)
    return (float(f0), share) if share >= ONE_RATE_SHARE else None


def one_rate_note(u: np.ndarray, fs: float) -> list[str]:
    """The identification's warning for an input at one rate (empty otherwise).

    Parameters
    ----------
    u : ndarray
        Input samples.
    fs : float
        Sampling rate in Hz.

    Returns
    -------
    list of str
        One sentence, or none.
    """
    found = one_rate(u, fs)
    if found is None:
        return []
    f0, share = found
    return [f"the input runs at one rate (a sine: {100 * share:.3f} % of its variance at "
            f"{f0:.4g} Hz): at one rate the loop's width from the hysteresis and a phase "
            "lag of L1 or L2 cannot be told apart, so the model may be far off at other rates "
            "or levels; validate it on another input, or identify on one with several rates "
            "(a multisine, PRBN, a chirp)"]


def rate_dependence(model: Any, u: np.ndarray, y: np.ndarray) -> float:
    """How much a model's output moves when the record's input runs at twice or half its rate.

    The model is simulated from rest on the input, on every second sample of it (twice the
    rate) and on it interpolated to twice as many samples (half the rate); each output is
    compared with the first at the same input samples, over the second half of the record (the
    first half lets the starts settle). The larger RMS difference, over the standard deviation
    of the record's output. A rate-independent loop between slow linear blocks gives nearly 0.

    Parameters
    ----------
    model : Sandwich
        Any member, placed.
    u, y : ndarray
        The record's input and output (the output's spread is the scale).

    Returns
    -------
    float
        The relative change; inf when a simulation is not finite or the output is constant.
    """
    from ..baselines import simulate_from_rest

    u = np.asarray(u, dtype=float)
    y = np.asarray(y, dtype=float)
    n = len(u)
    scale = float(np.std(y[np.isfinite(y)])) if np.isfinite(y).any() else 0.0
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


def rate_note(model: Any, u: np.ndarray, y: np.ndarray, fs: float) -> list[str]:
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

    Returns
    -------
    list of str
        One sentence, or none.
    """
    if one_rate(u, fs) is None:
        return []
    change = rate_dependence(model, u, y)
    if change <= RATE_LIMIT:
        return []
    return [f"the model's output moves by {change:.2g} times the record's spread when the same "
            "input runs at twice or half its rate: fitted at one rate, its loop is made by its "
            "linear blocks' lag, not by the hysteresis, and it will be off at other rates"]
