"""Gross faults of a record that the fit cannot see: warned about, never silently fitted.

Each check is robust (median absolute deviations, quantiles) and returns sentences for the
identification's warnings; none changes the data (the batch fits leave a burst's samples out of
their cost, :func:`burst_spans`):

* :func:`output_bursts` -- the output leaps away and back within a short stretch while the
  input moves smoothly (a sensor glitch, a loose connector);
* :func:`output_is_drift` -- the output is a straight line in time, whatever the input did
  (the sensor is not recording the stage, or the stage is not driven).
"""

from __future__ import annotations

import numpy as np

__all__ = ["BURST_SIGMAS", "DRIFT_SHARE", "burst_spans", "output_bursts", "output_is_drift",
           "record_warnings"]

#: A leap of the output is this many robust standard deviations of its sample-to-sample steps.
BURST_SIGMAS = 20.0
#: The output is "only drift" when a straight line in time leaves less than this share of its
#: spread.
DRIFT_SHARE = 0.02


def _robust_sigma(x: np.ndarray) -> float:
    return 1.4826 * float(np.median(np.abs(x - np.median(x))))


def output_bursts(u: np.ndarray, y: np.ndarray, longest: float = 0.1) -> list[str]:
    """Stretches where the output leaps away and back while the input does not leap.

    Parameters
    ----------
    u, y : ndarray
        Input and output samples.
    longest : float
        Longest burst, as a share of the record.

    Returns
    -------
    list of str
        One sentence per burst found (at most three).
    """
    return [note for _, note in _bursts(u, y, longest)]


def burst_spans(u: np.ndarray, y: np.ndarray, longest: float = 0.1) -> list[tuple[int, int]]:
    """The samples of each burst of :func:`output_bursts`, ``(first, stop)``.

    Parameters
    ----------
    u, y : ndarray
        Input and output samples.
    longest : float
        Longest burst, as a share of the record.

    Returns
    -------
    list of (int, int)
        The first sample away and the first sample back, per burst.
    """
    return [span for span, _ in _bursts(u, y, longest)]


def _bursts(u: np.ndarray, y: np.ndarray, longest: float) -> list[tuple[tuple[int, int], str]]:
    if len(y) < 8:
        return []
    dy, du = np.diff(y), np.abs(np.diff(u))
    lo, hi = np.quantile(y, [0.02, 0.98])
    spread = max(float(hi - lo), 1e-300)
    limit = max(BURST_SIGMAS * _robust_sigma(dy), 0.2 * spread)
    u_slew = float(np.quantile(du, 0.999)) if len(du) else 0.0
    leaps = [k for k in np.flatnonzero(np.abs(dy) > limit)
             if du[max(k - 2, 0):k + 3].max(initial=0.0) <= 1.5 * u_slew]
    out = []
    for i, k in enumerate(leaps):
        back = [j for j in leaps[i + 1:] if j - k <= longest * len(y)
                and np.sign(dy[j]) == -np.sign(dy[k]) and abs(dy[j]) > 0.5 * abs(dy[k])]
        if back:
            j = back[0]
            out.append(((k + 1, j + 1),
                        f"the output leaps by {dy[k]:+.4g} at sample {k + 1} and back by "
                        f"{dy[j]:+.4g} at sample {j + 1} ({j - k} samples) while the input "
                        "moves smoothly: a sensor glitch? the batch fits leave those samples "
                        "out (crop them, --crop, or clean the record)"))
        if len(out) == 3:
            break
    return out


def output_is_drift(t: np.ndarray, y: np.ndarray) -> list[str]:
    """Whether a straight line in time explains the output (a drift, not a stage).

    Parameters
    ----------
    t : ndarray
        Sample times.
    y : ndarray
        Output samples.

    Returns
    -------
    list of str
        One sentence when the line leaves less than :data:`DRIFT_SHARE` of the output's
        spread, else none.
    """
    if len(y) < 8:
        return []
    k = np.arange(len(y), dtype=float)  # in samples: a line in any time unit is one in k
    coef = np.polyfit(k, y, 1)
    rest = y - np.polyval(coef, k)
    spread = float(np.ptp(y))
    left = float(np.quantile(np.abs(rest), 0.98))
    if spread > 0 and left < DRIFT_SHARE * spread:
        per_second = coef[0] * (len(t) - 1) / (t[-1] - t[0]) if t[-1] > t[0] else coef[0]
        return [f"the output is a straight line in time ({per_second:.4g} per second) to within "
                f"{100 * left / spread:.2g} % of its range: it does not follow the input (is the "
                "sensor recording the stage?); the identified model is not trustworthy"]
    return []


def record_warnings(u: np.ndarray, y: np.ndarray, fs: float) -> list[str]:
    """Every check of this module on one record.

    Parameters
    ----------
    u, y : ndarray
        Input and output samples.
    fs : float
        Sampling rate in Hz.

    Returns
    -------
    list of str
    """
    return output_bursts(u, y) + output_is_drift(np.arange(len(y)) / fs, y)
