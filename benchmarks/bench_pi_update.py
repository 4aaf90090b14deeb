"""The PI recursion one sample at a time against its chunked path, in the same process.

On a reference-stage record (30 kHz, 1 nm noise) the identifier is warmed up on the first
``WARMUP`` samples, then run over the rest two ways from copies of that state: ``partial_fit``
on the whole rest (compiled chunks of :attr:`PIRecursiveIdentifier.chunk` samples) and
``update(u, y)`` once per sample. The table gives the time per sample of each (the best of
``--repeat`` runs), their ratio, and the largest difference between the two parameter
histories (relative to the largest parameter), for both regressor forms.

Usage: python benchmarks/bench_pi_update.py [--samples N] [--repeat R]
"""

from __future__ import annotations

import argparse
import copy
import time

import numpy as np
from _common import table, write_json

from hystid.identify.pi_recursive import PIRecursiveIdentifier
from hystid.pi import pi_thresholds
from hystid.reference import reference_record

WARMUP = 1000


def warmed(form: str, rec) -> PIRecursiveIdentifier:
    """An identifier that has taken the first ``WARMUP`` samples of ``rec``."""
    r = pi_thresholds(rec.u, 40)
    idf = PIRecursiveIdentifier(thresholds=r, form=form, fs=rec.fs,
                                warmup=WARMUP if form == "output-error" else 0)
    idf.partial_fit(rec[:WARMUP])
    return idf


def run_chunked(idf: PIRecursiveIdentifier, rec) -> tuple[float, np.ndarray]:
    """Seconds and parameter history of ``partial_fit`` over ``rec``."""
    t0 = time.perf_counter()
    res = idf.partial_fit(rec)
    return time.perf_counter() - t0, res.history


def run_updates(idf: PIRecursiveIdentifier, rec) -> tuple[float, np.ndarray]:
    """Seconds and parameter history of one ``update`` per sample of ``rec``."""
    u, y = rec.u.tolist(), rec.y.tolist()
    out = np.empty((len(u), len(idf.names)))
    update = idf.update
    t0 = time.perf_counter()
    for k in range(len(u)):
        out[k] = update(u[k], y[k])
    return time.perf_counter() - t0, out


def measure(form: str, samples: int, repeat: int) -> dict:
    """Per-sample times of both paths for one form, and how far their histories differ."""
    rec = reference_record(samples / 30_000.0, seed=0, noise=1e-3)
    start = warmed(form, rec)
    rest = rec[WARMUP:]
    run_chunked(copy.deepcopy(start), rest[:200])  # compile outside the timing
    run_updates(copy.deepcopy(start), rest[:200])
    chunked, single = float("inf"), float("inf")
    for _ in range(repeat):
        t, h_chunk = run_chunked(copy.deepcopy(start), rest)
        chunked = min(chunked, t)
        t, h_one = run_updates(copy.deepcopy(start), rest)
        single = min(single, t)
    n = rest.n
    diff = float(np.max(np.abs(h_one - h_chunk)) / np.max(np.abs(h_chunk)))
    return {"form": form, "samples": n, "us_per_sample_chunked": 1e6 * chunked / n,
            "us_per_sample_update": 1e6 * single / n, "ratio": single / chunked,
            "max_rel_history_difference": diff, "bit_equal": bool(np.array_equal(h_one, h_chunk))}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--samples", type=int, default=6000, help="record length (6000)")
    parser.add_argument("--repeat", type=int, default=3, help="runs, the best kept (3)")
    args = parser.parse_args()
    rows = [measure(form, args.samples, args.repeat) for form in ("output-error", "key-term")]
    print(table([[r["form"], r["samples"], f"{r['us_per_sample_chunked']:.2f}",
                  f"{r['us_per_sample_update']:.2f}", f"{r['ratio']:.2f}",
                  f"{r['max_rel_history_difference']:.1e}", r["bit_equal"]] for r in rows],
                ["form", "samples", "chunked us/sample", "update() us/sample",
                 "update / chunked", "history difference", "bit-equal"]))
    path = write_json("pi_update", {"warmup": WARMUP, "repeat": args.repeat, "rows": rows})
    print(f"wrote {path}")


if __name__ == "__main__":
    main()
