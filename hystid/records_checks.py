"""Gross faults of a record that the fit cannot see: warned about, never silently fitted.

Each check is robust (median absolute deviations, quantiles) and returns sentences for the
identification's warnings; none changes the data (the batch fits leave a burst's samples out of
their cost, :func:`burst_spans`):

* :func:`output_bursts` -- the output leaps away and back within a short stretch while the
  input moves smoothly (a sensor glitch, a loose connector);
* :func:`output_is_drift` -- the output is a straight line in time, whatever the input did
  (the sensor is not recording the stage, or the stage is not driven);
* :func:`one_rate` -- the input is one sine: at one rate the loop's width from the hysteresis
  and a phase lag of the linear blocks cannot be told apart (what a model does about it:
  :mod:`hystid.identify.rates`).
"""

from __future__ import annotations

import numpy as np

__all__ = ["BAND", "BURST_SIGMAS", "DRIFT_SHARE", "ONE_RATE_SHARE", "burst_spans", "one_rate",
           "one_rate_note", "output_bursts", "output_is_drift", "record_warnings"]

#: A leap of the output is this many robust standard deviations of its sample-to-sample steps.
BURST_SIGMAS = 20.0
#: The output is "only drift" when a straight line in time leaves less than this share of its
#: spread.
DRIFT_SHARE = 0.02
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


def _robust_sigma(x: np.ndarray) -> float:
    return 1.4826 * float(np.median(np.abs(x - np.median(x))))


def output_bursts(u: np.ndarray, y: np.ndarray, longest: float = 0.1,
                  quiet: np.ndarray | None = None) -> list[str]:
    """Stretches where the output leaps away and back while the input does not leap.

    Parameters
    ----------
    u, y : ndarray
        Input and output samples.
    longest : float
        Longest burst, as a share of the record.
    quiet : ndarray of bool, optional
        Samples where no burst is looked for (the stage's own transient after an input jump,
        which the fit leaves out: a lightly damped mode rings there).

    Returns
    -------
    list of str
        One sentence per burst found (at most three).
    """
    return [note for _, note in _bursts(u, y, longest, quiet)]


def burst_spans(u: np.ndarray, y: np.ndarray, longest: float = 0.1,
                quiet: np.ndarray | None = None) -> list[tuple[int, int]]:
    """The samples of each burst of :func:`output_bursts`, ``(first, stop)``.

    Parameters
    ----------
    u, y : ndarray
        Input and output samples.
    longest : float
        Longest burst, as a share of the record.
    quiet : ndarray of bool, optional
        Samples where no burst is looked for (see :func:`output_bursts`).

    Returns
    -------
    list of (int, int)
        The first sample away and the first sample back, per burst.
    """
    return [span for span, _ in _bursts(u, y, longest, quiet)]


def _bursts(u: np.ndarray, y: np.ndarray, longest: float,
            quiet: np.ndarray | None = None) -> list[tuple[tuple[int, int], str]]:
    if len(y) < 8:
        return []
    dy, du = np.diff(y), np.abs(np.diff(u))
    lo, hi = np.quantile(y, [0.02, 0.98])
    spread = max(float(hi - lo), 1e-300)
    limit = max(BURST_SIGMAS * _robust_sigma(dy), 0.2 * spread)
    u_slew = float(np.quantile(du, 0.999)) if len(du) else 0.0
    leaps = [k for k in np.flatnonzero(np.abs(dy) > limit)
             if du[max(k - 2, 0):k + 3].max(initial=0.0) <= 1.5 * u_slew
             and (quiet is None or not quiet[k + 1])]
    out = []
    closed = -1  # the leap back of the last burst: it and the leaps before it open none
    for i, k in enumerate(leaps):
        if k <= closed:
            continue
        back = [j for j in leaps[i + 1:] if j - k <= longest * len(y)
                and np.sign(dy[j]) == -np.sign(dy[k]) and abs(dy[j]) > 0.5 * abs(dy[k])]
        if back:
            j = closed = back[0]
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
        spread (both measured on the samples between its 1st and 99th percentiles, so that a
        few wild samples do not decide), else none.
    """
    y = np.asarray(y, dtype=float)
    k = np.arange(len(y), dtype=float)  # in samples: a line in any time unit is one in k
    seen = np.isfinite(y)
    if np.count_nonzero(seen) < 8:
        return []
    # the spread and the line from the 1st-99th percentiles: a few wild samples (a 1e6 um
    # spike) neither make a stage's output look flat nor hide a drift
    low, high = np.quantile(y[seen], [0.01, 0.99])
    inner = seen & (y >= low) & (y <= high)
    if np.count_nonzero(inner) < 8:
        return []
    coef = np.polyfit(k[inner], y[inner], 1)
    rest = y[inner] - np.polyval(coef, k[inner])
    spread = float(high - low)
    left = float(np.quantile(np.abs(rest), 0.98))
    if spread > 0 and left < DRIFT_SHARE * spread:
        per_second = coef[0] * (len(t) - 1) / (t[-1] - t[0]) if t[-1] > t[0] else coef[0]
        return [f"the output is a straight line in time ({per_second:.4g} per second) to within "
                f"{100 * left / spread:.2g} % of its range: it does not follow the input (is the "
                "sensor recording the stage?); the identified model is not trustworthy"]
    return []


def record_warnings(u: np.ndarray, y: np.ndarray, fs: float,
                    quiet: np.ndarray | None = None) -> list[str]:
    """Every check of this module on one record.

    Parameters
    ----------
    u, y : ndarray
        Input and output samples.
    fs : float
        Sampling rate in Hz.
    quiet : ndarray of bool, optional
        Samples where no burst is looked for (see :func:`output_bursts`).

    Returns
    -------
    list of str
    """
    return (rate_note(fs) + output_bursts(u, y, quiet=quiet)
            + output_is_drift(np.arange(len(y)) / fs, y))


#: Below this sampling rate [Hz] a record is said to be unlike a positioning stage's (their
#: records are sampled at 100 Hz to 100 kHz; a time column in milliseconds reads as 1000x less).
SLOWEST_RATE = 50.0


def rate_note(fs: float) -> list[str]:
    """Whether a sampling rate is implausibly slow for a positioning stage.

    Parameters
    ----------
    fs : float
        Sampling rate in Hz.

    Returns
    -------
    list of str
        One sentence below :data:`SLOWEST_RATE`, else none. A time column ``t`` in
        milliseconds (a 5 kHz record read as 5 Hz) was taken as seconds without a word.
    """
    if not fs < SLOWEST_RATE:
        return []
    return [f"the record is sampled at {fs:.4g} Hz, slower than a positioning stage's records "
            "(100 Hz to 100 kHz): if its time column is not in seconds (milliseconds read "
            "1000x slower), convert it to seconds"]


def one_rate(u: np.ndarray, fs: float) -> tuple[float, float] | None:
    """Whether an input runs at one rate: its fundamental and the share of its variance there.

    The samples given (pass the input after its leading rest), their mean removed and a Hann
    window applied: the share of their power within :data:`BAND` of the strongest frequency.

    Parameters
    ----------
    u : ndarray
        Input samples after the leading rest.
    fs : float
        Sampling rate in Hz.

    Returns
    -------
    tuple of float or None
        ``(f0, share)`` in Hz and as a fraction when the share is at least
        :data:`ONE_RATE_SHARE`; None otherwise (or for fewer than 16 samples).
    """
    x = np.asarray(u, dtype=float)
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
        Input samples after the leading rest.
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
