"""Command-line option parsers shared by the ``hystid`` sub-commands.

Every parser refuses what it cannot use -- non-finite numbers, values out of range, malformed
text -- with a message that names the option and says what was expected. The number parsers
are ``type=`` callables for :mod:`argparse` (they raise :class:`argparse.ArgumentTypeError`, which
argparse prints after the option's name); :func:`parse_crop`, :func:`crop` and
:func:`parse_structure` raise :class:`OptionError`, whose message starts with the option.
"""

from __future__ import annotations

import argparse
import math
from collections.abc import Callable
from typing import TYPE_CHECKING

from .errors import OptionError
from .validate import MAX_DELAY, MAX_ORDER

if TYPE_CHECKING:  # pragma: no cover
    from .model import Structure
    from .records import Record

__all__ = [
    "MAX_DELAY",
    "MAX_ORDER",
    "MAX_SECONDS",
    "OptionError",
    "crop",
    "fraction",
    "integer",
    "number",
    "parse_crop",
    "parse_structure",
]

#: Longest simulated record accepted by ``--seconds``.
MAX_SECONDS = 600.0

_TRUE = ("1", "true", "yes", "on")
_FALSE = ("0", "false", "no", "off")


# --------------------------------------------------------------------------- numbers
def number(
    minimum: float | None = None,
    maximum: float | None = None,
    *,
    strict_minimum: bool = False,
) -> Callable[[str], float]:
    """An argparse ``type=`` parser for a finite float within bounds.

    Parameters
    ----------
    minimum, maximum : float, optional
        Bounds (inclusive, unless ``strict_minimum``).
    strict_minimum : bool
        Require ``value > minimum`` (for "positive").

    Returns
    -------
    callable
        ``parse(text) -> float`` raising :class:`argparse.ArgumentTypeError`.
    """

    def parse(text: str) -> float:
        try:
            value = float(text)
        except ValueError as err:
            raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from err
        if not math.isfinite(value):
            raise argparse.ArgumentTypeError(f"expected a finite number, got {text!r}")
        _check_bounds(value, text, minimum, maximum, strict_minimum)
        return value

    return parse


def integer(minimum: int | None = None, maximum: int | None = None) -> Callable[[str], int]:
    """An argparse ``type=`` parser for an integer within bounds (inclusive).

    Parameters
    ----------
    minimum, maximum : int, optional
        Bounds.

    Returns
    -------
    callable
        ``parse(text) -> int`` raising :class:`argparse.ArgumentTypeError`.
    """

    def parse(text: str) -> int:
        try:
            value = int(text)
        except ValueError as err:
            raise argparse.ArgumentTypeError(f"expected an integer, got {text!r}") from err
        _check_bounds(value, text, minimum, maximum, False)
        return value

    return parse


def fraction(text: str) -> float:
    """An argparse ``type=`` parser for a number strictly between 0 and 1.

    Parameters
    ----------
    text : str
        The option's value.

    Returns
    -------
    float
    """
    value = number()(text)
    if not 0.0 < value < 1.0:
        raise argparse.ArgumentTypeError(f"expected a fraction in (0, 1), got {text!r}")
    return value


def _check_bounds(value: float, text: str, minimum: float | None, maximum: float | None,
                  strict_minimum: bool) -> None:
    if minimum is not None and (value <= minimum if strict_minimum else value < minimum):
        relation = ">" if strict_minimum else ">="
        wanted = "a positive number" if strict_minimum and minimum == 0 else \
            f"a value {relation} {minimum:g}"
        raise argparse.ArgumentTypeError(f"expected {wanted}, got {text!r}")
    if maximum is not None and value > maximum:
        raise argparse.ArgumentTypeError(f"expected a value <= {maximum:g}, got {text!r}")


# --------------------------------------------------------------------------- --crop
def parse_crop(text: str, option: str = "--crop") -> tuple[float | None, float | None]:
    """Parse ``START:STOP`` in seconds; either end may be left empty.

    Parameters
    ----------
    text : str
        The option's value, e.g. ``3.2:`` or ``0.5:1.5``.
    option : str
        The option's name, for messages.

    Returns
    -------
    tuple
        ``(start, stop)``, ``None`` for an open end.

    Raises
    ------
    OptionError
        On a malformed text, a non-finite or negative time, or ``START >= STOP``.
    """
    parts = text.split(":")
    if len(parts) != 2:
        raise OptionError(f"{option}: expected START:STOP in seconds (e.g. 0.5:2 or 3.2:), "
                          f"got {text!r}")
    ends: list[float | None] = []
    for label, part in zip(("START", "STOP"), parts, strict=True):
        if not part.strip():
            ends.append(None)
            continue
        try:
            value = float(part)
        except ValueError as err:
            raise OptionError(f"{option}: {label} {part!r} is not a number (expected seconds)") \
                from err
        if not math.isfinite(value) or value < 0:
            raise OptionError(f"{option}: {label} is {part!r} (expected a finite time >= 0 s)")
        ends.append(value)
    start, stop = ends
    if start is not None and stop is not None and not start < stop:
        raise OptionError(f"{option}: START {start:g} s is not before STOP {stop:g} s")
    return start, stop


def crop(record: Record, span: tuple[float | None, float | None] | None,
         option: str = "--crop") -> Record:
    """The part of ``record`` between ``span = (start, stop)`` seconds.

    Parameters
    ----------
    record : Record
        The record.
    span : tuple or None
        From :func:`parse_crop`; ``None`` keeps the whole record.
    option : str
        The option's name, for messages.

    Returns
    -------
    Record

    Raises
    ------
    OptionError
        When the span does not lie within the record or selects no sample.
    """
    if span is None:
        return record
    start, stop = span
    # clipped before rounding: a time of 1e308 s is past the end, not an overflow
    i = 0 if start is None else int(round(min(start * record.fs, record.n + 1.0)))
    j = record.n if stop is None else int(round(min(stop * record.fs, record.n + 1.0)))
    if not 0 <= i < j <= record.n:
        shown = f"{'' if start is None else f'{start:g}'}:{'' if stop is None else f'{stop:g}'}"
        raise OptionError(f"{option} {shown}: record {record.name!r} covers 0..{record.duration:g}"
                          " s (expected 0 <= START < STOP within it, selecting at least one "
                          "sample)")
    return record[i:j]


# --------------------------------------------------------------------------- --structure
def parse_structure(text: str, option: str = "--structure") -> Structure:
    """Parse ``key=value,...`` into a Duhem sandwich :class:`~hystid.model.Structure`.

    Keys ``n1a, n1b, n2a, n2b`` (orders, 0..:data:`MAX_ORDER`), ``q1, q2`` (delays in samples,
    0..:data:`MAX_DELAY`), ``f0`` and ``directional`` (``0/1``, ``true/false``, ``yes/no``),
    ``f_order`` (1..3) and ``g_order`` (0..2) of the generalised Duhem block; keys left out keep
    the paper's experimental structure.

    Parameters
    ----------
    text : str
        The option's value, e.g. ``n2a=2,f0=1``.
    option : str
        The option's name, for messages.

    Returns
    -------
    Structure

    Raises
    ------
    OptionError
        On an unknown or repeated key, a value that is not an integer (or a boolean for
        ``f0``), or one out of range.
    """
    from .model import Structure

    keys = ("n1a", "n1b", "n2a", "n2b", "q1", "q2", "f0", "f_order", "g_order", "directional")
    values: dict[str, int | bool] = {}
    for part in text.split(","):
        key, sep, raw = (s.strip() for s in part.partition("="))
        if not sep or not key or not raw:
            raise OptionError(f"{option}: expected key=value pairs like n2a=2,f0=1, got "
                              f"{part!r}")
        if key not in keys:
            raise OptionError(f"{option}: unknown key {key!r} (expected some of "
                              f"{', '.join(keys)})")
        if key in values:
            raise OptionError(f"{option}: {key} is given twice")
        values[key] = _structure_value(key, raw, option)
    return Structure(**values)


def _structure_value(key: str, raw: str, option: str) -> int | bool:
    if key in ("f0", "directional"):
        if raw.lower() in _TRUE:
            return True
        if raw.lower() in _FALSE:
            return False
        raise OptionError(f"{option}: {key}={raw} (expected 0 or 1, true or false)")
    try:
        value = int(raw)
    except ValueError as err:
        raise OptionError(f"{option}: {key}={raw} is not an integer") from err
    shape = {"f_order": (1, 3), "g_order": (0, 2)}
    if key in shape:
        low, high = shape[key]
        if not low <= value <= high:
            raise OptionError(f"{option}: {key}={raw} (expected {low}..{high})")
        return value
    top = MAX_DELAY if key.startswith("q") else MAX_ORDER
    if not 0 <= value <= top:
        what = "delay in samples" if key.startswith("q") else "order"
        raise OptionError(f"{option}: {key}={raw} (expected a {what} in 0..{top})")
    return value
