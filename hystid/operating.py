"""Where a sandwich model sits in the world: rest level, sensor offset, units, input envelope.

The sandwich of eqs. (1), (2), (7) is written about a state of rest at zero. A measured stage
rests at some input level ``u_rest`` and its sensor reads ``offset`` there (the sensor's zero
is not the stage's). hystid keeps the paper's equations for the signals relative to that rest
and places the model in the record's units with two numbers::

    u_model(k) = u(k) - u_rest          (the input the sandwich sees)
    y(k)       = y_model(k) + offset    (what the sensor reads)

For the Duhem block without the ``f0 sgn`` term this is no restriction: eq. (7) is unchanged
when ``w1`` is shifted by ``c`` and ``w2`` by ``f1 c``, so a rest at ``u_rest`` is the rest at 0
of the shifted signals.

An identified model is valid for inputs like the ones it was identified on. The
:class:`Envelope` records them (range and slew); simulating on an input that leaves it, or on
which condition (8) ``alpha |dw1(k)| < 2`` fails, issues an :class:`AdmissibilityWarning`.
"""

from __future__ import annotations

import os
import warnings
from collections.abc import Mapping
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np

from .errors import AdmissibilityWarning
from .signals import finite_number

__all__ = ["AdmissibilityWarning", "Envelope", "Placed", "SLEW_QUANTILE", "warn_admissibility"]

#: The envelope's slew is this quantile of |du|: a slew the input holds for at least 0.1 % of
#: its samples. Isolated jumps (a step out of rest, a generator wrapping its last sample round)
#: are not part of what the input does.
SLEW_QUANTILE = 0.999
#: An input leaves the envelope's slew only when more than this share of its steps are faster
#: (twice the share the quantile leaves out): the quantile of a few isolated steps moves with
#: the record's length, and the first 4 000 samples of a model's own 4 200-sample training
#: record (a 3.5 V step out of rest and three more of 1.5-1.9 V) read 1.53 V per sample
#: against the 1.24 of the whole and were warned about.
FAST_SHARE = 2.0 * (1.0 - SLEW_QUANTILE)


@dataclass(frozen=True)
class Envelope:
    """Range and slew of the inputs a model was identified on.

    Parameters
    ----------
    u_min, u_max : float
        Smallest and largest input, in the record's units.
    slew : float
        Largest input change per sample that the input holds (the :data:`SLEW_QUANTILE`
        quantile of ``|u(k) - u(k-1)|``), in input units per sample.
    from_rest : bool
        Whether the record began with the stage at rest (True by default). When it did not,
        the model's rest level ``u_rest`` is the record's first input, a point of its motion,
        and the model's state there is nothing a stage rests in:
        :func:`hystid.baselines.simulate_from_rest` then settles the model at the loop's
        centre before a record (:func:`hystid.baselines.settled_at_centre`).
    """

    u_min: float
    u_max: float
    slew: float
    from_rest: bool = True

    def __post_init__(self) -> None:
        values = (self.u_min, self.u_max, self.slew)
        if not all(np.isfinite(v) for v in values) or self.u_max < self.u_min or self.slew < 0:
            raise ValueError(f"Envelope: expected finite u_min <= u_max and slew >= 0, got "
                             f"{values}")
        if not isinstance(self.from_rest, bool | np.bool_):
            raise ValueError(f"Envelope: expected from_rest true or false, got "
                             f"{self.from_rest!r}")
        object.__setattr__(self, "from_rest", bool(self.from_rest))

    @classmethod
    def of(cls, u: np.ndarray, *, from_rest: bool = True) -> Envelope:
        """The envelope of one input signal.

        Parameters
        ----------
        u : ndarray
            Input samples.
        from_rest : bool
            Whether the record began with the stage at rest.

        Returns
        -------
        Envelope
        """
        u = np.asarray(u, dtype=float)
        du = np.abs(np.diff(u)) if len(u) > 1 else np.zeros(1)
        return cls(float(np.min(u)), float(np.max(u)), float(np.quantile(du, SLEW_QUANTILE)),
                   from_rest)

    @property
    def amplitude(self) -> float:
        """Half the input range."""
        return 0.5 * (self.u_max - self.u_min)

    def violations(self, u: np.ndarray, tolerance: float = 0.1) -> list[str]:
        """How an input leaves this envelope (empty when it stays inside).

        Parameters
        ----------
        u : ndarray
            Input samples.
        tolerance : float
            Relative allowance: the range may grow by ``tolerance`` of the span at each end and
            the slew by ``tolerance`` of the envelope's slew (on more than :data:`FAST_SHARE`
            of the input's steps).

        Returns
        -------
        list of str
            One sentence per violation.
        """
        other = Envelope.of(u)
        span = max(self.u_max - self.u_min, 1e-300)
        out = []
        low, high = self.u_min - tolerance * span, self.u_max + tolerance * span
        if other.u_min < low or other.u_max > high:
            out.append(f"the input spans {other.u_min:.4g} .. {other.u_max:.4g}, outside the "
                       f"identified range {self.u_min:.4g} .. {self.u_max:.4g}")
        limit = (1.0 + tolerance) * self.slew
        fast = np.count_nonzero(np.abs(np.diff(np.asarray(u, dtype=float))) > limit)
        if other.slew > limit and fast > FAST_SHARE * max(len(u) - 1, 1):
            out.append(f"the input slews {other.slew:.4g} per sample, faster than the identified "
                       f"{self.slew:.4g}")
        return out

    def to_dict(self) -> dict[str, float | bool]:
        """The envelope as a plain dictionary (``Envelope(**d)`` rebuilds it).

        Returns
        -------
        dict
            The fields by name: numbers, and ``from_rest`` a bool.
        """
        return {k: v if k == "from_rest" else float(v) for k, v in asdict(self).items()}

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> Envelope:
        """Rebuild an envelope from :meth:`to_dict`'s output.

        Parameters
        ----------
        data : mapping
            Keys ``u_min``, ``u_max``, ``slew``; ``from_rest`` optional (true when absent: files
            written before it was kept).

        Returns
        -------
        Envelope
        """
        from_rest = data.get("from_rest", True)
        if not isinstance(from_rest, bool):
            raise ValueError(f"envelope: expected from_rest true or false, got {from_rest!r}")
        try:
            values = [data[k] for k in ("u_min", "u_max", "slew")]
            if any(isinstance(v, bool | str | bytes) for v in values):  # not numbers, though
                raise TypeError("true, false or text")              # float() takes them
            return cls(*(float(v) for v in values), from_rest)
        except (KeyError, TypeError, ValueError, OverflowError) as err:
            raise ValueError(f"envelope: expected numbers u_min, u_max, slew, got "
                             f"{str(dict(data))[:120]}") from err


def warn_admissibility(messages: list[str], name: str, stacklevel: int = 3) -> None:
    """Issue one :class:`AdmissibilityWarning` carrying every message (nothing when empty).

    Parameters
    ----------
    messages : list of str
        What is wrong, one sentence each.
    name : str
        The model's name.
    stacklevel : int
        Passed to :func:`warnings.warn`.
    """
    if messages:
        warnings.warn(f"model {name!r}: " + "; ".join(messages), AdmissibilityWarning,
                      stacklevel=stacklevel)


class Placed:
    """What both sandwiches share beyond their equations: rest level, offset, envelope, units.

    Attributes
    ----------
    u_rest, offset : float
        Input rest level and sensor offset (see the module docstring).
    envelope : Envelope or None
        Inputs the model was identified on.
    units : dict
        Units of ``u`` and ``y``.
    """

    u_rest: float
    offset: float
    envelope: Envelope | None
    units: dict[str, str]

    def _place(self, u_rest: float, offset: float, envelope: Envelope | None,
               units: Mapping[str, str] | None) -> None:
        self.u_rest, self.offset = finite_number(u_rest, "u_rest"), finite_number(offset, "offset")
        self.envelope = envelope
        self.units = dict(units) if units is not None else {"u": "V", "y": "um"}

    def save(
        self,
        path: str | os.PathLike[str],
        *,
        provenance: Mapping[str, Any] | None = None,
        force: bool = False,
    ) -> Path:
        """Keep the model in a versioned JSON file (see :func:`hystid.modelfile.save_model`).

        Parameters
        ----------
        path : str or os.PathLike
            The file; an existing one is replaced only with ``force``.
        provenance : mapping, optional
            Method, record hash and settings (:func:`hystid.modelfile.make_provenance`).
        force : bool
            Replace an existing file.

        Returns
        -------
        pathlib.Path
            The written file; :func:`hystid.load_model` reads it back.
        """
        from .document import save_model

        return save_model(self, path, provenance=provenance, force=force)


