"""On-line identification of the ``pi-stage`` member: a separable recursion with a moving horizon.

The ``pi-stage`` member (:data:`hystid.identify.members.MEMBERS`) is a PI operator between a
static L1 (``w1 = u``) and a third-order L2 with one input delay. Its L2 is run here in
parallel form, a slow first-order branch beside a second-order (flexure mode) branch, both of
unit DC gain::

    y(k)  = sum_i mu_i x_i(k)
    x_i   = g  S(z) p_i  +  (1 - g) M(z) p_i
    S(z)  = (1 - p) z^-1 / (1 - p z^-1)                               slow real pole p
    M(z)  = (m0 + m1 z^-1) z^-1 / (1 + c1 z^-1 + c2 z^-2),  m0 = 1 + c1 + c2 - m1

with ``p = K tanh(xp)``, ``c2 = K tanh(x2)``, ``c1 = K tanh(x1) (1 + c2)``, ``K = 1 - 1e-6``
(so L2 is stable, and no branch an integrator, for every value of the search coordinates
``phi = [mu_0..mu_N-1, g, xp, x1, x2, m1]``, and ``c, d`` after them on a record that begins
in motion: the sensor's zero drifts, ``c + d t(k)`` is added to ``y(k)``, a straight line over
the window, see below). Multiplied out, it is the
member's L2 ``B(z) / A(z)`` (:func:`theta_from_stage`; :func:`stage_from_theta` goes back).
The ``pi-poly`` member's polynomial terms ``u^2, u^3`` are operators after the plays, their
``x_i`` run alike and their coefficients follow the weights in ``phi``. Why this form:

* the operator outputs ``p_i`` do not depend on the parameters (L1 is static), and the branch
  states ``S p_i``, ``M p_i`` depend on the four filter coordinates only: the prediction and
  its gradient with respect to the weights and ``g`` are exact whatever the weights were in
  the past. In the polynomial form the simulated output keeps, through the slow pole (radius
  ~0.9999 on stage A, a memory of ~1 s), the contribution of every past estimate, and the
  recursion of :class:`~hystid.identify.pi_recursive.PIRecursiveIdentifier` left even the batch
  optimum (measured: 400-480 nm held-out from a start at 25-30 nm);
* its coordinates are well conditioned: the polynomial coefficients of a pole at 0.9999 make
  an information matrix of condition ~1e13 there.

The identifier (:class:`PIStageOnline`), in the recursion's normalised units:

1. the leading rest is not counted: the warm-up clock starts at the first sample that leaves
   the first input value;
2. warm-up: the first ``warmup`` excited samples (and the last samples of the rest) are fitted
   off-line once (:func:`~hystid.identify.pi_recursive.fit_pi_output_error`'s solver), a
   bounded one-time cost. When the model it gives predicts none of the next chunk
   (:data:`REWARM_RATIO`), it is fitted again on every sample so far (while they are all in
   the window), and said;
3. two starts (``two_starts``), on a record that begins at rest: a warm-up of 0.1-0.2 s
   cannot place a creep of a second, and its fit uses the slow branch for something faster.
   A second identifier, started from the same fit with its slow branch as the batch fit's
   slow-branch start, runs beside it until the window is full; the one whose model runs
   closer to the output from rest over every sample so far is kept;
4. every sample: the branch states and their sensitivities are propagated and the estimate is
   updated by a recursive Gauss-Newton step (a recursive prediction-error method) with a
   bounded step, kept admissible;
5. every ``every`` excited samples (a chunk), a *background* re-solve of bounded size: a few
   Levenberg-Marquardt iterations on the last ``window`` samples, from the branch states at
   the window's start, with an arrival cost (a moving-horizon estimator): each chunk of
   samples that leaves the window is folded into a quadratic prior, linearised at the
   estimate of the time, and the prior's information is halved at every re-solve
   (:data:`ARRIVAL_DECAY`). Its cost, ``O(window n^2)`` per iteration, is spread over the
   samples that follow (:class:`~hystid.identify.horizon.HorizonSolve`, ``resolve_rate``
   simulated samples of work per sample), and its estimate taken at the first chunk
   boundary after it finished, the branches carried forward over the samples since its
   window ended: no ``update()`` call carries a whole re-solve, and the estimates depend on
   sample counts only. With the default ``window`` (1 s, 10 000-20 000 samples) the last
   re-solve on a record with 1 s of excitation spans all of it.

Samples the caller knows to be bad (``left_out``; ``identify`` gives those its batch fit
leaves out: the transient after a jump of the input, outliers) are run but not learned from.

The drift, on a record that begins in motion (no rest pins the sensor's zero): its clock
``t(k)`` runs 1 over the window and is moved to 0 at every chunk boundary (``c`` is then the
zero there; the estimates, the arrival cost and the covariance move with it), and ``c, d``
are marginalised out of the arrival cost before each window is solved (once the chunks leaving
it are folded in), so that the window alone fixes the line: a rate that changes is followed
once the window has passed the change. There the
window spans at most :data:`~hystid.identify.pi_batch.DRIFT_KNOT_SECONDS` (the batch fit's
straight pieces). Taken from the warm-up only, a drift that began after it was fitted as the
stage (measured on the stage-B look-alike, a drift of 0.1 um/s from 10 s: 0.38-1.14 um
held-out with the means removed, nothing said; now 0.069-0.081, the drift-free record's).

Admissible: L2 stable (by construction); with ``monotone``, a positive loading slope as well,
every cumulative sum of the weights ``mu_0 + .. + mu_i > 0``: the warm-up fit is moved into
that set (:func:`admissible_weights`) and a step that would leave it is halved (the re-solve
damps it). The batch fit does not impose it, and by default neither does this identifier: on
the helper's Bouc-Wen stage (exponent 2) the batch fit's first weight is -0.49 of the loop's
slope, and held at 0 the on-line model was 1.2-4.3x the batch fit's held-out error off
(0.95-1.35x without). Whatever the weights, a stable L2 after play operators keeps the output
bounded for a bounded input: a larger input cannot make the model diverge.
"""

from __future__ import annotations

import itertools
import math
import time
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from ..pi import PISandwich, PIStructure
from ..records import Record
from .base import Estimator, record_signals, sample_arrays, sample_floats
from .horizon import HorizonSolve
from .pi_batch import (
    drift_note,
)
from .pi_online_arrival import ARRIVAL_DECAY, ArrivalAndDrift
from .pi_online_horizon import REST_BAND, MovingHorizon
from .pi_online_kernels import _STATE_ROWS, _run, _slope, _theta_rows
from .pi_online_warmup import _REST_KEPT, WarmUp
from .pi_stage_coordinates import (
    admissible_weights,
    is_stage_structure,
    stage_from_theta,
    theta_from_stage,
)
from .result import IdentificationResult, converged_at

__all__ = ["PIStageOnline", "admissible_weights", "is_stage_structure", "stage_from_theta",
           "theta_from_stage"]

#: Default work of the running re-solve per processed sample, in simulated samples (6-10 us a
#: sample on stage A: 20 operators, 140-250 ns a simulated sample). A re-solve there takes some
#: 88 000 on average (``benchmarks/bench_pi_online.py``; a few simulations of the 10 000-sample
#: window for each of its two starts), more than the 80 000 granted over the 2 000 samples of a
#: chunk (the default ``every``): the rest is done at its boundary. With a re-solve every 500
#: samples (and 150 here) the held-out figures on stage A were the same and the identifier 3x
#: slower.
RESOLVE_RATE = 40.0
#: Default window of the re-solves (:class:`PIStageOnline`'s ``window``): this many seconds,
#: at least :data:`WINDOW` samples. A window shorter than the creep's time constant leaves the
#: slow branch to the arrival cost: on a Maxwell-slip stage with a creep of 0.5 s at 20 kHz
#: (``tests/test_pi_online_creep.py``), 10 000 samples left the on-line model 1.3-5.2x the
#: batch fit's held-out error off, 20 000 samples 0.93-1.14x.
WINDOW_SECONDS = 1.0
WINDOW = 10_000
#: ... and at most this many samples: a re-solve's work grows with its window. With 1 s at
#: 30 kHz (30 000 samples) it would be some 3 x 88 000 simulated samples on stage A's
#: operators, about the 290 000 that 12 trials a start took there (:data:`ITERATIONS`), when
#: the identifier ran 25 000 samples a second, below that rate.
WINDOW_MOST = 20_000
#: Default Levenberg-Marquardt trials per start of a re-solve. Without the monotone bound on
#: the weights (``monotone``) a re-solve on stage A used all of its trials (12 then): 290 000
#: simulated samples of work against 29 000 with the bound, and the identifier took 25 000
#: samples a second, below a 30 kHz loop's rate. With 4, 88 000 and 69 000 samples a second,
#: and the same held-out figures on stage A and the helper's stages (within 1 %; 1.14x against
#: 0.97x the batch fit on one record of the creep stage of ``tests/test_pi_online_creep.py``).
ITERATIONS = 4
#: Default samples between two re-solves (:class:`PIStageOnline`'s ``every``).
EVERY = 2000


# =========================================================================== the identifier
class PIStageOnline(WarmUp, MovingHorizon, ArrivalAndDrift, Estimator):
    """On-line identification of the ``pi-stage`` sandwich (see the module docstring).

    Keeps the estimator contract (:class:`~hystid.identify.base.Estimator`): :meth:`update`
    takes one sample and returns theta(k) in the member's parameters (:attr:`names`, record
    units); :meth:`fit` restarts and :meth:`partial_fit` continues; a non-finite output is
    skipped (the model runs on, nothing is learned from it), a non-finite input refused.

    Parameters
    ----------
    thresholds : array_like
        Play-operator thresholds in input units, relative to the record's first input value.
    structure : PIStructure, optional
        The member's structure (:func:`is_stage_structure`); ``pi-stage``'s by default.
    warmup : int
        Excited samples fitted off-line before the recursion starts (the leading rest, the
        samples before the input first moves, is not counted).
    window : int, optional
        Samples of the moving-horizon re-solve (the last ``window`` samples); by default
        :data:`WINDOW_SECONDS` of the record, at least :data:`WINDOW` and at most
        :data:`WINDOW_MOST` samples.
    every : int, optional
        Excited samples between two re-solves; by default :data:`EVERY`, or the window when
        that is shorter.
    iterations : int
        Levenberg-Marquardt trials per start of a re-solve (0: the recursion alone); a start
        stops earlier once its steps gain next to nothing
        (:data:`~hystid.identify.horizon.RTOL`). See :data:`ITERATIONS`.
    resolve_rate : float
        Work of the running re-solve done per processed sample, in simulated samples (see
        :mod:`hystid.identify.horizon`), which bounds its share of each ``update()`` call. A
        re-solve's estimate takes over at the next chunk boundary; the work it has left then
        (if any) is done in that call. The estimates do not depend on the rate.
    settle_at_end : bool
        :meth:`partial_fit` (and :meth:`fit`) end with :meth:`settle`, so that the model at
        the end of a record is the re-solve's over its last window (``identify`` runs it so);
        by default they end as ``update()`` calls would.
    skip : int
        Samples from the first one that are run but not learned from (the model's start is not
        the stage's on a record that begins in motion; the batch fit leaves the same burn-in
        out of its cost).
    left_out : sequence of (int, int)
        Spans ``[first, stop)`` of sample indices (from the first sample processed) that are
        run but not learned from, as ``skip``; ``identify`` gives the samples its batch fit
        leaves out (after a jump of the input, outliers). Learned from, the ringing after the
        jump out of rest of the helper's Maxwell-slip stage (20 kHz) held the model 1.2-1.6x
        the batch fit's held-out error off with the whole record in the window.
    offset : float, optional
        The sensor's output at rest, taken off before the recursion; by default the median
        output over the leading rest (the first output when the record does not start at
        rest). The input's rest is its first value. On a record that begins in motion (fewer
        than :data:`~hystid.identify.prepare.REST_SAMPLES` samples at the first input) a
        correction of it is estimated with the parameters (a last search coordinate), as the
        batch fit estimates the offset: held at the first output (a point of a loop's branch,
        not the stage at rest), it biased the parameters (measured on the stage-B look-alike:
        up to 1.4x the batch fit's held-out error, 1.0-1.02x with it). After a rest the rest
        pins it: estimated there too, stage A's held-out errors went from 1.03x to 1.42x the
        batch fit's and the identifier ran 4x slower. A drift of the zero is tracked beside it
        (see the module docstring).
    rest_swing : float, optional
        The stage's last excursion before its rest, input units from the rest: on a record
        that begins at rest the plays start where that excursion left them
        (:attr:`hystid.pi.PISandwich.rest_swing`) and the prediction is relative to the output
        at rest. A number is held (0: the plays virgin); ``identify(..., method="online")``
        with the default ``model="auto"`` passes the swing its batch choice found. None (the
        default): estimated once, when the two starts are chosen between (``two_starts``;
        every excited sample is then in the window), as the batch fit estimates it
        (:func:`~hystid.identify.pi_rest_swing.scan_rest_swing` with the current L1 and L2, on
        the output relative to its value at rest; the same rule for keeping it), and held
        from there. Estimated from the warm-up alone (0.2 s), a swing was kept
        on measured stage A that the batch fit does not keep.
    P0 : float
        Prior variance of every search coordinate (normalised units) before any data.
    forgetting : float
        Forgetting factor of the per-sample recursion, in (0, 1]; 1 forgets nothing.
    arrival_decay : float
        Factor, in (0, 1], on the arrival cost's information at every re-solve (1 keeps it
        whole; see :data:`ARRIVAL_DECAY`).
    slow_start : bool
        On a record that begins at rest, start the recursion from the warm-up fit with its
        slow branch moved to a time constant of :data:`~hystid.identify.pi_batch.SLOW_START_SPAN`
        of the window and half the DC gain (the batch fit's slow-branch start): a warm-up
        shorter than the creep cannot place its pole.
    monotone : bool
        Keep every cumulative sum of the play weights positive (the operator then has an
        exact inverse, :meth:`~hystid.pi.PISandwich.is_invertible`); the batch fit does not
        (a compensator then inverts the nearest such operator). Either way the model stays
        bounded for a bounded input (a stable L2 after play operators).
    two_starts : bool
        On a record that begins at rest, run a second identifier beside this one, started as
        ``slow_start`` does, until the window is full (or :meth:`settle`); then keep the one
        whose model, run from rest over every sample so far, is closer to the output (the
        batch fit chooses among its starts alike), each after a re-solve of
        :data:`~hystid.identify.pi_online_horizon.CHOICE_ITERATIONS` trials done in that
        call. Twice the work per sample until then.
    max_step : float
        Largest change of the search coordinates in one sample (normalised units).
    epsilon : float
        Stop index of :func:`~hystid.identify.result.converged_at`.
    fs : float
        Sampling rate in Hz.

    Attributes
    ----------
    theta : ndarray
        Current estimate in the member's parameters (record units).
    k : int
        Samples processed.
    n_resolves : int
        Re-solves run so far.
    n_rewarms : int
        Warm-ups fitted again because the warm-up's model predicted nothing
        (:data:`REWARM_RATIO`); each is said in the result's warnings.
    started_from : str
        ``"warm-up fit"`` or ``"slow branch"``: the start the estimate comes from
        (``two_starts``).
    swing_scan_ : dict or None
        Once the swing before the rest was estimated (``rest_swing`` None): the swing found
        (input units), whether it was kept, the RMS residual with it and from the virgin state
        (output units) and whether it was an end of the input's range.
    start_errors_ : dict
        Once the two starts were compared: each one's RMS error run from rest over the
        samples then, output units.
    choice_seconds_ : float
        Seconds of the call that chose between the two starts (their last re-solves).
    resolve_work_ : float
        Work the re-solves have done so far, in simulated samples
        (:attr:`~hystid.identify.horizon.HorizonSolve.spent`).
    e, yhat : float
        Prediction error and prediction of the last sample (output units).
    drift_per_second_ : float
        The drift of the output's zero over the last window (on a record that begins in
        motion; 0 otherwise), output units per second.
    drift_range_ : float
        How far the zero moved over the samples so far, output units.
    """

    method = "pi-stage-online"

    def __init__(
        self,
        thresholds: np.ndarray,
        structure: PIStructure | None = None,
        *,
        warmup: int = 2000,
        window: int | None = None,
        every: int | None = None,
        iterations: int = ITERATIONS,
        resolve_rate: float = RESOLVE_RATE,
        settle_at_end: bool = False,
        skip: int = 0,
        left_out: Sequence[tuple[int, int]] = (),
        offset: float | None = None,
        rest_swing: float | None = None,
        P0: float = 1.0,
        forgetting: float = 1.0,
        arrival_decay: float = ARRIVAL_DECAY,
        slow_start: bool = False,
        two_starts: bool = True,
        monotone: bool = False,
        max_step: float = 0.05,
        epsilon: float = 1e-4,
        fs: float = 10_000.0,
    ) -> None:
        s = structure or PIStructure(n_operators=len(np.ravel(thresholds)), n1a=0, n1b=1, q1=0,
                                     n2a=3, n2b=3, q2=1)
        if not is_stage_structure(s):
            raise ValueError(f"structure: expected the pi-stage shape (static L1, n2a=3, n2b=3, "
                             f"q2=1), got {s}")
        r = np.ascontiguousarray(np.asarray(thresholds, dtype=float).ravel())
        if len(r) != s.n_operators or not np.all(np.isfinite(r)) or np.any(r < 0):
            raise ValueError(f"thresholds: expected {s.n_operators} finite non-negative values")
        for label, value in (("warmup", warmup), ("window", 1 if window is None else window),
                             ("every", EVERY if every is None else every),
                             ("iterations", iterations + 1)):
            if int(value) != value or value < 1:
                raise ValueError(f"{label}: expected a positive integer, got {value!r}")
        if int(skip) != skip or skip < 0:
            raise ValueError(f"skip: expected a non-negative integer, got {skip!r}")
        try:
            spans = tuple(sorted((int(a), int(b)) for a, b in left_out))
        except (TypeError, ValueError):
            raise ValueError(f"left_out: expected (first, stop) pairs of sample indices, got "
                             f"{left_out!r}") from None
        if any(not 0 <= a < b for a, b in spans):
            raise ValueError(f"left_out: expected pairs with 0 <= first < stop, got {left_out!r}")
        if window is not None and every is not None and every > window:
            raise ValueError(f"every: expected at most window ({window}), got {every}")
        for label, value in (("P0", P0), ("max_step", max_step), ("epsilon", epsilon),
                             ("fs", fs)):
            if not (np.isfinite(value) and value > 0):
                raise ValueError(f"{label}: expected a positive finite number, got {value!r}")
        if offset is not None and not np.isfinite(offset):
            raise ValueError(f"offset: expected a finite number or None, got {offset!r}")
        try:
            swing = None if rest_swing is None else float(rest_swing)
        except (TypeError, ValueError):
            swing = math.nan
        if isinstance(rest_swing, bool) or (swing is not None and not math.isfinite(swing)):
            raise ValueError(f"rest_swing: expected None (estimated) or a finite swing in input "
                             f"units from the rest, got {rest_swing!r} (the batch fit's "
                             f"rest_swing=True/False switches its estimation)")
        if not resolve_rate > 0:  # inf allowed
            raise ValueError(f"resolve_rate: expected a positive number, got {resolve_rate!r}")
        if not 0.0 < forgetting <= 1.0:
            raise ValueError(f"forgetting: expected a value in (0, 1], got {forgetting!r}")
        if not 0.0 < arrival_decay <= 1.0:
            raise ValueError(f"arrival_decay: expected a value in (0, 1], got {arrival_decay!r}")
        self.thresholds, self.structure = r, s
        self.warmup = int(warmup)
        self.window = None if window is None else int(window)
        self._window = (min(WINDOW_MOST, max(WINDOW, int(round(WINDOW_SECONDS * fs))))
                        if window is None else self.window)
        self.every = None if every is None else int(every)
        self._every = min(EVERY, self._window) if every is None else int(every)
        self.iterations, self.resolve_rate = int(iterations), float(resolve_rate)
        self.settle_at_end, self.skip = bool(settle_at_end), int(skip)
        self.left_out = spans
        self.offset = None if offset is None else float(offset)
        self.rest_swing = swing
        self.P0, self.forgetting, self.max_step = float(P0), float(forgetting), float(max_step)
        self.epsilon, self.fs = float(epsilon), float(fs)
        self.arrival_decay = float(arrival_decay)
        self.slow_start = bool(slow_start)
        self.two_starts = bool(two_starts) and not self.slow_start
        self.monotone = bool(monotone)
        self._nslope = s.n_operators if self.monotone else 0
        self.reset()

    # ----------------------------------------------------------------- configuration
    @property
    def settings(self) -> dict[str, Any]:
        """The constructor's configuration as plain values (JSON-ready)."""
        return {"thresholds": self.thresholds.tolist(), "n_operators": self.structure.n_operators,
                "n_poly": self.structure.n_poly,
                "warmup": self.warmup, "window": self.window, "every": self.every,
                "iterations": self.iterations, "resolve_rate": self.resolve_rate,
                "settle_at_end": self.settle_at_end, "skip": self.skip,
                "left_out": [list(span) for span in self.left_out], "offset": self.offset,
                "rest_swing": self.rest_swing,
                "P0": self.P0, "forgetting": self.forgetting,
                "arrival_decay": self.arrival_decay, "slow_start": self.slow_start,
                "two_starts": self.two_starts, "monotone": self.monotone,
                "max_step": self.max_step,
                "epsilon": self.epsilon, "fs": self.fs}

    @property
    def names(self) -> tuple[str, ...]:
        """Names of the member's parameters (the entries of :attr:`theta`)."""
        return self.structure.names

    @property
    def theta(self) -> np.ndarray:
        """The current estimate in the member's parameters, record units."""
        if self._phi is None:
            return self._theta_rest.copy()
        return self._record_theta(self._phi)

    def _record_theta(self, phi: np.ndarray) -> np.ndarray:
        """The member's parameters in record units of search coordinates (a vector or rows)."""
        if phi.ndim == 1:  # one compiled call, no reshaping: update() returns it every sample
            _theta_rows(phi[np.newaxis], self._n_weights, self._theta1)
            return self._theta1[0] * self._to_record
        return theta_from_stage(phi, self._n_weights) * self._to_record

    @property
    def _n_weights(self) -> int:
        """The weights of the operators: the plays', then the polynomial terms'."""
        return self.structure.n_operators + self.structure.n_poly

    @property
    def model(self) -> PISandwich:
        """The current estimate as a :class:`~hystid.pi.PISandwich`, at rest at the first input
        value (after :attr:`rest_swing` when the record began at rest), its output there the
        offset (corrected by the estimate)."""
        model = PISandwich(self.theta, self.thresholds, self.structure, fs=self.fs,
                           name="identified PI sandwich (on-line)", u_rest=self._u0 or 0.0,
                           offset=self.offset_, rest_swing=self._swing * self._su)
        if model.rest_swing:  # the output at rest is the offset: the plays' share taken off
            model.offset -= model.hysteresis_output(0.0, model.rest_plays)
        return model

    @property
    def offset_(self) -> float:
        """The sensor's output at rest: :attr:`offset` (or the one taken from the record)
        corrected by the estimate; where the drift is tracked, the zero at the next sample."""
        if not self._tracks_drift:
            return self._y0
        c, d = self._phi[len(self.names):len(self.names) + 2]
        return self._y0 + float(c + d * self._st[0, self._n_weights]) * self._sy

    def reset(self) -> PIStageOnline:
        """Forget everything learned: at rest, before the warm-up, at sample 0.

        Returns
        -------
        PIStageOnline
            The identifier.
        """
        n = self._n_weights
        self.k = 0
        self.n_skipped = 0
        self.n_resolves = 0
        self.e = self.yhat = 0.0
        self.excited_at: int | None = None
        self.warmup_seconds_ = 0.0
        self.choice_seconds_ = 0.0  # the call that chooses between the two starts
        self.resolve_seconds_ = 0.0
        self.resolve_work_ = 0.0
        self._u0: float | None = None
        self._y0 = 0.0 if self.offset is None else self.offset
        self._tick = 0.0  # the drift's clock step per sample (1 / the window on a record in
        self._span = self._window  # motion, which spans at most DRIFT_KNOT_SECONDS there)
        self._zeros = (0.0, 0.0)  # the least and largest zero seen (normalised output)
        self._warm_rms = 0.0  # the warm-up fit's RMS residual (output units)
        self._rest: list[tuple[float, float]] = []
        self._buffer: list[tuple[float, float]] = []
        self._n_left_out = 0  # samples of the warm-up in left_out (the warm-up lasts longer)
        self._twin: PIStageOnline | None = None  # the slow-branch start, until chosen
        if self.two_starts:
            self._twin = PIStageOnline(
                self.thresholds, self.structure, warmup=self.warmup, window=self.window,
                every=self.every, iterations=self.iterations, resolve_rate=self.resolve_rate,
                settle_at_end=False, skip=self.skip, left_out=self.left_out,
                offset=self.offset, rest_swing=self.rest_swing, P0=self.P0,
                forgetting=self.forgetting, arrival_decay=self.arrival_decay, slow_start=True,
                two_starts=False, monotone=self.monotone, max_step=self.max_step,
                epsilon=self.epsilon, fs=self.fs)
        self.started_from = "warm-up fit"  # which start the estimate comes from
        self.start_errors_: dict[str, float] | None = None
        self.n_rewarms = 0  # warm-ups fitted again (see REWARM_RATIO) ..
        self._rewarm_notes: list[str] = []  # .. and what was said of each
        self._kept_rest: np.ndarray | None = None  # the rest, while a warm-up may be redone
        self._chunk_sq, self._chunk_n = 0.0, 0  # the open chunk's prediction errors
        self._phi: np.ndarray | None = None
        self._theta_rest = np.zeros(len(self.names))
        self._swing = 0.0  # the swing in force (normalised input; 0 on a record in motion)
        self.swing_scan_: dict[str, Any] | None = None  # the swing's estimate, once made
        self._su = self._sy = 1.0
        self._to_record = np.ones(n + 5)  # theta's scale from normalised to record units
        self._theta1 = np.empty((1, n + 5))
        self._rn = self.thresholds
        # the member's parameters in search coordinates (a correction of the offset is added
        # at the warm-up on a record that begins in motion)
        npar = len(self.names)
        self._P = np.eye(npar) * self.P0
        self._st = np.zeros((_STATE_ROWS, n + 1))  # the branches, and the drift's clock
        self._open = np.empty((2, self._every))  # the open chunk: u, y (normalised) ..
        self._n_open = 0  # .. its samples so far, and those at rest (_at_rest)
        self._chunk_rest = 0
        self._still = np.array([np.inf, 0.0])  # where the input stands, and for how long
        self._band: float | None = None  # how far it may move and stand still (_at_rest)
        self._chunks: list[tuple[np.ndarray, np.ndarray]] = []  # the window's whole chunks
        self._wstate = np.zeros((_STATE_ROWS, n + 1))  # the branches at the window's start
        self._arrival: tuple[np.ndarray, np.ndarray] | None = None  # estimate, information
        self._solved: np.ndarray | None = None  # the last re-solve's estimate
        self._job: HorizonSolve | None = None  # the re-solve running
        self._no_rows = np.zeros((0, npar))  # the kernel's optional outputs unused
        self._one = tuple(np.empty(1) for _ in range(4))  # update(): u, y, yhat, error
        return self

    # ----------------------------------------------------------------- one sample
    def update(self, u_k: float, y_k: float) -> np.ndarray:
        """Process one sample ``(u(k), y(k))``; returns the estimate theta(k).

        Parameters
        ----------
        u_k : float
            Input u(k), finite.
        y_k : float
            Measured y(k); when not finite the model runs on and nothing is learned.

        Returns
        -------
        ndarray
            A copy of theta(k), in the order of :attr:`names`.
        """
        if self._phi is None or self.k < self.skip or self._left_out_at(self.k, 1):
            self._process(*sample_arrays(u_k, y_k))
            return self.theta
        u, y = sample_floats(u_k, y_k)
        if not math.isfinite(y):
            self.n_skipped += 1
        # the recursion of one sample without a temporary array (beside a fast loop)
        un, yn, yhat, err = self._one
        un[0], yn[0] = (u - self._u0) / self._su, (y - self._y0) / self._sy
        self._kernel(un, yn, yhat, err, self._no_rows)
        self._book(un, yn, yhat, err)
        if self._twin is not None:
            self._twin.update(u_k, y_k)
            self._choose_when_full()
        return self.theta

    def settle(self) -> np.ndarray:
        """Let the running re-solve's estimate take over now, its remaining work done in this
        call: the estimate of the latest window (and the branches and covariance with it)
        instead of the recursion's since the last chunk boundary. For the model at the end of
        a record; beside a loop it is the burst the stepped re-solve avoids.

        Returns
        -------
        ndarray
            A copy of theta(k), in the order of :attr:`names`.
        """
        if self._twin is not None and self._phi is not None and self._twin._phi is not None:
            self._choose()
        if self._job is not None:
            self._apply()
        return self.theta

    def _process(self, u: np.ndarray, y: np.ndarray,
                 history: np.ndarray | None = None, errors: np.ndarray | None = None,
                 progress: Callable[[int, int], None] | None = None) -> None:
        """Rest, warm-up and recursion over a block of samples."""
        i, n = 0, len(u)
        measured = y
        self.n_skipped += int(np.count_nonzero(~np.isfinite(y)))
        if self.k < self.skip or self._left_out_at(self.k, n):  # run, not learned from
            y = np.array(y, dtype=float)
            y[:max(0, self.skip - self.k)] = np.nan
            for a, b in self.left_out:
                y[max(0, a - self.k):max(0, b - self.k)] = np.nan
        while i < n:
            a = i
            if self._phi is None:
                i = self._before_recursion(u, y, i, history, errors)
            else:  # the recursion up to the end of the open chunk (or of the block)
                i = min(n, i + self._every - self._n_open)
                self._recurse(u[a:i], y[a:i], None if errors is None else errors[a:i],
                              None if history is None else history[a:i])
                if progress is not None:
                    progress(i, n)
            if self._twin is not None:  # the same samples, then perhaps the choice
                self._twin._process(u[a:i], measured[a:i])
                self._choose_when_full()
                if self._twin is None and history is not None:  # as update() returns it
                    history[i - 1] = self.theta

    def _left_out_at(self, k: int, n: int) -> bool:
        """Whether samples ``k .. k + n - 1`` meet a span of :attr:`left_out`."""
        return any(a < k + n and k < b for a, b in self.left_out)

    def _before_recursion(self, u, y, i, history, errors) -> int:
        """Rest and warm-up samples from index ``i``; returns the next index."""
        if self._u0 is None:
            self._u0 = float(u[i])
        tol = REST_BAND * max(float(self.thresholds[-1]), 1e-300)
        if self.excited_at is None and abs(u[i] - self._u0) <= tol:
            self._rest = (self._rest + [(float(u[i]), float(y[i]))])[-_REST_KEPT:]
        else:
            if self.excited_at is None:
                self.excited_at = self.k
            self._buffer.append((float(u[i]), float(y[i])))
            self._n_left_out += self._left_out_at(self.k, 1)
        self.k += 1
        if len(self._buffer) - self._n_left_out >= self.warmup:
            self._warm_start()
        if history is not None:
            history[i] = self.theta
            errors[i] = np.nan
        return i + 1

    def _recurse(self, u, y, errors, history) -> None:
        """The per-sample recursion over samples that stay inside the open chunk."""
        m = len(u)
        un, yn = (u - self._u0) / self._su, (y - self._y0) / self._sy
        yhat, err = np.empty(m), np.empty(m)
        kept = self._no_rows if history is None else np.empty((m, len(self._phi)))
        self._kernel(un, yn, yhat, err, kept)
        if history is not None:  # the estimate after each sample, as theta gives it
            history[:] = self._record_theta(kept)
        if errors is not None:
            errors[:] = err * self._sy
        if self._book(un, yn, yhat, err) and history is not None:
            history[-1] = self.theta

    def _kernel(self, un, yn, yhat, err, kept) -> None:
        """The compiled recursion over normalised samples (estimate, covariance and branches
        updated in place); the samples at rest (:meth:`_at_rest`) are run, not learned from."""
        rest = self._at_rest(un)
        edges = ((0, 1) if len(un) == 1 else  # update(): no search for runs
                 (0, *(np.flatnonzero(rest[1:] != rest[:-1]) + 1).tolist(), len(un)))
        for a, b in itertools.pairwise(edges):  # runs of samples that learn or not
            _run(self._phi, self._P, 1.0, self.forgetting, self.max_step, self._rn,
                 self.structure.n_poly, un[a:b], yn[a:b], self._st, not rest[a],
                 self._no_rows, yhat[a:b], err[a:b], kept[a:b] if len(kept) else kept,
                 self._nslope)

    def _book(self, un, yn, yhat, err) -> bool:
        """The samples the recursion ran kept in the open chunk and fed to the running
        re-solve; returns whether they closed the chunk."""
        m = len(un)
        self.k += m
        self.e, self.yhat = float(err[-1] * self._sy), float(yhat[-1] * self._sy + self._y0)
        self._open[0, self._n_open:self._n_open + m] = un
        self._open[1, self._n_open:self._n_open + m] = yn
        self._n_open += m
        seen = err[np.isfinite(err)]
        self._chunk_sq += float(seen @ seen)
        self._chunk_n += len(seen)
        self._advance(un, yn)
        if self._n_open < self._every:
            return False
        if self._predicts_nothing():
            self._rewarm()
        else:
            self._close_chunk()
        self._chunk_sq, self._chunk_n = 0.0, 0
        return True

    # ----------------------------------------------------------------- a record
    def _restart(self, record: Record) -> None:
        """:meth:`reset`, and a record refused whose excited part is shorter than the
        warm-up."""
        u, _, name = record_signals(record, self.fs)
        self.reset()
        moved = np.flatnonzero(np.abs(u - u[0]) > REST_BAND * max(float(self.thresholds[-1]),
                                                                  1e-300))
        first = moved[0] if len(moved) else len(u)
        out = sum(max(0, min(b, len(u)) - max(a, first)) for a, b in self.left_out)
        if len(u) - first - out <= self.warmup:
            left = f" ({out} of them left out)" if out else ""
            raise ValueError(f"record {name!r}: {len(u) - first} excited samples{left} are too "
                             f"few for the on-line PI identifier (expected more than the "
                             f"warm-up, {self.warmup})")
        if self.skip >= moved[0] + self.warmup:
            raise ValueError(f"skip: {self.skip} samples not learned from cover the warm-up of "
                             f"record {name!r} (its {self.warmup} excited samples from sample "
                             f"{moved[0]}); expected fewer than {moved[0] + self.warmup}")

    def partial_fit(self, record: Record,
                    progress: Callable[[int, int], None] | None = None) -> IdentificationResult:
        """Run over a record from the current state, keeping the history.

        Parameters
        ----------
        record : Record
            Input and measured output at :attr:`fs`.
        progress : callable, optional
            Called as ``progress(k, n)`` after each chunk of samples.

        Returns
        -------
        IdentificationResult
            ``method="pi-stage-online"``; ``history`` has one row per sample (the member's
            parameters, record units); ``info`` holds the prediction errors (NaN at rest, in
            the warm-up and at skipped samples), their RMS over the last 10 % of the samples,
            the re-solves and the time spent.
        """
        u, y, _ = record_signals(record, self.fs)
        n, before = len(u), self.n_skipped
        history = np.empty((n, len(self.names)))
        errors = np.empty(n)
        t0 = time.perf_counter()
        self._process(u, y, history, errors, progress)
        if self.settle_at_end and n:
            history[-1] = self.settle()
        self._warn_skipped(before)
        tail = errors[-max(1, n // 10):]
        tail = tail[np.isfinite(tail)]
        info = {
            "rms_prediction_error_last10": float(np.sqrt(np.mean(tail ** 2))) if tail.size
            else None,
            "prediction_errors": errors,
            "excited_at": self.excited_at,
            "resolves": self.n_resolves,
            "seconds": time.perf_counter() - t0,
            "warmup_seconds": self.warmup_seconds_,
            "choice_seconds": self.choice_seconds_,
            "resolve_seconds": self.resolve_seconds_,
            "thresholds": self.thresholds.tolist(),
            "stable": bool(self.model.is_stable()),
            "loading_slope_min": float(_slope(self.theta, self.structure.n_operators)),
            "drift_per_second": self.drift_per_second_,
            "drift_range": self.drift_range_,
            "rewarms": self.n_rewarms,
            "started_from": self.started_from,
            "start_errors": self.start_errors_,
            "rest_swing": self._swing * self._su,
            "swing_scan": self.swing_scan_,
            "warnings": drift_note(self.drift_per_second_, self.drift_range_, self._warm_rms,
                                   _output_unit(record),
                                   "samples so far: its range; the rate is the last window's")
            + self._rewarm_notes,
        }
        return IdentificationResult(self.model, self.method, {**self.settings, "samples": n},
                                    history=history,
                                    converged_at=converged_at(history, self.epsilon), info=info)


def _output_unit(record: Any) -> str:
    """The record's output unit for a sentence (any object with ``u``, ``y`` is a record)."""
    units = getattr(record, "units", None) or {}
    return str(units.get("y") or "output units")
