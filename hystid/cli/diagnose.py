"""``hystid diagnose``: the sim-to-real gap diagnosis from the command line.

``hystid diagnose TRAIN [--val VAL ...] [--repeat REC ...] [--fs HZ] [--model MODEL.json]
[--json] [--out DIR] [--force] [--quiet]`` identifies the nominal sandwich on TRAIN (or takes the
saved model given with ``--model``), localises its held-out error, screens and refits the
candidate effects and prints a summary (or, with ``--json``, one JSON object). Bad input
(unreadable or too-short records, mismatched sampling rates, records that cannot show a
requested effect, an output folder that would overwrite files) gives a message on stderr and
exit status 2 before any work.
"""

from __future__ import annotations

import argparse
import json
import warnings
from pathlib import Path
from typing import TYPE_CHECKING, Any

from ..errors import DiagnosisError, OptionError, RecordError
from ..options import crop, fraction, integer, number, parse_crop, parse_structure
from .support import (
    CommandError,
    as_option,
    bind,
    check_model_on,
    check_out,
    positive_arg,
    refused,
    remember,
    run_command,
    tell,
)

if TYPE_CHECKING:  # pragma: no cover
    from ..diagnose.final_model import FinalModel
    from ..diagnose.result import DiagnosisResult
    from ..model import Structure
    from ..records import Record

__all__ = ["OUTPUT_FILES", "configure_parser", "run"]

#: Files ``--out`` receives.
OUTPUT_FILES = ("report.json", "summary.txt", "model.json", "error_time.png", "spectrum.png",
                "branch.png", "gap.png", "correlation.png")

def configure_parser(parser: argparse.ArgumentParser) -> None:
    """Add the ``diagnose`` arguments to ``parser``.

    Parameters
    ----------
    parser : argparse.ArgumentParser
        The sub-command's parser.
    """
    from ..diagnose.diagnosis import DEFAULT_EFFECTS
    from ..diagnose.effects import FAMILIES

    parser.description = ("Localise the model error, screen unmodelled effects and measure how "
                          "far each closes the gap on held-out data.")
    parser.add_argument("train", metavar="TRAIN",
                        help="record to identify on (csv, npz, mat, h5 or file.h5:group)")
    parser.add_argument("--val", nargs="+", metavar="VAL", default=[],
                        help="held-out record(s); without them the end of TRAIN is held out")
    parser.add_argument("--fs", type=positive_arg(float), default=None,
                        help="sampling rate in Hz (for files without a time vector or fs)")
    parser.add_argument("--columns", default=None, metavar="t=1,u=3,y=2",
                        help="where t, u and y are in the files (names or 0-based positions)")
    parser.add_argument("--units", default=None, metavar="u=V,y=um",
                        help="units of the input and output, e.g. u=N,y=m (default: those "
                        "stored in the files, else V and um)")
    parser.add_argument("--model", default=None, metavar="MODEL.json",
                        help="diagnose this saved model instead of identifying one (the "
                        "model.json written by 'hystid identify --out'; an older report.json "
                        "with 'params' and 'structure' is read too); a model of another member "
                        "than the Duhem sandwich (e.g. pi-stage) is scored beside the "
                        "diagnosed Duhem sandwich and the members in the final table")
    parser.add_argument("--members", default=None, metavar="pi-stage,pi-poly",
                        help="members of the model family tried as the hysteresis itself in "
                        "the final table (comma-separated; default pi-stage; pi-poly adds "
                        "asymmetric loops, mduhem and gduhem other operators: one fit more "
                        "each)")
    parser.add_argument("--structure", default=None, metavar="n1a=1,n2a=2,...",
                        help="structure of the identified nominal model (keys n1a, n1b, n2a, "
                        "n2b, q1, q2, f0); the paper's experimental one by default")
    parser.add_argument("--json", action="store_true", help="print one JSON object")
    parser.add_argument("--out", default=None, metavar="DIR",
                        help="write report.json, summary.txt and the figures to DIR")
    parser.add_argument("--force", action="store_true", help="replace files already in DIR")
    parser.add_argument("--quiet", action="store_true", help="no progress lines on stderr")
    parser.add_argument("--effects", default=None, metavar="NAMES",
                        help=f"comma-separated families or forms (default all forms of "
                        f"{','.join(FAMILIES)}: {','.join(DEFAULT_EFFECTS)});"
                        " a named candidate that the records cannot show is an error")
    parser.add_argument("--holdout", type=fraction, default=0.4,
                        help="share of TRAIN's excitation (after its leading rest) held out at "
                        "its end when no --val is given (default 0.4)")
    parser.add_argument("--crop", default=None, metavar="START:STOP",
                        help="keep only this time span of every record, in seconds")
    parser.add_argument("--u-scale", type=positive_arg(float), default=1.0, metavar="K",
                        help="multiply the input by K (keeps alpha |dw1| of condition (8) "
                        "in a range the fit starts well from, e.g. 1/150 for +-150 V)")
    parser.add_argument("--train-skip", type=number(0.0), default=0.0, metavar="S",
                        help="seconds at the start of TRAIN simulated but left out of the fit's "
                        "cost (an initial transient the model cannot represent)")
    parser.add_argument("--initial", choices=("auto", "rest", "level"), default="auto",
                        help="records start at rest at zero output (rest) or at the output "
                        "level measured before the input first moves (level); auto (default): "
                        "level for a record that starts with 10 samples at rest")
    parser.add_argument("--alpha", type=fraction, default=0.01,
                        help="family-wise level of the held-out test per round (default 0.01)")
    parser.add_argument("--min-reduction", type=fraction, default=0.02,
                        help="smallest relative held-out RMS reduction worth having "
                        "(default 0.02)")
    parser.add_argument("--max-rounds", type=integer(1, 20), default=3,
                        help="greedy rounds at most (default 3, at most 20)")
    parser.add_argument("--refit-all", action="store_true",
                        help="refit every excited candidate, not only the promising ones")
    parser.add_argument("--repeat", nargs="+", metavar="REC", default=[],
                        help="records of the same input as TRAIN or a --val record: the gap is "
                        "then measured against their repeatability when it is above the "
                        "sensor noise")
    parser.add_argument("--time-budget", type=number(0.0), default=None, metavar="S",
                        help="seconds after which no further form is refitted (the best form "
                        "of every family the screen cannot rule out always is; default: half "
                        "as long as the nominal identification took; 0: only those, the same "
                        "diagnosis on every machine)")
    parser.add_argument("--workers", type=integer(1, 64), default=None, metavar="N",
                        help="threads for the member fits and each round's refits (default: "
                        "the cores, at most 4); the diagnosis does not depend on it, except "
                        "through the time budget")
    bind(parser, run)


def run(args: argparse.Namespace) -> int:
    """Run ``hystid diagnose``; returns the exit status (2 for bad input).

    Parameters
    ----------
    args : argparse.Namespace
        Parsed arguments (see :func:`configure_parser`).

    Returns
    -------
    int
        0 on success, 2 for bad input or a failed write.
    """
    return run_command(args, _diagnose)


def _columns(text: str | None) -> dict | None:
    from ..records import parse_columns

    if text is None:
        return None
    with refused("--columns: "):
        return parse_columns(text)


def _units(text: str | None) -> dict | None:
    from ..records import parse_units

    if text is None:
        return None
    with refused("--units: "):
        return parse_units(text)


def _mended(rec: Record, args: argparse.Namespace, label: str) -> Record:
    """A scored record with its input glitches interpolated over, as the fit mends the
    training record (the diagnosis' own identify does), said as a warning."""
    from ..identify.prepare import without_input_glitches

    mended, notes = without_input_glitches(rec)
    for note in notes:
        tell(args, f"{label}: {note}", "warning")
    return mended


def _load(path: str, args: argparse.Namespace, label: str) -> Record:
    from ..records import Record, load_record

    with refused(errors=RecordError):
        rec = load_record(path, fs=args.fs, columns=_columns(args.columns),
                          units=_units(args.units))
    remember(rec, path)  # its messages name the file too
    with refused(suffix=f" ({label})", errors=OptionError):
        rec = crop(rec, parse_crop(args.crop) if args.crop is not None else None)
    if args.u_scale != 1.0:
        units = dict(rec.units)
        units["u"] = f"{args.u_scale:g} {units.get('u', '')}".strip()
        rec = Record(rec.u * args.u_scale, rec.y, rec.fs, units, rec.name)
    return rec


def _model(path: str | None, fs: float) -> Any:
    """The model saved in ``path`` (a model file of any member, or an older report.json of a
    Duhem sandwich with a structure)."""
    if path is None:
        return None
    from ..errors import ModelFileError
    from ..model import DuhemSandwich, Structure
    from ..modelfile import FORMAT, load_model

    with refused(f"--model {path}: cannot read a JSON object (", ")",
                 errors=(OSError, ValueError)):
        data = json.loads(Path(path).read_text(encoding="utf-8"))
    if isinstance(data, dict) and "format" in data:
        if data.get("format") != FORMAT:
            raise CommandError(f"--model {path}: 'format' is {data.get('format')!r} (expected "
                               f"{FORMAT!r})")
        with refused("--model ", errors=ModelFileError):
            model = load_model(path)
        return model
    if not isinstance(data, dict) or not isinstance(data.get("params"), dict):
        raise CommandError(f"--model {path}: expected a model file (model.json) or a JSON "
                           "object with 'params' and 'structure'")
    if not isinstance(data.get("structure"), dict):
        raise CommandError(f"--model {path}: has parameters but no 'structure' (orders and "
                           "delays cannot be guessed from names; use the model.json written by "
                           "hystid identify --out)")
    with refused(f"--model {path}: ", errors=(TypeError, ValueError)):
        structure = Structure(**data["structure"])
        return DuhemSandwich(data["params"], structure, fs=fs,
                             name=f"model from {Path(path).name}")


def _runs_on(model: Any, train: Any, args: argparse.Namespace) -> None:
    """Refuse a model given with ``--model`` whose simulation of the train record is not
    finite (a diagnosis of it would only compare infinities)."""
    import numpy as np

    from ..baselines import simulate_from_rest
    from ..metrics import runaway

    with np.errstate(all="ignore"), warnings.catch_warnings():
        warnings.simplefilter("ignore")
        y = simulate_from_rest(model, train.u, check=False)
    if runaway(train.y, y):
        spread = float(np.nanmax(train.y) - np.nanmin(train.y))
        with np.errstate(all="ignore"):
            reach = float(np.max(np.abs(y)))
        raise CommandError(f"--model {args.model}: its simulation of TRAIN {args.train} "
                           f"diverges (it reaches {reach:.3g} where the record spans "
                           f"{spread:.3g}); expected a model that runs on the train record")


def _structure(text: str | None) -> Structure | None:
    if text is None:
        return None
    with refused(errors=OptionError):
        return parse_structure(text)


def _write(out: Path, report: dict, result: DiagnosisResult, final: FinalModel, summary: str,
           provenance: dict) -> None:
    """Write the report, the summary, the model and the figures: all of them, or none on a
    failure."""
    from ..modelfile import save_model
    from ..safeio import atomic_folder, write_json, write_text

    with atomic_folder(out) as stage:
        write_json(stage / "report.json", report)
        write_text(stage / "summary.txt", summary + "\n")
        save_model(final.model, stage / "model.json", provenance=provenance)
        result.plot(stage)


#: :func:`hystid.diagnose.diagnose`'s settings, as the options that set them.
_OPTIONS = {"train_skip": "--train-skip", "holdout": "--holdout", "alpha": "--alpha",
            "min_reduction": "--min-reduction", "max_rounds": "--max-rounds",
            "time_budget": "--time-budget", "effects": "--effects", "initial": "--initial",
            "workers": "--workers", "members": "--members"}


def _diagnose(args: argparse.Namespace) -> None:
    """``hystid diagnose``'s steps (see :func:`run`)."""
    from ..diagnose.diagnosis import DEFAULT_EFFECTS, diagnose
    from ..diagnose.final_model import FINAL_MEMBERS, final_model
    from ..kernels import is_plain
    from ..model import DuhemSandwich
    from ..validate import check_fit_size, check_magnitudes

    with refused(errors=DiagnosisError):
        check_out(args, args.out, OUTPUT_FILES,
                  inputs=(args.train, *args.val, *args.repeat, args.model))
        train = _load(args.train, args, "TRAIN")
        vals = [_mended(_load(p, args, f"--val {p}"), args, f"--val {p}") for p in args.val]
        repeats = [_mended(_load(p, args, f"--repeat {p}"), args, f"--repeat {p}")
                   for p in args.repeat]
        try:  # the diagnosis refits the batch fit many times: the batch fit's cap holds
            for path, rec in zip([args.train, *args.val], [train, *vals], strict=True):
                check_magnitudes(rec, path)
            check_fit_size(train.n, "batch", f"TRAIN {args.train}")
        except ValueError as err:
            raise CommandError(str(err).replace(", or use --method online (one pass, linear "
                                                "in the length, with progress)", "")) from err
        if args.effects is None:
            names, strict = DEFAULT_EFFECTS, False
        else:
            names = tuple(n.strip() for n in args.effects.split(",") if n.strip())
            strict = True
            if not names:
                raise CommandError(f"--effects {args.effects!r}: names no effect (expected "
                                   "comma-separated families or forms, e.g. creep,drift; leave "
                                   "--effects out for all of them)")
        model = _model(args.model, train.fs)
        if model is not None:
            _runs_on(model, train, args)
        given = None
        if model is not None and (not isinstance(model, DuhemSandwich)
                                  or not is_plain(model.structure.layout)):
            check_model_on(model, train)
            if abs(model.fs - train.fs) > 1e-9 * train.fs:
                raise CommandError(f"--model {args.model}: a model of a stage sampled at "
                                   f"{model.fs:g} Hz, TRAIN {args.train} at {train.fs:g} Hz "
                                   "(expected the same rate)")
            given = (f"given: {Path(args.model).name}", model)
            kind = ("generalised Duhem sandwich" if isinstance(model, DuhemSandwich)
                    else type(model).__name__)
            tell(args, f"--model {args.model}: a {kind}; the candidate effects extend the plain "
                 "eq. (7), so the rounds diagnose a Duhem sandwich identified on the "
                 "train record, and the model given is scored beside it and the members in the "
                 "final table")
            model = None
        members = FINAL_MEMBERS if args.members is None else tuple(
            n.strip() for n in args.members.split(",") if n.strip())
        if not members:
            raise CommandError(f"--members {args.members!r}: names no member (expected "
                               "comma-separated names, e.g. pi-stage,pi-poly)")
        try:
            result = diagnose(
                train, vals, model, structure=_structure(args.structure), effects=names,
                holdout=args.holdout, alpha=args.alpha,
                min_reduction=args.min_reduction, max_rounds=args.max_rounds,
                train_skip=args.train_skip, initial=args.initial, refit_all=args.refit_all,
                repeats=repeats, time_budget=args.time_budget,
                require_excitation=strict, members=members, workers=args.workers,
                progress=not args.quiet,
            )
        except DiagnosisError as err:  # its settings said as the options that set them
            raise DiagnosisError(as_option(str(err), _OPTIONS)) from err
        final = final_model(result, train, vals, given=given, members=members,
                            progress=None if args.quiet else (lambda m: tell(args, m)))
    report = result.to_dict()
    report["records"] = {"train": train.name, "val": [v.name for v in vals],
                         "repeat": [r.name for r in repeats],
                         "units": train.units, "u_scale": args.u_scale, "crop": args.crop}
    report["final_model"] = final.to_dict()
    summary = "\n".join([result.summary(), "", *final.summary_lines(train.units.get("y", ""))])
    if args.out:
        from ..modelfile import make_provenance

        out = Path(args.out)
        provenance = make_provenance("diagnose", args.train, {"model": final.chosen})
        with refused(f"--out {out}: ", errors=OSError):
            _write(out, report, result, final, summary, provenance)
    if args.json:
        from ..safeio import dumps_strict

        print(dumps_strict(report))
    else:
        print(summary)
        if args.out:
            print(f"\nfigures, report and model.json ({final.chosen}) written to {args.out}")
