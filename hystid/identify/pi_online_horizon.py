"""The ``pi-stage`` on-line identifier's moving horizon (see :mod:`hystid.identify.pi_online`):
the window's chunks, the background re-solve launched at each chunk's boundary, its work spread
over the samples that follow, and its estimate taken over at the next boundary.

:class:`MovingHorizon` holds these steps of :class:`~hystid.identify.pi_online.PIStageOnline`,
which inherits them; they read and set its state.
"""

from __future__ import annotations

import time

import numpy as np

from .horizon import HorizonSolve, covariance, drain, run_steps
from .pi_online_kernels import _l2_stable, _run, _slope, still_mask

__all__ = ["CHOICE_ITERATIONS", "MovingHorizon", "REST_BAND", "REST_HOLD", "REST_SHARE"]

#: Levenberg-Marquardt trials a start of the re-solve each of the two starts runs when they are
#: chosen between (``two_starts``: when the window is full, or at the end of a shorter
#: record), done in that call. With :data:`ITERATIONS` alone the creep stage of
#: ``tests/test_pi_online_creep.py`` with 1 s records (the window) was 1.0-8.7x the batch
#: fit's held-out error, depending on the seed and on the slow branch's start; with this,
#: 0.17-1.0x.
CHOICE_ITERATIONS = 12
#: Samples the input must stay where it stood, within :data:`REST_BAND` of the largest
#: threshold (the tolerance the leading rest is found with), before the stage counts as at
#: rest: from then on the recursion runs those samples without learning from them (a held
#: input excites nothing; stage A's flexure mode rings down within a few tens of samples). A
#: slow input near a turning point still moves by more than that: with half the smallest
#: threshold as the band, 84 % of a 1 Hz sine's samples at 10 kHz counted as a rest. A creep
#: that shows only while the stage rests is not learned from ..
REST_HOLD = 20
REST_BAND = 1e-6
#: .. and a chunk with at least this share of its samples at rest launches a re-solve that
#: folds the chunks leaving the window into the arrival cost and moves nothing (no trial, no
#: decay of the arrival cost's information). Fed measured stage A's 1 s rest once more after
#: ``prbn_1``, the estimate ran off along what the rest does not fix (L2's mode went from two
#: poles at 0.9886 to 0.94 and 0.10): 78 / 79 nm off ``sine50_1`` / ``tri50_1`` against 26 /
#: 25 before the rest; now 26 / 24.
REST_SHARE = 0.5


class MovingHorizon:
    """The window and the re-solves of :class:`~hystid.identify.pi_online.PIStageOnline` (a
    mixin: the state is the identifier's)."""

    def _keep(self) -> int:
        return max(1, self._span // self._every)

    def _close_chunk(self) -> None:
        """The open chunk is complete: keep it in the window and open the next one; the
        running re-solve's estimate takes over (the work it has left done now) and the next
        re-solve is launched (one that moves nothing when the chunk found the stage at rest,
        :data:`REST_SHARE`)."""
        self._chunks.append((self._open[0].copy(), self._open[1].copy()))
        at_rest = self._chunk_at_rest()
        self._n_open, self._chunk_rest = 0, 0
        recursion = self._phi.copy()
        if self._job is not None:
            self._apply()
        (recursion,) = self._rereference(recursion)
        self._launch((recursion, self._solved), 0 if at_rest else None, decay=not at_rest)

    def _at_rest(self, un: np.ndarray) -> np.ndarray:
        """Which of the samples ``un`` (normalised, the next ones of the open chunk) find the
        stage at rest (:data:`REST_HOLD`); counted in the open chunk."""
        if self._band is None:  # the leading rest's tolerance, normalised
            self._band = REST_BAND * max(float(self._rn[-1]), 1e-300)
        rest = np.empty(len(un), dtype=np.bool_)
        still_mask(np.ascontiguousarray(un, dtype=float), self._still, self._band, REST_HOLD,
                   rest)
        self._chunk_rest += int(np.count_nonzero(rest))
        return rest

    def _chunk_at_rest(self) -> bool:
        """Whether the open chunk found the stage at rest: :data:`REST_SHARE` of its samples
        or more (:meth:`_at_rest`)."""
        return self._n_open > 0 and self._chunk_rest >= REST_SHARE * self._n_open

    def _simulate(self, phi: np.ndarray, st0: np.ndarray, u: np.ndarray,
                  y: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        return drain(run_steps(self._slice, phi, st0, u, y))

    def _slice(self, phi: np.ndarray, st: np.ndarray, u: np.ndarray, y: np.ndarray,
               J: np.ndarray, err: np.ndarray) -> None:
        """The branches over a slice, gradients and errors written (the re-solve's
        :data:`~hystid.identify.horizon.Simulate`)."""
        _run(phi, self._P, 1.0, 1.0, 1.0, self._rn, self.structure.n_poly, u, y, st, False, J,
             np.empty(len(u)), err, self._no_rows, 0)

    def _admissible(self, trial: np.ndarray, phi: np.ndarray) -> bool:
        """A re-solve's trial: L2 stable, the loading slope positive or no lower than at
        ``phi``."""
        nplay, n = self._nslope, self._n_weights
        after = _slope(trial, nplay)
        return bool((after > 0 or after >= _slope(phi, nplay)) and _l2_stable(trial, n)
                    and (trial[n + 1] <= self._xp_most or trial[n + 1] <= phi[n + 1]))

    def _polish(self) -> None:
        """The running re-solve's estimate takes over, the swing before the rest is estimated
        (when it is not given), then one more re-solve of the window with
        :data:`CHOICE_ITERATIONS` trials a start, solved now."""
        if self._job is not None:
            self._apply()
        self._estimate_swing()
        if self._chunks:
            self._launch((self._phi, self._solved), CHOICE_ITERATIONS)
            self._apply()

    def _launch(self, starts: tuple[np.ndarray, ...],
                iterations: int | None = None, decay: bool = True) -> HorizonSolve:
        """A re-solve of the window's last ``window // every`` chunks (the older ones folded
        into the arrival cost at the last re-solve's estimate first), from the recursion's
        estimate and from the last re-solve's (the lower cost is kept: the recursion may have
        drifted along a direction the data do not fix)."""
        leaving = max(0, len(self._chunks) - self._keep())
        if leaving:  # samples leave the window: a warm-up can no longer be fitted again
            self._kept_rest = None
        self._job = HorizonSolve(self._slice, self._admissible, self._chunks, self._wstate,
                                 self._arrival, starts,
                                 self.iterations if iterations is None else iterations,
                                 leaving=leaving,
                                 linearised_at=self._solved,
                                 forget=self._forget if decay else None)
        return self._job

    def _apply(self) -> None:
        """The solved re-solve's estimate takes over, with the branches it ran over the
        samples since its window ended and its information (the recursion's covariance is the
        inverse); the chunks it folded leave the window."""
        t0, before = time.perf_counter(), self._job.spent
        res = self._job.result()
        self.resolve_work_ += self._job.spent - before
        del self._chunks[:len(self._job.leaving)]
        self._arrival, self._wstate = res.arrival, res.start
        self._phi, self._st, self._solved = res.phi.copy(), res.state, res.phi.copy()
        self._P = covariance(res.information)
        self._job = None
        self.n_resolves += 1
        self.resolve_seconds_ += time.perf_counter() - t0

    def _advance(self, u: np.ndarray, y: np.ndarray) -> None:
        """Samples the running re-solve follows, and its share of work for them."""
        if self._job is not None:
            t0, before = time.perf_counter(), self._job.spent
            self._job.feed(u, y)
            self._job.advance(len(u) * self.resolve_rate)
            self.resolve_work_ += self._job.spent - before
            self.resolve_seconds_ += time.perf_counter() - t0
