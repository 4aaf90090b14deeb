"""The ``hystid`` command line: demo, simulate, identify, diagnose, compensate."""

from __future__ import annotations

import argparse
import sys
import time
import warnings
from pathlib import Path

import numpy as np

from . import __version__, cli_support
from .cli_support import EXIT_BAD_INPUT, CommandError, OneLineParser, Progress  # noqa: F401
from .options import MAX_SECONDS, integer, number

#: numpy's floating-point RuntimeWarnings raised while a fit tries a diverging candidate: not
#: shown by ``identify`` (a result the fit could not trust carries its own warnings).
NUMERIC_NOISE = r"(overflow|invalid value|divide by zero|underflow) encountered"
#: Files ``identify --out`` and ``demo --out`` write into their folder.
kernels_cached = cli_support.kernels_cached  # where it always was
REPORT_FILES = ("report.json", "model.json", "validation.png", "convergence.png")
_RECORD_SUFFIXES = (".csv", ".npz", ".mat", ".h5", ".hdf5")


# --------------------------------------------------------------------------- helpers
def _load(path: str, fs: float | None, columns: dict | None = None, option: str = "",
          units: dict | None = None):
    """Load a record; a problem with it is a :class:`CommandError` naming ``option`` and file."""
    from .records import RecordError, load_record

    try:
        return cli_support.remember(load_record(path, fs=fs, columns=columns, units=units), path)
    except RecordError as err:
        raise CommandError(f"{option} {err}" if option else str(err)) from err


def _check_file(path: str | None, option: str, args: argparse.Namespace,
                inputs: tuple = (), create_folder: bool = False) -> Path | None:
    """Check an output file before any work (see :func:`hystid.safeio.check_output`)."""
    from .safeio import OutputError, check_output

    if path is None:
        return None
    try:
        return check_output(path, option=option, inputs=inputs,
                            force=getattr(args, "force", False), create_folder=create_folder)
    except OutputError as err:
        raise CommandError(str(err)) from err


def _check_identify_outputs(args: argparse.Namespace, inputs: tuple) -> None:
    """``--history`` and ``--out`` of ``identify``: each writable, and apart from each other.

    ``--history`` may lie inside the ``--out`` folder (which is created), but never be the
    folder or one of the files written into it, not even with ``--force``.
    """
    from .safeio import OutputError, check_apart, inside

    if args.history and args.out:
        try:
            check_apart(args.history, args.out, REPORT_FILES, option="--history")
        except OutputError as err:
            raise CommandError(str(err)) from err
    _check_dir(args.out, args, inputs)
    in_out = bool(args.history and args.out and inside(args.history, args.out))
    _check_file(args.history, "--history", args, inputs, create_folder=in_out)


def _check_dir(path: str | None, args: argparse.Namespace, inputs: tuple = (),
               names: tuple[str, ...] = REPORT_FILES) -> Path | None:
    """Check an output folder and the files to be written into it, before any work."""
    from .safeio import OutputError, check_output_dir

    if path is None:
        return None
    try:
        return check_output_dir(path, names, option="--out", inputs=inputs,
                                force=getattr(args, "force", False))
    except OutputError as err:
        raise CommandError(str(err)) from err


def _columns_arg(text: str) -> dict:
    from .records import parse_columns

    try:
        return parse_columns(text)
    except ValueError as err:
        raise argparse.ArgumentTypeError(str(err)) from err


def _units_arg(text: str) -> dict:
    from .records import parse_units

    try:
        return parse_units(text)
    except ValueError as err:
        raise argparse.ArgumentTypeError(str(err)) from err


UNITS_HELP = ("units of the input and output, e.g. u=N,y=m (default: those stored in the "
              "file, else V and um; they label the numbers, the fit does not depend on them)")


def _positive(kind):
    """argparse ``type=`` for a positive finite ``kind`` (float or int)."""
    return number(0.0, strict_minimum=True) if kind is float else integer(1)


_non_negative_float = number(0.0)


def _path(text: str) -> str:
    """argparse ``type=`` for a file or folder name: not empty, not blank."""
    if not text.strip():
        raise argparse.ArgumentTypeError(f"expected a file or folder name, got {text!r}")
    return text


def _crop_arg(args):
    text = getattr(args, "crop", None)
    if text is None:
        return None
    from .options import OptionError, parse_crop

    try:
        return parse_crop(text)
    except OptionError as err:
        raise CommandError(str(err)) from err


def _cropped(rec, span):
    if span is None:
        return rec
    from .options import OptionError, crop

    try:
        return crop(rec, span)
    except OptionError as err:
        raise CommandError(str(err)) from err


def _holdout_fraction(text: str) -> float:
    value = _non_negative_float(text)
    if not value < 1:
        raise argparse.ArgumentTypeError(f"expected a share in [0, 1), got {text!r}")
    return value


#: Methods of each hysteresis block (``--model``) that keep a parameter history.
#: The members of the model family (``hystid.identify.members.MEMBERS``; a test keeps the two
#: equal, so that the parser does not import the models).
MODEL_NAMES = ("duhem", "gduhem", "pi", "pi-stage", "mduhem")
_HISTORY_METHODS = {"duhem": ("online", "eria", "ekf"), "pi": ("online", "eria")}


def _model_arg(args: argparse.Namespace) -> str:
    """The ``--model`` of ``identify``: as given, else ``auto`` for a batch fit that no other
    option ties to the Duhem sandwich (``--structure``, an on-line ``--method``)."""
    model = getattr(args, "model", None)
    if model is None:
        tied = (getattr(args, "structure", None) is not None
                or args.method not in (None, "batch") or getattr(args, "history", None))
        model = "duhem" if tied else "auto"
        args.model = model
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
    if model_kind == "auto" and method != "batch":
        raise CommandError(f"--model auto chooses on batch fits (got --method {method}; "
                           "expected --model duhem or pi for an on-line method)")
    if getattr(args, "history", None) and method not in _HISTORY_METHODS[family]:
        raise CommandError(f"--history: method {method!r} keeps no parameter history "
                           f"(expected --method {cli_support.one_of(_HISTORY_METHODS[family])})")
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


def _check_skip(args: argparse.Namespace, train, structure) -> None:
    """``--skip`` must leave the batch fit enough samples of the record it fits."""
    from .identify import min_samples

    if getattr(args, "skip", None) is None:
        return
    left = train.n - int(round(args.skip * train.fs))
    need = min_samples("batch", None if structure == "auto" else structure)
    if left < need:
        raise CommandError(f"--skip {args.skip:g}: leaves {max(left, 0)} of the {train.n} "
                           f"samples fitted ({train.n / train.fs:g} s of {train.name!r} "
                           f"without its held-out end; expected at least {need} samples left)")


def _identify_record(rec, args, progress: Progress, structure=None):
    """Run the chosen model/method on a record; returns the IdentificationResult."""
    from .identify import identify
    from .validate import check_fit_size

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
    return identify(rec, method=method, structure=structure, model=_model_arg(args),
                    **settings)


def _structure_arg(args):
    text = getattr(args, "structure", None)
    if text is None or text == "auto":
        return text
    from .options import OptionError, parse_structure

    try:
        return parse_structure(text)
    except OptionError as err:
        raise CommandError(str(err)) from err


def _split_for_validation(rec, val, args):
    """The identification record, the validation target and the first sample to score.

    Without ``--val`` the end of the record is held out (``--holdout``) and the whole record is
    simulated, so the held-out part starts from the model's own state.
    """
    if val is not None:
        return rec, val, None
    share = getattr(args, "holdout", 0.0) or 0.0
    if share == 0.0:
        return rec, rec, 0
    k = int(round((1.0 - share) * rec.n))
    if k < 2 or rec.n - k < 2:
        raise CommandError(f"--holdout {share:g}: record {rec.name!r} is too short to hold out "
                           "a part of it")
    return rec[:k], rec, k


def _report(result, rec, val, args, scored_from=None, repeats=None) -> tuple[dict, np.ndarray,
                                                                              object]:
    from .baselines import compare, rest_zero, simulate_from_rest
    from .metrics import validate

    target = val if val is not None else rec
    k = scored_from
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        yhat = simulate_from_rest(result.model, target.u, check=False)
        if val is not None:  # another record: its own zero, as compare() scores it
            yhat = yhat + rest_zero(yhat, target)
    problems = result.model.admissibility(target.u) if hasattr(result.model, "admissibility") \
        else (result.model.envelope.violations(target.u) if result.model.envelope else [])
    baselines = compare(result.model, rec, [(target, k) if k is not None else target],
                        repeats=repeats)
    k = k or 0
    finite = bool(np.all(np.isfinite(yhat[k:])))
    validation = validate(target.y[k:], yhat[k:] if finite else np.zeros(target.n - k),
                          target.fs)
    warnings_ = list(result.info.get("warnings", []))
    warnings_ += [f"on the validation input: {p}" for p in problems]
    warnings_ += baselines.notes
    if not finite:
        warnings_.append("the model diverges on the validation input; its figures are not "
                         "reported")
    return {
        "model": result.info.get("model", getattr(args, "model", None) or "duhem"),
        "method": result.method,
        "params": result.params,
        "u_rest": getattr(result.model, "u_rest", 0.0),
        "offset": getattr(result.model, "offset", 0.0),
        "units": dict(rec.units),
        "structure": getattr(result.model.structure, "__dict__", {}),
        "validation": validation.to_dict() if finite else None,
        "validated_on": ("validation record" if getattr(args, "val", None) else
                         f"held-out end of the record (samples {k}..{target.n - 1})" if k
                         else "identification record"),
        "zeroed_on": ("the output at rest at the start of the validation record (a sensor's "
                      "zero moves between records)" if val is not None else
                      "the offset identified (the held-out part shares the record's zero)"),
        "baselines": baselines.to_dict(),
        "beats_baselines": baselines.beats_baselines,
        "warnings": warnings_,
        "converged_at": result.converged_at,
        "settings": {k_: v for k_, v in result.settings.items() if cli_support.jsonable(v)},
        "record": {"name": rec.name, "samples": rec.n, "fs": rec.fs},
        "info": {k_: v for k_, v in result.info.items() if cli_support.jsonable(v)},
    }, yhat, target


def _write_history(path: str, result) -> None:
    """Write the parameter history as CSV (atomically; its folder is created when missing)."""
    from .safeio import atomic_open

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


# --------------------------------------------------------------------------- commands
def cmd_simulate(args: argparse.Namespace) -> int:
    """``hystid simulate``: a record from the built-in reference stage or from a saved model.

    Parameters
    ----------
    args : argparse.Namespace
        The parsed command line.

    Returns
    -------
    int
        The exit status (0).
    """
    progress = Progress(args.quiet)
    inputs = tuple(p for p in (args.model, args.input) if p)
    out = _check_file(args.out, "--out", args, inputs)
    if out.suffix.lower() not in _RECORD_SUFFIXES:
        raise CommandError(f"--out {out}: expected a .csv, .npz, .mat, .h5 or .hdf5 file name")
    if args.model is None:
        rec = _reference_stage_record(args)
    else:
        rec = _model_record(args, progress)
    rec.save(out)
    progress.say(f"wrote {out}: {rec.n} samples at {rec.fs:g} Hz, y in "
                 f"[{rec.y.min():.4g}, {rec.y.max():.4g}] {rec.units.get('y', '')}")
    return 0


def _reference_stage_record(args: argparse.Namespace):
    """The built-in stage excited like the paper (``--seconds``, ``--seed``, ``--noise``)."""
    from .reference import reference_record

    for option, value in (("--input", args.input), ("--columns", args.columns),
                          ("--fs", args.fs)):
        if value is not None:
            raise CommandError(f"{option} applies to --model only (simulate a saved model on a "
                               "record's input)")
    missing = [o for o, v in (("--seconds", args.seconds), ("--seed", args.seed)) if v is None]
    if missing:
        raise CommandError(f"{' and '.join(missing)} required to simulate the built-in stage "
                           "(or give --model M --input REC)")
    noise = 1e-3 if args.noise is None else args.noise
    cli_support.check_seconds(args.seconds, 2, 30_000.0)
    return reference_record(args.seconds, seed=args.seed, noise=noise,
                            name=f"reference stage seed {args.seed}")


def _model_record(args: argparse.Namespace, progress: Progress):
    """A saved model (``--model``) simulated on a record's input (``--input``)."""
    from .modelfile import ModelFileError, load_model
    from .records import Record, RecordError

    if args.input is None:
        raise CommandError("--model needs --input REC: the record whose input u is simulated")
    if args.seconds is not None:
        raise CommandError("--seconds applies to the built-in stage only; with --model the "
                           "input record sets the length")
    if args.noise and args.seed is None:
        raise CommandError("--noise needs --seed with --model (every random figure takes a "
                           "seed)")
    try:
        model = load_model(args.model)
    except ModelFileError as err:
        raise CommandError(f"--model {err}") from err
    rec = _load(args.input, args.fs, args.columns, units=args.units)
    cli_support.check_model_on(model, rec)
    if not np.isclose(rec.fs, model.fs, rtol=1e-9):
        raise CommandError(f"--input {args.input}: sampled at {rec.fs:g} Hz but the model at "
                           f"{model.fs:g} Hz (expected the model's rate)")
    from .operating import AdmissibilityWarning

    with warnings.catch_warnings():  # the reasons are in resp.warnings, printed below
        warnings.simplefilter("ignore", AdmissibilityWarning)
        resp = model.simulate(rec.u)
    for reason in resp.warnings:
        progress.say(f"warning: {reason}")
    if not np.all(np.isfinite(resp.y)):
        raise CommandError(f"--model {args.model}: the simulation diverges on the input of "
                           f"{args.input} (condition 8 fails); nothing written")
    y = resp.y
    if args.noise:
        y = y + np.random.default_rng(args.seed).normal(0.0, args.noise, len(y))
    try:
        return Record(rec.u, y, model.fs, units=model.units,
                      name=f"{model.name} on {rec.name}")
    except RecordError as err:  # pragma: no cover - checked above
        raise CommandError(str(err)) from err


def cmd_identify(args: argparse.Namespace) -> int:
    """``hystid identify``: identify a record, validate, print or write JSON.

    Parameters
    ----------
    args : argparse.Namespace
        The parsed command line.

    Returns
    -------
    int
        The exit status (0).
    """
    from .safeio import dumps_strict

    progress = Progress(args.quiet or args.json)
    inputs = (args.record, args.val, *(args.repeat or []))
    _check_identify_outputs(args, inputs)
    _method_arg(args)
    span = _crop_arg(args)
    structure = _structure_arg(args)
    rec = _cropped(_load(args.record, args.fs, args.columns, units=args.units), span)
    val = (_cropped(_load(args.val, args.fs, args.columns, "--val", args.units), span)
           if args.val else None)
    repeats = [_cropped(_load(p, args.fs, args.columns, "--repeat", args.units), span)
               for p in args.repeat or []]
    for other, label in [(val, f"--val {args.val}")] + [
            (r, f"--repeat {p}") for r, p in zip(repeats, args.repeat or [], strict=True)]:
        if other is not None and not np.isclose(other.fs, rec.fs, rtol=1e-9):
            raise CommandError(f"{label}: fs {other.fs:g} Hz differs from {rec.fs:g} Hz "
                               f"of {args.record}")
    train, target, scored_from = _split_for_validation(rec, val, args)
    _check_skip(args, train, structure)
    progress.say(f"identifying {args.record}: {train.n} samples at {rec.fs:g} Hz")
    try:
        with warnings.catch_warnings():  # the fit's own checks report what these would mean
            warnings.filterwarnings("ignore", NUMERIC_NOISE, RuntimeWarning)
            result = _identify_record(train, args, progress, structure)
        floor_set = [target, *repeats] if repeats else None
        report, yhat, target = _report(result, train, target if val is not None or scored_from
                                       is not None else None, args, scored_from, floor_set)
    except ValueError as err:
        raise CommandError(str(err)) from err
    for w in report["warnings"]:
        if not args.json:
            print(f"hystid identify: warning: {cli_support.for_cli(w)}", file=sys.stderr)
    if args.out:
        from .modelfile import make_provenance

        provenance = make_provenance(result.method, args.record, result.settings)
        _write_outputs(Path(args.out), report, target, yhat, result, provenance=provenance,
                       scored_from=scored_from or 0)
    if args.history:
        _write_history(args.history, result)
    if args.json:
        print(dumps_strict(report))
    else:
        rows, yu = [[k, f"{v:.6g}"] for k, v in report["params"].items()], rec.units.get("y", "")
        rows += [[f"{k} [{rec.units.get(x, '')}]", f"{report[k]:.6g}"]
                 for k, x in (("u_rest", "u"), ("offset", "y"))]
        print(cli_support.table(rows, ["parameter", "estimate"]))
        _print_choice(result.info.get("member_selection"), rec.units.get("y", ""))
        v = report["validation"]
        if v is not None:
            print(f"\nvalidation ({report['validated_on']}): error {v['err_min']:.4g} .. "
                  f"{v['err_max']:.4g} {yu}, RMS {v['rms']:.4g} {yu}, fit {v['fit_percent']:.2f} %")
        b = report["baselines"]
        for row in b["rows"]:
            model_rms = "diverged" if row["model"] is None else f"{row['model']:.4g}"
            print(f"held-out RMS [{rec.units.get('y', '')}]: model {model_rms}, static line "
                  f"{row['static_line']:.4g}, linear model {row['linear']:.4g}"
                  + ("" if row["beats"] else "  -> the hysteresis model does NOT beat them"))
        if b["repeat_floor"] is not None:
            print(f"repeat floor (no deterministic model beats it): {b['repeat_floor']:.4g} {yu}")
        if report["converged_at"] is not None:
            print(f"converged at sample {report['converged_at']}")
    return 0


def _print_choice(selection: dict | None, unit: str) -> None:
    """The member choice of ``--model auto``: every candidate and baseline on the held-out
    end of the identification record."""
    if not selection:
        return
    rows = [[c["member"], str(c["n_params"]), f"{c['heldout_rms']:.4g} {unit}",
             "chosen" if c["chosen"] else ""] for c in selection["candidates"]]
    rows += [[b.replace("_", " "), "", f"{v:.4g} {unit}", "baseline"]
             for b, v in selection["baselines"].items()]
    print(f"\nmodel choice (held-out samples {selection['holdout_from']}.."
          f"{selection['holdout_to'] - 1} of the identification record; a richer member must "
          f"be {100 * selection['margin']:.0f} % better):")
    print(cli_support.table(rows, ["member", "parameters", "held-out RMS", ""]))


def _write_outputs(out: Path, report: dict, target, yhat, result, truth=None,
                   provenance: dict | None = None, seed: int | None = None,
                   scored_from: int = 0) -> None:
    """Write report.json, model.json and the figures into ``out``, all or none of them.

    The files are written into a staging folder and moved in place once all are written
    (:func:`hystid.safeio.atomic_folder`): a failure midway leaves ``out`` as it was. The
    validation figure shows the samples the validation figures were computed on: from
    ``scored_from`` (a held-out end of the record) less the transient.
    """
    from .metrics import plot_convergence, plot_validation
    from .modelfile import save_model
    from .safeio import atomic_folder, write_json

    model = result.model
    units = {"u": target.units.get("u", ""), "y": target.units.get("y", "")}
    report = {
        **report,
        "units": {**units, "validation": units["y"], "u_rest": units["u"],
                  "offset": units["y"], "time": "s", "fs": "Hz"},
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


def cmd_demo(args: argparse.Namespace) -> int:
    """``hystid demo``: the main job on the built-in reference stage.

    Parameters
    ----------
    args : argparse.Namespace
        The parsed command line.

    Returns
    -------
    int
        The exit status (0).
    """
    from .identify import METHODS, identify, min_samples
    from .metrics import validate
    from .reference import PAPER_PARAMS, reference_model, reference_record

    progress = Progress(args.quiet)
    _check_dir(args.out, args)
    cli_support.check_seconds(args.seconds, max(min_samples(m) for m in METHODS), 30_000.0)
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
    print(cli_support.table(params, ["parameter", "truth", *methods]))
    print()
    print(cli_support.table(rows, ["method", "max param err", "converged at", "restarts",
                        "val error [nm]", "RMS [nm]", "fit %", "time [s]"]))
    print("batch: off-line output error; online: hystid's recursive identifier; eria: the "
          "paper's recursion as published (see README, method)")
    result, yhat = results.get("online", results["batch"])
    report["validation_of"] = result.method
    report["truth_simulated_rms_um"] = float(np.sqrt(np.mean((truth.simulate(val.u).y
                                                               - val.y) ** 2)))
    from .modelfile import make_provenance

    report["noise_um"] = args.noise
    _write_outputs(out, {"model": "duhem", "method": result.method,
                         "validation": report["methods"][result.method]["validation"],
                         **report}, val, yhat, result, truth=PAPER_PARAMS,
                   provenance=make_provenance(result.method, settings=result.settings),
                   seed=args.seed)
    print(f"\nreport written to {out}/report.json, model to {out}/model.json (figures: "
          "validation.png"
          f"{', convergence.png' if result.history is not None else ''})")
    return 0


_seconds = number(0.0, MAX_SECONDS, strict_minimum=True)
_seed = integer(0, 2**63 - 1)


def build_parser(only: str | None = None) -> argparse.ArgumentParser:
    """The argument parser of the ``hystid`` command.

    Parameters
    ----------
    only : str, optional
        Give the options of ``diagnose`` and ``fleet`` only when this is that command (the
        others keep their one-line help), so that ``hystid --help`` does not load their
        modules; every command in full by default.

    Returns
    -------
    argparse.ArgumentParser
        The parser; each command sets ``func``.
    """
    parser = OneLineParser(
        prog="hystid",
        description="Identify piezo-driven positioning stages (L1-Duhem-L2 sandwich).",
    )
    parser.add_argument("--version", action="version", version=f"hystid {__version__}")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")

    p = sub.add_parser("demo", help="identify the built-in reference stage and report",
                       description="Make a record from the built-in reference stage (the paper's "
                       "eqs. 26-28 at 30 kHz), identify it, validate on a second record and write "
                       "a short report (JSON + PNG).")
    p.add_argument("--out", type=_path, default="hystid-demo",
                   help="report folder (default: hystid-demo)")
    p.add_argument("--force", action="store_true", help="replace files already in --out")
    p.add_argument("--seconds", type=_seconds, default=1.0,
                   help=f"length of each record in seconds (default 1.0, at most {MAX_SECONDS:g})")
    p.add_argument("--seed", type=_seed, default=0, help="random seed (default 0)")
    p.add_argument("--noise", type=_non_negative_float, default=1e-3,
                   help="sensor noise standard deviation in um (default 0.001 = 1 nm)")
    p.add_argument("--quiet", action="store_true", help="no progress lines")
    p.set_defaults(func=cmd_demo)

    p = sub.add_parser("simulate", help="write a record from the reference stage or a model",
                       description="Simulate the reference stage with the paper's excitation "
                       "(starting at rest; --seconds, --seed) or a saved model on the input of a "
                       "record (--model, --input), and write the record (u, y).")
    p.add_argument("--seconds", type=_seconds, default=None,
                   help=f"record length [s] of the built-in stage (at most {MAX_SECONDS:g})")
    p.add_argument("--seed", type=_seed, default=None, help="random seed")
    p.add_argument("--noise", type=_non_negative_float, default=None,
                   help="sensor noise standard deviation in the output's units (default 0.001 um "
                   "for the built-in stage, none for --model)")
    p.add_argument("--model", type=_path, default=None, metavar="MODEL.json",
                   help="a saved model (hystid identify --out writes DIR/model.json)")
    p.add_argument("--input", type=_path, default=None, metavar="REC",
                   help="record whose input u drives --model")
    p.add_argument("--fs", type=_positive(float), default=None,
                   help="sampling rate of --input in Hz (if it has no t column or fs)")
    p.add_argument("--columns", type=_columns_arg, metavar="t=1,u=3,y=2",
                   help="where t, u and y are in --input (names or 0-based positions)")
    p.add_argument("--units", type=_units_arg, metavar="u=V,y=um", help=UNITS_HELP)
    p.add_argument("--out", type=_path, required=True, help="output file (.csv, .npz, .mat, .h5)")
    p.add_argument("--force", action="store_true", help="replace --out if it exists")
    p.add_argument("--quiet", action="store_true", help="no progress lines")
    p.set_defaults(func=cmd_simulate)

    p = sub.add_parser("identify", help="identify a record",
                       description="Identify a sandwich model from a record (CSV with a header "
                       "naming u, y and optionally t; .npz, .mat, .h5) and validate it.")
    p.add_argument("record", type=_path, help="record file")
    p.add_argument("--fs", type=_positive(float), help="sampling rate in Hz (if no t column)")
    p.add_argument("--val", type=_path,
                   help="validation record (default: the last --holdout share of the record)")
    p.add_argument("--columns", type=_columns_arg, metavar="t=1,u=3,y=2",
                   help="where t, u and y are in the files (names or 0-based positions)")
    p.add_argument("--units", type=_units_arg, metavar="u=V,y=um", help=UNITS_HELP)
    p.add_argument("--model", choices=("auto", *MODEL_NAMES), default=None,
                   help="member of the model family (default: auto, the simplest member that "
                   "no richer one beats on the record's held-out end; duhem when --structure "
                   "or an on-line --method is given)")
    p.add_argument("--method", choices=("eria", "online", "ekf", "batch"), default=None,
                   help="estimator (default: batch; online for --model pi)")
    p.add_argument("--structure", default=None, metavar="auto|n1a=1,n2a=2,...",
                   help="model structure: keys n1a, n1b, n2a, n2b, q1, q2, f0 (the paper's "
                   "experimental one by default), or 'auto' to choose on held-out error")
    p.add_argument("--crop", default=None, metavar="START:STOP",
                   help="keep only this time span of every record, in seconds")
    p.add_argument("--offset", choices=("estimate", "none"), default=None,
                   help="batch fit: estimate the sensor offset (default) or take the output as "
                   "zero at rest")
    p.add_argument("--skip", type=_non_negative_float, default=None, metavar="S",
                   help="seconds at the start simulated but left out of the fit (default: none "
                   "for a record that starts at rest, else until the input has swept its range)")
    p.add_argument("--holdout", type=_holdout_fraction, default=0.4, metavar="F",
                   help="without --val, the share of the record held out at its end for "
                   "validation (default 0.4; 0 validates on the record itself)")
    p.add_argument("--repeat", type=_path, nargs="+", default=None, metavar="REC",
                   help="records of the same input as the validation record: their "
                   "repeat-to-repeat RMS is the floor no deterministic model can beat")
    p.add_argument("--history", type=_path,
                   help="write the parameter history of an on-line method (CSV: k, one column "
                   "a parameter); may lie in --out but never be one of its files")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.add_argument("--out", type=_path, help="folder for report.json, model.json and figures")
    p.add_argument("--force", action="store_true",
                   help="replace --history and files already in --out")
    p.add_argument("--quiet", action="store_true", help="no progress lines")
    p.set_defaults(func=cmd_identify)

    p = sub.add_parser("diagnose", help="diagnose the sim-to-real gap",
                       description="Localise the model error, screen unmodelled effects and "
                       "measure how far each closes the gap on held-out data.")
    if only in (None, "diagnose"):
        from .diagnose import command as diagnose_command

        diagnose_command.configure_parser(p)
        p.set_defaults(func=diagnose_command.run)

    p = sub.add_parser("compensate", help="the command that makes a saved model follow a "
                       "reference", description="Compute the compensated command (inverse "
                       "model) for a reference displacement or a scan, in the record's units, "
                       "and write t,r,u,y_pred to a CSV.")
    if only in (None, "compensate"):
        from .compensate import command as compensate_command

        compensate_command.configure_parser(p)
        p.set_defaults(func=compensate_command.run)

    p = sub.add_parser("fleet", help="identify or diagnose many records on Dask",
                       description="Identify or diagnose many records as Dask tasks; one result "
                       "row per record (CSV and Parquet), resumable.")
    if only in (None, "fleet"):
        from . import fleet_command

        fleet_command.configure_parser(p)
        p.set_defaults(func=fleet_command.run)

    p = sub.add_parser("export", help="a saved model as C99 (model, compensator, RPEM step)")
    if only in (None, "export"):
        from .export import command as export_command

        export_command.configure_parser(p)
        p.set_defaults(func=export_command.run)
    return parser


def _command_word(argv: list[str]) -> str:
    """The command named on a command line (the first word not an option), or ``""``."""
    return next((a for a in argv if not a.startswith("-")), "")


def main(argv: list[str] | None = None) -> int:
    """Entry point of the ``hystid`` command; returns the exit status.

    Parameters
    ----------
    argv : list of str, optional
        The arguments (``sys.argv[1:]`` by default).

    Returns
    -------
    int
        0 on success, 2 on bad input or a failed write, 130 when interrupted.
    """
    argv = sys.argv[1:] if argv is None else [str(a) for a in argv]
    parser = build_parser(only=_command_word(argv))
    args = parser.parse_args(argv)
    return cli_support.run_command(args)

if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
