"""Reading npz, MATLAB and HDF5 records, refusing files that decode to more than they hold."""

from __future__ import annotations

import json
import os
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import RecordError
from ..signals import finite_signal
from .checks import _fs_from_time, _stated_fs
from .record import (
    _DEFAULT_UNITS,
    _ROLES,
    EXPANSION_FLOOR,
    FS_RTOL,
    MAX_EXPANSION,
    Locator,
    Record,
    _as_fs,
)


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
    units_stored: Any = None  # the file's own 'units' entry, as stored


def _check_stored_units(src: _Arrays, units_given: bool) -> None:
    """Refuse a ``units`` entry the file holds but :func:`_units` cannot read, unless the
    caller states the units itself (then the entry is not needed)."""
    if units_given or src.units is not None or src.units_stored is None:
        return
    text = _text(src.units_stored)
    shown = repr(text)[:80] if text is not None else \
        f"an array of shape {np.shape(src.units_stored)}"
    raise RecordError(f"its 'units' entry is {shown}, which hystid cannot read (expected the "
                      "text of a JSON mapping such as {\"u\": \"V\", \"y\": \"um\"}); state "
                      "the units with units= (--units u=V,y=um on the command line)",
                      file=src.file)


def _record_from_arrays(src: _Arrays, fs: float | None, name: str | None,
                        units_given: bool = False) -> Record:
    _check_stored_units(src, units_given)
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
    import lzma
    import zipfile
    import zlib

    # lzma.LZMAError: a member that claims LZMA compression with options the module refuses
    return (*_ARCHIVE_ERRORS, zipfile.BadZipFile, zlib.error, lzma.LZMAError, RuntimeError,
            NotImplementedError)


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
                   units_stored=extra.get("units"),
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
                   units_stored=content.get("units"),
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
        try:
            node = node.get(part) if link is not None else None
        except (RuntimeError, KeyError, OSError) as err:  # a soft link in a loop
            raise RecordError(f"group {part!r} is a link that cannot be followed ({err})",
                              file=file) from err
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
    try:
        dset = node[key]
    except (RuntimeError, KeyError, OSError) as err:  # a soft link in a loop, or dangling
        raise RecordError(f"dataset {key!r} is a link that cannot be followed ({err})",
                          file=file) from err
    if not isinstance(dset, h5py.Dataset):
        raise RecordError(f"{key!r} is a {type(dset).__name__.lower()}, not a dataset "
                          "(expected a dataset of numbers)", file=file)
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
                   units_stored=attrs.get("units"),
                   default_name=default)


def _h5_is_dataset(node: Any, key: str) -> bool:
    """True for a dataset, or an external link (refused when used); never opens other files."""
    import h5py

    link = node.get(key, getlink=True)
    if isinstance(link, h5py.ExternalLink):
        return True
    try:
        return isinstance(node.get(key), h5py.Dataset)
    except (RuntimeError, KeyError, OSError):  # a soft link that cannot be followed
        return isinstance(link, h5py.SoftLink)  # refused with the reason when it is used
