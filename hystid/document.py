"""Writing the hystid model file: a model's document and its atomic write.

The format is described in :mod:`hystid.modelfile`, which reads it back. Writing needs nothing
of the model classes beyond what every model carries (its ``kind``, structure, parameters and
placement; a diagnosed model its nominal ``model`` and ``effects``), so the models themselves
can save (:meth:`hystid.operating.Placed.save`) without an import running back up to them.
"""

from __future__ import annotations

import datetime as _dt
import hashlib
import json
import os
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from .errors import ModelFileError
from .safeio import check_output, dumps_strict, write_text

__all__ = ["FORMAT", "KINDS", "VERSION", "ModelFileError", "file_sha256", "make_provenance",
           "model_document", "save_model"]

#: Value of the ``format`` entry.
FORMAT = "hystid-model"
#: Version written by this hystid; the only one it reads.
VERSION = 1
#: Model kinds a file may hold.
KINDS = ("duhem", "pi", "mduhem")


#: Structure keys of the generalised Duhem block, written only when the block uses them.
_SHAPE_KEYS = ("f_order", "g_order", "directional")


# --------------------------------------------------------------------------- provenance
def file_sha256(path: str | os.PathLike[str]) -> str:
    """SHA-256 of a file's bytes, as hex (an HDF5 ``file.h5:group`` suffix is ignored).

    Parameters
    ----------
    path : str or os.PathLike
        The file.

    Returns
    -------
    str
    """
    from .safeio import _strip_group

    digest = hashlib.sha256()
    with open(_strip_group(os.fspath(path)), "rb") as handle:
        for block in iter(lambda: handle.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()


def make_provenance(
    method: str | None = None,
    record: str | os.PathLike[str] | None = None,
    settings: Mapping[str, Any] | None = None,
) -> dict[str, Any]:
    """Where a model came from: hystid's version, the method, the date and the record's hash.

    Parameters
    ----------
    method : str, optional
        The identification method.
    record : path, optional
        The record file the model was identified on; its bytes are hashed.
    settings : mapping, optional
        The identifier's settings; entries that are not JSON are left out.

    Returns
    -------
    dict
        Keys ``hystid_version``, ``method``, ``date`` (UTC, ISO 8601), ``record``,
        ``record_sha256`` and ``settings``.
    """
    from . import __version__

    return {
        "hystid_version": __version__,
        "method": method,
        "date": _dt.datetime.now(_dt.UTC).isoformat(timespec="seconds").replace("+00:00", "Z"),
        "record": None if record is None else os.fspath(record),
        "record_sha256": None if record is None else file_sha256(record),
        "settings": {k: v for k, v in (settings or {}).items() if _is_json(v)},
    }


def _is_json(value: Any) -> bool:
    try:
        json.dumps(value, allow_nan=False)
    except (TypeError, ValueError):
        return False
    return True


# --------------------------------------------------------------------------- saving
def model_document(
    model: Any, provenance: Mapping[str, Any] | None = None
) -> dict[str, Any]:
    """The model file's content as a dictionary.

    Parameters
    ----------
    model : DuhemSandwich, PISandwich or MultiDuhemSandwich
        The model (or a diagnosed ``AugmentedSandwich``: the nominal model's document with
        its ``effects``).
    provenance : mapping, optional
        See :func:`make_provenance`; one with only hystid's version and the date by default.

    Returns
    -------
    dict
    """
    from dataclasses import asdict

    effects = _effects_of(model)
    if effects is not None:  # the nominal model's document with the effects switched on
        doc = model_document(model.model, provenance)
        doc["effects"] = effects
        return doc
    kind = _kind_of(model)
    structure = asdict(model.structure)
    if getattr(model.structure, "is_plain", False):  # the paper's eq. (7): files as before
        structure = {k: v for k, v in structure.items() if k not in _SHAPE_KEYS}
    if kind == "pi" and not structure.get("n_poly"):  # the plays alone: files as before
        structure.pop("n_poly", None)
    doc: dict[str, Any] = {
        "format": FORMAT,
        "version": VERSION,
        "kind": kind,
        "name": model.name,
        "structure": {k: (bool(v) if k in ("f0", "directional") else int(v))
                      for k, v in structure.items()},
        "params": {k: float(v) for k, v in model.params.items()},
    }
    if kind == "pi":
        doc["thresholds"] = [float(r) for r in model.thresholds]
        if model.rest_swing:
            doc["rest_swing"] = float(model.rest_swing)
    elif kind == "mduhem":
        doc["rates"] = [float(r) for r in model.rates]
    else:
        doc["rest_memory"] = float(model.rest_memory)
    doc.update({
        "fs": float(model.fs),
        "u_rest": float(model.u_rest),
        "offset": float(model.offset),
        "envelope": None if model.envelope is None else model.envelope.to_dict(),
        "units": dict(model.units),
        "provenance": dict(provenance) if provenance is not None else make_provenance(),
    })
    return doc


def save_model(
    model: Any,
    path: str | os.PathLike[str],
    *,
    provenance: Mapping[str, Any] | None = None,
    force: bool = False,
) -> Path:
    """Write a model file.

    Parameters
    ----------
    model : DuhemSandwich, PISandwich or MultiDuhemSandwich
        The model to keep.
    path : str or os.PathLike
        The file (``.json`` by convention). Written atomically: a failure leaves any previous
        file as it was.
    provenance : mapping, optional
        See :func:`make_provenance`.
    force : bool
        Replace an existing file.

    Returns
    -------
    pathlib.Path
        The written file.

    Raises
    ------
    ModelFileError
        If the model is of another kind, or the path exists (without ``force``), is a link or
        a folder, or cannot be written.
    """
    try:
        out = check_output(path, option="model file", force=force)
    except ValueError as err:
        raise ModelFileError(str(err)) from err
    text = dumps_strict(model_document(model, provenance))
    write_text(out, text + "\n")
    return out


def _effects_of(model: Any) -> dict[str, dict[str, float]] | None:
    """The effects of a diagnosed model (a nominal ``model`` with ``effects``), else None."""
    effects = getattr(model, "effects", None)
    if effects is None or not hasattr(model, "model"):
        return None
    return {name: {k: float(v) for k, v in p.items()} for name, p in effects.items()}


def _kind_of(model: Any) -> str:
    kind = getattr(type(model), "kind", None)
    if kind not in KINDS:
        raise ModelFileError(f"model: expected a DuhemSandwich, a PISandwich or a "
                             f"MultiDuhemSandwich, got {type(model).__name__}")
    return kind
