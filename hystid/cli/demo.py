"""``hystid demo``: the main job on the built-in reference stage.

``hystid demo [--out DIR] [--seconds S] [--seed N] [--noise SD]`` makes a record of the
reference stage (the paper's eqs. 26-28 at 30 kHz), identifies it with the batch fit and the
on-line estimators, validates each on a second record, prints their parameters and figures
against the truth and writes the report (``report.json``, ``model.json`` and the figures) to
``--out``.
"""

from __future__ import annotations

import argparse
import time
import warnings
from pathlib import Path

import numpy as np

from ..options import MAX_SECONDS
from .identify import REPORT_FILES, write_outputs
from .support import (
    Progress,
    bind,
    check_out,
    check_seconds,
    file_arg,
    kernels_cached,
    non_negative_arg,
    run_command,
    seconds_arg,
    seed_arg,
    table,
)

__all__ = ["configure_parser", "run"]


def configure_parser(parser: argparse.ArgumentParser) -> None:
    """Add the arguments of ``hystid demo`` to ``parser``.

    Parameters
    ----------
    parser : argparse.ArgumentParser
        The command's parser.
    """
    parser.description = ("Make a record from the built-in reference stage (the paper's eqs. "
                          "26-28 at 30 kHz), identify it, validate on a second record and write "
                          "a short report (JSON + PNG).")
    p = parser
    p.add_argument("--out", type=file_arg, default="hystid-demo",
                   help="report folder (default: hystid-demo)")
    p.add_argument("--force", action="store_true", help="replace files already in --out")
    p.add_argument("--seconds", type=seconds_arg, default=1.0,
                   help=f"length of each record in seconds (default 1.0, at most {MAX_SECONDS:g})")
    p.add_argument("--seed", type=seed_arg, default=0, help="random seed (default 0)")
    p.add_argument("--noise", type=non_negative_arg, default=1e-3,
                   help="sensor noise standard deviation in um (default 0.001 = 1 nm)")
    p.add_argument("--quiet", action="store_true", help="no progress lines")
    bind(parser, run)


def run(args: argparse.Namespace) -> int:
    """Run ``hystid demo``.

    Parameters
    ----------
    args : argparse.Namespace
        Parsed arguments (see :func:`configure_parser`).

    Returns
    -------
    int
        0 on success, 2 on bad input or a failed write.
    """
    return run_command(args, _demo)


def _demo(args: argparse.Namespace) -> None:
    """``hystid demo``'s steps (see :func:`run`)."""
    from ..identify import METHODS, identify, min_samples
    from ..metrics import validate
    from ..reference import PAPER_PARAMS, reference_model, reference_record

    progress = Progress(args.quiet)
    check_out(args, args.out, REPORT_FILES)
    check_seconds(args.seconds, max(min_samples(m) for m in METHODS), 30_000.0)
    truth = reference_model()
    train = reference_record(args.seconds, seed=args.seed, noise=args.noise, name="demo train")
    val = reference_record(args.seconds, seed=args.seed + 1, noise=args.noise, name="demo val")
    progress.say(f"reference stage: {train.n} samples at {train.fs:g} Hz, "
                 f"noise {args.noise * 1e3:g} nm; identifying")
    if not kernels_cached():
        progress.say("compiling the numba kernels: once, about a minute; later runs load them "
                     "from numba's cache")
    methods = [m for m in ("batch", "online", "eria") if m in METHODS]
    rows, results, report = [], {}, {"truth": PAPER_PARAMS, "methods": {}}
    out = Path(args.out)
    for method in methods:
        t0 = time.perf_counter()
        settings = {} if method == "batch" else {"progress": progress}
        with warnings.catch_warnings():  # ERIA's restarts are counted in the table instead
            warnings.simplefilter("ignore", RuntimeWarning)
            result = identify(train, method=method, model="duhem", **settings)
        elapsed = time.perf_counter() - t0
        yhat = result.model.simulate(val.u).y
        v = validate(val.y, yhat, val.fs)
        err = {k: abs(result.params[k] - PAPER_PARAMS[k]) / abs(PAPER_PARAMS[k])
               for k in PAPER_PARAMS}
        report["methods"][method] = {
            "params": result.params, "validation": v.to_dict(), "seconds": elapsed,
            "max_rel_error": max(err.values()), "converged_at": result.converged_at,
        }
        rows.append([method, f"{100 * max(err.values()):.3g} %",
                     str(result.converged_at if result.history is not None else "-"),
                     str(result.info.get("n_recoveries", 0)),
                     f"{v.err_min * 1e3:.1f} .. {v.err_max * 1e3:.1f}", f"{v.rms * 1e3:.2f}",
                     f"{v.fit_percent:.2f}", f"{elapsed:.2f}"])
        results[method] = (result, yhat)
        progress.say(f"{method}: done in {elapsed:.2f} s")
    params = [[k, f"{v:.6g}"] + [f"{report['methods'][m]['params'][k]:.6g}" for m in methods]
              for k, v in PAPER_PARAMS.items()]
    print(table(params, ["parameter", "truth", *methods]))
    print()
    print(table(rows, ["method", "max param err", "converged at", "restarts",
                       "val error [nm]", "RMS [nm]", "fit %", "time [s]"]))
    print("batch: off-line output error; online: hystid's recursive identifier; eria: the "
          "paper's recursion as published (see README, method)")
    result, yhat = results.get("online", results["batch"])
    report["validation_of"] = result.method
    report["truth_simulated_rms_um"] = float(np.sqrt(np.mean((truth.simulate(val.u).y
                                                               - val.y) ** 2)))
    from ..modelfile import make_provenance

    report["noise_um"] = args.noise
    write_outputs(out, {"model": "duhem", "method": result.method,
                        "validation": report["methods"][result.method]["validation"],
                        **report}, val, yhat, result, truth=PAPER_PARAMS,
                  provenance=make_provenance(result.method, settings=result.settings),
                  seed=args.seed)
    print(f"\nreport written to {out}/report.json, model to {out}/model.json (figures: "
          "validation.png"
          f"{', convergence.png' if result.history is not None else ''})")
