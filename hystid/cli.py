"""The ``hystid`` command line: demo, simulate, identify, diagnose."""

from __future__ import annotations

import argparse
import json
import sys
import time
import warnings
from pathlib import Path

import numpy as np

from . import __version__

EXIT_BAD_INPUT = 2


class CommandError(Exception):
    """A user-facing error: printed without a traceback, exit status 2."""


class Progress:
    """Periodic progress lines on stderr (silent when ``quiet``)."""

    def __init__(self, quiet: bool = False, every: float = 1.0):
        self.quiet = quiet
        self.every = every
        self._last = 0.0
        self._t0 = time.perf_counter()

    def say(self, message: str) -> None:
        """Print one line now."""
        if not self.quiet:
            print(f"[{time.perf_counter() - self._t0:6.1f} s] {message}", file=sys.stderr)

    def __call__(self, k: int, n: int) -> None:
        """Print ``k/n`` at most once per ``every`` seconds (and at the end)."""
        now = time.perf_counter()
        if k >= n or now - self._last >= self.every:
            self._last = now
            self.say(f"sample {k}/{n} ({100.0 * k / max(n, 1):.0f} %)")


# --------------------------------------------------------------------------- helpers
def _load(path: str, fs: float | None, columns: dict | None = None):
    from .records import RecordError, load_record

    try:
        return load_record(path, fs=fs, columns=columns)
    except RecordError as err:
        raise CommandError(str(err)) from err


def _columns_arg(text: str) -> dict:
    from .records import parse_columns

    try:
        return parse_columns(text)
    except ValueError as err:
        raise argparse.ArgumentTypeError(str(err)) from err


def _positive(kind):
    def parse(text: str):
        try:
            value = kind(text)
        except ValueError as err:
            raise argparse.ArgumentTypeError(f"expected a {kind.__name__}, got {text!r}") from err
        if not value > 0:
            raise argparse.ArgumentTypeError(f"expected a positive number, got {text!r}")
        return value

    return parse


def _non_negative_float(text: str) -> float:
    try:
        value = float(text)
    except ValueError as err:
        raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from err
    if not (np.isfinite(value) and value >= 0):
        raise argparse.ArgumentTypeError(f"expected a non-negative number, got {text!r}")
    return value


def _table(rows: list[list[str]], header: list[str]) -> str:
    widths = [max(len(str(r[i])) for r in [header, *rows]) for i in range(len(header))]
    line = "  ".join(h.ljust(w) for h, w in zip(header, widths, strict=True))
    out = [line, "  ".join("-" * w for w in widths)]
    out += ["  ".join(str(c).ljust(w) for c, w in zip(r, widths, strict=True)) for r in rows]
    return "\n".join(out)


def _identify_record(rec, args, progress: Progress):
    """Run the chosen model/method on a record; returns (result, simulate function)."""
    from .identify import identify

    model_kind = getattr(args, "model", "duhem")
    if model_kind == "pi":
        from .identify.pi_recursive import identify_pi

        method = "recursive" if args.method in (None, "online", "eria") else args.method
        return identify_pi(rec, method=method)
    method = args.method or "batch"
    settings = {"progress": progress} if method != "batch" else {}
    return identify(rec, method=method, **settings)


def _report(result, rec, val, args) -> dict:
    from .metrics import validate

    target = val if val is not None else rec
    yhat = result.model.simulate(target.u).y
    validation = validate(target.y, yhat, target.fs)
    return {
        "model": getattr(args, "model", "duhem"),
        "method": result.method,
        "params": result.params,
        "validation": validation.to_dict(),
        "validated_on": "validation record" if val is not None else "identification record",
        "converged_at": result.converged_at,
        "settings": {k: v for k, v in result.settings.items() if _jsonable(v)},
        "record": {"name": rec.name, "samples": rec.n, "fs": rec.fs},
        "info": {k: v for k, v in result.info.items() if _jsonable(v)},
    }, yhat, target


def _jsonable(value) -> bool:
    try:
        json.dumps(value)
    except TypeError:
        return False
    return True


def _write_history(path: str, result) -> None:
    if result.history is None:
        raise CommandError(f"--history: method {result.method!r} keeps no parameter history")
    names = list(result.names)
    k = np.arange(1, len(result.history) + 1)
    data = np.column_stack([k, result.history])
    np.savetxt(path, data, delimiter=",", header=",".join(["k", *names]), comments="",
               fmt=["%d"] + ["%.10g"] * len(names))


# --------------------------------------------------------------------------- commands
def cmd_simulate(args: argparse.Namespace) -> int:
    """``hystid simulate``: a record from the built-in reference stage."""
    from .reference import reference_record

    progress = Progress(args.quiet)
    rec = reference_record(args.seconds, seed=args.seed, noise=args.noise,
                           name=f"reference stage seed {args.seed}")
    out = Path(args.out)
    if out.suffix.lower() not in (".csv", ".npz", ".mat", ".h5", ".hdf5"):
        raise CommandError(f"--out {out}: expected a .csv, .npz, .mat, .h5 or .hdf5 file name")
    rec.save(out)
    progress.say(f"wrote {out}: {rec.n} samples at {rec.fs:g} Hz, y in "
                 f"[{rec.y.min():.3f}, {rec.y.max():.3f}] um")
    return 0


def cmd_identify(args: argparse.Namespace) -> int:
    """``hystid identify``: identify a record, validate, print or write JSON."""
    progress = Progress(args.quiet or args.json)
    rec = _load(args.record, args.fs, args.columns)
    val = _load(args.val, args.fs, args.columns) if args.val else None
    if val is not None and not np.isclose(val.fs, rec.fs, rtol=1e-9):
        raise CommandError(f"--val {args.val}: fs {val.fs:g} Hz differs from {rec.fs:g} Hz "
                           f"of {args.record}")
    progress.say(f"identifying {args.record}: {rec.n} samples at {rec.fs:g} Hz")
    try:
        result = _identify_record(rec, args, progress)
        report, yhat, target = _report(result, rec, val, args)
    except ValueError as err:
        raise CommandError(str(err)) from err
    if args.history:
        _write_history(args.history, result)
    if args.out:
        _write_outputs(Path(args.out), report, target, yhat, result)
    if args.json:
        print(json.dumps(report, indent=2))
    else:
        rows = [[k, f"{v:.6g}"] for k, v in report["params"].items()]
        print(_table(rows, ["parameter", "estimate"]))
        v = report["validation"]
        print(f"\nvalidation ({report['validated_on']}): error {v['err_min']:.4g} .. "
              f"{v['err_max']:.4g}, RMS {v['rms']:.4g}, fit {v['fit_percent']:.2f} %")
        if report["converged_at"] is not None:
            print(f"converged at sample {report['converged_at']}")
    return 0


def _write_outputs(out: Path, report: dict, target, yhat, result, truth=None) -> None:
    from .metrics import plot_validation

    out.mkdir(parents=True, exist_ok=True)
    (out / "report.json").write_text(json.dumps(report, indent=2))
    plot_validation(target.t, target.y, yhat, out / "validation.png",
                    title=f"{report['model']} sandwich, {report['method']}: validation",
                    unit=target.units.get("y", ""), skip=report["validation"]["skip"])
    if result.history is not None:
        import matplotlib.pyplot as plt

        axes = result.plot(truth=truth)
        axes[0].figure.tight_layout()
        axes[0].figure.savefig(out / "convergence.png", dpi=110)
        plt.close(axes[0].figure)


def cmd_demo(args: argparse.Namespace) -> int:
    """``hystid demo``: the main job on the built-in reference stage."""
    from .identify import METHODS, identify
    from .metrics import validate
    from .reference import PAPER_PARAMS, reference_model, reference_record

    progress = Progress(args.quiet)
    truth = reference_model()
    train = reference_record(args.seconds, seed=args.seed, noise=args.noise, name="demo train")
    val = reference_record(args.seconds, seed=args.seed + 1, noise=args.noise, name="demo val")
    progress.say(f"reference stage: {train.n} samples at {train.fs:g} Hz, "
                 f"noise {args.noise * 1e3:g} nm; identifying")
    methods = [m for m in ("batch", "online", "eria") if m in METHODS]
    rows, results, report = [], {}, {"truth": PAPER_PARAMS, "methods": {}}
    out = Path(args.out)
    for method in methods:
        t0 = time.perf_counter()
        settings = {} if method == "batch" else {"progress": progress}
        with warnings.catch_warnings():  # ERIA's restarts are counted in the table instead
            warnings.simplefilter("ignore", RuntimeWarning)
            result = identify(train, method=method, **settings)
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
    print(_table(params, ["parameter", "truth", *methods]))
    print()
    print(_table(rows, ["method", "max param err", "converged at", "restarts",
                        "val error [nm]", "RMS [nm]", "fit %", "time [s]"]))
    print("batch: off-line output error; online: hystid's recursive identifier; eria: the "
          "paper's recursion as published (see README, method)")
    result, yhat = results.get("online", results["batch"])
    report["validation_of"] = result.method
    report["truth_simulated_rms_um"] = float(np.sqrt(np.mean((truth.simulate(val.u).y
                                                               - val.y) ** 2)))
    _write_outputs(out, {"model": "duhem", "method": result.method,
                         "validation": report["methods"][result.method]["validation"],
                         **report}, val, yhat, result, truth=PAPER_PARAMS)
    print(f"\nreport written to {out}/report.json (figures: validation.png"
          f"{', convergence.png' if result.history is not None else ''})")
    return 0


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of the ``hystid`` command."""
    parser = argparse.ArgumentParser(
        prog="hystid",
        description="Identify piezo-driven positioning stages (L1-Duhem-L2 sandwich).",
    )
    parser.add_argument("--version", action="version", version=f"hystid {__version__}")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")

    p = sub.add_parser("demo", help="identify the built-in reference stage and report",
                       description="Make a record from the built-in reference stage (the paper's "
                       "eqs. 26-28 at 30 kHz), identify it, validate on a second record and write "
                       "a short report (JSON + PNG).")
    p.add_argument("--out", default="hystid-demo", help="report folder (default: hystid-demo)")
    p.add_argument("--seconds", type=_positive(float), default=1.0,
                   help="length of each record in seconds (default 1.0)")
    p.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
    p.add_argument("--noise", type=_non_negative_float, default=1e-3,
                   help="sensor noise standard deviation in um (default 0.001 = 1 nm)")
    p.add_argument("--quiet", action="store_true", help="no progress lines")
    p.set_defaults(func=cmd_demo)

    p = sub.add_parser("simulate", help="write a record from the reference stage",
                       description="Simulate the reference stage with the paper's excitation "
                       "(starting at rest) and write the record (u in V, y in um).")
    p.add_argument("--seconds", type=_positive(float), required=True, help="record length [s]")
    p.add_argument("--seed", type=int, required=True, help="random seed")
    p.add_argument("--noise", type=_non_negative_float, default=1e-3,
                   help="sensor noise standard deviation in um (default 0.001)")
    p.add_argument("--out", required=True, help="output file (.csv, .npz, .mat, .h5)")
    p.add_argument("--quiet", action="store_true", help="no progress lines")
    p.set_defaults(func=cmd_simulate)

    p = sub.add_parser("identify", help="identify a record",
                       description="Identify a sandwich model from a record (CSV with a header "
                       "naming u, y and optionally t; .npz, .mat, .h5) and validate it.")
    p.add_argument("record", help="record file")
    p.add_argument("--fs", type=_positive(float), help="sampling rate in Hz (if no t column)")
    p.add_argument("--val", help="validation record (default: validate on the record itself)")
    p.add_argument("--columns", type=_columns_arg, metavar="t=1,u=3,y=2",
                   help="where t, u and y are in the files (names or 0-based positions)")
    p.add_argument("--model", choices=("duhem", "pi"), default="duhem", help="hysteresis block")
    p.add_argument("--method", choices=("eria", "online", "ekf", "batch"), default=None,
                   help="estimator (default: batch for duhem, recursive for pi)")
    p.add_argument("--history", help="write the parameter history (CSV: k, one column a parameter)")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.add_argument("--out", help="folder for report.json and figures")
    p.add_argument("--quiet", action="store_true", help="no progress lines")
    p.set_defaults(func=cmd_identify)

    try:
        from .diagnose import command as diagnose_command
    except ImportError:
        diagnose_command = None
    if diagnose_command is not None:
        p = sub.add_parser("diagnose", help="diagnose the sim-to-real gap",
                           description="Localise the model error, screen unmodelled effects and "
                           "measure how far each closes the gap on held-out data.")
        diagnose_command.configure_parser(p)
        p.set_defaults(func=diagnose_command.run)

    from . import fleet_command

    p = sub.add_parser("fleet", help="identify or diagnose many records on Dask",
                       description="Identify or diagnose many records as Dask tasks; one result "
                       "row per record (CSV and Parquet), resumable.")
    fleet_command.configure_parser(p)
    p.set_defaults(func=fleet_command.run)
    return parser


def main(argv: list[str] | None = None) -> int:
    """Entry point of the ``hystid`` command; returns the exit status."""
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return int(args.func(args) or 0)
    except CommandError as err:
        print(f"hystid {args.command}: error: {err}", file=sys.stderr)
        return EXIT_BAD_INPUT
    except KeyboardInterrupt:
        return 130


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
