"""The ``hystid`` command's parser: the commands there are, each configured by its own module.

Command ``NAME`` lives in :mod:`hystid.cli.NAME`, which gives ``configure_parser(parser)`` (its
options, its description, and its ``run``) and ``run(args)``. :func:`build_parser` names every
command with its one line of ``hystid --help`` and loads only the module of the command asked
for, so that ``hystid --help`` and a command's own ``--help`` load no more than they show.
"""

from __future__ import annotations

import argparse
from importlib import import_module

from .. import __version__
from .support import OneLineParser

__all__ = ["COMMANDS", "build_parser", "command_word"]

#: The commands in the order ``hystid --help`` lists them, with their line there.
COMMANDS = {
    "demo": "identify the built-in reference stage and report",
    "simulate": "write a record from the reference stage or a model",
    "identify": "identify a record",
    "diagnose": "diagnose the sim-to-real gap",
    "compensate": "the command that makes a saved model follow a reference",
    "fleet": "identify or diagnose many records on Dask",
    "export": "a saved model as C99 (model, compensator, RPEM step)",
}


def build_parser(only: str | None = None) -> argparse.ArgumentParser:
    """The argument parser of the ``hystid`` command.

    Parameters
    ----------
    only : str, optional
        Give the options of this command only (the others keep their one-line help), so that
        ``hystid --help`` loads no command's module; every command in full by default.

    Returns
    -------
    argparse.ArgumentParser
        The parser; each command sets ``func`` (its ``run``) and ``prog``.
    """
    parser = OneLineParser(
        prog="hystid",
        description="Identify piezo-driven positioning stages (L1-Duhem-L2 sandwich).",
    )
    parser.add_argument("--version", action="version", version=f"hystid {__version__}")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for name, summary in COMMANDS.items():
        command = sub.add_parser(name, help=summary)
        if only in (None, name):
            import_module(f"{__package__}.{name}").configure_parser(command)
    return parser


def command_word(argv: list[str]) -> str:
    """The command named on a command line (the first word not an option), or ``""``.

    Parameters
    ----------
    argv : list of str
        The arguments.

    Returns
    -------
    str
    """
    return next((a for a in argv if not a.startswith("-")), "")
