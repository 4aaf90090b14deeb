"""Simulated responses as python-control :class:`~control.TimeResponseData`, signals by name.

A response holds labelled inputs, outputs and states like any python-control response, so
``resp.plot()``, ``resp.to_pandas()``, ``resp.outputs['y']`` and ``t, y = resp`` work. Each
labelled signal is also an attribute holding its 1-D samples (``resp.y``, ``resp.w1``,
``resp.u_ff``). python-control keeps all the outputs in an attribute ``y`` and all the inputs in
``u``; here ``resp.y`` and ``resp.u`` are the signals named ``y`` and ``u``, and the arrays of all
signals are ``resp.outputs``, ``resp.inputs`` and ``resp.states``.

This module imports python-control; :mod:`hystid` loads it only when a response is made.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING, Any

import control as ct
import numpy as np

if TYPE_CHECKING:  # pragma: no cover
    import pandas as pd

__all__ = ["LabelledResponse", "SandwichResponse"]


class LabelledResponse(ct.TimeResponseData):
    """A single-trace :class:`control.TimeResponseData` whose signals are attributes by label.

    Parameters
    ----------
    t : ndarray
        Time in seconds.
    inputs, outputs, states : mapping of str to ndarray
        Signals by label, each with one value per time (``states`` may be empty).
    name : str
        Name of the simulated system (``sysname``).
    title : str, optional
        Title of the response's plot.
    """

    def __init__(
        self,
        t: np.ndarray,
        inputs: dict[str, np.ndarray],
        outputs: dict[str, np.ndarray],
        states: dict[str, np.ndarray] | None = None,
        *,
        name: str = "system",
        title: str | None = None,
    ) -> None:
        states = states or {}
        self._labelled = False  # until python-control's __init__ is done: y, u are its arrays
        super().__init__(
            np.asarray(t, float), _stack(outputs), _stack(states) if states else None,
            _stack(inputs), issiso=len(inputs) == 1 and len(outputs) == 1,
            output_labels=list(outputs), state_labels=list(states) or None,
            input_labels=list(inputs), sysname=name, title=title or name,
        )
        self._labelled = True

    # python-control stores every output in ``y`` and every input in ``u``: kept aside here so
    # that ``y`` and ``u`` are the signals of those names.
    @property
    def y(self) -> np.ndarray:
        """The output labelled ``y`` (all outputs when none is)."""
        return self._named("y", self._all_outputs)

    @y.setter
    def y(self, value: np.ndarray) -> None:
        if self.__dict__.get("_labelled"):
            self._replace("y", value)
        else:
            self._all_outputs = value

    @property
    def u(self) -> np.ndarray:
        """The signal labelled ``u`` (all inputs when none is)."""
        return self._named("u", self._all_inputs)

    @u.setter
    def u(self, value: np.ndarray | None) -> None:
        if self.__dict__.get("_labelled"):
            self._replace("u", value)
        else:
            self._all_inputs = value

    def _replace(self, label: str, value: np.ndarray) -> None:
        """Give the signal ``label`` new samples (the arrays are copied, not written into)."""
        for labels_key, data_key in (("input_labels", "_all_inputs"),
                                     ("output_labels", "_all_outputs")):
            labels = self.__dict__.get(labels_key) or []
            if label in labels:
                data = np.array(self.__dict__[data_key], dtype=float)
                row = np.asarray(value, dtype=float).reshape(-1)
                if row.shape != data.shape[1:]:
                    raise ValueError(f"{label}: expected {data.shape[1]} samples, got shape "
                                     f"{np.shape(value)}")
                data[labels.index(label)] = row
                self.__dict__[data_key] = data
                return
        raise AttributeError(f"{type(self).__name__} has no signal {label!r} to replace")

    @property
    def outputs(self) -> ct.NamedSignal:
        """All outputs, indexable by label (python-control's squeeze rules)."""
        return self.as_time_response().outputs

    @property
    def inputs(self) -> ct.NamedSignal:
        """All inputs, indexable by label (python-control's squeeze rules)."""
        return self.as_time_response().inputs

    @property
    def name(self) -> str:
        """Name of the simulated system."""
        return self.sysname

    def _named(self, label: str, default: Any) -> Any:
        found = self._find(label)
        return default if found is None else found

    def _find(self, label: str) -> np.ndarray | None:
        d = self.__dict__
        if not d.get("_labelled"):
            return None
        for labels_key, data_key in (("input_labels", "_all_inputs"),
                                     ("output_labels", "_all_outputs"), ("state_labels", "x")):
            labels = d.get(labels_key) or []
            if label in labels and d.get(data_key) is not None:
                return d[data_key][labels.index(label)]
        return None

    def __getattr__(self, label: str) -> np.ndarray:
        # only reached when normal lookup fails: a signal by its label
        if label.startswith("_") or "output_labels" not in self.__dict__:
            raise AttributeError(label)
        found = self._find(label)
        if found is None:
            raise AttributeError(
                f"{type(self).__name__} has no attribute or signal {label!r} (signals: "
                f"{', '.join(self.signal_labels)})"
            )
        return found

    @property
    def signal_labels(self) -> list[str]:
        """Labels of the inputs, outputs and states, in that order."""
        return [*self.input_labels, *self.output_labels, *(self.state_labels or [])]

    def as_time_response(self) -> ct.TimeResponseData:
        """The same data as a plain :class:`control.TimeResponseData` (no arrays copied).

        Returns
        -------
        control.TimeResponseData
            With ``y``, ``u`` and ``x`` in python-control's layout (signal, time).
        """
        return ct.TimeResponseData(
            self.t, self._all_outputs, self.x, self._all_inputs, issiso=self.issiso,
            output_labels=self.output_labels, state_labels=self.state_labels,
            input_labels=self.input_labels, title=self.title, sysname=self.sysname,
        )

    def to_pandas(self) -> pd.DataFrame:
        """The signals as a data frame: a ``time`` column and one column per label.

        Returns
        -------
        pandas.DataFrame
            Columns ``time``, the inputs, the outputs and the states.
        """
        return self.as_time_response().to_pandas()

    def plot(self, *args: Any, **kwargs: Any) -> ct.ControlPlot:
        """Plot the outputs (and inputs) with :func:`control.time_response_plot`.

        Parameters
        ----------
        *args, **kwargs
            Passed to :func:`control.time_response_plot` (``plot_inputs``, ``ax``, ...).

        Returns
        -------
        control.ControlPlot
            The figure, its axes and lines.
        """
        return self.as_time_response().plot(*args, **kwargs)


class SandwichResponse(LabelledResponse):
    """Simulated signals of a sandwich model: input ``u``, output ``y``, states ``w1``, ``w2``.

    Unpacks as ``t, y`` like python-control responses.

    Parameters
    ----------
    t, u, w1, w2, y : ndarray
        Time (s), input, internal signals and output. ``u`` and ``y`` are in the record's units
        (the sensor offset included); ``w1`` and ``w2`` are relative to the model's rest.
    name : str
        Name of the simulated model.
    warnings : list of str, optional
        Why the response may not be trustworthy: the input left the model's envelope, or
        condition (8) failed (empty when neither).
    units : mapping, optional
        Units of ``u`` and ``y`` (shown in the plot's labels).

    Attributes
    ----------
    warnings : list of str
        As above.
    """

    def __init__(
        self,
        t: np.ndarray,
        u: np.ndarray,
        w1: np.ndarray,
        w2: np.ndarray,
        y: np.ndarray,
        name: str = "sandwich",
        warnings: Sequence[str] | None = None,
        *,
        units: dict[str, str] | None = None,
    ) -> None:
        units = units or {}
        label = {k: f"{k} [{units[k]}]" if units.get(k) else k for k in ("u", "y")}
        super().__init__(t, {"u": u}, {"y": y}, {"w1": w1, "w2": w2}, name=name,
                         title=f"{name}: {label['u']} -> {label['y']}")
        self.warnings = list(warnings or [])

    @property
    def duhem_margin(self) -> float:
        """max_k |dw1(k)|: condition (8) asks ``alpha * duhem_margin < 2``."""
        w1 = self.w1
        return float(np.max(np.abs(np.diff(w1)))) if len(w1) > 1 else 0.0


def _stack(signals: dict[str, np.ndarray]) -> np.ndarray:
    """Signals as rows of one float array (a view for a single signal), of one length."""
    rows = [np.asarray(v, dtype=float).reshape(-1) for v in signals.values()]
    if len({len(r) for r in rows}) > 1:
        sizes = ", ".join(f"{k}: {len(r)}" for k, r in zip(signals, rows, strict=True))
        raise ValueError(f"signals must share one length, got {sizes}")
    return rows[0][np.newaxis] if len(rows) == 1 else np.stack(rows)
