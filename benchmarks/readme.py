"""The README's figures, generated from the benchmarks: one command measures and rewrites them.

Every table of figures in ``README.md`` sits between two markers::

    <!-- figures:NAME:begin -->
    ...
    <!-- figures:NAME:end -->

and is rendered from a payload measured by one benchmark script, which declares the blocks it
renders (``README_BLOCKS = {"NAME": "render"}``, see :func:`declared_blocks`). Each such script
has ``measure(quick=False) -> dict`` (the figures, JSON-able) and its renderers
(``render(payload) -> str``, Markdown); running the script prints the same rendering. The
payload the README shows is kept, with the commit, date and machine load it was measured on, in
``benchmarks/readme_figures/SCRIPT.json`` (committed), so the README is reproducible from the
repository and ``tests/test_readme_figures.py`` fails when a block was edited by hand or
rendered from other figures. The ``accuracy`` block is rendered from the accuracy gate's
baseline (``benchmarks/accuracy_baseline.json``), which CI recomputes from the code in
``tests/test_accuracy_gate.py``: those figures cannot drift from what the code does.

Usage::

    python benchmarks/readme.py                  # measure every block, rewrite the README
    python benchmarks/readme.py --only simulate,memory
    python benchmarks/readme.py --render         # re-render from the stored payloads only
    python benchmarks/readme.py --check          # exit 1 when the README differs from them
    python benchmarks/readme.py --list           # the blocks, their scripts and last runs
"""

from __future__ import annotations

import argparse
import ast
import datetime
import difflib
import importlib
import json
import os
import re
import subprocess
import sys
import time
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path
from types import ModuleType

HERE = Path(__file__).resolve().parent
if str(HERE) not in sys.path:  # the scripts beside this one import each other by name
    sys.path.insert(0, str(HERE))
if __name__ == "__main__":  # run as a script: measure the checkout this file belongs to
    sys.path.insert(0, str(HERE.parent))

README = HERE.parent / "README.md"
STORE = HERE / "readme_figures"
MARKER = re.compile(r"<!-- figures:(?P<name>[\w-]+):(?P<end>begin|end) -->")


@dataclass(frozen=True)
class Block:
    """A generated block of the README.

    Attributes
    ----------
    name : str
        The marker's name.
    script : str
        The benchmark module (in ``benchmarks/``) with ``measure`` and the block's renderer.
    renderer : str
        The name of the module's function that renders this block from the payload.
    """

    name: str
    script: str
    renderer: str = "render"

    @property
    def path(self) -> Path:
        """Where the payload the README shows is kept (one file per script)."""
        return STORE / f"{self.script}.json"

    def module(self) -> ModuleType:
        """The benchmark module."""
        return importlib.import_module(self.script)

    @property
    def command(self) -> str:
        """The command that measures the same figures and prints them."""
        return getattr(self.module(), "COMMAND", f"python benchmarks/{self.script}.py")


DECLARED = re.compile(r"^README_BLOCKS\s*=\s*(\{[^}]*\})", re.MULTILINE)


def declared_blocks(folder: Path = HERE) -> dict[str, Block]:
    """The blocks the scripts declare, by name.

    A script takes part by a module-level ``README_BLOCKS = {"name": "renderer", ...}`` (read
    from its text, without importing it), a ``measure(quick=False) -> dict`` and the renderers,
    each ``renderer(payload) -> str``; optionally ``COMMAND``, the command line to name.

    Parameters
    ----------
    folder : Path
        The benchmarks folder.

    Returns
    -------
    dict
        Name -> :class:`Block`.

    Raises
    ------
    ValueError
        A block declared by two scripts, naming both.
    """
    out: dict[str, Block] = {}
    for path in sorted(folder.glob("*.py")):
        m = DECLARED.search(path.read_text())
        if m is None:
            continue
        for name, renderer in ast.literal_eval(m[1]).items():
            if name in out:
                raise ValueError(f"{path}: block {name!r} already declared by "
                                 f"{out[name].script}.py")
            out[name] = Block(name, path.stem, renderer)
    return out


#: The README's generated blocks.
BLOCKS: dict[str, Block] = declared_blocks()


# ---------------------------------------------------------------------------------------------
# the stored payloads


def _git(*args: str) -> str:
    try:
        return subprocess.run(["git", "-C", str(HERE.parent), *args], capture_output=True,
                              text=True, check=True).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return ""


def provenance() -> dict:
    """Where and when a measurement runs: commit (``+`` when the tree has changes), date, load.

    Returns
    -------
    dict
        ``commit``, ``date`` (ISO, UTC), ``cpus``, ``load_average`` (1 min, before the run).
    """
    commit = _git("rev-parse", "--short", "HEAD") or "unknown"
    if _git("status", "--porcelain", "--untracked-files=no", "--", "hystid", "benchmarks",
            ":!benchmarks/readme_figures"):
        commit += "+"
    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else None
    return {"commit": commit, "cpus": os.cpu_count(),
            "date": datetime.datetime.now(datetime.UTC).strftime("%Y-%m-%d"),
            "load_average": None if load is None else round(load, 1)}


def measure(block: Block) -> dict:
    """Run a block's measurement and store its payload with its provenance.

    Parameters
    ----------
    block : Block

    Returns
    -------
    dict
        What was written to ``block.path``.
    """
    module = block.module()
    if not hasattr(module, "measure"):  # the accuracy gate: its baseline is the payload
        return stored(block)
    if block.path in _measured:  # another block of the same script, measured this run
        return _measured[block.path]
    entry = provenance()
    t0 = time.perf_counter()
    payload = module.measure()
    entry.update(seconds=round(time.perf_counter() - t0, 1), command=block.command,
                 payload=payload)
    STORE.mkdir(exist_ok=True)
    tmp = block.path.with_suffix(".tmp")
    tmp.write_text(json.dumps(entry, indent=1, default=float) + "\n")
    os.replace(tmp, block.path)
    _measured[block.path] = entry
    return entry


_measured: dict[Path, dict] = {}


def stored(block: Block) -> dict:
    """The payload the README shows, with its provenance.

    Parameters
    ----------
    block : Block

    Returns
    -------
    dict
        ``payload`` and, for measured blocks, ``commit``, ``date``, ``cpus``,
        ``load_average``, ``seconds``, ``command``.

    Raises
    ------
    ValueError
        When the block has never been measured, naming the file and the command.
    """
    module = block.module()
    if not hasattr(module, "measure"):
        return {"payload": module.load_baseline(), "command": block.command}
    try:
        return json.loads(block.path.read_text())
    except FileNotFoundError:
        raise ValueError(f"{block.path}: block {block.name!r} not measured yet; run "
                         f"'python benchmarks/readme.py --only {block.name}'") from None


# ---------------------------------------------------------------------------------------------
# the README


def render(block: Block, entry: dict | None = None) -> str:
    """A block's Markdown: the provenance line, then the script's rendering.

    Parameters
    ----------
    block : Block
    entry : dict, optional
        What :func:`stored` returns; read from the store by default.

    Returns
    -------
    str
    """
    entry = stored(block) if entry is None else entry
    if "commit" in entry:
        load = entry.get("load_average")
        where = (f"commit {entry['commit']}, {entry['date']}, {entry['cpus']} cores"
                 + (f", load average {load:g}" if load is not None else ""))
        head = (f"Measured with `{entry['command']}` ({where}); `python benchmarks/readme.py "
                f"--only {block.name}` measures again and rewrites this block:")
    else:
        head = (f"`{entry['command']}` writes these figures to "
                "`benchmarks/accuracy_baseline.json`, which CI recomputes from the code "
                "(rendered by `python benchmarks/readme.py --render`):")
    body = getattr(block.module(), block.renderer)(entry["payload"])
    return head + "\n\n" + body.strip()


def blocks_in(text: str, path: Path = README) -> dict[str, tuple[int, int]]:
    """The marked blocks of a README: name -> (start, end) of the text between its markers.

    Parameters
    ----------
    text : str
        The README's text.
    path : Path
        Its path, for the messages.

    Returns
    -------
    dict

    Raises
    ------
    ValueError
        A marker without its pair, a block opened twice or nested, naming the line.
    """
    out: dict[str, tuple[int, int]] = {}
    open_name, start = None, 0
    for m in MARKER.finditer(text):
        line = text.count("\n", 0, m.start()) + 1
        name, end = m["name"], m["end"] == "end"
        if not end:
            if open_name is not None:
                raise ValueError(f"{path}:{line}: block {name!r} opens inside {open_name!r}")
            if name in out:
                raise ValueError(f"{path}:{line}: block {name!r} appears twice")
            open_name, start = name, m.end()
        else:
            if open_name != name:
                raise ValueError(f"{path}:{line}: end of {name!r} without its begin")
            out[name] = (start, m.start())
            open_name = None
    if open_name is not None:
        raise ValueError(f"{path}: block {open_name!r} has no end marker")
    return out


def rewrite(text: str, names: Iterable[str], path: Path = README) -> str:
    """``text`` with the named blocks rendered afresh.

    Parameters
    ----------
    text : str
        The README's text.
    names : iterable of str
        Blocks to render (each must be in the README and in :data:`BLOCKS`).
    path : Path
        For the messages.

    Returns
    -------
    str
    """
    spans = blocks_in(text, path)
    for name in names:
        if name not in spans:
            raise ValueError(f"{path}: no block '<!-- figures:{name}:begin -->'")
    for name in sorted(names, key=lambda n: spans[n][0], reverse=True):
        start, end = spans[name]
        text = text[:start] + "\n" + render(BLOCKS[name]) + "\n" + text[end:]
    return text


def check(path: Path = README) -> list[str]:
    """Differences between the README's blocks and the stored payloads' renderings.

    Parameters
    ----------
    path : Path
        The README.

    Returns
    -------
    list of str
        One message per block that differs, is missing or is unknown (empty when it agrees).
    """
    text = path.read_text()
    spans = blocks_in(text, path)
    problems = [f"{path}: block {n!r} declared by no script (README_BLOCKS in benchmarks/*.py)"
                for n in spans if n not in BLOCKS]
    problems += [f"{path}: block {n!r} missing" for n in BLOCKS if n not in spans]
    for name in (n for n in BLOCKS if n in spans):
        start, end = spans[name]
        try:
            want = "\n" + render(BLOCKS[name]) + "\n"
        except ValueError as err:  # never measured
            problems.append(str(err))
            continue
        if text[start:end] != want:
            diff = "\n".join(difflib.unified_diff(text[start:end].splitlines(),
                                                  want.splitlines(), "README", "rendered",
                                                  lineterm="", n=0))
            problems.append(f"{path}: block {name!r} differs from its stored figures:\n{diff}")
    return problems


def _unmeasured(block: Block) -> bool:
    try:
        stored(block)
    except ValueError:
        return True
    return False


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--only", default=None, help="comma-separated blocks (see --list)")
    what = parser.add_mutually_exclusive_group()
    what.add_argument("--render", action="store_true", help="do not measure; re-render only")
    what.add_argument("--check", action="store_true",
                      help="exit 1 when the README differs from the stored figures")
    what.add_argument("--list", action="store_true", help="list the blocks")
    args = parser.parse_args()
    names = list(BLOCKS) if args.only is None else [n.strip() for n in args.only.split(",")]
    unknown = [n for n in names if n not in BLOCKS]
    if unknown:
        parser.error(f"--only: unknown block(s) {', '.join(unknown)}; expected some of "
                     f"{', '.join(BLOCKS)}")
    if args.list:
        for b in BLOCKS.values():
            try:
                e = stored(b)
                when = f"{e.get('commit', 'baseline')} {e.get('date', '')} {e.get('seconds', '')}"
            except ValueError:
                when = "not measured"
            print(f"{b.name:14s} {b.command:62s} {when}")
        return
    if args.check:
        problems = check()
        print("\n".join(problems) or f"{README}: every block agrees with its stored figures")
        sys.exit(1 if problems else 0)
    # a script's blocks share one measurement: re-render all of them
    names = [b.name for b in BLOCKS.values() if b.script in {BLOCKS[n].script for n in names}]
    if not args.render:
        for name in names:
            print(f"measuring {name}: {BLOCKS[name].command}", flush=True)
            entry = measure(BLOCKS[name])
            print(f"  {entry['seconds']} s -> {BLOCKS[name].path}" if "seconds" in entry
                  else "  the gate's baseline, as committed", flush=True)
    if args.render:  # blocks never measured are named and left as they are
        missing = [n for n in names if _unmeasured(BLOCKS[n])]
        for n in missing:
            print(f"not measured yet, left as it is: {n} "
                  f"('python benchmarks/readme.py --only {n}')")
        names = [n for n in names if n not in missing]
    text = README.read_text()
    try:
        new = rewrite(text, names)
    except ValueError as err:
        sys.exit(str(err))
    if new != text:
        tmp = README.with_suffix(".md.tmp")
        tmp.write_text(new)
        os.replace(tmp, README)
    print(f"{README}: {'updated' if new != text else 'unchanged'} ({', '.join(names)})")


if __name__ == "__main__":
    main()
