"""Validation metrics as the paper reports them (Fig. 4) and the validation figure."""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:  # pragma: no cover
    from matplotlib.figure import Figure

__all__ = ["Validation", "validate", "plot_validation", "PAPER_TRANSIENT_S"]

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


def plot_validation(
    t: np.ndarray, y: np.ndarray, yhat: np.ndarray, path: str | Path | None = None,
    *, title: str = "model validation", unit: str = "um", skip: int = 0,
) -> Figure:
    """The paper's Fig. 4: measured and model output (top) and the error (bottom).

    Writes a PNG when ``path`` is given; returns the figure.
    """
    import matplotlib

    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt

    fig, (ax1, ax2) = plt.subplots(2, 1, sharex=True, figsize=(8, 5))
    sl = slice(skip, None)
    ax1.plot(t[sl], y[sl], lw=0.8, label="measured")
    ax1.plot(t[sl], yhat[sl], lw=0.8, ls="--", label="model")
    ax1.set_ylabel(f"y [{unit}]")
    ax1.legend(loc="best")
    ax1.set_title(title)
    ax2.plot(t[sl], (y - yhat)[sl], lw=0.6, color="C3")
    ax2.set_ylabel(f"error [{unit}]")
    ax2.set_xlabel("time [s]")
    fig.tight_layout()
    if path is not None:
        fig.savefig(path, dpi=120)
        plt.close(fig)
    return fig
