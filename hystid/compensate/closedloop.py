"""Feed-forward + feedback around the stage: the python-control interconnection and a fast twin.

::

    r --[ff: compensator]--u_ff--(+)--u_cmd--[amplifier: clip]--u--[stage]--y--(+ n)--ym
              |                   ^                      |                       |
              yd                 u_fb                   du                       |
              +-------(+)--e--[C (anti-windup)]<---------+-----------(-)---------+

* ``ff`` is :func:`~hystid.compensate.hysteresis_inverse.inverse` (``feedforward=True``), its
  uncompensated baseline (``"linear"``) or the reference path alone (``False``): it always
  gives ``yd``, the desired output aligned with ``y``.
* ``C`` is a :class:`~hystid.compensate.feedback.FeedbackDesign` realised with back-calculation
  anti-windup (``du`` = applied minus commanded voltage), any SISO LTI controller ``e -> u_fb``,
  or nothing.
* The amplifier clips the total command to ``u_limits``; the compensator clips its own part and
  follows it, so neither path winds up.
* While the compensator turns the hysteresis round before a reversal (status
  :data:`~hystid.compensate.compensator.TURNING`) the stage's incremental gain is small or of
  the other sign (after a reversal of ``w1`` the paper's Duhem block first keeps going the old
  way), so feedback there would only wind its integrator up and release it as an overshoot
  after the turn: the error fed to ``C`` is held at zero for those samples
  (``hold_while_turning``).

The loop runs about the model's rest: the reference, ``y`` and ``yd`` are relative to its
output at rest (its sensor offset off) and the commands relative to its rest level
``u_rest``, as the compensator's chain (:func:`~hystid.compensate.hysteresis_inverse.inverse`)
sees them; a placed model drives the loop without its placement. In the record's units (offset
and rest level included, the state remembered at rest) the command comes from
:func:`~hystid.compensate.placed.compensate`.

:func:`closed_loop` returns the :class:`control.InterconnectedSystem` and
:func:`closed_loop_response` simulates it with :func:`control.input_output_response`;
:func:`simulate_closed_loop` runs the same loop compiled (the Duhem stage only), about 200
times faster (``benchmarks/bench_compensate.py``), for long runs.
"""

from __future__ import annotations

import copy
from collections.abc import Sequence
from typing import TYPE_CHECKING, Literal

import control as ct
import numpy as np
from numba import njit
from numba.core.dispatcher import Dispatcher

from ..kernels import step as stage_step
from ..model import DuhemSandwich
from ..response import LabelledResponse
from ..signals import finite_signal
from .compensator import (
    _P,
    COMPENSATIONS,
    DUHEM_BOUND,
    TURNING,
    _as_reference,
    _build,
    _pad_hold,
    chain_step,
    source_stamp,
)
from .duhem_inverse import planner_memo
from .feedback import FeedbackDesign
from .hysteresis_inverse import HysteresisInverse
from .tracking import TrackingMetrics, tracking_metrics

if TYPE_CHECKING:  # pragma: no cover
    from matplotlib.axes import Axes

    from ..pi import PISandwich

__all__ = [
    "ClosedLoopResponse",
    "closed_loop",
    "closed_loop_response",
    "simulate_closed_loop",
]

OUTPUTS = ["y", "u", "yd", "e", "u_ff", "u_fb", "du", "ff_status"]


class ClosedLoopResponse(LabelledResponse):
    """Signals of a closed-loop run, as a :class:`control.TimeResponseData`. Unpacks as ``t, y``.

    Input ``y_ref``; outputs ``y, u, yd, e, u_ff, u_fb, status`` (each also an attribute), so
    ``.plot()`` and ``.to_pandas()`` work as for any python-control response.

    Parameters
    ----------
    t : ndarray
        Time in seconds.
    y_ref, yd : ndarray
        Reference and the desired output the compensator aims at (``M y_ref``).
    y : ndarray
        Stage output (without sensor noise).
    u, u_ff, u_fb : ndarray
        Applied command and its feed-forward and feedback parts (before clipping).
    e : ndarray
        Error seen by the controller: ``yd - (y + noise)``, or 0 while it holds.
    status : ndarray
        Compensator status flags (see :class:`~hystid.compensate.compensator.Feedforward`).
    name : str
        Name of the loop.
    unit : str
        The output's unit (the model's; :meth:`metrics` shows the figures in it). A model in
        metres was shown in nm as if in um, 1e6 too small.
    """

    def __init__(self, t: np.ndarray, y_ref: np.ndarray, yd: np.ndarray, y: np.ndarray,
                 u: np.ndarray, u_ff: np.ndarray, u_fb: np.ndarray, e: np.ndarray,
                 status: np.ndarray, name: str = "closed loop", unit: str = "um") -> None:
        outputs = {"y": y, "u": u, "yd": yd, "e": e, "u_ff": u_ff, "u_fb": u_fb,
                   "status": status}
        super().__init__(t, {"y_ref": y_ref}, outputs, name=name)
        self.unit = str(unit)

    @property
    def status(self) -> np.ndarray:
        """Compensator status flags, as integers."""
        return self._find("status").astype(np.int64)

    def metrics(self, skip: int = 0, *, against: str = "y_ref") -> TrackingMetrics:
        """Tracking figures of ``y`` against ``y_ref`` (or ``"yd"``) after ``skip`` samples.

        Parameters
        ----------
        skip : int
            Leading samples left out.
        against : {"y_ref", "yd"}
            The reference, or the desired output the compensator aims at.

        Returns
        -------
        TrackingMetrics
            Maximum and RMS error and the loop width left.
        """
        if against not in ("y_ref", "yd"):
            raise ValueError(f"against: expected 'y_ref' or 'yd', got {against!r}")
        return tracking_metrics(getattr(self, against), self.y, skip=skip, unit=self.unit)

    def plot_tracking(
        self, ax: Sequence[Axes] | np.ndarray | None = None, label: str | None = None,
        *, unit: str = "um",
    ) -> Sequence[Axes] | np.ndarray:
        """Output against reference, and the error in nm; returns the two axes.

        Parameters
        ----------
        ax : two matplotlib axes, optional
            Where to draw; a new figure (not registered with pyplot) by default.
        label : str, optional
            Legend label of the lines.
        unit : str
            Unit of ``y`` (the error is drawn in nm when it is ``"um"``).

        Returns
        -------
        sequence of matplotlib.axes.Axes
            The output axis and the error axis.
        """
        if ax is None:
            from matplotlib.figure import Figure

            ax = Figure(figsize=(7, 5), layout="constrained").subplots(2, 1, sharex=True)
        scale, e_unit = (1e3, "nm") if unit == "um" else (1.0, unit)
        ax[0].plot(self.t, self.y_ref, color="0.6", lw=0.8)
        ax[0].plot(self.t, self.y, lw=0.9, label=label)
        ax[0].set_ylabel(f"y [{unit}]")
        ax[1].plot(self.t, scale * (self.y - self.y_ref), lw=0.9, label=label)
        ax[1].set_ylabel(f"y - y_ref [{e_unit}]")
        ax[1].set_xlabel("time [s]")
        return ax


def _compensation(feedforward) -> str:
    if feedforward is True:
        return "inverse"
    if feedforward is False or feedforward is None:
        return "none"
    if feedforward not in COMPENSATIONS:
        raise ValueError(
            f"feedforward: expected True, False or one of {', '.join(COMPENSATIONS)}, "
            f"got {feedforward!r}"
        )
    return feedforward


def _controller_ss(controller, dt: float) -> ct.StateSpace:
    """The controller as a state-space block with inputs ``e`` (and ``du``), output ``u_fb``."""
    if controller is None:
        return ct.ss(np.zeros((0, 0)), np.zeros((0, 2)), np.zeros((1, 0)), np.zeros((1, 2)), dt,
                     inputs=["e", "du"], outputs=["u_fb"], name="C")
    if isinstance(controller, FeedbackDesign):
        if not np.isclose(controller.dt, dt):
            raise ValueError(f"controller: dt {controller.dt:g} differs from the model's {dt:g}")
        return controller.anti_windup(name="C")
    if not isinstance(controller, ct.LTI) or controller.ninputs != 1 or \
            controller.noutputs != 1:
        raise ValueError(
            f"controller: expected a FeedbackDesign, a SISO control LTI system or None, "
            f"got {controller!r}"
        )
    if not controller.dt or not np.isclose(float(controller.dt), dt):
        raise ValueError(f"controller: must be discrete with dt = {dt:g} s")
    ss = controller if isinstance(controller, ct.StateSpace) else \
        ct.tf2ss(controller, method="scipy")
    A, B, C, D = (np.asarray(m, float) for m in (ss.A, ss.B, ss.C, ss.D))
    # a plain controller has no anti-windup: du enters nowhere
    B2 = np.column_stack([B, np.zeros(A.shape[0])])
    D2 = np.column_stack([D, np.zeros(1)])
    return ct.ss(A, B2, C, D2, dt, inputs=["e", "du"], outputs=["u_fb"], name="C")


def _stage(model, plant) -> ct.InputOutputSystem:
    """The stage driven, about its rest: a sandwich model's python-control system without its
    placement (input ``u - u_rest``, output less the offset), as the compensator and the
    compiled loop see it. With it, a placed model's output carried its sensor offset into the
    loop's error while the compensator's desired output did not: on an independently simulated
    Bouc-Wen stage (offset 1.017 um) the python-control loop tracked 63 nm where the compiled
    one, the same loop, tracked 329."""
    stage = model if plant is None else plant
    if hasattr(stage, "to_control"):
        if getattr(stage, "u_rest", 0.0) or getattr(stage, "offset", 0.0):
            stage = copy.copy(stage)
            stage.u_rest, stage.offset = 0.0, 0.0
        return stage.to_control()
    if isinstance(stage, ct.InputOutputSystem):
        if "u" not in stage.input_labels or "y" not in stage.output_labels:
            raise ValueError("plant: a python-control plant needs an input 'u' and an output 'y'")
        return stage
    raise ValueError(f"plant: expected a sandwich model or a python-control system, got {stage!r}")


def closed_loop(
    model: DuhemSandwich | PISandwich,
    controller: FeedbackDesign | ct.LTI | None = None,
    feedforward: bool | str = True,
    *,
    plant: DuhemSandwich | PISandwich | ct.InputOutputSystem | None = None,
    u_limits: tuple[float, float] = (0.0, 10.0),
    reference_model: ct.LTI | Literal["exact"] | None = None,
    reference_lead: int | None = None,
    preview: int | None = None,
    duhem_bound: float = DUHEM_BOUND,
    hold_while_turning: bool = True,
    noise_input: bool = True,
    name: str = "closed loop",
) -> ct.InterconnectedSystem:
    """Feed-forward compensator + feedback controller + stage, as one python-control system.

    Parameters
    ----------
    model : DuhemSandwich or PISandwich
        The identified model the compensator inverts.
    controller : FeedbackDesign, control LTI or None
        Feedback ``e -> u_fb``; a :class:`FeedbackDesign` brings its anti-windup.
    feedforward : bool or {"inverse", "linear", "none"}
        The compensator (``True`` = ``"inverse"``, ``False`` = ``"none"``: feedback only).
    plant : sandwich model or python-control system, optional
        The stage actually driven (input ``u``, output ``y``); the model itself by default.
    u_limits, reference_model, reference_lead, preview, duhem_bound
        As for :func:`~hystid.compensate.hysteresis_inverse.inverse`.
    hold_while_turning : bool
        Feed ``C`` a zero error while the compensator turns the hysteresis round.
    noise_input : bool
        Add an input ``n`` (sensor noise, added to ``y`` before the controller).
    name : str
        System name.

    Returns
    -------
    control.InterconnectedSystem
        Inputs ``r`` (the reference advanced by the compensator's ``advance``, see
        :func:`closed_loop_response`) and ``n``; outputs ``y, u, yd, e, u_ff, u_fb, du,
        ff_status``.
    """
    dt = model.dt
    ff = _ff_block(model, feedforward, u_limits, reference_model, reference_lead, preview,
                   duhem_bound)
    umin, umax = (float(v) for v in u_limits)

    def amplifier(t, x, u, params):
        v = float(u[0])
        clipped = min(max(v, umin), umax)
        return np.array([clipped, clipped - v])

    sat = ct.nlsys(None, amplifier, inputs=["u_cmd"], outputs=["u", "du"], dt=dt,
                   name="amplifier")

    def error(t, x, u, params):
        held = hold_while_turning and (int(round(u[2])) & TURNING)
        return np.array([0.0 if held else u[0] - u[1]])

    blocks = [
        ff,
        ct.nlsys(None, error, inputs=["yd", "ym", "ff_status"], outputs=["e"], dt=dt,
                 name="error"),
        _controller_ss(controller, dt),
        ct.summing_junction(["u_ff", "u_fb"], "u_cmd", dt=dt, name="command"),
        sat,
        _stage(model, plant),
    ]
    if noise_input:
        blocks.insert(1, ct.summing_junction(["y", "n"], "ym", dt=dt, name="sensor"))
        inplist = ["r", "n"]
    else:
        blocks.insert(1, ct.summing_junction(["y"], "ym", dt=dt, name="sensor"))
        inplist = ["r"]
    return ct.interconnect(blocks, inplist=inplist, outlist=OUTPUTS, inputs=inplist,
                           outputs=OUTPUTS, dt=dt, name=name, check_unused=False)


def _ff_block(model, feedforward, u_limits, reference_model, reference_lead, preview,
              duhem_bound) -> HysteresisInverse:
    from .hysteresis_inverse import inverse

    return inverse(model, u_limits=u_limits, reference_model=reference_model,
                   reference_lead=reference_lead, preview=preview, duhem_bound=duhem_bound,
                   compensation=_compensation(feedforward), inputs="r",
                   outputs=("u_ff", "yd", "ff_status"), name="ff")


def closed_loop_response(
    sys: ct.InterconnectedSystem,
    y_ref: np.ndarray | Sequence[float],
    *,
    noise: np.ndarray | None = None,
) -> ClosedLoopResponse:
    """Simulate a :func:`closed_loop` system with :func:`control.input_output_response`.

    Builds the advanced reference input and the initial state (compensator primed with the
    reference, everything else at rest).

    Parameters
    ----------
    sys : control.InterconnectedSystem
        Made by :func:`closed_loop`.
    y_ref : array_like
        Desired output, one value per sample, starting at rest.
    noise : ndarray, optional
        Sensor noise added to ``y`` (needs ``noise_input=True``).

    Returns
    -------
    ClosedLoopResponse
        Input ``y_ref``; outputs ``y, u, yd, e, u_ff, u_fb, status``.
    """
    subs = {s.name: s for s in sys.syslist}
    ff = subs.get("ff")
    if not isinstance(ff, HysteresisInverse):
        raise ValueError("sys: expected a system made by hystid.compensate.closed_loop")
    y_ref = _as_reference(y_ref)
    n = len(y_ref)
    inputs = [ff.reference_input(y_ref)]
    if "n" in sys.input_labels:
        noise = np.zeros(n) if noise is None else np.asarray(noise, float)
        if noise.shape != (n,):
            raise ValueError(f"noise: expected {n} samples, got shape {noise.shape}")
        inputs.append(noise)
    elif noise is not None:
        raise ValueError("noise: the system has no noise input (closed_loop(noise_input=True))")
    x0 = np.concatenate([ff.initial_state(y_ref) if s is ff else np.zeros(s.nstates)
                         for s in sys.syslist])
    t = np.arange(n) * sys.dt
    resp = ct.input_output_response(sys, t, np.vstack(inputs), X0=x0)
    out = {label: resp.outputs[i] for i, label in enumerate(sys.output_labels)}
    return ClosedLoopResponse(
        t, y_ref, out["yd"], out["y"], out["u"], out["u_ff"], out["u_fb"], out["e"],
        out["ff_status"].astype(np.int64), name=sys.name, unit=_output_unit(ff.model),
    )


def _output_unit(model) -> str:
    """The model's output unit (um when it carries none)."""
    return str((getattr(model, "units", None) or {}).get("y") or "um")


# =========================================================================== compiled twin
def _stamped_run_loop(stamp: int) -> Dispatcher:
    """:func:`_run_loop` compiled with the source ``stamp`` of the kernels it calls."""

    @njit(cache=True)
    def _run_loop(x_ff, rs, chain_args, Ac, Bc, Cc, Dc, theta, layout, U, W1, W2, Y, P0,
                  noise, umin, umax, hold, y, u, u_ff, u_fb, yd, e, status):
        _ = stamp  # in numba's cache key: see compensator.source_stamp
        nc = Ac.shape[0]
        xc = np.zeros(nc)
        xc_new = np.zeros(nc)
        (ispec, fpar, a1, b1t, a2, b2t, AM, BM, CM, DM, r_pi, mu_pi, r_inv, mu_inv) = chain_args
        mi, mf, ms = planner_memo(ispec[_P] + 1)
        for k in range(rs.shape[0]):
            stage_step(theta, layout, U, W1, W2, Y, P0 + k)  # y(k) from u(k-1) and before
            y[k] = Y[P0 + k]
            x_ff, uf, ydk, st = chain_step(x_ff, rs[k], ispec, fpar, a1, b1t, a2, b2t, AM, BM, CM,
                                           DM, r_pi, mu_pi, r_inv, mu_inv, mi, mf, ms)
            ek = ydk - (y[k] + noise[k])
            if hold and (st & 8):
                ek = 0.0
            ub = Dc[0] * ek
            for i in range(nc):
                ub += Cc[i] * xc[i]
            uc = uf + ub
            ua = min(max(uc, umin), umax)
            du = ua - uc
            for i in range(nc):
                acc = Bc[i, 0] * ek + Bc[i, 1] * du
                for j in range(nc):
                    acc += Ac[i, j] * xc[j]
                xc_new[i] = acc
            for i in range(nc):
                xc[i] = xc_new[i]
            U[P0 + k] = ua
            u[k] = ua
            u_ff[k] = uf
            u_fb[k] = ub
            yd[k] = ydk
            e[k] = ek
            status[k] = st

    return _run_loop


_run_loop = _stamped_run_loop(source_stamp(stage_step, chain_step, planner_memo))


def simulate_closed_loop(
    model: DuhemSandwich | PISandwich,
    y_ref: np.ndarray | Sequence[float],
    controller: FeedbackDesign | ct.LTI | None = None,
    *,
    feedforward: bool | str = True,
    plant: DuhemSandwich | None = None,
    noise: float | np.ndarray = 0.0,
    seed: int | None = 0,
    u_limits: tuple[float, float] = (0.0, 10.0),
    reference_model: ct.LTI | Literal["exact"] | None = None,
    reference_lead: int | None = None,
    preview: int | None = None,
    duhem_bound: float = DUHEM_BOUND,
    hold_while_turning: bool = True,
) -> ClosedLoopResponse:
    """The loop of :func:`closed_loop`, compiled, for a Duhem stage.

    Same signals and the same numbers as :func:`closed_loop_response` (tested), with the stage
    simulated by the model's compiled kernel.

    Parameters
    ----------
    model : DuhemSandwich or PISandwich
        The identified model the compensator inverts.
    y_ref : array_like
        Desired output, starting at rest.
    controller : FeedbackDesign, control LTI or None
        Feedback controller.
    feedforward : bool or {"inverse", "linear", "none"}
        The compensator.
    plant : DuhemSandwich, optional
        The stage driven (another parameter set, for robustness); the model by default. Its L1
        must have a delay (``q1 >= 1``): the loop has no algebraic loop then.
    noise : float or ndarray
        Sensor noise: a standard deviation in output units (white, Gaussian, from ``seed``) or
        the samples themselves.
    seed : int or None
        Seed of the noise.
    u_limits, reference_model, reference_lead, preview, duhem_bound
        As for :func:`~hystid.compensate.hysteresis_inverse.inverse`.
    hold_while_turning : bool
        As for :func:`closed_loop`.

    Returns
    -------
    ClosedLoopResponse
        Input ``y_ref``; outputs ``y, u, yd, e, u_ff, u_fb, status``.
    """
    stage = model if plant is None else plant
    if not isinstance(stage, DuhemSandwich):
        raise ValueError(
            "plant: the compiled loop drives a DuhemSandwich; use closed_loop + "
            "closed_loop_response for other plants"
        )
    if stage.structure.q1 < 1:
        raise ValueError("plant: the compiled loop needs a delay in L1 (q1 >= 1)")
    y_ref = _as_reference(y_ref)
    n = len(y_ref)
    if np.ndim(noise) == 0:
        sigma = float(noise)
        if not (np.isfinite(sigma) and sigma >= 0):
            raise ValueError(f"noise: expected a non-negative standard deviation, got {noise!r}")
        noise = sigma * np.random.default_rng(seed).standard_normal(n) if sigma else np.zeros(n)
    else:
        noise = finite_signal(noise, "noise")
        if noise.shape != (n,):
            raise ValueError(f"noise: expected {n} samples, got {noise.size}")
    kind = COMPENSATIONS[_compensation(feedforward)]
    chain = _build(model, kind=kind, u_limits=u_limits, reference_model=reference_model,
                   preview=preview, duhem_bound=duhem_bound, reference_lead=reference_lead)
    css = _controller_ss(controller, model.dt)
    Ac, Bc, Cc, Dc = (np.ascontiguousarray(np.asarray(m, float))
                      for m in (css.A, css.B, css.C[0], css.D[0]))
    P0 = stage.structure.history
    U, W1, W2, Y = (np.zeros(P0 + n) for _ in range(4))
    x_ff = chain.initial_state(y_ref)
    rs = np.ascontiguousarray(_pad_hold(y_ref, chain.advance)[chain.advance:])
    out = [np.empty(n) for _ in range(6)]
    status = np.empty(n, dtype=np.int64)
    umin, umax = (float(v) for v in u_limits)
    _run_loop(x_ff, rs, chain.args(), Ac, Bc, Cc, Dc, stage.theta, stage.structure.layout,
              U, W1, W2, Y, P0, np.ascontiguousarray(noise), umin, umax,
              bool(hold_while_turning), *out, status)
    y, u, u_ff, u_fb, yd, e = out
    return ClosedLoopResponse(np.arange(n) * model.dt, y_ref, yd, y, u, u_ff, u_fb, e, status,
                              unit=_output_unit(model))
