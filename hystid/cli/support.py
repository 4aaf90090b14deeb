"""Pieces of the ``hystid`` command line kept apart from :mod:`hystid.cli`.

The error and progress types every command uses, and the checks a command runs before its
work: the length of a simulated record, the delays of a model against its input record.
"""

from __future__ import annotations

import argparse
import json
import re
import sys
import time
from typing import NoReturn

from ..errors import CommandError

#: Exit status of a refused input or a failed write.
EXIT_BAD_INPUT = 2
#: Compiled kernels every ``hystid demo`` runs, as (module, name): while one of them is not in
#: numba's cache yet, the demo says that it compiles them.
DEMO_KERNELS = (("hystid.kernels", "simulate_into"), ("hystid.kernels", "sensitivities_into"),
                ("hystid.identify.online", "rpem_run"), ("hystid.identify.eria", "eria_run"))

__all__ = ["DEMO_KERNELS", "EXIT_BAD_INPUT", "RECORD_FILES", "CommandError", "OneLineParser",
           "Progress", "check_model_on", "check_seconds", "for_cli", "jsonable", "kernels_cached",
           "one_of", "remember", "run_command", "table"]


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


def check_model_on(model, rec, option: str = "--model") -> None:
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

    try:
        check_delays_fit(model.structure, rec.n, f"{option}: on {rec.name!r}")
    except ValueError as err:
        raise CommandError(str(err)) from err


#: The file each record the command loaded came from, by the record's name.
RECORD_FILES: dict[str, str] = {}


def remember(rec, path: str):
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

    RECORD_FILES[rec.name] = str(path)
    try:
        check_magnitudes(rec, str(path))
    except ValueError as err:
        raise CommandError(str(err)) from err
    return rec


def _columns_option(match: re.Match) -> str:
    pairs = re.findall(r"""['"]?(\w+)['"]?\s*:\s*['"]?([^'",}]+)['"]?""", match.group(1))
    return "--columns " + ",".join(f"{k}={v.strip()}" for k, v in pairs)


def for_cli(message: str) -> str:
    """An API error message as the command line should say it.

    The Python syntax of a hint (``columns={'u': 1, 'y': 2}``) becomes the option that does
    the same (``--columns u=1,y=2``), and a record named by its name alone (``record 'rec'``)
    is also named by the file it was loaded from.

    Parameters
    ----------
    message : str
        The message.

    Returns
    -------
    str
    """
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


def run_command(args: argparse.Namespace) -> int:
    """Run a parsed command: a refused input or a failed write is one line, status 2.

    Parameters
    ----------
    args : argparse.Namespace
        The parsed command line; ``args.func`` runs the command.

    Returns
    -------
    int
        The command's status; 2 on a :class:`CommandError`, an
        :class:`~hystid.safeio.OutputError` raised while writing (an output that appeared
        meanwhile) or an :class:`OSError`; 130 when interrupted.
    """
    from .. import safeio

    safeio._CLAIMS.clear()  # the outputs of an earlier command run in this process
    try:
        return int(args.func(args) or 0)
    except (CommandError, safeio.OutputError) as err:
        print(f"hystid {args.command}: error: {for_cli(str(err))}", file=sys.stderr)
        return EXIT_BAD_INPUT
    except OSError as err:  # a full disk, a folder removed meanwhile: no file was half-written
        where = f" ({err.filename})" if err.filename else ""
        print(f"hystid {args.command}: error: {err.strerror or err}{where}; no file was "
              "half-written and files that were already there are left as they were",
              file=sys.stderr)
        return EXIT_BAD_INPUT
    except KeyboardInterrupt:
        return 130


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
