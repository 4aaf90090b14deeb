"""The record: one experiment's input and output, uniformly sampled, and its writers.

Its errors are :class:`~hystid.errors.RecordError`.
"""

from __future__ import annotations

import json
import math
import operator
import os
import re
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import RecordError
from ..safeio import atomic_open, atomic_path
from ..signals import finite_signal

#: Largest relative deviation of one time step from the median step for ``t`` to count as uniform.
T_UNIFORM_RTOL = 1e-3
#: Largest relative difference between a stated ``fs`` and the one derived from ``t``.
FS_RTOL = 1e-6
#: Array files may decode to at most this many times their size (beyond EXPANSION_FLOOR).
MAX_EXPANSION = 20
#: Decoded bytes always allowed, whatever the file size (64 MiB).
EXPANSION_FLOOR = 64 << 20

_CSV_SUFFIXES = (".csv", ".txt", ".tsv")
_H5_SUFFIXES = (".h5", ".hdf5")
_SUFFIXES = (*_CSV_SUFFIXES, ".npz", ".mat", *_H5_SUFFIXES)
_ROLES = ("t", "u", "y")
_DEFAULT_UNITS = {"u": "V", "y": "um"}
_META_PREFIX = "hystid record:"
_META_RE = re.compile(r"name=(?P<name>.*), fs=(?P<fs>[^,]*), units(?P<units>.*)$")

#: Where a value sits in a file: keyword arguments for :class:`RecordError`.
Locator = Callable[[int], dict[str, Any]]


def control_characters(text: str) -> bool:
    """Whether a label holds control characters (a line break, an escape sequence).

    A unit or a name is written into files' header lines and printed on terminals: a line break
    there would end the header line early, an escape sequence would drive the terminal.

    Parameters
    ----------
    text : str
        The label.

    Returns
    -------
    bool
        True when any character is a control character (Unicode category Cc).
    """
    return any(ord(c) < 32 or 127 <= ord(c) < 160 for c in text)


def _printable(text: str) -> str:
    """``text`` with every run of whitespace or control characters made one space."""
    return " ".join("".join(" " if control_characters(c) else c for c in text).split())


# --------------------------------------------------------------------------- the record
@dataclass(eq=False, repr=False)
class Record:
    """One input/output experiment sampled uniformly.

    Parameters
    ----------
    u : array_like
        Input signal, 1-D, converted to float64.
    y : array_like
        Output signal, 1-D, same length as ``u``, converted to float64.
    fs : float
        Sampling rate in Hz, finite and > 0.
    units : dict of str to str, optional
        Units of the signals, by default ``{"u": "V", "y": "um"}``.
    name : str, optional
        Short label used in messages and plots, by default ``"record"``.

    Raises
    ------
    RecordError
        If a signal is not 1-D, is empty, contains a non-finite value, the lengths differ, or
        ``fs`` is not a finite positive number.

    Notes
    -----
    Slicing with a step of 1 (``rec[a:b]``) returns a new record; integer indexing is refused.
    Two records compare equal only if they are the same object.
    """

    u: np.ndarray
    y: np.ndarray
    fs: float
    units: dict[str, str] = field(default_factory=lambda: dict(_DEFAULT_UNITS))
    name: str = "record"

    def __post_init__(self) -> None:
        self.name = str(self.name)
        where = f"record {self.name!r}"
        self.u, self.y = (finite_signal(v, f"{where}: {label}", min_size=1, copy=True,
                                        error=RecordError)
                          for v, label in ((self.u, "u"), (self.y, "y")))
        if self.u.size != self.y.size:
            raise RecordError(
                f"{where}: u and y have different lengths (u: {self.u.size}, y: {self.y.size}) "
                "(expected equal lengths)"
            )
        self.fs = _as_fs(self.fs, where)
        if not isinstance(self.units, Mapping):
            raise RecordError(f"{where}: units must be a mapping such as {_DEFAULT_UNITS!r}")
        self.units = {str(key): str(value) for key, value in self.units.items()}
        for key, value in self.units.items():
            if control_characters(value):
                raise RecordError(f"{where}: the unit of {key} is {value!r}, which holds control "
                                  "characters (expected a plain unit name such as 'um')")

    # ----------------------------------------------------------------------- properties
    @property
    def n(self) -> int:
        """int: Number of samples."""
        return int(self.u.size)

    @property
    def t(self) -> np.ndarray:
        """numpy.ndarray: Sample times ``k / fs`` in seconds, starting at 0."""
        return np.arange(self.n) / self.fs

    @property
    def duration(self) -> float:
        """float: Time covered by the samples, ``n / fs`` seconds (``t[-1] + 1 / fs``)."""
        return self.n / self.fs

    def __len__(self) -> int:
        """Return the number of samples."""
        return self.n

    def __repr__(self) -> str:
        """Return a one-line summary (name, length, sampling rate, units)."""
        return (
            f"Record(name={self.name!r}, n={self.n}, fs={self.fs:g}, units={self.units!r})"
        )

    # ----------------------------------------------------------------------- slicing
    def __getitem__(self, key: slice) -> Record:
        """Return the samples selected by a slice with step 1 as a new record.

        Parameters
        ----------
        key : slice
            ``start:stop`` with an optional step of 1; negative bounds count from the end.

        Returns
        -------
        Record
            A new record with copies of the selected samples and the same ``fs``, units and name.

        Raises
        ------
        TypeError
            If ``key`` is not a slice (for example an integer).
        ValueError
            If the slice has a step other than 1 or selects no samples.
        """
        if not isinstance(key, slice):
            raise TypeError(
                f"Record indices must be slices such as rec[100:2000], not "
                f"{type(key).__name__}; use rec.u[k] or rec.y[k] for single samples"
            )
        if key.step not in (None, 1):
            raise ValueError(f"Record slices must have step 1, got step {key.step!r}")
        start, stop, _ = key.indices(self.n)
        if stop <= start:
            raise ValueError(
                f"slice {key.start}:{key.stop} selects no samples of record {self.name!r} "
                f"({self.n} samples)"
            )
        return self._part(start, stop)

    def _part(self, start: int, stop: int) -> Record:
        return Record(
            u=self.u[start:stop].copy(),
            y=self.y[start:stop].copy(),
            fs=self.fs,
            units=dict(self.units),
            name=self.name,
        )

    def split(
        self, fraction: float | None = None, *, at: int | None = None
    ) -> tuple[Record, Record]:
        """Split into a training and a validation record.

        Parameters
        ----------
        fraction : float, optional
            Share of the samples in the training part, in (0, 1); 0.5 when neither ``fraction``
            nor ``at`` is given. The split index is ``round(fraction * n)``, kept so that both
            parts have at least one sample.
        at : int, optional
            Split index instead of ``fraction``: the training part is ``rec[:at]`` and the
            validation part ``rec[at:]``; must be in ``1 .. n - 1``.

        Returns
        -------
        tuple of Record
            ``(train, validation)``.

        Raises
        ------
        ValueError
            If both arguments are given, if either is out of range, or if the record has fewer
            than 2 samples.
        """
        if fraction is not None and at is not None:
            raise ValueError("split: give either fraction or at, not both")
        if self.n < 2:
            raise ValueError(f"split: record {self.name!r} has {self.n} sample; cannot split it")
        if at is None:
            k = self._split_index(0.5 if fraction is None else fraction)
        else:
            if isinstance(at, bool):
                raise ValueError(f"split: at must be an integer sample index, got {at!r}")
            try:
                k = operator.index(at)
            except TypeError as err:
                raise ValueError(f"split: at must be an integer sample index, got {at!r}") from err
            if not 1 <= k <= self.n - 1:
                raise ValueError(f"split: at must be in 1..{self.n - 1}, got {k}")
        return self._part(0, k), self._part(k, self.n)

    def _split_index(self, fraction: float) -> int:
        try:
            value = float(fraction)
        except (TypeError, ValueError) as err:
            raise ValueError(
                f"split: fraction must be a number in (0, 1), got {fraction!r}"
            ) from err
        if not 0.0 < value < 1.0:
            raise ValueError(f"split: fraction must be in (0, 1), got {fraction!r}")
        return min(max(round(value * self.n), 1), self.n - 1)

    # ----------------------------------------------------------------------- export
    def to_dict(self) -> dict[str, Any]:
        """Return the record as a plain dictionary.

        Returns
        -------
        dict
            Keys ``u`` and ``y`` (copies of the arrays), ``fs`` (float), ``units`` (a copy) and
            ``name``; ``Record(**rec.to_dict())`` rebuilds the record.
        """
        return {
            "u": self.u.copy(),
            "y": self.y.copy(),
            "fs": self.fs,
            "units": dict(self.units),
            "name": self.name,
        }

    def save(self, path: str | os.PathLike[str]) -> None:
        """Write the record to a file; the format follows the extension.

        Parameters
        ----------
        path : str or os.PathLike
            Destination, replaced if it exists. The file is written under a temporary name in
            the same folder and renamed over ``path`` once complete, so a failure (a full disk)
            leaves any previous file as it was:

            - ``.csv``, ``.txt`` or ``.tsv`` (tab-separated): a comment line
              ``# hystid record: name=..., fs=..., units u=V y=um``, the header ``t,u,y`` and one
              row per sample, numbers with 17 significant digits (exact round trip);
            - ``.npz``: arrays ``u``, ``y``, ``fs`` and 0-d unicode arrays ``name`` and ``units``
              (JSON), readable with ``allow_pickle=False``;
            - ``.mat``: variables ``u``, ``y`` (columns), ``fs``, ``name`` and ``units`` (JSON);
            - ``.h5`` or ``.hdf5``: datasets ``u`` and ``y`` and attributes ``fs``, ``name`` and
              ``units`` (JSON) at the root.

        Raises
        ------
        RecordError
            If the extension is none of the above.
        """
        suffix = Path(path).suffix.lower()
        writers = {".npz": _save_npz, ".mat": _save_mat}
        writers.update(dict.fromkeys(_CSV_SUFFIXES, _save_csv))
        writers.update(dict.fromkeys(_H5_SUFFIXES, _save_h5))
        if suffix not in writers:
            raise RecordError(_unknown_extension(suffix), file=path)
        writers[suffix](self, path)


def _as_fs(fs: Any, where: str) -> float:
    try:
        value = float(fs)
    except (TypeError, ValueError) as err:
        raise RecordError(f"{where}: fs must be a number, got {fs!r}") from err
    if not (math.isfinite(value) and value > 0):
        raise RecordError(f"{where}: fs is {fs!r} (expected a finite sampling rate > 0 Hz)")
    return value


def _unknown_extension(suffix: str) -> str:
    shown = repr(suffix) if suffix else "none"
    return f"unknown extension {shown} (expected one of {', '.join(_SUFFIXES)})"


# --------------------------------------------------------------------------- writers
def _meta_line(rec: Record) -> str:
    name = _printable(rec.name)
    units = " ".join(f"{key}={_printable(value).replace(' ', '_')}"
                     for key, value in rec.units.items())
    return f"# {_META_PREFIX} name={name}, fs={rec.fs!r}, units {units}\n"


def _save_csv(rec: Record, path: str | os.PathLike[str]) -> None:
    sep = "\t" if Path(path).suffix.lower() == ".tsv" else ","
    with atomic_open(path, "w", newline="\n") as out:
        out.write(_meta_line(rec))
        out.write(sep.join("tuy") + "\n")
        np.savetxt(out, np.column_stack([rec.t, rec.u, rec.y]), fmt="%.17g", delimiter=sep)


def _save_npz(rec: Record, path: str | os.PathLike[str]) -> None:
    with atomic_open(path, "wb") as out:  # an open file keeps numpy from appending ".npz"
        np.savez(
            out,
            u=rec.u,
            y=rec.y,
            fs=np.float64(rec.fs),
            name=np.array(rec.name, dtype=np.str_),
            units=np.array(json.dumps(rec.units), dtype=np.str_),
        )


def _save_mat(rec: Record, path: str | os.PathLike[str]) -> None:
    from scipy.io import savemat

    with atomic_open(path, "wb") as out:
        savemat(
            out,
            {"u": rec.u, "y": rec.y, "fs": rec.fs, "name": rec.name,
             "units": json.dumps(rec.units)},
            oned_as="column",
        )


def _save_h5(rec: Record, path: str | os.PathLike[str]) -> None:
    import h5py

    with atomic_path(path) as tmp, h5py.File(tmp, "w") as out:
        out.create_dataset("u", data=rec.u)
        out.create_dataset("y", data=rec.y)
        out.attrs["fs"] = rec.fs
        out.attrs["name"] = rec.name
        out.attrs["units"] = json.dumps(rec.units)


