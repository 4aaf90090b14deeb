"""Writing files without losing what the user had.

Three rules, applied by every writer in hystid:

1. **Check before work.** :func:`check_output` refuses an output that is one of the inputs, an
   existing file (unless ``force``), a symbolic link, or a place that cannot be written, before
   any computation starts; :func:`check_output_dir` does the same for a folder and the files
   that will be written into it, and :func:`check_apart` refuses a file output that is a
   folder output or one of the files written into it (two outputs never overwrite each other,
   not even with ``force``).
2. **Write atomically.** :func:`atomic_path` and :func:`atomic_open` write to a temporary file in
   the destination's folder and rename it over the destination (``os.replace``) only once the
   writing succeeded; on any failure (a full disk, an exception in the writer) the temporary
   file is removed and the previous file is left as it was. :func:`atomic_folder` does the
   same for a set of files written into one folder: they are written into a hidden staging
   folder and moved in place only once every one of them is written, so a failure leaves the
   folder's previous files all as they were (and a new folder does not appear at all).
3. **Strict JSON.** :func:`dumps_strict` never writes ``NaN`` or ``Infinity`` (which are not
   JSON): non-finite floats become ``null`` and the replacements are listed in a ``"notes"``
   entry of the top-level object.
"""

from __future__ import annotations

import contextlib
import json
import math
import os
import shutil
import tempfile
from collections.abc import Iterable, Iterator, Mapping
from pathlib import Path
from typing import IO, Any

import numpy as np

from .errors import OutputError

__all__ = [
    "OutputError",
    "atomic_folder",
    "atomic_open",
    "atomic_path",
    "check_apart",
    "check_output",
    "check_output_dir",
    "dumps_strict",
    "folder_lock",
    "inside",
    "same_file",
    "strict_json",
    "write_json",
    "write_text",
]

PathLike = str | os.PathLike[str]


# --------------------------------------------------------------------------- checks
def same_file(a: PathLike, b: PathLike) -> bool:
    """True when ``a`` and ``b`` name the same file (links and ``..`` resolved).

    Parameters
    ----------
    a, b : str or os.PathLike
        Paths; ``b`` may carry an HDF5 group suffix ``file.h5:group``.

    Returns
    -------
    bool
    """
    pa, pb = Path(a), Path(_strip_group(os.fspath(b)))
    try:
        if pa.exists() and pb.exists():
            return os.path.samefile(pa, pb)
    except OSError:
        pass
    return pa.resolve() == pb.resolve()


def _strip_group(text: str) -> str:
    head, sep, _ = text.rpartition(":")
    if sep and Path(head).suffix.lower() in (".h5", ".hdf5"):
        return head
    return text


def check_output(
    path: PathLike,
    *,
    option: str,
    inputs: Iterable[PathLike] = (),
    force: bool = False,
    create_folder: bool = False,
) -> Path:
    """Check that ``path`` may be written, before any work is done.

    Parameters
    ----------
    path : str or os.PathLike
        The file that will be written.
    option : str
        How the user named it (``"--out"``, ``"--history"``), used in the messages.
    inputs : iterable of path
        Files the command reads; none of them may be the output, even with ``force``.
    force : bool
        Allow replacing an existing regular file.
    create_folder : bool
        The file's folder may not exist yet (the writer creates it, with its parents); by
        default it must exist.

    Returns
    -------
    pathlib.Path
        ``path`` as a :class:`~pathlib.Path`.

    Raises
    ------
    OutputError
        If the output is an input, a symbolic link, a folder, an existing file without
        ``force``, or lies in a folder that does not exist or cannot be written.
    """
    out = Path(path)
    label = f"{option} {out}"
    for source in inputs:
        if source is not None and same_file(out, source):
            raise OutputError(f"{label}: is the input file {source} (expected a new file; "
                              "hystid never writes over its inputs)")
    if out.is_symlink():
        raise OutputError(f"{label}: is a symbolic link (expected a plain file path; links are "
                          "not followed when writing)")
    if out.is_dir():
        raise OutputError(f"{label}: is a folder (expected a file name)")
    if out.exists():
        if not out.is_file():
            raise OutputError(f"{label}: exists and is not a regular file")
        if not force:
            raise OutputError(f"{label}: the file exists (pass --force, or force=True from "
                              "Python, to replace it)")
        if not os.access(out, os.W_OK):
            raise OutputError(f"{label}: the file is not writable")
    _check_writable_folder(out.parent, label, create=create_folder)
    _CLAIMS[_claim_key(out)] = force
    return out


def check_apart(
    path: PathLike,
    folder: PathLike,
    names: Iterable[str],
    *,
    option: str,
    folder_option: str = "--out",
) -> None:
    """Refuse a file output that is a folder output, or one of the files written into it.

    Two outputs of one command must never overwrite each other, whatever ``force`` says: the
    check holds whether or not the files exist yet.

    Parameters
    ----------
    path : str or os.PathLike
        The file output (e.g. ``--history``).
    folder : str or os.PathLike
        The folder output (e.g. ``--out``).
    names : iterable of str
        File names written into ``folder``.
    option, folder_option : str
        How the user named the two outputs, used in the messages.

    Raises
    ------
    OutputError
        If ``path`` is ``folder`` or ``folder / name`` for one of ``names``.
    """
    label = f"{option} {path}"
    if same_file(path, folder):
        raise OutputError(f"{label}: is the {folder_option} folder (expected a file name "
                          f"outside the folder's own files)")
    for name in names:
        if same_file(path, Path(folder) / name):
            raise OutputError(f"{label}: is {name}, which {folder_option} {folder} writes too "
                              f"(expected another file name: the two outputs would overwrite "
                              f"each other, even with --force)")


def inside(path: PathLike, folder: PathLike) -> bool:
    """True when ``path`` lies in ``folder`` or below it (links and ``..`` resolved).

    Parameters
    ----------
    path, folder : str or os.PathLike
        A file and a folder; neither needs to exist.

    Returns
    -------
    bool
    """
    return Path(folder).resolve() in Path(path).resolve().parents


def check_output_dir(
    folder: PathLike,
    names: Iterable[str],
    *,
    option: str = "--out",
    inputs: Iterable[PathLike] = (),
    force: bool = False,
) -> Path:
    """Check that a report folder and the files to be written into it may be written.

    The folder may exist or not (it is created later, with its parents); each of ``names``
    inside it is checked with :func:`check_output`.

    Parameters
    ----------
    folder : str or os.PathLike
        The output folder.
    names : iterable of str
        File names that will be written into it.
    option : str
        The option naming the folder, for the messages.
    inputs : iterable of path
        Files the command reads.
    force : bool
        Allow replacing existing files inside the folder.

    Returns
    -------
    pathlib.Path
        The folder.

    Raises
    ------
    OutputError
        If the folder is a file or a link, cannot be created or written, or holds one of the
        files and ``force`` is not given.
    """
    out = Path(folder)
    label = f"{option} {out}"
    inputs = [p for p in inputs if p is not None]
    if out.is_symlink():
        raise OutputError(f"{label}: is a symbolic link (expected a plain folder path)")
    if out.exists():
        if not out.is_dir():
            raise OutputError(f"{label}: is a file (expected a folder)")
        if not os.access(out, os.W_OK | os.X_OK):
            raise OutputError(f"{label}: the folder is not writable")
        existing = [name for name in names if (out / name).exists() or (out / name).is_symlink()]
        for name in names:
            check_output(out / name, option=option, inputs=inputs, force=True)
        if existing and not force:
            raise OutputError(f"{label}: holds {', '.join(existing)} already (pass --force to "
                              "replace them)")
    else:
        _check_writable_folder(out.parent, label, create=True)
        for name in names:
            for source in inputs:
                if same_file(out / name, source):
                    raise OutputError(f"{label}: {name} would be the input file {source}")
    for name in names:
        _CLAIMS[_claim_key(out / name)] = force
    return out


def _check_writable_folder(folder: Path, label: str, create: bool = False) -> None:
    """The nearest existing ancestor must be a writable folder (and ``folder`` itself exist
    unless ``create``)."""
    folder = folder if str(folder) else Path(".")
    probe = folder
    while not probe.exists():
        if probe.is_symlink():
            raise OutputError(f"{label}: {probe} is a broken symbolic link")
        if probe.parent == probe:
            break
        probe = probe.parent
    if not create and probe != folder:
        raise OutputError(f"{label}: the folder {folder} does not exist (expected an existing "
                          "folder)")
    if not probe.is_dir():
        raise OutputError(f"{label}: {probe} is not a folder")
    if not os.access(probe, os.W_OK | os.X_OK):
        raise OutputError(f"{label}: cannot write in {probe} (permission denied)")


# --------------------------------------------------------------------------- atomic writes
@contextlib.contextmanager
def atomic_path(path: PathLike) -> Iterator[Path]:
    """Yield a temporary path beside ``path``; rename it over ``path`` when the block succeeds.

    The temporary file has the destination's suffix (some writers look at it). When the block
    raises, the temporary file is removed and ``path`` is untouched.

    Parameters
    ----------
    path : str or os.PathLike
        The destination. A symbolic link there is replaced, not followed.

    Yields
    ------
    pathlib.Path
        Where the writer must write.
    """
    dest = Path(path)
    folder = dest.parent if str(dest.parent) else Path(".")
    fd, tmp = tempfile.mkstemp(prefix=f".{dest.name}.", suffix=f".tmp{dest.suffix}",
                               dir=folder)
    os.close(fd)
    tmp_path = Path(tmp)
    try:
        yield tmp_path
        _fsync(tmp_path)
        _keep_mode(dest, tmp_path)
        _commit(tmp_path, dest)
    except BaseException:
        with contextlib.suppress(OSError):
            tmp_path.unlink()
        raise


@contextlib.contextmanager
def atomic_open(path: PathLike, mode: str = "w", **kwargs: Any) -> Iterator[IO[Any]]:
    """Open a temporary file for writing; it replaces ``path`` when the block succeeds.

    Parameters
    ----------
    path : str or os.PathLike
        The destination.
    mode : str
        ``"w"`` (text) or ``"wb"`` (binary).
    **kwargs
        Passed to :func:`open` (``encoding``, ``newline``).

    Yields
    ------
    file object
    """
    if mode not in ("w", "wb"):
        raise ValueError(f"mode: expected 'w' or 'wb', got {mode!r}")
    if mode == "w":
        kwargs.setdefault("encoding", "utf-8")
    with atomic_path(path) as tmp, open(tmp, mode, **kwargs) as handle:
        yield handle


@contextlib.contextmanager
def atomic_folder(folder: PathLike) -> Iterator[Path]:
    """Yield a staging folder; its files replace those of ``folder`` when the block succeeds.

    The writer writes every file into the staging folder (a hidden folder inside ``folder``, or
    beside it when ``folder`` does not exist yet). Only when the block succeeds are the files
    synced and moved in place: into an existing ``folder`` one by one (files of ``folder`` not
    written in the block are left alone), or, for a new ``folder``, by renaming the staging
    folder itself. When the block raises, the staging folder is removed: the previous files
    are all left as they were and a new folder does not appear.

    Parameters
    ----------
    folder : str or os.PathLike
        The destination folder; its parents are created when missing.

    Yields
    ------
    pathlib.Path
        The staging folder to write the files into (no sub-folders).
    """
    dest = Path(folder)
    exists = dest.is_dir()
    home = dest if exists else (dest.parent if str(dest.parent) else Path("."))
    home.mkdir(parents=True, exist_ok=True)
    stage = Path(tempfile.mkdtemp(prefix=f".{dest.name}.", suffix=".tmp", dir=home))
    try:
        yield stage
        files = sorted(p for p in stage.iterdir())
        for written in files:
            _fsync(written)
            _keep_mode(dest / written.name, written)
        if not exists:
            os.chmod(stage, 0o777 & ~_umask())
            try:
                os.rename(stage, dest)  # fails when a folder with files appeared meanwhile
                return
            except OSError as err:
                if not dest.exists():
                    raise
                if not dest.is_dir():
                    raise OutputError(f"{dest}: a file of that name appeared while the command "
                                      "ran; left as it was, nothing written") from err
        taken = [p.name for p in files if (dest / p.name).exists()
                 and not _CLAIMS.get(_claim_key(dest / p.name), True)]
        if taken:
            raise OutputError(_appeared(dest / taken[0]))
        for written in files:
            _commit(written, dest / written.name)
        stage.rmdir()
    except BaseException:
        shutil.rmtree(stage, ignore_errors=True)
        raise


#: Outputs checked by :func:`check_output` or :func:`check_output_dir` in this process, and
#: whether each may replace a file (``force``). A file that appears at a path checked as new
#: while the command runs (another run, the user) is never replaced: the write fails instead.
_CLAIMS: dict[str, bool] = {}


def _claim_key(path: PathLike) -> str:
    return os.path.abspath(os.fspath(path))


def _appeared(dest: Path) -> str:
    return (f"{dest}: appeared while the command ran (another run writing the same output, or "
            "a file written there meanwhile); left as it was and nothing written (pass --force "
            "to replace it, or choose another output)")


def _commit(tmp: Path, dest: Path) -> None:
    """Move a finished file in place: over ``dest`` only when its check allowed replacing.

    A destination checked as new is linked without replacing (:func:`os.link` fails when a
    file is there), so of two runs writing the same new output one wins and the other fails.
    """
    if _CLAIMS.pop(_claim_key(dest), True):
        os.replace(tmp, dest)
        return
    try:
        os.link(tmp, dest)
    except FileExistsError as err:
        raise OutputError(_appeared(dest)) from err
    except OSError:  # a file system without hard links: claim the name, then move in place
        try:
            os.close(os.open(dest, os.O_CREAT | os.O_EXCL | os.O_WRONLY, 0o600))
        except FileExistsError as err:
            raise OutputError(_appeared(dest)) from err
        os.replace(tmp, dest)
        return
    os.unlink(tmp)


@contextlib.contextmanager
def folder_lock(folder: PathLike, option: str = "--out") -> Iterator[Path]:
    """Hold ``folder/.hystid.lock`` while a command writes into ``folder``.

    The lock file is created exclusively and holds the process id; a lock left by a process
    that no longer runs is taken over.

    Parameters
    ----------
    folder : str or os.PathLike
        An existing folder.
    option : str
        How the user named it, for the message.

    Yields
    ------
    pathlib.Path
        The lock file (removed on exit).

    Raises
    ------
    OutputError
        When another running process holds the lock.
    """
    lock = Path(folder) / ".hystid.lock"
    for _ in range(2):
        try:
            fd = os.open(lock, os.O_CREAT | os.O_EXCL | os.O_WRONLY, 0o644)
            break
        except FileExistsError:
            try:
                pid = int(lock.read_text().strip() or "0")
            except (OSError, ValueError):
                pid = 0
            if pid > 0 and _running(pid):
                raise OutputError(f"{option} {folder}: another hystid run (process {pid}) is "
                                  f"writing there (lock {lock}); wait for it to end or choose "
                                  "another folder") from None
            with contextlib.suppress(OSError):
                lock.unlink()  # left by a run that ended without removing it
    else:  # pragma: no cover - lost the race for a stale lock twice
        raise OutputError(f"{option} {folder}: another hystid run is writing there")
    try:
        os.write(fd, str(os.getpid()).encode())
        os.close(fd)
        yield lock
    finally:
        with contextlib.suppress(OSError):
            lock.unlink()


def _running(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


def _fsync(path: Path) -> None:
    with open(path, "rb") as handle:
        os.fsync(handle.fileno())


def _keep_mode(dest: Path, tmp: Path) -> None:
    """Give the new file the old file's permissions, or the umask's default for a new file."""
    try:
        mode = dest.stat().st_mode & 0o777 if dest.is_file() else 0o666 & ~_umask()
        os.chmod(tmp, mode)
    except OSError:
        pass


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def write_text(path: PathLike, text: str) -> None:
    """Write ``text`` (UTF-8) to ``path`` atomically.

    Parameters
    ----------
    path : str or os.PathLike
        The destination.
    text : str
        The content.
    """
    with atomic_open(path, "w", newline="\n") as handle:
        handle.write(text)


# --------------------------------------------------------------------------- strict JSON
def strict_json(value: Any, where: str = "$", notes: list[str] | None = None) -> Any:
    """A copy of ``value`` made of JSON types only, with non-finite floats replaced by ``None``.

    Parameters
    ----------
    value : object
        Nested dicts, lists, tuples, numbers (NumPy scalars and arrays included), strings,
        booleans and ``None``.
    where : str
        Path of ``value`` in the document, for the notes.
    notes : list of str, optional
        Receives one sentence per replaced value.

    Returns
    -------
    object
        The converted value.

    Raises
    ------
    TypeError
        On a value of another type (naming where it sits).
    """
    notes = [] if notes is None else notes
    if isinstance(value, np.ndarray):
        value = value.tolist()
    elif isinstance(value, np.generic):
        value = value.item()
    if value is None or isinstance(value, bool | str):
        return value
    if isinstance(value, int):
        return value
    if isinstance(value, float):
        if math.isfinite(value):
            return value
        notes.append(f"{where} was {value!r}, written as null")
        return None
    if isinstance(value, Mapping):
        return {str(k): strict_json(v, f"{where}.{k}", notes) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [strict_json(v, f"{where}[{i}]", notes) for i, v in enumerate(value)]
    raise TypeError(f"{where}: {type(value).__name__} is not JSON (expected numbers, strings, "
                    "lists or mappings)")


def dumps_strict(document: Any, indent: int | None = 2) -> str:
    """Serialise ``document`` as strict JSON (never ``NaN`` or ``Infinity``).

    Non-finite floats become ``null``; when ``document`` is a mapping the replacements are
    listed under ``"notes"`` (appended to an existing list of notes).

    Parameters
    ----------
    document : object
        What :func:`strict_json` accepts.
    indent : int, optional
        Passed to :func:`json.dumps`.

    Returns
    -------
    str
    """
    notes: list[str] = []
    clean = strict_json(document, "$", notes)
    if notes and isinstance(clean, dict):
        previous = clean.get("notes")
        clean["notes"] = ([*previous] if isinstance(previous, list) else
                          ([previous] if previous is not None else [])) + notes
    return json.dumps(clean, indent=indent, allow_nan=False)


def write_json(path: PathLike, document: Any) -> None:
    """Write ``document`` as strict JSON to ``path`` atomically.

    Parameters
    ----------
    path : str or os.PathLike
        The destination.
    document : object
        What :func:`dumps_strict` accepts.
    """
    write_text(path, dumps_strict(document) + "\n")
