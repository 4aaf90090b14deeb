"""The filterpy EKF baseline on the reference stage: convergence and speed.

For each sensor noise (0, 1 and 10 nm), seed and start (the paper's theta0 = 0.01, and the linear
ARX bootstrap on the first 300 samples), runs :class:`hystid.identify.ekf.KalmanIdentifier` with
its default settings (``r = max(noise, 1 nm)^2``) over a reference-stage record and reports the
samples after which the max relative parameter error stays below 2 % and 0.1 %, the final max
relative error, the stop-index sample (epsilon = 1e-4), the guards' counters and the speed (as
samples per second and as a ratio against the compiled simulation of the same record).

Usage: python benchmarks/bench_ekf.py [--quick] [--samples N] [--seeds S] [--alpha-min A]
"""

from __future__ import annotations

import argparse
import time
import warnings

import numpy as np
from _common import best_time, table, write_json

from hystid.identify.ekf import KalmanIdentifier
from hystid.reference import reference_model, reference_record

NOISES = (0.0, 1e-3, 1e-2)
STARTS = (0.01, "linear")


def settle_sample(rel: np.ndarray, level: float) -> int | None:
    """First sample after which ``rel`` stays at or below ``level`` (None: never)."""
    above = np.flatnonzero(rel > level)
    if len(above) == 0:
        return 0
    k = int(above[-1]) + 1
    return k if k < len(rel) else None


def run_one(n: int, noise: float, seed: int, theta0, truth: np.ndarray, **settings) -> dict:
    """One EKF run; returns the figures of one table row."""
    record = reference_record(n / 30_000.0, seed=seed, noise=noise)
    ekf = KalmanIdentifier(theta0=theta0, r=max(noise, 1e-3) ** 2, **settings)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        t0 = time.perf_counter()
        result = ekf.fit(record)
        seconds = time.perf_counter() - t0
    rel = np.max(np.abs(result.history - truth) / np.abs(truth), axis=1)
    sim = best_time(lambda: reference_model().simulate(record.u), repeat=3)
    start_rel = float(np.max(np.abs(ekf.theta_start_ - truth) / np.abs(truth)))
    return {
        "noise_nm": noise * 1e3, "seed": seed, "start": str(theta0), "samples": n,
        "start_max_rel_error": start_rel,
        "samples_to_2pc": settle_sample(rel, 0.02),
        "samples_to_0.1pc": settle_sample(rel, 1e-3),
        "final_max_rel_error": float(rel[-1]),
        "converged_at": result.converged_at,
        "n_resets": ekf.n_resets, "n_projections": ekf.n_projections,
        "samples_per_second": n / seconds,
        "time_ratio_vs_simulation": seconds / sim,
        "final_params": result.params,
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--quick", action="store_true", help="3 000 samples, one seed")
    parser.add_argument("--samples", type=int, default=None)
    parser.add_argument("--seeds", type=int, default=None)
    parser.add_argument("--alpha-min", type=float, default=None,
                        help="override the alpha floor (1e-9: only alpha > 0, for the ablation)")
    args = parser.parse_args()
    settings = {} if args.alpha_min is None else {"alpha_min": args.alpha_min}
    n = args.samples or (3_000 if args.quick else 30_000)
    seeds = range(args.seeds or (1 if args.quick else 3))
    truth = reference_model().theta
    KalmanIdentifier().fit(reference_record(0.01, seed=0))  # compile outside the timing
    rows, out = [], []
    for theta0 in STARTS:
        for noise in NOISES:
            for seed in seeds:
                r = run_one(n, noise, seed, theta0, truth, **settings)
                out.append(r)
                rows.append([
                    r["start"], f"{r['noise_nm']:g}", seed, f"{r['start_max_rel_error']:.2f}",
                    r["samples_to_2pc"] if r["samples_to_2pc"] is not None else "never",
                    r["samples_to_0.1pc"] if r["samples_to_0.1pc"] is not None else "never",
                    f"{r['final_max_rel_error']:.2e}",
                    r["converged_at"] if r["converged_at"] is not None else "never",
                    r["n_projections"], r["n_resets"],
                    f"{r['samples_per_second']:.0f}", f"{r['time_ratio_vs_simulation']:.0f}",
                ])
                print(".", end="", flush=True)
    print()
    print(f"EKF baseline (filterpy ExtendedKalmanFilter, settings: default {settings}), "
          f"reference stage, {n} samples per record; errors are max relative parameter errors")
    print(table(rows, ["theta0", "noise nm", "seed", "start err", "to 2 %", "to 0.1 %",
                       "final err", "stop index", "proj", "resets", "samples/s",
                       "time / simulation"]))
    used = KalmanIdentifier(**settings).settings
    used["r"] = "max(noise, 1e-3)**2"
    name = "ekf" if not settings else f"ekf_alpha_min_{args.alpha_min:g}"
    path = write_json(name, {"samples": n, "seeds": list(seeds), "settings": used,
                              "truth": dict(reference_model().params), "runs": out})
    print(f"wrote {path}")


if __name__ == "__main__":
    main()
