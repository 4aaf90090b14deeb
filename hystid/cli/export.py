"""``hystid export MODEL --c DIR``: a saved model as C99 ``DIR/hystid_model.h`` and ``.c``.

Bad input (not a model file, a folder that cannot be written, files already there without
``--force``, a compensator option the model cannot take) is one line on stderr and exit
status 2; nothing is written then.
"""

from __future__ import annotations

import argparse

from .support import CommandError, as_option, bind, run_command, tell

__all__ = ["configure_parser", "run"]


def _limits(text: str) -> tuple[float, float]:
    try:
        low, high = (float(v) for v in text.split(","))
    except ValueError as err:
        raise argparse.ArgumentTypeError(f"expected LOW,HIGH (two numbers), got {text!r}") \
            from err
    if not low < high:
        raise argparse.ArgumentTypeError(f"expected LOW < HIGH, got {text!r}")
    return low, high


def _samples(text: str) -> int:
    try:
        value = int(text)
    except ValueError as err:
        raise argparse.ArgumentTypeError(f"expected a whole number of samples, got {text!r}") \
            from err
    if value < 0:
        raise argparse.ArgumentTypeError(f"expected at least 0, got {text!r}")
    return value


def _share(text: str) -> float:
    try:
        value = float(text)
    except ValueError as err:
        raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from err
    if not 0 <= value < float("inf"):
        raise argparse.ArgumentTypeError(f"expected a share >= 0, got {text!r}")
    return value


def _window(text: str) -> int:
    value = _samples(text)
    if value < 3 or value % 2 == 0:
        raise argparse.ArgumentTypeError(f"expected an odd window length >= 3, got {text!r}")
    return value


def _positive(text: str) -> float:
    try:
        value = float(text)
    except ValueError as err:
        raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from err
    if not value > 0 or value == float("inf"):
        raise argparse.ArgumentTypeError(f"expected a positive number, got {text!r}")
    return value


def configure_parser(parser: argparse.ArgumentParser) -> None:
    """Add the arguments of ``hystid export``.

    Parameters
    ----------
    parser : argparse.ArgumentParser
        The sub-command's parser.
    """
    parser.description = ("Write a saved model as C99 DIR/hystid_model.h and DIR/hystid_model.c: "
                          "the placed model's step, the feed-forward compensator's step and "
                          "the on-line identifier's step (no allocation, only math.h).")
    parser.add_argument("model", metavar="MODEL", help="a saved model file (hystid identify "
                        "--out writes DIR/model.json)")
    parser.add_argument("--c", dest="c_dir", required=True, metavar="DIR",
                        help="folder for hystid_model.h and hystid_model.c (created if missing)")
    parser.add_argument("--force", action="store_true", help="replace the two files in DIR")
    parser.add_argument("--u-limits", type=_limits, default=None, metavar="LOW,HIGH",
                        help="compensator: command limits in the record's units (default: the "
                        "model's input envelope widened by --margin of its span at each end)")
    parser.add_argument("--margin", type=_share, default=None, metavar="F",
                        help="compensator: share of the input envelope's span added at each end "
                        "of the default limits (default 0.1)")
    parser.add_argument("--preview", type=_samples, default=None, metavar="N",
                        help="compensator: reversal planner preview in samples (default: "
                        "compensate's)")
    parser.add_argument("--smooth", type=_window, default=None, metavar="L",
                        help="compensator: ask for the reference smoothed over L samples (odd, "
                        ">= 3) without lag, as hystid compensate --smooth (its delay adds to "
                        "HYSTID_FF_DELAY)")
    parser.add_argument("--anchor", choices=("model", "reference"), default=None,
                        help="compensator: the stage rests at the model's output at rest "
                        "(default) or at the first reference sample the step is given (a sensor "
                        "zero that moved)")
    parser.add_argument("--rpem-sigma", type=_positive, default=None, metavar="S",
                        help="on-line identifier: initial residual scale in output units "
                        "(default: 1e-3 of the model's output span)")
    parser.add_argument("--rpem-record", default=None, metavar="REC",
                        help="on-line identifier: a record of the stage for its starting "
                        "covariance and residual scale (default: the model on the paper's "
                        "excitation within its envelope)")
    parser.add_argument("--rpem-bare", action="store_true",
                        help="on-line identifier: the bare recursion by default "
                        "(HYSTID_RPEM_SUPERVISE 0), without the supervisor that rolls it back "
                        "to the last validated estimate (default: supervised, as "
                        "method='online')")
    parser.add_argument("--quiet", action="store_true", help="print nothing on success")
    bind(parser, run)


def run(args: argparse.Namespace) -> int:
    """Run ``hystid export``.

    Parameters
    ----------
    args : argparse.Namespace
        Parsed arguments (see :func:`configure_parser`).

    Returns
    -------
    int
        0 on success, 2 on bad input.
    """
    return run_command(args, _export)


def _export(args: argparse.Namespace) -> None:
    """``hystid export``'s steps (see :func:`run`): every refusal said on one line."""
    from ..export.c import export_c
    from ..modelfile import load_model

    options = {k: v for k, v in (("u_limits", args.u_limits), ("margin", args.margin),
                                 ("preview", args.preview), ("anchor", args.anchor))
               if v is not None}
    notes: list[str] = []
    record = None
    try:
        model = load_model(args.model)
        if args.smooth is not None:
            from ..compensate import smoothing_model

            options["reference_model"] = smoothing_model(args.smooth, model.dt)
        if args.rpem_record is not None:
            from ..records import load_record

            record = load_record(args.rpem_record)
        paths = export_c(model, args.c_dir, force=args.force, source=str(args.model),
                         compensator=options or None, rpem_sigma=args.rpem_sigma,
                         rpem_record=record, rpem_supervise=not args.rpem_bare, notes=notes)
    except ValueError as err:  # a ModelFileError, an OutputError, the generator's refusals
        message = _as_option(str(err))
        if record is not None and message.startswith(f"record {record.name!r}"):
            message = f"--rpem-record {args.rpem_record}: {message}"
        raise CommandError(_one_line(message)) from err
    except OSError as err:
        raise CommandError(_one_line(
            f"--c {args.c_dir}: cannot write there ({err.strerror or err}"
            f"{f': {err.filename}' if err.filename else ''}); no file was half-written")) from err
    for note in notes:
        tell(args, note, "note")
    if not args.quiet:
        print("wrote " + ", ".join(str(p) for p in paths))


#: The API's names of the compensator's and identifier's settings, as the options say them.
_OPTIONS = {"preview": "--preview", "u_limits": "--u-limits", "margin": "--margin",
            "samples": "--smooth", "sigma": "--rpem-sigma", "anchor": "--anchor"}


def _as_option(message: str) -> str:
    """A refusal of :func:`~hystid.export.c.export_c` that starts with a setting's API name
    (``preview: ...``) said with the option's (``--preview: ...``)."""
    return as_option(message, _OPTIONS)


def _one_line(message: str) -> str:
    """``message`` with its line breaks and runs of spaces as single spaces."""
    return " ".join(message.split())
