"""Supervision of the on-line identifier: the recursion against the last estimate that validated.

A recursive prediction-error method is only locally convergent: where the input hardly excites a
direction of the parameter space (a 1 Hz sine excites few), a stretch of data the model cannot
fit (a turning point) can push the estimate along that direction, the model's own output moves
with it and the residual grows with the step -- the estimate wanders. The residual of the
recursion alone does not show every such wander: it is the output of a model whose parameters
change while it runs, so an estimate whose own free run is far off can still have a small
one-step residual right after it moved.

The supervisor is the estimator-based supervision of adaptive control (Morse; Hespanha,
Liberzon and Morse, "Hysteresis-based switching algorithms for supervisory control", 2003):
candidate models run beside the process, each with a *monitoring signal* (its own output error),
and the supervisor switches to a candidate only when the one in use does markedly worse (a
hysteresis constant ``h``). Here the candidates are the running recursion and two frozen
estimates, each simulated freely (its *shadow*) on the same samples:

* the **accepted** estimate ``A``: the last one that validated, with the covariance it had;
* the **candidate** ``C``: the recursion's estimate (and covariance) at the start of the current
  validation interval.

Every :data:`BLOCK` samples, once the start-up checks are over (outside the per-sample kernel,
which is unchanged):

1. both shadows run over the block (one compiled call each; no sensitivities);
2. *divergence*: the recursion's residual RMS over the block exceeds ``diverge_ratio`` times the
   accepted shadow's over the same samples, or (once the recursion has had ``n_start`` samples,
   the start-up window's length, to settle from a start)
   *wander*: over the interval so far (at least two blocks) the recursion's residual RMS exceeds
   ``1 + h`` times the accepted shadow's -> the recursion is **rolled back** to ``A`` (estimate,
   covariance, and the signal windows of ``A``'s shadow, which is ``A``'s own free run); the
   rollback is a recovery (counted, warned, in ``info["warnings"]``);
3. *validation*: once the candidate's interval is long enough for the Duhem block to forget its
   initial state (eq. 7: two runs with the same ``w1`` approach each other by
   ``1 - alpha |dw1|`` per sample, so ``sum alpha |dw1| >=`` :data:`FORGET` e-folds), the
   candidate's free run is compared with the accepted one's over the interval: no worse than
   ``1 + h`` times -> ``C`` becomes ``A``; worse -> the recursion is rolled back to ``A``. The
   recursion's estimate then becomes the next candidate.

A stage that really changes is tracked: the recursion then does better than the frozen ``A``
(no rollback) and its candidates validate (``A`` follows). An input that stops exciting
leaves ``A`` as it is (no candidate completes its interval) while the divergence and wander
checks still hold the recursion to it.
"""

from __future__ import annotations

from typing import Any, Protocol

import numpy as np
from numba import njit

from ..kernels import step
from .online_kernels import _FIRST, _GOODAGE, _HOLD, _I_POS, _NREC, _SHORT, _SIG


class Supervised(Protocol):
    """What the supervisor reads and sets of the identifier it supervises
    (:class:`hystid.identify.online.OnlineIdentifier`, which imports this module)."""

    P: np.ndarray
    structure: Any
    window: int
    _P_good: np.ndarray
    _est: np.ndarray
    _est_good: np.ndarray
    _ints: np.ndarray
    _scal: np.ndarray
    _windows: tuple

__all__ = ["BLOCK", "FORGET", "HYSTERESIS", "Supervisor", "finite_squares"]

#: Samples per supervision step.
BLOCK = 100
#: Hysteresis constant ``h`` of the switching: an estimate is replaced when it does more than
#: ``1 + h`` times worse than the other on the same samples.
HYSTERESIS = 0.25
#: E-folds of the Duhem block's initial state forgotten over a validation interval (95 %).
FORGET = 3.0


@njit(cache=True)
def finite_squares(e: np.ndarray) -> tuple[float, float]:
    """Sum of squares of the finite samples of ``e``, added in order, and their count (one
    order of additions on every CPU and numpy, which the exported C step does too)."""
    total, count = 0.0, 0.0
    for x in e:
        if np.isfinite(x):
            total += x * x
            count += 1.0
    return total, count


@njit(cache=True)
def shadow_block(est, layout, U, W1, W2, Y, w, u, y, sums):
    """Simulate one estimate freely over a block; add to ``sums = [sum e^2, n, sum |dw1|]``.

    ``U, W1, W2, Y`` hold the last ``w`` samples of the free run at ``[0, w)`` and room for the
    block after them; on return the last ``w`` samples are moved back to the front.
    """
    npar = est.shape[0] - 1
    theta = est[:npar]
    offset = est[npar]
    m = u.shape[0]
    for i in range(m):
        k = w + i
        U[k] = u[i]
        step(theta, layout, U, W1, W2, Y, k)
        e = y[i] - Y[k] - offset
        if np.isfinite(e):
            sums[0] += e * e
            sums[1] += 1.0
        sums[2] += abs(W1[k] - W1[k - 1])
    for a in (U, W1, W2, Y):
        a[:w] = a[m:m + w]


class _Shadow:
    """A frozen estimate (with its covariance) and its free run: the windows and the sums of
    its squared output error and of ``|dw1|`` since it was taken."""

    def __init__(self, est: np.ndarray, P: np.ndarray, windows: list[np.ndarray],
                 i_alpha: int) -> None:
        self.est, self.P = est.copy(), P.copy()
        self.i_alpha = i_alpha
        w = len(windows[0])
        self.windows = [np.concatenate([a, np.zeros(BLOCK)]) for a in windows]
        self.w = w
        self.sums = np.zeros(3)

    def run(self, layout: np.ndarray, u: np.ndarray, y: np.ndarray) -> tuple[float, float]:
        """Advance the free run over a block; returns the block's ``(sum e^2, n)``."""
        before = self.sums[:2].copy()
        shadow_block(self.est, layout, *self.windows, self.w, u, y, self.sums)
        return float(self.sums[0] - before[0]), float(self.sums[1] - before[1])

    def rms(self) -> float:
        return float(np.sqrt(self.sums[0] / max(self.sums[1], 1.0)))

    def forgotten(self) -> float:
        """E-folds of the Duhem block's initial state forgotten since the shadow was taken."""
        return float(self.est[self.i_alpha] * self.sums[2])

    def tail(self) -> list[np.ndarray]:
        return [a[:self.w] for a in self.windows]


class Supervisor:
    """Rolls the recursion back to the last validated estimate when it diverges or wanders.

    Parameters
    ----------
    diverge_ratio : float
        A block whose residual RMS exceeds this many times the accepted estimate's on the same
        samples is a divergence.
    floor : float
        Error level below which residuals are not compared (round-off).

    Attributes
    ----------
    n_rollbacks : int
        Rollbacks to the accepted estimate.
    n_accepted : int
        Candidates that validated.
    first_reason : str
        Why the first rollback happened, in words ("" if none).
    """

    def __init__(self, diverge_ratio: float, floor: float = 0.0) -> None:
        self.diverge_ratio = float(diverge_ratio)
        self.floor = float(floor)
        self.n_rollbacks = 0
        self.n_accepted = 0
        self.first_reason = ""
        self.accepted: _Shadow | None = None
        self.candidate: _Shadow | None = None
        self._u, self._y, self._e = np.zeros(BLOCK), np.zeros(BLOCK), np.zeros(BLOCK)
        self.filled = 0
        self._settle_until = 0
        self._live = np.zeros(2)     # recursion: sum e^2, n over the candidate's interval
        self._versus = np.zeros(2)   # accepted shadow: the same over the same samples

    # ----------------------------------------------------------------- helpers
    @staticmethod
    def _shadow(ident: Supervised) -> _Shadow:
        """The recursion's estimate, covariance and signal windows, frozen."""
        pos, w = int(ident._ints[_I_POS]), ident.window
        return _Shadow(ident._est, ident.P, [a[pos - w:pos] for a in ident._windows[:4]],
                       ident.structure.names.index("alpha"))

    def _new_candidate(self, ident: Supervised) -> None:
        self.candidate = self._shadow(ident)
        self._live[:] = 0.0
        self._versus[:] = 0.0

    def reset(self, ident: Supervised, settle_until: int = 0) -> None:
        """Accept the recursion's current estimate as it is (after a start-up solve).

        Parameters
        ----------
        ident : OnlineIdentifier
            The identifier whose state is taken.
        settle_until : int
            Sample count until which the recursion settles from the start: only a divergence
            is checked, and the first candidate is taken at its end.
        """
        self.accepted = self._shadow(ident)
        self._new_candidate(ident)
        self.filled = 0
        self._settle_until = settle_until

    @property
    def room(self) -> int:
        """Samples until the next supervision step."""
        return BLOCK - self.filled

    # ----------------------------------------------------------------- the steps
    def feed(self, ident: Supervised, u: np.ndarray, y: np.ndarray, e: np.ndarray,
             k: int) -> bool:
        """Take samples the recursion has just processed (at most :attr:`room`).

        Parameters
        ----------
        ident : OnlineIdentifier
            The identifier (rolled back in place when needed).
        u, y : ndarray
            Input (less the rest level) and measured output of the samples.
        e : ndarray
            The recursion's residuals on them.
        k : int
            Sample count after the last of them.

        Returns
        -------
        bool
            Whether the recursion was rolled back.
        """
        if self.accepted is None:  # a recursion started without a start-up solve
            self.reset(ident)
        m = len(u)
        a = self.filled
        self._u[a:a + m], self._y[a:a + m], self._e[a:a + m] = u, y, e
        self.filled += m
        if self.filled < BLOCK:
            return False
        self.filled = 0
        return self._step(ident, k)

    def feed_one(self, ident: Supervised, u: float, y: float, e: float, k: int) -> bool:
        """:meth:`feed` for one sample (the real-time path).

        Parameters
        ----------
        ident : OnlineIdentifier
            The identifier.
        u, y, e : float
            Input, output and residual of the sample.
        k : int
            Sample count after it.

        Returns
        -------
        bool
            Whether the recursion was rolled back.
        """
        if self.accepted is None:
            self.reset(ident)
        a = self.filled
        self._u[a], self._y[a], self._e[a] = u, y, e
        self.filled = a + 1
        if self.filled < BLOCK:
            return False
        self.filled = 0
        return self._step(ident, k)

    def _step(self, ident: Supervised, k: int) -> bool:
        layout = ident._ints[:10].copy()
        u, y, e = self._u, self._y, self._e
        sq_a, n_a = self.accepted.run(layout, u, y)
        self.candidate.run(layout, u, y)
        sq_r, n_r = finite_squares(e)
        self._live += (sq_r, n_r)
        self._versus += (sq_a, n_a)
        # 2. divergence over the block, wander over the interval
        if n_r and n_a:
            block_r = np.sqrt(sq_r / n_r)
            block_a = max(np.sqrt(sq_a / n_a), self.floor)
            if block_r > self.diverge_ratio * block_a:
                return self._rollback(ident, k, f"its residual ({block_r:.3g} RMS over "
                                      f"{BLOCK} samples) exceeded {self.diverge_ratio:g}x the "
                                      f"last validated estimate's ({block_a:.3g})")
        if k < self._settle_until:  # the recursion settles from its start
            return False
        if self._settle_until:
            self._settle_until = 0
            self._new_candidate(ident)
            return False
        if self._live[1] >= 2 * BLOCK and self._versus[1]:
            live = np.sqrt(self._live[0] / self._live[1])
            versus = max(np.sqrt(self._versus[0] / self._versus[1]), self.floor)
            if live > (1.0 + HYSTERESIS) * versus:
                return self._rollback(ident, k, f"it wandered: its residual ({live:.3g} RMS "
                                      f"over {int(self._live[1])} samples) exceeded "
                                      f"{1 + HYSTERESIS:g}x the last validated estimate's "
                                      f"({versus:.3g})")
        # 3. validation of the candidate once its free run has forgotten its start
        c = self.candidate
        if c.forgotten() >= FORGET and c.sums[1] >= 2 * BLOCK:
            versus = max(np.sqrt(self._versus[0] / max(self._versus[1], 1.0)), self.floor)
            if c.rms() > (1.0 + HYSTERESIS) * versus:
                return self._rollback(ident, k, f"its estimate at the start of the last "
                                      f"{int(c.sums[1])} samples ran {c.rms():.3g} RMS freely "
                                      f"there, more than {1 + HYSTERESIS:g}x the last "
                                      f"validated estimate's ({versus:.3g})")
            self.accepted = c
            self.n_accepted += 1
            self._new_candidate(ident)
        return False

    def _rollback(self, ident: Supervised, k: int, reason: str) -> bool:
        """The recursion restarts from the accepted estimate, its covariance and its free run."""
        a = self.accepted
        ident._est[:] = a.est
        ident.P[:] = a.P
        ident._est_good[:] = a.est
        ident._P_good[:] = a.P
        pos, w = int(ident._ints[_I_POS]), ident.window
        for dst, src in zip(ident._windows[:4], a.tail(), strict=True):
            dst[pos - w:pos] = src
        for sens in ident._windows[5:]:
            sens[pos - w:pos] = 0.0
        scal = ident._scal
        scal[_NREC] += 1.0
        if scal[_FIRST] < 0:
            scal[_FIRST] = float(k)
        level = max(a.rms(), self.floor, 1e-300)
        scal[_SIG] = level
        scal[_SHORT] = level * level
        scal[_HOLD] = scal[_GOODAGE] = 0.0
        self.n_rollbacks += 1
        if not self.first_reason:
            self.first_reason = f"at sample {k}: {reason}"
        self._new_candidate(ident)
        return True

    def info(self) -> dict:
        """Counts for ``result().info["supervisor"]``.

        Returns
        -------
        dict
        """
        return {"rollbacks": self.n_rollbacks, "accepted": self.n_accepted,
                "first": self.first_reason}
