"""The result of an identification: the model, the parameter history and the settings used."""

from __future__ import annotations

from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np
from numba import njit

from ..model import DuhemSandwich

if TYPE_CHECKING:  # pragma: no cover
    from matplotlib.axes import Axes
    from matplotlib.figure import Figure

__all__ = ["HISTORY_MODES", "HistoryRecorder", "IdentificationResult", "converged_at"]

#: How an on-line estimator keeps its parameter history: every sample, every m-th sample so that
#: at most ``history_rows`` rows are kept, or none.
HISTORY_MODES = ("full", "decimated", "none")


def converged_at(history: np.ndarray, epsilon: float) -> int | None:
    """First sample after which every parameter's relative change stays within ``epsilon``.

    The change at sample ``k`` is ``max_i |theta_i(k) - theta_i(k-1)| / max(|theta_i(k)|, 1e-12)``;
    the paper stops when it falls below the stop index ``epsilon`` (1e-4). Returns ``None`` when
    the estimate never settles.

    Parameters
    ----------
    history : ndarray
        Parameter history, one row per sample.
    epsilon : float
        The stop index.

    Returns
    -------
    int or None
        The sample index.
    """
    history = np.ascontiguousarray(history, dtype=float)
    if history.ndim != 2 or len(history) < 2:
        return None
    j = last_step_above(history, float(epsilon))
    if j < 0:
        return 0
    k = j + 1
    return k if k < len(history) - 1 else None


@njit(cache=True)
def last_step_above(rows, epsilon):
    """The last ``j`` whose step ``rows[j] -> rows[j + 1]`` exceeds ``epsilon`` (-1: none).

    The step is ``max_i |theta_i(j+1) - theta_i(j)| / max(|theta_i(j+1)|, 1e-12)`` (a NaN in
    it makes the step NaN, never above). Searched from the end, so that a run whose estimate
    is still moving costs one row, not a pass over the history.
    """
    n, p = rows.shape
    for j in range(n - 2, -1, -1):
        m = -np.inf
        for i in range(p):
            d = abs(rows[j + 1, i])
            if d < 1e-12:
                d = 1e-12
            v = abs(rows[j + 1, i] - rows[j, i]) / d
            if v != v:
                m = v
                break
            if v > m:
                m = v
        if m > epsilon:
            return j
    return -1


class HistoryRecorder:
    """The parameter history of a run, kept in full, decimated or not at all.

    The stop index (:func:`converged_at`) is followed on every sample whatever is kept, so a
    decimated history gives the same ``converged_at`` as the full one.

    Parameters
    ----------
    n : int
        Samples the run will see.
    n_params : int
        Parameters per row.
    n_diagnostics : int
        Diagnostic columns per row (0 for none).
    mode : {"full", "decimated", "none"}
        What to keep (see :data:`HISTORY_MODES`).
    rows : int
        Most rows kept by ``"decimated"``: every ``ceil(n / rows)``-th sample.
    epsilon : float
        Stop index of :func:`converged_at`.
    """

    def __init__(self, n: int, n_params: int, n_diagnostics: int, mode: str = "decimated",
                 rows: int = 100_000, epsilon: float = 1e-4) -> None:
        if mode not in HISTORY_MODES:
            raise ValueError(f"history: expected one of {', '.join(HISTORY_MODES)}, got {mode!r}")
        if int(rows) != rows or rows < 2:
            raise ValueError(f"history_rows: expected an integer >= 2, got {rows!r}")
        self.n, self.mode, self.epsilon = int(n), mode, float(epsilon)
        self.every = 1 if mode == "full" else max(1, -(-self.n // int(rows)))
        kept = 0 if mode == "none" else -(-self.n // self.every)
        self.history = np.empty((kept, n_params))
        self.diagnostics = np.empty((kept, n_diagnostics)) if n_diagnostics else None
        self.index = np.arange(kept) * self.every + (self.every - 1)
        if kept:
            self.index[-1] = min(self.index[-1], self.n - 1)
        self._seen = 0
        self._last = None
        self._last_above = -1

    def add(self, history: np.ndarray, diagnostics: np.ndarray | None = None) -> None:
        """Take the rows of the next samples (one row per sample).

        Parameters
        ----------
        history : ndarray
            Estimates after each of the next samples, shape ``(m, n_params)``.
        diagnostics : ndarray, optional
            Diagnostics after each of them, shape ``(m, n_diagnostics)``.
        """
        m = len(history)
        if m == 0:
            return
        history = np.ascontiguousarray(history, dtype=float)
        j = last_step_above(history, self.epsilon)
        if j >= 0:
            self._last_above = self._seen + j
        elif (self._last is not None
              and last_step_above(np.vstack([self._last, history[:1]]), self.epsilon) == 0):
            self._last_above = self._seen - 1  # the step from the previous chunk's last row
        self._last = history[-1:].copy()
        if len(self.history):
            first = self._seen
            pick = np.flatnonzero((np.arange(first, first + m) + 1) % self.every == 0)
            if first + m == self.n and (self.n % self.every):
                pick = np.r_[pick, m - 1]
            slot = (first + pick) // self.every
            self.history[slot] = history[pick]
            if self.diagnostics is not None and diagnostics is not None:
                self.diagnostics[slot] = diagnostics[pick]
        self._seen += m

    @property
    def converged_at(self) -> int | None:
        """First sample after which the estimate stays within the stop index (None: never)."""
        if self._seen < 2:
            return None
        k = self._last_above + 1
        return k if k < self._seen - 1 else None


@dataclass
class IdentificationResult:
    """What an identifier returns. Unpacks as ``model, history``.

    Attributes
    ----------
    model : DuhemSandwich
        The identified model (any sandwich model class).
    method : str
        Identifier name (``batch``, ``eria``, ``online``, ``ekf``...).
    settings : dict
        The identifier's settings, for the report.
    history : ndarray or None
        Parameter estimate after each sample, shape ``(N, n_params)`` (on-line methods).
    converged_at : int or None
        First sample after which the estimate stays within the stop index.
    info : dict
        Method-specific figures (cost, iterations, warnings...). ``info["warnings"]`` (a list
        of str), when present, says what the result should not be trusted for.
    history_index : ndarray or None
        Sample index of each row of :attr:`history` (``None``: one row per sample).
    """

    model: DuhemSandwich
    method: str
    settings: dict[str, Any] = field(default_factory=dict)
    history: np.ndarray | None = field(default=None, repr=False)
    converged_at: int | None = None
    info: dict[str, Any] = field(default_factory=dict, repr=False)
    history_index: np.ndarray | None = field(default=None, repr=False)

    def __iter__(self) -> Iterator[Any]:
        yield self.model
        yield self.history

    @property
    def params(self) -> dict[str, float]:
        """Identified parameters by name."""
        return self.model.params

    @property
    def names(self) -> tuple[str, ...]:
        """Parameter names, the columns of :attr:`history`."""
        return tuple(self.model.params)

    def plot(
        self,
        truth: dict[str, float] | None = None,
        axes: Axes | Sequence[Axes] | np.ndarray | None = None,
    ) -> Figure:
        """Plot the parameter history (the paper's Fig. 3) and return the figure.

        The figure is built without :mod:`matplotlib.pyplot`: no global figure is opened or
        left behind. Save it with ``fig.savefig(path)``; a notebook shows it as a cell's value.

        Parameters
        ----------
        truth : dict, optional
            True values by name, drawn as dashed lines.
        axes : matplotlib axes, optional
            One per parameter, in the order of :attr:`names`, all on one figure; by default a
            new figure with one panel per parameter, sharing the sample axis.

        Returns
        -------
        matplotlib.figure.Figure
            The figure holding the axes.

        Raises
        ------
        ValueError
            If the method keeps no parameter history, or fewer axes than parameters are given.
        """
        if self.history is None:
            raise ValueError(f"method {self.method!r} keeps no parameter history")
        names = self.names
        axes = _history_axes(len(names)) if axes is None else np.atleast_1d(axes).ravel()
        if len(axes) < len(names):
            raise ValueError(f"axes: expected {len(names)} axes (one per parameter: "
                             f"{', '.join(names)}), got {len(axes)}")
        samples = (np.arange(len(self.history)) if self.history_index is None
                   else np.asarray(self.history_index))
        for ax, name, col in zip(axes, names, self.history.T, strict=False):
            ax.plot(samples, col, lw=0.8)
            if truth and name in truth:
                ax.axhline(truth[name], color="k", ls="--", lw=0.6)
            ax.set_ylabel(name)
        axes[len(names) - 1].set_xlabel("sample k")
        return axes[0].figure


def _history_axes(count: int) -> np.ndarray:
    """A new figure (not pyplot's) with ``count`` panels stacked on a shared sample axis."""
    from matplotlib.figure import Figure

    fig = Figure(figsize=(7, 1.4 * count), layout="constrained")
    return fig.subplots(count, 1, sharex=True, squeeze=False)[:, 0]
