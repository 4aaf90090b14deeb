"""``hystid diagnose``: the sim-to-real gap diagnosis from the command line.

``hystid diagnose TRAIN [--val VAL ...] [--repeat REC ...] [--fs HZ] [--json] [--out DIR]
[--quiet]`` identifies
the nominal sandwich on TRAIN, localises its held-out error, screens and refits the candidate
effects and prints a summary (or, with ``--json``, one JSON object). Bad input (unreadable or
too-short records, mismatched sampling rates, records that cannot show a requested effect) gives
a message on stderr and exit status 2.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

__all__ = ["EXIT_BAD_INPUT", "configure_parser", "run"]

EXIT_BAD_INPUT = 2


def _fraction(text: str) -> float:
    try:
        v = float(text)
    except ValueError as err:
        raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from err
    if not 0 < v < 1:
        raise argparse.ArgumentTypeError(f"expected a fraction in (0, 1), got {text!r}")
    return v


def _positive(text: str) -> float:
    try:
        v = float(text)
    except ValueError as err:
        raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from err
    if not (np.isfinite(v) and v > 0):
        raise argparse.ArgumentTypeError(f"expected a positive number, got {text!r}")
    return v


def configure_parser(parser: argparse.ArgumentParser) -> None:
    """Add the ``diagnose`` arguments to ``parser``.

    Parameters
    ----------
    parser : argparse.ArgumentParser
        The sub-command's parser.
    """
    from .effects import EFFECT_NAMES

    parser.add_argument("train", metavar="TRAIN",
                        help="record to identify on (csv, npz, mat, h5 or file.h5:group)")
    parser.add_argument("--val", nargs="+", metavar="VAL", default=[],
                        help="held-out record(s); without them the end of TRAIN is held out")
    parser.add_argument("--fs", type=_positive, default=None,
                        help="sampling rate in Hz (for files without a time vector or fs)")
    parser.add_argument("--columns", default=None, metavar="t=1,u=3,y=2",
                        help="where t, u and y are in the files (names or 0-based positions)")
    parser.add_argument("--model", default=None, metavar="FILE.json",
                        help="diagnose this model instead of identifying one: a JSON object "
                        "with 'params' (as written by 'hystid identify --out') and optionally "
                        "'structure' (n1a, n1b, n2a, n2b, q1, q2, f0)")
    parser.add_argument("--structure", default=None, metavar="n1a=1,n2a=2,...",
                        help="structure of the identified nominal model (keys n1a, n1b, n2a, "
                        "n2b, q1, q2, f0); the paper's experimental one by default")
    parser.add_argument("--json", action="store_true", help="print one JSON object")
    parser.add_argument("--out", default=None, metavar="DIR",
                        help="write report.json, summary.txt and the figures to DIR")
    parser.add_argument("--quiet", action="store_true", help="no progress lines on stderr")
    parser.add_argument("--effects", default=None, metavar="NAMES",
                        help=f"comma-separated candidates (default all: {','.join(EFFECT_NAMES)});"
                        " a named candidate that the records cannot show is an error")
    parser.add_argument("--holdout", type=_fraction, default=0.4,
                        help="share of TRAIN held out when no --val is given (default 0.4)")
    parser.add_argument("--crop", default=None, metavar="START:STOP",
                        help="keep only this time span of every record, in seconds")
    parser.add_argument("--u-scale", type=_positive, default=1.0, metavar="K",
                        help="multiply the input by K (keeps alpha |dw1| of condition (8) "
                        "in a range the fit starts well from, e.g. 1/150 for +-150 V)")
    parser.add_argument("--train-skip", type=float, default=0.0, metavar="S",
                        help="seconds at the start of TRAIN simulated but left out of the fit's "
                        "cost (an initial transient the model cannot represent)")
    parser.add_argument("--initial", choices=("rest", "level"), default="rest",
                        help="records start at rest at zero output (rest) or at the output "
                        "level measured before the input first moves (level)")
    parser.add_argument("--alpha", type=_fraction, default=0.01,
                        help="family-wise level of the held-out test per round (default 0.01)")
    parser.add_argument("--min-reduction", type=_fraction, default=0.02,
                        help="smallest relative held-out RMS reduction worth having "
                        "(default 0.02)")
    parser.add_argument("--max-rounds", type=int, default=3,
                        help="greedy rounds at most (default 3)")
    parser.add_argument("--refit-all", action="store_true",
                        help="refit every excited candidate, not only the promising ones")
    parser.add_argument("--repeat", nargs="+", metavar="REC", default=[],
                        help="records of the same input as TRAIN or a --val record: the gap is "
                        "then measured against their repeatability when it is above the "
                        "sensor noise")
    parser.add_argument("--time-budget", type=_positive, default=None, metavar="S",
                        help="seconds for refitting further forms once every family the "
                        "screen cannot rule out has had its best form refitted (default: no "
                        "limit)")


class _BadInput(Exception):
    pass


def _columns(text: str | None) -> dict | None:
    from ..records import parse_columns

    if text is None:
        return None
    try:
        return parse_columns(text)
    except ValueError as err:
        raise _BadInput(f"--columns: {err}") from err


def _crop(text: str | None, rec, label: str):
    if text is None:
        return rec
    try:
        a, b = text.split(":")
        start = float(a) if a.strip() else 0.0
        stop = float(b) if b.strip() else rec.duration
    except ValueError as err:
        raise _BadInput(f"--crop: expected START:STOP in seconds, got {text!r}") from err
    i, j = int(round(start * rec.fs)), int(round(stop * rec.fs))
    if not 0 <= i < j <= rec.n:
        raise _BadInput(f"--crop {text}: {label} {rec.name!r} covers 0..{rec.duration:g} s "
                        f"(expected 0 <= START < STOP within it)")
    return rec[i:j]


def _load(path: str, args, label: str):
    from ..records import Record, RecordError, load_record

    try:
        rec = load_record(path, fs=args.fs, columns=_columns(args.columns))
    except RecordError as err:
        raise _BadInput(str(err)) from err
    rec = _crop(args.crop, rec, label)
    if args.u_scale != 1.0:
        units = dict(rec.units)
        units["u"] = f"{args.u_scale:g} {units.get('u', '')}".strip()
        rec = Record(rec.u * args.u_scale, rec.y, rec.fs, units, rec.name)
    return rec


def _model(path: str | None, fs: float):
    if path is None:
        return None
    from ..model import DuhemSandwich, Structure

    try:
        data = json.loads(Path(path).read_text())
    except (OSError, ValueError) as err:
        raise _BadInput(f"--model {path}: cannot read a JSON object ({err})") from err
    if not isinstance(data, dict) or not isinstance(data.get("params"), dict):
        raise _BadInput(f"--model {path}: expected a JSON object with a 'params' mapping")
    params = data["params"]
    if "structure" in data:
        try:
            structure = Structure(**data["structure"])
        except (TypeError, ValueError) as err:
            raise _BadInput(f"--model {path}: bad 'structure': {err}") from err
    else:
        count = {k: sum(1 for n in params if n.startswith(k) and n[2:].isdigit())
                 for k in ("a1", "b1", "a2", "b2")}
        structure = Structure(count["a1"], count["b1"], count["a2"], count["b2"],
                              f0="f0" in params)
    try:
        return DuhemSandwich(params, structure, fs=fs, name=f"model from {Path(path).name}")
    except ValueError as err:
        raise _BadInput(f"--model {path}: {err}") from err


def _structure(text: str | None):
    if text is None:
        return None
    from ..model import Structure

    values: dict[str, int] = {}
    for part in text.split(","):
        key, _, val = part.partition("=")
        try:
            values[key.strip()] = int(val)
        except ValueError as err:
            raise _BadInput(f"--structure: expected key=integer pairs, got {part!r}") from err
    try:
        return Structure(**{k: (bool(v) if k == "f0" else v) for k, v in values.items()})
    except (TypeError, ValueError) as err:
        raise _BadInput(f"--structure: {err}") from err


def run(args: argparse.Namespace) -> int:
    """Run ``hystid diagnose``; returns the exit status (2 for bad input).

    Parameters
    ----------
    args : argparse.Namespace
        Parsed arguments (see :func:`configure_parser`).
    """
    from .diagnosis import DiagnosisError, diagnose
    from .effects import EFFECT_NAMES

    try:
        train = _load(args.train, args, "TRAIN")
        vals = [_load(p, args, f"--val {p}") for p in args.val]
        repeats = [_load(p, args, f"--repeat {p}") for p in args.repeat]
        if args.effects is None:
            names, strict = EFFECT_NAMES, False
        else:
            names = tuple(n.strip() for n in args.effects.split(",") if n.strip())
            strict = True
        if args.max_rounds < 1:
            raise _BadInput(f"--max-rounds: expected a positive integer, got {args.max_rounds}")
        model = _model(args.model, train.fs)
        result = diagnose(
            train, vals, model, structure=_structure(args.structure), effects=names,
            holdout=args.holdout, alpha=args.alpha,
            min_reduction=args.min_reduction, max_rounds=args.max_rounds,
            train_skip=args.train_skip, initial=args.initial, refit_all=args.refit_all,
            repeats=repeats, time_budget=args.time_budget,
            require_excitation=strict, progress=not args.quiet,
        )
    except (_BadInput, DiagnosisError) as err:
        print(f"hystid diagnose: error: {err}", file=sys.stderr)
        return EXIT_BAD_INPUT
    report = result.to_dict()
    report["records"] = {"train": train.name, "val": [v.name for v in vals],
                         "repeat": [r.name for r in repeats],
                         "units": train.units, "u_scale": args.u_scale, "crop": args.crop}
    if args.out:
        out = Path(args.out)
        try:
            out.mkdir(parents=True, exist_ok=True)
        except OSError as err:
            print(f"hystid diagnose: error: --out {out}: {err}", file=sys.stderr)
            return EXIT_BAD_INPUT
        (out / "report.json").write_text(json.dumps(report, indent=2))
        (out / "summary.txt").write_text(result.summary() + "\n")
        result.plot(out)
    if args.json:
        print(json.dumps(report, indent=2))
    else:
        print(result.summary())
        if args.out:
            print(f"\nfigures and report written to {args.out}")
    return 0
