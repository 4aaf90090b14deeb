"""An on-line identifier of the sandwich that converges: recursive prediction error (RPEM).

The estimate minimises the simulation (output) error of the whole sandwich, not the equation
error of eq. (12). The sandwich sees ``u - u_rest`` and the sensor reads ``y_model + offset``;
the offset is estimated with the parameters (sensitivity 1). Each sample:

1. the model runs one step with the current estimate, and the compiled sensitivity recursion
   gives ``psi(k) = d yhat(k) / d theta`` exactly through L1, the Duhem block and L2;
2. the residual ``e(k) = y(k) - yhat(k) - offset`` is clipped at ``clip`` times a running
   robust scale ``sigma(k)`` (a burst of bad samples moves the estimate by a bounded amount);
3. a recursive Gauss-Newton step with forgetting factor ``lambda(k)``::

       K(k)     = P(k-1) psi / (lambda(k) + psi^T P(k-1) psi)
       theta(k) = theta(k-1) + K(k) e(k)
       P(k)     = (P(k-1) - K(k) psi^T P(k-1)) / lambda(k)

   where ``lambda(k)`` rises from ``lambda0`` to ``1 - 1/memory`` and ``trace(P)`` is capped;
4. projection: a step that leaves the admissible set (alpha > 0, L1 and L2 stable and minimum
   phase: Assumption 1; ``alpha |dw1| < 2``: condition 8) is not taken.

Start-up: a cold start from theta = 0.01 is a local minimum for any gradient method (the
measured facts: 400 samples are not enough for a batch fit from there). The identifier collects
the first ``n_start`` samples and solves the output-error problem on them
(:func:`~hystid.identify.offline.fit_output_error`: the batch fit's preparation, rest level,
offset and data-driven starts) and runs the recursion from that solution with ``P`` set to the
inverse Gauss-Newton information. The start is **checked** (:func:`check_start`): the simulation
error must reach its own noise estimate (from the residual's sample-to-sample differences: a
white residual is noise, a smooth one is a misfit) and beat the linear baseline
(:class:`hystid.baselines.LinearModel` of :func:`hystid.baselines.baseline_orders`). The check
runs on the start-up window and again, on
the running estimate, once ``start_retries`` samples (1 000 and 3 000 by default) have come,
most of which the start-up solve never saw -- a window can be fitted to its noise by a wrong
solution when it does not excite the stage enough. When such a check fails the problem is
solved again on all the samples so far (from theta0 and the data-driven starts, as the batch
fit starts, and from the best solution so far) and the recursion restarts from the better of
the two. A mismatch that persists to the last window is a warning in ``info["warnings"]``, and
``converged_at`` is then never reported.

Divergence watch: the short-term residual RMS is compared with its long-term level; when it
exceeds ``diverge_ratio`` times that level for ``diverge_hold`` samples the estimate is declared
diverging, a warning is issued and the identifier restarts from the last estimate that had a
low residual, with ``P`` reset. A supervisor (:mod:`~hystid.identify.online_supervisor`)
rolls the recursion back to the last validated estimate when it diverges or wanders.

State: every array of the recursion lives in one preallocated buffer (signal windows as linear
ring buffers of ``window + block`` samples that slide back when full), so :meth:`update` is one
compiled call per sample with no allocation.
"""

from __future__ import annotations

import math
import warnings
from dataclasses import asdict
from typing import TYPE_CHECKING, Any

import numpy as np

from ..kernels import sensitivities_into
from ..model import DuhemSandwich, Structure
from ..records import Record
from ._recursive import RecursiveIdentifier
from .base import as_sample
from .offline import fit_output_error
from .online_start import StartUpCheck, check_start
from .online_supervisor import Supervisor
from .prepare import IdentificationDataError

if TYPE_CHECKING:  # pragma: no cover
    from .result import HistoryRecorder, IdentificationResult

from .online_kernels import (
    _DW1MAX,
    _FIRST,
    _I_CAP,
    _I_NPAR,
    _I_POS,
    _I_W,
    _K,
    _LAM,
    _LONG,
    _NCLIP,
    _NINTS,
    _NPRESET,
    _NPROJ,
    _NREC,
    _SHORT,
    _SIG,
    ALPHA_MARGIN,
    DIAGNOSTICS,
    _buffer_size,
    _views,
    rpem_one,
    rpem_run,
)

__all__ = ["DIAGNOSTICS", "N_START", "START_RETRIES", "OnlineIdentifier", "StartUpCheck",
           "check_start"]

#: Default length of the start-up window, in samples.
N_START = 400
#: Default longer windows solved again when the start-up check fails. On measured stage A
#: (10 kHz, 1 s of PRBN) every check fails (the model's error is far above the sensor noise)
#: and the solve on 3 000 samples sits in a wrong basin the recursion never leaves (held out
#: 70-81 nm); the last window of 10 000 samples lands where the batch fit does (40-78 nm
#: against 39-78 nm). A one-time, bounded cost, paid only while the check fails.
START_RETRIES = (1_000, 3_000, 10_000)
#: Samples of a leading hold kept at the head of the start-up window (the rest level).
REST_KEEP = 50
#: A start-up solution whose error anywhere in its window exceeds this many times the output's
#: range has run away: it is not taken as a start while another is at hand.
RUNAWAY = 2.0
# =========================================================================== the identifier
class OnlineIdentifier(RecursiveIdentifier):
    """Converging on-line identifier of the Duhem sandwich (recursive prediction error).

    Parameters
    ----------
    structure : Structure, optional
        Orders, delays and the f0 option; the paper's experimental structure by default.
    fs : float
        Sampling rate in Hz.
    theta0 : float, dict or array
        Initial estimate (0.01 for every parameter, as in the paper). An inadmissible start
        (unstable L1/L2, alpha <= 0) is projected onto the admissible set with a warning.
    n_start : int
        Samples collected before the start-up solve (see the module docstring).
    start_retries : sequence of int
        Longer windows solved again, in turn, while the start-up check fails.
    u_rest : float, optional
        Input level at which the stage rests before the record. By default the start-up solve
        finds it as the batch fit does (:func:`hystid.identify.prepare.rest_level`: a leading
        constant segment, or the first sample); a number is taken off the input first.
    offset : float, optional
        Sensor offset (the output at rest). By default it is estimated in the start-up solve
        and tracked by the recursion (sensitivity 1); a number fixes it.
    memory : float
        Asymptotic memory in samples: ``lambda -> 1 - 1/memory``. Shorter tracks faster
        parameter changes, longer averages the noise better.
    lambda0 : float
        Forgetting factor right after start-up; rises to ``1 - 1/memory`` with time constant
        ``lambda_time`` samples.
    lambda_time : float
        Time constant of that rise, in samples.
    clip : float
        Residuals beyond ``clip`` running standard deviations are clipped.
    trace_max : float
        Cap on ``trace(P)`` (prevents covariance wind-up when excitation fades).
    diverge_ratio, diverge_hold : float, int
        Divergence is declared when the short-term residual RMS stays above ``diverge_ratio``
        times the long-term RMS for ``diverge_hold`` samples.
    epsilon : float
        Stop index for ``converged_at`` (1e-4).
    supervise : bool
        Roll the recursion back to the last validated estimate when it diverges or wanders
        (:mod:`~hystid.identify.online_supervisor`).
    history : {"decimated", "full", "none"}
        Parameter history kept by :meth:`fit`: by default at most ``history_rows`` rows (every
        m-th sample), so that a long run stays small.
    history_rows : int
        Rows kept by ``history="decimated"``.
    block : int
        Samples of room in the signal windows before they slide back.

    Attributes
    ----------
    theta : ndarray
        Current estimate (a view of the state: assigning into it changes the estimate).
    offset_estimate : float
        Current sensor-offset estimate.
    u_rest_ : float or None
        The input rest level in use (None before the start-up solve).
    P : ndarray
        Current covariance-like matrix of the Gauss-Newton recursion (theta, then the offset).
    start_checks : list of StartUpCheck
        The start-up solutions tried and their checks.
    start_warnings : list of str
        A start-up check that never passed, in words.

    Notes
    -----
    :attr:`model` is the recursion's estimate, as :meth:`fit` returns it too, with the Duhem
    state at rest (``rest_memory``) and the offset of its start-up solve. A stage at rest after
    earlier excitation sits on one branch of its loop:
    ``hystid.identify.identify(record, model="duhem", method="online")`` places the model after
    the run (:func:`hystid.identify.place_after_run`: the Duhem state at rest and the offset
    fitted again on the whole record), as the batch fit does. On measured stage A (fitted on
    prbn_1) the recursion's model is 38 / 88 nm off prbn_2 / tri50_1, placed 40 / 78 nm (it
    started from the loop's centre before, 129 / 117 nm).
    """

    method = "online"
    divergence_reason = ("the residual diverged (short-term RMS above diverge_ratio x "
                         "long-term, or far above the last validated estimate's)")
    n_diagnostics = len(DIAGNOSTICS)

    def __init__(
        self,
        structure: Structure | None = None,
        fs: float = 30_000.0,
        *,
        theta0=0.01,
        n_start: int = N_START,
        start_retries: tuple[int, ...] = START_RETRIES,
        u_rest: float | None = None,
        offset: float | None = None,
        memory: float = 100_000.0,
        lambda0: float = 0.9999,
        lambda_time: float = 2_000.0,
        clip: float = 4.0,
        trace_max: float = 1e4,
        diverge_ratio: float = 20.0,
        diverge_hold: int = 200,
        epsilon: float = 1e-4,
        supervise: bool = True,
        history: str = "decimated",
        history_rows: int = 100_000,
        block: int = 4_096,
    ) -> None:
        if int(n_start) != n_start or n_start < 50:
            raise ValueError(f"n_start: expected an integer >= 50 samples, got {n_start!r}")
        retries = tuple(start_retries)
        if any(int(r) != r or r <= n_start for r in retries) or list(retries) != sorted(retries):
            raise ValueError(f"start_retries: expected increasing sample counts above n_start "
                             f"({n_start}), got {start_retries!r}")
        if not (memory > 1):
            raise ValueError(f"memory: expected more than 1 sample, got {memory!r}")
        if not (0 < lambda0 <= 1):
            raise ValueError(f"lambda0: expected a value in (0, 1], got {lambda0!r}")
        for name, value in (("lambda_time", lambda_time), ("clip", clip),
                            ("trace_max", trace_max), ("diverge_ratio", diverge_ratio),
                            ("diverge_hold", diverge_hold), ("block", block)):
            if not (np.isfinite(value) and value > 0):
                raise ValueError(f"{name}: expected a positive number, got {value!r}")
        for name, value in (("u_rest", u_rest), ("offset", offset)):
            if value is not None and not np.isfinite(value):
                raise ValueError(f"{name}: expected a finite number or None, got {value!r}")
        self.n_start = int(n_start)
        self.start_retries = tuple(int(r) for r in retries)
        self.u_rest = None if u_rest is None else float(u_rest)
        self.offset = None if offset is None else float(offset)
        self.memory = float(memory)
        self.lambda0 = float(lambda0)
        self.lambda_time = float(lambda_time)
        self.clip = float(clip)
        self.trace_max = float(trace_max)
        self.diverge_ratio = float(diverge_ratio)
        self.diverge_hold = int(diverge_hold)
        self.block = int(block)
        self.supervise = bool(supervise)
        super().__init__(structure, fs, theta0, epsilon, history, history_rows)

    # ----------------------------------------------------------------- state
    def _allocate(self) -> None:
        from .constraints import is_admissible, project_admissible

        theta = self.__dict__.pop("theta", None)  # set by reset(); from now on a state view
        if theta is None:  # a reset: the setter wrote theta0 into the previous state
            theta = self._est[:-1].copy()
        if not is_admissible(theta, self.structure):
            warnings.warn(
                "online: theta0 is outside the admissible set (alpha > 0, stable and "
                "minimum-phase L1, L2); projected onto it", RuntimeWarning, stacklevel=4)
            theta = project_admissible(theta, self.structure)
        npar = len(theta)
        cap = self.window + self.block
        self._ints = np.zeros(_NINTS, dtype=np.int64)
        self._ints[:10] = self.structure.layout
        self._ints[_I_NPAR], self._ints[_I_W], self._ints[_I_CAP] = npar, self.window, cap
        self._buf = np.zeros(_buffer_size(npar, cap))
        self._bind_views()
        self._n_rec_seen = 0
        self._est[:npar] = theta
        self._est[npar] = 0.0 if self.offset is None else self.offset
        self.P[:] = np.eye(npar + 1)
        self._scal[_LAM] = self.lambda0
        self._scal[_FIRST] = -1.0
        self._diag[:] = np.nan
        self._sett[:] = [1.0 - 1.0 / self.memory, np.exp(-1.0 / self.lambda_time), self.clip,
                         self.trace_max, self.diverge_ratio, float(self.diverge_hold),
                         min(1.0, self.trace_max / (npar + 1)), 1.0 - 1e-6, 1.0 / 50.0,
                         1.0 / 5_000.0, 1.0 / 500.0, float(self.offset is None)]
        self._start_u = np.zeros(max((self.n_start, *self.start_retries)))
        self._start_y = np.zeros_like(self._start_u)
        self._stages = [self.n_start, *self.start_retries]
        self._running = False
        self.u_rest_: float | None = self.u_rest
        self.rest_memory_ = 0.0
        self.start_checks: list[StartUpCheck] = []
        self.start_info: dict = {}
        self.start_warnings: list[str] = []
        self._tried: list = []
        self._filled = 0
        self._verify_at: int | None = None
        self._u_first: float | None = None
        self._rest_u = self._rest_y = np.zeros(0)
        self._candidate: DuhemSandwich | None = None
        self._supervisor = Supervisor(self.diverge_ratio) if self.supervise else None

    _VIEWS = ("_est", "P", "_est_good", "_P_good", "_scal", "_sett", "_diag", "_windows",
              "_theta_view")

    def _bind_views(self) -> None:
        """Name the parts of the packed state (numpy views of ``_buf``)."""
        (self._est, self.P, self._est_good, self._P_good, self._scal, self._sett, self._diag,
         *rest) = _views(self._buf, self._ints)
        self._windows = tuple(rest[3:11])
        self._theta_view = self._est[:-1]

    def __getstate__(self) -> dict[str, Any]:
        """State for copy and pickle: the packed buffer, without its views."""
        return {k: v for k, v in self.__dict__.items() if k not in self._VIEWS}

    def __setstate__(self, state: dict[str, Any]) -> None:
        """Restore the state and bind the views to the restored buffer."""
        self.__dict__.update(state)
        self._bind_views()

    @property
    def theta(self) -> np.ndarray:
        """Current estimate theta(k) (a view of the state)."""
        return self._est[:-1]

    @theta.setter
    def theta(self, value: np.ndarray) -> None:
        if "_est" in self.__dict__:
            self._est[:-1] = value
        else:
            self.__dict__["theta"] = np.asarray(value, float)

    @property
    def offset_estimate(self) -> float:
        """Current sensor-offset estimate (output units)."""
        return float(self._est[-1])

    @property
    def started(self) -> bool:
        """True once the start-up solve has run and the recursion is on."""
        return self._running

    @property
    def n_recoveries(self) -> int:
        """Restarts after a divergence."""
        return int(self._scal[_NREC]) if "_scal" in self.__dict__ else 0

    @n_recoveries.setter
    def n_recoveries(self, value: int) -> None:
        if "_scal" in self.__dict__:
            self._scal[_NREC] = value

    @property
    def first_recovery(self) -> int | None:
        """Sample of the first restart (None: none)."""
        if "_scal" not in self.__dict__ or self._scal[_FIRST] <= 0:
            return None
        return int(self._scal[_FIRST])

    @first_recovery.setter
    def first_recovery(self, value: int | None) -> None:
        if "_scal" in self.__dict__:
            self._scal[_FIRST] = -1.0 if value is None else value

    # ----------------------------------------------------------------- start-up
    def _restart(self, record: Record) -> None:
        """:meth:`reset`; on a record whose excitation ends before the longest start-up window,
        that window is the whole excitation (a short record still gets its start-up solve
        checked and retried on all its samples, not on a window it never fills)."""
        from .base import record_signals

        u, _, _ = record_signals(record, self.fs)
        self.reset()
        tol = 1e-12 * max(1.0, abs(float(u[0]))) if len(u) else 0.0
        moving = np.flatnonzero(np.abs(u - u[0]) > tol)
        if not len(moving):
            return
        excited = len(u) - int(moving[0]) + min(REST_KEEP, int(moving[0]))
        if self.n_start < excited < self._stages[-1]:
            self._stages = [s for s in self._stages if s < excited] + [excited]

    def _window(self, n: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The first ``n`` buffered samples: input, output, which outputs are finite."""
        y = self._start_y[:n]
        return self._start_u[:n], y, np.isfinite(y)

    def _solve(self, n: int) -> tuple[DuhemSandwich, str]:
        """Output-error solve on the first ``n`` samples (the batch fit's preparation, rest
        level, offset and starts: theta0 and the data-driven ones), on a retry from the best
        solution so far too (besides those starts, not instead of theta0: a solution that fit a
        shorter window may sit in a basin that the longer window shows to be wrong)."""
        u, y, ok = self._window(n)
        if not ok.any():
            raise ValueError("online: every output sample of the start-up window is non-finite")
        y = y.copy()
        if not ok.all():  # fill skipped samples by interpolation for the start-up solve only
            idx = np.arange(n)
            y[~ok] = np.interp(idx[~ok], idx[ok], y[ok])
        shift_u = self.u_rest or 0.0
        shift_y = self.offset or 0.0
        rec = Record(u - shift_u, y - shift_y, self.fs, name="start-up window")
        more = {}
        if self._tried:
            # by their error on this window (each check's own RMS is over a shorter one)
            more["best so far"] = min(self._tried, key=lambda t: self._rms_on(t[1], n))[1].theta
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            fit = fit_output_error(rec, self.structure, self.theta0, offset=self.offset is None,
                                   max_nfev=100, starts=more)
        m = fit.model
        model = DuhemSandwich(m.theta, self.structure, fs=self.fs, u_rest=m.u_rest + shift_u,
                              offset=m.offset + shift_y, rest_memory=m.rest_memory)
        label = fit.info.get("start", "theta0")
        return model, label if not self._tried else f"{label} (retry on {n} samples)"

    def _try_start(self, n: int) -> bool:
        """Solve and check on ``n`` samples; returns whether the check passed."""
        try:
            model, label = self._solve(n)
        except IdentificationDataError as exc:  # e.g. the input has not moved enough yet
            if n == self._stages[-1]:
                raise
            self.start_checks.append(StartUpCheck(n, np.nan, np.nan, np.nan, str(exc), False))
            return False
        u, y, ok = self._window(n)
        with np.errstate(all="ignore"):
            yhat = model.simulate(u, check=False).y
            miss = np.abs(yhat[ok] - y[ok])
        check = check_start(u[ok], y[ok], yhat[ok], self.structure, self.fs, label)
        self.start_checks.append(check)
        # a solution that runs away on its own window (condition 8 broken where the solve did
        # not score, past an input jump) is no start, unless there is nothing else
        runaway = not (np.all(np.isfinite(miss))
                       and np.max(miss, initial=0.0) <= RUNAWAY * max(float(np.ptp(y[ok])),
                                                                      1e-300))
        if not runaway or self._candidate is None:
            self._tried.append((check, model))
            self._candidate = model
        if check.passed:
            return True
        if n == self._stages[-1]:  # no longer window left: keep the best, say so
            self._candidate = min(self._tried, key=lambda t: self._rms_on(t[1], n))[1]
            self.start_warnings.append(
                f"start-up: the solution on {n} samples fails its check: {check.reason()} "
                f"(tried {', '.join(str(c.samples) for c in self.start_checks)} samples); the "
                "estimate may sit in a wrong basin")
        return False

    def _rms_on(self, model: DuhemSandwich, n: int, start: int = 0) -> float:
        u, y, ok = self._window(n)
        e = (y - model.simulate(u, check=False).y)[start:][ok[start:]]
        return float(np.sqrt(np.mean(e ** 2)))

    def _hold(self, model: DuhemSandwich) -> None:
        """Show a start-up solution as the estimate (the recursion is not on yet)."""
        self._est[:-1] = model.theta
        self._est[-1] = model.offset
        self.u_rest_ = model.u_rest
        self.rest_memory_ = model.rest_memory

    def _start(self, n: int, k: int) -> None:
        """Start the recursion on the first ``n`` buffered samples (sample ``k`` of the run)."""
        model = self._candidate
        self._hold(model)
        theta, offset = model.theta, model.offset
        s = self.structure
        u, y, ok = self._window(n)
        u = u - model.u_rest
        npar = len(theta)
        Pp = s.history
        U, W1, W2, Y = (np.zeros(Pp + n) for _ in range(4))
        U[Pp:] = u
        past = model.at_rest()  # a window that starts on a branch of the loop (rest_memory)
        for name, arr in (("w2", W2), ("y", Y)):
            arr[:Pp] = past.window(name, Pp)
        S1, S2, SY = (np.zeros((Pp + n, npar)) for _ in range(3))
        sensitivities_into(theta, s.layout, U, W1, W2, Y, S1, S2, SY, Pp)
        # condition (8) over the window: the recursion keeps alpha below 2 / max|dw1| from here
        dw1max = float(np.max(np.abs(np.diff(W1[Pp:])), initial=0.0))
        i_alpha = s.names.index("alpha")
        if dw1max > 0 and theta[i_alpha] * dw1max >= 2.0 * ALPHA_MARGIN:
            theta = theta.copy()
            theta[i_alpha] = 2.0 * ALPHA_MARGIN / dw1max
            sensitivities_into(theta, s.layout, U, W1, W2, Y, S1, S2, SY, Pp)
        r = (y - Y[Pp:] - offset)[ok]
        sigma = max(float(np.sqrt(np.mean(r**2))), 1e-12)
        J = SY[Pp:][ok]
        if self.offset is None:
            J = np.column_stack([J, np.ones(len(J))])
        info = J.T @ J
        P = np.linalg.pinv(info + 1e-9 * np.trace(info) / len(info) * np.eye(len(info)))
        self.P[:] = 0.0
        self.P[:len(P), :len(P)] = P
        self._est[:npar] = theta
        self._est[npar] = offset
        self._est_good[:] = self._est
        self._P_good[:] = self.P
        Ym = np.concatenate([np.zeros(Pp), np.where(np.isfinite(y), y - offset, Y[Pp:])])
        w = self.window
        for dst, src in zip(self._windows, (U, W1, W2, Y, Ym, S1, S2, SY), strict=True):
            m = min(w, len(src))
            dst[w - m:w] = src[len(src) - m:]
        self._ints[_I_POS] = w
        self._scal[_SIG] = sigma
        self._scal[_SHORT] = self._scal[_LONG] = sigma**2
        self._scal[_DW1MAX] = dw1max
        self._scal[_K] = k
        last = self.start_checks[-1]
        self.start_info = {"rms_residual": sigma, "start": last.start, "samples": n,
                           "checks": [asdict(c) for c in self.start_checks]}
        self._running = True
        if self._supervisor is not None:  # the start is the first validated estimate
            self._supervisor.floor = 1e-9 * max(float(np.std(y[ok])), 1e-300)
            self._supervisor.reset(self, k + self.n_start)

    def _collect(self, u: np.ndarray, y: np.ndarray, history: np.ndarray,
                 diagnostics: np.ndarray) -> int:
        """Buffer start-up samples (solving at each stage); returns how many were taken.

        A leading hold (the input at its first value) is not buffered beyond its last
        :data:`REST_KEEP` samples: the windows count from the end of the hold.
        """
        take = 0
        while take < len(u) and not self._running:
            history[take:] = self.theta
            diagnostics[take:] = np.nan
            diagnostics[take:, -1] = self._est[-1]
            if self._filled == 0:
                take = self._hold_samples(u, y, take)
                if take == len(u):
                    break
            stage = next(s for s in self._stages if s > self._filled)
            m = min(len(u) - take, stage - self._filled)
            a = self._filled
            self._start_u[a:a + m] = u[take:take + m]
            self._start_y[a:a + m] = y[take:take + m]
            self._filled += m
            take += m
            if self._filled == stage:
                self._try_start(stage)
                if self._candidate is not None:  # start; later stages check it on new samples
                    self._start(stage, self.k + take)
                    self._verify_at = self._next_stage(stage)
                history[take - 1] = self.theta
        return take

    def _next_stage(self, n: int) -> int | None:
        return next((s for s in self._stages if s > n), None)

    def _verify(self, n: int, k: int) -> None:
        """Check the running estimate on all ``n`` buffered samples (most of them not seen by
        the start-up solve); when it fails, solve again on them and restart from the solution
        if it is the better one over the window's last third (a running estimate that tracks
        a drifting stage fits the recent samples best; one in a wrong basin fits none)."""
        current = self.model
        u, y, ok = self._window(n)
        yhat = current.simulate(u, check=False).y
        check = check_start(u[ok], y[ok], yhat[ok], self.structure, self.fs,
                            f"estimate at sample {n}")
        self.start_checks.append(check)
        self._verify_at = self._next_stage(n)
        if check.passed:
            return
        self._tried.append((check, current))
        self._try_start(n)
        recent = (2 * n) // 3
        if self._rms_on(self._candidate, n, recent) < self._rms_on(current, n, recent):
            self._start(n, k)
        else:  # the report lists every check, the restarts' and the others'
            self.start_info["checks"] = [asdict(c) for c in self.start_checks]

    def _hold_samples(self, u: np.ndarray, y: np.ndarray, take: int) -> int:
        """Pass over a leading hold; when the input moves, start the buffer with its end."""
        if self._u_first is None:
            self._u_first = float(u[take])
        tol = 1e-12 * max(1.0, abs(self._u_first))
        moving = np.flatnonzero(np.abs(u[take:] - self._u_first) > tol)
        end = take + (int(moving[0]) if len(moving) else len(u) - take)
        self._rest_u = np.r_[self._rest_u, u[take:end]][-REST_KEEP:]
        self._rest_y = np.r_[self._rest_y, y[take:end]][-REST_KEEP:]
        if end < len(u):
            r = len(self._rest_u)
            self._start_u[:r], self._start_y[:r] = self._rest_u, self._rest_y
            self._filled = r
        return end

    def _run(self, u, y, history, diagnostics) -> None:
        done = 0
        if not self._running:
            done = self._collect(u, y, history, diagnostics)
        sup = self._supervisor  # supervises once the start-up checks are over
        while done < len(u):
            stop = len(u)
            if self._verify_at is not None:  # keep buffering until the next check
                stop = min(stop, done + self._verify_at - self._filled)
                a = self._filled
                self._start_u[a:a + stop - done] = u[done:stop]
                self._start_y[a:a + stop - done] = y[done:stop]
                self._filled += stop - done
            elif sup is not None:
                stop = min(stop, done + sup.room)
            rel = np.ascontiguousarray(u[done:stop] - (self.u_rest_ or 0.0), float)  # as update
            rpem_run(self._buf, self._ints, rel, np.ascontiguousarray(y[done:stop], float),
                     history[done:stop], diagnostics[done:stop])
            if (sup is not None and self._verify_at is None
                    and sup.feed(self, rel, y[done:stop], diagnostics[done:stop, 0],
                                 self.k + stop)):
                history[stop - 1] = self.theta
            elif self._verify_at is not None and self._filled == self._verify_at:
                self._verify(self._filled, self.k + stop)
                history[stop - 1] = self.theta
                if sup is not None and self._verify_at is None:  # the estimate that passed
                    sup.reset(self, self.k + stop + self.n_start)
            done = stop
        self._n_rec_seen = self.n_recoveries

    def update(self, u_k: float, y_k: float) -> np.ndarray:
        """Process one sample ``(u(k), y(k))``: one compiled call, no allocation.

        Parameters
        ----------
        u_k : float
            Input sample; a non-finite one is an error.
        y_k : float
            Output sample; a non-finite one is skipped (counted in :attr:`n_skipped`).

        Returns
        -------
        ndarray
            The estimate theta(k), a copy.
        """
        if (self._verify_at is None and self._running and isinstance(u_k, float)
                and isinstance(y_k, float) and u_k - u_k == 0.0):  # the real-time path
            v = u_k - (self.u_rest_ or 0.0)  # the recursion's windows hold u - u_rest
            n_rec = rpem_one(self._buf, self._ints, v, y_k)
            self.k += 1
            if self._supervisor is not None:  # a rollback is a recovery
                n_rec += self._supervisor.feed_one(self, v, y_k, self._diag[0], self.k)
            if y_k - y_k != 0.0:
                self.n_skipped += 1
            if n_rec != self._n_rec_seen:
                self._warn_recoveries(self._n_rec_seen)
                self._n_rec_seen = n_rec
            return self._theta_view.copy()
        if not self._running or self._verify_at is not None:
            return super().update(u_k, y_k)
        u, y = as_sample(u_k, "u_k"), as_sample(y_k, "y_k")
        if not math.isfinite(u):
            raise ValueError(f"u_k: expected a finite input sample, got {u_k!r}")
        return self.update(u, y)

    # ----------------------------------------------------------------- intermediates
    @property
    def psi(self) -> np.ndarray:
        """Last output sensitivity d yhat(k) / d theta."""
        return self._windows[-1][self._ints[_I_POS] - 1].copy()

    @property
    def e(self) -> float:
        """Last residual y(k) - yhat(k) - offset."""
        return float(self._diag[0])

    @property
    def sigma(self) -> float:
        """Running robust residual scale."""
        return float(self._scal[_SIG])

    @property
    def n_projections(self) -> int:
        """Steps refused because they left the admissible set."""
        return int(self._scal[_NPROJ])

    @property
    def n_covariance_resets(self) -> int:
        """Times P lost positive definiteness (or hit the trace cap) and was reset."""
        return int(self._scal[_NPRESET])

    @property
    def n_clipped(self) -> int:
        """Residuals clipped as outliers."""
        return int(self._scal[_NCLIP])

    @property
    def diagnostics(self) -> dict[str, float]:
        """Monitored quantities at the last sample."""
        return dict(zip(DIAGNOSTICS, map(float, self._diag), strict=True))

    @property
    def model(self) -> DuhemSandwich:
        """The model of the current estimate, at the rest level and sensor offset in use."""
        return DuhemSandwich(self.theta.copy(), self.structure, fs=self.fs,
                             name=f"{self.method} estimate", u_rest=self.u_rest_ or 0.0,
                             offset=self.offset_estimate, rest_memory=self.rest_memory_)

    def result(self, recorder: HistoryRecorder | None = None) -> IdentificationResult:
        """The current estimate as an IdentificationResult (with start-up and guard counts).

        Parameters
        ----------
        recorder : HistoryRecorder, optional
            The history of the run.

        Returns
        -------
        IdentificationResult
            ``info["warnings"]`` holds a failed start-up check; ``converged_at`` is then None.
        """
        res = super().result(recorder)
        res.info.update({"n_projections": self.n_projections, "n_clipped": self.n_clipped,
                         "n_covariance_resets": self.n_covariance_resets,
                         "start_up": self.start_info, "u_rest": self.u_rest_,
                         "offset": self.offset_estimate})
        res.info["warnings"] = list(self.start_warnings)
        sup = self._supervisor
        if sup is not None:
            res.info["supervisor"] = sup.info()
            if sup.n_rollbacks:
                res.info["warnings"].append(
                    f"online: the recursion was rolled back to the last validated estimate "
                    f"{sup.n_rollbacks} time(s), first {sup.first_reason}")
        if self.start_warnings or not self._running:
            res.converged_at = None
        return res

    @property
    def settings(self) -> dict[str, Any]:
        """The configuration, JSON-ready."""
        return {**super().settings, "n_start": self.n_start,
                "start_retries": list(self.start_retries), "u_rest": self.u_rest,
                "offset": self.offset, "memory": self.memory, "lambda0": self.lambda0,
                "lambda_time": self.lambda_time, "clip": self.clip,
                "trace_max": self.trace_max, "diverge_ratio": self.diverge_ratio,
                "diverge_hold": self.diverge_hold, "block": self.block,
                "supervise": self.supervise}
