"""Reading CSV records: header, comment line, delimiter, every field located by line."""

from __future__ import annotations

import csv
import itertools
import re
from collections.abc import Iterable
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import RecordError
from ..signals import finite_signal
from .checks import _fs_from_time, _stated_fs
from .record import _DEFAULT_UNITS, _META_PREFIX, _META_RE, _ROLES, Locator, Record


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
    named = {} if headerless else header_units(labels)
    if "t" in values and named.get("t", "s") != "s":
        values["t"] = values["t"] / _TIME_UNITS[named["t"]]
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
        units=meta.get("units") or {**_DEFAULT_UNITS,
                                    **{r: v for r, v in named.items() if r in ("u", "y")}},
        name=name if name is not None else meta.get("name", Path(file).stem),
    )


#: A unit a time column's header may name (``t_ms``, ``time [us]``), and how many of it make a
#: second.
_TIME_UNITS = {"s": 1.0, "ms": 1e3, "us": 1e6, "\u00b5s": 1e6}
#: Units a header may name for the input or the output: voltages, currents, forces, lengths
#: and angles (a name outside this list is taken for part of the column's name).
_SIGNAL_UNITS = ("V", "mV", "kV", "uV", "A", "mA", "N", "mN", "m", "mm", "um", "\u00b5m", "nm",
                 "pm", "rad", "mrad", "urad", "deg")
#: A unit at the end of a header field: ``pos_nm``, ``pos nm``, ``pos [nm]``, ``pos (nm)``,
#: ``pos/nm``.
_UNIT_IN_LABEL = re.compile(r"(?:^|[_\s/\-]|[\[(]\s*)([A-Za-z\u00b5]+)\s*[\])]?\s*$")


def header_units(labels: dict[str, str]) -> dict[str, str]:
    """The units a CSV header names in its column labels (``cmd_mV``, ``pos [nm]``, ``t_ms``).

    Only units this module knows are read (:data:`_TIME_UNITS` for ``t``,
    :data:`_SIGNAL_UNITS` for ``u`` and ``y``, case as written), so that a label such as
    ``drive_signal`` names none. A file that states its units in a hystid comment line, or
    units given by the caller, take precedence.

    Parameters
    ----------
    labels : dict
        Role (``t``, ``u``, ``y``) to the header field read for it.

    Returns
    -------
    dict
        Role to unit, for the roles whose label ends in a known unit.
    """
    found = {}
    for role, label in labels.items():
        match = _UNIT_IN_LABEL.search(str(label).strip())
        if match is None or match.start(1) == 0:
            continue
        unit = match[1]
        known = _TIME_UNITS if role == "t" else _SIGNAL_UNITS
        if unit in known:
            found[role] = unit
    return found


def _without_unit(label: str, role: str) -> str:
    """A header field less a unit :func:`header_units` knows at its end (``u [V]`` -> ``u``),
    casefolded; the field casefolded when it names none."""
    match = _UNIT_IN_LABEL.search(label)
    if match is None or match.start(1) == 0 or not header_units({role: label}):
        return label.casefold()
    return label[:match.start()].strip().casefold()


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
        if not hits and role not in roles:  # ``u [V]``, ``y_nm``, ``t (ms)``: the role and a unit
            hits = [k for k, name in enumerate(found) if _without_unit(name, role) == role]
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
                comma = re.fullmatch(r"\s*[-+]?\d*,\d+([eE][-+]?\d+)?\s*", text)
                hint = ("; a decimal comma? write numbers with a decimal point (and separate "
                        "the fields with commas, semicolons or tabs)" if comma else "")
                raise RecordError(f"{shown} is not a number (expected a finite number{hint})",
                                  file=file, line=linenos[k], column=column) from None
        raise  # pragma: no cover - the loop above always finds the culprit
    return finite_signal(values, column, locate=_csv_locator(linenos, column, file), raw=raw,
                         error=RecordError)


