"""Loading a record: the format from the suffix, the columns and units, several files."""

from __future__ import annotations

import os
from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import Any

from ..errors import RecordError
from .arrays import _read_h5, _read_mat, _read_npz, _record_from_arrays
from .csvfile import _load_csv
from .record import (
    _CSV_SUFFIXES,
    _H5_SUFFIXES,
    _ROLES,
    _SUFFIXES,
    Record,
    _unknown_extension,
    control_characters,
)


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
        if not sep or role not in ("u", "y") or not unit or role in out \
                or control_characters(unit):
            raise ValueError(f"expected u=UNIT,y=UNIT (each at most once, plain names without "
                             f"control characters) like u=V,y=um, got "
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
    path : str, bytes or os.PathLike
        The file. ``.csv``, ``.txt`` and ``.tsv``: delimited text; ``.npz``; ``.mat``; ``.h5`` and
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
        states. Without them, the units stored in the file (files written by
        :meth:`Record.save`), else those a CSV header names at the end of a column's label
        (``cmd_mV``, ``y [nm]``), else V and um, which only label the numbers (the fits do not
        depend on the units). A CSV time column labelled in ms or us (``t_ms``, ``t [us]``)
        is read in that unit; a header field ``u [V]`` is column ``u``.

    Returns
    -------
    Record
        The loaded record. Units come from ``units``, else from the file when it stores them
        (files written by :meth:`Record.save`), else from a CSV header's labels, else the
        :class:`Record` default.

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
    if not isinstance(path, str | bytes | os.PathLike):
        raise TypeError(f"path: expected a file name (str, bytes or os.PathLike), got "
                        f"{type(path).__name__} {path!r:.40}")
    text = os.fspath(path)
    if isinstance(text, bytes):  # a path of bytes, as os functions take them
        text = os.fsdecode(text)
    file, group = _split_h5_group(text)
    suffix = Path(file).suffix.lower()
    if Path(file).is_dir():
        raise RecordError("file is a directory (expected a record file)", file=file)
    if suffix not in _SUFFIXES:
        raise RecordError(_unknown_extension(suffix), file=text)
    if not Path(file).is_file():
        reason = ("is a directory" if Path(file).is_dir() else
                  "is not a regular file (a FIFO, a device or a socket)" if Path(file).exists()
                  else "does not exist")
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
        rec = _record_from_arrays(source, fs, name, units_given=bool(stated))
    if stated:
        rec.units = {**rec.units, **stated}
    return rec


def _check_units(units: Mapping[str, str] | None, where: str) -> dict[str, str]:
    if units is None:
        return {}
    if not isinstance(units, Mapping) or not set(units) <= {"u", "y"} or not all(
            isinstance(v, str) and v.strip() and not control_characters(v)
            for v in units.values()):
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


