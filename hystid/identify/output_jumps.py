"""A sensor zero that moves during a record: a lasting step of the measured output that the
input does not cause.

A capacitive or strain sensor can re-zero mid-record (a range switch, a knock on the cable):
from one sample on, every output reads a constant more. No member of the family makes such a
step from an input that does not jump, so a fit spreads it over its parameters and the model
is worse everywhere (on the Bouc-Wen look-alike of stage A, a 0.3 um step a third into a 2 s
record costs the held-out error 5-23 %), without a word. After the fit, the residual (measured
less simulated output) shows it as one sample-to-sample change far beyond the residual's
ordinary ones, after which the residual's level stays moved by as much:

* the change: ``|e(k+1) - e(k)|`` at least :data:`JUMP_Z` times the robust spread (1.4826
  MAD) of all of them, and at least the robust spread of the residual itself;
* the level: the residual's median over :data:`LEVEL_SECONDS` after the change less the one
  before it is :data:`PERSIST` of the change (a spike, a burst or a transient returns);
* alone: no other change over :data:`LEVEL_SECONDS` on either side, but those within
  :data:`SMEAR` samples of it (a sensor's filter spreads a step), is :data:`ISOLATION` of it
  or more. A model that misses a mode leaves a residual ringing at it, every change of the
  ringing as large as the largest: on a piece of stage A's ``prbn_1`` cut 0.05 s into its
  excitation, the on-line ``pi-stage`` model's residual rang at 0.5 um, and one of its swings,
  0.23 um in a sample and its level moved as much, was taken for a moved zero;
* not within two such windows of the record's ends or of an input jump
  (:data:`~hystid.identify.prepare.JUMP_SLEWS` times the input's 99 % slew), where the
  model's own error changes fast.

:func:`hystid.identify.identify` then takes the step off the samples after it, identifies the
model again and says so; the model's sensor offset is the one before the step.
"""

from __future__ import annotations

from contextvars import ContextVar
from dataclasses import dataclass, replace

import numpy as np

from ..records import Record
from .prepare import JUMP_SLEWS, rest_level

__all__ = ["ISOLATION", "JUMP_Z", "LEVEL_SECONDS", "PERSIST", "SMEAR", "OutputJump",
           "find_output_jump", "residual_after_rest", "without_jump"]

#: A change of the residual this many times the robust spread of its changes is a step.
JUMP_Z = 12.0
#: Seconds over which the residual's level before and after a step is taken (at least 20
#: samples).
LEVEL_SECONDS = 0.02
#: The level's move, as a share of the step, that makes it lasting.
PERSIST = (0.6, 1.6)

#: A step stands alone: every change of the residual over :data:`LEVEL_SECONDS` on either side,
#: but those within :data:`SMEAR` samples of it, is under this share of it.
ISOLATION = 0.5
SMEAR = 2

#: Whether :func:`hystid.identify.identify` looks for a step after its fit (off inside the
#: fits it runs itself: the outermost call looks once).
CHECKING: ContextVar[bool] = ContextVar("hystid_output_jump_check", default=True)


@dataclass(frozen=True)
class OutputJump:
    """A step of the measured output found after a fit.

    Parameters
    ----------
    sample : int
        The first sample that reads the moved zero.
    size : float
        The step, in the output's units (positive: the output reads more from there on).
    z : float
        The step against the robust spread of the residual's sample-to-sample changes.
    """

    sample: int
    size: float
    z: float

    def to_dict(self) -> dict[str, float]:
        """Plain, JSON-ready form.

        Returns
        -------
        dict
        """
        return {"sample": self.sample, "size": self.size, "z": self.z}

    def note(self, record: Record) -> str:
        """The warning :func:`hystid.identify.identify` gives.

        Parameters
        ----------
        record : Record
            The record it was found in.

        Returns
        -------
        str
        """
        unit = record.units.get("y", "")
        return (f"the measured output steps by {self.size:+.4g} {unit} at sample {self.sample} "
                f"(t = {self.sample / record.fs:.6g} s) where the input does not (a change "
                f"{self.z:.0f} times the residual's usual ones, its level moved as much "
                "after): a sensor zero that moved? The samples from there were shifted back "
                "by as much and the model identified again; its sensor offset is the one "
                "before the step")


def find_output_jump(e: np.ndarray, u: np.ndarray, fs: float) -> OutputJump | None:
    """The lasting step of a residual, if one stands out (see the module docstring).

    Parameters
    ----------
    e : ndarray
        Measured less simulated output (NaN where not scored).
    u : ndarray
        The input of the same samples.
    fs : float
        Sampling rate in Hz.

    Returns
    -------
    OutputJump or None
    """
    e = np.asarray(e, dtype=float)
    window = max(20, int(round(LEVEL_SECONDS * fs)))
    de = np.diff(e)
    seen = np.isfinite(de)
    if np.count_nonzero(seen) < 10 * window:
        return None
    spread = 1.4826 * float(np.median(np.abs(de[seen] - np.median(de[seen]))))
    level = e[np.isfinite(e)]
    level_spread = 1.4826 * float(np.median(np.abs(level - np.median(level))))
    if not spread > 0:
        return None
    size = np.where(seen, np.abs(de), 0.0)
    size[:2 * window] = 0.0
    size[-2 * window:] = 0.0
    du = np.abs(np.diff(np.asarray(u, dtype=float)))
    slew = float(np.quantile(du, 0.99)) if du.size else 0.0
    if slew > 0:
        for i in np.flatnonzero(du > JUMP_SLEWS * slew):
            size[max(0, i - 2 * window):i + 2 * window] = 0.0
    k = int(np.argmax(size))
    step = float(de[k])
    if not (abs(step) >= JUMP_Z * spread and abs(step) >= level_spread):
        return None
    moved = float(np.nanmedian(e[k + 1:k + 1 + window]) - np.nanmedian(e[k + 1 - window:k + 1]))
    if not PERSIST[0] <= moved / step <= PERSIST[1]:
        return None
    around = np.r_[size[max(0, k - window):max(0, k - SMEAR)], size[k + SMEAR + 1:k + window + 1]]
    if around.size and float(np.max(around)) >= ISOLATION * abs(step):
        return None
    return OutputJump(k + 1, step, abs(step) / spread)


def residual_after_rest(record: Record, model) -> np.ndarray:
    """The record's output less the model's free run from rest, NaN over the leading rest
    (a constant between them moves neither a step nor a level, so none is taken off).

    Parameters
    ----------
    record : Record
        The record the model was identified on.
    model : object
        The identified model (any member).

    Returns
    -------
    ndarray
        Measured less simulated output.
    """
    from ..baselines import simulate_from_rest

    with np.errstate(all="ignore"):
        e = record.y - simulate_from_rest(model, record.u, check=False)
    e[:rest_level(record.u)[2]] = np.nan
    return e


def without_jump(record: Record, jump: OutputJump) -> Record:
    """The record with the step taken off the samples from ``jump.sample`` on.

    Parameters
    ----------
    record : Record
        As measured.
    jump : OutputJump
        The step found.

    Returns
    -------
    Record
        A new record (the one given is left as it is).
    """
    y = record.y.copy()
    y[jump.sample:] -= jump.size
    return replace(record, y=y)
