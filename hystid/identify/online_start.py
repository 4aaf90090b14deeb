"""The on-line identifier's start-up check: a start-up solution against its own noise
estimate and the linear baseline (:class:`StartUpCheck`, :func:`check_start`).

:class:`~hystid.identify.online.OnlineIdentifier` solves the sandwich on its first samples
before the recursion runs; a solution that passes this check is where the recursion starts.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..model import Structure
from ..records import Record

__all__ = ["NOISE_RATIO", "StartUpCheck", "check_start"]

#: The start-up residual may exceed its noise estimate by this factor (white: about 1).
NOISE_RATIO = 1.3


@dataclass
class StartUpCheck:
    """The start-up solution against its own noise estimate and a linear model.

    Attributes
    ----------
    samples : int
        Samples the solution was fitted on.
    rms : float
        RMS simulation error of the solution on them (output units).
    noise : float
        Noise estimate from the same residual: ``RMS(diff r) / sqrt(2)`` (a white residual has
        ``noise ~ rms``; a misfit is smooth and has ``noise << rms``).
    rms_linear : float
        RMS simulation error of the linear baseline with its own offset
        (:func:`hystid.baselines.baseline_orders`, as :func:`hystid.baselines.compare` fits).
    start : str
        Which start the solution came from.
    passed : bool
        ``rms <= NOISE_RATIO noise`` (or at round-off level) and ``rms < rms_linear``.
    """

    samples: int
    rms: float
    noise: float
    rms_linear: float
    start: str
    passed: bool

    def reason(self) -> str:
        """Why the check failed, in words (empty when it passed).

        Returns
        -------
        str
        """
        if self.passed:
            return ""
        parts = []
        if self.rms > NOISE_RATIO * self.noise:
            ratio = self.rms / max(self.noise, 1e-300)
            parts.append(f"its simulation error ({self.rms:.3g} RMS) is {ratio:.2g}x its noise "
                         f"estimate ({self.noise:.3g})")
        if self.rms >= self.rms_linear:
            parts.append(f"it does not beat a linear model ({self.rms_linear:.3g} RMS)")
        return " and ".join(parts)


def check_start(u: np.ndarray, y: np.ndarray, yhat: np.ndarray, structure: Structure, fs: float,
                start: str = "") -> StartUpCheck:
    """Check a start-up solution on the samples it was fitted on.

    Parameters
    ----------
    u, y : ndarray
        The window's input and measured output.
    yhat : ndarray
        The solution's simulated output (offset included).
    structure : Structure
        The sandwich's structure (the linear baseline's orders follow from it).
    fs : float
        Sampling rate in Hz.
    start : str
        Label of the start the solution came from.

    Returns
    -------
    StartUpCheck
    """
    from ..baselines import LinearModel, baseline_orders

    r = y - yhat
    rms = float(np.sqrt(np.mean(r**2)))
    noise = float(np.sqrt(np.mean(np.diff(r) ** 2) / 2.0))
    rec = Record(u, y, fs, name="start-up window")
    linear = LinearModel.fit(rec, *baseline_orders(structure))
    rms_linear = float(np.sqrt(np.mean((y - linear.predict(u)) ** 2)))
    round_off = 1e-9 * max(float(np.std(y)), 1e-300)
    white = rms <= NOISE_RATIO * noise or rms <= round_off
    passed = bool(white and rms < rms_linear)
    return StartUpCheck(len(u), rms, noise, rms_linear, start, passed)
