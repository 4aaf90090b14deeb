"""Identification methods on the reference stage: convergence, accuracy, validation and speed.

For each method (off-line batch output error, the paper's ERIA, the converging on-line RPEM and
the filterpy EKF baseline) and each noise level, over seeds: samples until the estimate stays
within 2 % and 0.1 % of the truth, final max relative error, validation error range and RMS on a
fresh record, samples per second, restarts. Usage:

    python benchmarks/bench_identify.py [--quick] [--seeds N] [--samples N]
"""

from __future__ import annotations

import argparse
import time
import warnings

import numpy as np
from _common import table, write_json

from hystid.identify import identify
from hystid.metrics import validate
from hystid.reference import PAPER_PARAMS, reference_record

TRUTH = np.array(list(PAPER_PARAMS.values()))


def samples_to(err: np.ndarray, bound: float) -> int | None:
    """First sample count after which ``err`` stays below ``bound`` (None if never)."""
    above = np.flatnonzero(err > bound)
    if len(above) == 0:
        return 1
    k = int(above[-1]) + 2
    return k if k <= len(err) else None


def run_one(method: str, seed: int, noise: float, n: int) -> dict:
    rec = reference_record(n / 30_000.0, seed=seed, noise=noise)
    val = reference_record(0.5, seed=10_000 + seed, noise=noise)
    settings = {"truth": PAPER_PARAMS} if method == "eria" else {}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        t0 = time.perf_counter()
        res = identify(rec, method=method, **settings)
        elapsed = time.perf_counter() - t0
    final = float(np.max(np.abs(res.model.theta - TRUTH) / np.abs(TRUTH)))
    row = {"method": method, "seed": seed, "noise_nm": noise * 1e3, "final_err": final,
           "samples_per_s": n / elapsed, "restarts": res.info.get("n_recoveries", 0)}
    if res.history is not None:
        err = np.max(np.abs(res.history - TRUTH) / np.abs(TRUTH), axis=1)
        row.update(to_2pc=samples_to(err, 0.02), to_01pc=samples_to(err, 1e-3),
                   err_at_1000=float(err[min(999, n - 1)]), nan=bool(np.isnan(err).any()))
    finite = np.all(np.isfinite(res.model.theta))
    if finite and res.model.is_stable():
        v = validate(val.y, res.model.simulate(val.u).y, val.fs)
        row.update(val_min=v.err_min, val_max=v.err_max, val_rms=v.rms)
    return row


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


def throughput(method: str, seconds: float) -> dict:
    """Steady-state samples per second of a recursive method (start-up excluded)."""
    from hystid.identify.eria import ERIA
    from hystid.identify.online import OnlineIdentifier

    cls = {"online": OnlineIdentifier, "eria": ERIA}.get(method)
    if cls is None:
        from hystid.identify.ekf import KalmanIdentifier as cls
    rec = reference_record(seconds, seed=99)
    est = cls()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        est.fit(rec[:2_000])
        t0 = time.perf_counter()
        est.fit(rec[2_000:])
        elapsed = time.perf_counter() - t0
    rate = (rec.n - 2_000) / elapsed
    return {"method": method, "samples": rec.n - 2_000, "samples_per_s": rate,
            "x_30kHz": rate / 30_000.0}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--quick", action="store_true", help="3 seeds, 6 000 samples")
    parser.add_argument("--seeds", type=int, default=None, help="seeds for the online method")
    parser.add_argument("--samples", type=int, default=None)
    parser.add_argument("--methods", default="batch,eria,online,ekf")
    args = parser.parse_args()
    n = args.samples or (6_000 if args.quick else 30_000)
    seeds_online = args.seeds or (3 if args.quick else 20)
    seeds_other = min(seeds_online, 3 if args.quick else 5)
    with warnings.catch_warnings():  # compile outside the timing
        warnings.simplefilter("ignore", RuntimeWarning)
        identify(reference_record(0.02), method="online")
        identify(reference_record(0.02), method="eria")
    rows = []
    for method in args.methods.split(","):
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
    for method in args.methods.split(","):
        if method != "batch":
            seconds = (0.5 if args.quick else 2.0) if method == "ekf" else \
                (2.0 if args.quick else 10.0)
            speed.append(throughput(method, seconds))
    print("\nSteady-state throughput on one core (start-up excluded), baseline: a 30 kHz loop")
    print(table([[r["method"], f"{r['samples']}", f"{r['samples_per_s']:.3g}",
                  f"{r['x_30kHz']:.1f}x"] for r in speed],
                ["method", "samples", "samples/s", "vs 30 kHz real time"]))
    path = write_json("identify", {"samples": n, "rows": rows, "throughput": speed})
    print(f"wrote {path}")


if __name__ == "__main__":
    main()
