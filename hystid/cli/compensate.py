"""``hystid compensate``: the command that makes a saved model follow a reference.

``hystid compensate MODEL (--reference REC | --scan KIND:HZ:AMP) --out U.csv [--force]``
computes the compensated command with :func:`~hystid.compensate.compensate` and writes a CSV
with the header ``t,r,u,y_pred`` (time, reference, command, the model's predicted output), a
comment line above it naming the model and the units. ``--reference`` takes the reference from
the ``y`` of a record (a measured displacement, in the record's units); ``--scan
triangle:50:2`` makes a scan of 2 output units peak to peak at 50 Hz about the model's output at
rest, reached from rest. Bad input gives one line on stderr and exit status 2 before any work;
an existing ``--out`` is replaced only with ``--force``, and atomically.
"""

from __future__ import annotations

import argparse
import warnings
from pathlib import Path
from typing import Any

import numpy as np

from ..options import MAX_SECONDS
from .support import CommandError, as_option, bind, check_out, refused, run_command, tell

__all__ = ["HEADER", "configure_parser", "parse_scan", "run", "scan_for"]

#: Columns of the written CSV.
HEADER = ("t", "r", "u", "y_pred")
#: Seconds at rest before a scan's approach, and of the approach itself.
SCAN_REST, SCAN_LEAD_IN = 0.01, 0.01


def parse_scan(text: str) -> tuple[str, float, float]:
    """Read ``KIND:HZ:AMP`` (``triangle:50:2``) of ``--scan``.

    Parameters
    ----------
    text : str
        Waveform (``triangle`` or ``sine``), frequency in Hz and peak-to-peak amplitude in the
        model's output units, separated by colons.

    Returns
    -------
    (str, float, float)
        Kind, frequency and amplitude.

    Raises
    ------
    ValueError
        Naming what is wrong.
    """
    parts = text.split(":")
    if len(parts) != 3:
        raise ValueError(f"expected KIND:HZ:AMP such as triangle:50:2, got {text!r}")
    kind = parts[0].strip().lower()
    if kind not in ("triangle", "sine"):
        raise ValueError(f"KIND: expected triangle or sine, got {parts[0]!r}")
    values = []
    for label, raw in (("HZ", parts[1]), ("AMP", parts[2])):
        try:
            value = float(raw)
        except ValueError:
            raise ValueError(f"{label}: expected a number, got {raw!r}") from None
        if not (np.isfinite(value) and value > 0):
            raise ValueError(f"{label}: expected a positive number, got {raw!r}")
        values.append(value)
    return kind, values[0], values[1]


def scan_for(model: Any, kind: str, frequency: float, amplitude: float,
             seconds: float) -> np.ndarray:
    """A scan about the model's output at rest, reached from rest, in the record's units.

    Parameters
    ----------
    model : placed model
        The model (its rate and output at rest).
    kind : {"triangle", "sine"}
        Waveform.
    frequency : float
        Hz.
    amplitude : float
        Peak to peak, in the model's output units, centred on the output at rest.
    seconds : float
        Length of the scan after the approach.

    Returns
    -------
    ndarray
        The reference, starting at the model's output at rest.
    """
    from ..compensate.placed import _rest
    from ..compensate.tracking import scan_reference

    if frequency >= model.fs / 2:
        raise ValueError(f"HZ: {frequency:g} Hz is not below half the model's rate "
                         f"({model.fs / 2:g} Hz)")
    scan = scan_reference(kind, frequency, fs=model.fs, periods=seconds * frequency,
                          low=-amplitude / 2, high=amplitude / 2, lead_in=SCAN_LEAD_IN,
                          rest=SCAN_REST)
    return scan.y + float(model.offset) + _rest(model)[1]


def configure_parser(parser: argparse.ArgumentParser) -> None:
    """Add the ``compensate`` arguments to ``parser``.

    Parameters
    ----------
    parser : argparse.ArgumentParser
        The sub-command's parser.
    """
    parser.description = ("Compute the compensated command (inverse model) for a reference "
                          "displacement or a scan, in the record's units, and write t,r,u,y_pred "
                          "to a CSV.")
    parser.add_argument("model", metavar="MODEL",
                        help="a saved model (hystid identify --out writes DIR/model.json)")
    source = parser.add_mutually_exclusive_group(required=True)
    source.add_argument("--reference", metavar="REC",
                        help="record whose y is the reference (csv, npz, mat, h5), in the "
                        "model's units and rate")
    source.add_argument("--scan", metavar="KIND:HZ:AMP",
                        help="a triangle or sine scan, e.g. triangle:50:2 (AMP peak to peak in "
                        "the model's output units, about its output at rest)")
    parser.add_argument("--seconds", default="1", metavar="S",
                        help=f"length of a --scan in seconds (default 1, at most "
                        f"{MAX_SECONDS:g})")
    parser.add_argument("--fs", default=None, metavar="HZ",
                        help="sampling rate of --reference (if it has no t column or fs)")
    parser.add_argument("--columns", default=None, metavar="t=1,u=3,y=2",
                        help="where t, u and y are in --reference (names or 0-based positions)")
    parser.add_argument("--units", default=None, metavar="u=V,y=um",
                        help="units of --reference (default: those stored in it, else V and um)")
    parser.add_argument("--limits", default=None, metavar="LOW:HIGH",
                        help="command limits in the model's input units (default: the "
                        "identified input range widened by --margin)")
    parser.add_argument("--margin", default="0.1", metavar="F",
                        help="share of the identified input span added at each end of the "
                        "default limits (default 0.1)")
    parser.add_argument("--smooth", default=None, metavar="L",
                        help="ask for the reference smoothed over L samples (odd, >= 3) without "
                        "lag: advisable for measured displacements (their noise would dither "
                        "the hysteresis inverse) and for corners")
    parser.add_argument("--anchor", choices=("model", "reference"), default="model",
                        help="the stage rests at the model's output at rest (default) or at the "
                        "reference's first sample (a sensor zero that moved)")
    parser.add_argument("--out", required=True, metavar="U.csv",
                        help="CSV to write: t,r,u,y_pred")
    parser.add_argument("--force", action="store_true", help="replace --out if it exists")
    parser.add_argument("--quiet", action="store_true", help="no summary line")
    bind(parser, run)


def run(args: argparse.Namespace) -> int:
    """Run ``hystid compensate``; returns the exit status (2 for bad input).

    Parameters
    ----------
    args : argparse.Namespace
        Parsed arguments (see :func:`configure_parser`).

    Returns
    -------
    int
        0 on success, 2 for bad input or a failed write.
    """
    return run_command(args, _compensate)


def _number(text: str, option: str, *, minimum: float, strict: bool) -> float:
    try:
        value = float(text)
    except ValueError:
        raise CommandError(f"{option}: expected a number, got {text!r}") from None
    if not np.isfinite(value) or value < minimum or (strict and value == minimum):
        raise CommandError(f"{option}: expected a number {'>' if strict else '>='} {minimum:g}, "
                        f"got {text!r}")
    return value


def _limits(text: str | None) -> tuple[float, float] | None:
    if text is None:
        return None
    parts = text.split(":")
    try:
        low, high = (float(p) for p in parts)
    except ValueError:
        raise CommandError(f"--limits: expected LOW:HIGH such as -100:80, got {text!r}") \
            from None
    if not (np.isfinite(low) and np.isfinite(high) and low < high):
        raise CommandError(f"--limits: expected finite LOW < HIGH, got {text!r}")
    return low, high


def _load_model(path: str) -> Any:
    from ..modelfile import load_model

    with refused(f"MODEL {path}: ", errors=(OSError, ValueError)):  # a ModelFileError too
        return load_model(path)


def _reference(args: argparse.Namespace, model: Any) -> tuple[np.ndarray, str]:
    """The reference and a label for it."""
    if args.scan is not None:
        with refused("--scan: "):
            kind, hz, amp = parse_scan(args.scan)
        seconds = _number(args.seconds, "--scan: --seconds", minimum=0.0, strict=True)
        if seconds > MAX_SECONDS:
            raise CommandError(f"--seconds {args.seconds}: a scan of at most {MAX_SECONDS:g} s "
                               "is made (expected a shorter --seconds)")
        with refused("--scan: "):
            return scan_for(model, kind, hz, amp, seconds), f"scan {args.scan}"
    from ..errors import RecordError
    from ..records import load_record, parse_columns, parse_units

    with refused("--columns/--units: "):
        columns = parse_columns(args.columns) if args.columns is not None else None
        units = parse_units(args.units) if args.units is not None else None
    fs = None if args.fs is None else _number(args.fs, "--fs", minimum=0.0, strict=True)
    with refused("--reference ", errors=RecordError):
        rec = load_record(args.reference, fs=fs, columns=columns, units=units)
    if not np.isclose(rec.fs, model.fs, rtol=1e-6):
        raise CommandError(f"--reference {args.reference}: sampled at {rec.fs:g} Hz, the model "
                           f"at {model.fs:g} Hz (expected the model's rate)")
    unit = model.units.get("y")
    if rec.units.get("y") != unit:
        raise CommandError(f"--reference {args.reference}: y is in {rec.units.get('y')!r}, the "
                           f"model's output in {unit!r} (give --units, or a record in the "
                           "model's units)")
    return rec.y, f"y of {args.reference}"


def _write(path: Path, result: Any, model_path: str, label: str) -> None:
    from ..safeio import atomic_open

    units = {"t": "s", "r": result.units.get("y", ""), "u": result.units.get("u", ""),
             "y_pred": result.units.get("y", "")}
    data = np.column_stack([result.t, result.r, result.u, result.y_pred])
    with atomic_open(path, "w", newline="") as handle:
        handle.write(f"# hystid compensate: model={model_path}, reference={label}, "
                     f"preview={result.preview}, units "
                     + " ".join(f"{k}={v}" for k, v in units.items()) + "\n")
        handle.write(",".join(HEADER) + "\n")
        np.savetxt(handle, data, delimiter=",", fmt="%.17g")


def _compensate(args: argparse.Namespace) -> None:
    """``hystid compensate``'s steps (see :func:`run`)."""
    from ..compensate.linear_parts import smoothing_model
    from ..compensate.placed import compensate

    with refused():  # a model that cannot be inverted, a reference it cannot follow
        out = check_out(args, args.out, inputs=(args.model, args.reference))
        if out.suffix.lower() != ".csv":
            raise CommandError(f"--out {out}: expected a .csv file")
        margin = _number(args.margin, "--margin", minimum=0.0, strict=False)
        limits = _limits(args.limits)
        model = _load_model(args.model)
        y_ref, label = _reference(args, model)
        smoother = None
        if args.smooth is not None:
            try:
                window = int(args.smooth)
            except ValueError:
                raise CommandError(f"--smooth: expected an odd whole number of samples >= 3, "
                                   f"got {args.smooth!r}") from None
            try:
                smoother = smoothing_model(window, model.dt)
            except ValueError as err:  # even, shorter than 3 samples, longer than 1 s
                raise CommandError(as_option(str(err), {"samples": "--smooth"})) from err
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            result = compensate(model, y_ref, u_limits=limits, margin=margin,
                                reference_model=smoother, anchor=args.anchor)
    with refused(f"--out {out}: ", "; a file already there is left as it was", errors=OSError):
        _write(out, result, args.model, label)
    if not args.quiet:
        for note in result.warnings:
            tell(args, note, "warning")
        u_unit, y_unit = result.units.get("u", ""), result.units.get("y", "")
        print(f"{out}: {result.u.size} samples, command {result.u.min():.4g} .. "
              f"{result.u.max():.4g} {u_unit} (limits {result.u_limits[0]:.4g} .. "
              f"{result.u_limits[1]:.4g}), predicted output within "
              f"{np.max(np.abs(result.y_pred - result.y_des)):.3g} {y_unit} of the asked one, "
              f"{100 * np.mean(result.exact):.1f} % exact samples")
