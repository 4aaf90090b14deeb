"""Where the simulation error lies: in time, frequency, operating zone and branch.

The error is the free-run simulation error ``e = y - yhat`` of a model on held-out data. Every
figure is stated against the noise floor, estimated from the data (:func:`noise_floor`). Bands of
the correlation tests are valid for coloured signals (Bartlett's formula for the variance of a
cross-correlation between two independent autocorrelated series); the coherence bound uses the
number of independent Welch segments.

:func:`localise` returns a :class:`Where`: JSON-ready figures (``to_dict()``) and the series used
by the figures (``series``).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
from scipy import signal, stats

from .correlation import correlation, cross_correlation_test

__all__ = [
    "Segment",
    "Where",
    "correlation",
    "cross_correlation_test",
    "harmonics",
    "input_period",
    "localise",
    "noise_floor",
    "noise_floor_of",
    "periodic_noise",
]


@dataclass
class Segment:
    """One stretch of held-out data with the model's simulation over it.

    Attributes
    ----------
    u, y : ndarray
        Input and measured output.
    yhat : ndarray
        Free-run simulated output.
    w1 : ndarray
        Simulated Duhem input (its sign of change tells the branch).
    fs : float
        Sampling rate in Hz.
    t0 : float
        Time of the first sample from the start of its record, in seconds.
    name : str
        Record name.
    """

    u: np.ndarray
    y: np.ndarray
    yhat: np.ndarray
    w1: np.ndarray
    fs: float
    t0: float = 0.0
    name: str = "held-out"

    @property
    def e(self) -> np.ndarray:
        """Simulation error ``y - yhat``."""
        return self.y - self.yhat

    @property
    def n(self) -> int:
        """Number of samples."""
        return len(self.y)


def _welch_nperseg(n: int) -> int:
    return int(min(8192, max(64, 2 ** int(np.floor(np.log2(max(n // 8, 64)))))))


def noise_floor(
    e: np.ndarray,
    fs: float,
    *,
    signals: list[np.ndarray] | None = None,
    lags: int = 8,
    quantile: float = 0.2,
) -> dict[str, float]:
    """White-noise floor of a residual from the quiet part of its spectrum.

    Sensor noise is white and sits under everything else; unmodelled dynamics only add power.
    The part of the residual that is a linear function of nearby samples of known ``signals``
    (for example the input and the simulated output: an input delay leaves such an error up to
    the Nyquist frequency) is first removed by least squares. The floor level is then a low
    quantile of the Welch spectrum over the upper 90 % of the band (the slow trend and the
    excitation band are left out), divided by the same quantile of the chi-square law of a
    Welch estimate so that a white residual gives its own variance back.

    Parameters
    ----------
    e : ndarray
        Residual samples.
    fs : float
        Sampling rate in Hz.
    signals : list of ndarray, optional
        Known signals (same length as ``e``) whose lagged samples ``-lags..lags`` explain part
        of the residual.
    lags : int
        Half width of the lag window.
    quantile : float
        Quantile of the spectrum taken as the floor.

    Returns
    -------
    dict
        ``rms`` (noise standard deviation), ``psd`` (one-sided level, units^2/Hz),
        ``band_hz`` (band used) and ``segments`` (independent Welch segments).
    """
    e = np.asarray(e, float)
    n = len(e)
    dof_scale = 1.0
    if signals:
        # the regression runs on the band where the floor is read (above 0.1 Nyquist)
        sos = signal.butter(6, 0.1, "highpass", output="sos")
        eh = signal.sosfiltfilt(sos, e)
        cols = []
        for x in signals:
            x = signal.sosfiltfilt(sos, np.asarray(x, float))
            xs = x / (np.std(x) or 1.0)
            cols += [np.roll(xs, j) for j in range(-lags, lags + 1)]
        A = np.column_stack(cols)[lags:n - lags]
        H = A.T @ A
        coef = np.linalg.solve(H + 1e-12 * np.trace(H) / len(H) * np.eye(len(H)),
                               A.T @ eh[lags:n - lags])
        e = eh[lags:n - lags] - A @ coef
        dof_scale = len(e) / max(len(e) - A.shape[1], 1)
    nper = _welch_nperseg(len(e))
    f, p = signal.welch(e - e.mean(), fs, nperseg=nper)
    band = (f >= 0.1 * fs / 2) & (f <= 0.98 * fs / 2)
    k_eff = max(2, len(e) // nper)
    # a Welch bin is ~ level * chi2(2K)/(2K) with about 2K_eff degrees of freedom (50 % overlap)
    dof = 2 * (2 * k_eff - 1)
    correction = stats.chi2.ppf(quantile, dof) / dof
    level = float(np.quantile(p[band], quantile) / correction * dof_scale)
    return {
        "rms": float(np.sqrt(level * fs / 2)),
        "psd": level,
        "band_hz": [float(f[band][0]), float(f[band][-1])],
        "segments": int(k_eff),
    }


def input_period(u: np.ndarray) -> int | None:
    """Period of ``u`` in samples when it repeats (relative mismatch below 1e-3), else None.

    The candidate period is the highest peak of the overlap-normalised autocorrelation after
    its first drop below zero; at least two periods must fit in the record.

    Parameters
    ----------
    u : ndarray
        Input samples.

    Returns
    -------
    int or None
        The period in samples.
    """
    u = np.asarray(u, float)
    n = len(u)
    if n < 64 or np.ptp(u) == 0:
        return None
    ac = correlation(u - u.mean(), None, n // 2 - 1)
    if ac[0] <= 0:
        return None
    ac = ac / (n - np.arange(len(ac)))
    neg = np.flatnonzero(ac < 0)
    if len(neg) == 0:
        return None
    lo = int(neg[0])
    if lo >= len(ac) - 1:
        return None
    period = lo + int(np.argmax(ac[lo:]))
    best = None
    span = max(2, period // 50)
    for p in range(max(2, period - span), min(n // 2, period + span + 1)):
        du = u[p:] - u[:-p]
        mismatch = float(np.sqrt(np.mean(du**2)))
        if best is None or mismatch < best[1]:
            best = (p, mismatch)
    if best is None or best[1] > 1e-3 * np.ptp(u):
        return None
    return best[0]


def periodic_noise(u: np.ndarray, y: np.ndarray, fs: float) -> dict[str, float] | None:
    """Noise from repeated periods: ``std(y(k + T) - y(k)) / sqrt(2)`` where ``u`` repeats.

    Returns ``None`` when the input does not repeat or holds fewer than two periods. The figure
    is an upper bound of the sensor noise: drift and any non-repeatable error add to it.

    Parameters
    ----------
    u, y : ndarray
        Input and measured output.
    fs : float
        Sampling rate in Hz.

    Returns
    -------
    dict or None
        The noise figure and the period it was measured over.
    """
    period = input_period(u)
    if period is None:
        return None
    dy = np.asarray(y, float)[period:] - np.asarray(y, float)[:-period]
    return {"rms": float(np.std(dy) / np.sqrt(2)), "period_s": float(period / fs)}


def harmonics(e: np.ndarray, period: int, fs: float, top: int = 5) -> dict:
    """Error at the harmonics of a periodic input: amplitudes over whole periods.

    Returns the fundamental ``f0_hz``, the ``top`` strongest harmonics ``[(k, f, amplitude)]``
    and the share of the error's mean square that lies at harmonics.

    Parameters
    ----------
    e : ndarray
        The error.
    period : int
        Period of the input in samples.
    fs : float
        Sampling rate in Hz.
    top : int
        Number of harmonics listed.

    Returns
    -------
    dict
        ``f0_hz``, ``top`` and the harmonic share of the mean square.
    """
    m = len(e) // period
    x = np.asarray(e[: m * period], float)
    spec = np.fft.rfft(x) / len(x)
    amp = 2 * np.abs(spec[m::m])
    power = float(np.sum(amp**2) / 2 + np.abs(spec[0]) ** 2)
    order = np.argsort(amp)[::-1][:top]
    return {
        "f0_hz": float(fs / period),
        "periods": int(m),
        "strongest": [[int(k + 1), float((k + 1) * fs / period), float(amp[k])] for k in order],
        "harmonic_fraction": float(power / max(np.mean(x**2), 1e-300)),
    }


# --------------------------------------------------------------------------- result
@dataclass
class Where:
    """Localisation of the simulation error.

    Attributes
    ----------
    noise : dict
        Noise floor (``rms``, ``method``...).
    rms : float
        RMS of the error.
    time, frequency, zone, branch, correlation : dict
        JSON-ready figures of each view.
    findings : list of str
        Readable one-line findings, most important first.
    series : dict
        Arrays for the figures (not part of the JSON).
    """

    noise: dict
    rms: float
    time: dict
    frequency: dict
    zone: dict
    branch: dict
    correlation: dict
    findings: list[str]
    series: dict = field(default_factory=dict, repr=False)

    @property
    def above_noise(self) -> float:
        """RMS error less the sensor-noise floor (the gap itself is measured to the higher of
        the noise and the repeatability floors, :func:`hystid.metrics.gap_closed`)."""
        return self.rms - self.noise["rms"]

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready figures.

        Returns
        -------
        dict
            The localisation's figures by name.
        """
        return {
            "rms": self.rms,
            "noise_floor_rms": self.noise["rms"],
            "above_noise": self.above_noise,
            "noise": self.noise,
            "time": self.time,
            "frequency": self.frequency,
            "zone": self.zone,
            "branch": self.branch,
            "correlation": self.correlation,
            "findings": list(self.findings),
        }


# --------------------------------------------------------------------------- views
def _rolling_rms(e: np.ndarray, w: int) -> np.ndarray:
    c = np.concatenate([[0.0], np.cumsum(e * e)])
    w = max(1, min(w, len(e)))
    r = (c[w:] - c[:-w]) / w
    pad = w // 2
    r = np.concatenate([np.full(pad, r[0]), r, np.full(len(e) - len(r) - pad, r[-1])])
    return np.sqrt(np.maximum(r, 0.0))


def _time_view(segs: list[Segment], noise: float) -> tuple[dict, dict]:
    fs = segs[0].fs
    e = np.concatenate([s.e for s in segs])
    t = np.concatenate([s.t0 + np.arange(s.n) / fs for s in segs])
    n = len(e)
    w = int(max(16, min(n // 50, round(0.02 * fs))))
    roll = _rolling_rms(e, w)
    # slow trend: quadratic in time over each segment, after the periodic part of the error
    # when the input repeats (a periodic error is no trend)
    e_ap = [_aperiodic(s.e, input_period(s.u)) for s in segs]
    trend = np.concatenate([_poly_trend(a, s.t0 + np.arange(s.n) / fs)
                            for a, s in zip(e_ap, segs, strict=True)])
    var_e = float(np.mean((e - e.mean()) ** 2)) + e.mean() ** 2
    excess = var_e - noise**2  # the shares below are of it: none when the error is all noise

    def share(power: float) -> float:
        return min(power / excess, 1.0) if excess > 0 else 0.0
    slope = np.polyfit(t, np.concatenate(e_ap), 1)[0] if n > 2 else 0.0
    # step-aligned averages: e after input steps, signed by the step direction
    u = np.concatenate([s.u for s in segs])
    du = np.diff(u, prepend=u[0])
    pre, post = 5, int(max(20, round(0.002 * fs)))
    adu = np.abs(du)
    thr = max(0.2 * adu.max(), 10.0 * np.median(adu)) if adu.max() > 0 else np.inf
    bounds = np.cumsum([0] + [s.n for s in segs])
    steps = []
    for a, b in zip(bounds[:-1], bounds[1:], strict=True):
        k = np.flatnonzero(adu[a + 1:b] > thr) + a + 1
        steps.extend(int(i) for i in k if i - pre >= a and i + post < b)
    step_avg = np.zeros(pre + post)
    step_ratio = 0.0
    peak_lag = 0
    if len(steps) >= 5:
        idx = np.asarray(steps)
        sign = np.sign(du[idx])
        win = idx[:, None] + np.arange(-pre, post)[None, :]
        step_avg = np.mean(sign[:, None] * e[win], axis=0)
        se = np.std(e) / np.sqrt(len(steps))
        step_ratio = float(np.sqrt(np.mean(step_avg[pre:] ** 2)) / se) if se > 0 else 0.0
        peak_lag = int(np.argmax(np.abs(step_avg[pre:])))
    lead = max(1, n // 10)
    early = float(np.sqrt(np.mean(e[:lead] ** 2)))
    view = {
        "rolling_window_s": w / fs,
        "rolling_rms_max": float(roll.max()),
        "rolling_rms_median": float(np.median(roll)),
        "time_of_max_s": float(t[int(np.argmax(roll))]),
        "first_tenth_rms": early,
        "mean": float(e.mean()),
        "mean_fraction": share(float(e.mean() ** 2)),
        "trend_rms": float(np.sqrt(np.mean(trend**2))),
        "trend_fraction": share(float(np.mean(trend**2))),
        "slope_per_s": float(slope),
        "steps": len(steps),
        "step_error_peak": float(np.max(np.abs(step_avg))) if len(steps) >= 5 else 0.0,
        "step_error_lag_samples": peak_lag,
        "step_error_ratio": step_ratio,
    }
    series = {"t": t, "e": e, "rolling_rms": roll, "trend": trend,
              "step_lags": np.arange(-pre, post), "step_avg": step_avg}
    return view, series


def _aperiodic(e: np.ndarray, period: int | None) -> np.ndarray:
    """``e`` less its average over the periods of a repeating input (unchanged otherwise)."""
    if period is None:
        return e
    m = -(-len(e) // period)
    pad = np.full(m * period, np.nan)
    pad[: len(e)] = e
    mean = np.nanmean(pad.reshape(m, period), axis=0)
    return e - np.tile(mean, m)[: len(e)]


def _poly_trend(e: np.ndarray, t: np.ndarray) -> np.ndarray:
    if len(e) < 4:
        return np.zeros_like(e)
    tt = (t - t.mean()) / max(np.ptp(t), 1e-12)
    return np.polyval(np.polyfit(tt, e, 2), tt)


def _frequency_view(segs: list[Segment], noise: dict) -> tuple[dict, dict]:
    fs = segs[0].fs
    n_min = min(s.n for s in segs)
    nper = _welch_nperseg(n_min)
    weights = np.array([s.n for s in segs], float)
    psd, coh_num, puu, pee = 0.0, 0.0, 0.0, 0.0
    k_eff = 0
    for s, wgt in zip(segs, weights / weights.sum(), strict=True):
        e = s.e - s.e.mean()
        f, p = signal.welch(e, fs, nperseg=nper)
        psd = psd + wgt * p
        _, pue = signal.csd(s.u - s.u.mean(), e, fs, nperseg=nper)
        _, pu = signal.welch(s.u - s.u.mean(), fs, nperseg=nper)
        coh_num = coh_num + wgt * pue
        puu = puu + wgt * pu
        pee = pee + wgt * p
        k_eff += max(1, s.n // nper)
    coh = np.abs(coh_num) ** 2 / np.maximum(puu * pee, 1e-300)
    level = noise["psd"]
    excess = np.maximum(psd - level, 0.0)
    df = f[1] - f[0]
    tot = excess.sum() * df
    if tot > 0:
        cum = np.cumsum(excess) / excess.sum()
        band = [float(f[np.searchsorted(cum, 0.1)]), float(f[min(np.searchsorted(cum, 0.9),
                                                                 len(f) - 1)])]
        peak = float(f[int(np.argmax(excess))])
    else:
        band, peak = [0.0, 0.0], 0.0
    # coherence bound at 1 % for K independent segments: 1 - 0.01^(1/(K-1))
    bound = float(1.0 - 0.01 ** (1.0 / max(k_eff - 1, 1)))
    above = coh > bound
    # excess peaks above the flexure band, as narrow-band candidates
    peaks = _spectral_peaks(f, psd, level)
    low = f <= max(10.0 * fs / sum(s.n for s in segs), 2 * df)
    periods = [input_period(s.u) for s in segs]
    harm = None
    if periods[0] is not None:
        harm = harmonics(segs[0].e, periods[0], fs)
    view = {
        "harmonics": harm,
        "welch_segment_s": nper / fs,
        "band_hz": band,
        "peak_hz": peak,
        "excess_power": float(tot),
        "low_frequency_fraction": float(excess[low].sum() * df / tot) if tot > 0 else 0.0,
        "peaks_hz": peaks,
        "coherence_bound": bound,
        "coherence_max": float(coh.max()),
        "coherence_max_hz": float(f[int(np.argmax(coh))]),
        "coherent_fraction": float(np.mean(above)),
    }
    series = {"f": f, "psd": psd, "noise_psd": level, "coherence": coh,
              "coherence_bound": bound}
    return view, series


def _spectral_peaks(f: np.ndarray, psd: np.ndarray, level: float, n: int = 3) -> list[float]:
    """Frequencies of the strongest local peaks standing well above their neighbourhood."""
    if len(psd) < 16:
        return []
    logp = np.log(np.maximum(psd, 1e-300))
    base = signal.medfilt(logp, 31 if len(psd) > 64 else 7)
    prom = logp - base
    idx, _ = signal.find_peaks(prom, height=np.log(4.0), distance=5)
    idx = [i for i in idx if psd[i] > 4 * level and f[i] > 0]
    idx = sorted(idx, key=lambda i: -(psd[i] - level))[:n]
    return [float(f[i]) for i in idx]


def _bins(x: np.ndarray, nbins: int) -> tuple[np.ndarray, np.ndarray]:
    edges = np.unique(np.quantile(x, np.linspace(0, 1, nbins + 1)))
    if len(edges) < 2:
        return np.zeros(len(x), int), edges
    return np.clip(np.searchsorted(edges, x, side="right") - 1, 0, len(edges) - 2), edges


def _zone_view(segs: list[Segment]) -> tuple[dict, dict]:
    e = np.concatenate([s.e for s in segs])
    u = np.concatenate([s.u for s in segs])
    y = np.concatenate([s.y for s in segs])
    du = np.abs(np.concatenate([np.diff(s.u, prepend=s.u[0]) for s in segs]))
    out, series = {}, {}
    for label, x, nb in (("u_level", u, 6), ("y_level", y, 6), ("u_rate", du, 4)):
        b, edges = _bins(x, nb)
        rms = [float(np.sqrt(np.mean(e[b == i] ** 2))) if np.any(b == i) else 0.0
               for i in range(len(edges) - 1)]
        mean = [float(np.mean(e[b == i])) if np.any(b == i) else 0.0
                for i in range(len(edges) - 1)]
        out[label] = {"edges": [float(v) for v in edges], "rms": rms, "mean": mean}
        series[label] = (edges, np.array(rms), np.array(mean))
    total = float(np.sqrt(np.mean(e**2)))
    worst = max(out, key=lambda k: max(out[k]["rms"]) / max(total, 1e-300))
    i = int(np.argmax(out[worst]["rms"]))
    out["worst"] = {"by": worst, "bin": [out[worst]["edges"][i], out[worst]["edges"][i + 1]],
                    "rms_ratio": float(out[worst]["rms"][i] / max(total, 1e-300))}
    return out, series


#: Samples after an input reversal count as "after a turning point" until the input has
#: travelled this share of its range.
TURNING_TRAVEL = 0.1


def _after_turning_points(segs: list[Segment], noise: float) -> dict[str, float]:
    """How the error after the input's turning points compares with the rest.

    After each reversal of the input, the samples until it has travelled
    :data:`TURNING_TRAVEL` of its range: their share of the samples, their RMS error over the
    other samples' and their share of the excess error power (above the noise).
    """
    from ..thresholds import turning_points

    near, e_all = [], []
    for s in segs:
        mask = np.zeros(s.n, bool)
        span = float(np.ptp(s.u)) or 1.0
        travel = np.cumsum(np.abs(np.diff(s.u, prepend=s.u[0])))
        for k in turning_points(s.u)[1:-1]:
            stop = int(np.searchsorted(travel, travel[k] + TURNING_TRAVEL * span))
            mask[k:max(stop, k + 1)] = True
        near.append(mask)
        e_all.append(s.e)
    m, e = np.concatenate(near), np.concatenate(e_all)
    if not m.any() or m.all():
        return {"share_samples": float(m.mean()), "rms_ratio": float("nan"),
                "excess_share": float("nan")}
    p_near, p_rest = float(np.mean(e[m] ** 2)), float(np.mean(e[~m] ** 2))
    excess = max(float(np.mean(e**2)) - noise**2, 1e-300)
    return {"share_samples": float(m.mean()),
            "rms_ratio": float(np.sqrt(p_near / max(p_rest, 1e-300))),
            "excess_share": float(max(p_near - noise**2, 0.0) * m.mean() / excess)}


def _branch_view(segs: list[Segment], noise: float) -> tuple[dict, dict]:
    e = np.concatenate([s.e for s in segs])
    y = np.concatenate([s.yhat for s in segs])
    dw = np.concatenate([np.diff(s.w1, prepend=s.w1[0]) for s in segs])
    up, down = dw > 0, dw < 0
    b, edges = _bins(y, 8)
    nb = len(edges) - 1
    asc = np.full(nb, np.nan)
    desc = np.full(nb, np.nan)
    for i in range(nb):
        if np.sum((b == i) & up) >= 10:
            asc[i] = np.mean(e[(b == i) & up])
        if np.sum((b == i) & down) >= 10:
            desc[i] = np.mean(e[(b == i) & down])
    ok = np.isfinite(asc) & np.isfinite(desc)
    common = np.where(ok, 0.5 * (asc + desc), np.nan)
    width = np.where(ok, 0.5 * (asc - desc), np.nan)
    # per-sample decomposition: branch mean error per bin and direction
    comp_c = np.zeros_like(e)
    comp_w = np.zeros_like(e)
    for i in np.flatnonzero(ok):
        m = b == i
        comp_c[m] = common[i]
        comp_w[m & up] = width[i]
        comp_w[m & down] = -width[i]
    # shares of the error power above the noise floor: none when there is none (the branch
    # means carry noise too, so their powers may add up to more than a small excess)
    excess = float(np.mean(e**2)) - noise**2
    parts = float(np.mean(comp_w**2) + np.mean(comp_c**2))
    share = max(excess, parts) if excess > 0 else np.inf
    view = {
        "y_edges": [float(v) for v in edges],
        "ascending_mean": [None if not np.isfinite(v) else float(v) for v in asc],
        "descending_mean": [None if not np.isfinite(v) else float(v) for v in desc],
        "common_rms": float(np.sqrt(np.mean(comp_c**2))),
        "width_rms": float(np.sqrt(np.mean(comp_w**2))),
        "width_fraction": float(np.mean(comp_w**2) / share),
        "common_fraction": float(np.mean(comp_c**2) / share),
        "turning": _after_turning_points(segs, noise),
    }
    series = {"edges": edges, "ascending": asc, "descending": desc,
              "y": y, "e": e, "up": up}
    return view, series


def _correlation_view(segs: list[Segment]) -> tuple[dict, dict]:
    fs = segs[0].fs
    max_lag = int(min(min(s.n for s in segs) // 20, max(50, round(0.005 * fs))))
    out, series = {}, {}
    e = np.concatenate([s.e - s.e.mean() for s in segs])
    u = np.concatenate([s.u for s in segs])
    du = np.concatenate([np.diff(s.u, prepend=s.u[0]) for s in segs])
    u2 = (u - u.mean()) ** 2
    tests = {
        "u_e": (u, e),          # linear: input-residual cross-correlation
        "u2_e": (u2, e),        # nonlinear (Billings-Voon): squared input vs residual
        "u2_e2": (u2, e * e),   # nonlinear: squared input vs squared residual
        "du_e": (du, e),        # dynamics: input increments vs residual
        "absdu_e": (np.abs(du), e),  # rate / direction effects
    }
    for name, (x, r) in tests.items():
        res = cross_correlation_test(x, r, max_lag)
        series[name] = res
        out[name] = {k: v for k, v in res.items() if k not in ("lags", "rho")}
    return out, series


# --------------------------------------------------------------------------- driver
def localise(segments: list[Segment], noise: dict | None = None) -> Where:
    """Localise the simulation error of held-out segments.

    Parameters
    ----------
    segments : list of Segment
        Held-out data with the model's free-run simulation (same sampling rate).
    noise : dict, optional
        Noise floor from :func:`noise_floor`; estimated from the segments' residual when
        omitted (the periodic estimate is added when the input repeats).

    Returns
    -------
    Where
        Figures per view and readable findings.
    """
    if not segments:
        raise ValueError("segments: expected at least one held-out segment")
    fs = segments[0].fs
    e = np.concatenate([s.e for s in segments])
    if noise is None:
        noise = noise_floor_of(segments)
    rms = float(np.sqrt(np.mean(e**2)))
    tv, ts = _time_view(segments, noise["rms"])
    fv, fser = _frequency_view(segments, noise)
    zv, zs = _zone_view(segments)
    bv, bs = _branch_view(segments, noise["rms"])
    cv, cs = _correlation_view(segments)
    w = Where(noise, rms, tv, fv, zv, bv, cv, [],
              {"time": ts, "frequency": fser, "zone": zs, "branch": bs, "correlation": cs,
               "fs": fs})
    w.findings = _findings(w)
    return w


def noise_floor_of(segments: list[Segment]) -> dict:
    """Noise floor of the segments' residual (:func:`noise_floor`), with the repeated-period
    figure added when the input repeats.

    Parameters
    ----------
    segments : list of Segment
        The record's segments with their residuals.

    Returns
    -------
    dict
        The noise-floor figures.
    """
    fs = segments[0].fs
    parts = []
    for s in segments:
        plain = noise_floor(s.e, fs)
        cleaned = noise_floor(s.e, fs, signals=[s.u, s.yhat])
        parts.append(min(plain, cleaned, key=lambda p: p["psd"]))
    w = np.array([s.n for s in segments], float)
    level = float(np.sum(w * [p["psd"] for p in parts]) / w.sum())
    noise = {"rms": float(np.sqrt(level * fs / 2)), "psd": level,
             "method": "high-frequency residual: low quantile of its spectrum, as it is or "
                       "after removing what lagged input and simulated output explain (lower "
                       "of the two)",
             "band_hz": parts[0]["band_hz"]}
    per = [periodic_noise(s.u, s.y, fs) for s in segments]
    per = [p for p in per if p is not None]
    if per:
        noise["repeated_periods_rms"] = float(np.mean([p["rms"] for p in per]))
        noise["period_s"] = per[0]["period_s"]
        if noise["repeated_periods_rms"] < noise["rms"]:
            # an upper bound of the noise below the spectral level: the model's error fills the
            # upper band (harmonics of a slow periodic input at a low sampling rate: 0.048 um
            # read there on the stage-B look-alike, whose noise is 0.02 um; the periods 0.0195)
            noise["spectral_rms"] = noise["rms"]
            noise["rms"] = noise["repeated_periods_rms"]
            noise["psd"] = noise["rms"] ** 2 * 2.0 / fs
            noise["method"] = ("repeated periods of the input: std(y(k + T) - y(k)) / sqrt(2), "
                               "below the high-frequency residual's level, which the model's "
                               "error fills")
    return noise


def _findings(w: Where) -> list[str]:
    out: list[tuple[float, str]] = []
    nf = w.noise["rms"]
    above = w.above_noise
    out.append((1e9, f"held-out RMS error {w.rms:.4g} against a sensor-noise floor of {nf:.4g} "
                     f"({above:.3g} above it, {100 * above / max(w.rms, 1e-300):.0f} % of the "
                     "error)"))
    if w.rms < 1.05 * nf:
        out.append((1e8, "the error is at the noise floor: nothing to localise"))
        return [s for _, s in sorted(out, key=lambda x: -x[0])]
    t = w.time
    if t["mean_fraction"] > 0.2:
        out.append((t["mean_fraction"],
                    f"a constant offset ({t['mean']:.3g}) carries {100 * t['mean_fraction']:.0f} % "
                    f"of the excess error"))
    if t["trend_fraction"] > 0.2:
        out.append((t["trend_fraction"],
                    f"slow trend carries {100 * t['trend_fraction']:.0f} % of the excess error "
                    f"(slope {t['slope_per_s']:.3g} per s)"))
    if t["step_error_ratio"] > 4:
        out.append((0.5 + 0.01 * t["step_error_ratio"],
                    f"error follows input steps: peak {t['step_error_peak']:.3g} at "
                    f"{t['step_error_lag_samples']} samples after the step "
                    f"({t['step_error_ratio']:.0f}x its standard error)"))
    f = w.frequency
    if f.get("harmonics"):
        h = f["harmonics"]
        top = ", ".join(f"{k} x {h['f0_hz']:.3g} Hz ({a:.3g})" for k, _, a in h["strongest"][:3])
        out.append((0.45, f"the input repeats every {1 / h['f0_hz']:.4g} s: "
                          f"{100 * h['harmonic_fraction']:.0f} % of the error is periodic; "
                          f"strongest harmonics {top}"))
    out.append((0.4, f"excess error power lies in {f['band_hz'][0]:.4g}-{f['band_hz'][1]:.4g} Hz"
                     f" (peak {f['peak_hz']:.4g} Hz)"))
    if f["peaks_hz"]:
        out.append((0.3, "narrow-band excess at " + ", ".join(f"{p:.4g} Hz"
                                                             for p in f["peaks_hz"])))
    if f["coherent_fraction"] > 0.05:
        out.append((0.35, f"residual coherent with the input over "
                          f"{100 * f['coherent_fraction']:.0f} % of the band (max "
                          f"{f['coherence_max']:.2f} at {f['coherence_max_hz']:.4g} Hz)"))
    b = w.branch
    if b["width_fraction"] > 0.1:
        out.append((b["width_fraction"],
                    f"branches differ: loop-width error carries {100 * b['width_fraction']:.0f} %"
                    f" of the excess error (common part {100 * b['common_fraction']:.0f} %)"))
    z = w.zone["worst"]
    if z["rms_ratio"] > 1.5:
        out.append((0.2, f"worst operating zone: {z['by']} in [{z['bin'][0]:.3g}, "
                         f"{z['bin'][1]:.3g}] ({z['rms_ratio']:.1f}x the overall RMS)"))
    sig = [k for k, v in w.correlation.items() if v["significant"]]
    if sig:
        out.append((0.25, "significant correlation tests (coloured-signal bands): "
                          + ", ".join(sig)))
    return [s for _, s in sorted(out, key=lambda x: -x[0])]
