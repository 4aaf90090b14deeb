"""Validation metrics as the paper reports them (Fig. 4) and the validation figure."""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:  # pragma: no cover
    from matplotlib.figure import Figure

__all__ = ["PAPER_TRANSIENT_S", "Validation", "error_scale", "gap_closed", "plot_convergence",
           "plot_validation", "runaway", "validate", "zoom_window", "noise_level", "LOOP_SPAN"]


def gap_closed(nominal: float, value: float, floor: float) -> float:
    """The one definition of the gap closed: ``(nominal - value) / (nominal - floor)``.

    The gap is what separates the nominal model's held-out RMS from the floor (sensor noise or
    the repeatability of the stage, whichever is higher); a model scored alike closes this
    share of it (1: down to the floor; negative: worse than the nominal model).

    Parameters
    ----------
    nominal : float
        The nominal model's held-out RMS.
    value : float
        The other model's held-out RMS, scored as the nominal one was.
    floor : float
        The floor.

    Returns
    -------
    float
        The share; 0 when the nominal model is already at the floor.
    """
    gap = nominal - floor
    return float((nominal - value) / gap) if gap > 0 else 0.0

#: The paper drops the first 0.0017 s of the validation (51 samples at 30 kHz).
PAPER_TRANSIENT_S = 0.0017


@dataclass
class Validation:
    """Free-run validation figures. Unpacks as ``err_min, err_max, rms, fit_percent``.

    Attributes
    ----------
    err_min, err_max : float
        Range of the error ``y - yhat`` after the initial transient (output units).
    rms : float
        RMS of the error after the transient.
    fit_percent : float
        ``100 (1 - ||y - yhat|| / ||y - mean(y)||)`` (NRMSE fit).
    y_min, y_max : float
        Range of the measured output over the same samples.
    skip : int
        Samples dropped as the initial transient.
    """

    err_min: float
    err_max: float
    rms: float
    fit_percent: float
    y_min: float
    y_max: float
    skip: int

    def __iter__(self) -> Iterator[float]:
        yield from (self.err_min, self.err_max, self.rms, self.fit_percent)

    def to_dict(self) -> dict[str, float]:
        """The figures as a plain dict (JSON-ready).

        Returns
        -------
        dict
            The fields by name.
        """
        return asdict(self)


def validate(
    y: np.ndarray, yhat: np.ndarray, fs: float, transient: float = PAPER_TRANSIENT_S
) -> Validation:
    """Compare a measured output with a free-run simulation.

    Parameters
    ----------
    y, yhat : ndarray
        Measured and simulated outputs, same length.
    fs : float
        Sampling rate in Hz.
    transient : float
        Seconds dropped at the start (the paper's 0.0017 s by default).

    Returns
    -------
    Validation
        Error range, RMS and fit after the transient.
    """
    y, yhat = np.asarray(y, float), np.asarray(yhat, float)
    if y.shape != yhat.shape or y.ndim != 1:
        raise ValueError(f"y and yhat: expected equal 1-D shapes, got {y.shape} and {yhat.shape}")
    skip = int(round(transient * fs))
    if len(y) - skip < 2:
        raise ValueError(
            f"record too short to validate: {len(y)} samples, {skip} dropped as transient"
        )
    e = (y - yhat)[skip:]
    ys = y[skip:]
    spread = np.linalg.norm(ys - ys.mean())
    fit = 100.0 * (1.0 - np.linalg.norm(e) / spread) if spread > 0 else float("nan")
    return Validation(
        float(e.min()), float(e.max()), float(np.sqrt(np.mean(e**2))), float(fit),
        float(ys.min()), float(ys.max()), skip,
    )


#: Length units and their size in nm: errors of a length are drawn in nm.
_NM_PER_UNIT = {"nm": 1.0, "um": 1e3, "µm": 1e3, "mm": 1e6, "m": 1e9}


def error_scale(unit: str) -> tuple[float, str]:
    """Factor and unit in which an error of ``unit`` is shown: nm for a length, else as is.

    Parameters
    ----------
    unit : str
        Unit of the output (``"um"``, ``"nm"``, ``"mm"``, ``"m"``, or anything else).

    Returns
    -------
    tuple of (float, str)
        Multiply the error by the factor to get it in the returned unit.
    """
    if unit in _NM_PER_UNIT:
        return _NM_PER_UNIT[unit], "nm"
    return 1.0, unit


def zoom_window(t: np.ndarray, e: np.ndarray, seconds: float = 0.01) -> tuple[int, int]:
    """Samples ``start, stop`` of a window of ``seconds`` centred on the largest error.

    Parameters
    ----------
    t : ndarray
        Time in seconds (uniform).
    e : ndarray
        Error, same length.
    seconds : float
        Width of the window (at most the record).

    Returns
    -------
    tuple of int
        ``start, stop`` indices into ``t``.
    """
    n = len(t)
    dt = (t[-1] - t[0]) / max(n - 1, 1)
    width = int(min(n, max(2, round(seconds / dt)))) if dt > 0 else n
    finite = np.isfinite(e)
    centre = int(np.argmax(np.where(finite, np.abs(e), -1.0))) if finite.any() else 0
    start = int(np.clip(centre - width // 2, 0, n - width))
    return start, start + width


def plot_validation(
    t: np.ndarray, y: np.ndarray, yhat: np.ndarray, path: str | Path | None = None,
    *, u: np.ndarray | None = None, title: str = "model validation", unit: str = "um",
    u_unit: str = "V", skip: int = 0, zoom: float = 0.01,
) -> Figure:
    """The paper's Fig. 4, readable: output, a zoomed window, the y-u loop and the error.

    Top: measured and model output over the record (the transient ``skip`` left out), with
    the zoomed window shaded. Middle: the window of ``zoom`` seconds around the largest error
    and, when ``u`` is given, the output against the input (the hysteresis loop), measured and
    model over :data:`LOOP_SPAN` such windows, the whole record's loop faint behind. Bottom:
    the error, in nm when ``unit`` is a length, with its RMS and range, and the band of the
    sensor noise estimated from it (:func:`noise_level`).

    The figure is a :class:`matplotlib.figure.Figure` not registered with pyplot: the caller's
    backend and current figure are left alone.

    Parameters
    ----------
    t : ndarray
        Time in seconds.
    y, yhat : ndarray
        Measured and simulated output, same length as ``t``.
    path : str or Path, optional
        Write a PNG there.
    u : ndarray, optional
        The input, for the y-u loop.
    title : str
        Figure title.
    unit, u_unit : str
        Units of the output and the input.
    skip : int
        Leading samples left out (the transient).
    zoom : float
        Width of the zoomed window in seconds.

    Returns
    -------
    matplotlib.figure.Figure
        The figure.
    """
    from matplotlib.figure import Figure

    sl = slice(skip, None)
    t, y, yhat = (np.asarray(a, float)[sl] for a in (t, y, yhat))
    yhat, n_runaway = _drawable(y, yhat)
    if n_runaway:
        title = f"{title} (the model diverged: {n_runaway} samples not drawn)"
    scale, e_unit = error_scale(unit)
    e = scale * (y - yhat)
    fig = Figure(figsize=(10, 7.5), layout="constrained")
    grid = fig.add_gridspec(3, 2, height_ratios=[1.0, 1.2, 0.9])
    ax_all = fig.add_subplot(grid[0, :])
    ax_zoom = fig.add_subplot(grid[1, 0] if u is not None else grid[1, :])
    ax_err = fig.add_subplot(grid[2, :], sharex=ax_all)
    start, stop = zoom_window(t, e, zoom)
    for ax, part in ((ax_all, slice(None)), (ax_zoom, slice(start, stop))):
        ax.plot(t[part], y[part], lw=0.8, label="measured")
        ax.plot(t[part], yhat[part], lw=0.8, ls="--", label="model")
        ax.set_ylabel(f"y [{unit}]")
    ax_all.axvspan(t[start], t[stop - 1], color="0.85", zorder=0, label="zoomed window")
    ax_all.legend(loc="upper right", fontsize=8, ncols=3)
    ax_all.set_title(title)
    ax_zoom.set_title(f"zoom: {1e3 * (t[stop - 1] - t[start]):.3g} ms around the largest error",
                      fontsize=9)
    ax_zoom.set_xlabel("time [s]")
    if u is not None:
        ax_loop = fig.add_subplot(grid[1, 1])
        uu = np.asarray(u, float)[sl]
        a, b = zoom_window(t, e, LOOP_SPAN * zoom)  # a few loops, not the whole record's
        ax_loop.plot(uu, y, lw=0.4, color="0.8", label="measured, whole record")
        ax_loop.plot(uu[a:b], y[a:b], lw=2.0, color="C0", alpha=0.5, label="measured")
        ax_loop.plot(uu[a:b], yhat[a:b], lw=0.8, ls="--", color="C1", label="model")
        ax_loop.set_xlabel(f"u [{u_unit}]")
        ax_loop.set_ylabel(f"y [{unit}]")
        ax_loop.set_title(f"y against u (loop): {1e3 * (t[b - 1] - t[a]):.3g} ms around the "
                          "largest error", fontsize=9)
        ax_loop.legend(loc="upper left", fontsize=8)
    noise = noise_level(e[np.isfinite(e)]) if np.isfinite(e).sum() > 2 else 0.0
    ax_err.axhspan(-noise, noise, color="0.85", zorder=0,
                   label=f"sensor noise +-{noise:.3g} {e_unit} (from sample-to-sample steps)")
    ax_err.plot(t, e, lw=0.6, color="C3")
    ax_err.axhline(0.0, color="0.5", lw=0.6)
    ax_err.legend(loc="upper right", fontsize=8)
    ax_err.set_ylabel(f"error [{e_unit}]")
    ax_err.set_xlabel("time [s]")
    ax_err.set_title(f"measured - model: RMS {np.sqrt(np.nanmean(e**2)):.3g} {e_unit}, range "
                     f"{np.nanmin(e):.3g} .. {np.nanmax(e):.3g} {e_unit}"
                     + (" where drawn" if n_runaway else ""), fontsize=9)
    if path is not None:
        fig.savefig(path, dpi=120)
    return fig


#: A model output further than this many times the measured output's spread from its median
#: is not drawn (a diverged simulation: matplotlib cannot place ticks on 1e32).
RUNAWAY_SPREADS = 1e3


def runaway(y: np.ndarray, yhat: np.ndarray) -> bool:
    """Whether a model's output ran away from the measured one: a sample not finite or further
    than :data:`RUNAWAY_SPREADS` times the measured output's spread from its median.

    Parameters
    ----------
    y, yhat : ndarray
        Measured and simulated output.

    Returns
    -------
    bool
    """
    return _drawable(np.asarray(y, float), np.asarray(yhat, float))[1] > 0


def _drawable(y: np.ndarray, yhat: np.ndarray) -> tuple[np.ndarray, int]:
    """``yhat`` with non-finite and runaway samples (:data:`RUNAWAY_SPREADS`) set to NaN, and
    how many there were."""
    fin = y[np.isfinite(y)]
    mid = float(np.median(fin)) if fin.size else 0.0
    spread = float(np.ptp(fin)) if fin.size else 1.0
    with np.errstate(invalid="ignore", over="ignore"):
        bad = ~np.isfinite(yhat) | (np.abs(yhat - mid) > RUNAWAY_SPREADS * max(spread, 1e-300))
    n = int(np.count_nonzero(bad))
    if n == len(yhat):  # nothing to draw: the measured output alone
        return np.full(len(yhat), np.nan), n
    return (np.where(bad, np.nan, yhat), n) if n else (yhat, 0)


#: The loop panel spans this many zoom widths around the largest error.
LOOP_SPAN = 10


def noise_level(e: np.ndarray) -> float:
    """White-noise level of a signal from its sample-to-sample steps: ``1.4826 MAD(de) / sqrt 2``
    (a slow error does not count; a robust scale, outliers do not count either).

    Parameters
    ----------
    e : ndarray
        The signal (an error).

    Returns
    -------
    float
        The estimated standard deviation of its white part (0 for fewer than 3 samples).
    """
    d = np.diff(np.asarray(e, float))
    d = d[np.isfinite(d)]
    if d.size < 2:
        return 0.0
    return float(1.4826 * np.median(np.abs(d - np.median(d))) / np.sqrt(2.0))


def _group(name: str) -> str:
    """Parameter family: digits dropped (``mu12`` -> ``mu``), ``a11`` -> ``a1``."""
    stem = name.rstrip("0123456789")
    return stem if len(stem) > 1 else name[:2]


def plot_convergence(
    history: np.ndarray, names: list[str] | tuple[str, ...], truth: dict[str, float] | None = None,
    path: str | Path | None = None, *, samples: np.ndarray | None = None,
    title: str = "parameter convergence", max_lines: int = 12,
) -> Figure:
    """Relative parameter error against the sample, both on log axes, in one panel.

    With ``truth`` the error is ``|theta_i(k) - truth_i| / |truth_i|`` and each line's label
    gives the true value; without it, the distance to the final estimate. When there are more
    than ``max_lines`` parameters (a PI sandwich's weights) the parameters of one family
    (``mu``, ``a1``, ``b2``...) share a line: the largest relative error in the family.

    Parameters
    ----------
    history : ndarray
        Parameter estimates, one row per sample.
    names : sequence of str
        Parameter names, one per column.
    truth : dict, optional
        True values by name.
    path : str or Path, optional
        Write a PNG there.
    samples : ndarray, optional
        The sample (0-based) of each row, for a decimated history; row ``i`` is sample ``i``
        by default.
    title : str
        Figure title.
    max_lines : int
        Most lines drawn one per parameter.

    Returns
    -------
    matplotlib.figure.Figure
        The figure (not registered with pyplot).
    """
    from matplotlib.figure import Figure

    history = np.asarray(history, float)
    if history.ndim != 2 or history.shape[1] != len(names):
        raise ValueError(f"history: expected one column per name ({len(names)}), got shape "
                         f"{history.shape}")
    known = truth is not None and all(n in truth for n in names)
    ref = np.array([truth[n] for n in names]) if known else history[-1]
    scale = np.where(np.abs(ref) > 0, np.abs(ref), 1.0)
    err = np.abs(history - ref) / scale
    k = 1 + (np.arange(len(history)) if samples is None else np.asarray(samples, float))
    fig = Figure(figsize=(8, 4.8), layout="constrained")
    ax = fig.add_subplot()
    if len(names) <= max_lines:
        for i, name in enumerate(names):
            label = f"{name} (true {ref[i]:.4g})" if known else name
            ax.plot(k, np.maximum(err[:, i], 1e-16), lw=0.9, label=label)
    else:
        families: dict[str, list[int]] = {}
        for i, name in enumerate(names):
            families.setdefault(_group(name), []).append(i)
        for family, cols in families.items():
            label = family if len(cols) == 1 else f"{family} ({len(cols)} parameters, largest)"
            ax.plot(k, np.maximum(err[:, cols].max(axis=1), 1e-16), lw=0.9, label=label)
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("sample k")
    ax.set_ylabel("relative error to the truth" if known else
                  "relative distance to the final estimate")
    ax.grid(True, which="major", lw=0.4, alpha=0.6)
    ax.legend(loc="lower left", fontsize=8, ncols=2)
    ax.set_title(title)
    if path is not None:
        fig.savefig(path, dpi=120)
    return fig
