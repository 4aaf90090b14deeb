"""Machinery shared by the recursive identifiers: signal windows, guards, the update/fit loop.

A recursive identifier keeps short windows of the signals (most recent sample at the last index)
and runs a compiled kernel over a chunk of samples. ``update(u_k, y_k)`` is a chunk of one sample,
``partial_fit(record)`` the same over a record, so both give the same numbers; ``fit(record)``
restarts first (see :mod:`hystid.identify.base`).
"""

from __future__ import annotations

import warnings
from collections.abc import Callable

import numpy as np
from numba import njit

from ..model import DuhemSandwich, Structure
from ..poly import schur_cohn_into
from ..records import Record
from .base import Estimator, record_signals, sample_arrays
from .offline import initial_theta
from .result import HistoryRecorder, IdentificationResult

__all__ = ["RecursiveIdentifier", "admissible", "admissible_into", "extended", "keep_tail"]


def extended(window: np.ndarray, n: int) -> np.ndarray:
    """The window followed by room for ``n`` new samples (axis 0)."""
    return np.concatenate([window, np.zeros((n, *window.shape[1:]))])


def keep_tail(window: np.ndarray, ext: np.ndarray) -> None:
    """Copy the last ``len(window)`` samples of an extended array back into the window."""
    window[...] = ext[len(ext) - len(window):]


@njit(cache=True)
def admissible(theta, layout, kmax):
    """theta is finite, alpha > 0 (with ``|ad| < 1`` for a direction-dependent block) and L1,
    L2 stable and minimum phase (Assumption 1)."""
    return admissible_into(theta, layout, kmax, np.empty(theta.shape[0]))


@njit(cache=True)
def admissible_into(theta, layout, kmax, work):
    """:func:`admissible` with a caller-provided scratch array (no allocation)."""
    for v in theta:
        if not np.isfinite(v):
            return False
    n1a, n1b, n2a, n2b, has_f0 = layout[0], layout[1], layout[2], layout[3], layout[6]
    i_alpha = n2b
    i_f1 = i_alpha + 1 + (1 if has_f0 else 0)
    i_b1 = i_f1 + 1
    i_g0 = i_b1 + n1b
    i_a1 = i_g0 + 1
    i_a2 = i_a1 + n1a
    if theta[i_alpha] <= 0.0:
        return False
    if layout[9] and abs(theta[i_a2 + n2a + layout[7] + layout[8]]) >= 1.0:
        return False  # the generalised block's rates alpha (1 +- ad) must stay positive
    return (
        schur_cohn_into(theta, i_a1, n1a, kmax, work)
        and schur_cohn_into(theta, i_a2, n2a, kmax, work)
        and schur_cohn_into(theta, i_b1, n1b, kmax, work)
        and schur_cohn_into(theta, 0, n2b, kmax, work)
    )


class RecursiveIdentifier(Estimator):
    """Base class of the compiled recursions: configuration, validated input, the result.

    Subclasses set :attr:`method`, implement :meth:`_allocate` (the state arrays) and
    :meth:`_run` (the compiled kernel over a chunk). :meth:`update`, :meth:`partial_fit` and
    :meth:`fit` keep the :class:`~hystid.identify.base.Estimator` contract.
    """

    method = "recursive"
    #: What a restart means, for the warning.
    divergence_reason = "the estimate diverged"
    #: Samples of signal history kept in the windows beyond the structure's own.
    extra_history = 2
    #: Samples per compiled call in :meth:`partial_fit`.
    chunk = 65_536

    def __init__(self, structure: Structure | None, fs: float, theta0, epsilon: float,
                 history: str = "decimated", history_rows: int = 100_000):
        self.structure = structure or Structure()
        if not isinstance(self.structure, Structure):
            raise ValueError(f"structure: expected a Structure, got {type(structure).__name__}")
        if not (np.isfinite(fs) and fs > 0):
            raise ValueError(f"fs: expected a positive sampling rate in Hz, got {fs!r}")
        if not (np.isfinite(epsilon) and epsilon > 0):
            raise ValueError(f"epsilon: expected a positive stop index, got {epsilon!r}")
        HistoryRecorder(2, 1, 0, history, history_rows)  # validates both
        self.fs = float(fs)
        self.epsilon = float(epsilon)
        self.theta0 = theta0
        self.history = history
        self.history_rows = int(history_rows)
        self.reset()

    # ----------------------------------------------------------------- state
    @property
    def window(self) -> int:
        """Length of the signal windows."""
        s = self.structure
        return max(s.q1 + s.q2 + s.n1b + 1, s.q2 + 1 + s.n1a, s.n2a + 1, s.q2 + s.n2b + 1,
                   s.history) + self.extra_history

    def reset(self) -> RecursiveIdentifier:
        """Forget everything learned: back to theta0 at sample 0.

        Returns
        -------
        RecursiveIdentifier
            ``self``.
        """
        self.theta = initial_theta(self.structure, self.theta0).copy()
        self.k = 0
        self.n_recoveries = 0
        self.n_skipped = 0
        self.first_recovery: int | None = None
        self._allocate()
        return self

    def _allocate(self) -> None:  # pragma: no cover - abstract
        raise NotImplementedError

    def _run(self, u, y, history, diagnostics):  # pragma: no cover - abstract
        raise NotImplementedError

    n_diagnostics = 0

    # ----------------------------------------------------------------- on-line API
    def update(self, u_k: float, y_k: float) -> np.ndarray:
        """Process one sample ``(u(k), y(k))``; returns the new estimate theta(k).

        Parameters
        ----------
        u_k : float
            Input sample; a non-finite one is an error (the model cannot be propagated).
        y_k : float
            Output sample; a non-finite one is skipped (counted in :attr:`n_skipped`).

        Returns
        -------
        ndarray
            The estimate theta(k), a copy.
        """
        u, y = sample_arrays(u_k, y_k)
        self._process(u, y, np.empty((1, len(self.theta))),
                      np.empty((1, self.n_diagnostics)))
        return self.theta.copy()

    def _process(self, u, y, history, diagnostics) -> None:
        before = self.n_recoveries
        skipped = int(np.count_nonzero(~np.isfinite(y)))
        self._run(u, y, history, diagnostics)
        self.k += len(u)
        self.n_skipped += skipped
        self._warn_recoveries(before)

    def _warn_recoveries(self, before: int) -> None:
        if self.n_recoveries > before:
            warnings.warn(
                f"{self.method}: {self.divergence_reason} {self.n_recoveries - before} "
                f"time(s), first at sample {self.first_recovery}; restarted from the last "
                "good estimate", RuntimeWarning, stacklevel=4,
            )

    def partial_fit(
        self, record: Record, progress: Callable[[int, int], None] | None = None
    ) -> IdentificationResult:
        """Run over a record from the current state; returns the result with history.

        Parameters
        ----------
        record : Record
            Input and output samples (the identifier assumes the stage starts at rest unless
            it has already seen earlier samples).
        progress : callable, optional
            Called as ``progress(k, n)`` after each chunk.

        Returns
        -------
        IdentificationResult
            The estimate; ``history`` as the ``history`` setting says (``history_index`` gives
            the sample of each row when decimated).
        """
        u, y, _ = record_signals(record, self.fs)
        n = len(u)
        before = self.n_skipped
        rec = HistoryRecorder(n, len(self.theta), self.n_diagnostics, self.history,
                              self.history_rows, self.epsilon)
        size = min(n, self.chunk)
        history = np.empty((size, len(self.theta)))
        diagnostics = np.empty((size, self.n_diagnostics))
        for start in range(0, n, size or 1):
            stop = min(n, start + size)
            m = stop - start
            self._process(u[start:stop], y[start:stop], history[:m], diagnostics[:m])
            rec.add(history[:m], diagnostics[:m])
            if progress is not None:
                progress(stop, n)
        self._warn_skipped(before)
        return self.result(rec)

    def result(self, recorder: HistoryRecorder | None = None) -> IdentificationResult:
        """The current estimate as an :class:`IdentificationResult`.

        Parameters
        ----------
        recorder : HistoryRecorder, optional
            The history of the run that led to it.

        Returns
        -------
        IdentificationResult
        """
        info = {"n_recoveries": self.n_recoveries, "first_recovery": self.first_recovery,
                "n_skipped": self.n_skipped, "samples": self.k, "warnings": []}
        history = index = conv = None
        if recorder is not None:
            conv = recorder.converged_at
            if recorder.mode != "none":
                history = recorder.history
                index = None if recorder.every == 1 else recorder.index
                if recorder.diagnostics is not None and self.n_diagnostics:
                    info["diagnostics"] = recorder.diagnostics
        return IdentificationResult(self.model, self.method, self.settings, history, conv, info,
                                    history_index=index)

    @property
    def model(self) -> DuhemSandwich:
        """The model of the current estimate."""
        return DuhemSandwich(self.theta.copy(), self.structure, fs=self.fs,
                             name=f"{self.method} estimate")

    @property
    def settings(self) -> dict:
        """The identifier's configuration (JSON-ready)."""
        s = self.structure
        return {"structure": {k: getattr(s, k) for k in ("n1a", "n1b", "n2a", "n2b", "q1", "q2",
                                                          "f0")},
                "fs": self.fs, "epsilon": self.epsilon, "theta0": _jsonable(self.theta0),
                "history": self.history, "history_rows": self.history_rows}


def _jsonable(value):
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, dict):
        return {str(k): float(v) for k, v in value.items()}
    return value
