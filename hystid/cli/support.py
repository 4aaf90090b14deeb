"""What every ``hystid`` command shares, so that a command's module holds only its own steps.

* **The runner.** A command module's ``run(args)`` is :func:`run_command` over its steps:
  they raise a :class:`~hystid.errors.CommandError` (or let an
  :class:`~hystid.errors.OutputError` through) on an input they refuse, and the runner prints
  it as one line, ``hystid COMMAND: error: MESSAGE``, and returns :data:`EXIT_BAD_INPUT`; a
  failed write (:class:`OSError`) is one line too, and an interrupt is status 130.
  :func:`refused` turns an error of the library into the command's, its option named;
  :func:`bind` ties the steps to their parser.
* **Checks before work.** :func:`check_out` (the outputs, with ``--force``),
  :func:`check_seconds`, :func:`check_model_on`, and :func:`load` (a record, remembered for
  the messages).
* **Option types** shared by several commands (``type=`` for :mod:`argparse`):
  :func:`file_arg`, :func:`columns_arg`, :func:`units_arg`, :func:`positive_arg` and the
  parsers :data:`non_negative_arg`, :data:`seconds_arg`, :data:`seed_arg`.
* **What a command prints** besides its result: :func:`tell` (a warning, a note, a progress
  line in the command's name), :class:`Progress`, :func:`for_cli` (an API message as the
  command line says it), :func:`table`.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import re
import sys
import time
import warnings
from collections.abc import Callable, Iterable, Iterator
from pathlib import Path
from typing import TYPE_CHECKING, Any, NoReturn

from ..errors import CommandError
from ..options import MAX_SECONDS, integer, number

if TYPE_CHECKING:  # pragma: no cover
    from ..records import Record

__all__ = ["DEMO_KERNELS", "EXIT_BAD_INPUT", "EXIT_INTERRUPTED", "IDENTIFY_KERNELS", "RECORD_FILES",
           "UNITS_HELP", "CommandError", "OneLineParser", "Progress", "as_option", "bind",
           "check_model_on",
           "check_out", "check_seconds", "columns_arg", "file_arg", "for_cli", "jsonable",
           "kernels_cached", "load", "non_negative_arg", "one_of", "positive_arg", "refused",
           "remember", "run_command", "seconds_arg", "seed_arg", "table", "tell", "units_arg"]

#: Exit status of a refused input or a failed write.
EXIT_BAD_INPUT = 2
#: Exit status of a command interrupted (Ctrl-C).
EXIT_INTERRUPTED = 130
#: Compiled kernels every ``hystid demo`` runs, as (module, name): while one of them is not in
#: numba's cache yet, the demo says that it compiles them.
DEMO_KERNELS = (("hystid.kernels", "simulate_into"), ("hystid.kernels", "sensitivities_into"),
                ("hystid.identify.online", "rpem_run"), ("hystid.identify.eria", "eria_run"))
#: Compiled kernels the default ``hystid identify`` runs (the Duhem and PI sandwiches' fits):
#: while one of them is not in numba's cache yet, the command says that it compiles them.
IDENTIFY_KERNELS = (("hystid.kernels", "simulate_into"), ("hystid.kernels", "sensitivities_into"),
                    ("hystid.identify.pi_kernels", "pi_sensitivities_into"))
#: The file each record the command loaded came from, by the record's name.
RECORD_FILES: dict[str, str] = {}
#: Help of ``--units``.
UNITS_HELP = ("units of the input and output, e.g. u=N,y=m (default: those stored in the "
              "file, else those its CSV header names, as in cmd_mV or y [nm], else V and um; "
              "they label the numbers, the fit does not depend on them)")

#: A command's steps: the parsed command line in, the exit status out (``None`` for 0).
Steps = Callable[[argparse.Namespace], int | None]


# --------------------------------------------------------------------------- the runner
def bind(parser: argparse.ArgumentParser, run: Callable[[argparse.Namespace], int]) -> None:
    """Make ``run`` what ``parser``'s command runs, its lines said in ``parser.prog``.

    Parameters
    ----------
    parser : argparse.ArgumentParser
        The command's parser (``hystid identify``, ``hystid fleet diagnose``...).
    run : callable
        The command's ``run(args)``.
    """
    parser.set_defaults(func=run, prog=parser.prog)


def run_command(args: argparse.Namespace, steps: Steps) -> int:
    """Run a command's steps: a refused input or a failed write is one line, status 2.

    Parameters
    ----------
    args : argparse.Namespace
        The parsed command line (``args.prog`` names the command, see :func:`bind`).
    steps : callable
        The command's own steps, ``steps(args)``, returning the exit status (``None`` for 0).

    Returns
    -------
    int
        The steps' status; :data:`EXIT_BAD_INPUT` on a :class:`CommandError`, an
        :class:`~hystid.errors.OutputError` (an output refused before the work, or one that
        appeared meanwhile) or an :class:`OSError`; :data:`EXIT_INTERRUPTED` when interrupted.
    """
    from .. import safeio

    safeio._CLAIMS.clear()  # the outputs of an earlier command run in this process
    RECORD_FILES.clear()  # and the records it loaded
    try:
        with warnings.catch_warnings():
            warnings.showwarning = _one_line(args)
            return int(steps(args) or 0)
    except (CommandError, safeio.OutputError) as err:
        tell(args, str(err), "error")
        return EXIT_BAD_INPUT
    except OSError as err:  # a full disk, a folder removed meanwhile: no file was half-written
        where = f" ({err.filename})" if err.filename else ""
        tell(args, f"{err.strerror or err}{where}; no file was half-written and files that were "
             "already there are left as they were", "error")
        return EXIT_BAD_INPUT
    except KeyboardInterrupt:
        return EXIT_INTERRUPTED


def _one_line(args: argparse.Namespace) -> Callable[..., None]:
    """A :func:`warnings.showwarning` that says a Python warning raised during a command (an
    estimator's, numpy's) as the command's own line, ``hystid COMMAND: warning: MESSAGE``,
    not as Python prints it (the source file, its line, the code)."""
    def show(message: Warning | str, category: type[Warning], filename: str, lineno: int,
             file: Any = None, line: str | None = None) -> None:
        tell(args, str(message), "warning")
    return show


@contextlib.contextmanager
def refused(prefix: str = "", suffix: str = "",
            errors: type[Exception] | tuple[type[Exception], ...] = ValueError) -> Iterator[None]:
    """Say an error raised inside as the command's own: a :class:`CommandError`.

    Parameters
    ----------
    prefix, suffix : str
        Put before and after the error's message (the option, the record it is about).
    errors : exception class or tuple of them
        What is refused (:class:`ValueError` by default, which the library's errors are).

    Yields
    ------
    None

    Raises
    ------
    CommandError
        ``prefix + message + suffix``, raised from the error.
    """
    try:
        yield
    except errors as err:
        raise CommandError(f"{prefix}{err}{suffix}") from err


def as_option(message: str, options: dict[str, str]) -> str:
    """A library message that starts with a setting's Python name (``train_skip: ...``) said
    with the option's (``--train-skip: ...``).

    Parameters
    ----------
    message : str
        The message.
    options : dict
        Python name to option, e.g. ``{"train_skip": "--train-skip"}``.

    Returns
    -------
    str
        The message, its first word replaced when it is one of ``options``.
    """
    head, sep, rest = message.partition(":")
    return f"{options[head]}:{rest}" if sep and head in options else message


def tell(args: argparse.Namespace, message: str, kind: str = "") -> None:
    """Print one line on stderr in the command's name: ``hystid COMMAND: KIND: MESSAGE``.

    Parameters
    ----------
    args : argparse.Namespace
        The parsed command line (``args.prog`` names the command).
    message : str
        The line; said as the command line says it (:func:`for_cli`: a hint names
        ``--columns`` where the command has it).
    kind : str
        ``"error"``, ``"warning"``, ``"note"``, or ``""`` for a progress line.
    """
    label = f"{getattr(args, 'prog', 'hystid')}: {f'{kind}: ' if kind else ''}"
    print(f"{label}{for_cli(message, columns=hasattr(args, 'columns'))}", file=sys.stderr,
          flush=True)


class OneLineParser(argparse.ArgumentParser):
    """An argument parser whose errors are one line on stderr (no usage block), status 2."""

    def error(self, message: str) -> NoReturn:
        """Print ``PROG: error: MESSAGE`` and a pointer to ``--help``, exit with status 2.

        Parameters
        ----------
        message : str
            argparse's message; an option given no value because the value starts with ``-``
            gets the way to write it (``--crop=-1:2``).
        """
        missing = re.fullmatch(r"argument (--[\w-]+)(?:/\S+)?: expected one argument", message)
        if missing:
            option = missing.group(1)
            message += f" (a value starting with '-' is written {option}=VALUE)"
        self.exit(EXIT_BAD_INPUT, f"{self.prog}: error: {message} (see {self.prog} --help)\n")


class Progress:
    """Periodic progress lines on stderr (silent when ``quiet``).

    Parameters
    ----------
    quiet : bool
        Print nothing.
    every : float
        Least seconds between two periodic lines.
    """

    def __init__(self, quiet: bool = False, every: float = 1.0):
        self.quiet = quiet
        self.every = every
        self._last = 0.0
        self._t0 = time.perf_counter()

    def say(self, message: str) -> None:
        """Print one line now.

        Parameters
        ----------
        message : str
            The line, printed after the seconds elapsed.
        """
        if not self.quiet:
            print(f"[{time.perf_counter() - self._t0:6.1f} s] {message}", file=sys.stderr)

    def __call__(self, k: int, n: int) -> None:
        """Print ``k/n`` at most once per ``every`` seconds (and at the end)."""
        now = time.perf_counter()
        if k >= n or now - self._last >= self.every:
            self._last = now
            self.say(f"sample {k}/{n} ({100.0 * k / max(n, 1):.0f} %)")


# --------------------------------------------------------------------------- checks before work
def check_out(args: argparse.Namespace, path: str | None, names: Iterable[str] | None = None, *,
              option: str = "--out", inputs: Iterable[str | None] = (),
              create_folder: bool = False) -> Path | None:
    """Check an output before any work: a file, or a folder and the files written into it.

    Parameters
    ----------
    args : argparse.Namespace
        The parsed command line: ``args.force``, when the command has it, allows replacing
        files.
    path : str or None
        The output; ``None`` when the command is to write none.
    names : iterable of str, optional
        The output is a folder that receives these files; a file when not given.
    option : str
        The option that names it, for the messages.
    inputs : iterable of str or None
        The files the command reads (``None`` for an input not given): never written over.
    create_folder : bool
        A file's folder may not exist yet (its writer creates it).

    Returns
    -------
    pathlib.Path or None
        The output; ``None`` for none.

    Raises
    ------
    hystid.errors.OutputError
        See :func:`hystid.safeio.check_output` and :func:`hystid.safeio.check_output_dir`.
    """
    from ..safeio import check_output, check_output_dir

    if path is None:
        return None
    force = getattr(args, "force", False)
    inputs = tuple(p for p in inputs if p is not None)
    if names is not None:
        return check_output_dir(path, tuple(names), option=option, inputs=inputs, force=force)
    return check_output(path, option=option, inputs=inputs, force=force,
                        create_folder=create_folder)


def check_seconds(seconds: float, need: int, fs: float, option: str = "--seconds") -> None:
    """Refuse a record length that gives fewer than ``need`` samples, before any work.

    Parameters
    ----------
    seconds : float
        The length asked for.
    need : int
        Fewest samples the command can use.
    fs : float
        Sampling rate in Hz.
    option : str
        The option's name, for the message.

    Raises
    ------
    CommandError
        Saying how many samples the length gives and the shortest length that works.
    """
    n = int(round(min(seconds * fs, 2.0**62)))
    if n < need:
        raise CommandError(f"{option} {seconds:g}: {n} samples at {fs:g} Hz (expected at least "
                           f"{need} samples: {option} {need / fs:.3g} or more)")


def check_model_on(model: Any, rec: Record, option: str = "--model") -> None:
    """Refuse a model whose delays reach past most of the record it is simulated on.

    Parameters
    ----------
    model : DuhemSandwich or PISandwich
        The model.
    rec : Record
        The input record.
    option : str
        The model's option, for the message.

    Raises
    ------
    CommandError
        When the model's delays and orders are not shorter than half the record.
    """
    from ..validate import check_delays_fit

    with refused():
        check_delays_fit(model.structure, rec.n, f"{option}: on {rec.name!r}")


def load(path: str, fs: float | None = None, columns: dict | None = None, option: str = "",
         units: dict | None = None) -> Record:
    """Load a record for a command: remembered, its sizes checked (see :func:`remember`).

    Parameters
    ----------
    path : str
        The record file.
    fs : float, optional
        Sampling rate, for a file without a time vector or a stated rate.
    columns, units : dict, optional
        As :func:`hystid.records.load_record` takes them.
    option : str
        The option that named the file (``"--val"``), put before a problem's message.

    Returns
    -------
    Record

    Raises
    ------
    CommandError
        On a :class:`~hystid.errors.RecordError`, naming ``option`` and the file.
    """
    from ..records import RecordError, load_record

    with refused(f"{option} " if option else "", errors=RecordError):
        rec = load_record(path, fs=fs, columns=columns, units=units)
    return remember(rec, path)


def remember(rec: Record, path: str) -> Record:
    """Note the file a record came from (see :func:`for_cli`), check its sizes, return it.

    Parameters
    ----------
    rec : Record
        The loaded record.
    path : str
        Its file.

    Returns
    -------
    Record
        ``rec`` itself.

    Raises
    ------
    CommandError
        When its samples are beyond :data:`hystid.validate.MAX_MAGNITUDE`.
    """
    from ..validate import check_magnitudes

    if RECORD_FILES.get(rec.name, str(path)) != str(path):  # two files, one record name
        rec.name = f"{rec.name} ({Path(path).name})"
    RECORD_FILES[rec.name] = str(path)
    with refused():
        check_magnitudes(rec, str(path))
    return rec


# --------------------------------------------------------------------------- option types
def file_arg(text: str) -> str:
    """argparse ``type=`` for a file or folder name: not empty, not blank.

    Parameters
    ----------
    text : str
        The option's value.

    Returns
    -------
    str
        ``text`` itself.
    """
    if not text.strip():
        raise argparse.ArgumentTypeError(f"expected a file or folder name, got {text!r}")
    return text


def columns_arg(text: str) -> dict:
    """argparse ``type=`` for ``--columns t=1,u=3,y=2`` (see :func:`hystid.records.parse_columns`).

    Parameters
    ----------
    text : str
        The option's value.

    Returns
    -------
    dict
        Role to column name or 0-based position.
    """
    from ..records import parse_columns

    try:
        return parse_columns(text)
    except ValueError as err:
        raise argparse.ArgumentTypeError(str(err)) from err


def units_arg(text: str) -> dict:
    """argparse ``type=`` for ``--units u=V,y=um`` (see :func:`hystid.records.parse_units`).

    Parameters
    ----------
    text : str
        The option's value.

    Returns
    -------
    dict
        Role to unit.
    """
    from ..records import parse_units

    try:
        return parse_units(text)
    except ValueError as err:
        raise argparse.ArgumentTypeError(str(err)) from err


def positive_arg(kind: type) -> Callable[[str], Any]:
    """argparse ``type=`` for a positive finite ``kind``.

    Parameters
    ----------
    kind : {float, int}
        The number's type.

    Returns
    -------
    callable
        ``parse(text)`` (see :func:`hystid.options.number`, :func:`hystid.options.integer`).
    """
    return number(0.0, strict_minimum=True) if kind is float else integer(1)


#: argparse ``type=`` for a finite number >= 0.
non_negative_arg = number(0.0)
#: argparse ``type=`` for a simulated record's length in seconds.
seconds_arg = number(0.0, MAX_SECONDS, strict_minimum=True)
#: argparse ``type=`` for a random seed.
seed_arg = integer(0, 2**63 - 1)


# --------------------------------------------------------------------------- what a command prints
def _columns_option(match: re.Match) -> str:
    pairs = re.findall(r"""['"]?(\w+)['"]?\s*:\s*['"]?([^'",}]+)['"]?""", match.group(1))
    return "--columns " + ",".join(f"{k}={v.strip()}" for k, v in pairs)


def for_cli(message: str, columns: bool = True) -> str:
    """An API error message as the command line should say it.

    The Python syntax of a hint (``columns={'u': 1, 'y': 2}``) becomes the option that does
    the same (``--columns u=1,y=2``), and a record named by its name alone (``record 'rec'``)
    is also named by the file it was loaded from.

    Parameters
    ----------
    message : str
        The message.
    columns : bool
        The command has ``--columns`` (a command without it keeps the hint as it is).

    Returns
    -------
    str
    """
    if columns:
        message = re.sub(r"columns=\{([^}]*)\}", _columns_option, message)
        message = message.replace("or a columns= mapping", "or --columns u=NAME,y=NAME")
    for name, path in RECORD_FILES.items():
        if path in message:
            continue
        found = re.search(r"'(" + re.escape(name) + r"[^']*)'", message)
        if found:
            at = found.end()
            message = f"{message[:at]} (file {path}){message[at:]}"
    return message


def kernels_cached(kernels: tuple[tuple[str, str], ...] = DEMO_KERNELS) -> bool:
    """Whether numba's cache holds every kernel named (True when it cannot tell).

    Parameters
    ----------
    kernels : tuple of (str, str)
        Module and name of each compiled kernel.

    Returns
    -------
    bool
        False when one of them has no cache index yet: it compiles on first use.
    """
    import importlib
    import os

    for modname, name in kernels:
        kernel = getattr(importlib.import_module(modname), name, None)
        try:
            index = kernel._cache._cache_file._index_path  # numba's index file of the kernel
        except AttributeError:  # not a cached kernel, or numba keeps its cache otherwise
            continue
        if not os.path.exists(index):
            return False
    return True


def table(rows: list[list[str]], header: list[str]) -> str:
    """A plain-text table: the header, a rule, the rows, columns padded to their width.

    Parameters
    ----------
    rows : list of list of str
        The cells.
    header : list of str
        Column titles.

    Returns
    -------
    str
    """
    widths = [max(len(str(r[i])) for r in [header, *rows]) for i in range(len(header))]
    line = "  ".join(h.ljust(w) for h, w in zip(header, widths, strict=True))
    out = [line, "  ".join("-" * w for w in widths)]
    out += ["  ".join(str(c).ljust(w) for c, w in zip(r, widths, strict=True)) for r in rows]
    return "\n".join(out)


def one_of(names: tuple[str, ...]) -> str:
    """``"a, b or c"``.

    Parameters
    ----------
    names : tuple of str
        The choices.

    Returns
    -------
    str
    """
    return " or ".join([", ".join(names[:-1]), names[-1]] if len(names) > 1 else names)


def jsonable(value: object) -> bool:
    """Whether :func:`json.dumps` takes ``value``.

    Parameters
    ----------
    value : object
        Anything.

    Returns
    -------
    bool
    """
    try:
        json.dumps(value)
    except TypeError:
        return False
    return True
