"""The contract every on-line estimator of hystid keeps.

The on-line identifier (:class:`~hystid.identify.online.OnlineIdentifier`), the paper's ERIA
(:class:`~hystid.identify.eria.ERIA`), the EKF baseline
(:class:`~hystid.identify.ekf.KalmanIdentifier`) and the PI recursion
(:class:`~hystid.identify.pi_recursive.PIRecursiveIdentifier`) all derive from :class:`Estimator`:

* configuration in the constructor, read back as the JSON-ready :attr:`Estimator.settings`;
* ``update(u_k, y_k)`` processes one sample and returns the parameter estimate theta(k)
  (a copy, in the order of :attr:`Estimator.names`);
* ``fit(record)`` **restarts**: it forgets everything learned (:meth:`Estimator.reset`) and runs
  over the record, so two calls on the same record give the same result (scikit-learn's
  meaning); ``partial_fit(record)`` **continues** from the current state, as ``update`` does;
* non-finite samples: a non-finite output ``y_k`` is skipped (the model is propagated, nothing is
  learned from it) and counted in :attr:`Estimator.n_skipped`; a non-finite input ``u_k`` is
  refused with a ``ValueError`` naming it, since the model cannot be propagated without it.
  ``fit`` and ``partial_fit`` warn once per call when samples were skipped;
* :attr:`Estimator.model` is the model of the current estimate and :meth:`Estimator.result` an
  :class:`~hystid.identify.result.IdentificationResult` of it.
"""

from __future__ import annotations

import math
import warnings
from abc import ABC, abstractmethod
from collections.abc import Callable
from typing import Any

import numpy as np

from ..signals import finite_signal
from .result import IdentificationResult

__all__ = ["Estimator", "as_sample", "finite_signal", "record_signals", "sample_arrays",
           "sample_floats"]


def as_sample(value: Any, argname: str) -> float:
    """One sample as a float (a scalar or a one-element array).

    Parameters
    ----------
    value : float or array_like
        The sample.
    argname : str
        Name used in the error message.

    Returns
    -------
    float
        The value (possibly non-finite: the caller decides).
    """
    if type(value) is float:  # the common case of a real-time loop, without numpy
        return value
    arr = np.asarray(value, dtype=float)
    if arr.size != 1:
        raise ValueError(f"{argname}: expected one sample (a scalar), got shape {arr.shape}")
    return float(arr.reshape(()))


def sample_arrays(u_k: Any, y_k: Any) -> tuple[np.ndarray, np.ndarray]:
    """One sample pair as two one-element arrays, for ``update(u_k, y_k)``.

    Parameters
    ----------
    u_k, y_k : float
        Input and output of the sample; the input must be finite (the output may not be: the
        estimators skip it).

    Returns
    -------
    u, y : ndarray
        One-element float64 arrays.
    """
    u, y = sample_floats(u_k, y_k)
    return np.array([u]), np.array([y])


def sample_floats(u_k: Any, y_k: Any) -> tuple[float, float]:
    """One sample pair as two floats, the input checked finite (without numpy for floats).

    Parameters
    ----------
    u_k, y_k : float
        Input and output of the sample; the input must be finite (the output may not be: the
        estimators skip it).

    Returns
    -------
    u, y : float
    """
    u, y = as_sample(u_k, "u_k"), as_sample(y_k, "y_k")
    if not math.isfinite(u):
        raise ValueError(f"u_k: expected a finite input sample, got {u_k!r}")
    return u, y


def record_signals(record: Any, fs: float) -> tuple[np.ndarray, np.ndarray, str]:
    """Input and output of a record for an estimator sampled at ``fs``.

    Parameters
    ----------
    record : Record or record-like
        Anything with 1-D ``u`` and ``y`` of one length and ``fs`` (a stream read elsewhere may
        hold non-finite outputs, which the estimators skip).
    fs : float
        The estimator's sampling rate in Hz.

    Returns
    -------
    u, y : ndarray
        Contiguous float64 copies; ``u`` is finite.
    name : str
        The record's name, for messages.
    """
    if not (hasattr(record, "u") and hasattr(record, "y")):
        raise TypeError(f"record: expected a hystid Record (with u, y and fs), got "
                        f"{type(record).__name__}")
    name = str(getattr(record, "name", "record"))
    u = finite_signal(record.u, f"record {name!r}: u")
    y = np.ascontiguousarray(record.y, dtype=float)
    if y.shape != u.shape:
        raise ValueError(f"record {name!r}: u and y must be 1-D of one length, got {u.shape} and "
                         f"{y.shape}")
    rec_fs = float(getattr(record, "fs", fs))
    if not np.isclose(rec_fs, fs, rtol=1e-9):
        raise ValueError(f"record {name!r}: fs {rec_fs:g} Hz differs from the estimator's fs "
                         f"{fs:g} Hz (pass fs={rec_fs:g})")
    return u, y, name


class Estimator(ABC):
    """Base class of the on-line estimators: one meaning for update, fit and settings.

    Subclasses implement :meth:`reset`, :meth:`update`, :meth:`partial_fit` and
    :attr:`settings`; :meth:`fit` is ``reset()`` followed by ``partial_fit(record)``.

    Attributes
    ----------
    method : str
        Short name of the method (``"online"``, ``"eria"``, ``"ekf"``, ``"pi-recursive"``).
    theta : ndarray
        Current parameter estimate, in the order of :attr:`names`.
    k : int
        Samples processed since the last :meth:`reset`.
    n_skipped : int
        Samples with a non-finite output, skipped.
    fs : float
        Sampling rate in Hz.
    """

    method = "estimator"
    theta: np.ndarray
    k: int = 0
    n_skipped: int = 0
    fs: float = 30_000.0

    @abstractmethod
    def reset(self) -> Any:
        """Forget everything learned: back to the start estimate at sample 0.

        Returns
        -------
        object
            The estimator (or None).
        """

    @abstractmethod
    def update(self, u_k: float, y_k: float) -> np.ndarray:
        """Process one sample ``(u(k), y(k))``.

        Parameters
        ----------
        u_k : float
            Input at sample k; must be finite.
        y_k : float
            Measured output at sample k; a non-finite value is skipped (:attr:`n_skipped`).

        Returns
        -------
        ndarray
            The estimate theta(k), a copy.
        """

    @abstractmethod
    def partial_fit(
        self, record: Any, progress: Callable[[int, int], None] | None = None
    ) -> IdentificationResult:
        """Run over a record from the current state (as repeated :meth:`update` calls would).

        Parameters
        ----------
        record : Record
            Input ``u`` and measured output ``y`` at :attr:`fs`.
        progress : callable, optional
            Called as ``progress(k, n)`` while the record is processed.

        Returns
        -------
        IdentificationResult
            The estimate with its history over this record.
        """

    def fit(
        self, record: Any, progress: Callable[[int, int], None] | None = None
    ) -> IdentificationResult:
        """Restart (:meth:`reset`) and run over a whole record.

        Parameters
        ----------
        record : Record
            Input ``u`` and measured output ``y`` at :attr:`fs`, the stage at rest before it.
        progress : callable, optional
            Called as ``progress(k, n)`` while the record is processed.

        Returns
        -------
        IdentificationResult
            The estimate with its history; the same for two calls on the same record.
        """
        self._restart(record)
        return self.partial_fit(record, progress=progress)

    def _restart(self, record: Any) -> None:
        """Back to the start before a whole-record :meth:`fit` (:meth:`reset`); estimators
        whose start depends on the record (its range, its first samples) override this, never
        :meth:`fit` itself."""
        self.reset()

    @property
    @abstractmethod
    def settings(self) -> dict[str, Any]:
        """The constructor's configuration as plain values (JSON-ready)."""

    @classmethod
    def _param_names(cls) -> tuple[str, ...]:
        """The constructor's parameter names (scikit-learn's convention: each is kept as the
        attribute of that name)."""
        import inspect

        sig = inspect.signature(cls.__init__)
        return tuple(p.name for p in sig.parameters.values() if p.name != "self"
                     and p.kind not in (p.VAR_POSITIONAL, p.VAR_KEYWORD))

    def get_params(self) -> dict[str, Any]:
        """The constructor's arguments as the estimator holds them, derived from its signature.

        ``type(est)(**est.get_params())`` builds an estimator with the same configuration
        (``tests/test_estimator_contract.py`` checks it for every estimator).

        Returns
        -------
        dict
            Parameter name -> value.
        """
        return {name: getattr(self, name) for name in self._param_names()}

    def set_params(self, **params: Any) -> Estimator:
        """Change constructor arguments; the estimator is built again from them and restarts.

        Parameters
        ----------
        **params
            Constructor arguments by name.

        Returns
        -------
        Estimator
            The estimator itself.

        Raises
        ------
        ValueError
            Naming an argument the constructor does not take (and the ones it does).
        """
        unknown = sorted(set(params) - set(self._param_names()))
        if unknown:
            raise ValueError(f"{type(self).__name__}.set_params: unknown parameter(s) "
                             f"{', '.join(unknown)} (expected some of "
                             f"{', '.join(self._param_names())})")
        self.__init__(**{**self.get_params(), **params})  # type: ignore[misc]
        return self

    @property
    def names(self) -> tuple[str, ...]:
        """Names of the entries of :attr:`theta`."""
        return tuple(self.model.params)

    @property
    @abstractmethod
    def model(self) -> Any:
        """The model of the current estimate."""

    def _warn_skipped(self, before: int) -> None:
        """One warning for the samples skipped since ``before`` (called by partial_fit)."""
        skipped = self.n_skipped - before
        if skipped:
            warnings.warn(f"{self.method}: {skipped} non-finite output samples skipped "
                          "(see n_skipped)", RuntimeWarning, stacklevel=3)

