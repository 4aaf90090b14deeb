"""Speed-up of a fleet from 1 to 2 Dask workers, and what a record costs.

The same records (the reference stage, seeded excitations, 1 nm noise, saved as .npz) are
identified and validated (held-out end of each record, against the static line and the linear
model) three ways in this process:

* serially, with :func:`hystid.fleet.run_job` in a plain loop (no Dask: the baseline);
* on a local cluster of 1 worker process and of 2 worker processes (one thread each), with
  :func:`hystid.fleet.run_fleet` (``force=True``, results written as in production).

Each worker compiles (or loads) the kernels before the clock starts; the clusters' start-up time
is reported on its own. Every configuration is timed ``--repeat`` times, interleaved, and the
best is kept (the machine is shared: the load average is printed and stored). Goal: >= 1.7x
from 1 to 2 workers on a 2-core machine.

The withheld-effect cases of ``bench_withheld_effects.py`` (its ``run_case``, the first
``--withheld`` cases of its draw) run once serially and once through
:func:`hystid.fleet.map_seeds` on each cluster; the diagnoses must agree case by case. Usage:

    python benchmarks/bench_fleet.py [--records N] [--seconds S] [--repeat R] [--withheld M]
"""

from __future__ import annotations

import argparse
import contextlib
import os
import tempfile
import time
from pathlib import Path

# one BLAS thread in this process, as in Dask's worker processes: the serial loop is timed
# like for like (must come before NumPy is imported)
for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

from _common import table, write_json  # noqa: E402

from hystid.fleet import Job, fleet_client, map_seeds, run_fleet, run_job  # noqa: E402
from hystid.reference import reference_record  # noqa: E402


def warm_up(path: str) -> float:
    """Identify one short record so that the kernels are compiled or loaded from the cache."""
    t0 = time.perf_counter()
    run_job(Job("warm-up", path))
    return time.perf_counter() - t0


def make_records(folder: Path, count: int, seconds: float) -> list[Job]:
    """``count`` records of ``seconds`` from the reference stage, one seed each."""
    jobs = []
    for seed in range(count):
        path = folder / f"stage{seed:03d}.npz"
        reference_record(seconds, seed=seed, name=f"stage {seed}").save(path)
        jobs.append(Job(path.name, str(path)))
    return jobs


def withheld_jobs(count: int, seed: int = 2024) -> list[tuple]:
    """The first ``count`` cross-form cases of the withheld-effect check (its own draw)."""
    import numpy as np
    from bench_withheld_effects import jobs_cross_form

    jobs = jobs_cross_form(1, 4, np.random.default_rng(seed))
    return [jobs[i] for i in np.random.default_rng(seed).permutation(len(jobs))[:count]]


def withheld_case(job: tuple, n: int) -> dict:
    """One withheld-effect diagnosis (``bench_withheld_effects.diagnose_job``), without the
    time budget (``time_budget=0``: which forms are refitted does not depend on how fast the
    worker is, so the serial loop and every cluster make the same diagnoses)."""
    import bench_withheld_effects

    return bench_withheld_effects.diagnose_job(job, n, time_budget=0)


def time_withheld(jobs: list[tuple[str, int, int]], n: int, clusters: dict) -> dict:
    """Serial loop vs map_seeds on each cluster; the diagnoses must be the same."""
    import bench_withheld_effects
    import cloudpickle

    cloudpickle.register_pickle_by_value(bench_withheld_effects)  # workers need not import it
    keys = ("accepted", "top1_form", "rms_val_final")
    warm = (*jobs[0][:3], jobs[0][3] + 1)  # another case: kernels loaded everywhere
    withheld_case(warm, n // 3)
    for client, _ in clusters.values():
        client.run(withheld_case, warm, n // 3)
    t0 = time.perf_counter()
    serial = [withheld_case(j, n) for j in jobs]
    out = {"serial": time.perf_counter() - t0}
    for workers, (client, _) in clusters.items():
        t0 = time.perf_counter()
        rows = map_seeds(withheld_case, jobs, n, client=client)
        out[f"{workers} worker{'s' if workers > 1 else ''}"] = time.perf_counter() - t0
        for a, b in zip(serial, rows, strict=True):
            assert all(a[k] == b[k] for k in keys), (a, b)
    return out


def time_serial(jobs: list[Job]) -> float:
    t0 = time.perf_counter()
    rows = [run_job(j) for j in jobs]
    elapsed = time.perf_counter() - t0
    assert all(r["status"] == "ok" for r in rows), [r["error"] for r in rows]
    return elapsed


def time_fleet(client, jobs: list[Job], out: Path) -> float:
    t0 = time.perf_counter()
    result = run_fleet(jobs, out, client=client, force=True, progress=False)
    elapsed = time.perf_counter() - t0
    assert (result["status"] == "ok").all(), list(result["error"])
    return elapsed


def start_cluster(workers: int, warm_path: str, stack: contextlib.ExitStack):
    """A local cluster of ``workers`` single-threaded processes (:func:`fleet_client`, closed
    with ``stack``), warmed up; and its start-up time (cluster, client, kernels on every worker,
    one fleet of one record)."""
    t0 = time.perf_counter()
    client = stack.enter_context(fleet_client(workers))
    client.run(warm_up, warm_path)
    # the client's side too: pandas and pyarrow imported, the writers used once
    run_fleet([Job("warm-up", warm_path)], Path(warm_path).parent / f"warm{workers}",
              client=client, progress=False)
    return client, time.perf_counter() - t0


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--records", type=int, default=16, help="records (default 16)")
    parser.add_argument("--seconds", type=float, default=0.5,
                        help="length of each record in seconds (default 0.5 = 15 000 samples)")
    parser.add_argument("--repeat", type=int, default=3, help="timings per configuration")
    parser.add_argument("--withheld", type=int, default=12,
                        help="withheld-effect diagnoses (0.3 s + 0.3 s records) to run on the "
                        "clusters too (default 12; 0 to skip)")
    args = parser.parse_args()
    load_before = os.getloadavg()
    with tempfile.TemporaryDirectory(prefix="bench-fleet-") as tmp:
        folder = Path(tmp)
        jobs = make_records(folder, args.records, args.seconds)
        warm_path = str(folder / "warm.npz")
        reference_record(0.05, seed=999).save(warm_path)
        warm_up(warm_path)
        stack = contextlib.ExitStack()
        clusters = {n: start_cluster(n, warm_path, stack) for n in (1, 2)}
        times: dict[str, list[float]] = {"serial": [], "1 worker": [], "2 workers": []}
        with stack:
            for r in range(args.repeat):
                times["serial"].append(time_serial(jobs))
                for n, (client, _) in clusters.items():
                    label = f"{n} worker{'s' if n > 1 else ''}"
                    times[label].append(time_fleet(client, jobs, folder / f"out{n}-{r}"))
                print(f"round {r + 1}/{args.repeat}: " + ", ".join(
                    f"{k} {v[-1]:.2f} s" for k, v in times.items()), flush=True)
            withheld = (time_withheld(withheld_jobs(args.withheld), 9000, clusters)
                        if args.withheld else {})
    load_after = os.getloadavg()
    best = {k: min(v) for k, v in times.items()}
    speedup = best["1 worker"] / best["2 workers"]
    rows = [[k, f"{best[k]:.2f}", f"{1e3 * best[k] / args.records:.0f}",
             f"{best['serial'] / best[k]:.2f}", " ".join(f"{t:.2f}" for t in v)]
            for k, v in times.items()]
    print(f"\n{args.records} records of {args.seconds:g} s ({int(args.seconds * 30000)} samples),"
          f" identify + held-out comparison with the baselines")
    print(table(rows, ["configuration", "best [s]", "ms per record", "speed vs serial",
                       "all timings [s]"]))
    startup = {f"{n} worker{'s' if n > 1 else ''}": c[1] for n, c in clusters.items()}
    print(f"\nspeed-up from 1 to 2 workers: {speedup:.2f}x (goal >= 1.7x)")
    print(f"Dask overhead with 1 worker: {100 * (best['1 worker'] / best['serial'] - 1):+.1f} % "
          f"against the serial loop")
    print("cluster start-up incl. kernel warm-up: "
          + ", ".join(f"{k} {v:.1f} s" for k, v in startup.items()))
    if withheld:
        ratio = withheld["1 worker"] / withheld["2 workers"]
        print(f"\n{args.withheld} withheld-effect diagnoses through map_seeds (same diagnoses as "
              "the serial loop): " + ", ".join(f"{k} {v:.1f} s" for k, v in withheld.items())
              + f"; speed-up from 1 to 2 workers {ratio:.2f}x")
    print(f"load average (1, 5, 15 min) before {load_before[0]:.2f} {load_before[1]:.2f} "
          f"{load_before[2]:.2f}, after {load_after[0]:.2f} {load_after[1]:.2f} "
          f"{load_after[2]:.2f} on {os.cpu_count()} cores")
    path = write_json("fleet", {
        "settings": {"records": args.records, "seconds": args.seconds, "repeat": args.repeat},
        "timings_s": times, "best_s": best,
        "ms_per_record": {k: 1e3 * v / args.records for k, v in best.items()},
        "speedup_1_to_2_workers": speedup, "goal_speedup": 1.7,
        "overhead_1_worker_vs_serial": best["1 worker"] / best["serial"] - 1,
        "withheld_effect_diagnoses": {"cases": args.withheld, "seconds": withheld},
        "startup_s": startup, "cores": os.cpu_count(),
        "load_average_before": load_before, "load_average_after": load_after})
    print(f"wrote {path}")


if __name__ == "__main__":
    main()
