"""Fleets of records and Monte Carlo studies on Dask (``dask.distributed``).

A fleet is many records, each identified (and validated on held-out data) or diagnosed on its
own. Every record is one Dask task: the records are read by the workers from paths they can
see, so on a cluster the records live on a file system the workers share. The steps:

1. :func:`find_jobs` -- the records: a glob, a folder, or a CSV table of ``train,val`` pairs;
2. :func:`run_fleet` -- skip the records that already have a result row (unless ``force``),
   submit the rest, collect a row per record as it finishes (a failed record is a row with
   status ``failed`` and its reason; the others go on), and write the table as CSV and
   Parquet atomically (temporary file + :func:`os.replace`) while the run goes on, so that an
   interrupted run resumes where it stopped;
3. :func:`map_seeds` -- a Monte Carlo helper: a function mapped over seeds on the cluster.

The cluster is a :class:`distributed.LocalCluster` of single-threaded worker processes by
default, or an existing scheduler when its address is given (:func:`fleet_client`).
"""

from __future__ import annotations

import contextlib
import csv
import glob
import json
import math
import os
import sys
import tempfile
import time
import warnings
import zlib
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from .errors import FleetError, OutputError
from .safeio import folder_lock

__all__ = ["KINDS", "RECORD_SUFFIXES", "WORKERS_PER_CORE", "FailedSeed", "FleetError", "Job",
           "find_jobs", "fleet_client", "map_seeds", "max_local_workers", "read_results",
           "result_paths", "run_fleet", "run_job", "spawn_seeds"]

#: What a fleet can do with each record.
KINDS = ("identify", "diagnose")
#: File name endings taken as records when a folder is given.
RECORD_SUFFIXES = (".csv", ".txt", ".tsv", ".npz", ".mat", ".h5", ".hdf5")
#: Columns every result row has (parameters follow as ``param_<name>``).
BASE_COLUMNS = ("name", "status", "error", "train", "val", "held_out", "method", "model",
                "samples", "fs", "u_rest", "offset", "unit", "rms_model", "rms_static_line",
                "rms_linear",
                "beats_baselines", "accepted", "best", "rms_nominal", "rms_final", "noise_floor",
                "gap_closed", "seed", "seconds", "worker", "fingerprint")


#: Dask starts worker processes with ``MALLOC_TRIM_THRESHOLD_=65536``: with it an
#: identification runs 1.6x slower (the allocator hands memory back to the system at every
#: step). The local cluster unsets it; see the README for workers started by ``dask worker``.
LOCAL_WORKER_ENV = "distributed.nanny.pre-spawn-environ.MALLOC_TRIM_THRESHOLD_"
#: A local cluster starts at most this many worker processes per core of the machine (each
#: imports hystid and numba's kernels; beyond a few per core they only wait for one another).
WORKERS_PER_CORE = 4


def max_local_workers() -> int:
    """The most worker processes a local cluster starts on this machine.

    Returns
    -------
    int
        :data:`WORKERS_PER_CORE` times the machine's cores.
    """
    return WORKERS_PER_CORE * (os.cpu_count() or 1)


# --------------------------------------------------------------------------- the records
@dataclass(frozen=True)
class Job:
    """One record of a fleet and what to do with it.

    Attributes
    ----------
    name : str
        Unique name of the record in the fleet (its path relative to the fleet's root).
    train : str
        Path of the record to identify on.
    val : tuple of str
        Held-out records; empty to hold out the end of ``train``.
    """

    name: str
    train: str
    val: tuple[str, ...] = ()

    def files(self) -> tuple[str, ...]:
        """The files the job reads (an HDF5 ``file.h5:group`` reduced to the file).

        Returns
        -------
        tuple of str
        """
        return tuple(_file_part(p) for p in (self.train, *self.val))


def _file_part(path: str) -> str:
    if not os.path.exists(path) and ":" in path[2:]:
        head, _, _ = path.rpartition(":")
        if head.lower().endswith((".h5", ".hdf5")):
            return head
    return path


def find_jobs(source: str | os.PathLike[str]) -> list[Job]:
    """The records of a fleet.

    Parameters
    ----------
    source : str or os.PathLike
        A folder (every file ending in one of :data:`RECORD_SUFFIXES`, sorted), a CSV table
        with a header holding a ``train`` column and optionally ``val`` (several held-out
        records separated by ``;``) and ``name`` (paths relative to the table's folder), or a
        glob pattern (``**`` descends into folders).

    Returns
    -------
    list of Job
        Sorted by name.

    Raises
    ------
    FleetError
        No record found, or a malformed table (the message names the file and line).
    """
    text = os.fspath(source)
    path = Path(text)
    if path.is_dir():
        files = sorted(str(p) for p in path.iterdir()
                       if p.is_file() and p.suffix.lower() in RECORD_SUFFIXES)
        if not files:
            raise FleetError(f"{text}: no record files in this folder (expected files ending "
                             f"in {', '.join(RECORD_SUFFIXES)})")
        return _named(files, path)
    if path.is_file() and path.suffix.lower() == ".csv" and _is_table(path):
        return _read_table(path)
    files = sorted(p for p in glob.glob(text, recursive=True) if os.path.isfile(p))
    if not files:
        raise FleetError(f"{text}: no record files match (expected a folder, a glob pattern "
                         f"or a CSV table with a 'train' column)")
    root = Path(os.path.commonpath([os.path.dirname(os.path.abspath(f)) for f in files]))
    return _named(files, root)


def _named(files: Sequence[str], root: Path) -> list[Job]:
    return [Job(Path(os.path.relpath(os.path.abspath(f), root)).as_posix(), f) for f in files]


def _is_table(path: Path) -> bool:
    with open(path, newline="") as fh:
        for line in fh:
            if line.strip() and not line.lstrip().startswith("#"):
                header = next(csv.reader([line]))
                return "train" in [h.strip().lower() for h in header]
    return False


def _read_table(path: Path) -> list[Job]:
    base = path.parent
    jobs: dict[str, Job] = {}
    with open(path, newline="") as fh:
        rows = [(i, r) for i, r in enumerate(csv.reader(fh), 1)
                if r and not r[0].lstrip().startswith("#")]
    header = [h.strip().lower() for h in rows[0][1]]
    for line, row in rows[1:]:
        cells = dict(zip(header, (c.strip() for c in row), strict=False))
        if not cells.get("train"):
            raise FleetError(f"{path}, line {line}: empty 'train' cell (expected the path of "
                             f"the record to identify on)")
        train = str(base / cells["train"])
        val = tuple(str(base / v.strip()) for v in cells.get("val", "").split(";") if v.strip())
        name = cells.get("name") or Path(cells["train"]).as_posix()
        if name in jobs:
            raise FleetError(f"{path}, line {line}: name {name!r} appears twice (expected one "
                             f"row per record; add a 'name' column to tell the rows apart)")
        jobs[name] = Job(name, train, val)
    if not jobs:
        raise FleetError(f"{path}: the table has a header but no rows")
    return sorted(jobs.values(), key=lambda j: j.name)


def fingerprint(job: Job, kind: str, settings: dict[str, Any]) -> str:
    """What a result row was computed from: the files' sizes and times, the kind, the settings.

    A result row is reused by a resumed run only when its fingerprint is the same.

    Parameters
    ----------
    job : Job
        The record.
    kind : str
        One of :data:`KINDS`.
    settings : dict
        The run's settings (JSON-serialisable).

    Returns
    -------
    str
        A hexadecimal CRC-32 of all that.
    """
    stats = []
    for f in job.files():
        try:
            st = os.stat(f)
            stats.append([f, st.st_size, st.st_mtime_ns])
        except OSError:
            stats.append([f, None, None])
    text = json.dumps([job.name, job.train, job.val, stats, kind, settings], sort_keys=True,
                      default=str)
    return f"{zlib.crc32(text.encode()):08x}"


# --------------------------------------------------------------------------- one record
def run_job(job: Job, kind: str = "identify", settings: dict[str, Any] | None = None,
            seed: int = 0) -> dict[str, Any]:
    """Identify or diagnose one record; never raises: a failure is a row with its reason.

    Parameters
    ----------
    job : Job
        The record (read here, on the worker).
    kind : {'identify', 'diagnose'}
        ``identify``: identify on ``train`` and compare with the baselines on the held-out
        records (:func:`hystid.baselines.compare`) or on the held-out end of ``train``.
        ``diagnose``: :func:`hystid.diagnose.diagnose` and the same comparison for its
        nominal model.
    settings : dict, optional
        ``method`` and ``model`` (identify: the estimator and the member of the model family,
        as :func:`hystid.identify.identify` takes them; ``"batch"`` and the member
        :func:`~hystid.identify.identify` fits by default, ``"auto"`` for ``"batch"`` and
        ``"online"``, by default), ``holdout`` (share of ``train`` held out without ``val``,
        default 0.4), ``fs``, ``columns`` (for :func:`hystid.records.load_record`),
        ``effects``, ``initial`` (diagnose).
    seed : int
        Seeds NumPy's global generator before the work, for any random figure inside.

    Returns
    -------
    dict
        One result row (see :data:`BASE_COLUMNS`; parameters as ``param_<name>``).
    """
    settings = dict(settings or {})
    row: dict[str, Any] = {"name": job.name, "train": job.train, "val": ";".join(job.val),
                           "seed": seed, "worker": _worker_name()}
    t0 = time.perf_counter()
    try:
        if kind not in KINDS:
            raise ValueError(f"kind: expected one of {', '.join(KINDS)}, got {kind!r}")
        np.random.seed(seed)
        train, vals = _load_job(job, settings)
        work = _identify_row if kind == "identify" else _diagnose_row
        row.update(work(train, vals, settings))
        row["status"], row["error"] = "ok", ""
    except Exception as err:  # noqa: BLE001 - one broken record must not stop the fleet
        row["status"], row["error"] = "failed", f"{type(err).__name__}: {err}"
    row["seconds"] = time.perf_counter() - t0
    return row


def _worker_name() -> str:
    try:
        from distributed import get_worker

        return str(get_worker().address)
    except (ImportError, ValueError):
        return "local"


def _load_job(job: Job, settings: dict[str, Any]):
    from .records import load_record

    opts = {"fs": settings.get("fs"), "columns": settings.get("columns")}
    train = load_record(job.train, **opts)
    vals = [load_record(v, **opts) for v in job.val]
    for v, path in zip(vals, job.val, strict=True):
        if not np.isclose(v.fs, train.fs, rtol=1e-9):
            raise ValueError(f"{path}: fs {v.fs:g} Hz differs from {train.fs:g} Hz of "
                             f"{job.train}")
    return train, vals


def _split(train, vals, settings: dict[str, Any]):
    """The part to fit on and the held-out records (with the sample each is scored from)."""
    if vals:
        return train, list(vals), f"{len(vals)} record(s)"
    holdout = float(settings.get("holdout", 0.4))
    if not 0 < holdout < 1:
        raise ValueError(f"holdout: expected a fraction in (0, 1), got {holdout}")
    from .identify.prepare import held_out_from

    k = held_out_from(train.u, holdout)
    return train[:k], [(train, k)], f"last {100 * holdout:.0f} % of the excitation"


def _identify_row(train, vals, settings: dict[str, Any]) -> dict[str, Any]:
    from .identify import identify

    fit_on, held, label = _split(train, vals, settings)
    method = settings.get("method") or "batch"
    result = identify(fit_on, method=method, model=settings.get("model"))
    model = result.info.get("model") or getattr(result.model, "kind", "")
    return {"method": result.method, "model": model, "held_out": label,
            **_model_columns(result.model, fit_on),
            **_held_out_columns(result.model, fit_on, held)}


def _diagnose_row(train, vals, settings: dict[str, Any]) -> dict[str, Any]:
    from .diagnose import diagnose

    opts = {k: settings[k] for k in ("effects", "initial", "holdout") if k in settings}
    # one thread a record: the fleet's own workers are the parallelism
    res = diagnose(train, vals or None, progress=False, workers=1, **opts)
    fit_on, held, label = _split(train, vals, settings)
    return {"method": "diagnose", "held_out": label, **_model_columns(res.model, fit_on),
            **_held_out_columns(res.model, fit_on, held),
            "accepted": ";".join(res.accepted), "best": res.best,
            "rms_nominal": float(res.nominal["rms_val"]),
            "rms_final": float(res.final["rms_val"]),
            "noise_floor": float(res.noise_floor_rms),
            "gap_closed": _finite_or_nan(res.final.get("gap_closed"))}


def _model_columns(model, fit_on) -> dict[str, Any]:
    return {"samples": fit_on.n, "fs": fit_on.fs, "u_rest": float(getattr(model, "u_rest", 0.0)),
            "offset": float(getattr(model, "offset", 0.0)),
            "unit": str((fit_on.units or {}).get("y", "")),
            **{f"param_{k}": float(v) for k, v in model.params.items()}}


def _held_out_columns(model, fit_on, held) -> dict[str, Any]:
    """Held-out RMS of the model and of the baselines, pooled over the scored samples."""
    from .baselines import compare

    rows = compare(model, fit_on, held).rows
    total = sum(r["samples"] for r in rows)
    pooled = {k: math.sqrt(sum(r["samples"] * r[k] ** 2 for r in rows) / total)
              for k in ("model", "static_line", "linear")}
    return {"rms_model": pooled["model"], "rms_static_line": pooled["static_line"],
            "rms_linear": pooled["linear"],
            "beats_baselines": bool(pooled["model"] < min(pooled["static_line"],
                                                          pooled["linear"]))}


def _finite_or_nan(value: Any) -> float:
    return float(value) if value is not None and np.isfinite(value) else math.nan


# --------------------------------------------------------------------------- the cluster
def _require_dask():
    try:
        import distributed
    except ImportError as err:  # pragma: no cover - depends on the installation
        raise FleetError("fleets need dask.distributed: pip install 'dask[distributed]' "
                         "pyarrow pandas") from err
    return distributed


@contextlib.contextmanager
def fleet_client(workers: int | None = None, scheduler: str | None = None,
                 host: str = "127.0.0.1") -> Iterator[Any]:
    """A Dask client: to an existing scheduler, or to a local cluster started for the run.

    Parameters
    ----------
    workers : int, optional
        Worker processes of the local cluster (one thread each); the machine's cores by
        default, at most :func:`max_local_workers`. Not allowed with ``scheduler``.
    scheduler : str, optional
        Address of a running scheduler (``tcp://HOST:PORT``); its workers must see the
        records' paths and be able to import ``hystid``.
    host : str
        Interface the local cluster listens on (loopback by default).

    Yields
    ------
    distributed.Client
    """
    distributed = _require_dask()
    if scheduler is not None and workers is not None:
        raise FleetError("give either a number of workers (local cluster) or a scheduler "
                         "address, not both")
    if scheduler is not None:
        try:
            client = distributed.Client(scheduler, timeout="20s")
        except OSError as err:
            raise FleetError(f"scheduler {scheduler}: cannot connect ({err})") from err
        with client:
            yield client
        return
    n = int(workers) if workers is not None else (os.cpu_count() or 1)
    if n < 1:
        raise FleetError(f"workers: expected at least 1, got {n}")
    if n > max_local_workers():
        raise FleetError(f"workers: {n} worker processes on a machine of {os.cpu_count()} "
                         f"cores (expected at most {max_local_workers()}, {WORKERS_PER_CORE} a "
                         "core; for more, start workers on other machines and give their "
                         "scheduler)")
    import dask

    with warnings.catch_warnings(), dask.config.set({LOCAL_WORKER_ENV: None}):
        # the HTTP server takes another port when another cluster holds the usual one
        warnings.filterwarnings("ignore", message="Port .* is already in use")
        cluster = distributed.LocalCluster(n_workers=n, threads_per_worker=1, processes=True,
                                           host=host, dashboard_address=None)
    with cluster, distributed.Client(cluster) as client:
        yield client


@contextlib.contextmanager
def _client_or(client: Any | None, workers: int | None, scheduler: str | None):
    if client is not None:
        yield client
    else:
        with fleet_client(workers, scheduler) as own:
            yield own


class _Ticker:
    """A plain progress line on stderr at most every ``every`` seconds (and at the end)."""

    def __init__(self, total: int, label: str, enabled: bool, every: float = 2.0):
        self.total, self.label, self.enabled, self.every = total, label, enabled, every
        self.t0 = self.last = time.perf_counter()

    def __call__(self, done: int, failed: int = 0, force: bool = False) -> None:
        now = time.perf_counter()
        if self.enabled and (force or now - self.last >= self.every or done >= self.total):
            self.last = now
            extra = f", {failed} failed" if failed else ""
            print(f"[{now - self.t0:7.1f} s] {self.label}: {done}/{self.total} done{extra}",
                  file=sys.stderr, flush=True)


# --------------------------------------------------------------------------- the results
def result_paths(out: str | os.PathLike[str], kind: str) -> tuple[Path, Path]:
    """The CSV and Parquet files of a fleet's results.

    Parameters
    ----------
    out : str or os.PathLike
        The output folder.
    kind : str
        One of :data:`KINDS`.

    Returns
    -------
    tuple of Path
        ``out/<kind>.csv`` and ``out/<kind>.parquet``.
    """
    out = Path(out)
    return out / f"{kind}.csv", out / f"{kind}.parquet"


def read_results(out: str | os.PathLike[str], kind: str):
    """The result table of a previous run, or ``None`` when there is none.

    Parameters
    ----------
    out : str or os.PathLike
        The output folder.
    kind : str
        One of :data:`KINDS`.

    Returns
    -------
    pandas.DataFrame or None

    Raises
    ------
    FleetError
        When the file exists but is not a fleet result table.
    """
    import pandas as pd

    csv_path, parquet_path = result_paths(out, kind)
    try:
        if parquet_path.exists():
            table = pd.read_parquet(parquet_path)
        elif csv_path.exists():
            table = pd.read_csv(csv_path, keep_default_na=False, na_values=[""])
        else:
            return None
    except Exception as err:  # noqa: BLE001 - any reader error means the same to the user
        raise FleetError(f"{parquet_path if parquet_path.exists() else csv_path}: not readable "
                         f"as a fleet result table ({err}); move it away or choose another "
                         f"--out") from err
    missing = {"name", "status", "fingerprint"} - set(table.columns)
    if missing:
        raise FleetError(f"{csv_path.parent}: {kind} results lack the columns "
                         f"{', '.join(sorted(missing))}: not written by hystid fleet; move them "
                         f"away or choose another --out")
    return table


def _write_results(rows: Sequence[dict[str, Any]], out: Path, kind: str):
    """Write the table as CSV and Parquet, each to a temporary file then moved in place."""
    import pandas as pd

    params = sorted({k for r in rows for k in r if k.startswith("param_")})
    columns = [*BASE_COLUMNS, *params]
    table = pd.DataFrame([{c: r.get(c) for c in columns} for r in rows], columns=columns)
    table = table.sort_values("name", kind="stable").reset_index(drop=True)
    for c in ("error", "val", "held_out", "method", "accepted", "best", "worker"):
        table[c] = table[c].fillna("").astype(str)
    table["samples"] = table["samples"].astype("Int64")
    table["beats_baselines"] = table["beats_baselines"].astype("boolean")
    csv_path, parquet_path = result_paths(out, kind)
    _atomic(csv_path, lambda p: table.to_csv(p, index=False))
    _atomic(parquet_path, lambda p: table.to_parquet(p, index=False))
    return table


def _atomic(path: Path, write: Callable[[str], Any]) -> None:
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    os.close(fd)
    try:
        write(tmp)
        os.replace(tmp, path)
    finally:
        if os.path.exists(tmp):
            os.remove(tmp)


# --------------------------------------------------------------------------- the fleet
def run_fleet(source: str | os.PathLike[str] | Sequence[Job], out: str | os.PathLike[str],
              kind: str = "identify", *, settings: dict[str, Any] | None = None,
              client: Any | None = None, workers: int | None = None,
              scheduler: str | None = None, force: bool = False, retry_failed: bool = False,
              seed: int = 0, progress: bool = True, write_every: float = 2.0):
    """Identify or diagnose every record of a fleet on Dask; write one result row per record.

    Parameters
    ----------
    source : str, os.PathLike or sequence of Job
        Records: see :func:`find_jobs`.
    out : str or os.PathLike
        Folder of the results ``<kind>.csv`` and ``<kind>.parquet`` (created if needed).
    kind : {'identify', 'diagnose'}
        What to do with each record (see :func:`run_job`).
    settings : dict, optional
        Passed to :func:`run_job` (``method``, ``holdout``, ``fs``, ``columns``...).
    client : distributed.Client, optional
        A client to use; otherwise one is made by :func:`fleet_client`.
    workers : int, optional
        Worker processes of the local cluster.
    scheduler : str, optional
        Address of an existing scheduler.
    force : bool
        Recompute records that already have a result row.
    retry_failed : bool
        Recompute the records whose row says ``failed`` (the others are kept).
    seed : int
        Root seed; each record gets its own seed from it and its name.
    progress : bool
        A progress line on stderr every few seconds.
    write_every : float
        Seconds between rewrites of the result files while the run goes on.

    Returns
    -------
    pandas.DataFrame
        The whole table (earlier rows kept and new rows), sorted by name.

    Raises
    ------
    FleetError
        Bad source or output folder, unknown kind, or a cluster that cannot be reached.
    """
    if kind not in KINDS:
        raise FleetError(f"kind: expected one of {', '.join(KINDS)}, got {kind!r}")
    settings = dict(settings or {})
    jobs = list(source) if _is_job_list(source) else find_jobs(source)
    out = Path(out)
    if out.exists() and not out.is_dir():
        raise FleetError(f"--out {out}: exists and is not a folder")
    out.mkdir(parents=True, exist_ok=True)
    with contextlib.ExitStack() as stack:
        try:  # a second run writing into the same folder fails instead of overwriting
            stack.enter_context(folder_lock(out, "--out"))
        except OutputError as err:
            raise FleetError(str(err)) from err
        rows = _previous_rows(out, kind)
        prints = {j.name: fingerprint(j, kind, settings) for j in jobs}
        todo = [j for j in jobs if force or not _is_done(rows.get(j.name), prints[j.name],
                                                          retry_failed)]
        tick = _Ticker(len(todo), f"{kind} ({len(jobs) - len(todo)} of {len(jobs)} already done)",
                       progress)
        if not todo:
            tick(0, force=True)
            return _write_results(list(rows.values()), out, kind)
        with _client_or(client, workers, scheduler) as cl:
            futures = {cl.submit(run_job, j, kind, settings, _job_seed(seed, j.name), pure=False,
                                 key=f"hystid-{kind}-{_job_seed(seed, j.name):x}-{i}"): j
                       for i, j in enumerate(todo)}
            return _collect(futures, rows, prints, out, kind, tick, write_every)


def _is_job_list(source: Any) -> bool:
    return isinstance(source, list | tuple) and all(isinstance(j, Job) for j in source)


def _previous_rows(out: Path, kind: str) -> dict[str, dict[str, Any]]:
    table = read_results(out, kind)
    if table is None:
        return {}
    records = table.astype(object).where(table.notna(), None).to_dict("records")
    return {str(r["name"]): r for r in records}


def _is_done(row: dict[str, Any] | None, fp: str, retry_failed: bool) -> bool:
    if row is None or str(row.get("fingerprint")) != fp:
        return False
    return not (retry_failed and row.get("status") != "ok")


def _job_seed(seed: int, name: str) -> int:
    return int(np.random.SeedSequence([int(seed), zlib.crc32(name.encode())])
               .generate_state(1)[0])


def _collect(futures: dict[Any, Job], rows: dict[str, dict[str, Any]], prints: dict[str, str],
             out: Path, kind: str, tick: _Ticker, write_every: float):
    from distributed import as_completed

    done = failed = 0
    last_write = time.perf_counter()
    try:
        for future in as_completed(futures):
            job = futures[future]
            try:
                row = future.result()
            except Exception as err:  # noqa: BLE001 - a lost worker fails this record only
                row = {"name": job.name, "train": job.train, "val": ";".join(job.val),
                       "status": "failed", "error": f"task lost: {type(err).__name__}: {err}"}
            row["fingerprint"] = prints[job.name]
            rows[job.name] = row
            done += 1
            failed += row["status"] != "ok"
            future.release()
            tick(done, failed)
            if time.perf_counter() - last_write >= write_every:
                _write_results(list(rows.values()), out, kind)
                last_write = time.perf_counter()
    finally:  # an interrupted run keeps what it has done: the next one resumes from there
        table = _write_results(list(rows.values()), out, kind)
    return table


# --------------------------------------------------------------------------- Monte Carlo
@dataclass
class FailedSeed:
    """The place of a seed whose run raised (with ``errors='keep'`` in :func:`map_seeds`).

    Attributes
    ----------
    seed : Any
        The seed.
    error : str
        The exception's type and message.
    """

    seed: Any
    error: str = field(default="")


def spawn_seeds(seed: int, n: int) -> list[int]:
    """``n`` independent seeds drawn from one root seed (:class:`numpy.random.SeedSequence`).

    Parameters
    ----------
    seed : int
        Root seed.
    n : int
        How many.

    Returns
    -------
    list of int
    """
    return [int(s.generate_state(1)[0]) for s in np.random.SeedSequence(seed).spawn(n)]


def map_seeds(fn: Callable[..., Any], seeds: Sequence[Any], *args: Any,
              client: Any | None = None, workers: int | None = None,
              scheduler: str | None = None, errors: str = "raise", progress: bool = False,
              **kwargs: Any) -> list[Any]:
    """``[fn(seed, *args, **kwargs) for seed in seeds]``, each call a task on the cluster.

    Parameters
    ----------
    fn : callable
        Takes a seed first; it must be picklable (a module-level function or a
        :func:`functools.partial` of one) and draw every random figure from that seed.
    seeds : sequence
        One call per item (ints, or any picklable case description).
    *args, **kwargs
        Passed to every call.
    client : distributed.Client, optional
        A client to use; otherwise a local cluster (or ``scheduler``) for this call.
    workers : int, optional
        Worker processes of that local cluster.
    scheduler : str, optional
        Address of an existing scheduler.
    errors : {'raise', 'keep'}
        ``raise``: the first failing call's exception is raised; ``keep``: its place in the
        list holds a :class:`FailedSeed` and the others go on.
    progress : bool
        A progress line on stderr every few seconds.

    Returns
    -------
    list
        The results, in the order of ``seeds``.
    """
    if errors not in ("raise", "keep"):
        raise ValueError(f"errors: expected 'raise' or 'keep', got {errors!r}")
    seeds = list(seeds)
    if not seeds:
        return []
    tick = _Ticker(len(seeds), getattr(fn, "__name__", "map_seeds"), progress)
    with _client_or(client, workers, scheduler) as cl:
        from distributed import as_completed

        futures = {cl.submit(fn, s, *args, pure=False, **kwargs): i for i, s in enumerate(seeds)}
        results: list[Any] = [None] * len(seeds)
        done = failed = 0
        for future in as_completed(futures):
            i = futures[future]
            try:
                results[i] = future.result()
            except Exception as err:
                if errors == "raise":
                    for f in futures:
                        f.cancel()
                    raise
                results[i] = FailedSeed(seeds[i], f"{type(err).__name__}: {err}")
                failed += 1
            done += 1
            tick(done, failed)
    return results
