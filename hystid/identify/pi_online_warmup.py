"""The ``pi-stage`` on-line identifier's start: the warm-up fit, a warm-up fitted again when
its model predicts nothing, the second start beside it, and the bound on the slow pole (see
:mod:`hystid.identify.pi_online`).

:class:`WarmUp` holds these steps of :class:`~hystid.identify.pi_online.PIStageOnline`, which
inherits them; they read and set its state.
"""

from __future__ import annotations

import math
import time

import numpy as np

from ..pi_operator import rest_plays
from .horizon import covariance
from .pi_batch import SLOW_START_LONGEST, _scale_weights, _weights_given_blocks, with_slow_branch
from .pi_online_kernels import _KMAX, _STATE_ROWS
from .pi_stage_coordinates import admissible_weights, stage_from_theta, theta_from_stage
from .prepare import REST_SAMPLES

__all__ = ["REWARM_RATIO", "REWARM_SPREAD", "WARMUP_NFEV", "WARMUP_SCREEN", "WarmUp"]

#: Rest samples kept before the excitation for the warm-up fit.
_REST_KEPT = 200
#: Evaluations of the warm-up fit: each start screened for :data:`WARMUP_SCREEN`, the best
#: polished for at most :data:`WARMUP_NFEV` (the batch fit's 25 and 200). The warm-up only
#: starts the recursion: the first re-solve, in the same call, solves its samples again, and
#: every later one the growing window. On stage A the held-out figures are the same to 0.1 nm
#: with 254 evaluations or 45, and the warm-up call takes a fifth of the time
#: (``benchmarks/bench_pi_online.py``).
WARMUP_SCREEN = 10
WARMUP_NFEV = 25
#: The warm-up is fitted again (on every excited sample so far, while they all are in the
#: window) when the prediction errors over a chunk after it exceed both this many times the
#: warm-up fit's residual and :data:`REWARM_SPREAD` of the output's spread over that chunk:
#: its model predicts nothing. On the helper's Maxwell-slip stage (20 kHz) a record that ramps
#: for 2 000 samples before 10 s of band-limited noise was warmed up on the ramp alone: the
#: flexure's coordinates went where their gradient vanishes, the prediction errors stayed at
#: 93-100 % of the output's spread (700-1 700x the warm-up's residual) for 10 s, and the model
#: was 1.3-2.0 um off held-out records (0.16-0.27 the batch fit's). On the other stages
#: measured, the prediction error over a chunk stayed under 11x the warm-up's residual.
REWARM_RATIO = 30.0
REWARM_SPREAD = 0.5


class WarmUp:
    """The warm-up, the re-warm, the two starts and the slow pole's bound of
    :class:`~hystid.identify.pi_online.PIStageOnline` (a mixin: the state is the
    identifier's)."""

    def _choose_when_full(self) -> None:
        """Choose between this identifier and its twin once the window is full (the next
        chunk would leave it): every excited sample is still in the chunks."""
        if self._phi is None or self._twin is None:
            return
        if self._twin._phi is None:  # the twin has not warmed up yet
            return
        if len(self._chunks) >= self._keep():
            self._choose()

    def _window_samples(self) -> tuple[np.ndarray, np.ndarray]:
        """The window's chunks and the open one: input and output, normalised."""
        parts = [*self._chunks, self._open[:, :self._n_open]]
        return (np.concatenate([c[0] for c in parts]), np.concatenate([c[1] for c in parts]))

    def _free_run_rms(self) -> float:
        """RMS error of the current estimate run from rest over every sample so far (the rest
        kept, then the window's chunks and the open one), output units."""
        u, y = self._window_samples()
        err = self._simulate(self._phi, self._wstate.copy(), u, y)[0]
        err = err[np.isfinite(err)]
        return float(np.sqrt(np.mean(err ** 2))) * self._sy if err.size else math.inf

    def _choose(self) -> None:
        """Keep this identifier or take over its twin's state, whichever's model runs closer
        to the output from rest (:meth:`_free_run_rms`) after one more re-solve each
        (``_polish``); the twin is dropped."""
        t0 = time.perf_counter()
        twin, self._twin = self._twin, None
        self._polish()
        twin._polish()
        mine, its = self._free_run_rms(), twin._free_run_rms()
        self.start_errors_ = {"warm-up fit": mine, "slow branch": its}
        if its < mine:
            keep = {name: getattr(self, name) for name in self.settings if hasattr(self, name)}
            keep.update(thresholds=self.thresholds, structure=self.structure,
                        two_starts=self.two_starts, start_errors_=self.start_errors_)
            self.__dict__.update(twin.__dict__)
            self.__dict__.update(keep)
            self.started_from = "slow branch"
        self.choice_seconds_ = time.perf_counter() - t0

    def _predicts_nothing(self) -> bool:
        """Whether the open chunk, just complete, says that the warm-up went wrong: its
        prediction errors above :data:`REWARM_RATIO` times the warm-up fit's residual and
        above :data:`REWARM_SPREAD` of the output's spread over the chunk; checked only
        while every excited sample is still in the window (a warm-up can be fitted again),
        and not on a chunk that found the stage at rest
        (:meth:`~hystid.identify.pi_online_horizon.MovingHorizon._chunk_at_rest`): its error
        is a level, not a model that predicts nothing. Continued from measured stage A's
        ``prbn_1`` onto ``prbn_2`` (1 s at rest, the sensor's zero moved by 35 nm), the rest's
        first chunk was 37x the warm-up's residual and 26x the output's spread there, and the
        warm-up was fitted again in one call of 0.56 s; an excited chunk that follows is still
        checked."""
        if self._kept_rest is None or not self._chunk_n or self._chunk_at_rest():
            return False
        rms = math.sqrt(self._chunk_sq / self._chunk_n)
        yn = self._open[1, :self._n_open]
        spread = float(np.std(yn[np.isfinite(yn)])) if np.isfinite(yn).sum() > 1 else 0.0
        bad = rms > REWARM_RATIO * self._warm_rms / self._sy and rms > REWARM_SPREAD * spread
        if bad:
            self._rewarm_notes.append(
                f"the warm-up's model predicted none of the next {self._n_open} samples "
                f"(prediction error {rms / max(spread, 1e-300):.0%} of the output's spread, "
                f"{rms * self._sy / max(self._warm_rms, 1e-300):.0f}x the warm-up fit's "
                f"residual): the warm-up was fitted again on every excited sample so far")
        return bad

    def _rewarm(self) -> None:
        """Fit the warm-up again on the rest kept and every excited sample so far (all still
        in the window's chunks and the open one); the recursion and the re-solves start
        again from that fit."""
        un, yn = self._window_samples()
        u, y = un * self._su + (self._u0 or 0.0), yn * self._sy + self._y0
        self._rest = [tuple(row) for row in self._kept_rest]
        self._buffer = list(zip(u.tolist(), y.tolist(), strict=True))
        self._chunks, self._n_open, self._chunk_rest, self._job = [], 0, 0, None
        self.n_rewarms += 1
        self._warm_start()

    def _warm_start(self) -> None:
        """Fit the rest kept and the warm-up samples off-line; replay them as chunks."""
        from .pi_batch import _fit_normalised_from_zero

        t0 = time.perf_counter()
        n = self._n_weights
        rest = np.array(self._rest).reshape(-1, 2)
        exc = np.array(self._buffer)
        self._kept_rest = rest.copy()
        if not np.isfinite(exc[:, 1]).any():
            raise ValueError(f"the warm-up's {len(exc)} outputs are all skipped (skip={self.skip}) "
                             "or not finite: nothing to fit; expected a skip shorter than the "
                             "samples before the warm-up ends")
        if self.offset is None:  # the output at rest: the leading rest's, else the first
            seen = np.r_[rest[:, 1], exc[:, 1]]
            seen = seen[np.isfinite(seen)]
            at_rest = rest[:, 1][np.isfinite(rest[:, 1])]
            self._y0 = (float(np.median(at_rest)) if at_rest.size else
                        float(seen[0]) if seen.size else 0.0)
        u = np.r_[rest[:, 0], exc[:, 0]] - (self._u0 or 0.0)
        y = np.r_[rest[:, 1], exc[:, 1]] - self._y0
        in_motion = len(rest) < REST_SAMPLES  # no rest pins the output's zero
        if in_motion:  # the slow-branch start is for a record that begins at rest
            self._twin = None
        swing = 0.0 if in_motion else self.rest_swing or 0.0  # before a rest only
        # swung, the fit's offset takes the plays' share of the output at rest (dropped after:
        # the recursion's prediction is relative to the output at rest)
        fit, su, sy = _fit_normalised_from_zero(u, y, self.thresholds, self.structure,
                                                max_nfev=WARMUP_NFEV, screen_nfev=WARMUP_SCREEN,
                                                offset=in_motion or bool(swing), drift=in_motion,
                                                swing=swing)
        self._su, self._sy, self._rn = su, sy, self.thresholds / su
        self._band = None  # the rest's band follows the thresholds' scale
        self._swing = swing / su
        self._to_record = _scale_weights(np.ones(n + 5), self.structure, sy, su)
        phi = stage_from_theta(fit.theta, n)
        nplay = self.structure.n_operators
        if self.monotone:
            phi[:nplay] = admissible_weights(phi[:nplay])
        un, yn = u / su, y / sy
        if self.slow_start and not in_motion:
            phi = self._slow_branch(phi, un, yn)
        st0 = np.zeros((_STATE_ROWS, n + 1))
        _settle_plays(st0, rest_plays(self._swing, self._rn))
        if in_motion:  # the offset and the drift's rate: search coordinates from here on
            phi = np.r_[phi, fit.y0, self._start_clock(fit, y, st0)]
        self._warm_rms = fit.rms * sy
        nr = len(rest)
        self._wstate = self._simulate(phi, st0, un[:nr], yn[:nr])[2]
        err, J, st = self._simulate(phi, self._wstate, un[nr:], yn[nr:])
        seen = np.isfinite(err)
        s2 = max(float(np.mean(err[seen] ** 2)), 1e-12)
        # the recursion is scale-free: information in plain sums of squares, the prior's
        # variance P0 relative to the warm-up fit's residual variance
        self._prior = s2 / self.P0
        if self.slow_start and not in_motion:  # the residual of the twin's own start
            self._warm_rms = math.sqrt(s2) * sy
        self._arrival = (phi.copy(), np.eye(len(phi)) * self._prior)
        for a in range(0, len(exc) - self._every + 1, self._every):
            self._chunks.append((un[nr + a:nr + a + self._every],
                                 yn[nr + a:nr + a + self._every]))
        done = len(self._chunks) * self._every
        left = len(exc) - done
        self._open[0, :left], self._open[1, :left] = un[nr + done:], yn[nr + done:]
        self._n_open = left
        self._phi, self._st, self._solved = phi, st, phi.copy()
        self._P = covariance(J[seen].T @ J[seen] + self._arrival[1])
        self._buffer, self._rest = [], []
        if self._chunks and not self._n_open:  # a first re-solve, in the warm-up's time
            self._rereference()
            self._launch((self._phi, self._phi))
            self._apply()
        self.warmup_seconds_ = time.perf_counter() - t0

    def _estimate_swing(self) -> None:
        """Estimate the swing before the rest, as the batch fit does, on every excited sample
        so far (all still in the window), with the current L1 and L2 held
        (:func:`~hystid.identify.pi_rest_swing.scan_rest_swing`; kept by the batch fit's rule,
        :func:`~hystid.identify.pi_rest_swing.keeps_swing`). When kept, the branches at the
        window's start settle where the swing left the plays, the weights are the scan's, and
        the re-solve that follows starts from there. Only when :attr:`rest_swing` is None,
        once, on a record that began at rest."""
        if (self.rest_swing is not None or self.swing_scan_ is not None or self._phi is None
                or self._tracks_drift or self._kept_rest is None or not self._chunks):
            return
        from .pi_batch import RIDGE
        from .pi_rest_swing import keeps_swing, scan_rest_swing

        un, yn = self._window_samples()
        rows = np.flatnonzero(np.isfinite(yn))
        n, nplay = self._n_weights, self.structure.n_operators
        # relative to the output at rest, as the recursion predicts it (no offset to fit)
        found = scan_rest_swing(theta_from_stage(self._phi, n), un, yn, rows, self._rn,
                                self.structure, np.ones((len(rows), 0)), RIDGE, relative=True)
        kept = keeps_swing(found["rms"], found["rms_virgin"], found["at_bound"])
        self.swing_scan_ = {"swing": found["swing"] * self._su, "kept": bool(kept),
                            "rms": found["rms"] * self._sy,
                            "rms_virgin": found["rms_virgin"] * self._sy,
                            "at_bound": bool(found["at_bound"])}
        if not kept:
            return
        self._swing = found["swing"]
        _settle_plays(self._wstate, rest_plays(self._swing, self._rn))
        phi = self._phi.copy()
        phi[:n] = stage_from_theta(found["theta"], n)[:n]
        if self.monotone:
            phi[:nplay] = admissible_weights(phi[:nplay])
        self._phi, self._solved = phi, phi.copy()
        self._arrival = (phi.copy(), self._arrival[1])

    def _slow_branch(self, phi: np.ndarray, un: np.ndarray, yn: np.ndarray) -> np.ndarray:
        """The warm-up fit's blocks with a slow branch, as the batch fit's slow-branch start
        (:func:`~hystid.identify.pi_batch._slow_branch_start`): its share of the DC gain
        :data:`~hystid.identify.pi_batch.SLOW_START_GAIN`, its time constant
        :data:`~hystid.identify.pi_batch.SLOW_START_SPAN` of the window, and the weights that
        fit the warm-up samples best for those blocks (linear least squares). The weights
        fitted without the branch halved the model's gain over the warm-up: on the creep stage
        of ``tests/test_pi_online_creep.py`` with a 1 s record, this start was 0.22 um off its
        record from rest (the warm-up fit's 0.10), and the on-line model 4.5-5.3x the batch
        fit's held-out error."""
        n = self._n_weights
        phi = with_slow_branch(phi, n, self._window)
        rows = np.flatnonzero(np.isfinite(yn))
        theta, _ = _weights_given_blocks(theta_from_stage(phi, n), un, yn, rows, self._rn,
                                         self.structure, bool(self._swing),
                                         swing=self._swing)
        out = stage_from_theta(theta, n)
        if self.monotone:
            out[:self.structure.n_operators] = admissible_weights(
                out[:self.structure.n_operators])
        return out if np.isfinite(out).all() else phi

    @property
    def _xp_most(self) -> float:
        """The slow pole's largest search coordinate a re-solve may move to: a time constant
        of :data:`~hystid.identify.pi_batch.SLOW_START_LONGEST` times the excited samples so
        far (the batch fit keeps its slow-branch start's fit only within that), on a record
        that begins at rest. Without a bound, the slow pole ran to 1.0 on the Maxwell-slip
        creep stage of ``tests/test_pi_online_creep.py`` (6-16x the batch fit's held-out
        error, 0.91-0.97x with it). On a record in motion there is no bound: the
        stage-A look-alike cut 0.2 s into its excitation was 0.032-0.13 um off held-out
        records with it, 0.019-0.11 without."""
        if self._tracks_drift:
            return math.inf
        seen = max(1, self.k - (self.excited_at or 0))
        return float(np.arctanh(np.exp(-1.0 / (SLOW_START_LONGEST * seen)) / _KMAX))


def _settle_plays(st: np.ndarray, p: np.ndarray) -> None:
    """Write into a branch state ``st`` (:data:`~hystid.identify.pi_online_kernels._STATE_ROWS`
    rows) the plays settled at ``p`` (one per play, the first columns): each play and both
    branches after it at ``p``, no sensitivities, and ``p`` as the operator's output at rest
    (row 12), which the prediction takes off."""
    nplay = len(p)
    st[:, :nplay] = 0.0
    st[[0, 1, 2, 4, 5, 12], :nplay] = p
