"""``hystid fleet``: identify or diagnose many records as Dask tasks.

``hystid fleet identify SOURCE --out DIR [--workers N | --scheduler tcp://HOST:PORT] [--force]
[--method M]`` and ``hystid fleet diagnose SOURCE --out DIR ...``. SOURCE is a glob pattern
(quote it), a folder or a CSV table with ``train`` and ``val`` columns. The results are
``DIR/identify.csv`` and ``DIR/identify.parquet`` (``diagnose.*`` likewise), one row per record;
records that already have a row are skipped unless ``--force``. Bad input (no records, a
malformed table, results in DIR that are not a fleet's, an unreachable scheduler) gives a message
on stderr and exit status 2; failed records are rows with their reason, and the exit status is 1
when any record failed.
"""

from __future__ import annotations

import argparse

from ..errors import FleetError
from .identify import MODEL_NAMES
from .support import bind, columns_arg, refused, run_command, seed_arg

__all__ = ["EXIT_SOME_FAILED", "configure_parser", "run"]

#: Exit status when some record failed (its row says why).
EXIT_SOME_FAILED = 1


def _positive_int(text: str) -> int:
    try:
        value = int(text)
    except ValueError as err:
        raise argparse.ArgumentTypeError(f"expected a whole number, got {text!r}") from err
    if value < 1:
        raise argparse.ArgumentTypeError(f"expected at least 1, got {text!r}")
    return value


def _workers(text: str) -> int:
    from ..fleet import WORKERS_PER_CORE, max_local_workers

    value = _positive_int(text)
    if value > max_local_workers():
        raise argparse.ArgumentTypeError(
            f"expected at most {max_local_workers()} ({WORKERS_PER_CORE} worker processes a "
            f"core of this machine; for more, start workers elsewhere and give --scheduler), "
            f"got {text!r}")
    return value


def _fraction(text: str) -> float:
    try:
        value = float(text)
    except ValueError as err:
        raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from err
    if not 0 < value < 1:
        raise argparse.ArgumentTypeError(f"expected a fraction in (0, 1), got {text!r}")
    return value


def _positive_float(text: str) -> float:
    try:
        value = float(text)
    except ValueError as err:
        raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from err
    if not (value > 0 and value < float("inf")):
        raise argparse.ArgumentTypeError(f"expected a positive finite number, got {text!r}")
    return value


def _scheduler(text: str) -> str:
    if "://" not in text:
        raise argparse.ArgumentTypeError(f"expected an address like tcp://HOST:PORT, got {text!r}")
    return text


def _common(p: argparse.ArgumentParser) -> None:
    p.add_argument("source", metavar="SOURCE",
                   help="records: a glob pattern (quote it), a folder, or a CSV table with "
                   "columns train, val (';' between several held-out records) and optionally name")
    p.add_argument("--out", required=True, metavar="DIR",
                   help="folder of the result table (<kind>.csv and <kind>.parquet)")
    where = p.add_mutually_exclusive_group()
    where.add_argument("--workers", type=_workers, default=None, metavar="N",
                       help="worker processes of the local cluster (default: the machine's cores)")
    where.add_argument("--scheduler", type=_scheduler, default=None, metavar="tcp://HOST:PORT",
                       help="use a running Dask scheduler; its workers must see the records' "
                       "paths and import hystid")
    p.add_argument("--force", action="store_true",
                   help="recompute records that already have a result row")
    p.add_argument("--retry-failed", action="store_true",
                   help="recompute the records whose row says failed")
    p.add_argument("--holdout", type=_fraction, default=0.4,
                   help="share of a record held out when it has no val record (default 0.4)")
    p.add_argument("--fs", type=_positive_float, default=None,
                   help="sampling rate in Hz (for files without a time vector or fs)")
    p.add_argument("--columns", type=columns_arg, default=None, metavar="t=1,u=3,y=2",
                   help="where t, u and y are in the files (names or 0-based positions)")
    p.add_argument("--seed", type=seed_arg, default=0,
                   help="root seed; each record's seed is drawn from it and its name (default 0)")
    p.add_argument("--quiet", action="store_true", help="no progress lines on stderr")


def configure_parser(parser: argparse.ArgumentParser) -> None:
    """Add the ``fleet`` sub-commands (``identify``, ``diagnose``) to ``parser``.

    Parameters
    ----------
    parser : argparse.ArgumentParser
        The ``fleet`` sub-command's parser.
    """
    parser.description = ("Identify or diagnose many records as Dask tasks; one result row per "
                          "record (CSV and Parquet), resumable.")
    sub = parser.add_subparsers(dest="fleet_kind", required=True, metavar="KIND")
    p = sub.add_parser("identify", help="identify and validate every record",
                       description="Identify a member of the model family on every record "
                       "(hystid.identify.identify with --model and --method), validate it on "
                       "the held-out data against a static line and a linear model.")
    _common(p)
    p.add_argument("--method", choices=("batch", "online", "eria", "ekf"), default="batch",
                   help="estimator (default batch)")
    p.add_argument("--model", choices=("auto", *MODEL_NAMES), default=None,
                   help="member of the model family (default: as hystid identify, auto for "
                   "batch and online, chosen per record on data held out inside it; duhem, "
                   "the quickest, for eria and ekf)")
    bind(p, run)
    p = sub.add_parser("diagnose", help="diagnose the sim-to-real gap of every record",
                       description="Run the sim-to-real gap diagnosis on every record.")
    _common(p)
    p.add_argument("--effects", default=None, metavar="NAMES",
                   help="comma-separated candidate effects (default all)")
    p.add_argument("--initial", choices=("rest", "level"), default="rest",
                   help="records start at rest at zero output or at the measured level")
    bind(p, run)


def _settings(args: argparse.Namespace) -> dict:
    settings = {"holdout": args.holdout}
    if args.fs is not None:
        settings["fs"] = args.fs
    if args.columns is not None:
        settings["columns"] = args.columns
    if args.fleet_kind == "identify":
        settings["method"] = args.method
        settings["model"] = args.model
    else:
        settings["initial"] = args.initial
        if args.effects:
            from ..diagnose.screen import effect_names_check

            names = [e.strip() for e in args.effects.split(",") if e.strip()]
            with refused("--effects: "):
                effect_names_check(names)
            settings["effects"] = names
    return settings


def run(args: argparse.Namespace) -> int:
    """Run ``hystid fleet``; print a summary; return the exit status.

    Parameters
    ----------
    args : argparse.Namespace
        Parsed arguments (see :func:`configure_parser`).

    Returns
    -------
    int
        0 when every record is ok, 1 when some failed, 2 on bad input.
    """
    return run_command(args, _fleet)


def _fleet(args: argparse.Namespace) -> int:
    """``hystid fleet``'s steps (see :func:`run`)."""
    from ..fleet import result_paths, run_fleet

    with refused(errors=FleetError):
        table = run_fleet(args.source, args.out, args.fleet_kind, settings=_settings(args),
                          workers=args.workers, scheduler=args.scheduler, force=args.force,
                          retry_failed=args.retry_failed, seed=args.seed,
                          progress=not args.quiet)
    ok = table[table["status"] == "ok"]
    failed = table[table["status"] != "ok"]
    print(f"{len(table)} records: {len(ok)} ok, {len(failed)} failed")
    if len(ok):
        beats = int(ok["beats_baselines"].astype(bool).sum())
        # one median per output unit: records in metres and in micrometres do not pool
        units = ok["unit"].fillna("") if "unit" in ok else None
        groups = [("", ok)] if units is None or units.nunique() <= 1 else list(ok.groupby(units))
        for unit, rows in groups:
            shown = f" [{unit}]" if unit else ""
            print(f"held-out RMS of the model{shown}: median {rows['rms_model'].median():.4g}, "
                  f"worst {rows['rms_model'].max():.4g} over {len(rows)} records")
        print(f"beats both baselines on {beats} of {len(ok)}")
    for _, r in failed.head(10).iterrows():
        print(f"  failed {r['name']}: {r['error']}")
    if len(failed) > 10:
        print(f"  ... {len(failed) - 10} more failed rows in the table")
    csv_path, parquet_path = result_paths(args.out, args.fleet_kind)
    print(f"results: {csv_path}, {parquet_path}")
    return EXIT_SOME_FAILED if len(failed) else 0
