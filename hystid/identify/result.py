"""The result of an identification: the model, the parameter history and the settings used."""

from __future__ import annotations

from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

from ..model import DuhemSandwich

if TYPE_CHECKING:  # pragma: no cover
    from matplotlib.axes import Axes

__all__ = ["IdentificationResult", "converged_at"]


def converged_at(history: np.ndarray, epsilon: float) -> int | None:
    """First sample after which every parameter's relative change stays within ``epsilon``.

    The change at sample ``k`` is ``max_i |theta_i(k) - theta_i(k-1)| / max(|theta_i(k)|, 1e-12)``;
    the paper stops when it falls below the stop index ``epsilon`` (1e-4). Returns ``None`` when
    the estimate never settles.
    """
    history = np.asarray(history, dtype=float)
    if history.ndim != 2 or len(history) < 2:
        return None
    step = np.max(
        np.abs(np.diff(history, axis=0)) / np.maximum(np.abs(history[1:]), 1e-12), axis=1
    )
    above = np.flatnonzero(step > epsilon)
    if len(above) == 0:
        return 0
    k = int(above[-1]) + 1
    return k if k < len(history) - 1 else None


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
        Method-specific figures (cost, iterations, warnings...).
    """

    model: DuhemSandwich
    method: str
    settings: dict[str, Any] = field(default_factory=dict)
    history: np.ndarray | None = field(default=None, repr=False)
    converged_at: int | None = None
    info: dict[str, Any] = field(default_factory=dict, repr=False)

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
    ) -> np.ndarray:
        """Plot the parameter history (the paper's Fig. 3); returns the axes."""
        import matplotlib.pyplot as plt

        if self.history is None:
            raise ValueError(f"method {self.method!r} keeps no parameter history")
        names = self.names
        if axes is None:
            _, axes = plt.subplots(len(names), 1, sharex=True, figsize=(7, 1.4 * len(names)))
        axes = np.atleast_1d(axes)
        for ax, name, col in zip(axes, names, self.history.T, strict=False):
            ax.plot(col, lw=0.8)
            if truth and name in truth:
                ax.axhline(truth[name], color="k", ls="--", lw=0.6)
            ax.set_ylabel(name)
        axes[-1].set_xlabel("sample k")
        return axes
