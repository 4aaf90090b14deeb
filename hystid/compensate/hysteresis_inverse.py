"""The compensator as a discrete python-control system (:func:`inverse`,
:class:`HysteresisInverse`): the chain of :mod:`hystid.compensate.compensator` one sample per
update, for interconnection with the stage and a controller.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING, Literal

import control as ct
import numpy as np

from .compensator import (
    COMPENSATIONS,
    DUHEM_BOUND,
    _as_reference,
    _build,
    _Chain,
    _functions,
    _pad_hold,
)

if TYPE_CHECKING:
    from ..model import DuhemSandwich
    from ..pi import PISandwich

__all__ = ["HysteresisInverse", "inverse"]


class HysteresisInverse(ct.NonlinearIOSystem):
    """The compensator as a discrete python-control system; made by :func:`inverse`.

    Input ``r(k) = y_ref(k + advance)``; outputs the command ``u``, the desired output ``yd``
    aligned with the stage's ``y`` and a ``status`` (bit flags: 1 step clipped to the bound of
    condition 8, 2 no exact step existed, 4 command saturated -- none of these: exact; and 8,
    :data:`TURNING`, the compensator is turning the hysteresis round).

    Attributes
    ----------
    model : DuhemSandwich, MultiDuhemSandwich or PISandwich
        The model inverted.
    delay : int
        ``q1 + q2``, samples from ``u`` to ``y``.
    preview : int
        Samples of reference the reversal planner looks ahead.
    advance : int
        ``delay + preview``: how far ahead of ``y`` the input reference runs.

    Parameters
    ----------
    model : DuhemSandwich, MultiDuhemSandwich or PISandwich
        The model inverted.
    chain : _Chain
        The compiled chain's arrays (made by :func:`inverse`).
    inputs : str
        Name of the reference input.
    outputs : sequence of str
        Names of the command, desired-output and status outputs.
    name : str
        System name.
    """

    def __init__(self, model, chain: _Chain, *, inputs, outputs, name):
        update, output = _functions(chain)
        super().__init__(update, output, inputs=inputs, outputs=outputs, states=list(chain.states),
                         dt=model.dt, name=name)
        self.model = model
        self._chain = chain

    @property
    def delay(self) -> int:
        """``q1 + q2``."""
        return self._chain.delay

    @property
    def preview(self) -> int:
        """Planner preview in samples."""
        return self._chain.preview

    @property
    def advance(self) -> int:
        """Samples the input reference runs ahead of ``y``."""
        return self._chain.advance

    def reference_input(self, y_ref: np.ndarray | Sequence[float]) -> np.ndarray:
        """The input signal ``r(k) = y_ref(k + advance)`` (the last value held at the end).

        Parameters
        ----------
        y_ref : array_like
            Desired output, one value per sample.

        Returns
        -------
        ndarray
            The advanced reference, as long as ``y_ref``.
        """
        y = _as_reference(y_ref)
        return _pad_hold(y, self.advance)[self.advance:]

    def initial_state(self, y_ref: np.ndarray | Sequence[float] | None = None) -> np.ndarray:
        """State at rest with the first ``advance`` reference samples already read in.

        Pass it as ``X0`` to :func:`control.input_output_response` together with
        :meth:`reference_input`; without ``y_ref``, the reference is taken as zero before
        sample ``advance``.

        Parameters
        ----------
        y_ref : array_like, optional
            Desired output, one value per sample.

        Returns
        -------
        ndarray
            The compensator's state vector.
        """
        return self._chain.initial_state(None if y_ref is None else _as_reference(y_ref))


def inverse(
    model: DuhemSandwich | PISandwich,
    *,
    u_limits: tuple[float, float] = (0.0, 10.0),
    reference_model: ct.LTI | Literal["exact"] | None = None,
    reference_lead: int | None = None,
    preview: int | None = None,
    duhem_bound: float = DUHEM_BOUND,
    compensation: str = "inverse",
    inputs: str = "r",
    outputs: Sequence[str] = ("u", "yd", "status"),
    name: str = "inverse",
) -> HysteresisInverse:
    """The inverse sandwich (hysteresis compensator) as a discrete python-control system.

    Parameters
    ----------
    model : DuhemSandwich, MultiDuhemSandwich or PISandwich
        The identified stage. L1 (and L2 when it is inverted dynamically) must be minimum
        phase; a PI operator must have an exact inverse. A generalised Duhem block (``gduhem``)
        and parallel Duhem operators (``mduhem``) are inverted per sample without look-ahead
        (:mod:`~hystid.compensate.member_inverse`).
    u_limits : (float, float)
        Amplifier input limits in volts (0-10 V like the paper's amplifier). The command is
        clipped and the compensator's internal model follows the clipped command (no windup).
    reference_model : None, 'exact' or control.TransferFunction
        ``None``: invert L2 through its static gain (``w2d = y_ref / L2(1)``); ``'exact'``:
        invert L2 whole (``y = y_ref``); a discrete SISO system ``M`` (same ``dt``): ``y = M
        y_ref``. The dynamic choices need L2 minimum phase.
    reference_lead : int, optional
        Samples of ``M``'s delay taken from the preview, so that ``yd(k) = (M y_ref)(k + lead)``
        is aligned with ``y_ref``; by default ``M``'s DC group delay (see :func:`dc_delay`).
    preview : int, optional
        Samples the Duhem reversal planner looks ahead (:data:`DEFAULT_PREVIEW` for a Duhem
        model, 0 for a PI model, which needs none; the generalised and multi-Duhem inverses have
        no planner and take 0 only). ``0`` gives a strictly causal inverse
        that cannot prepare reversals (they are then approximate for a stage like the paper's).
        The stretch a reversal needs grows as the scan slows: on the reference stage, for a
        7 um sine, 300 samples suffice down to 5 Hz, 1 000 at 2 Hz, 3 000 at 1 Hz; a preview too
        short leaves the reversal approximate (status 2 for a few samples). While the stage
        follows the plan the planner reuses the previous sample's look-ahead (a few steps a
        sample, whatever the preview); a sample off the plan (a saturated command, a clipped
        or far-branch step) simulates the preview again up to its next reversal
        (``benchmarks/bench_compensate.py``).
    duhem_bound : float
        Largest ``alpha |dw1|`` per sample, below the stability bound 2 of condition (8).
    compensation : {"inverse", "linear", "none"}
        ``"inverse"``: the hysteresis inverse; ``"linear"``: the uncompensated baseline (the
        hysteresis replaced by its central line, see :func:`linear_feedforward`); ``"none"``:
        the reference path only (``u = 0``, ``yd`` still given: feedback alone).
    inputs, outputs, name : str
        Signal and system names (python-control keywords).

    Returns
    -------
    HysteresisInverse
        A :class:`control.NonlinearIOSystem` with pure update and output functions; feed it
        :meth:`HysteresisInverse.reference_input` and start it from
        :meth:`HysteresisInverse.initial_state`.
    """
    if compensation not in COMPENSATIONS:
        raise ValueError(
            f"compensation: expected one of {', '.join(COMPENSATIONS)}, got {compensation!r}"
        )
    chain = _build(model, kind=COMPENSATIONS[compensation], u_limits=u_limits,
                   reference_model=reference_model, preview=preview, duhem_bound=duhem_bound,
                   reference_lead=reference_lead)
    outputs = list(outputs)
    if len(outputs) != 3:
        raise ValueError(f"outputs: expected three names (command, yd, status), got {outputs!r}")
    return HysteresisInverse(model, chain, inputs=[inputs], outputs=outputs, name=name)
