"""Machinery shared by the recursive identifiers: signal windows, guards, the update/fit loop.

A recursive identifier keeps short windows of the signals (most recent sample at the last index)
and runs a compiled kernel over a chunk of samples. ``update(u_k, y_k)`` is a chunk of one sample,
``fit(record)`` a chunk of the whole record, so both give the same numbers.
"""

from __future__ import annotations

import warnings
from collections.abc import Callable

import numpy as np
from numba import njit

from ..model import DuhemSandwich, Structure
from ..records import Record
from .offline import initial_theta
from .result import IdentificationResult, converged_at

__all__ = ["RecursiveIdentifier", "admissible", "admissible_into", "extended", "keep_tail"]


def extended(window: np.ndarray, n: int) -> np.ndarray:
    """The window followed by room for ``n`` new samples (axis 0)."""
    return np.concatenate([window, np.zeros((n, *window.shape[1:]))])


def keep_tail(window: np.ndarray, ext: np.ndarray) -> None:
    """Copy the last ``len(window)`` samples of an extended array back into the window."""
    window[...] = ext[len(ext) - len(window):]


@njit(cache=True)
def _reflection_ok(theta, start, n, kmax, work):
    """All reflection coefficients of ``1 + c_1 z^-1 + ... + c_n z^-n`` (``c = theta[start:]``)
    strictly inside (-kmax, kmax); step-down recursion in the scratch array ``work``."""
    for i in range(n):
        work[i] = theta[start + i]
    for m in range(n, 0, -1):
        km = work[m - 1]
        if not (abs(km) < kmax):
            return False
        d = 1.0 - km * km
        for i in range((m - 1 + 1) // 2):
            a, b = work[i], work[m - 2 - i]
            work[i] = (a - km * b) / d
            work[m - 2 - i] = (b - km * a) / d
    return True


@njit(cache=True)
def admissible(theta, layout, kmax):
    """theta is finite, alpha > 0 and L1, L2 stable and minimum phase (Assumption 1)."""
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
    return (
        _reflection_ok(theta, i_a1, n1a, kmax, work)
        and _reflection_ok(theta, i_a2, n2a, kmax, work)
        and _reflection_ok(theta, i_b1, n1b, kmax, work)
        and _reflection_ok(theta, 0, n2b, kmax, work)
    )


class RecursiveIdentifier:
    """Base class: configuration, validated input, the update/fit loop and the result.

    Subclasses set :attr:`method`, implement :meth:`_allocate` (the state arrays) and
    :meth:`_run` (the compiled kernel over a chunk).
    """

    method = "recursive"
    #: What a restart means, for the warning.
    divergence_reason = "the estimate diverged"
    #: Samples of signal history kept in the windows beyond the structure's own.
    extra_history = 2

    def __init__(self, structure: Structure | None, fs: float, theta0, epsilon: float):
        self.structure = structure or Structure()
        if not (np.isfinite(fs) and fs > 0):
            raise ValueError(f"fs: expected a positive sampling rate in Hz, got {fs!r}")
        if not (np.isfinite(epsilon) and epsilon > 0):
            raise ValueError(f"epsilon: expected a positive stop index, got {epsilon!r}")
        self.fs = float(fs)
        self.epsilon = float(epsilon)
        self.theta0 = theta0
        self.reset()

    # ----------------------------------------------------------------- state
    @property
    def window(self) -> int:
        """Length of the signal windows."""
        s = self.structure
        return max(s.q1 + s.q2 + s.n1b + 1, s.q2 + 1 + s.n1a, s.n2a + 1, s.q2 + s.n2b + 1,
                   s.history) + self.extra_history

    def reset(self) -> None:
        """Forget everything learned: back to theta0 at sample 0."""
        self.theta = initial_theta(self.structure, self.theta0).copy()
        self.k = 0
        self.n_recoveries = 0
        self.n_skipped = 0
        self.first_recovery: int | None = None
        self._allocate()

    def _allocate(self) -> None:  # pragma: no cover - abstract
        raise NotImplementedError

    def _run(self, u, y, history, diagnostics):  # pragma: no cover - abstract
        raise NotImplementedError

    n_diagnostics = 0

    # ----------------------------------------------------------------- on-line API
    def update(self, u_k: float, y_k: float) -> np.ndarray:
        """Process one sample ``(u(k), y(k))``; returns the new estimate theta(k).

        A non-finite ``y_k`` is skipped (counted in :attr:`n_skipped`); a non-finite ``u_k``
        is an error since the model cannot be propagated without it.
        """
        u = np.array([_scalar(u_k, "u_k")])
        y = np.array([_scalar(y_k, "y_k")])
        if not np.isfinite(u[0]):
            raise ValueError(f"u_k: expected a finite input sample, got {u_k!r}")
        self._process(u, y, np.empty((1, len(self.theta))),
                      np.empty((1, self.n_diagnostics)))
        return self.theta.copy()

    def _process(self, u, y, history, diagnostics) -> None:
        before = self.n_recoveries
        skipped = int(np.count_nonzero(~np.isfinite(y)))
        self._run(u, y, history, diagnostics)
        self.k += len(u)
        self.n_skipped += skipped
        if self.n_recoveries > before:
            warnings.warn(
                f"{self.method}: {self.divergence_reason} {self.n_recoveries - before} "
                f"time(s), first at sample {self.first_recovery}; restarted from the last "
                "good estimate", RuntimeWarning, stacklevel=3,
            )

    def fit(
        self, record: Record, progress: Callable[[int, int], None] | None = None,
        chunk: int = 100_000,
    ) -> IdentificationResult:
        """Run over a whole record from the current state; returns the result with history.

        Parameters
        ----------
        record : Record
            Input and output samples (the identifier assumes the stage starts at rest unless
            it has already seen earlier samples).
        progress : callable, optional
            Called as ``progress(k, n)`` after each chunk.
        chunk : int
            Samples per compiled call (progress granularity).
        """
        if not isinstance(record, Record):
            raise TypeError(f"record: expected a hystid Record, got {type(record).__name__}")
        if not np.isclose(record.fs, self.fs, rtol=1e-9):
            raise ValueError(f"record {record.name!r}: fs {record.fs:g} Hz differs from the "
                             f"identifier's fs {self.fs:g} Hz")
        n = record.n
        history = np.empty((n, len(self.theta)))
        diagnostics = np.empty((n, self.n_diagnostics))
        for start in range(0, n, chunk):
            stop = min(n, start + chunk)
            self._process(record.u[start:stop], record.y[start:stop], history[start:stop],
                          diagnostics[start:stop])
            if progress is not None:
                progress(stop, n)
        return self.result(history, diagnostics)

    def result(
        self, history: np.ndarray | None = None, diagnostics: np.ndarray | None = None
    ) -> IdentificationResult:
        """The current estimate as an :class:`IdentificationResult`."""
        info = {"n_recoveries": self.n_recoveries, "first_recovery": self.first_recovery,
                "n_skipped": self.n_skipped, "samples": self.k}
        if diagnostics is not None and self.n_diagnostics:
            info["diagnostics"] = diagnostics
        conv = converged_at(history, self.epsilon) if history is not None else None
        return IdentificationResult(self.model, self.method, self.settings, history, conv, info)

    @property
    def model(self) -> DuhemSandwich:
        """The model of the current estimate."""
        return DuhemSandwich(self.theta.copy(), self.structure, fs=self.fs,
                             name=f"{self.method} estimate")

    @property
    def settings(self) -> dict:
        """The identifier's configuration (JSON-ready)."""
        return {"epsilon": self.epsilon, "theta0": _jsonable(self.theta0)}


def _scalar(value, name: str) -> float:
    arr = np.asarray(value, dtype=float)
    if arr.ndim != 0 and arr.shape != (1,):
        raise ValueError(f"{name}: expected one sample (a scalar), got shape {arr.shape}")
    return float(arr.reshape(()))


def _jsonable(value):
    if isinstance(value, np.ndarray):
        return value.tolist()
    return value
