"""Speed of two commits as ratios measured in one run (never an absolute time).

Each commit is checked out into a temporary git worktree; the workloads of this checkout
(``benchmarks/workloads.py``) then run on each commit's ``hystid`` in child processes, the
two commits in alternation for ``--rounds`` rounds, so that a busy machine slows both alike.
The best time of each is kept and the table gives ``B / A`` per workload (below 1: B is
faster). Usage::

    python benchmarks/compare_commits.py A B [--workloads simulate,identify_online] [--rounds 3]
    python benchmarks/compare_commits.py main HEAD

A workload that fails on a commit (an API it does not have yet) is reported as failed. The
table is written to ``benchmarks/results/compare_commits.json``. ``asv continuous A B`` does
the same with asv's own environments (it builds and installs each commit first).
"""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import subprocess
import sys
import tempfile
from collections.abc import Iterator
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent


def _git(*args: str) -> str:
    return subprocess.run(["git", "-C", str(ROOT), *args], check=True, capture_output=True,
                          text=True).stdout.strip()


@contextlib.contextmanager
def checkouts(revs: list[str]) -> Iterator[dict[str, Path]]:
    """Temporary detached worktrees of ``revs``, removed on exit.

    Parameters
    ----------
    revs : list of str
        Commits, branches or tags.

    Yields
    ------
    dict
        Revision -> worktree folder.

    Raises
    ------
    SystemExit
        When a revision is not a commit of this repository.
    """
    with tempfile.TemporaryDirectory(prefix="hystid-compare-") as tmp:
        made = {}
        try:
            for i, rev in enumerate(revs):
                try:
                    sha = _git("rev-parse", "--verify", f"{rev}^{{commit}}")
                except subprocess.CalledProcessError:
                    raise SystemExit(f"{rev!r}: not a commit of {ROOT}") from None
                path = Path(tmp) / f"rev{i}"
                _git("worktree", "add", "--detach", "--quiet", str(path), sha)
                made[rev] = path
            yield made
        finally:
            for path in made.values():
                subprocess.run(["git", "-C", str(ROOT), "worktree", "remove", "--force",
                                str(path)], check=False, capture_output=True)


def time_in_child(checkout: Path, workload: str, repeat: int) -> dict:
    """Best time of ``workload`` on ``checkout``'s hystid, in a child process.

    Parameters
    ----------
    checkout : Path
        Folder whose ``hystid`` package is imported.
    workload : str
        Key of :data:`workloads.WORKLOADS`.
    repeat : int
        Timing rounds inside the child (best kept).

    Returns
    -------
    dict
        ``seconds``, or ``error`` with the child's last line.
    """
    env = dict(os.environ, PYTHONPATH=str(checkout))
    proc = subprocess.run([sys.executable, str(Path(__file__)), "--child", workload,
                           "--repeat", str(repeat)], env=env, capture_output=True, text=True,
                          cwd=str(checkout))
    if proc.returncode != 0:
        lines = (proc.stderr or proc.stdout).strip().splitlines() or ["no output"]
        return {"error": lines[-1]}
    got = json.loads(proc.stdout.strip().splitlines()[-1])
    if Path(got["hystid"]).resolve().parent != checkout.resolve():
        return {"error": f"imported hystid from {got['hystid']}, not from {checkout}"}
    return got


def _child(workload: str, repeat: int) -> None:
    from _common import best_time
    from workloads import make

    import hystid

    fn = make(workload)
    print(json.dumps({"seconds": best_time(fn, repeat=repeat, min_time=0.0),
                      "hystid": str(Path(hystid.__file__).parent)}))


def compare(rev_a: str, rev_b: str, names: list[str], rounds: int, repeat: int) -> list[dict]:
    """Time every workload on both commits, alternating, and form the ratios.

    Parameters
    ----------
    rev_a, rev_b : str
        The two commits.
    names : list of str
        Workloads.
    rounds : int
        Alternating rounds (A, B, A, B...); the best of each commit is kept.
    repeat : int
        Timings inside each child process.

    Returns
    -------
    list of dict
        Per workload: ``workload``, best ``a`` and ``b`` seconds (or ``error``), ``ratio``.
    """
    rows = []
    with checkouts([rev_a, rev_b]) as trees:
        for name in names:
            best = {rev_a: float("inf"), rev_b: float("inf")}
            errors = {}
            for _ in range(rounds):
                for rev in (rev_a, rev_b):
                    got = time_in_child(trees[rev], name, repeat)
                    if "error" in got:
                        errors[rev] = got["error"]
                    else:
                        best[rev] = min(best[rev], got["seconds"])
            row = {"workload": name}
            if errors:
                row["error"] = "; ".join(f"{rev}: {e}" for rev, e in errors.items())
            else:
                row.update(a=best[rev_a], b=best[rev_b], ratio=best[rev_b] / best[rev_a])
            rows.append(row)
            print(f"  {name}: " + (row.get("error") or f"B / A = {row['ratio']:.3f}"),
                  flush=True)
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("a", nargs="?", help="baseline commit")
    parser.add_argument("b", nargs="?", help="commit compared with it")
    parser.add_argument("--workloads", default=None,
                        help="comma-separated (default: all of benchmarks/workloads.py)")
    parser.add_argument("--rounds", type=int, default=3, help="alternating rounds (default 3)")
    parser.add_argument("--repeat", type=int, default=3, help="timings per child (default 3)")
    parser.add_argument("--child", default=None, help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.child:
        _child(args.child, args.repeat)
        return
    if not (args.a and args.b):
        parser.error("expected two commits A and B")
    from _common import table, write_json
    from workloads import WORKLOADS

    names = args.workloads.split(",") if args.workloads else list(WORKLOADS)
    unknown = [n for n in names if n not in WORKLOADS]
    if unknown:
        parser.error(f"--workloads: unknown {', '.join(unknown)}; expected some of "
                     f"{', '.join(WORKLOADS)}")
    rows = compare(args.a, args.b, names, args.rounds, args.repeat)
    print(f"\nA = {args.a}, B = {args.b}; best of {args.rounds} alternating rounds "
          f"x {args.repeat} timings; ratio B / A (below 1: B faster)")
    print(table([[r["workload"], WORKLOADS[r["workload"]],
                  r.get("error", "")[:60] or f"{r['ratio']:.3f}"] for r in rows],
                ["workload", "what", "B / A"]))
    print(f"wrote {write_json('compare_commits', {'a': args.a, 'b': args.b, 'rows': rows})}")


if __name__ == "__main__":
    main()
