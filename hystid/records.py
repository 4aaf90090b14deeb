"""Input/output records of a positioning stage and their loaders.

A :class:`Record` holds one experiment: the input ``u`` (typically the amplifier voltage), the
output ``y`` (typically the measured displacement), both sampled uniformly at ``fs`` Hz.

:func:`load_record` reads a record from CSV (``.csv``, ``.txt``), NumPy (``.npz``), MATLAB
(``.mat``) or HDF5 (``.h5``, ``.hdf5``, optionally ``file.h5:group/path``) files, and
:meth:`Record.save` writes the same formats. Every problem with the input data raises a
:class:`RecordError` whose message names the file, the line and the column (or the array and the
index) and says what was expected.

Time columns
------------
When a file carries a time vector ``t`` instead of (or besides) a sampling rate, ``fs`` is derived
from it. ``t`` must be strictly increasing and uniform: every step must be within
:data:`T_UNIFORM_RTOL` (0.1 %) of the median step. The tolerance is that loose on purpose: measured
files print ``t`` with about nine significant digits and their acquisition clock jitters (the
5 kHz piezo record steps between 0.19998 ms and 0.20002 ms, 1.5e-4 relative), while a genuinely
irregular sample (for example one sample 10 % late) is still rejected. Since single steps are that
noisy, ``fs`` is taken from the whole span, ``(n - 1) / (t[-1] - t[0])``, rather than from one
step. A sampling rate stated beside ``t`` (the ``fs=`` argument, or the comment line written by
:meth:`Record.save`) must agree with it within :data:`FS_RTOL`; the stated value is then used.
The time origin is not kept: :attr:`Record.t` always starts at 0.

Hostile files
-------------
A record file is read from its own bytes only, and never decodes to much more than it holds:

* HDF5 external links, datasets stored in external files and virtual datasets are refused;
* the declared size of every array (npz member, MATLAB variable -- read from the variable
  headers without inflating the data -- or HDF5 dataset) may exceed the file's size at most
  :data:`MAX_EXPANSION` times, or :data:`EXPANSION_FLOOR` bytes, whichever is larger;
* an npz member whose header declares more samples than it stores, and an uncompressed HDF5
  dataset whose storage is smaller than its shape (unwritten or truncated), are refused;
* truncated or corrupt archives give a :class:`RecordError` naming the file.

Two roles may not read the same column (``columns={"u": "y"}`` would identify ``y`` from
itself). :meth:`Record.save` writes atomically (see :mod:`hystid.safeio`).
"""

from __future__ import annotations

import csv
import itertools
import json
import math
import operator
import os
import re
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from .safeio import atomic_open, atomic_path
from .signals import finite_signal

__all__ = [
    "EXPANSION_FLOOR",
    "FS_RTOL",
    "MAX_EXPANSION",
    "T_UNIFORM_RTOL",
    "Record",
    "RecordError",
    "load_piezo_sine_150v",
    "load_record",
    "parse_columns",
    "read_records",
]

#: Largest relative deviation of one time step from the median step for ``t`` to count as uniform.
T_UNIFORM_RTOL = 1e-3
#: Largest relative difference between a stated ``fs`` and the one derived from ``t``.
FS_RTOL = 1e-6
#: Array files may decode to at most this many times their size (beyond EXPANSION_FLOOR).
MAX_EXPANSION = 20
#: Decoded bytes always allowed, whatever the file size (64 MiB).
EXPANSION_FLOOR = 64 << 20

_CSV_SUFFIXES = (".csv", ".txt")
_H5_SUFFIXES = (".h5", ".hdf5")
_SUFFIXES = (*_CSV_SUFFIXES, ".npz", ".mat", *_H5_SUFFIXES)
_ROLES = ("t", "u", "y")
_DEFAULT_UNITS = {"u": "V", "y": "um"}
_META_PREFIX = "hystid record:"
_META_RE = re.compile(r"name=(?P<name>.*), fs=(?P<fs>[^,]*), units(?P<units>.*)$")

#: Where a value sits in a file: keyword arguments for :class:`RecordError`.
Locator = Callable[[int], dict[str, Any]]


class RecordError(ValueError):
    """A record or a record file is invalid.

    The message starts with the location of the problem (file, line, column, or array and index,
    whichever are known) followed by what is wrong and what was expected, for example
    ``rec.csv, line 17, column 'y': value 'nan' is not finite (expected a finite number)``.

    Parameters
    ----------
    message : str
        What is wrong and what was expected.
    file : str or os.PathLike, optional
        The file, as the user named it.
    line : int, optional
        1-based line number, counting comment and header lines.
    column : str, optional
        Column name (CSV files).
    array : str, optional
        Array, variable or dataset name (NumPy, MATLAB and HDF5 files).
    kind : str, optional
        What ``array`` is called in the message: ``"array"`` (default), ``"variable"``, ...
    index : int, optional
        0-based sample index in ``array``.

    Attributes
    ----------
    file, line, column, array, index
        The location given at construction (``None`` when unknown).
    """

    def __init__(
        self,
        message: str,
        *,
        file: str | os.PathLike[str] | None = None,
        line: int | None = None,
        column: str | None = None,
        array: str | None = None,
        kind: str = "array",
        index: int | None = None,
    ) -> None:
        self.file = None if file is None else os.fspath(file)
        self.line = line
        self.column = column
        self.array = array
        self.index = index
        parts = []
        if self.file is not None:
            parts.append(self.file)
        if line is not None:
            parts.append(f"line {line}")
        if column is not None:
            parts.append(f"column {column!r}")
        if array is not None:
            parts.append(f"{kind} {array!r}")
        if index is not None:
            parts.append(f"index {index}")
        super().__init__(f"{', '.join(parts)}: {message}" if parts else message)


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

            - ``.csv`` or ``.txt``: a comment line
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
    name = " ".join(rec.name.splitlines())
    units = " ".join(f"{key}={value.replace(' ', '_')}" for key, value in rec.units.items())
    return f"# {_META_PREFIX} name={name}, fs={rec.fs!r}, units {units}\n"


def _save_csv(rec: Record, path: str | os.PathLike[str]) -> None:
    with atomic_open(path, "w", newline="\n") as out:
        out.write(_meta_line(rec))
        out.write("t,u,y\n")
        np.savetxt(out, np.column_stack([rec.t, rec.u, rec.y]), fmt="%.17g", delimiter=",")


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


# --------------------------------------------------------------------------- loading
def parse_columns(text: str) -> dict[str, str | int]:
    """Parse a column map written ``role=column,...`` (``t=1,u=3,y=2`` or ``u=voltage,y=disp``).

    Digits give 0-based positions, anything else a column or array name; the result is the
    ``columns`` argument of :func:`load_record`. Raises ``ValueError`` on a malformed text.

    Parameters
    ----------
    text : str
        The map, e.g. ``t=1,u=3,y=2``.

    Returns
    -------
    dict
        Role (``t``, ``u``, ``y``) to a column name or a 0-based position.
    """
    out: dict[str, str | int] = {}
    for part in text.split(","):
        role, sep, col = (s.strip() for s in part.partition("="))
        if not sep or not role or not col:
            raise ValueError(f"expected role=column pairs like t=1,u=3,y=2, got {text!r}")
        if role in out:
            raise ValueError(f"role {role!r} is given twice in {text!r} (expected each of t, u, "
                             "y at most once)")
        out[role] = int(col) if col.lstrip("-").isdigit() else col
    _distinct_columns(out, repr(text))
    return out


def parse_units(text: str) -> dict[str, str]:
    """Parse the units of a record written ``u=N,y=m`` (the ``units`` of :func:`load_record`).

    Raises ``ValueError`` on a malformed text.

    Parameters
    ----------
    text : str
        The map, e.g. ``u=N,y=m`` or ``y=nm``.

    Returns
    -------
    dict
        ``u`` and/or ``y`` to a unit name.
    """
    out: dict[str, str] = {}
    for part in text.split(","):
        role, sep, unit = (s.strip() for s in part.partition("="))
        if not sep or role not in ("u", "y") or not unit or role in out:
            raise ValueError(f"expected u=UNIT,y=UNIT (each at most once) like u=V,y=um, got "
                             f"{text!r}")
        out[role] = unit
    return out


def _distinct_columns(columns: Mapping[str, str | int], shown: str) -> None:
    """Raise ``ValueError`` when two roles read the same column (roles left out keep their
    own name, e.g. ``u=y`` alone reads u and y from column 'y')."""
    positions = columns and all(isinstance(v, int) and not isinstance(v, bool)
                                for v in columns.values())
    where = dict(columns) if positions else {r: columns.get(r, r) for r in _ROLES}
    seen: dict[Any, str] = {}
    for role, col in where.items():
        key = col.casefold() if isinstance(col, str) else col
        if key in seen:
            raise ValueError(f"{shown}: {seen[key]} and {role} both read column {col!r} "
                             "(expected a different column for each of t, u, y; an output read "
                             "from the input column identifies nothing)")
        seen[key] = role


def load_record(
    path: str | os.PathLike[str],
    *,
    fs: float | None = None,
    columns: Mapping[str, str | int] | None = None,
    name: str | None = None,
    units: Mapping[str, str] | None = None,
) -> Record:
    """Load a record from a file; the format follows the extension.

    Parameters
    ----------
    path : str or os.PathLike
        The file. ``.csv`` and ``.txt``: delimited text; ``.npz``; ``.mat``; ``.h5`` and
        ``.hdf5``, where ``file.h5:group/path`` reads the datasets of that group.
    fs : float, optional
        Sampling rate in Hz. Required when the file has neither a time vector ``t`` nor a stored
        ``fs``; otherwise checked against the file (within :data:`FS_RTOL`) and used.
    columns : mapping, optional
        Where the signals ``"t"``, ``"u"`` and ``"y"`` are, for files that do not use these
        names. Strings name CSV header columns (case-insensitive) or arrays, variables or
        datasets, e.g. ``{"t": "time", "u": "voltage", "y": "displacement"}``; roles left out
        keep their own name. Integers are 0-based column positions of a CSV file that has *no*
        header line, e.g. ``{"t": 1, "u": 3, "y": 2}``; then ``u`` and ``y`` must both be given
        and all values must be integers.
    name : str, optional
        Name of the record; by default the name stored in the file, else the file stem (with
        the HDF5 group appended).
    units : mapping, optional
        The units of ``u`` and ``y``, e.g. ``{"u": "N", "y": "m"}``; they replace what the file
        states. Without them and without units stored in the file the record says V and um,
        which only labels the numbers (the fits do not depend on the units).

    Returns
    -------
    Record
        The loaded record. Units come from ``units``, else from the file when it stores them
        (files written by :meth:`Record.save`), else the :class:`Record` default.

    Raises
    ------
    RecordError
        If the file is missing or unreadable, or its content is invalid. See the module notes
        for the rules on time vectors.

    Notes
    -----
    CSV rules: lines starting with ``#`` (after optional blanks) and blank lines are skipped;
    the first remaining line is the header unless ``columns`` gives integer positions; the
    fields are separated by ``;``, a tab or ``,`` (the first of these the header, or the first
    row of a file without header, holds outside double quotes) or else by blanks, and may be
    quoted with double quotes (``"1.5"``; a decimal comma is not a number); every
    row has as many fields as the header (or as the first row when there is no header); values
    of the used columns must be finite numbers, unused columns may hold anything (even nothing).
    """
    text = os.fspath(path)
    file, group = _split_h5_group(text)
    suffix = Path(file).suffix.lower()
    if Path(file).is_dir():
        raise RecordError("file is a directory (expected a record file)", file=file)
    if suffix not in _SUFFIXES:
        raise RecordError(_unknown_extension(suffix), file=text)
    if not Path(file).is_file():
        reason = "is a directory" if Path(file).is_dir() else "does not exist"
        raise RecordError(f"file {reason} (expected a record file)", file=file)
    roles = _check_columns(columns, text)
    stated = _check_units(units, text)
    if suffix in _CSV_SUFFIXES:
        rec = _load_csv(file, fs, roles, name)
    else:
        if suffix == ".npz":
            source = _read_npz(file, roles)
        elif suffix == ".mat":
            source = _read_mat(file, roles)
        else:
            source = _read_h5(file, group, roles)
        rec = _record_from_arrays(source, fs, name)
    if stated:
        rec.units = {**rec.units, **stated}
    return rec


def _check_units(units: Mapping[str, str] | None, where: str) -> dict[str, str]:
    if units is None:
        return {}
    if not isinstance(units, Mapping) or not set(units) <= {"u", "y"} or not all(
            isinstance(v, str) and v.strip() for v in units.values()):
        raise RecordError(f"units={units!r} (expected a mapping of 'u' and/or 'y' to unit "
                          "names, e.g. {'u': 'N', 'y': 'm'})", file=where)
    return {k: v.strip() for k, v in units.items()}


def load_piezo_sine_150v(path: str | os.PathLike[str]) -> Record:
    """Load the measured piezo actuator record ``hysteresis_v_150_1hz.csv``.

    The file has no header and four columns: an empty index, time [s], displacement [um] and
    voltage [V], sampled at 5 kHz for 10 s (50 001 rows).

    Parameters
    ----------
    path : str or os.PathLike
        The CSV file, or the folder holding ``hysteresis_v_150_1hz.csv``.

    Returns
    -------
    Record
        ``u`` the voltage [V], ``y`` the displacement [um], ``fs`` from the time column, named
        after the folder (``piezo_sine_150V_1Hz``).

    Raises
    ------
    RecordError
        If the file is missing or does not have that layout.
    """
    file = Path(path)
    if file.is_dir():
        file = file / "hysteresis_v_150_1hz.csv"
    return load_record(file, columns={"t": 1, "y": 2, "u": 3}, name=file.parent.name,
                       units={"u": "V", "y": "um"})


def read_records(
    paths: str | os.PathLike[str] | Iterable[str | os.PathLike[str]], fs: float | None = None
) -> list[Record]:
    """Load several records with :func:`load_record`.

    Parameters
    ----------
    paths : path or iterable of paths
        The files; a single path is accepted too.
    fs : float, optional
        Sampling rate passed to every :func:`load_record` call.

    Returns
    -------
    list of Record
        One record per path, in order.

    Raises
    ------
    RecordError
        From the first file that fails to load.
    """
    if isinstance(paths, str | os.PathLike):
        paths = [paths]
    return [load_record(path, fs=fs) for path in paths]


def _split_h5_group(text: str) -> tuple[str, str | None]:
    """Split ``file.h5:group/path`` into the file and the group (``None`` without a group)."""
    head, sep, tail = text.rpartition(":")
    if sep and Path(head).suffix.lower() in _H5_SUFFIXES:
        return head, tail.strip("/") or None
    return text, None


def _check_columns(columns: Mapping[str, str | int] | None, file: str) -> dict[str, str | int]:
    """Validate ``columns``; return the role -> name or position map."""
    if columns is None:
        return {}
    if not isinstance(columns, Mapping):
        raise RecordError(f"columns must be a mapping such as {{'u': 'voltage'}}, got {columns!r}",
                          file=file)
    unknown = sorted(set(columns) - set(_ROLES))
    if unknown:
        raise RecordError(f"columns has unknown keys {unknown} (expected some of t, u, y)",
                          file=file)
    positions = [isinstance(v, int) and not isinstance(v, bool) for v in columns.values()]
    names = [isinstance(v, str) for v in columns.values()]
    if not (all(positions) or all(names)):
        raise RecordError(
            f"columns {dict(columns)!r}: expected all header names (str) or all 0-based "
            "positions (int) for a file without header", file=file
        )
    if columns and all(positions):
        if any(v < 0 for v in columns.values()):
            raise RecordError(f"columns {dict(columns)!r}: positions must be >= 0", file=file)
        if not {"u", "y"} <= set(columns):
            raise RecordError(f"columns {dict(columns)!r}: positions of both 'u' and 'y' are "
                              "required for a file without header", file=file)
    try:
        _distinct_columns(columns, f"columns {dict(columns)!r}")
    except ValueError as err:
        raise RecordError(str(err), file=file) from err
    return dict(columns)


# --------------------------------------------------------------------------- shared checks
def _fs_from_time(t: np.ndarray, stated: float | None, stated_by: str, locate: Locator,
                  file: str) -> float:
    """Check that ``t`` is increasing and uniform; return the sampling rate it implies.

    ``stated`` (described by ``stated_by``) is returned instead when it agrees with ``t``.
    """
    if t.size < 2:
        if stated is None:
            raise RecordError("a single sample of t does not define fs (pass fs=... or --fs)",
                              file=file)
        return stated
    dt = np.diff(t)
    bad = np.flatnonzero(dt <= 0)
    if bad.size:
        k = int(bad[0]) + 1
        what = "repeats" if dt[k - 1] == 0 else "decreases"
        raise RecordError(
            f"t {what}: {float(t[k])!r} after {float(t[k - 1])!r} (expected strictly "
            "increasing times)", **locate(k)
        )
    step = float(np.median(dt))
    off = np.flatnonzero(np.abs(dt - step) > T_UNIFORM_RTOL * step)
    if off.size:
        k = int(off[0]) + 1
        raise RecordError(
            f"t is not uniform: step {float(dt[k - 1])!r} s from the previous sample differs "
            f"from the median step {step!r} s by {abs(dt[k - 1] / step - 1):.3g} (expected at most "
            f"{T_UNIFORM_RTOL:g} relative)", **locate(k)
        )
    derived = (t.size - 1) / float(t[-1] - t[0])
    if stated is None:
        return derived
    if abs(stated - derived) > FS_RTOL * derived:
        raise RecordError(
            f"fs mismatch: {stated_by}{stated!r} Hz but t gives {derived!r} Hz "
            f"(expected agreement within {FS_RTOL:g} relative)", file=file
        )
    return stated


def _stated_fs(fs: float | None, file: str) -> float | None:
    if fs is None:
        return None
    return _as_fs(fs, f"{file}: argument fs")


# --------------------------------------------------------------------------- CSV
def _load_csv(file: str, fs: float | None, roles: dict[str, str | int],
              name: str | None) -> Record:
    lines = _read_lines(file)
    data, meta = _scan_lines(lines)
    headerless = bool(roles) and all(isinstance(v, int) for v in roles.values())
    rows = _CsvRows(file, _delimiter(data[0][1]) if data else ",")
    if headerless:
        fields, positions, labels = None, roles, {role: role for role in roles}
    else:
        if not data:
            raise RecordError("no data rows (the file is empty; expected a header naming the "
                              "columns t, u, y, then data rows)", file=file)
        header_line, header = data.pop(0)
        fields = rows.split(header, header_line)
        positions, labels = _header_positions(fields, header_line, roles, file)
    if not data:
        raise RecordError("no data rows (expected at least one row of numbers after the header)",
                          file=file)
    linenos, raw = _split_rows(rows, data, positions, fields, file)
    values = {role: _parse_column(raw[role], linenos, labels[role], file) for role in raw}
    stated = _stated_fs(fs, file)
    stated_by = "fs=" if stated is not None else ""
    if stated is None and meta.get("fs") is not None:
        stated, stated_by = meta["fs"], f"the comment on line {meta['line']} says fs="
    if "t" in values:
        locate = _csv_locator(linenos, labels["t"], file)
        rate = _fs_from_time(values["t"], stated, stated_by, locate, file)
    elif stated is not None:
        rate = stated
    else:
        raise RecordError("no t column and no sampling rate: pass fs=... (or --fs on the command "
                          "line), or add a column t in seconds", file=file)
    return Record(
        u=values["u"],
        y=values["y"],
        fs=rate,
        units=meta.get("units") or dict(_DEFAULT_UNITS),
        name=name if name is not None else meta.get("name", Path(file).stem),
    )


def _read_lines(file: str) -> list[str]:
    try:
        with open(file, encoding="utf-8-sig") as src:
            return src.read().split("\n")
    except UnicodeDecodeError as err:
        raise RecordError(f"not a UTF-8 text file ({err.reason} at byte {err.start})",
                          file=file) from err
    except OSError as err:
        raise RecordError(f"cannot read the file ({err.strerror})", file=file) from err


def _scan_lines(lines: list[str]) -> tuple[list[tuple[int, str]], dict[str, Any]]:
    """Return the data lines as ``(index, text)`` and the metadata of a hystid comment line."""
    data = []
    meta: dict[str, Any] = {}
    for index, text in enumerate(lines):
        stripped = text.strip()
        if not stripped:
            continue
        if stripped.startswith("#"):
            if not meta:
                meta = _parse_meta(stripped, index + 1)
            continue
        data.append((index, text))
    return data, meta


def _parse_meta(comment: str, lineno: int) -> dict[str, Any]:
    """Parse ``# hystid record: name=..., fs=..., units u=V y=um`` (empty dict otherwise)."""
    body = comment.lstrip("#").strip()
    if not body.startswith(_META_PREFIX):
        return {}
    match = _META_RE.match(body[len(_META_PREFIX):].strip())
    if match is None:
        return {}
    meta: dict[str, Any] = {"name": match["name"], "line": lineno}
    try:
        meta["fs"] = float(match["fs"])
    except ValueError:
        meta["fs"] = None
    units = dict(item.split("=", 1) for item in match["units"].split() if "=" in item)
    if units:
        meta["units"] = units
    return meta


def _delimiter(line: str) -> str | None:
    """The field separator of a CSV line: ``;``, tab or ``,`` (the first one the line holds
    outside double quotes, in that order), else ``None`` for blanks (spaces and tabs)."""
    bare = re.sub(r'"[^"]*"', "", line)
    return next((sep for sep in (";", "\t", ",") if sep in bare), None)


class _CsvRows:
    """Splits the lines of one CSV file into fields with the :mod:`csv` module.

    ``delimiter`` is ``;``, tab, ``,`` or ``None`` (runs of blanks); fields may be quoted with
    double quotes (``"1.5"``), and a quote left open at the end of a line is an error located
    at that line.
    """

    def __init__(self, file: str, delimiter: str | None) -> None:
        self.file = file
        self.delimiter = delimiter

    def split_all(self, data: list[tuple[int, str]]) -> Iterable[tuple[int, list[str]]]:
        """Yield ``(line index, fields)`` for each ``(line index, text)`` of ``data``."""
        if self.delimiter is None:
            texts = (text.strip() for _, text in data)
            reader = csv.reader(texts, delimiter=" ", skipinitialspace=True, strict=True)
        else:
            reader = csv.reader((text for _, text in data), delimiter=self.delimiter,
                                strict=True)
        done = 0  # rows yielded; the row being read starts at data[done]
        try:
            for fields in reader:
                index = data[done][0]
                if reader.line_num != done + 1:
                    raise RecordError("a quoted field is not closed on its line (expected a "
                                      "closing double quote)", file=self.file, line=index + 1)
                done += 1
                yield index, fields
        except csv.Error as err:
            raise RecordError(f"unreadable row ({err}; expected delimited fields, each quote "
                              "closed on its line)", file=self.file,
                              line=data[done][0] + 1) from None

    def split(self, text: str, index: int) -> list[str]:
        """Fields of one line (``index`` locates errors)."""
        return next(iter(self.split_all([(index, text)])))[1]


def _header_positions(header: list[str], line_index: int, roles: dict[str, str | int],
                      file: str) -> tuple[dict[str, int], dict[str, str]]:
    """Find the columns t, u, y in the header fields; return positions and names by role."""
    found = [field.strip().strip("\"'") for field in header]
    folded = [name.casefold() for name in found]
    positions: dict[str, int] = {}
    labels: dict[str, str] = {}
    for role in _ROLES:
        wanted = str(roles.get(role, role))
        hits = [k for k, name in enumerate(folded) if name == wanted.casefold()]
        if len(hits) > 1:
            raise RecordError(f"column {wanted!r} appears {len(hits)} times in the header "
                              "(expected once)", file=file, line=line_index + 1)
        if hits:
            positions[role], labels[role] = hits[0], found[hits[0]]
        elif role != "t" or role in roles:
            hint = ("; if the file has no header, pass 0-based positions, e.g. "
                    "columns={'u': 1, 'y': 2}" if _looks_numeric(found) else "")
            raise RecordError(
                f"missing column {wanted!r} (found columns {found}; expected u and y, t "
                f"optional, or a columns= mapping){hint}", file=file, line=line_index + 1
            )
    return positions, labels


def _looks_numeric(fields: list[str]) -> bool:
    for text in fields:
        try:
            float(text)
        except ValueError:
            continue
        return True
    return False


def _split_rows(rows: _CsvRows, data: list[tuple[int, str]], positions: dict[str, int],
                header: list[str] | None, file: str) -> tuple[list[int], dict[str, list[str]]]:
    """Split data lines into the raw text of the used columns; check the field counts."""
    split = rows.split_all(data)
    first_index, first = next(split)
    width = len(header) if header is not None else len(first)
    if header is None:
        needed = max(positions.values()) + 1
        if needed > width:
            raise RecordError(
                f"{width} fields but columns={positions} needs at least {needed} "
                "(expected a column at every given position)", file=file, line=data[0][0] + 1
            )
    expected = ("as the header" if header is not None
                else f"as the first data row (line {data[0][0] + 1})")
    raw: dict[str, list[str]] = {role: [] for role in positions}
    items = list(positions.items())
    linenos = []
    for index, fields in itertools.chain([(first_index, first)], split):
        if len(fields) != width:
            raise RecordError(f"{len(fields)} fields (expected {width}, as many {expected})",
                              file=file, line=index + 1)
        for role, pos in items:
            raw[role].append(fields[pos])
        linenos.append(index + 1)
    return linenos, raw


def _csv_locator(linenos: list[int], column: str, file: str) -> Locator:
    return lambda k: {"file": file, "line": linenos[k], "column": column}


def _parse_column(raw: list[str], linenos: list[int], column: str, file: str) -> np.ndarray:
    """Convert the text of one column to float64; locate any bad value by line and column."""
    try:
        values = np.array([float(text) for text in raw], dtype=np.float64)
    except ValueError:
        for k, text in enumerate(raw):
            try:
                float(text)
            except ValueError:
                shown = "empty value" if not text.strip() else f"value {text.strip()!r}"
                raise RecordError(f"{shown} is not a number (expected a finite number)",
                                  file=file, line=linenos[k], column=column) from None
        raise  # pragma: no cover - the loop above always finds the culprit
    return finite_signal(values, column, locate=_csv_locator(linenos, column, file), raw=raw,
                         error=RecordError)


# --------------------------------------------------------------------------- array formats
@dataclass
class _Arrays:
    """Raw content of an array file: what :func:`_record_from_arrays` needs."""

    file: str
    kind: str  # "array", "variable" or "dataset", used in messages
    arrays: dict[str, np.ndarray]  # role -> values, roles u, y and optionally t
    labels: dict[str, str]  # role -> name in the file
    fs: Any = None
    fs_label: str = ""  # where fs is stored, e.g. "attribute 'fs'"; "{kind} 'fs'" when empty
    name: str | None = None
    units: dict[str, str] | None = None
    default_name: str = "record"


def _record_from_arrays(src: _Arrays, fs: float | None, name: str | None) -> Record:
    vectors = {role: _as_vector(values, src, role) for role, values in src.arrays.items()}
    lengths = {src.labels[role]: v.size for role, v in vectors.items()}
    if len(set(lengths.values())) > 1:
        listed = ", ".join(f"{label}: {size}" for label, size in lengths.items())
        raise RecordError(f"{src.kind}s have different lengths ({listed}) (expected equal "
                          "lengths)", file=src.file)
    if vectors["u"].size == 0:
        raise RecordError(f"{src.kind}s {src.labels['u']!r} and {src.labels['y']!r} are empty "
                          "(expected at least 1 sample)", file=src.file)
    stated = _stated_fs(fs, src.file)
    stated_by = "fs="
    fs_label = src.fs_label or f"{src.kind} 'fs'"
    stored = None if src.fs is None else _stored_fs(src.fs, f"{src.file}, {fs_label}")
    if "t" in vectors:
        if stated is None and stored is not None:
            stated, stated_by = stored, f"{fs_label} says fs="
        locate = _array_locator(src, "t")
        rate = _fs_from_time(vectors["t"], stated, stated_by, locate, src.file)
    elif stated is not None and stored is not None:
        if abs(stated - stored) > FS_RTOL * stored:
            raise RecordError(f"fs mismatch: fs={stated!r} Hz but {fs_label} is "
                              f"{stored!r} Hz (expected agreement within {FS_RTOL:g} "
                              "relative)", file=src.file)
        rate = stated
    elif stated is not None or stored is not None:
        rate = stated if stated is not None else stored
    else:
        raise RecordError(f"no {src.kind} fs or t and no sampling rate: pass fs=... (or --fs on "
                          f"the command line), or store fs or t in the file", file=src.file)
    return Record(
        u=vectors["u"],
        y=vectors["y"],
        fs=rate,
        units=src.units or dict(_DEFAULT_UNITS),
        name=name if name is not None else (src.name or src.default_name),
    )


def _array_locator(src: _Arrays, role: str) -> Locator:
    return lambda k: {"file": src.file, "array": src.labels[role], "kind": src.kind, "index": k}


def _as_vector(values: Any, src: _Arrays, role: str) -> np.ndarray:
    """Squeeze to 1-D float64 and check that every value is finite."""
    label = src.labels[role]
    array = np.asarray(values)
    if array.dtype.kind not in "biuf":
        raise RecordError(f"{src.kind} {label!r} has dtype {array.dtype} (expected real numbers)",
                          file=src.file)
    vector = np.atleast_1d(np.squeeze(array)).astype(np.float64)
    if vector.ndim != 1:
        raise RecordError(f"{src.kind} {label!r} has shape {array.shape} (expected a vector)",
                          file=src.file)
    return finite_signal(vector, label, locate=_array_locator(src, role), error=RecordError)


def _stored_fs(value: Any, where: str) -> float:
    array = np.asarray(value)
    if array.dtype.kind not in "iuf" or array.size != 1:
        raise RecordError(f"{where}: has dtype {array.dtype} and shape {array.shape} (expected "
                          "one sampling rate in Hz)")
    return _as_fs(array.reshape(-1)[0], where)


def _names(roles: dict[str, str | int], file: str) -> dict[str, str]:
    """Map each role to the array name to look up (integer positions are CSV-only)."""
    if any(isinstance(v, int) for v in roles.values()):
        raise RecordError("integer column positions apply to headerless CSV files only "
                          "(expected array names, e.g. columns={'u': 'voltage'})", file=file)
    return {role: str(roles.get(role, role)) for role in _ROLES}


def _collect(file: str, kind: str, names: dict[str, str], found: Mapping[str, Any] | set[str],
             fetch: Callable[[str], Any]) -> tuple[dict[str, Any], dict[str, str]]:
    """Fetch the u, y (required) and t (optional unless renamed) arrays by name."""
    names_given = {role for role in _ROLES if names[role] != role}
    arrays: dict[str, Any] = {}
    for role in _ROLES:
        if names[role] in found:
            arrays[role] = fetch(names[role])
        elif role != "t" or role in names_given:
            listed = sorted(k for k in found if not k.startswith("__"))
            raise RecordError(f"missing {kind} {names[role]!r} (found {listed}; expected u and "
                              "y, and fs or t)", file=file)
    return arrays, {role: names[role] for role in arrays}


def _text(value: Any) -> str | None:
    """A string stored as str, bytes or a (0-d or 1-element) string array, else ``None``."""
    array = np.asarray(value)
    if array.dtype.kind not in "US" or array.size != 1:
        return None
    item = array.reshape(-1)[0].item()
    return item.decode("utf-8", "replace") if isinstance(item, bytes) else str(item)


def _units(value: Any) -> dict[str, str] | None:
    text = _text(value)
    if text is None:
        return None
    try:
        units = json.loads(text)
    except json.JSONDecodeError:
        return None
    if not isinstance(units, dict):
        return None
    return {str(k): str(v) for k, v in units.items()}


# --------------------------------------------------------------------------- hostile files
def _check_declared(nbytes: int, file: str, what: str) -> None:
    """Refuse data that would expand far beyond what the file can hold.

    A file of ``s`` bytes may decode to at most ``max(EXPANSION_FLOOR, MAX_EXPANSION * s)``
    bytes: compressed measurements shrink a few times at most, so more is a decompression bomb
    or a header that lies about the shape.
    """
    size = os.path.getsize(file)
    limit = max(EXPANSION_FLOOR, MAX_EXPANSION * size)
    if nbytes > limit:
        raise RecordError(
            f"{what} declares {nbytes:,} bytes of data but the file has {size:,} bytes (expected "
            f"at most {limit:,}: {MAX_EXPANSION}x the file size, or {EXPANSION_FLOOR >> 20} MiB; "
            "a decompression bomb or a lying header is refused)", file=file)


def _npz_members(file: str) -> set[str]:
    """Check every ``.npy`` member's declared shape against its stored bytes; return the keys."""
    import zipfile

    keys, total = set(), 0
    with zipfile.ZipFile(file) as archive:
        for info in archive.infolist():
            if not info.filename.endswith(".npy"):
                continue
            key = info.filename[:-4]
            keys.add(key)
            total += info.file_size
            _check_declared(total, file, f"array {key!r} (with the arrays before it)")
            with archive.open(info) as member:
                version = np.lib.format.read_magic(member)
                reader = (np.lib.format.read_array_header_1_0 if version == (1, 0)
                          else np.lib.format.read_array_header_2_0)
                shape, _, dtype = reader(member)
                header = member.tell()
            declared = int(np.prod(shape, dtype=object)) * dtype.itemsize
            if declared > info.file_size - header:
                raise RecordError(
                    f"array {key!r} declares shape {shape} ({declared:,} bytes) but the archive "
                    f"holds {info.file_size - header:,} bytes for it (a truncated or lying "
                    "archive)", file=file)
    return keys


_ARCHIVE_ERRORS: tuple[type[BaseException], ...] = (OSError, ValueError, EOFError, KeyError)


def _archive_errors() -> tuple[type[BaseException], ...]:
    import zipfile
    import zlib

    return (*_ARCHIVE_ERRORS, zipfile.BadZipFile, zlib.error, RuntimeError, NotImplementedError)


def _read_npz(file: str, roles: dict[str, str | int]) -> _Arrays:
    names = _names(roles, file)
    errors = _archive_errors()
    try:
        keys = _npz_members(file)
        archive = np.load(file, allow_pickle=False)
    except RecordError:
        raise
    except errors as err:
        raise RecordError(f"not a readable .npz archive ({err})", file=file) from err
    if not isinstance(archive, np.lib.npyio.NpzFile):
        raise RecordError("holds a single .npy array (expected a .npz archive with arrays u, y, "
                          "and fs or t)", file=file)
    with archive:

        def fetch(key: str) -> np.ndarray:
            try:
                return archive[key]
            except ValueError as err:
                if "pickle" in str(err).lower():
                    raise RecordError(f"array {key!r} is an object array that needs pickle, "
                                      "which is not loaded for safety (expected a numeric "
                                      "array)", file=file) from err
                raise RecordError(f"array {key!r} cannot be read ({err}; a truncated or "
                                  "corrupt archive)", file=file) from err
            except errors as err:
                raise RecordError(f"array {key!r} cannot be read ({err}; a truncated or "
                                  "corrupt archive)", file=file) from err

        found = set(archive.files) & keys
        arrays, labels = _collect(file, "array", names, found, fetch)
        extra = {key: fetch(key) for key in ("fs", "name", "units") if key in found}
    return _Arrays(file, "array", arrays, labels, fs=extra.get("fs"),
                   name=_text(extra.get("name")), units=_units(extra.get("units")),
                   default_name=Path(file).stem)


def _read_mat(file: str, roles: dict[str, str | int]) -> _Arrays:
    from scipy.io import loadmat, whosmat
    from scipy.io.matlab import MatReadError

    names = _names(roles, file)
    errors = (*_archive_errors(), NotImplementedError, TypeError, MatReadError)
    try:
        listing = _mat_v5_listing(file)
        if listing is None:  # MATLAB v4 files are never compressed: scipy lists them cheaply
            listing = [(name, shape) for name, shape, _ in whosmat(file)]
    except errors as err:
        hint = " (MATLAB v7.3 files are HDF5: rename to .h5)" if "7.3" in str(err) else ""
        raise RecordError(f"not a readable .mat file ({err}){hint}", file=file) from err
    found = {name for name, _ in listing}
    wanted = sorted(found & ({*names.values(), "fs", "name", "units"}))
    declared = sum(8 * int(np.prod(shape, dtype=object)) for name, shape in listing
                   if name in wanted)
    _check_declared(declared, file, f"variables {wanted}")
    try:
        content = loadmat(file, variable_names=wanted)
    except errors as err:
        raise RecordError(f"not a readable .mat file ({err}; a truncated or corrupt file)",
                          file=file) from err
    arrays, labels = _collect(file, "variable", names, found, content.__getitem__)
    return _Arrays(file, "variable", arrays, labels, fs=content.get("fs"),
                   name=_text(content.get("name")), units=_units(content.get("units")),
                   default_name=Path(file).stem)


def _mat_v5_listing(file: str) -> list[tuple[str, tuple[int, ...]]] | None:
    """Names and declared shapes of a MATLAB v5 file's variables, without decompressing them.

    Only the first bytes of each compressed variable are inflated (its tag, flags, dimensions
    and name). Returns ``None`` for a file that is not v5 (v4); raises ``ValueError`` on a
    malformed one.
    """
    import struct
    import zlib

    with open(file, "rb") as src:
        head = src.read(128)
        if len(head) < 128 or head[126:128] not in (b"IM", b"MI") or head[:4] == b"\0\0\0\0":
            return None
        order = "<" if head[126:128] == b"IM" else ">"
        size = os.path.getsize(file)
        out = []
        while src.tell() + 8 <= size:
            kind, nbytes = struct.unpack(order + "II", src.read(8))
            if kind >> 16:  # a small data element at the top level: nothing to list
                continue
            payload = src.read(nbytes)
            if len(payload) < nbytes:
                raise ValueError(f"variable {len(out) + 1} is truncated ({len(payload)} of "
                                 f"{nbytes} bytes)")
            if kind == 15:  # miCOMPRESSED (not padded): inflate only the header
                payload = zlib.decompressobj().decompress(payload, 512)
                kind, nbytes = struct.unpack(order + "II", payload[:8])
                payload = payload[8:]
            else:
                src.seek((8 - src.tell() % 8) % 8, os.SEEK_CUR)
            if kind == 14:  # miMATRIX
                out.append(_mat_matrix_header(payload, order))
        return out


def _mat_matrix_header(payload: bytes, order: str) -> tuple[str, tuple[int, ...]]:
    """Name and dimensions from the first sub-elements of a MATLAB v5 miMATRIX."""
    import struct

    def element(pos: int) -> tuple[bytes, int]:
        kind, nbytes = struct.unpack(order + "II", payload[pos:pos + 8])
        if kind >> 16:  # small data element: the data sit in the tag's second word
            small = (kind >> 16) if order == "<" else (kind & 0xFFFF)
            return payload[pos + 4:pos + 4 + small], pos + 8
        end = pos + 8 + nbytes
        return payload[pos + 8:end], end + (8 - end % 8) % 8

    _, pos = element(0)  # array flags
    dims, pos = element(pos)
    name, _ = element(pos)
    shape = struct.unpack(f"{order}{len(dims) // 4}i", dims[: len(dims) // 4 * 4])
    return name.decode("latin-1"), tuple(max(d, 0) for d in shape)


def _h5_node(handle: Any, group: str | None, file: str) -> Any:
    """The group ``group`` of an open file, reached without following external links."""
    import h5py

    node = handle
    for part in [p for p in (group or "").split("/") if p]:
        link = node.get(part, getlink=True) if isinstance(node, h5py.Group) else None
        if isinstance(link, h5py.ExternalLink):
            raise RecordError(f"group {part!r} is an external link to {link.filename}:"
                              f"{link.path} (refused: a record is read from its own file only)",
                              file=file)
        node = node.get(part) if link is not None else None
        if node is None:
            break
    return node


def _h5_dataset(node: Any, key: str, file: str) -> Any:
    """Dataset ``key`` of ``node`` checked against external data and lying shapes."""
    import h5py

    link = node.get(key, getlink=True)
    if isinstance(link, h5py.ExternalLink):
        raise RecordError(f"dataset {key!r} is an external link to {link.filename}:{link.path} "
                          "(refused: a record is read from its own file only)", file=file)
    dset = node[key]
    if dset.external:
        raise RecordError(f"dataset {key!r} keeps its data in external files "
                          f"{[e[0] for e in dset.external]} (refused: a record is read from its "
                          "own file only)", file=file)
    if dset.is_virtual:
        raise RecordError(f"dataset {key!r} is a virtual dataset mapped from other files "
                          "(refused: a record is read from its own file only)", file=file)
    declared = int(dset.size) * dset.dtype.itemsize
    _check_declared(declared, file, f"dataset {key!r} of shape {dset.shape}")
    stored = dset.id.get_storage_size()
    if not dset._filters and declared > stored:
        raise RecordError(f"dataset {key!r} declares shape {dset.shape} ({declared:,} bytes) but "
                          f"stores {stored:,} bytes (unwritten or truncated data)", file=file)
    return dset


def _read_h5(file: str, group: str | None, roles: dict[str, str | int]) -> _Arrays:
    import h5py

    names = _names(roles, file)
    where = f"{file}:{group}" if group else file
    try:
        handle = h5py.File(file, "r")
    except OSError as err:
        raise RecordError(f"not a readable HDF5 file ({err})", file=file) from err
    with handle:
        node = _h5_node(handle, group, file)
        if not isinstance(node, h5py.Group):
            groups: list[str] = []
            handle.visit(lambda key: groups.append(key) if isinstance(handle.get(key),
                                                                       h5py.Group) else None)
            raise RecordError(f"no group {group!r} (groups in the file: {groups or 'none'})",
                              file=file)
        datasets = {key for key in node if _h5_is_dataset(node, key)}

        def fetch(key: str) -> Any:
            dset = _h5_dataset(node, key, file)
            try:
                return dset[()]
            except (OSError, ValueError, TypeError) as err:
                raise RecordError(f"dataset {key!r} cannot be read ({err}; a truncated or "
                                  "corrupt file)", file=file) from err

        arrays, labels = _collect(where, "dataset", names, datasets, fetch)
        attrs = dict(node.attrs)
        if "fs" in attrs:
            fs, fs_label = attrs["fs"], "attribute 'fs'"
        else:
            fs, fs_label = (fetch("fs") if "fs" in datasets else None), "dataset 'fs'"
    default = Path(file).stem + (f":{group}" if group else "")
    return _Arrays(where, "dataset", arrays, labels, fs=fs, fs_label=fs_label,
                   name=_text(attrs.get("name")), units=_units(attrs.get("units")),
                   default_name=default)


def _h5_is_dataset(node: Any, key: str) -> bool:
    """True for a dataset, or an external link (refused when used); never opens other files."""
    import h5py

    link = node.get(key, getlink=True)
    if isinstance(link, h5py.ExternalLink):
        return True
    return isinstance(node.get(key), h5py.Dataset)
