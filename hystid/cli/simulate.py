"""``hystid simulate``: a record from the built-in reference stage or from a saved model.

``hystid simulate --seconds S --seed N [--noise SD] --out REC`` excites the reference stage
(the paper's eqs. 26-28 at 30 kHz) from rest with the paper's excitation; ``hystid simulate
--model MODEL.json --input REC [--noise SD --seed N] --out REC`` drives a saved model with the
input of a record, started as the accuracy figures start it
(:func:`hystid.baselines.simulate_from_rest`: from the model's rest at the record's first
input, a record in motion from its mean level, a model identified on a record that did not
begin at rest from its loop's centre). The record (u, y) is written as CSV, NumPy, MATLAB or
HDF5 by its suffix.
"""

from __future__ import annotations

import argparse
import warnings
from typing import TYPE_CHECKING

import numpy as np

from ..options import MAX_SECONDS
from .support import (
    UNITS_HELP,
    CommandError,
    Progress,
    bind,
    check_model_on,
    check_out,
    check_seconds,
    columns_arg,
    file_arg,
    load,
    non_negative_arg,
    positive_arg,
    refused,
    run_command,
    seconds_arg,
    seed_arg,
    units_arg,
)

if TYPE_CHECKING:  # pragma: no cover
    from ..records import Record

__all__ = ["RECORD_SUFFIXES", "configure_parser", "run"]

#: Suffixes of the record files ``--out`` may name.
RECORD_SUFFIXES = (".csv", ".npz", ".mat", ".h5", ".hdf5")


def configure_parser(parser: argparse.ArgumentParser) -> None:
    """Add the arguments of ``hystid simulate`` to ``parser``.

    Parameters
    ----------
    parser : argparse.ArgumentParser
        The command's parser.
    """
    parser.description = ("Simulate the reference stage with the paper's excitation (starting "
                          "at rest; --seconds, --seed) or a saved model on the input of a "
                          "record (--model, --input), and write the record (u, y).")
    p = parser
    p.add_argument("--seconds", type=seconds_arg, default=None,
                   help=f"record length [s] of the built-in stage (at most {MAX_SECONDS:g})")
    p.add_argument("--seed", type=seed_arg, default=None, help="random seed")
    p.add_argument("--noise", type=non_negative_arg, default=None,
                   help="sensor noise standard deviation in the output's units (default 0.001 um "
                   "for the built-in stage, none for --model)")
    p.add_argument("--model", type=file_arg, default=None, metavar="MODEL.json",
                   help="a saved model (hystid identify --out writes DIR/model.json)")
    p.add_argument("--input", type=file_arg, default=None, metavar="REC",
                   help="record whose input u drives --model")
    p.add_argument("--fs", type=positive_arg(float), default=None,
                   help="sampling rate of --input in Hz (if it has no t column or fs)")
    p.add_argument("--columns", type=columns_arg, metavar="t=1,u=3,y=2",
                   help="where t, u and y are in --input (names or 0-based positions)")
    p.add_argument("--units", type=units_arg, metavar="u=V,y=um", help=UNITS_HELP)
    p.add_argument("--out", type=file_arg, required=True,
                   help="output file (.csv, .npz, .mat, .h5)")
    p.add_argument("--force", action="store_true", help="replace --out if it exists")
    p.add_argument("--quiet", action="store_true", help="no progress lines")
    bind(parser, run)


def run(args: argparse.Namespace) -> int:
    """Run ``hystid simulate``.

    Parameters
    ----------
    args : argparse.Namespace
        Parsed arguments (see :func:`configure_parser`).

    Returns
    -------
    int
        0 on success, 2 on bad input or a failed write.
    """
    return run_command(args, _simulate)


def _simulate(args: argparse.Namespace) -> None:
    """``hystid simulate``'s steps (see :func:`run`)."""
    progress = Progress(args.quiet)
    out = check_out(args, args.out, inputs=(args.model, args.input))
    if out.suffix.lower() not in RECORD_SUFFIXES:
        raise CommandError(f"--out {out}: expected a .csv, .npz, .mat, .h5 or .hdf5 file name")
    if args.model is None:
        rec = _reference_stage_record(args)
    else:
        rec = _model_record(args, progress)
    rec.save(out)
    progress.say(f"wrote {out}: {rec.n} samples at {rec.fs:g} Hz, y in "
                 f"[{rec.y.min():.4g}, {rec.y.max():.4g}] {rec.units.get('y', '')}")


def _reference_stage_record(args: argparse.Namespace) -> Record:
    """The built-in stage excited like the paper (``--seconds``, ``--seed``, ``--noise``)."""
    from ..reference import reference_record

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
    check_seconds(args.seconds, 2, 30_000.0)
    return reference_record(args.seconds, seed=args.seed, noise=noise,
                            name=f"reference stage seed {args.seed}")


def _model_record(args: argparse.Namespace, progress: Progress) -> Record:
    """A saved model (``--model``) simulated on a record's input (``--input``), started as every
    accuracy figure starts it (:func:`~hystid.baselines.simulate_from_rest`)."""
    from ..baselines import simulate_from_rest
    from ..errors import AdmissibilityWarning, ModelFileError, RecordError
    from ..modelfile import load_model
    from ..records import Record

    if args.input is None:
        raise CommandError("--model needs --input REC: the record whose input u is simulated")
    if args.seconds is not None:
        raise CommandError("--seconds applies to the built-in stage only; with --model the "
                           "input record sets the length")
    if args.noise and args.seed is None:
        raise CommandError("--noise needs --seed with --model (every random figure takes a "
                           "seed)")
    with refused("--model ", errors=ModelFileError):
        model = load_model(args.model)
    rec = load(args.input, args.fs, args.columns, units=args.units)
    check_model_on(model, rec)
    if not np.isclose(rec.fs, model.fs, rtol=1e-9):
        raise CommandError(f"--input {args.input}: sampled at {rec.fs:g} Hz but the model at "
                           f"{model.fs:g} Hz (expected the model's rate)")
    with warnings.catch_warnings(record=True) as caught:  # printed below
        warnings.simplefilter("always", AdmissibilityWarning)
        with refused(f"--input {args.input}: ", errors=ValueError):
            y = simulate_from_rest(model, rec.u)
    for w in caught:
        if issubclass(w.category, AdmissibilityWarning):
            progress.say(f"warning: {w.message}")
    if not np.all(np.isfinite(y)):
        raise CommandError(f"--model {args.model}: the simulation diverges on the input of "
                           f"{args.input} (condition 8 fails); nothing written")
    if args.noise:
        y = y + np.random.default_rng(args.seed).normal(0.0, args.noise, len(y))
    with refused(errors=RecordError):  # pragma: no cover - checked above
        return Record(rec.u, y, model.fs, units=model.units,
                      name=f"{model.name} on {rec.name}")
