"""Compensation from a placed model: reference and command in the record's units.

:func:`compensate` turns a wanted displacement, in the units a record of the stage has (sensor
offset included), into the amplifier command in the record's units (rest level included) for
any identified model that exposes the placed-model interface (``u_rest``, ``offset``,
``envelope``, ``units``, ``L1``, ``L2``, ``simulate`` and, for a model that remembers a state at
rest, ``at_rest()``)::

    y_ref --(- offset, - y at rest)--> M? --L2 stable inverse--> w2d --H^-1, L1^-1--> u + u_rest

* **Placement.** The model's output at rest (its sensor offset plus what L2 makes of the Duhem
  state the stage remembers at rest) is taken off the reference; the command gets the rest
  level back. The compensator starts from the model's own state at rest; for a model
  identified on a record that began in motion (``envelope.from_rest`` false) that rest is a
  point of the record's motion, which a :class:`CompensationWarning` says (on the stage-A
  look-alike, such a model's commands were up to 83 V off the applied input over the held-out
  record's rest, against 2 V for a model that saw its rest).
* **L2 inverted dynamically**, by its stable inverse
  (:func:`~hystid.compensate.linear_parts.inverse_filter`): exact for a minimum-phase L2; zeros
  outside the unit circle are inverted anti-causally (pre-actuation within
  :attr:`Compensation.preview` samples), which a :class:`CompensationWarning` says. The stage
  rests before the reference's first sample, so the pre-actuation that would fall there is made
  up over the first :attr:`Compensation.settle` samples (least output error there, the output
  exact afterwards).
* **Causal stages.** Every stage (the reference model, L2's inverse, the hysteresis and L1
  inverses) is a recursion read with a fixed delay: the command for a reference sample needs
  the reference :attr:`Compensation.preview` samples ahead and nothing else, so the same
  command comes out of a real-time step that returns it that many samples late (the C export,
  :mod:`hystid.export`). The reference is held at its last value after its end.
* **Limits from the envelope.** By default the command stays inside the range of the input
  the model was identified on, widened by ``margin`` of its span at each end (the tolerance the
  admissibility check itself allows).
* **Admissibility.** Samples where the command saturates or the inverse step is not exact, and
  commands the model is not admissible for (envelope, condition 8), are listed in
  :attr:`Compensation.warnings` and raised as one :class:`~hystid.operating.AdmissibilityWarning`.
"""

from __future__ import annotations

import warnings
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import control as ct
import numpy as np

from ..errors import CompensationWarning
from ..operating import warn_admissibility
from ..signals import finite_signal
from .compensator import (
    COMPENSATIONS,
    DUHEM_BOUND,
    KIND_DUHEM,
    KIND_GDUHEM,
    KIND_LINEAR,
    KIND_PI,
    NOT_EXACT,
    SATURATED,
    Feedforward,
    _build,
    _Chain,
    _run,
)
from .linear_parts import MAX_RUNOUT, InverseFilter, dc_delay, inverse_filter, lti_run

__all__ = ["DEFAULT_MARGIN", "Compensation", "CompensationWarning", "compensate",
           "envelope_limits"]

#: Share of the identified input span the default limits add at each end.
DEFAULT_MARGIN = 0.1
#: A reference starting further than this share of its span from the rest output is warned of.
START_TOLERANCE = 0.01


@dataclass
class Compensation:
    """A command computed by :func:`compensate`, with what the model predicts for it.

    Attributes
    ----------
    t : ndarray
        Time in seconds, from the reference's first sample.
    r : ndarray
        The reference, as given (record units, offset included).
    u : ndarray
        The command, in the record's input units (rest level included).
    y_pred : ndarray
        The model's output driven by ``u`` from its state at rest (record units).
    y_des : ndarray
        The output asked for: ``r``, or ``r`` through the reference model.
    status : ndarray
        Per-sample flags of the hysteresis inverse (see
        :class:`~hystid.compensate.Feedforward`).
    u_limits : (float, float)
        The limits the command was clipped to.
    preview : int
        Samples of reference needed ahead of each command sample (the delays of L1 and L2,
        the Duhem planner's look-ahead, L2's anti-causal part and the reference model's lead).
    y_rest : float
        The model's output at rest (record units).
    units : dict
        Units of ``u`` and ``y``.
    warnings : list of str
        What limits the command (saturation, inexact steps, admissibility, approximations).
    settle : int
        Output samples at the start where the model may miss the reference although every step
        is exact: L2's zeros outside the unit circle need pre-actuation, and what of it would
        fall before the first sample (the stage rests there) is made up over these samples
        (0 for a minimum-phase L2). See :attr:`settled_relative_error`.
    """

    t: np.ndarray
    r: np.ndarray
    u: np.ndarray
    y_pred: np.ndarray
    y_des: np.ndarray
    status: np.ndarray
    u_limits: tuple[float, float]
    preview: int
    y_rest: float
    units: dict[str, str]
    warnings: list[str] = field(default_factory=list)
    settle: int = 0

    @property
    def exact(self) -> np.ndarray:
        """Samples where the inverse step was exact and unsaturated."""
        return (self.status & NOT_EXACT) == 0

    @property
    def relative_error(self) -> float:
        """RMS of ``y_pred - y_des`` over the RMS of ``y_des`` about the rest output."""
        return _relative(self.y_pred - self.y_des, self.y_des - self.y_rest)

    @property
    def settled_relative_error(self) -> float:
        """:attr:`relative_error` from sample :attr:`settle` on (where L2 is inverted exactly)."""
        k = min(self.settle, self.u.size - 1)
        return _relative(self.y_pred[k:] - self.y_des[k:], self.y_des[k:] - self.y_rest)

    def to_dict(self) -> dict[str, Any]:
        """A summary (no signals) for JSON reports.

        Returns
        -------
        dict
            Limits, preview, exactness, relative errors and warnings.
        """
        return {"u_limits": list(self.u_limits), "preview": self.preview,
                "samples": int(self.u.size), "exact_share": float(np.mean(self.exact)),
                "relative_error": self.relative_error, "settle": self.settle,
                "settled_relative_error": self.settled_relative_error,
                "units": dict(self.units), "warnings": list(self.warnings)}


def _relative(err: np.ndarray, dev: np.ndarray) -> float:
    """RMS of ``err`` over the RMS of ``dev`` (``err``'s RMS when ``dev`` is zero)."""
    scale = float(np.sqrt(np.mean(dev ** 2)))
    rms = float(np.sqrt(np.mean(err ** 2)))
    return rms / scale if scale > 0 else rms


def envelope_limits(model: Any, margin: float = DEFAULT_MARGIN) -> tuple[float, float]:
    """Input limits from the model's envelope: its range widened by ``margin`` of the span.

    Parameters
    ----------
    model : placed model
        A model with an ``envelope`` (:class:`~hystid.operating.Envelope`).
    margin : float
        Share of the span added at each end.

    Returns
    -------
    (float, float)
        Lowest and highest command, in the record's input units.

    Raises
    ------
    ValueError
        When the model carries no envelope or ``margin`` is negative.
    """
    if not (np.isfinite(margin) and margin >= 0):
        raise ValueError(f"margin: expected a non-negative share of the span, got {margin!r}")
    env = getattr(model, "envelope", None)
    if env is None:
        raise ValueError("model: it carries no input envelope (identified elsewhere?); give "
                         "u_limits")
    span = env.u_max - env.u_min
    return env.u_min - margin * span, env.u_max + margin * span


def _rest(model: Any) -> tuple[float, float]:
    """``(w2, y)`` of the model at rest, relative to its placement."""
    at_rest = getattr(model, "at_rest", None)
    if at_rest is None:
        return 0.0, 0.0
    past = at_rest()
    return float(past.window("w2", 1)[0]), float(past.window("y", 1)[0])


def _reference_filter(reference_model: ct.LTI, lead: int | None,
                      dt: float) -> tuple[np.ndarray, np.ndarray, int]:
    """``(num, den, lead)`` of the reference model ``M`` in powers of ``z^-1`` (``den[0] = 1``)."""
    if not isinstance(reference_model, ct.LTI) or not reference_model.dt \
            or not np.isclose(float(reference_model.dt), dt):
        raise ValueError(f"reference_model: expected a discrete SISO system with dt = {dt:g} s, "
                         f"got {reference_model!r}")
    tf = ct.ss2tf(reference_model) if isinstance(reference_model, ct.StateSpace) \
        else reference_model
    num, den = (np.asarray(v[0][0], float) for v in (tf.num, tf.den))
    if np.any(np.abs(np.roots(den)) >= 1.0):
        raise ValueError("reference_model: must be stable (poles inside the unit circle)")
    lead = dc_delay(reference_model) if lead is None else int(lead)
    if lead < 0:
        raise ValueError(f"reference_lead: expected a non-negative number of samples, got {lead}")
    pad = len(den) - len(num)  # z-domain orders: pad the numerator to powers of z^-1
    num = np.r_[np.zeros(max(pad, 0)), num]
    return (np.ascontiguousarray(num / den[0]), np.ascontiguousarray(den / den[0]), lead)


@dataclass(frozen=True)
class _Plan:
    """What :func:`compensate` runs, stage by stage, each a causal recursion read with a fixed
    delay (the exported C step runs the same stages one sample at a time)::

        r - y_rest --M (lead)--> y_des - y_rest --L2 stable inverse--> w2d --chain--> u - u_rest
    """

    y_rest: float  # the model's output at rest (record units); anchor "reference": r(0)
    anchor: str
    m_num: np.ndarray  # the reference model (empty: none)
    m_den: np.ndarray
    lead: int
    l2: InverseFilter
    chain: _Chain
    rest: float  # the hysteresis block's output at rest (the chain's start)
    u_rest: float
    u_limits: tuple[float, float]
    plays: np.ndarray  # a PI block's plays at rest (empty: virgin, or not a PI block)

    @property
    def preview(self) -> int:
        """Samples of reference read ahead of each command sample (the C step's delay)."""
        return self.lead + self.l2.preview + self.chain.advance

    def run(self, y: np.ndarray, y_rest: float) -> tuple[Feedforward, np.ndarray]:
        """The chain's output over ``y`` (held at its end) and the desired output ``y_des``."""
        n = y.size
        dev = y - y_rest
        dev = np.concatenate([dev, np.full(self.preview, dev[-1])])  # the reference held
        if self.m_num.size:
            ym = np.empty(dev.size)
            lti_run(dev, self.m_num, self.m_den, ym)
            ym = ym[self.lead:]
        else:
            ym = dev
        w2d = self.l2.run(ym, n + self.chain.advance) + self.rest
        return _run(self.chain, w2d, n=n, rest=self.rest, plays=self.plays), ym[:n] + y_rest


def _plan(model: Any, *, u_limits: tuple[float, float] | None = None,
          margin: float = DEFAULT_MARGIN, reference_model: ct.LTI | None = None,
          reference_lead: int | None = None, preview: int | None = None,
          duhem_bound: float = DUHEM_BOUND, compensation: str = "inverse",
          anchor: str = "model") -> _Plan:
    """The stages of :func:`compensate` for ``model`` with its options (checked here)."""
    if compensation not in ("inverse", "linear"):
        raise ValueError(f"compensation: expected 'inverse' or 'linear', got {compensation!r}")
    for name in ("u_rest", "offset", "L2", "simulate", "fs"):
        if not hasattr(model, name):
            raise ValueError(f"model: expected an identified sandwich model (no {name!r}), got "
                             f"{model!r}")
    if u_limits is None:
        limits = envelope_limits(model, margin)
    else:
        try:
            if isinstance(u_limits, str | bytes):
                raise TypeError("text")
            limits = tuple(float(v) for v in u_limits)
        except (TypeError, ValueError, OverflowError) as err:
            raise ValueError(f"u_limits: expected two numbers (low, high), got "
                             f"{u_limits!r}") from err
    if len(limits) != 2 or not (np.all(np.isfinite(limits)) and limits[0] < limits[1]):
        if u_limits is None:  # from the model's envelope
            raise ValueError(f"u_limits: the model's input envelope gives no range "
                             f"({limits[0]:g} .. {limits[1]:g}); expected u_limits=(low, high) "
                             "(--limits LOW:HIGH)")
        raise ValueError(f"u_limits: expected (low, high) with low < high, got {u_limits!r}")
    if anchor not in ("model", "reference"):
        raise ValueError(f"anchor: expected 'model' or 'reference', got {anchor!r}")
    w2_rest, y_rest_rel = _rest(model)
    if reference_model is not None:
        m_num, m_den, lead = _reference_filter(reference_model, reference_lead, model.dt)
    elif reference_lead:
        raise ValueError("reference_lead: only meaningful with a reference model")
    else:
        m_num, m_den, lead = np.zeros(0), np.ones(1), 0
    chain = _build(model, kind=COMPENSATIONS[compensation],
                   u_limits=(limits[0] - model.u_rest, limits[1] - model.u_rest),
                   reference_model=None, preview=preview, duhem_bound=duhem_bound,
                   l2_identity=True)
    chain_kind = int(chain.ispec[0])
    plays = np.zeros(0)
    if chain_kind in (KIND_DUHEM, KIND_GDUHEM):  # from the Duhem state remembered at rest
        rest = w2_rest
    elif chain_kind == KIND_PI and getattr(model, "rest_swing", 0.0):  # plays at rest
        rest, plays = w2_rest, np.asarray(model.rest_plays, dtype=float)
    elif chain_kind == KIND_LINEAR or not w2_rest:  # the central line through the rest point
        rest = 0.0
    else:
        raise ValueError("model: a hysteresis state at rest is only handled for the Duhem block "
                         "(plain or generalised) and the PI block")
    return _Plan(float(model.offset) + y_rest_rel, anchor, m_num, m_den, lead,
                 inverse_filter(model.L2), chain, float(rest), float(model.u_rest),
                 (float(limits[0]), float(limits[1])), plays)


def compensate(
    model: Any,
    y_ref: np.ndarray | Sequence[float],
    *,
    u_limits: tuple[float, float] | None = None,
    margin: float = DEFAULT_MARGIN,
    reference_model: ct.LTI | None = None,
    reference_lead: int | None = None,
    preview: int | None = None,
    duhem_bound: float = DUHEM_BOUND,
    compensation: str = "inverse",
    anchor: str = "model",
    warn: bool = True,
) -> Compensation:
    """The command that makes a placed model follow a reference given in the record's units.

    Parameters
    ----------
    model : DuhemSandwich, MultiDuhemSandwich or PISandwich
        An identified model (batch or on-line), with its rest level, sensor offset, envelope
        and units; L1 must be minimum phase, L2 must have no zero on the unit circle. Every
        member has an inverse: the plain Duhem block with its reversal planner, the PI operator
        its exact inverse (when a partial sum of its weights is not positive, the nearest
        invertible operator's, said in the warnings:
        :func:`~hystid.compensate.linear_parts.invertible_weights`), the generalised Duhem
        block (``gduhem``) and the parallel Duhem
        operators (``mduhem``) their per-sample inverse without look-ahead
        (:mod:`~hystid.compensate.member_inverse`: a reversal the block cannot make in one step
        is approximate for a few samples, flagged in :attr:`Compensation.status`).
    y_ref : array_like
        Wanted displacement, one value per sample at the model's rate, in the record's output
        units (offset included: a displacement as the sensor reads it). It should start at
        the model's output at rest (:attr:`Compensation.y_rest`): the stage starts from rest.
    u_limits : (float, float), optional
        Command limits in the record's input units; by default the envelope's range widened by
        ``margin`` (:func:`envelope_limits`).
    margin : float
        Share of the envelope's span added at each end for the default limits.
    reference_model : control.TransferFunction, optional
        Ask for ``y = M y_ref`` (about the rest output) instead of ``y_ref`` itself, e.g. a
        :func:`~hystid.compensate.smoothing_model` for references with corners; its DC delay is
        taken from the preview unless ``reference_lead`` says otherwise.
    reference_lead : int, optional
        Samples of ``M``'s delay taken from the preview.
    preview : int, optional
        Look-ahead of the Duhem reversal planner (see :func:`~hystid.compensate.inverse`; the
        plain Duhem block's only).
    duhem_bound : float
        Largest ``alpha |dw1|`` per sample the inverse allows.
    compensation : {"inverse", "linear"}
        ``"linear"``: the hysteresis replaced by its central line through the rest point (the
        linear inverse, the baseline), L2 and the placement handled the same way.
    anchor : {"model", "reference"}
        Where the stage rests on the output axis. ``"model"``: at the model's output at rest
        (its sensor offset); a reference that starts elsewhere has a first step the stage
        cannot make (said in a warning). ``"reference"``: at the reference's first sample (a
        displacement measured in another run, whose sensor zero has moved): the model's offset
        is moved there for this command and its prediction.
    warn : bool
        Raise the warnings (an :class:`~hystid.operating.AdmissibilityWarning` for the envelope,
        saturation and inexact steps, a :class:`CompensationWarning` for approximations); they
        are in :attr:`Compensation.warnings` either way.

    Returns
    -------
    Compensation
        The command, the model's predicted output and how exact it is.
    """
    plan = _plan(model, u_limits=u_limits, margin=margin, reference_model=reference_model,
                 reference_lead=reference_lead, preview=preview, duhem_bound=duhem_bound,
                 compensation=compensation, anchor=anchor)
    y = finite_signal(y_ref, "y_ref", min_size=2)
    y_rest = float(y[0]) if anchor == "reference" else plan.y_rest
    notes: list[str] = []
    start = abs(float(y[0]) - y_rest)
    if start > START_TOLERANCE * max(float(np.ptp(y)), 1e-300):
        notes.append(f"the reference starts {start:.4g} {_unit(model, 'y')} away from the "
                     f"model's output at rest ({y_rest:.6g}): the stage cannot jump there, the "
                     "first samples are not tracked (anchor='reference' takes the reference's "
                     "start as the rest)")
    env = getattr(model, "envelope", None)
    if env is not None and not env.from_rest:
        notes.append(f"the model never saw its stage at rest (it was identified on a record "
                     f"that began in motion): its rest level {model.u_rest:.6g} "
                     f"{_unit(model, 'u')} and its state there are a point of that record's "
                     "motion, and the compensator starts from them; the first commands move "
                     "from there (identify on a record that begins at rest to compensate from "
                     "rest)")
    weights = getattr(model, "mu", None)
    if weights is not None and not len(getattr(model, "poly", ())) and not model.is_invertible():
        sums = np.cumsum(weights)
        notes.append(f"the model's PI operator has no exact inverse (a partial sum of its "
                     f"weights is {float(np.min(sums) / np.max(sums)):.2g} times the largest, "
                     "not positive: its loading curve falls somewhere); the command inverts "
                     "the nearest operator whose partial sums are positive, and the model's "
                     "output from it (y_pred, relative_error) says how far that is off")
    run, y_des = plan.run(y, y_rest)
    u = run.u + plan.u_rest
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        y_pred = np.asarray(model.simulate(u, check=False).y, float)
    y_pred += y_rest - plan.y_rest  # the sensor zero anchored
    l2 = plan.l2
    if l2.lag:
        zeros = ", ".join(f"{z:.4g}" for z in l2.outside)
        notes.append(f"L2 has zeros outside the unit circle ({zeros}): inverted by its stable "
                     f"non-causal inverse, which moves the command up to {l2.preview} samples "
                     "before the reference does (pre-actuation); what of it would fall before "
                     f"the first sample, where the stage rests, is made up over the first "
                     f"{l2.settle} samples (the output is exact from there on)")
        if l2.fir.size - 1 >= MAX_RUNOUT:
            notes.append(f"L2's zeros outside the unit circle lie so near it that its "
                         f"anti-causal inverse is cut at {MAX_RUNOUT} samples before it has "
                         "decayed: the inverse is approximate (a reference model that keeps "
                         "those zeros avoids this)")
    result = Compensation(np.arange(y.size) / model.fs, y, u, y_pred, y_des, run.status,
                          plan.u_limits, int(plan.preview), y_rest,
                          {"u": _unit(model, "u"), "y": _unit(model, "y")},
                          settle=l2.settle)
    admissibility = _admissibility(model, result)
    result.warnings = notes + admissibility
    if warn:
        if notes:
            warnings.warn(f"model {getattr(model, 'name', '')!r}: " + "; ".join(notes),
                          CompensationWarning, stacklevel=2)
        warn_admissibility(admissibility, getattr(model, "name", "model"))
    return result


def _unit(model: Any, key: str) -> str:
    """The model's unit of ``key`` (``""`` when it has none)."""
    return str(getattr(model, "units", {}).get(key, ""))


def _spans(mask: np.ndarray, fs: float) -> str:
    """``"n samples (first at t s)"`` for the true samples of ``mask``."""
    idx = np.flatnonzero(mask)
    return f"{idx.size} samples (the first at {idx[0] / fs:.4g} s)"


def _admissibility(model: Any, result: Compensation) -> list[str]:
    """Where the command leaves what the model is admissible for, one sentence each."""
    out = []
    fs = float(model.fs)
    sat = (result.status & SATURATED) != 0
    if np.any(sat):
        lo, hi = result.u_limits
        out.append(f"the command saturates at the limits {lo:.4g} .. {hi:.4g} "
                   f"{result.units.get('u', '')} at {_spans(sat, fs)}: the reference asks for "
                   "more than the model is admissible for")
    inexact = ((result.status & (NOT_EXACT & ~SATURATED)) != 0)
    if np.any(inexact):
        out.append(f"the hysteresis inverse has no exact step at {_spans(inexact, fs)} (a "
                   "reversal the block cannot make in one step and no preview prepared, or "
                   "alpha |dw1| at its bound)")
    check = getattr(model, "admissibility", None)
    if check is not None:
        out += check(result.u)
    elif getattr(model, "envelope", None) is not None:
        out += model.envelope.violations(result.u)
    return out
