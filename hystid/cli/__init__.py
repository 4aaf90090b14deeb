"""The ``hystid`` command line: one module a command, the parser that names them, what they share.

``hystid COMMAND ...`` (and ``python -m hystid``) runs :func:`main`. The package:

* :mod:`~hystid.cli.parser` -- :func:`build_parser`: the commands and their one-line help;
* one module a command, each with its options (``configure_parser``) and its steps (``run``):
  :mod:`~hystid.cli.demo`, :mod:`~hystid.cli.simulate`, :mod:`~hystid.cli.identify`,
  :mod:`~hystid.cli.diagnose`, :mod:`~hystid.cli.compensate`, :mod:`~hystid.cli.fleet`,
  :mod:`~hystid.cli.export`;
* :mod:`~hystid.cli.support` -- what every command shares: the runner that says a refused input
  as one line with exit status 2, the checks before work, the option types, progress lines.

A command's module loads the libraries it needs (python-control, numba, matplotlib, Dask) only
when it runs, so that ``hystid --help`` stays fast.
"""

from __future__ import annotations

import sys

from .parser import build_parser, command_word
from .support import EXIT_BAD_INPUT, CommandError, kernels_cached

__all__ = ["EXIT_BAD_INPUT", "CommandError", "build_parser", "kernels_cached", "main"]


def main(argv: list[str] | None = None) -> int:
    """Entry point of the ``hystid`` command; returns the exit status.

    Parameters
    ----------
    argv : list of str, optional
        The arguments (``sys.argv[1:]`` by default).

    Returns
    -------
    int
        0 on success, 2 on bad input or a failed write, 130 when interrupted (``fleet``: 1
        when some record failed).
    """
    argv = sys.argv[1:] if argv is None else [str(a) for a in argv]
    args = build_parser(only=command_word(argv)).parse_args(argv)
    return args.func(args)
