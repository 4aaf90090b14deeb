"""Identification methods on the reference stage: convergence, accuracy, validation and speed.

For each method (off-line batch output error, the paper's ERIA, the converging on-line RPEM and
the filterpy EKF baseline) and each noise level, over seeds: samples until the estimate stays
within 2 % and 0.1 % of the truth, final max relative error, validation error range and RMS on a
fresh record, samples per second, restarts. Then, for the on-line identifier and the PI
recursion: per-sample ``update()`` against the chunked ``partial_fit()`` on the same samples
(a ratio in one process,
the two timed in alternation, best of several rounds), and the memory a ``fit`` keeps per sample
(history and diagnostics, default decimated history) from 1e5 to 1e7 samples. Usage:

    python benchmarks/bench_identify.py [--quick] [--seeds N] [--samples N] [--methods ...]
    python benchmarks/bench_identify.py --methods none        # only the speed and memory part
"""

from __future__ import annotations

import argparse
import time
import warnings

import numpy as np
from _common import table, write_json
from figures import reference_identification, start_up_run

from hystid.identify import identify
from hystid.reference import reference_record


def run_one(method: str, seed: int, noise: float, n: int) -> dict:
    """One row of the table: :func:`figures.reference_identification`."""
    return reference_identification(method, seed=seed, noise=noise, samples=n)


def summarise(rows: list[dict]) -> list[list[str]]:
    out = []
    keys = sorted({(r["method"], r["noise_nm"]) for r in rows}, key=lambda x: (x[1], x[0]))
    for method, noise in keys:
        rs = [r for r in rows if r["method"] == method and r["noise_nm"] == noise]

        def med(key, rs=rs):
            vals = [r[key] for r in rs if r.get(key) is not None]
            if len(vals) < len(rs):
                return f"never ({len(rs) - len(vals)}/{len(rs)})" if vals == [] else \
                    f"{np.median(vals):.0f} ({len(rs) - len(vals)} never)"
            return f"{np.median(vals):.0f}"

        has_hist = "to_2pc" in rs[0]
        vr = [r for r in rs if "val_rms" in r]
        out.append([
            method, f"{noise:g}", str(len(rs)),
            med("to_2pc") if has_hist else "-", med("to_01pc") if has_hist else "-",
            f"{np.median([r['final_err'] for r in rs]):.2e}",
            f"{max(r['final_err'] for r in rs):.2e}",
            (f"{min(r['val_min'] for r in vr) * 1e3:.1f} .. "
             f"{max(r['val_max'] for r in vr) * 1e3:.1f}" if vr else "unstable"),
            f"{np.median([r['val_rms'] for r in vr]) * 1e3:.2f}" if vr else "-",
            f"{np.median([r['samples_per_s'] for r in rs]):.3g}",
            str(sum(r["restarts"] for r in rs)),
            "yes" if any(r.get("nan") for r in rs) else "no",
        ])
    return out


def estimator(method: str):
    """A fresh on-line estimator of ``method`` (the PI recursion warms up on 1 500 samples)."""
    from hystid.identify.ekf import KalmanIdentifier
    from hystid.identify.eria import ERIA
    from hystid.identify.online import OnlineIdentifier
    from hystid.identify.pi_recursive import PIRecursiveIdentifier

    makers = {"online": OnlineIdentifier, "eria": ERIA, "ekf": KalmanIdentifier,
              "pi-recursive": lambda: PIRecursiveIdentifier(warmup=1_500)}
    return makers[method]()


def throughput(method: str, seconds: float) -> dict:
    """Steady-state samples per second of a recursive method (start-up excluded)."""
    rec = reference_record(seconds, seed=99)
    est = estimator(method)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        est.fit(rec[:2_000])
        t0 = time.perf_counter()
        est.partial_fit(rec[2_000:])
        elapsed = time.perf_counter() - t0
    rate = (rec.n - 2_000) / elapsed
    return {"method": method, "samples": rec.n - 2_000, "samples_per_s": rate,
            "x_30kHz": rate / 30_000.0}


def per_sample_ratio(samples: int = 30_000, rounds: int = 5, method: str = "online") -> dict:
    """Per-sample ``update()`` vs chunked ``partial_fit()`` of an on-line estimator.

    Both run from the same state (after start-up) over the same samples; the two are timed in
    alternation ``rounds`` times and the best of each is kept, so a busy machine slows both.
    """
    import copy

    rec = reference_record((samples + 3_000) / 30_000.0, seed=99)
    warm, rest = rec[:3_000], rec[3_000:]
    base = estimator(method)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        base.fit(warm)
        u, y = rest.u.tolist(), rest.y.tolist()
        best_chunk = best_step = float("inf")
        for _ in range(rounds):
            est = copy.deepcopy(base)
            t0 = time.perf_counter()
            est.partial_fit(rest)
            best_chunk = min(best_chunk, time.perf_counter() - t0)
            est = copy.deepcopy(base)
            update = est.update
            t0 = time.perf_counter()
            for a, b in zip(u, y, strict=True):
                update(a, b)
            best_step = min(best_step, time.perf_counter() - t0)
    n = rest.n
    return {"method": method, "samples": n, "chunked_per_s": n / best_chunk,
            "update_per_s": n / best_step, "ratio": best_step / best_chunk}


def start_up_basins(seeds: int = 20, seconds: float = 1.0) -> list[dict]:
    """Wrong-basin rate of the on-line identifier's start-up on two simulators
    (:func:`figures.start_up_run`, 1 s records from rest, 0, 1 and 10 nm)."""
    rows = []
    for source in ("reference", "stages"):
        for noise in (0.0, 1e-3, 1e-2):
            done = [start_up_run(source, noise, seed, seconds) for seed in range(seeds)]
            rows += done
            print(f"  {source} {noise * 1e3:g} nm: {sum(r['wrong_basin'] for r in done)} "
                  f"wrong of {len(done)}", flush=True)
    return rows


def memory_per_sample(sizes: tuple[int, ...]) -> list[dict]:
    """Bytes a ``fit`` keeps per sample (history, diagnostics) and peak traced bytes per sample.

    The input is the paper's excitation repeated; the output is the reference stage's
    simulation with 1 nm noise. ``tracemalloc`` follows numpy's allocations.
    """
    import tracemalloc

    from hystid.identify.online import OnlineIdentifier
    from hystid.records import Record
    from hystid.reference import reference_model

    period = reference_record(1.0, seed=5)
    model = reference_model()
    rows = []
    for n in sizes:
        u = np.resize(period.u[3_000:], n)
        u[:3_000] = period.u[:3_000]
        y = model.simulate(u, check=False).y + 1e-3 * np.random.default_rng(1).standard_normal(n)
        rec = Record(u, y, 30_000.0, name=f"{n} samples")
        del y
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            tracemalloc.start()
            t0 = time.perf_counter()
            res = OnlineIdentifier().fit(rec)
            elapsed = time.perf_counter() - t0
            peak = tracemalloc.get_traced_memory()[1]
            tracemalloc.stop()
        kept = res.history.nbytes + res.info["diagnostics"].nbytes
        rows.append({"samples": n, "kept_bytes_per_sample": kept / n,
                     "peak_bytes_per_sample": peak / n, "history_rows": len(res.history),
                     "seconds": elapsed})
        del rec, res
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--quick", action="store_true", help="3 seeds, 6 000 samples")
    parser.add_argument("--seeds", type=int, default=None, help="seeds for the online method")
    parser.add_argument("--samples", type=int, default=None)
    parser.add_argument("--methods", default="batch,eria,online,ekf",
                        help="comma-separated, or 'none' for the speed and memory part only")
    parser.add_argument("--basins", type=int, default=20,
                        help="seeds of the start-up wrong-basin measurement (0: skip)")
    parser.add_argument("--memory", default="1e5,1e6,1e7",
                        help="record lengths of the memory measurement")
    args = parser.parse_args()
    if args.methods == "none":
        args.methods = ""
    n = args.samples or (6_000 if args.quick else 30_000)
    seeds_online = args.seeds or (3 if args.quick else 20)
    seeds_other = min(seeds_online, 3 if args.quick else 5)
    with warnings.catch_warnings():  # compile outside the timing
        warnings.simplefilter("ignore", RuntimeWarning)
        identify(reference_record(0.02), method="online")
        identify(reference_record(0.02), method="eria")
    rows = []
    for method in filter(None, args.methods.split(",")):
        seeds = seeds_online if method == "online" else seeds_other
        for noise in (0.0, 1e-3, 1e-2):
            for seed in range(seeds):
                rows.append(run_one(method, seed, noise, n))
            print(f"  {method:6s} noise {noise * 1e3:g} nm: {seeds} seeds done", flush=True)
    header = ["method", "noise nm", "seeds", "samples to 2 %", "samples to 0.1 %",
              "final err (median)", "final err (worst)", "val error [nm]", "val RMS [nm]",
              "samples/s", "restarts", "NaN"]
    print(f"\nReference stage, {n} samples per record, theta(0) = 0.01, records from rest")
    print(table(summarise(rows), header))
    speed = []
    for method in filter(None, args.methods.split(",")):
        if method != "batch":
            seconds = (0.5 if args.quick else 2.0) if method == "ekf" else \
                (2.0 if args.quick else 10.0)
            speed.append(throughput(method, seconds))
    speed.append(throughput("pi-recursive", 1.0 if args.quick else 3.0))
    print("\nSteady-state throughput on one core (start-up excluded), baseline: a 30 kHz loop")
    print(table([[r["method"], f"{r['samples']}", f"{r['samples_per_s']:.3g}",
                  f"{r['x_30kHz']:.1f}x"] for r in speed],
                ["method", "samples", "samples/s", "vs 30 kHz real time"]))
    ratios = [per_sample_ratio(6_000 if args.quick else 30_000, method=method)
              for method in ("online", "pi-recursive")]
    print("\nPer-sample update() vs chunked partial_fit(), same samples, best of 5 alternating "
          "rounds (goal: at most 3x)")
    print(table([[r["method"], f"{r['samples']}", f"{r['chunked_per_s']:.3g}",
                  f"{r['update_per_s']:.3g}", f"{r['ratio']:.2f}x"] for r in ratios],
                ["estimator", "samples", "chunked samples/s", "update() samples/s",
                 "update / chunked"]))
    basins = start_up_basins(args.basins) if args.basins else []
    if basins:
        print("\nOn-line start-up over seeds, 1 s records from rest: wrong basin = final max "
              "relative error > 20 % (goal 0); retried = start-up solved again on more samples")
        out = []
        for source in ("reference", "stages"):
            for noise in (0.0, 1.0, 10.0):
                rs = [r for r in basins if r["source"] == source and r["noise_nm"] == noise]
                out.append([source, f"{noise:g}", str(len(rs)),
                            str(sum(r["wrong_basin"] for r in rs)),
                            str(sum(r["wrong_basin"] and not r["warned"] for r in rs)),
                            str(sum(r["start_samples"] > 400 for r in rs)),
                            str(sum(r["warned"] for r in rs)),
                            f"{np.median([r['final_err'] for r in rs]):.2e}",
                            f"{max(r['final_err'] for r in rs):.2e}"])
        print(table(out, ["simulator", "noise nm", "seeds", "wrong basin", "silent",
                          "retried", "warned", "final err (median)", "final err (worst)"]))
    sizes = tuple(int(float(v)) for v in args.memory.split(","))
    mem = memory_per_sample(sizes)
    print("\nOn-line fit memory (default decimated history), bytes per sample")
    print(table([[f"{r['samples']:.0e}", f"{r['kept_bytes_per_sample']:.3g}",
                  f"{r['peak_bytes_per_sample']:.3g}", str(r["history_rows"]),
                  f"{r['seconds']:.1f}"] for r in mem],
                ["samples", "kept (history + diagnostics)", "peak traced", "history rows",
                 "fit s"]))
    path = write_json("identify", {"samples": n, "rows": rows, "throughput": speed,
                                   "per_sample": ratios, "memory": mem,
                                   "start_up_basins": basins})
    print(f"wrote {path}")


if __name__ == "__main__":
    main()
