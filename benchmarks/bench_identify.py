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

Prints every table and the README's block ``identify`` (see ``benchmarks/readme.py``); writes
``benchmarks/results/identify.json``.
"""

from __future__ import annotations

import argparse
import time
import warnings

import numpy as np
from _common import table, write_json
from figures import TRUTH, max_relative_error, quiet, reference_identification, start_up_run

from hystid.identify import identify
from hystid.reference import PAPER_PARAMS, reference_record

#: The README blocks this script renders (see ``benchmarks/readme.py``).
README_BLOCKS = {"identify": "render"}
#: The command that measures the README's figures (one BLAS thread, as in the README).
COMMAND = "OPENBLAS_NUM_THREADS=1 python benchmarks/bench_identify.py"
#: The identification methods compared, in the table's order.
METHODS = ("batch", "online", "eria", "ekf")
#: Samples of the throughput record consumed before the timing (the start-up solve among them).
WARM_UP = 2_000
#: The on-line identifier's speed goal, samples per second.
SPEED_GOAL = 1e6


def run_one(method: str, seed: int, noise: float, n: int) -> dict:
    """One row of the table: :func:`figures.reference_identification`.

    Parameters
    ----------
    method : str
        Identification method.
    seed : int
        Seed of the record.
    noise : float
        Sensor noise RMS, um.
    n : int
        Record length, samples.

    Returns
    -------
    dict
    """
    return reference_identification(method, seed=seed, noise=noise, samples=n)


def summarise(rows: list[dict]) -> list[list[str]]:
    """The console table's rows: one per method and noise level, figures over the seeds.

    Parameters
    ----------
    rows : list of dict
        From :func:`run_one`.

    Returns
    -------
    list of list of str
    """
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
    """A fresh on-line estimator of ``method`` (the PI recursion warms up on 1 500 samples).

    Parameters
    ----------
    method : {"online", "eria", "ekf", "pi-recursive"}
        The recursive method.

    Returns
    -------
    Estimator
        With default settings.
    """
    from hystid.identify.ekf import KalmanIdentifier
    from hystid.identify.eria import ERIA
    from hystid.identify.online import OnlineIdentifier
    from hystid.identify.pi_recursive import PIRecursiveIdentifier

    makers = {"online": OnlineIdentifier, "eria": ERIA, "ekf": KalmanIdentifier,
              "pi-recursive": lambda: PIRecursiveIdentifier(warmup=1_500)}
    return makers[method]()


def throughput(method: str, seconds: float) -> dict:
    """Steady-state samples per second of a recursive method (start-up excluded).

    Parameters
    ----------
    method : str
        A method of :func:`estimator`.
    seconds : float
        Length of the record (the first :data:`WARM_UP` samples are not timed).

    Returns
    -------
    dict
        ``samples`` timed, ``samples_per_s`` (wall clock), ``samples_per_cpu_s`` (this
        process's CPU time: what a core gives when the machine is shared), ``x_30kHz`` (wall
        clock) and ``warm_up_seconds`` (the first samples, start-up included, best of three
        fresh estimators).
    """
    rec = reference_record(seconds, seed=99)
    warm = float("inf")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        for _ in range(3):  # best of three fresh starts; the last one goes on
            est = estimator(method)
            t0 = time.perf_counter()
            est.fit(rec[:WARM_UP])
            warm = min(warm, time.perf_counter() - t0)
        t0, c0 = time.perf_counter(), time.process_time()
        est.partial_fit(rec[WARM_UP:])
        elapsed, cpu = time.perf_counter() - t0, time.process_time() - c0
    n = rec.n - WARM_UP
    return {"method": method, "samples": n, "samples_per_s": n / elapsed,
            "samples_per_cpu_s": n / cpu, "x_30kHz": n / elapsed / 30_000.0,
            "warm_up_samples": WARM_UP, "warm_up_seconds": warm}


def per_sample_ratio(samples: int = 30_000, rounds: int = 5, method: str = "online") -> dict:
    """Per-sample ``update()`` vs chunked ``partial_fit()`` of an on-line estimator.

    Both run from the same state (after start-up) over the same samples; the two are timed in
    alternation ``rounds`` times and the best of each is kept, so a busy machine slows both.

    Parameters
    ----------
    samples : int
        Samples timed.
    rounds : int
        Alternating rounds.
    method : str
        A method of :func:`estimator`.

    Returns
    -------
    dict
        Samples per second of each way and ``ratio`` (update time / chunked time).
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
    """Wrong-basin rate of the on-line identifier's start-up on two simulators.

    Parameters
    ----------
    seeds : int
        Seeds per simulator and noise level.
    seconds : float
        Record length (:func:`figures.start_up_run`, records from rest, 0, 1 and 10 nm).

    Returns
    -------
    list of dict
        One :func:`figures.start_up_run` per run.
    """
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

    Parameters
    ----------
    sizes : tuple of int
        Record lengths.

    Returns
    -------
    list of dict
        Per length: kept and peak traced bytes per sample, history rows, fit seconds.
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


def offline_optimum(seed: int, noise: float, n: int, first: int | None = None) -> dict:
    """The batch fit's error on an on-line run's very record: what the data allow.

    Parameters
    ----------
    seed : int
        Seed of the record (as :func:`run_one`).
    noise : float
        Sensor noise RMS, um.
    n : int
        Record length, samples.
    first : int, optional
        Fit only the first samples of the record.

    Returns
    -------
    dict
        ``seed``, ``samples`` fitted, ``final_err`` (max relative parameter error) and
        ``worst_param`` (the parameter it is reached on).
    """
    rec = reference_record(n / 30_000.0, seed=seed, noise=noise)
    if first is not None:
        rec = rec[:first]
    with quiet():
        theta = identify(rec, method="batch").model.theta
    rel = np.abs(theta - TRUTH) / np.abs(TRUTH)
    return {"seed": seed, "samples": rec.n, "final_err": max_relative_error(theta),
            "worst_param": list(PAPER_PARAMS)[int(np.argmax(rel))]}


def offline_checks(rows: list[dict], n: int, first: int = 1_000) -> dict:
    """Batch fits that the on-line figures at 1 nm are read against.

    Parameters
    ----------
    rows : list of dict
        From :func:`run_one`.
    n : int
        Record length of the rows.
    first : int
        Samples of the early comparison (seed 0).

    Returns
    -------
    dict
        ``first`` (the batch fit on seed 0's first samples) and ``missed_01pc`` (per on-line
        seed that ends above 0.1 %: its final error and the batch fit's on the same record).
    """
    online = [r for r in rows if r["method"] == "online" and r["noise_nm"] == 1.0]
    if not online:
        return {}
    missed = []
    for r in (r for r in online if r.get("to_01pc") is None):
        best = offline_optimum(r["seed"], 1e-3, n)
        missed.append({**best, "online_final_err": r["final_err"]})
    return {"first": offline_optimum(0, 1e-3, n, first=min(first, n)), "missed_01pc": missed}


def measure(quick: bool = False, seeds: int | None = None, samples: int | None = None,
            methods: tuple[str, ...] = METHODS, basins: int = 20,
            memory: tuple[int, ...] = (100_000, 1_000_000, 10_000_000)) -> dict:
    """Every part of the benchmark (see the module's docstring).

    Parameters
    ----------
    quick : bool
        3 seeds and 6 000 samples, shorter speed records.
    seeds : int, optional
        Seeds of the on-line method (the others take at most 5).
    samples : int, optional
        Record length of the identification runs.
    methods : tuple of str
        Methods of the table (empty: only the speed and memory part).
    basins : int
        Seeds of the start-up wrong-basin measurement (0: skip).
    memory : tuple of int
        Record lengths of the memory measurement.

    Returns
    -------
    dict
        ``samples``, ``seeds`` (per method), ``rows`` (:func:`run_one`), ``offline``
        (:func:`offline_checks`), ``throughput``, ``per_sample``, ``start_up_basins`` and
        ``memory``.
    """
    n = samples or (6_000 if quick else 30_000)
    seeds_online = seeds or (3 if quick else 20)
    seeds_other = min(seeds_online, 3 if quick else 5)
    with quiet():  # compile outside the timing
        identify(reference_record(0.02), method="online")
        identify(reference_record(0.02), method="eria")
    rows, seed_counts = [], {}
    for method in methods:
        seed_counts[method] = seeds_online if method == "online" else seeds_other
        for noise in (0.0, 1e-3, 1e-2):
            rows += [run_one(method, seed, noise, n) for seed in range(seed_counts[method])]
            print(f"  {method:6s} noise {noise * 1e3:g} nm: {seed_counts[method]} seeds done",
                  flush=True)
    speed = [throughput(m, (0.5 if quick else 2.0) if m == "ekf" else (2.0 if quick else 10.0))
             for m in methods if m != "batch"]
    speed.append(throughput("pi-recursive", 1.0 if quick else 3.0))
    ratios = [per_sample_ratio(6_000 if quick else 30_000, method=m)
              for m in ("online", "pi-recursive")]
    return {"samples": n, "seeds": seed_counts, "rows": rows,
            "offline": offline_checks(rows, n), "throughput": speed, "per_sample": ratios,
            "start_up_basins": start_up_basins(basins) if basins else [],
            "memory": memory_per_sample(tuple(memory))}


def report(payload: dict) -> str:
    """Every table of the benchmark, as printed.

    Parameters
    ----------
    payload : dict
        From :func:`measure`.

    Returns
    -------
    str
    """
    header = ["method", "noise nm", "seeds", "samples to 2 %", "samples to 0.1 %",
              "final err (median)", "final err (worst)", "val error [nm]", "val RMS [nm]",
              "samples/s", "restarts", "NaN"]
    out = [f"Reference stage, {payload['samples']} samples per record, theta(0) = 0.01, records "
           "from rest", table(summarise(payload["rows"]), header) if payload["rows"] else "-",
           "", "Steady-state throughput on one core (start-up excluded), baseline: a 30 kHz loop",
           table([[r["method"], f"{r['samples']}", f"{r['samples_per_s']:.3g}",
                   f"{r['x_30kHz']:.1f}x"] for r in payload["throughput"]],
                 ["method", "samples", "samples/s", "vs 30 kHz real time"]),
           "", "Per-sample update() vs chunked partial_fit(), same samples, best of 5 "
           "alternating rounds (goal: at most 3x)",
           table([[r["method"], f"{r['samples']}", f"{r['chunked_per_s']:.3g}",
                   f"{r['update_per_s']:.3g}", f"{r['ratio']:.2f}x"]
                  for r in payload["per_sample"]],
                 ["estimator", "samples", "chunked samples/s", "update() samples/s",
                  "update / chunked"])]
    basins = payload["start_up_basins"]
    if basins:
        rows = []
        for source in ("reference", "stages"):
            for noise in (0.0, 1.0, 10.0):
                rs = [r for r in basins if r["source"] == source and r["noise_nm"] == noise]
                rows.append([source, f"{noise:g}", str(len(rs)),
                             str(sum(r["wrong_basin"] for r in rs)),
                             str(sum(r["wrong_basin"] and not r["warned"] for r in rs)),
                             str(sum(r["start_samples"] > 400 for r in rs)),
                             str(sum(r["warned"] for r in rs)),
                             f"{np.median([r['final_err'] for r in rs]):.2e}",
                             f"{max(r['final_err'] for r in rs):.2e}"])
        out += ["", "On-line start-up over seeds, 1 s records from rest: wrong basin = final "
                "max relative error > 20 % (goal 0); retried = start-up solved again on more "
                "samples",
                table(rows, ["simulator", "noise nm", "seeds", "wrong basin", "silent",
                             "retried", "warned", "final err (median)", "final err (worst)"])]
    out += ["", "On-line fit memory (default decimated history), bytes per sample",
            table([[f"{r['samples']:.0e}", f"{r['kept_bytes_per_sample']:.3g}",
                    f"{r['peak_bytes_per_sample']:.3g}", str(r["history_rows"]),
                    f"{r['seconds']:.1f}"] for r in payload["memory"]],
                  ["samples", "kept (history + diagnostics)", "peak traced", "history rows",
                   "fit s"])]
    return "\n".join(out)


def _count(k: float) -> str:
    return f"{k:,.0f}".replace(",", " ")


def _samples_to(rs: list[dict], key: str) -> str:
    """Median over the seeds that get there, and how many do; "-" without a history."""
    if key not in rs[0]:
        return "-"
    got = [r[key] for r in rs if r.get(key) is not None]
    if not got:
        return "never"
    text = _count(np.median(got))
    return text if len(got) == len(rs) else f"{text} ({len(got)} of {len(rs)} seeds)"


def _nm(x: float) -> str:
    text = _count(x) if abs(x) >= 1_000 else f"{x:.1f}"
    return "0.0" if text == "-0.0" else text


def _validation(rs: list[dict]) -> str:
    vr = [r for r in rs if "val_rms" in r]
    if not vr:
        return "unstable"
    lo, hi = min(r["val_min"] for r in vr) * 1e3, max(r["val_max"] for r in vr) * 1e3
    rms = np.median([r["val_rms"] for r in vr]) * 1e3
    unstable = len(rs) - len(vr)
    return (f"{_nm(lo)} .. {_nm(hi)}, {_count(rms) if rms >= 100 else f'{rms:.2f}'}"
            + (f" ({unstable} unstable)" if unstable else ""))


def _noise(nm: float) -> str:
    return "0" if nm == 0 else f"{nm:g} nm"


def _pc(x: float) -> str:
    return f"{x * 100:.3g} %"


def _error(x: float) -> str:
    """A relative error: two significant digits, without an exponent from 100 on."""
    return _count(float(f"{x:.2g}")) if x >= 100 else f"{x:.2g}"


def _rate(x: float) -> str:
    return f"{x / 1e6:.2g} million" if x >= 1e5 else _count(float(f"{x:.2g}"))


def identification_table(payload: dict) -> str:
    """One row per method and noise level, figures over the seeds.

    Parameters
    ----------
    payload : dict
        From :func:`measure`.

    Returns
    -------
    str
        A Markdown table.
    """
    rows = payload["rows"]
    out = []
    for method in dict.fromkeys(r["method"] for r in rows):
        for noise in sorted({r["noise_nm"] for r in rows if r["method"] == method}):
            rs = [r for r in rows if r["method"] == method and r["noise_nm"] == noise]
            err = [r["final_err"] for r in rs]
            out.append([method, _noise(noise), str(len(rs)), _samples_to(rs, "to_2pc"),
                        _samples_to(rs, "to_01pc"),
                        f"{_error(float(np.median(err)))} / {_error(max(err))}", _validation(rs),
                        f"{'yes' if any(r.get('nan') for r in rs) else 'no'} / "
                        f"{_count(sum(r['restarts'] for r in rs))}"])
    return table(out, ["method", "noise", "seeds", "samples to 2 %", "samples to 0.1 %",
                       "final err median / worst", "val. error range, RMS [nm]",
                       "NaN / restarts"])


def _online(payload: dict, noise: float) -> list[dict]:
    return [r for r in payload["rows"] if r["method"] == "online" and r["noise_nm"] == noise]


def _early_bullet(payload: dict) -> str:
    """Within 2 % by sample 1 000, and the 2 % mark at 10 nm."""
    clean, one, ten = (_online(payload, nz) for nz in (0.0, 1.0, 10.0))
    at = [r["err_at_1000"] for r in clean + one]
    within = sum(e < 0.02 for e in at)
    first = payload["offline"]["first"]
    one_at = [r["err_at_1000"] for r in one]
    text = (f"* Within 2 % at sample 1 000: {within} of {len(at)} seeds at 0 and 1 nm (for good "
            f"from sample {_samples_to(clean + one, 'to_2pc')}, median, when the start-up solve "
            "lands). "
            f"At sample 1 000 the on-line estimate is "
            f"{_pc(min(one_at))[:-2]}-{_pc(max(one_at))} off "
            f"over the {len(one)} seeds at 1 nm (the off-line fit on the same first "
            f"{_count(first['samples'])} samples: {_pc(first['final_err'])} for seed "
            f"{first['seed']}).")
    if ten:
        got = [r["to_2pc"] for r in ten if r["to_2pc"] is not None]
        text += (f" At 10 nm the 2 % mark comes at sample {_count(np.median(got))} (median), "
                 f"{_count(max(got))} (worst)" if got else " At 10 nm no seed stays within 2 %")
        missing = len(ten) - len(got)
        text += (f", {missing} of {len(ten)} seeds never." if missing else ".")
    return text


def _accuracy_bullet(payload: dict) -> str:
    """Within 0.1 % by the end at 1 nm, and the off-line optimum of the seeds that miss it."""
    one = _online(payload, 1.0)
    missed = payload["offline"]["missed_01pc"]
    text = (f"* Within 0.1 % by sample {_count(payload['samples'])} at 1 nm: "
            f"{len(one) - len(missed)} of {len(one)} seeds.")
    if missed:
        text += " " + "; ".join(
            f"Seed {m['seed']} ends at {_pc(m['online_final_err'])}, where the off-line "
            f"optimum on the very same record is {_pc(m['final_err'])} (worst parameter: "
            f"{m['worst_param']})" for m in missed) + "."
    return text


def _robust_bullet(payload: dict) -> str:
    online = [r for r in payload["rows"] if r["method"] == "online"]
    nan = sum(bool(r.get("nan")) for r in online)
    restarts = sum(r["restarts"] for r in online)
    noises = ", ".join(f"{nz:g}" for nz in sorted({r["noise_nm"] for r in online}))
    return (f"* Over {payload['seeds']['online']} seeds x {{{noises}}} nm: "
            f"{'no NaN' if nan == 0 else f'{nan} runs with NaN'}, "
            f"{'no restart' if restarts == 0 else f'{restarts} restarts'}.")


def _speed_bullet(payload: dict) -> str:
    speed = {r["method"]: r for r in payload["throughput"]}
    online = speed["online"]
    others = ", ".join(f"{'ERIA' if m == 'eria' else 'the EKF'} {_rate(speed[m]['samples_per_s'])}"
                       for m in ("eria", "ekf") if m in speed)
    cpu = online.get("samples_per_cpu_s")
    return (f"* Speed, start-up excluded: {_rate(online['samples_per_s'])} samples per second "
            f"in steady state ({online['x_30kHz']:.0f}x a 30 kHz loop; the goal is "
            f"{_rate(SPEED_GOAL)} per core)"
            + (f", {_rate(cpu)} per second of the process's CPU time (the load above shares "
               "the cores)" if cpu else "")
            + (f"; {others} per second (same process)" if others else "")
            + f". The first {_count(online['warm_up_samples'])} samples, start-up solve "
            f"included, take {online['warm_up_seconds'] * 1e3:.0f} ms.")


def render(payload: dict) -> str:
    """The identification table and the figures quoted below it.

    Parameters
    ----------
    payload : dict
        From :func:`measure` with the four methods.

    Returns
    -------
    str
        Markdown: a sentence on the runs, the table, generated bullets.
    """
    seeds = payload["seeds"]
    others = sorted({v for m, v in seeds.items() if m != "online"})
    return "\n".join([
        f"{_count(payload['samples'])} samples per record from rest, theta(0) = 0.01, "
        f"{seeds['online']} seeds for `online`, {'/'.join(map(str, others))} for the others; "
        "samples to 2 % / 0.1 %: median over the seeds that stay within it to the end; errors "
        "are max relative parameter errors; validation on a fresh 0.5 s record:", "",
        identification_table(payload), "",
        _early_bullet(payload), _accuracy_bullet(payload), _robust_bullet(payload),
        _speed_bullet(payload)])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--quick", action="store_true", help="3 seeds, 6 000 samples")
    parser.add_argument("--seeds", type=int, default=None, help="seeds for the online method")
    parser.add_argument("--samples", type=int, default=None)
    parser.add_argument("--methods", default=",".join(METHODS),
                        help="comma-separated, or 'none' for the speed and memory part only")
    parser.add_argument("--basins", type=int, default=20,
                        help="seeds of the start-up wrong-basin measurement (0: skip)")
    parser.add_argument("--memory", default="1e5,1e6,1e7",
                        help="record lengths of the memory measurement")
    args = parser.parse_args()
    methods = () if args.methods == "none" else tuple(filter(None, args.methods.split(",")))
    unknown = [m for m in methods if m not in METHODS]
    if unknown:
        parser.error(f"--methods: unknown {', '.join(unknown)}; expected some of "
                     f"{', '.join(METHODS)} or 'none'")
    try:
        sizes = tuple(int(float(v)) for v in args.memory.split(","))
    except ValueError:
        parser.error(f"--memory: expected comma-separated record lengths such as 1e5,1e6, "
                     f"got {args.memory!r}")
    payload = measure(args.quick, args.seeds, args.samples, methods, args.basins, sizes)
    print(report(payload))
    if set(METHODS) <= set(methods):
        print("\n" + render(payload))
    print(f"wrote {write_json('identify', payload)}")


if __name__ == "__main__":
    main()
