"""Checks of what hystid is handed: model files, models and sizes, before any work.

A model file is read only when it is a plain regular file of at most :data:`MAX_MODEL_BYTES`
(a FIFO, a device such as ``/dev/zero`` or a symbolic link to one would block or never end);
the model it holds is refused when it could not be simulated soundly: a number beyond
:data:`MAX_MAGNITUDE` (no unit system puts a stage's parameter there, and the products of two
such numbers overflow), a pole of L1 or L2 on or outside the unit circle (its output grows
without bound), ``alpha <= 0`` for the Duhem block (the loop then grows instead of settling),
or orders and delays beyond :data:`MAX_ORDER` and
:data:`MAX_DELAY`. Each check raises ``ValueError`` (the caller wraps it in its
own error class) with a message naming the entry and what was expected.

The command line refuses records longer than a method takes in reasonable time and memory
(:data:`MAX_BATCH_SAMPLES` for the batch fit, :data:`MAX_RECURSIVE_SAMPLES` for the recursive
methods) before any work, saying what to do instead (fit a part with ``--crop``, decimate, or
go on-line); :func:`hystid.identify.identify` fits what it is given (the benchmarks measure
long fits on purpose).
"""

from __future__ import annotations

import os
import stat
from collections.abc import Mapping
from typing import Any

import numpy as np

__all__ = ["MAX_BATCH_SAMPLES", "MAX_MAGNITUDE", "MAX_MODEL_BYTES", "MAX_NESTING",
           "MAX_RECURSIVE_SAMPLES", "PLAIN_DUHEM_LAYOUT", "check_magnitudes",
           "check_delays_fit", "check_fit_size", "check_plain_duhem",
           "check_model", "check_structure_size", "read_plain_text", "too_deep"]

#: Largest size of a model file read (a model of the largest structure is a few kB).
MAX_MODEL_BYTES = 16 << 20
#: Largest absolute value of a model's parameter, threshold, rest level or offset.
MAX_MAGNITUDE = 1e100
#: Deepest nesting of JSON lists and objects read in a model file.
MAX_NESTING = 50
#: Most samples a batch fit takes: its cost grows linearly with the record but with the
#: hundreds of passes of the optimiser (about 0.3 ms a sample on one core, so 5 min here); a
#: longer record is refused up front with what to do (the recursive methods run one pass).
MAX_BATCH_SAMPLES = 1_000_000
#: Most samples the recursive methods take: one pass, linear in the length (about 12 us a
#: sample on a loaded 2-core machine with the validation and the baselines, so 40 s), and
#: the history, the validation and the baselines keep several copies of the record in memory.
MAX_RECURSIVE_SAMPLES = 3_000_000
#: Largest radius of a pole of L1 or L2 (a pole closer to the unit circle is a drift that does
#: not settle within any record).
MAX_POLE_RADIUS = 1.0 - 1e-9


#: Largest order of L1 or L2 of a model (``--structure``, model files).
MAX_ORDER = 10
#: Largest delay (samples) of L1 or L2 of a model.
MAX_DELAY = 1000
#: Entries of the plain Duhem sandwich's kernel layout ``[n1a, n1b, n2a, n2b, q1, q2, f0]``.
PLAIN_DUHEM_LAYOUT = 7

def read_plain_text(path: str, what: str = "model file",
                    limit: int = MAX_MODEL_BYTES) -> str:
    """Read a plain regular file as UTF-8 text, refusing anything else up front.

    Parameters
    ----------
    path : str
        The file (a symbolic link is followed only to a regular file).
    what : str
        What the file is, for messages.
    limit : int
        Largest size in bytes.

    Returns
    -------
    str
        The file's text.

    Raises
    ------
    FileNotFoundError, IsADirectoryError
        As :func:`open` would.
    ValueError
        For a FIFO, a device, a socket, a file larger than ``limit``, or one that grows past it
        while read.
    """
    info = os.stat(path)
    if stat.S_ISDIR(info.st_mode):
        raise IsADirectoryError(path)
    if not stat.S_ISREG(info.st_mode):
        raise ValueError(f"not a regular file (a FIFO, device or socket); expected a plain "
                         f"{what}")
    if info.st_size > limit:
        raise ValueError(f"{info.st_size:,} bytes (expected a {what} of at most {limit:,} "
                         "bytes)")
    fd = os.open(path, os.O_RDONLY | getattr(os, "O_NONBLOCK", 0))
    with os.fdopen(fd, "rb") as handle:
        if not stat.S_ISREG(os.fstat(handle.fileno()).st_mode):  # replaced since the stat
            raise ValueError(f"not a regular file; expected a plain {what}")
        data = handle.read(limit + 1)
    if len(data) > limit:
        raise ValueError(f"grew past {limit:,} bytes while read (expected a {what} of at most "
                         f"{limit:,} bytes)")
    return data.decode("utf-8")


def too_deep(value: Any, limit: int = MAX_NESTING) -> bool:
    """Whether lists and mappings nest deeper than ``limit`` in a parsed JSON value.

    Parameters
    ----------
    value : object
        A value from :func:`json.loads`.
    limit : int
        Deepest nesting allowed.

    Returns
    -------
    bool
    """
    level = [value]
    for _ in range(limit + 1):
        level = [v for x in level
                 for v in (x.values() if isinstance(x, Mapping) else x if isinstance(x, list)
                           else ())]
        if not level:
            return False
    return True


def check_structure_size(structure: Any) -> None:
    """Orders at most :data:`MAX_ORDER`, delays at most ``MAX_DELAY``.

    Parameters
    ----------
    structure : Structure or PIStructure
        The structure.

    Raises
    ------
    ValueError
        Naming the key, its value and the range expected.
    """
    for key, value in vars(structure).items():
        if key == "f0":
            continue
        top = MAX_DELAY if key.startswith("q") else (1000 if key == "n_operators" else MAX_ORDER)
        if value > top:
            what = "a delay in samples" if key.startswith("q") else "a count" if \
                key == "n_operators" else "an order"
            raise ValueError(f"structure {key}={value} (expected {what} in 0..{top})")


def check_delays_fit(structure: Any, n: int, where: str) -> None:
    """Refuse a structure whose delays and orders reach past a record of ``n`` samples.

    Parameters
    ----------
    structure : Structure or PIStructure
        The structure.
    n : int
        Samples of the record.
    where : str
        The record, for messages.

    Raises
    ------
    ValueError
        When the longest past the model needs (``q + order``) is not shorter than half the
        record: the output would not depend on most of the input.
    """
    s = vars(structure)
    longest = max(s.get("q1", 0) + s.get("n1b", 0), s.get("q2", 0) + s.get("n2b", 0),
                  s.get("n1a", 0), s.get("n2a", 0))
    if 2 * longest >= n:
        raise ValueError(f"{where}: the structure's delays and orders reach {longest} samples "
                         f"into the past, not shorter than half the record's {n} samples "
                         "(expected delays much shorter than the record)")


def _poles_radius(a: np.ndarray) -> float:
    a = np.asarray(a, dtype=float)
    if a.size == 0:
        return 0.0
    return float(np.max(np.abs(np.roots(np.concatenate([[1.0], a])))))


def check_model(model: Any) -> None:
    """Refuse a model that cannot be simulated soundly (see the module's docstring).

    Parameters
    ----------
    model : DuhemSandwich or PISandwich
        The model.

    Raises
    ------
    ValueError
        Naming the entry and what was expected.
    """
    check_structure_size(model.structure)
    values: Mapping[str, float] = {**model.params, "u_rest": model.u_rest,
                                   "offset": model.offset}
    for key, value in values.items():
        if not (np.isfinite(value) and abs(value) <= MAX_MAGNITUDE):
            raise ValueError(f"'{key}' is {value!r} (expected a finite number of magnitude at "
                             f"most {MAX_MAGNITUDE:g})")
    envelope = getattr(model, "envelope", None)
    for key, value in (envelope.to_dict() if envelope is not None else {}).items():
        if not abs(value) <= MAX_MAGNITUDE:
            raise ValueError(f"envelope '{key}' is {value!r} (expected a finite number of "
                             f"magnitude at most {MAX_MAGNITUDE:g})")
    thresholds = np.asarray(getattr(model, "thresholds", []), dtype=float)
    if thresholds.size and not np.all(np.abs(thresholds) <= MAX_MAGNITUDE):
        raise ValueError(f"'thresholds' reach {np.max(np.abs(thresholds)):g} (expected at most "
                         f"{MAX_MAGNITUDE:g})")
    if "alpha" in model.params and not model.params["alpha"] > 0:
        raise ValueError(f"'alpha' is {model.params['alpha']!r} (expected alpha > 0: with "
                         "alpha <= 0 the Duhem loop grows instead of settling)")
    if "ad" in model.params and not abs(model.params["ad"]) < 1.0:
        raise ValueError(f"'ad' is {model.params['ad']!r} (expected |ad| < 1: otherwise one "
                         "branch's rate alpha (1 +- ad) is not positive and the loop grows "
                         "instead of settling)")
    for block in ("L1", "L2"):
        radius = _poles_radius(getattr(model, f"a{block[1]}"))
        if not radius <= MAX_POLE_RADIUS:
            raise ValueError(f"{block} has a pole of radius {radius:.6g} (expected every pole "
                             "strictly inside the unit circle: the block is unstable and its "
                             "output grows without bound)")


def check_fit_size(n: int, method: str, where: str) -> None:
    """Refuse a fit of more samples than the method takes, before the work.

    A batch fit takes at most :data:`MAX_BATCH_SAMPLES` samples, the recursive methods at most
    :data:`MAX_RECURSIVE_SAMPLES`.

    Parameters
    ----------
    n : int
        Samples to fit.
    method : str
        The identification method.
    where : str
        The record, for the message.

    Raises
    ------
    ValueError
        Saying how long the fit would take and what to do instead.
    """
    if method == "batch" and n > MAX_BATCH_SAMPLES:
        raise ValueError(
            f"{where}: {n:,} samples are more than hystid batch-fits ({MAX_BATCH_SAMPLES:,}: "
            f"it would run for about {n * 3e-4 / 60:.0f} min); fit a part of it (--crop "
            "START:STOP, or record[i:j] from Python), decimate it, or use --method online "
            "(one pass, linear in the length, with progress)")
    if n > MAX_RECURSIVE_SAMPLES:
        raise ValueError(
            f"{where}: {n:,} samples are more than hystid identifies in one run "
            f"({MAX_RECURSIVE_SAMPLES:,} with --method {method}); fit a part of it (--crop "
            "START:STOP, or record[i:j] from Python) or decimate it to a lower rate first")


def check_magnitudes(record: Any, where: str | None = None) -> None:
    """Refuse a record with samples beyond :data:`MAX_MAGNITUDE` (no sensor reads 1e300).

    Parameters
    ----------
    record : Record
        The record.
    where : str, optional
        The record, for the message (its name by default).

    Raises
    ------
    ValueError
        Naming the signal, the largest value and the sample.
    """
    for label, x in (("u", record.u), ("y", record.y)):
        k = int(np.argmax(np.abs(x)))
        if abs(float(x[k])) > MAX_MAGNITUDE:
            raise ValueError(f"{where or f'record {record.name!r}'}: {label} reaches {x[k]:.4g} "
                             f"at sample {k} (expected values of magnitude at most "
                             f"{MAX_MAGNITUDE:g}: squares of such numbers overflow; rescale "
                             "the record, e.g. to SI or micro units)")


def check_plain_duhem(layout: Any, option: str) -> None:
    """Refuse a structure richer than the plain Duhem sandwich of eqs. (1), (7), (2).

    Kernels written for the plain sandwich read the first :data:`PLAIN_DUHEM_LAYOUT` entries of
    the layout and the parameters they name; a richer structure (a hysteresis block with more
    shape parameters, its options in further layout entries and its parameters appended to
    theta) would be computed as a plain Duhem without a word. This check refuses it instead.

    Parameters
    ----------
    layout : array_like of int
        The structure's kernel layout (:attr:`hystid.model.Structure.layout`).
    option : str
        The option that supports only the plain sandwich, for the message (e.g.
        ``"method='ekf'"``).

    Raises
    ------
    ValueError
        When the layout has fewer than :data:`PLAIN_DUHEM_LAYOUT` entries or a non-zero
        entry after them (the generalised Duhem block's ``nf, ng, directional``).
    """
    entries = np.asarray(layout).ravel()
    if entries.size < PLAIN_DUHEM_LAYOUT:
        found = f"only {entries.size} entries (expected {PLAIN_DUHEM_LAYOUT})"
    else:
        extra = entries[PLAIN_DUHEM_LAYOUT:]
        if not np.any(extra != 0):
            return
        found = (f"hysteresis-shape entries {extra.tolist()} after the seventh (a generalised "
                 "Duhem block), which it would ignore and compute a plain Duhem")
    raise ValueError(
        f"{option} supports only the plain Duhem sandwich of eqs. (1), (7), (2) (the layout "
        f"[n1a, n1b, n2a, n2b, q1, q2, f0] with no shape terms); this structure's "
        f"layout has {found}. Use a plain Structure with {option}"
    )
