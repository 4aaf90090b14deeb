"""Scan references and tracking figures: maximum and RMS error, hysteresis loop width left."""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import asdict, dataclass

import numpy as np

from ..signals import finite_signal

__all__ = ["ScanReference", "TrackingMetrics", "scan_reference", "tracking_metrics"]

#: Most samples :func:`scan_reference` makes (400 MB a signal): a longer scan is refused
#: before anything is allocated.
MAX_SCAN_SAMPLES = 50_000_000


@dataclass
class ScanReference:
    """A scan reference that starts at rest. Unpacks as ``t, y``.

    Attributes
    ----------
    t, y : ndarray
        Time (s) and desired output.
    skip : int
        Samples to leave out of the tracking figures: the rest, the lead-in and the first
        period (the hysteresis starts on its virgin curve).
    kind : str
        ``"triangle"`` or ``"sine"``.
    frequency : float
        Scan frequency in Hz.
    """

    t: np.ndarray
    y: np.ndarray
    skip: int
    kind: str
    frequency: float

    def __iter__(self) -> Iterator[np.ndarray]:
        yield self.t
        yield self.y


def scan_reference(
    kind: str,
    frequency: float,
    *,
    fs: float = 30_000.0,
    periods: float = 2.0,
    low: float = 1.0,
    high: float = 8.0,
    lead_in: float = 0.01,
    rest: float = 0.002,
) -> ScanReference:
    """A triangle or sine scan between ``low`` and ``high``, reached from rest.

    The output stays at 0 for ``rest`` seconds (so that a look-ahead smoother of the reference
    still starts at rest), rises from 0 to ``low`` along a raised cosine over ``lead_in``
    seconds (a stage at rest cannot follow a jump), then scans ``periods`` periods starting
    upwards from ``low``. The defaults cover most of the reference stage's stroke (about 0.5-8.5 um
    with the 0-10 V amplifier).

    Parameters
    ----------
    kind : {"triangle", "sine"}
        Waveform.
    frequency : float
        Scan frequency in Hz.
    fs : float
        Sampling rate in Hz.
    periods : float
        Number of scan periods after the lead-in.
    low, high : float
        Range of the scan in output units (um).
    lead_in : float
        Seconds of the approach from rest.
    rest : float
        Seconds at 0 before the approach.

    Returns
    -------
    ScanReference
        Time, desired output and the samples to skip in the tracking figures.

    Raises
    ------
    ValueError
        For a kind, frequency, rate, duration or range it cannot scan, or a scan of more than
        :data:`MAX_SCAN_SAMPLES` samples.
    """
    if kind not in ("triangle", "sine"):
        raise ValueError(f"kind: expected 'triangle' or 'sine', got {kind!r}")
    for name, value in (("frequency", frequency), ("fs", fs), ("periods", periods)):
        if not (np.isfinite(value) and value > 0):
            raise ValueError(f"{name}: expected a positive number, got {value!r}")
    if not (np.isfinite(low) and np.isfinite(high) and low < high):
        raise ValueError(f"low, high: expected low < high, got {low!r}, {high!r}")
    for name, value in (("lead_in", lead_in), ("rest", rest)):
        if not (np.isfinite(value) and value >= 0):
            raise ValueError(f"{name}: expected a non-negative duration, got {value!r}")
    n_rest = int(round(rest * fs))
    n_lead = int(round(lead_in * fs))
    n_scan = int(round(periods * fs / frequency))
    if n_rest + n_lead + n_scan > MAX_SCAN_SAMPLES:
        raise ValueError(f"periods: {periods:g} periods at {frequency:g} Hz and {fs:g} Hz make "
                         f"{n_rest + n_lead + n_scan:,} samples (expected at most "
                         f"{MAX_SCAN_SAMPLES:,})")
    ramp = 0.5 - 0.5 * np.cos(np.pi * np.arange(n_lead) / max(n_lead, 1))
    phase = (np.arange(n_scan) * frequency / fs) % 1.0
    if kind == "triangle":
        shape = 1.0 - np.abs(2.0 * phase - 1.0)
    else:
        shape = 0.5 - 0.5 * np.cos(2.0 * np.pi * phase)
    y = np.concatenate([np.zeros(n_rest), low * ramp, low + (high - low) * shape])
    skip = n_rest + n_lead + int(round(fs / frequency))
    return ScanReference(np.arange(len(y)) / fs, y, skip, kind, float(frequency))


@dataclass
class TrackingMetrics:
    """Tracking figures. Unpacks as ``max_error, rms_error, loop_width``.

    Attributes
    ----------
    max_error, rms_error : float
        Largest absolute and RMS value of ``y - y_ref`` (output units).
    loop_width : float
        Largest distance between the rising and the falling branch of ``y - y_ref`` plotted
        against ``y_ref`` (the hysteresis loop left, plus any phase lag); NaN when the
        reference does not both rise and fall over a common range.
    samples : int
        Samples the figures are computed on.
    unit : str
        The output's unit (the reference stage's um by default); ``str()`` shows the figures
        in it, or in nm when it is um.
    """

    max_error: float
    rms_error: float
    loop_width: float
    samples: int
    unit: str = "um"

    def __str__(self) -> str:
        scale, unit = (1e3, "nm") if self.unit in ("um", "\u00b5m") else (1.0, self.unit)
        return (f"max error {scale * self.max_error:.4g} {unit}, RMS {scale * self.rms_error:.4g} "
                f"{unit}, loop width {scale * self.loop_width:.4g} {unit} "
                f"({self.samples} samples)")

    def __iter__(self) -> Iterator[float]:
        yield from (self.max_error, self.rms_error, self.loop_width)

    def to_dict(self) -> dict[str, float]:
        """The figures as a plain dict (JSON-ready).

        Returns
        -------
        dict
            ``max_error, rms_error, loop_width, samples``.
        """
        return asdict(self)


def tracking_metrics(
    y_ref: np.ndarray,
    y: np.ndarray,
    *,
    skip: int = 0,
    bins: int = 40,
    central: float = 0.9,
    unit: str = "um",
) -> TrackingMetrics:
    """Maximum error, RMS error and the hysteresis loop width left.

    Parameters
    ----------
    y_ref, y : ndarray
        Reference and measured (or simulated) output, same length.
    skip : int
        Leading samples left out (start-up).
    bins : int
        Number of bins of ``y_ref`` over which the rising and falling branches are averaged.
    central : float
        Fraction of the reference range used for the loop width (the turning points, where
        both branches meet anyway, are left out).
    unit : str
        The output's unit (how :class:`TrackingMetrics` shows the figures).

    Returns
    -------
    TrackingMetrics
        ``max_error, rms_error, loop_width``.
    """
    y_ref = np.asarray(y_ref, dtype=float)
    y = np.asarray(y, dtype=float)
    if y_ref.ndim != 1 or y_ref.shape != y.shape:
        raise ValueError(f"y_ref, y: expected equal 1-D shapes, got {y_ref.shape} and {y.shape}")
    if int(skip) != skip or not 0 <= skip < len(y) - 2:
        raise ValueError(f"skip: expected 0 <= skip < {len(y) - 2}, got {skip!r}")
    if not 0 < central <= 1:
        raise ValueError(f"central: expected a fraction in (0, 1], got {central!r}")
    if int(bins) != bins or bins < 1:
        raise ValueError(f"bins: expected a positive integer, got {bins!r}")
    finite_signal(y_ref, "y_ref")
    finite_signal(y, "y")
    slope = np.gradient(y_ref)[skip:]
    r = y_ref[skip:]
    e = y[skip:] - r
    lo, hi = r.min(), r.max()
    margin = 0.5 * (1.0 - central) * (hi - lo)
    edges = np.linspace(lo + margin, hi - margin, int(bins) + 1)
    width = np.nan
    if hi > lo:
        idx = np.digitize(r, edges) - 1
        inside = (idx >= 0) & (idx < bins)
        rising = inside & (slope > 0)
        falling = inside & (slope < 0)
        count_r = np.bincount(idx[rising], minlength=bins)
        count_f = np.bincount(idx[falling], minlength=bins)
        both = (count_r > 0) & (count_f > 0)
        if np.any(both):
            mean_r = np.bincount(idx[rising], e[rising], minlength=bins)[both] / count_r[both]
            mean_f = np.bincount(idx[falling], e[falling], minlength=bins)[both] / count_f[both]
            width = float(np.max(np.abs(mean_f - mean_r)))
    return TrackingMetrics(float(np.max(np.abs(e))), float(np.sqrt(np.mean(e**2))), width, len(e),
                           str(unit))
