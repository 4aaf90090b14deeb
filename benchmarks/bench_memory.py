"""Memory per sample of the batch fit and of the on-line identifier at 1e5, 1e6 (and 1e7) samples.

Each case runs in a fresh process (peak RSS is a per-process figure): the record of the
reference stage is made and every kernel compiled on a short record first, then the fit runs
and two figures are taken for it alone: the peak of the memory numpy and Python allocate
(``tracemalloc``) and the growth of the peak resident set over the resident set before the fit
(the peak is reset before the fit through ``/proc/self/clear_refs``, so that making the record
does not hide it), both divided by the number of samples. The record itself (``u``, ``y``: 16
bytes per sample) is made before and is not counted.

    python benchmarks/bench_memory.py            # 1e5 and 1e6 samples
    python benchmarks/bench_memory.py --quick    # 1e5 only
    python benchmarks/bench_memory.py --full     # also 1e7 (the batch fit: beyond 20 minutes)

The children import the ``hystid`` of this checkout. Prints a table (the README's block
``memory``, see ``benchmarks/readme.py``) and writes ``benchmarks/results/bench_memory.json``.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import time
import tracemalloc
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import table, write_json  # noqa: E402

FS = 30_000.0
CASES = ("batch", "online")
ROOT = Path(__file__).resolve().parents[1]

#: The README blocks this script renders (see ``benchmarks/readme.py``).
README_BLOCKS = {"memory": "render"}
#: The command that measures the README's figures (one BLAS thread, as in the README).
COMMAND = "OPENBLAS_NUM_THREADS=1 python benchmarks/bench_memory.py"
#: What each case is called in the table.
LABELS = {"batch": "batch fit", "online": "on-line identifier"}


def _rss_bytes() -> int:
    """Current resident set size of this process in bytes."""
    with open("/proc/self/statm") as src:
        pages = int(src.read().split()[1])
    return pages * resource.getpagesize()


def _reset_peak_rss() -> None:
    """Start a new peak of the resident set (Linux: VmHWM := VmRSS)."""
    with open("/proc/self/clear_refs", "w") as out:
        out.write("5")


def _peak_rss_bytes() -> int:
    """Peak resident set size since the last :func:`_reset_peak_rss`, in bytes."""
    with open("/proc/self/status") as src:
        for line in src:
            if line.startswith("VmHWM:"):
                return int(line.split()[1]) * 1024
    raise RuntimeError("no VmHWM in /proc/self/status")


def _fit(case: str, record) -> None:
    from hystid.identify import identify

    identify(record, method=case, model="duhem")


def measure_case(case: str, n: int) -> dict:
    """Run one case in this process; the figures of the fit alone.

    Parameters
    ----------
    case : {"batch", "online"}
        The identification method.
    n : int
        Record length, samples.

    Returns
    -------
    dict
        ``case``, ``samples``, ``seconds``, ``traced_bytes_per_sample``,
        ``rss_growth_bytes_per_sample``, ``peak_rss_mb``.
    """
    import warnings

    from hystid.reference import reference_record

    warnings.simplefilter("ignore")
    _fit(case, reference_record(3000 / FS, seed=1))  # compile every kernel first
    record = reference_record(n / FS, seed=0)
    rss_before = _rss_bytes()
    _reset_peak_rss()
    tracemalloc.start()
    t0 = time.perf_counter()
    _fit(case, record)
    seconds = time.perf_counter() - t0
    traced_peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    peak = _peak_rss_bytes()
    return {
        "case": case, "samples": n, "seconds": seconds,
        "traced_bytes_per_sample": traced_peak / n,
        "rss_growth_bytes_per_sample": (peak - rss_before) / n,
        "peak_rss_mb": peak / 2**20,
    }


def run_case(case: str, n: int) -> dict:
    """One case in a fresh process that imports this checkout's ``hystid``.

    Parameters
    ----------
    case : {"batch", "online"}
        The identification method.
    n : int
        Record length, samples.

    Returns
    -------
    dict
        What :func:`measure_case` returns in the child.
    """
    env = {**os.environ,
           "PYTHONPATH": os.pathsep.join(filter(None, [str(ROOT), os.environ.get("PYTHONPATH")]))}
    out = subprocess.run([sys.executable, __file__, "--case", case, "--n", str(n)], env=env,
                         capture_output=True, text=True)
    if out.returncode != 0:
        raise RuntimeError(f"{__file__} --case {case} --n {n} failed:\n{out.stderr.strip()}")
    return json.loads(out.stdout.strip().splitlines()[-1])


def measure(quick: bool = False, full: bool = False) -> dict:
    """Both cases at each record length, each in its own process.

    Parameters
    ----------
    quick : bool
        1e5 samples only.
    full : bool
        Also 1e7 samples (the batch fit alone takes beyond 20 minutes there).

    Returns
    -------
    dict
        ``rows`` (:func:`measure_case` per case and length, shortest first) and ``full``.
    """
    sizes = [100_000] + ([] if quick else [1_000_000]) + ([10_000_000] if full else [])
    rows = []
    for n in sizes:
        for case in CASES:
            rows.append(run_case(case, n))
            r = rows[-1]
            print(f"{case} {n:.0e}: {r['traced_bytes_per_sample']:.0f} B/sample traced, "
                  f"{r['rss_growth_bytes_per_sample']:.0f} B/sample RSS, {r['seconds']:.1f} s",
                  flush=True)
    return {"rows": rows, "full": full}


def _count(n: float) -> str:
    return f"{n:,.0f}".replace(",", " ")


def render(payload: dict) -> str:
    """The table of bytes per sample, and the batch fit's time at the longest record.

    Parameters
    ----------
    payload : dict
        From :func:`measure`.

    Returns
    -------
    str
        Markdown.
    """
    rows = [[LABELS[r["case"]], f"{r['samples']:.0e}".replace("+0", ""),
             _count(r["traced_bytes_per_sample"]), _count(r["rss_growth_bytes_per_sample"]),
             _count(r["peak_rss_mb"]), f"{r['seconds']:.1f}"] for r in payload["rows"]]
    batch = [r for r in payload["rows"] if r["case"] == "batch"]
    longest = max(batch, key=lambda r: r["samples"])
    online = max((r for r in payload["rows"] if r["case"] == "online"),
                 key=lambda r: r["samples"])
    return "\n".join([
        table(rows, ["fit", "samples", "traced B/sample", "resident growth B/sample",
                     "peak resident MB", "seconds"]), "",
        f"The batch fit took {longest['seconds']:.0f} s at {longest['samples']:.0e} samples, "
        f"the on-line identifier {online['seconds']:.1f} s at {online['samples']:.0e}."
        .replace("e+0", "e")])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="1e5 samples only")
    parser.add_argument("--full", action="store_true", help="also run 1e7 samples")
    parser.add_argument("--case", choices=CASES, help=argparse.SUPPRESS)
    parser.add_argument("--n", type=int, help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.case:  # a child process: one case, its figures as JSON on stdout
        print(json.dumps(measure_case(args.case, args.n)))
        return
    payload = measure(args.quick, args.full)
    print()
    print(render(payload))
    write_json("bench_memory", payload)


if __name__ == "__main__":
    main()
