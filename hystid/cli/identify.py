"""``hystid identify``: identify a sandwich model from a record and validate it.

``hystid identify REC [--val VAL] [--model auto|duhem|pi|pi-stage] [--method M] [--out DIR]
[--history H.csv] [--json] ...`` fits the member of the model family asked for (by default the
simplest one that no richer member beats on a block held out in the record), validates it on
``--val`` or on the held-out end of the record against a static line and a linear model, and
prints the parameters and figures (or, with ``--json``, one JSON object). ``--out`` receives
``report.json``, ``model.json`` and the figures, all of them or none.
"""

from __future__ import annotations

import argparse
import warnings
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from ..errors import OptionError
from ..options import crop, integer, parse_crop, parse_structure
from .support import (
    IDENTIFY_KERNELS,
    UNITS_HELP,
    CommandError,
    Progress,
    bind,
    check_out,
    columns_arg,
    file_arg,
    jsonable,
    kernels_cached,
    load,
    non_negative_arg,
    one_of,
    positive_arg,
    refused,
    run_command,
    table,
    tell,
    units_arg,
)

if TYPE_CHECKING:  # pragma: no cover
    from ..identify.result import IdentificationResult
    from ..model import Structure
    from ..records import Record

__all__ = ["MODEL_NAMES", "NUMERIC_NOISE", "REPORT_FILES", "configure_parser", "run",
           "write_outputs"]

#: numpy's floating-point RuntimeWarnings raised while a fit tries a diverging candidate: not
#: shown by ``identify`` (a result the fit could not trust carries its own warnings).
NUMERIC_NOISE = r"(overflow|invalid value|divide by zero|underflow) encountered"
#: Files ``identify --out`` and ``demo --out`` write into their folder.
REPORT_FILES = ("report.json", "model.json", "validation.png", "convergence.png")


#: The members of the model family (``hystid.identify.members.MEMBERS``; a test keeps the two
#: equal, so that the parser does not import the models).
MODEL_NAMES = ("duhem", "gduhem", "pi", "pi-stage", "pi-poly", "mduhem")
#: Methods of each hysteresis block (``--model``) that keep a parameter history.
_HISTORY_METHODS = {"duhem": ("online", "eria", "ekf"), "pi": ("online", "eria")}


def configure_parser(parser: argparse.ArgumentParser) -> None:
    """Add the arguments of ``hystid identify`` to ``parser``.

    Parameters
    ----------
    parser : argparse.ArgumentParser
        The command's parser.
    """
    parser.description = ("Identify a sandwich model from a record (CSV with a header naming u, "
                          "y and optionally t; .npz, .mat, .h5) and validate it.")
    p = parser
    p.add_argument("record", type=file_arg, help="record file")
    p.add_argument("--fs", type=positive_arg(float), help="sampling rate in Hz (if no t column)")
    p.add_argument("--val", type=file_arg,
                   help="validation record (default: the last --holdout share of the record's "
                   "excitation)")
    p.add_argument("--columns", type=columns_arg, metavar="t=1,u=3,y=2",
                   help="where t, u and y are in the files (names or 0-based positions)")
    p.add_argument("--units", type=units_arg, metavar="u=V,y=um", help=UNITS_HELP)
    p.add_argument("--model", choices=("auto", *MODEL_NAMES), default=None,
                   help="member of the model family (default: auto, the simplest member that "
                   "no richer one beats on a block held out in the record; with --method online "
                   "chosen as for the batch fit, then identified on-line; duhem when "
                   "--structure, --history or --method eria/ekf is given)")
    p.add_argument("--method", choices=("eria", "online", "ekf", "batch"), default=None,
                   help="estimator (default: batch; online for --model pi)")
    p.add_argument("--workers", type=integer(1, 64), default=None, metavar="N",
                   help="threads the model choice fits its candidates in (default: the cores, "
                   "at most 4); the choice and the model do not depend on it")
    p.add_argument("--structure", default=None, metavar="auto|n1a=1,n2a=2,...",
                   help="model structure: keys n1a, n1b, n2a, n2b, q1, q2, f0, f_order, "
                   "g_order, directional (the paper's experimental one by default), or 'auto' "
                   "to choose on held-out error")
    p.add_argument("--crop", default=None, metavar="START:STOP",
                   help="keep only this time span of every record, in seconds")
    p.add_argument("--offset", choices=("estimate", "none"), default=None,
                   help="batch fit: estimate the sensor offset (default) or take the output as "
                   "zero at rest")
    p.add_argument("--skip", type=non_negative_arg, default=None, metavar="S",
                   help="seconds at the start simulated but left out of the fit (default: none "
                   "for a record that starts at rest, else until the input has swept its range)")
    p.add_argument("--holdout", type=_holdout_fraction, default=0.4, metavar="F",
                   help="without --val, the share of the record's excitation (after its "
                   "leading rest) held out at its end for validation (default 0.4; 0 "
                   "validates on the record itself)")
    p.add_argument("--repeat", type=file_arg, nargs="+", default=None, metavar="REC",
                   help="records of the same input as the validation record: their "
                   "repeat-to-repeat RMS is the floor no deterministic model can beat")
    p.add_argument("--history", type=file_arg,
                   help="write the parameter history of an on-line method (CSV: k, one column "
                   "a parameter); may lie in --out but never be one of its files")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.add_argument("--out", type=file_arg, help="folder for report.json, model.json and figures")
    p.add_argument("--force", action="store_true",
                   help="replace --history and files already in --out")
    p.add_argument("--quiet", action="store_true", help="no progress lines")
    bind(parser, run)


def run(args: argparse.Namespace) -> int:
    """Run ``hystid identify``: identify a record, validate, print or write JSON.

    Parameters
    ----------
    args : argparse.Namespace
        Parsed arguments (see :func:`configure_parser`).

    Returns
    -------
    int
        0 on success, 2 on bad input or a failed write.
    """
    return run_command(args, _identify)


# --------------------------------------------------------------------------- checks before work
def _holdout_fraction(text: str) -> float:
    value = non_negative_arg(text)
    if not value < 1:
        raise argparse.ArgumentTypeError(f"expected a share in [0, 1), got {text!r}")
    return value


def _check_outputs(args: argparse.Namespace, inputs: tuple) -> None:
    """``--history`` and ``--out``: each writable, and apart from each other.

    ``--history`` may lie inside the ``--out`` folder (which is created), but never be the
    folder or one of the files written into it, not even with ``--force``.
    """
    from ..safeio import check_apart, inside

    if args.history and args.out:
        check_apart(args.history, args.out, REPORT_FILES, option="--history")
    check_out(args, args.out, REPORT_FILES, inputs=inputs)
    in_out = bool(args.history and args.out and inside(args.history, args.out))
    check_out(args, args.history, option="--history", inputs=inputs, create_folder=in_out)


def _crop_arg(args: argparse.Namespace) -> tuple[float | None, float | None] | None:
    """The span of ``--crop`` (``None`` without it)."""
    if args.crop is None:
        return None
    with refused(errors=OptionError):
        return parse_crop(args.crop)


def _cropped(rec: Record, span: tuple[float | None, float | None] | None) -> Record:
    """The part of ``rec`` in ``span`` (all of it for ``None``)."""
    with refused(errors=OptionError):
        return crop(rec, span)


def _structure_arg(args: argparse.Namespace) -> Structure | str | None:
    """The structure of ``--structure``: ``None``, ``"auto"`` or a Duhem structure."""
    if args.structure is None or args.structure == "auto":
        return args.structure
    with refused(errors=OptionError):
        return parse_structure(args.structure)


def _model_arg(args: argparse.Namespace) -> str:
    """The ``--model`` of ``identify``: as given, else ``auto`` for a batch or on-line fit that
    no other option ties to the Duhem sandwich (``--structure``, ``--history``, ``--method eria``
    or ``ekf``)."""
    from ..identify import default_model

    model = getattr(args, "model", None)
    if model is None:
        model = default_model(args.method or "batch", getattr(args, "structure", None))
        if getattr(args, "history", None):  # the parameter history is the Duhem one's
            model = "duhem"
        args.model, args.model_defaulted = model, True
    return model


def _method_arg(args: argparse.Namespace) -> str:
    """The ``--method`` of ``identify`` checked against ``--model`` and ``--history``."""
    model_kind = _model_arg(args)
    family = "pi" if model_kind.startswith("pi") else "duhem"
    method = args.method or ("online" if model_kind == "pi" else "batch")
    if family == "pi" and method in ("ekf", "eria"):
        raise CommandError(f"--method {method}: the PI sandwich is identified by 'online' (its "
                           "recursive identifier) or 'batch' (expected one of these)")
    if model_kind == "mduhem" and method != "batch":
        raise CommandError(f"--method {method}: the mduhem member is identified by 'batch' only "
                           "(expected --method batch, or another --model)")
    if model_kind == "auto" and method not in ("batch", "online"):
        raise CommandError(f"--model auto chooses on batch fits, for --method batch or online "
                           f"(got --method {method}; expected --model duhem for it)")
    if getattr(args, "history", None) and method not in _HISTORY_METHODS[family]:
        raise CommandError(f"--history: method {method!r} keeps no parameter history "
                           f"(expected --method {one_of(_HISTORY_METHODS[family])})")
    batch_only = (("--skip", getattr(args, "skip", None)),
                  ("--offset", getattr(args, "offset", None)))
    for option, value in batch_only:
        if value is not None and method != "batch":
            raise CommandError(f"{option} applies to the batch fit only (got --method "
                               f"{method}; expected --method batch, or no {option})")
    if model_kind != "duhem" and getattr(args, "structure", None) is not None:
        raise CommandError(f"--structure applies to the Duhem sandwich only (got --model "
                           f"{model_kind})")
    return method


def _check_skip(args: argparse.Namespace, train: Record,
                structure: Structure | str | None) -> None:
    """``--skip`` must leave the batch fit enough samples of the record it fits."""
    from ..identify import min_samples

    if getattr(args, "skip", None) is None:
        return
    left = train.n - int(round(args.skip * train.fs))
    need = min_samples("batch", None if structure == "auto" else structure)
    if left < need:
        raise CommandError(f"--skip {args.skip:g}: leaves {max(left, 0)} of the {train.n} "
                           f"samples fitted ({train.n / train.fs:g} s of {train.name!r} "
                           f"without its held-out end; expected at least {need} samples left)")


def _identify_record(rec: Record, args: argparse.Namespace, progress: Progress,
                     structure: Structure | str | None = None) -> IdentificationResult:
    """Run the chosen model/method on a record; returns the IdentificationResult."""
    from ..identify import identify
    from ..validate import check_fit_size

    method = _method_arg(args)
    check_fit_size(rec.n, "batch" if structure == "auto" else method, f"record {rec.name!r}")
    settings: dict = {"progress": progress} if method != "batch" else {}
    if method == "batch":
        settings["offset"] = getattr(args, "offset", None) != "none"
        if _model_arg(args) in ("duhem", "mduhem"):  # the PI batch fit keeps its own settings
            settings["say"] = progress.say
        elif _model_arg(args) == "auto":  # a line per candidate fitted and scored
            settings["progress"] = progress
        else:
            progress.say(f"fitting the {_model_arg(args)} member (batch, one line when done)")
        if getattr(args, "skip", None) is not None:
            settings["skip"] = int(round(args.skip * rec.fs))
    # a defaulted choice is left to identify(), which fits the Duhem sandwich (and says so) on a
    # record too short to choose a member on
    defaulted = getattr(args, "model_defaulted", False) and _model_arg(args) == "auto"
    return identify(rec, method=method, structure=structure,
                    model=None if defaulted else _model_arg(args),
                    workers=getattr(args, "workers", None), **settings)


def _split_for_validation(rec: Record, val: Record | None,
                          args: argparse.Namespace) -> tuple[Record, Record, int | None]:
    """The identification record, the validation target and the first sample to score.

    Without ``--val`` the end of the record is held out (``--holdout``, a share of the
    excitation after the leading rest: :func:`~hystid.identify.prepare.held_out_from`) and the
    whole record is simulated, so the held-out part starts from the model's own state.
    """
    if val is not None:
        return rec, val, None
    share = getattr(args, "holdout", 0.0) or 0.0
    if share == 0.0:
        return rec, rec, 0
    from ..identify.prepare import check_excitation, held_out_from, rest_level

    with refused():  # a constant input is refused as such, not as a record too short
        check_excitation(rec)
    k = held_out_from(rec.u, share)
    if k < 2 or rec.n - k < 2:
        raise CommandError(f"--holdout {share:g}: record {rec.name!r} is too short to hold out "
                           "a part of it")
    from ..identify import min_samples

    need = min_samples(args.method or "batch")
    _, at_rest, lead = rest_level(rec.u)
    moving = k - (lead if at_rest else 0)  # samples of excitation left to identify on
    if moving < need:
        raise CommandError(f"--holdout {share:g}: leaves {moving} samples of excitation of "
                           f"record {rec.name!r} to identify on (expected at least {need} for "
                           f"--method {args.method or 'batch'}: a smaller --holdout, or --val)")
    if k < need:
        raise CommandError(f"--holdout {share:g}: leaves {k} of the {rec.n} samples of record "
                           f"{rec.name!r} to identify on (expected at least {need} for --method "
                           f"{args.method or 'batch'}: a smaller --holdout, or --val)")
    return rec[:k], rec, k


def _mended_for_scoring(target, held_from: int | None) -> tuple[object, list[str]]:
    """The scored record with its input glitches interpolated over, as the fit mends the
    record it identifies on (a glitch would otherwise drive the model through a spike that
    never reached the stage); what was mended, for glitches the fit's own notes do not name
    (those in a held-out end from ``held_from``, or anywhere in a validation record)."""
    from ..identify.prepare import input_glitches, without_input_glitches

    runs, notes = input_glitches(target.u, target.y)
    if not runs:
        return target, []
    mended, _ = without_input_glitches(target)
    start = held_from or 0
    said = [f"scored record: {n}" for (k, _), n in zip(runs, notes, strict=True)
            if k >= start]
    return mended, said


def _report(result, rec, val, args, scored_from=None, repeats=None) -> tuple[dict, np.ndarray,
                                                                              object]:
    from ..baselines import compare, rest_zero, simulate_from_rest
    from ..identify.prepare import without_input_glitches
    from ..metrics import runaway, validate
    from ..safeio import same_file

    target = val if val is not None else rec
    k = scored_from
    # glitches the fit mended and named are not named again (the record itself validated)
    target, mended = _mended_for_scoring(
        target, k if k is not None else (0 if val is not None else target.n))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        yhat = simulate_from_rest(result.model, target.u, check=False)
        if val is not None:  # another record: its own zero, as compare() scores it
            yhat = yhat + rest_zero(yhat, target)
    problems = result.model.admissibility(target.u) if hasattr(result.model, "admissibility") \
        else (result.model.envelope.violations(target.u) if result.model.envelope else [])
    baselines = compare(result.model, without_input_glitches(rec)[0],  # what the fit saw
                        [(target, k) if k is not None else target], repeats=repeats)
    if k is None and val is not None:  # scored from the burn-in, as compare() scores it
        from ..identify.prepare import burn_in, rest_level

        k = burn_in(target.u, rest_level(target.u)[1]) or None
    k = k or 0
    finite = not runaway(target.y[k:], yhat[k:])  # 7.5e18 um from --holdout 0.99 is no figure
    try:
        validation = validate(target.y[k:], yhat[k:] if finite else np.zeros(target.n - k),
                              target.fs)
    except ValueError as err:  # a validation record too short to score
        where = f"--val {args.val}" if getattr(args, "val", None) else f"record {rec.name!r}"
        raise ValueError(f"{where}: {err}") from err
    warnings_ = list(result.info.get("warnings", []))
    warnings_ += mended
    warnings_ += [f"on the validation input: {p}" for p in problems]
    warnings_ += baselines.notes
    val_path, rec_path = getattr(args, "val", None), getattr(args, "record", None)
    if val is not None and val_path and rec_path and same_file(val_path, rec_path):
        warnings_.append(f"--val {val_path} is the identification record itself: these figures "
                         "are not held out (without --val the record's end is held out, "
                         "--holdout)")
    if not finite:
        warnings_.append("the model diverges on the validation input (its output runs away "
                         "from the measured one); its figures are not reported: do not use "
                         "this model")
    return {
        "model": result.info.get("model", getattr(args, "model", None) or "duhem"),
        "method": result.method,
        "params": result.params,
        "u_rest": getattr(result.model, "u_rest", 0.0),
        "offset": getattr(result.model, "offset", 0.0),
        # the state at rest: a Duhem model's remembered w2, a PI model's swing before the rest
        "rest_memory": float(getattr(result.model, "rest_memory", 0.0)),
        "rest_swing": float(getattr(result.model, "rest_swing", 0.0)),
        "units": dict(rec.units),
        "structure": getattr(result.model.structure, "__dict__", {}),
        "validation": validation.to_dict() if finite else None,
        "scored_from": int(k),
        "validated_on": (("validation record" + (f" from sample {k}: it does not start at "
                                                  "rest, its start is a burn-in" if k else ""))
                         if getattr(args, "val", None) else
                         f"held-out end of the record (samples {k}..{target.n - 1})" if k
                         else "identification record"),
        "zeroed_on": ("the output at rest at the start of the validation record (a sensor's "
                      "zero moves between records)" if val is not None else
                      "the offset identified (the held-out part shares the record's zero)"),
        "baselines": baselines.to_dict(),
        "beats_baselines": baselines.beats_baselines,
        "warnings": warnings_,
        "converged_at": result.converged_at,
        "settings": {k_: v for k_, v in result.settings.items() if jsonable(v)},
        "record": {"name": rec.name, "samples": rec.n, "fs": rec.fs},
        "info": {k_: v for k_, v in result.info.items() if jsonable(v)},
    }, yhat, target


def _write_history(path: str, result) -> None:
    """Write the parameter history as CSV (atomically; its folder is created when missing)."""
    from ..safeio import atomic_open

    if result.history is None:  # pragma: no cover - refused before the work by _method_arg
        raise CommandError(f"--history: method {result.method!r} keeps no parameter history")
    names = list(result.names)
    index = getattr(result, "history_index", None)  # a decimated history names its samples
    k = np.arange(1, len(result.history) + 1) if index is None else np.asarray(index) + 1
    data = np.column_stack([k, result.history])
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    with atomic_open(path, "w", newline="\n") as out:
        np.savetxt(out, data, delimiter=",", header=",".join(["k", *names]), comments="",
                   fmt=["%d"] + ["%.10g"] * len(names))


# --------------------------------------------------------------------------- the steps
def _identify(args: argparse.Namespace) -> int:
    """``hystid identify``'s steps (see :func:`run`)."""
    from ..safeio import dumps_strict

    progress = Progress(args.quiet or args.json)
    inputs = (args.record, args.val, *(args.repeat or []))
    _check_outputs(args, inputs)
    _method_arg(args)
    span = _crop_arg(args)
    structure = _structure_arg(args)
    rec = _cropped(load(args.record, args.fs, args.columns, units=args.units), span)
    val = (_cropped(load(args.val, args.fs, args.columns, "--val", args.units), span)
           if args.val else None)
    repeats = [_cropped(load(p, args.fs, args.columns, "--repeat", args.units), span)
               for p in args.repeat or []]
    for other, label in [(val, f"--val {args.val}")] + [
            (r, f"--repeat {p}") for r, p in zip(repeats, args.repeat or [], strict=True)]:
        if other is not None and not np.isclose(other.fs, rec.fs, rtol=1e-9):
            raise CommandError(f"{label}: fs {other.fs:g} Hz differs from {rec.fs:g} Hz "
                               f"of {args.record}")
        if other is not None and other.units != rec.units:
            raise CommandError(f"{label}: in u={other.units.get('u')}, y={other.units.get('y')} "
                               f"but {args.record} in u={rec.units.get('u')}, "
                               f"y={rec.units.get('y')} (expected records in one set of units: "
                               "a model is scored in its record's; give the records in the "
                               "same units, or --units when the files state them wrongly)")
    train, target, scored_from = _split_for_validation(rec, val, args)
    _check_skip(args, train, structure)
    progress.say(f"identifying {args.record}: {train.n} samples at {rec.fs:g} Hz")
    if not kernels_cached(IDENTIFY_KERNELS):
        progress.say("compiling the numba kernels: once, up to a minute; later runs load them "
                     "from numba's cache")
    with refused():
        with warnings.catch_warnings():  # the fit's own checks report what these would mean
            warnings.filterwarnings("ignore", NUMERIC_NOISE, RuntimeWarning)
            result = _identify_record(train, args, progress, structure)
            floor_set = [target, *repeats] if repeats else None  # the baselines' fits too
            report, yhat, target = _report(result, train, target if val is not None or
                                           scored_from is not None else None, args, scored_from,
                                           floor_set)
    for w in report["warnings"]:
        if not args.json:
            tell(args, w, "warning")
    if args.out:
        from ..modelfile import make_provenance

        provenance = make_provenance(result.method, args.record, result.settings)
        write_outputs(Path(args.out), report, target, yhat, result, provenance=provenance,
                      scored_from=report["scored_from"])
    if args.history:
        _write_history(args.history, result)
    if args.json:
        print(dumps_strict(report))
    else:
        rows, yu = [[k, f"{v:.6g}"] for k, v in report["params"].items()], rec.units.get("y", "")
        rows += [[f"{k} [{rec.units.get(x, '')}]", f"{report[k]:.6g}"]
                 for k, x in (("u_rest", "u"), ("offset", "y"), ("rest_memory", "y"),
                              ("rest_swing", "u"))
                 if k in ("u_rest", "offset") or report[k]]
        print(table(rows, ["parameter", "estimate"]))
        _print_choice(result.info.get("member_selection"), rec.units.get("y", ""))
        v = report["validation"]
        if v is not None:
            print(f"\nvalidation ({report['validated_on']}): error {v['err_min']:.4g} .. "
                  f"{v['err_max']:.4g} {yu}, RMS {v['rms']:.4g} {yu}, fit {v['fit_percent']:.2f} %"
                  + (f" (the first {v['skip']} samples left out, the paper's transient; the "
                     "held-out table below scores them)" if v.get("skip") else ""))
        b = report["baselines"]
        for row in b["rows"]:
            model_rms = "diverged" if row["model"] is None else f"{row['model']:.4g}"
            print(f"held-out RMS [{rec.units.get('y', '')}]: model {model_rms}, static line "
                  f"{row['static_line']:.4g}, linear model {row['linear']:.4g}"
                  + ("" if row["beats"] else "  -> the hysteresis model does NOT beat them"))
        if b["rows"] and b.get("zero") == "rest":
            print("(on a held-out record that begins at rest, each prediction, the model's and "
                  "both baselines', is put on its measured output at rest: the static line is "
                  "then its gain through that point, not the offset fitted on the training "
                  "record)")
        if b["repeat_floor"] is not None:
            print(f"repeat floor (no deterministic model beats it): {b['repeat_floor']:.4g} {yu}")
        if report["converged_at"] is not None:
            print(f"converged at sample {report['converged_at']}")
    return 0


def _print_choice(selection: dict | None, unit: str) -> None:
    """The member choice of ``--model auto``: every candidate and baseline on the held-out
    block of the identification record."""
    if not selection:
        return
    rows = [[c["member"], str(c["n_params"]), f"{c['heldout_rms']:.4g} {unit}",
             "chosen" if c["chosen"] else ("left out" if c.get("left_out") else "")]
            for c in selection["candidates"]]
    rows += [[b.replace("_", " "), "", f"{v:.4g} {unit}", "baseline"]
             for b, v in selection["baselines"].items()]
    print(f"\nmodel choice (samples {selection['holdout_from']}..{selection['holdout_to'] - 1} "
          "of the identification record held out, fitted without them; a richer member must "
          f"be {100 * selection['margin']:.0f} % better):")
    print(table(rows, ["member", "parameters", "held-out RMS", ""]))
    for c in selection["candidates"]:
        if c.get("left_out"):
            print(f"{c['member']} left out: {c['left_out']}")


def write_outputs(out: Path, report: dict, target: Record, yhat: np.ndarray, result: Any,
                  truth: dict | None = None, provenance: dict | None = None,
                  seed: int | None = None, scored_from: int = 0) -> None:
    """Write report.json, model.json and the figures into ``out``, all or none of them.

    The files are written into a staging folder and moved in place once all are written
    (:func:`hystid.safeio.atomic_folder`): a failure midway leaves ``out`` as it was. The
    validation figure shows the samples the validation figures were computed on: from
    ``scored_from`` (a held-out end of the record) less the transient.

    Parameters
    ----------
    out : pathlib.Path
        The folder (created when missing).
    report : dict
        The report; the units and the provenance are added to it.
    target : Record
        The record validated on.
    yhat : ndarray
        The model's output on it.
    result : IdentificationResult
        The identification (its model, its parameter history).
    truth : dict, optional
        True parameters, drawn in the convergence figure.
    provenance : dict, optional
        The model file's provenance (:func:`hystid.modelfile.make_provenance`).
    seed : int, optional
        The random seed of a simulated record.
    scored_from : int
        First sample the validation figures score.
    """
    from ..metrics import plot_convergence, plot_validation
    from ..modelfile import save_model
    from ..safeio import atomic_folder, write_json

    model = result.model
    units = {"u": target.units.get("u", ""), "y": target.units.get("y", "")}
    report = {
        **report,
        "units": {**units, "validation": units["y"], "u_rest": units["u"],
                  "offset": units["y"], "rest_memory": units["y"], "rest_swing": units["u"],
                  "time": "s", "fs": "Hz"},
        "provenance": {**(provenance or {}), "fs": model.fs,
                       "structure": dict(vars(model.structure)), "seed": seed},
    }
    with atomic_folder(out) as stage:
        write_json(stage / "report.json", report)
        save_model(model, stage / "model.json", provenance=provenance)
        plot_validation(target.t, target.y, yhat, stage / "validation.png", u=target.u,
                        title=f"{report['model']} sandwich, {report['method']}: validation on "
                        f"{target.name}", unit=units["y"], u_unit=units["u"],
                        skip=scored_from + (report["validation"] or {}).get("skip", 0))
        if result.history is not None:
            plot_convergence(result.history, result.names, truth, stage / "convergence.png",
                             samples=result.history_index,
                             title=f"{report['model']} sandwich, {report['method']}: "
                             "parameter convergence")


