"""The filterpy EKF baseline on the reference stage: convergence and speed.

For each sensor noise (0, 1 and 10 nm), seed and start (the paper's theta0 = 0.01, and the linear
ARX bootstrap on the first 300 samples), runs :class:`hystid.identify.ekf.KalmanIdentifier` with
its default settings (``r = max(noise, 1 nm)^2``) over a reference-stage record and reports the
samples after which the max relative parameter error stays below 2 % and 0.1 %, the final max
relative error, the stop-index sample (epsilon = 1e-4), the guards' counters and the speed (as
samples per second and as a ratio against the compiled simulation of the same record).

Usage: python benchmarks/bench_ekf.py [--quick] [--samples N] [--seeds S] [--alpha-min A]

Prints every run and the README's summary (block ``ekf``, see ``benchmarks/readme.py``); writes
``benchmarks/results/ekf.json`` (``ekf_alpha_min_A.json`` with ``--alpha-min``).
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

#: The README blocks this script renders (see ``benchmarks/readme.py``).
README_BLOCKS = {"ekf": "render"}
#: The command that measures the README's figures (one BLAS thread, as in the README).
COMMAND = "OPENBLAS_NUM_THREADS=1 python benchmarks/bench_ekf.py"


def settle_sample(rel: np.ndarray, level: float) -> int | None:
    """First sample after which ``rel`` stays at or below ``level`` (None: never)."""
    above = np.flatnonzero(rel > level)
    if len(above) == 0:
        return 0
    k = int(above[-1]) + 1
    return k if k < len(rel) else None


def run_one(n: int, noise: float, seed: int, theta0, truth: np.ndarray, **settings) -> dict:
    """One EKF run on a reference-stage record.

    Parameters
    ----------
    n : int
        Record length, samples.
    noise : float
        Sensor noise RMS, um.
    seed : int
        Seed of the record.
    theta0 : float or str
        The start (``"linear"``: the ARX bootstrap).
    truth : ndarray
        The stage's parameters.
    **settings
        Passed to :class:`~hystid.identify.ekf.KalmanIdentifier`.

    Returns
    -------
    dict
        The figures of one row: samples to 2 % and 0.1 %, final error, guards, speed.
    """
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


def measure(quick: bool = False, samples: int | None = None, seeds: int | None = None,
            alpha_min: float | None = None) -> dict:
    """Every start, noise level and seed.

    Parameters
    ----------
    quick : bool
        3 000 samples and one seed instead of 30 000 samples and three.
    samples : int, optional
        Record length (overrides ``quick``).
    seeds : int, optional
        Number of seeds (overrides ``quick``).
    alpha_min : float, optional
        The alpha floor instead of the default.

    Returns
    -------
    dict
        ``samples``, ``seeds``, ``settings`` (as used), ``truth`` and ``runs`` (one per start,
        noise and seed: :func:`run_one`).
    """
    settings = {} if alpha_min is None else {"alpha_min": alpha_min}
    n = samples or (3_000 if quick else 30_000)
    seed_list = list(range(seeds or (1 if quick else 3)))
    truth = reference_model().theta
    KalmanIdentifier().fit(reference_record(0.01, seed=0))  # compile outside the timing
    runs = [run_one(n, noise, seed, theta0, truth, **settings)
            for theta0 in STARTS for noise in NOISES for seed in seed_list]
    used = KalmanIdentifier(**settings).settings
    used["r"] = "max(noise, 1e-3)**2"
    return {"samples": n, "seeds": seed_list, "settings": used,
            "truth": dict(reference_model().params), "runs": runs}


def _samples(k: int | None) -> str:
    return "never" if k is None else f"{k:,}".replace(",", " ")


def runs_table(payload: dict) -> str:
    """Every run as one row.

    Parameters
    ----------
    payload : dict
        From :func:`measure`.

    Returns
    -------
    str
        A Markdown table.
    """
    rows = [[r["start"], f"{r['noise_nm']:g}", r["seed"], f"{r['start_max_rel_error']:.2f}",
             _samples(r["samples_to_2pc"]), _samples(r["samples_to_0.1pc"]),
             f"{r['final_max_rel_error']:.2e}", _samples(r["converged_at"]),
             r["n_projections"], r["n_resets"], f"{r['samples_per_second']:.0f}",
             f"{r['time_ratio_vs_simulation']:.0f}"] for r in payload["runs"]]
    return table(rows, ["theta0", "noise nm", "seed", "start err", "to 2 %", "to 0.1 %",
                        "final err", "stop index", "proj", "resets", "samples/s",
                        "time / simulation"])


def _span(values: list, fmt) -> str:
    """``lo - hi`` of the values that are not None, or a single value; "never" when none is."""
    got = sorted(v for v in values if v is not None)
    if not got:
        return "never"
    text = fmt(got[0]) if got[0] == got[-1] else f"{fmt(got[0])} - {fmt(got[-1])}"
    missing = len(values) - len(got)
    return text + (f" ({missing} of {len(values)} never)" if missing else "")


def render(payload: dict) -> str:
    """The runs summarised per start and noise level, and the speed.

    Parameters
    ----------
    payload : dict
        From :func:`measure`.

    Returns
    -------
    str
        Markdown: a sentence on the runs, the table, the speed sentence.
    """
    runs, seeds = payload["runs"], payload["seeds"]
    labels = {"0.01": "theta(0) = 0.01", "linear": "linear ARX start"}
    rows = []
    for start in dict.fromkeys(r["start"] for r in runs):
        for noise in dict.fromkeys(r["noise_nm"] for r in runs):
            rs = [r for r in runs if r["start"] == start and r["noise_nm"] == noise]
            rows.append([labels.get(start, start), "0" if noise == 0 else f"{noise:g} nm",
                         _span([r["samples_to_2pc"] for r in rs], _samples),
                         ", ".join(_samples(r["samples_to_0.1pc"]) for r in rs),
                         _span([r["final_max_rel_error"] for r in rs], lambda x: f"{x:.2g}")])
    rate = [r["samples_per_second"] for r in runs]
    ratio = [r["time_ratio_vs_simulation"] for r in runs]
    seed_text = f"seed {seeds[0]}" if len(seeds) == 1 else f"seeds {seeds[0]}-{seeds[-1]}"
    return "\n".join([
        f"{_samples(payload['samples'])} samples per record, {seed_text}; \"samples to 0.1 %\" "
        "per seed, the others as the range over the seeds (max relative parameter error):", "",
        table(rows, ["start", "noise", "samples to 2 %", "samples to 0.1 %", "final err"]), "",
        f"Speed: {min(rate):,.0f}-{max(rate):,.0f} samples per second "
        f"({min(ratio):.0f}-{max(ratio):.0f}x the time of the compiled simulation of the same "
        "record).".replace(",", " ")])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--quick", action="store_true", help="3 000 samples, one seed")
    parser.add_argument("--samples", type=int, default=None)
    parser.add_argument("--seeds", type=int, default=None)
    parser.add_argument("--alpha-min", type=float, default=None,
                        help="override the alpha floor (1e-9: only alpha > 0, for the ablation)")
    args = parser.parse_args()
    payload = measure(args.quick, args.samples, args.seeds, args.alpha_min)
    print(f"EKF baseline (filterpy ExtendedKalmanFilter, settings {payload['settings']}), "
          f"reference stage; errors are max relative parameter errors")
    print(runs_table(payload))
    print()
    print(render(payload))
    name = "ekf" if args.alpha_min is None else f"ekf_alpha_min_{args.alpha_min:g}"
    print(f"wrote {write_json(name, payload)}")


if __name__ == "__main__":
    main()
