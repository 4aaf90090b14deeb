"""A light start: import time, ``hystid --help`` and the first feed-forward call in a fresh process.

Each figure is measured in a new Python process. "cold" runs with an empty numba cache
(``NUMBA_CACHE_DIR`` set to a fresh directory: every kernel compiles), "warm" runs again on the
cache the cold run left. Ratios are against ``python -c "import numpy"`` timed the same way.

The processes run in ``--root`` (this checkout by default), so that its ``hystid`` is the one
imported; ``--root`` another checkout measures that one.

Usage: python benchmarks/bench_start.py [--repeat N] [--root CHECKOUT]
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from _common import table, write_json

FIRST_FEEDFORWARD = """
import time
import numpy as np
from hystid.compensate import feedforward
from hystid.compensate.tracking import scan_reference
from hystid.reference import reference_model
ref = scan_reference("triangle", 100.0, periods=1.0)
t0 = time.perf_counter()
feedforward(reference_model(), ref.y)
print(time.perf_counter() - t0)
"""

HEAVY = """
import sys
import {module}
print(" ".join(m for m in ("control", "matplotlib") if m in sys.modules) or "-")
"""


def run(code: str, env: dict[str, str], root: Path) -> tuple[float, str]:
    """Wall time of a fresh ``python -c code`` run in ``root``, and its last printed line."""
    t0 = time.perf_counter()
    out = subprocess.run([sys.executable, "-c", code], env=env, cwd=root, check=True,
                         capture_output=True, text=True).stdout
    return time.perf_counter() - t0, out.strip().splitlines()[-1]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--repeat", type=int, default=3, help="runs of each warm figure")
    parser.add_argument("--root", type=Path, default=Path(__file__).resolve().parents[1],
                        help="checkout whose hystid is measured (default: this one)")
    args = parser.parse_args()
    root = args.root.resolve()
    with tempfile.TemporaryDirectory() as cache:
        env = {**os.environ, "NUMBA_CACHE_DIR": cache}
        base = min(run("import numpy; print(1)", env, root)[0] for _ in range(args.repeat))
        imports = {m: run(HEAVY.format(module=m), env, root) for m in ("hystid", "hystid.cli")}
        cold_total, cold_call = run(FIRST_FEEDFORWARD, env, root)
        warm = [run(FIRST_FEEDFORWARD, env, root) for _ in range(args.repeat)]
    warm_total = min(w[0] for w in warm)
    warm_call = min(float(w[1]) for w in warm)
    rows = [
        ["import hystid", f"{imports['hystid'][0]:.2f}", f"{imports['hystid'][0] / base:.1f}",
         imports["hystid"][1]],
        ["import hystid.cli (hystid --help)", f"{imports['hystid.cli'][0]:.2f}",
         f"{imports['hystid.cli'][0] / base:.1f}", imports["hystid.cli"][1]],
        ["first feedforward(), cold cache: call", f"{float(cold_call):.2f}", "", ""],
        ["first feedforward(), cold cache: process", f"{cold_total:.2f}",
         f"{cold_total / base:.1f}", ""],
        ["first feedforward(), warm cache: call", f"{warm_call:.3f}", "", ""],
        ["first feedforward(), warm cache: process", f"{warm_total:.2f}",
         f"{warm_total / base:.1f}", ""],
    ]
    print(f"Fresh processes in {root} (python -c 'import numpy': {base:.2f} s)")
    print(table(rows, ["what", "seconds", "x import numpy", "heavy modules imported"]))
    path = write_json("start", {
        "root": str(root), "import_numpy": base,
        "import": {m: {"seconds": s, "heavy": h} for m, (s, h) in imports.items()},
        "first_feedforward": {"cold_call": float(cold_call), "cold_process": cold_total,
                              "warm_call": warm_call, "warm_process": warm_total},
    })
    print(f"wrote {path}")


if __name__ == "__main__":
    main()
