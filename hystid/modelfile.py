"""The hystid model file: an identified sandwich kept as versioned JSON.

A model file holds everything needed to simulate the model again bit for bit, and where it came
from::

    {
      "format": "hystid-model",
      "version": 1,
      "kind": "duhem",                        # or "pi", "mduhem"
      "name": "...",
      "structure": {"n1a": 1, "n1b": 0, "n2a": 2, "n2b": 0, "q1": 1, "q2": 0, "f0": false},
      "params": {"alpha": 0.8365, ...},       # floats written with 17 significant digits
      "thresholds": [...],                    # PI sandwich only
      "rates": [...],                         # multi-Duhem sandwich only (alpha_j)
      "fs": 30000.0,
      "u_rest": 0.0, "offset": 0.0,
      "envelope": {"u_min": ..., "u_max": ..., "slew": ..., "from_rest": true} or null,
      "units": {"u": "V", "y": "um"},
      "provenance": {"hystid_version": "...", "method": "...", "date": "...Z",
                     "record_sha256": "...", "settings": {...}}
    }

:func:`save_model` writes it (atomically, never over an existing file unless ``force``) and
:func:`load_model` reads it back, refusing an unknown format, version or kind with a message
naming the file and the entry. Python writes floats with the shortest text that reads back to
the same double, so a saved and loaded model simulates to the same bits.
"""

from __future__ import annotations

import json
import math
import os
from collections.abc import Mapping
from pathlib import Path
from typing import TYPE_CHECKING, Any

from .document import (
    FORMAT,
    KINDS,
    VERSION,
    ModelFileError,
    file_sha256,
    make_provenance,
    model_document,
    save_model,
)
from .model import DuhemSandwich, Structure
from .operating import Envelope
from .records.record import control_characters
from .validate import check_model, check_structure_size

if TYPE_CHECKING:  # pragma: no cover
    from .mduhem import MultiDuhemSandwich
    from .pi import PISandwich

__all__ = ["FORMAT", "KINDS", "VERSION", "ModelFileError", "file_sha256", "load_model",
           "make_provenance", "model_document", "save_model"]

_DUHEM_KEYS = ("n1a", "n1b", "n2a", "n2b", "q1", "q2", "f0")
_SHAPE_KEYS = ("f_order", "g_order", "directional")
_PI_KEYS = ("n_operators", "n1a", "n1b", "n2a", "n2b", "q1", "q2")
_MDUHEM_KEYS = _PI_KEYS


def _with_effects(model: DuhemSandwich, effects: Any, where: str) -> Any:
    """The model with the file's ``effects`` switched on (an ``AugmentedSandwich``)."""
    if effects is None or effects == {}:
        return model
    ok = isinstance(effects, Mapping) and all(
        isinstance(p, Mapping) and all(isinstance(v, int | float) and not isinstance(v, bool)
                                       and math.isfinite(v) for v in p.values())
        for p in effects.values())
    if not ok:
        raise ModelFileError(f"{where}: 'effects' must map effect names to mappings of "
                             "parameter names to finite numbers")
    from .diagnose.effects import EFFECTS, AugmentedSandwich

    unknown = sorted(set(effects) - set(EFFECTS))
    if unknown:
        raise ModelFileError(f"{where}: unknown effect(s) {', '.join(unknown)} (expected some "
                             f"of {', '.join(EFFECTS)})")
    try:
        return AugmentedSandwich(model, effects, name=model.name)
    except (TypeError, ValueError, KeyError) as err:
        raise ModelFileError(f"{where}: 'effects': {err}") from err


# --------------------------------------------------------------------------- loading
def load_model(path: str | os.PathLike[str]) -> DuhemSandwich | PISandwich | MultiDuhemSandwich:
    """Read a model file written by :func:`save_model`.

    Parameters
    ----------
    path : str or os.PathLike
        The file.

    Returns
    -------
    DuhemSandwich, PISandwich or MultiDuhemSandwich
        The model, with its structure, parameters, sampling rate, rest level, offset, envelope
        and units. The file's provenance is in the model's ``provenance`` attribute. A Duhem
        model file with ``effects`` (written by ``hystid diagnose --out``) gives the
        :class:`~hystid.diagnose.effects.AugmentedSandwich` with those effects on.

    Raises
    ------
    ModelFileError
        If the file cannot be read, is not JSON, is not a hystid model file, has another
        version or an unknown kind, or an entry is missing or invalid (the message names it).
    """
    where = os.fspath(path)
    doc = _read_document(where)
    _check_header(doc, where)
    kind = doc["kind"]
    common = {
        "fs": _number(doc, "fs", where),
        "name": str(doc.get("name") or Path(where).stem),
        "u_rest": _number(doc, "u_rest", where, default=0.0),
        "offset": _number(doc, "offset", where, default=0.0),
        "envelope": _envelope(doc.get("envelope"), where),
        "units": _units(doc.get("units"), where),
    }
    params = _params(doc.get("params"), where)
    try:
        if kind == "duhem":
            structure = Structure(**_structure(doc, _DUHEM_KEYS, where, _SHAPE_KEYS))
            check_structure_size(structure)
            model = DuhemSandwich(params, structure, **common,
                                  rest_memory=_number(doc, "rest_memory", where, default=0.0))
        elif kind == "mduhem":
            from .mduhem import MultiDuhemSandwich, MultiDuhemStructure

            structure = MultiDuhemStructure(**_structure(doc, _MDUHEM_KEYS, where))
            rates = _numbers(doc, "rates", where, "a multi-Duhem model's operator rates "
                             "alpha_j")
            model = MultiDuhemSandwich(params, rates, structure, **common)
        else:
            from .pi import PISandwich, PIStructure

            structure = PIStructure(**_structure(doc, _PI_KEYS, where, ("n_poly",)))
            check_structure_size(structure)
            thresholds = _numbers(doc, "thresholds", where, "a PI model's play-operator "
                                  "thresholds")
            model = PISandwich(params, thresholds, structure, **common,
                               rest_swing=_number(doc, "rest_swing", where, default=0.0))
        check_model(model)
    except ModelFileError:
        raise
    except (TypeError, ValueError, OverflowError) as err:  # OverflowError: an integer of 400
        raise ModelFileError(f"{where}: {err}") from err     # digits in a list of numbers
    model.provenance = _provenance(doc.get("provenance"), where)
    if kind == "duhem":
        model = _with_effects(model, doc.get("effects"), where)
        model.provenance = _provenance(doc.get("provenance"), where)
    return model


def _provenance(data: Any, where: str) -> dict[str, Any]:
    """The file's provenance: a mapping (or null), nested at most a few levels."""
    from .validate import MAX_NESTING, too_deep

    if data is None:
        return {}
    if not isinstance(data, Mapping):
        raise ModelFileError(f"{where}: 'provenance' must be a mapping (hystid version, method, "
                             f"date, record), got {type(data).__name__} {str(data)[:40]!r}")
    if too_deep(data):
        raise ModelFileError(f"{where}: 'provenance' nests deeper than {MAX_NESTING} levels "
                             "(expected a flat mapping of where the model came from)")
    return dict(data)


def _read_document(where: str) -> dict[str, Any]:
    from .validate import read_plain_text

    try:
        text = read_plain_text(where)
    except FileNotFoundError as err:
        raise ModelFileError(f"{where}: the model file does not exist") from err
    except IsADirectoryError as err:
        raise ModelFileError(f"{where}: is a folder (expected a model file)") from err
    except (OSError, ValueError) as err:  # ValueError: not a plain file, too large, not UTF-8
        raise ModelFileError(f"{where}: cannot read the model file ({err})") from err
    try:
        doc = json.loads(text, parse_constant=_refuse_constant)
    except RecursionError as err:
        raise ModelFileError(f"{where}: JSON nested too deeply (expected a model file, whose "
                             "entries nest a few levels)") from err
    except ValueError as err:
        raise ModelFileError(f"{where}: not a JSON model file ({err})") from err
    if not isinstance(doc, dict):
        raise ModelFileError(f"{where}: expected a JSON object, got {type(doc).__name__}")
    return doc


def _refuse_constant(name: str) -> float:
    raise ValueError(f"{name} is not a JSON number")


def _check_header(doc: Mapping[str, Any], where: str) -> None:
    if doc.get("format") != FORMAT:
        raise ModelFileError(f"{where}: 'format' is {doc.get('format')!r} (expected {FORMAT!r}; "
                             "a model file is written by hystid identify --out or model.save)")
    version = doc.get("version")
    if version != VERSION or isinstance(version, bool):
        newer = isinstance(version, int) and not isinstance(version, bool) and version > VERSION
        hint = " (written by a newer hystid: upgrade to read it)" if newer else ""
        raise ModelFileError(f"{where}: model file version {version!r} is not supported "
                             f"(expected {VERSION}){hint}")
    if doc.get("kind") not in KINDS:
        raise ModelFileError(f"{where}: unknown model kind {doc.get('kind')!r} (expected one of "
                             f"{', '.join(KINDS)})")


def _number(doc: Mapping[str, Any], key: str, where: str, default: float | None = None) -> float:
    value = doc.get(key, default)
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise ModelFileError(f"{where}: '{key}' must be a number, got {value!r}")
    try:
        return float(value)
    except OverflowError as err:  # an integer written with hundreds of digits
        raise ModelFileError(f"{where}: '{key}' is an integer of {len(str(value))} digits "
                             "(expected a number a float can hold)") from err


def _numbers(doc: Mapping[str, Any], key: str, where: str, what: str) -> list[float]:
    """The list of numbers ``doc[key]`` (JSON numbers; not true/false, not text), as floats."""
    values = doc.get(key)
    if not isinstance(values, list) or not all(
            isinstance(v, int | float) and not isinstance(v, bool) for v in values):
        raise ModelFileError(f"{where}: '{key}' must be a list of numbers ({what})")
    try:
        return [float(v) for v in values]
    except OverflowError as err:
        raise ModelFileError(f"{where}: '{key}' holds an integer of hundreds of digits "
                             "(expected numbers a float can hold)") from err


def _params(data: Any, where: str) -> dict[str, float]:
    """The ``params`` mapping: parameter names to numbers (JSON numbers; not true/false, not
    text), each converted to a float."""
    if not isinstance(data, Mapping):
        raise ModelFileError(f"{where}: 'params' must be a mapping of parameter names to numbers")
    return {str(key): _number(data, key, where) for key in data}


def _structure(doc: Mapping[str, Any], keys: tuple[str, ...], where: str,
               optional: tuple[str, ...] = ()) -> dict[str, Any]:
    data = doc.get("structure")
    if not isinstance(data, Mapping):
        raise ModelFileError(f"{where}: 'structure' must be a mapping with {', '.join(keys)}")
    unknown = sorted(set(data) - set(keys) - set(optional))
    missing = [k for k in keys if k not in data]
    if unknown or missing:
        extra = f" (optional: {', '.join(optional)})" if optional else ""
        raise ModelFileError(f"{where}: 'structure' expected the keys {', '.join(keys)}{extra}; "
                             f"missing {missing}, unknown {unknown}")
    out: dict[str, Any] = {}
    for key in (*keys, *(k for k in optional if k in data)):
        value = data[key]
        if key in ("f0", "directional"):
            if not isinstance(value, bool):
                raise ModelFileError(f"{where}: structure {key!r} must be true or false, got "
                                     f"{value!r}")
        elif isinstance(value, bool) or not isinstance(value, int):
            raise ModelFileError(f"{where}: structure {key!r} must be an integer, got {value!r}")
        out[key] = value
    return out


def _envelope(data: Any, where: str) -> Envelope | None:
    if data is None:
        return None
    if not isinstance(data, Mapping):
        raise ModelFileError(f"{where}: 'envelope' must be null or a mapping u_min, u_max, slew")
    try:
        return Envelope.from_dict(data)
    except ValueError as err:
        raise ModelFileError(f"{where}: {err}") from err


def _units(data: Any, where: str) -> dict[str, str] | None:
    if data is None:
        return None
    if not isinstance(data, Mapping) or not all(isinstance(v, str) for v in data.values()):
        raise ModelFileError(f"{where}: 'units' must map signal names to strings, got {data!r}")
    for key, value in data.items():
        if control_characters(value):
            raise ModelFileError(f"{where}: the unit of {key} is {value!r}, which holds control "
                                 "characters (expected a plain unit name such as 'um')")
    return {str(k): v for k, v in data.items()}
