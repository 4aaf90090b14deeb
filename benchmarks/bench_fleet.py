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

    python benchmarks/bench_fleet.py [--quick] [--records N] [--seconds S] [--repeat R]
                                     [--withheld M]
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

#: The README blocks this script renders (see ``benchmarks/readme.py``).
README_BLOCKS = {"fleet": "render"}


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


def measure(quick: bool = False, records: int = 16, seconds: float = 0.5, repeat: int = 3,
            withheld: int = 12) -> dict:
    """Time the fleet serially and on 1 and 2 local workers (and the withheld-effect cases).

    Parameters
    ----------
    quick : bool
        4 records, one timing, 2 withheld-effect cases.
    records, seconds, repeat, withheld : int, float, int, int
        Records, their length, timings per configuration, withheld-effect diagnoses (0: none).

    Returns
    -------
    dict
        Timings, the best of each, per-record times, speed-up, start-up, load averages.
    """
    if quick:
        records, repeat, withheld = 4, 1, 2
    load_before = os.getloadavg()
    with tempfile.TemporaryDirectory(prefix="bench-fleet-") as tmp:
        folder = Path(tmp)
        jobs = make_records(folder, records, seconds)
        warm_path = str(folder / "warm.npz")
        reference_record(0.05, seed=999).save(warm_path)
        warm_up(warm_path)
        stack = contextlib.ExitStack()
        clusters = {n: start_cluster(n, warm_path, stack) for n in (1, 2)}
        times: dict[str, list[float]] = {"serial": [], "1 worker": [], "2 workers": []}
        with stack:
            for r in range(repeat):
                times["serial"].append(time_serial(jobs))
                for n, (client, _) in clusters.items():
                    label = f"{n} worker{'s' if n > 1 else ''}"
                    times[label].append(time_fleet(client, jobs, folder / f"out{n}-{r}"))
                print(f"round {r + 1}/{repeat}: " + ", ".join(
                    f"{k} {v[-1]:.2f} s" for k, v in times.items()), flush=True)
            diagnoses = (time_withheld(withheld_jobs(withheld), 9000, clusters)
                         if withheld else {})
    best = {k: min(v) for k, v in times.items()}
    return {
        "settings": {"records": records, "seconds": seconds, "repeat": repeat},
        "timings_s": times, "best_s": best,
        "ms_per_record": {k: 1e3 * v / records for k, v in best.items()},
        "speedup_1_to_2_workers": best["1 worker"] / best["2 workers"], "goal_speedup": 1.7,
        "overhead_1_worker_vs_serial": best["1 worker"] / best["serial"] - 1,
        "withheld_effect_diagnoses": {"cases": withheld, "seconds": diagnoses},
        "startup_s": {f"{n} worker{'s' if n > 1 else ''}": c[1] for n, c in clusters.items()},
        "cores": os.cpu_count(), "load_average_before": load_before,
        "load_average_after": os.getloadavg()}


def render(payload: dict) -> str:
    """The fleet's timings as Markdown.

    Parameters
    ----------
    payload : dict
        From :func:`measure`.

    Returns
    -------
    str
    """
    st, ms = payload["settings"], payload["ms_per_record"]
    configs = ("serial", "1 worker", "2 workers")
    rows = [["per record (best of the timings)", *(f"{ms[k]:.0f} ms" for k in configs)],
            [f"speed-up from 1 to 2 workers (goal >= {payload['goal_speedup']:g}x)", "", "",
             f"**{payload['speedup_1_to_2_workers']:.2f}x**"]]
    w = payload["withheld_effect_diagnoses"]
    if w["seconds"]:
        sec = w["seconds"]
        rows.append([f"{w['cases']} withheld-effect diagnoses via `map_seeds`",
                     *(f"{sec[k]:.1f} s" for k in configs[:2]),
                     f"{sec['2 workers']:.1f} s ({sec['1 worker'] / sec['2 workers']:.2f}x)"])
    before, after = payload["load_average_before"], payload["load_average_after"]
    startup = payload["startup_s"]
    return "\n".join([
        f"{st['records']} records of {st['seconds']:g} s from the reference stage, identified "
        f"(the default member, chosen per record) on 60 % and scored on the rest against both "
        f"baselines; best of {st['repeat']} interleaved timings; load average "
        f"{before[0]:.1f} before, {after[0]:.1f} after, on {payload['cores']} cores:", "",
        table(rows, ["", "serial loop, no Dask", "1 worker", "2 workers"]), "",
        f"A fleet on one worker takes {abs(100 * payload['overhead_1_worker_vs_serial']):.1f} % "
        f"{'more' if payload['overhead_1_worker_vs_serial'] > 0 else 'less'} time than the "
        f"plain loop; a local cluster starts, with the kernels loaded on every worker, in "
        + " / ".join(f"{v:.1f} s" for v in startup.values()) + " (1 / 2 workers)."])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--quick", action="store_true",
                        help="4 records, one timing, 2 withheld-effect cases")
    parser.add_argument("--records", type=int, default=16, help="records (default 16)")
    parser.add_argument("--seconds", type=float, default=0.5,
                        help="length of each record in seconds (default 0.5 = 15 000 samples)")
    parser.add_argument("--repeat", type=int, default=3, help="timings per configuration")
    parser.add_argument("--withheld", type=int, default=12,
                        help="withheld-effect diagnoses (0.3 s + 0.3 s records) to run on the "
                        "clusters too (default 12; 0 to skip)")
    args = parser.parse_args()
    payload = measure(args.quick, args.records, args.seconds, args.repeat, args.withheld)
    print(render(payload))
    print(f"wrote {write_json('fleet', payload)}")


if __name__ == "__main__":
    main()
