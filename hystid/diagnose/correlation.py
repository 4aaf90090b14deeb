"""Correlation tests of a model's residual: how much of it the input (and the residual's own
past) still explains, with the bounds of the whiteness and cross-correlation tests.

Used by the localisation (:mod:`hystid.diagnose.where`) and the screening of candidate
effects (:mod:`hystid.diagnose.screen`).
"""

from __future__ import annotations

from typing import Any

import numpy as np
from scipy import signal, stats

__all__ = ["correlation", "cross_correlation_test"]


def correlation(x: np.ndarray, e: np.ndarray | None, max_lag: int) -> np.ndarray:
    """Raw correlation sums ``c(k) = sum_i x(i) e(i + k)`` for ``k = 0..max_lag``.

    One FFT correlation (:func:`scipy.signal.correlate`) for every autocorrelation and
    cross-correlation of the diagnosis; ``e=None`` gives the autocorrelation of ``x``.

    Parameters
    ----------
    x, e : ndarray
        Equally long series (not demeaned here); ``e`` defaults to ``x``.
    max_lag : int
        Largest lag, in samples (at most ``len(x) - 1``).

    Returns
    -------
    ndarray
        ``max_lag + 1`` sums, lag 0 first.
    """
    x = np.asarray(x, float)
    e = x if e is None else np.asarray(e, float)
    full = signal.correlate(e, x, mode="full", method="fft")
    mid = len(x) - 1
    return full[mid: mid + max_lag + 1]


def _acf(x: np.ndarray, nlags: int) -> np.ndarray:
    ac = correlation(x - x.mean(), None, nlags)
    return ac / ac[0] if ac[0] > 0 else np.zeros(nlags + 1)


def cross_correlation_test(
    x: np.ndarray, e: np.ndarray, max_lag: int, *, level: float = 0.01
) -> dict[str, Any]:
    """Cross-correlation ``rho_xe(tau)``, ``tau = -max_lag..max_lag``, with a band valid for
    coloured signals.

    Under independence of ``x`` and ``e``, ``var rho_xe(tau) = (1/N) sum_k rho_xx(k) rho_ee(k)``
    (Bartlett); the sum runs over ``|k| < K`` with a triangular taper. The band is two-sided at
    ``level`` per lag, Bonferroni-corrected over the lags for the ``significant`` flag.

    Parameters
    ----------
    x, e : ndarray
        The two series, same length (an input and the error).
    max_lag : int
        Largest lag in samples.
    level : float
        Two-sided significance level per lag.

    Returns
    -------
    dict
        ``lags``, ``rho`` (arrays), ``band`` (per-lag half width), ``max_ratio`` (max |rho| /
        band), ``lag_at_max`` (samples, ``e`` after ``x`` when positive), ``fraction_outside``,
        ``significant``.
    """
    x = np.asarray(x, float) - np.mean(x)
    e = np.asarray(e, float) - np.mean(e)
    n = len(e)
    sx, se = np.sqrt(np.sum(x * x)), np.sqrt(np.sum(e * e))
    lags = np.arange(-max_lag, max_lag + 1)
    if sx == 0 or se == 0:
        return {"lags": lags, "rho": np.zeros(len(lags)), "band": 0.0, "max_ratio": 0.0,
                "lag_at_max": 0, "fraction_outside": 0.0, "significant": False}
    ahead, behind = correlation(x, e, max_lag), correlation(e, x, max_lag)
    # ahead[k] = sum_i x(i) e(i + k), behind[k] = sum_i x(i + k) e(i)
    rho = np.concatenate([behind[:0:-1], ahead]) / (sx * se)
    K = int(min(n // 4, max(10 * max_lag, 200)))
    rx, re = _acf(x, K), _acf(e, K)
    taper = 1.0 - np.arange(K + 1) / (K + 1)
    var = (1.0 + 2.0 * np.sum(taper[1:] * rx[1:] * re[1:])) / n
    sd = float(np.sqrt(max(var, 1.0 / n)))
    z = stats.norm.ppf(1 - level / 2)
    z_all = stats.norm.ppf(1 - level / (2 * len(lags)))
    ratio = np.abs(rho) / (z * sd)
    i = int(np.argmax(ratio))
    return {
        "lags": lags,
        "rho": rho,
        "band": float(z * sd),
        "max_ratio": float(ratio[i]),
        "lag_at_max": int(lags[i]),
        "fraction_outside": float(np.mean(ratio > 1)),
        "significant": bool(np.abs(rho[i]) > z_all * sd),
    }
