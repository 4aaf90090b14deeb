"""Hysteresis compensation and feedback design with an identified sandwich model.

What users identify the model for: track a reference with the stage.

* :func:`inverse` -- the inverse sandwich (reference for ``y`` -> amplifier voltage) as a
  discrete :class:`control.NonlinearIOSystem`: L2 inverted through its static gain or a
  reference model, the exact per-sample inverse of the Duhem block (eq. 7) with a reversal
  planner working on a preview of the reference, L1 inverted with its delay taken from the
  preview, input limits without windup. A :class:`~hystid.pi.PISandwich` is inverted through
  its exact inverse PI operator; the generalised Duhem block and the parallel Duhem operators
  of a :class:`~hystid.mduhem.MultiDuhemSandwich` by their per-sample inverses, without
  look-ahead.
* :func:`feedforward` -- the same compensator, compiled, over a whole reference;
  :func:`linear_feedforward` the uncompensated baseline.
* :func:`compensate` -- compensation from a placed (identified) model: reference and command
  in the record's units, limits from the model's envelope, L2 inverted by its stable inverse
  (:func:`stable_inverse`), warnings where the model is not admissible.
* :func:`design_feedback` -- integral (+P) control with a notch at the flexure mode, designed
  on the identified linear part with stated margins.
* :func:`closed_loop` -- feed-forward + feedback + stage as a
  :class:`control.InterconnectedSystem`; :func:`closed_loop_response` simulates it with
  python-control, :func:`simulate_closed_loop` runs the same loop compiled.
* :func:`perturbed_stage` -- a stage whose physical parameters differ from the model's;
  :func:`margins_on` the margins a design keeps on it.
* :func:`tracking_metrics` -- maximum and RMS error, hysteresis loop width left;
  :func:`scan_reference` -- triangle and sine scans from rest.

Modules: :mod:`~hystid.compensate.duhem_inverse` (the maths of the per-sample inverse and the
planner), :mod:`~hystid.compensate.member_inverse` (the per-sample inverses of the generalised
and multi-Duhem blocks), :mod:`~hystid.compensate.compensator` (the inverse chain),
:mod:`~hystid.compensate.linear_parts` (the linear blocks' inversion, reference models),
:mod:`~hystid.compensate.placed` (compensation in the record's units),
:mod:`~hystid.compensate.feedback`, :mod:`~hystid.compensate.closedloop`,
:mod:`~hystid.compensate.tracking`, :mod:`~hystid.compensate.robustness`; ``hystid compensate``
is :mod:`hystid.cli.compensate`.
"""

from .closedloop import (
    ClosedLoopResponse,
    closed_loop,
    closed_loop_response,
    simulate_closed_loop,
)
from .compensator import (
    DEFAULT_PREVIEW,
    DUHEM_BOUND,
    NOT_EXACT,
    SATURATED,
    TURNING,
    Feedforward,
    feedforward,
    hysteresis_gain,
    linear_feedforward,
    smoothing_model,
)
from .feedback import FeedbackDesign, design_feedback, flexure_mode, linear_plant
from .hysteresis_inverse import HysteresisInverse, inverse
from .linear_parts import StableInverse, stable_inverse
from .placed import Compensation, CompensationWarning, compensate, envelope_limits
from .robustness import PERTURBABLE, LoopMargins, margins_on, perturbed_stage
from .tracking import ScanReference, TrackingMetrics, scan_reference, tracking_metrics

__all__ = [
    "DEFAULT_PREVIEW",
    "DUHEM_BOUND",
    "NOT_EXACT",
    "PERTURBABLE",
    "SATURATED",
    "TURNING",
    "ClosedLoopResponse",
    "Compensation",
    "CompensationWarning",
    "FeedbackDesign",
    "Feedforward",
    "HysteresisInverse",
    "LoopMargins",
    "ScanReference",
    "StableInverse",
    "TrackingMetrics",
    "closed_loop",
    "closed_loop_response",
    "compensate",
    "design_feedback",
    "envelope_limits",
    "feedforward",
    "flexure_mode",
    "hysteresis_gain",
    "inverse",
    "linear_feedforward",
    "linear_plant",
    "margins_on",
    "perturbed_stage",
    "scan_reference",
    "simulate_closed_loop",
    "smoothing_model",
    "stable_inverse",
    "tracking_metrics",
]
