"""Withheld-effect check of the sim-to-real gap diagnosis.

Records are made from the reference stage (the paper's eqs. 26-28) with one unmodelled effect,
chosen at random (seeded) and hidden from the diagnosis, each at three strengths, with different
excitations (seed, offset, PRBS and sine amplitudes of :func:`hystid.reference.paper_excitation`,
plus slow level changes so that creep can be told from drift) and white sensor noise of 1-5 nm;
clean records (no effect) are mixed in. The diagnosis runs blind on each (a train record and a
held-out record with another excitation). Printed: the confusion matrix (true effect vs the
first accepted effect, ``none`` when nothing is accepted), top-1 accuracy (the best-ranked
candidate), the false-acceptance rate on clean records and the gap closed. Goal: top-1 >= 90 %,
false acceptance <= 10 %. Usage:

    python benchmarks/bench_withheld_effects.py [--quick] [--trials N] [--clean N] [--seconds S]
"""

from __future__ import annotations

import argparse
import time

import numpy as np
from _common import table, write_json

from hystid.diagnose import EFFECT_NAMES, diagnose, simulate_with_effect
from hystid.identify.offline import fit_output_error
from hystid.records import Record
from hystid.reference import paper_excitation, reference_model

FS = 30_000.0
STRENGTHS = ("weak", "medium", "strong")


def excitation(n: int, rng: np.random.Generator) -> np.ndarray:
    """The paper's excitation with random seed, offset and amplitudes, plus slow level steps.

    The level steps (raised-cosine transitions of 5 ms every 0.1-0.25 s, +-0.3-1 V) start after
    the paper's ramp from rest; condition (8) stays far from its limit.
    """
    lo = rng.uniform(0.3, 0.5)
    u = paper_excitation(
        n, FS, seed=int(rng.integers(1 << 30)), offset=rng.uniform(4.0, 6.0),
        prbs_amplitude=(lo, lo + rng.uniform(0.1, 0.2)),
        sine_amplitude=(rng.uniform(0.6, 1.2), rng.uniform(0.2, 0.4)),
        sine_frequency=(rng.uniform(300.0, 500.0), rng.uniform(10.0, 30.0)),
    )
    level = np.zeros(n)
    k = int(rng.uniform(0.05, 0.15) * FS)
    current = 0.0
    width = int(0.005 * FS)
    while k < n:
        target = rng.uniform(-1.0, 1.0)
        ramp = 0.5 - 0.5 * np.cos(np.pi * np.arange(1, width + 1) / width)
        seg = current + (target - current) * ramp
        level[k:k + width] = seg[: max(0, min(width, n - k))]
        level[k + width:] = target
        current = target
        k += width + int(rng.uniform(0.1, 0.25) * FS)
    return u + level


def effect_params(name: str, strength: int, rng: np.random.Generator, u: np.ndarray) -> dict:
    """Random parameters of ``name`` at strength 0 (weak), 1, 2 (strong)."""
    sign = rng.choice([-1.0, 1.0])
    if name == "creep":
        return {"gain": (0.005, 0.015, 0.04)[strength], "tau": float(np.exp(
            rng.uniform(np.log(0.02), np.log(0.3))))}
    if name == "drift":
        return {"rate": sign * (0.005, 0.015, 0.04)[strength],
                "accel": sign * rng.uniform(0.0, 0.01) * (1, 2, 4)[strength]}
    if name == "extra_mode":
        return {"gain": (0.002, 0.005, 0.015)[strength],
                "freq": float(np.exp(rng.uniform(np.log(600.0), np.log(12_000.0)))),
                "zeta": rng.uniform(0.01, 0.05)}
    if name == "delay":
        return {"samples": (0.1, 0.3, 1.0)[strength] * rng.uniform(0.8, 1.25)}
    if name == "asymmetry":
        e = (0.02, 0.05, 0.15)[strength]
        return {"alpha": sign * e, "g0": rng.uniform(-1.0, 1.0) * e}
    if name == "slew_limit":
        w1 = reference_model(FS).simulate(u).w1
        limit = (0.8, 0.6, 0.4)[strength] * float(np.max(np.abs(np.diff(w1))))
        return {"inv_rate": 1.0 / (limit * FS)}
    if name == "saturation":
        w1 = reference_model(FS).simulate(u).w1
        return {"cubic": sign * (0.01, 0.03, 0.1)[strength] / float(np.max(w1**2))}
    if name == "offset":
        return {"y0": sign * (0.002, 0.005, 0.015)[strength]}
    raise ValueError(name)


def make_case(effect: str, strength: int, seed: int, n: int) -> dict:
    """A train and a held-out record from the reference stage with ``effect``."""
    rng = np.random.default_rng(seed)
    model = reference_model(FS)
    noise = rng.uniform(1e-3, 5e-3)
    u_tr, u_val = excitation(n, rng), excitation(n, rng)
    params = {} if effect == "none" else effect_params(effect, strength, rng, u_tr)
    recs = []
    for label, u in (("train", u_tr), ("val", u_val)):
        r = simulate_with_effect(model, effect, params, u, noise=noise,
                                 seed=int(rng.integers(1 << 30)))
        recs.append(Record(u, r.y, FS, name=f"case {seed} {label}"))
    return {"train": recs[0], "val": recs[1], "noise": noise, "params": params}


def run_case(effect: str, strength: int, seed: int, n: int) -> dict:
    case = make_case(effect, strength, seed, n)
    t0 = time.perf_counter()
    res = diagnose(case["train"], [case["val"]], progress=False)
    elapsed = time.perf_counter() - t0
    return {
        "truth": effect,
        "strength": STRENGTHS[strength] if effect != "none" else "-",
        "seed": seed,
        "noise_nm": 1e3 * case["noise"],
        "params": case["params"],
        "diagnosis": res.best,
        "accepted": res.accepted,
        "top1": res.effects[0].name,
        "ranking": [e.name for e in res.effects],
        "rms_val_nominal": res.nominal["rms_val"],
        "rms_val_final": res.final["rms_val"],
        "noise_floor": res.noise_floor_rms,
        "gap_closed": res.final["gap_closed"],
        "gap_closed_truth": next((e.gap_closed for e in res.effects if e.name == effect), None),
        "seconds": elapsed,
    }


def budget(seconds: float = 1.5) -> dict:
    """The issue's budget: a 1.5 s record (45 000 samples) with a 1.5 s held-out record,
    diagnosed with all candidates; the time is also given as a ratio to the nominal
    identification alone (``fit_output_error`` on the same record, same process)."""
    n = int(round(seconds * FS))
    case = make_case("creep", 1, 7, n)
    fit_output_error(case["train"][:2000])  # compile and load the kernels first
    t0 = time.perf_counter()
    fit_output_error(case["train"])
    t_fit = time.perf_counter() - t0
    t0 = time.perf_counter()
    res = diagnose(case["train"], [case["val"]], progress=False)
    t_diag = time.perf_counter() - t0
    return {"samples": n, "held_out_samples": n, "seconds": t_diag,
            "nominal_fit_seconds": t_fit, "ratio_to_nominal_fit": t_diag / t_fit,
            "accepted": res.accepted, "within_60_s": t_diag < 60.0}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--quick", action="store_true",
                        help="one draw per effect, 6 clean records, 0.3 s records")
    parser.add_argument("--trials", type=int, default=None,
                        help="random effect draws (each at three strengths; default 4 per "
                        "effect)")
    parser.add_argument("--clean", type=int, default=None, help="clean records (default 24)")
    parser.add_argument("--seconds", type=float, default=None,
                        help="length of each train and held-out record (default 0.5 s)")
    parser.add_argument("--seed", type=int, default=2024, help="seed of the draws")
    args = parser.parse_args()
    trials = args.trials or (len(EFFECT_NAMES) if args.quick else 4 * len(EFFECT_NAMES))
    n_clean = args.clean or (6 if args.quick else 24)
    seconds = args.seconds or (0.3 if args.quick else 0.5)
    n = int(round(seconds * FS))
    rng = np.random.default_rng(args.seed)
    # effects drawn at random, balanced: each effect equally often, in a random order
    draws = list(rng.permutation(np.resize(np.array(EFFECT_NAMES), trials)))
    seeds = rng.integers(1 << 30, size=trials + n_clean)
    rows = []
    t_start = time.perf_counter()
    jobs = [(str(e), s, int(seeds[i])) for i, e in enumerate(draws) for s in range(3)]
    jobs += [("none", 0, int(seeds[trials + i])) for i in range(n_clean)]
    order = rng.permutation(len(jobs))
    for count, j in enumerate(order, 1):
        effect, strength, seed = jobs[j]
        r = run_case(effect, strength, seed, n)
        rows.append(r)
        print(f"[{time.perf_counter() - t_start:6.0f} s] {count}/{len(jobs)} truth {effect:10s} "
              f"{r['strength']:6s} -> accepted {','.join(r['accepted']) or 'none':22s} top-1 "
              f"{r['top1']:10s} ({r['seconds']:.1f} s)", flush=True)
    summary = summarise(rows)
    print_report(summary, rows)
    b = budget()
    summary["budget"] = b
    print(f"\nbudget: {b['samples']} + {b['held_out_samples']} samples diagnosed with all "
          f"candidates in {b['seconds']:.1f} s (goal < 60 s), {b['ratio_to_nominal_fit']:.1f}x "
          f"the nominal identification alone ({b['nominal_fit_seconds']:.1f} s); accepted "
          f"{', '.join(b['accepted']) or 'none'}")
    path = write_json("withheld_effects", {
        "settings": {"trials": trials, "clean": n_clean, "seconds": seconds, "seed": args.seed,
                     "quick": args.quick},
        "summary": summary, "cases": rows})
    print(f"\nwrote {path}")


def summarise(rows: list[dict]) -> dict:
    labels = (*EFFECT_NAMES, "none")
    conf = {t: {d: 0 for d in labels} for t in labels}
    for r in rows:
        conf[r["truth"]][r["diagnosis"]] += 1
    eff = [r for r in rows if r["truth"] != "none"]
    clean = [r for r in rows if r["truth"] == "none"]
    by_strength = {}
    for s in STRENGTHS:
        sub = [r for r in eff if r["strength"] == s]
        if sub:
            by_strength[s] = {
                "cases": len(sub),
                "top1": float(np.mean([r["top1"] == r["truth"] for r in sub])),
                "accepted_correct": float(np.mean([r["diagnosis"] == r["truth"] for r in sub])),
                "gap_closed_median": float(np.median([r["gap_closed"] for r in sub])),
                "gap_over_noise_median": float(np.median(
                    [(r["rms_val_nominal"] - r["noise_floor"]) / (1e-3 * r["noise_nm"])
                     for r in sub])),
            }
    by_effect = {}
    for e in EFFECT_NAMES:
        sub = [r for r in eff if r["truth"] == e]
        if sub:
            by_effect[e] = {"cases": len(sub),
                            "top1": float(np.mean([r["top1"] == e for r in sub])),
                            "accepted_correct": float(np.mean([r["diagnosis"] == e
                                                               for r in sub]))}
    correct = [r for r in eff if r["diagnosis"] == r["truth"]]
    return {
        "confusion": conf,
        "top1_accuracy": float(np.mean([r["top1"] == r["truth"] for r in eff])) if eff else None,
        "accepted_correct": float(np.mean([r["diagnosis"] == r["truth"] for r in eff]))
        if eff else None,
        "wrong_acceptance": float(np.mean([r["diagnosis"] not in ("none", r["truth"])
                                           for r in eff])) if eff else None,
        "false_acceptance_clean": float(np.mean([bool(r["accepted"]) for r in clean]))
        if clean else None,
        "gap_closed_median_when_correct": float(np.median([r["gap_closed"] for r in correct]))
        if correct else None,
        "by_strength": by_strength,
        "by_effect": by_effect,
        "median_seconds": float(np.median([r["seconds"] for r in rows])),
        "cases": len(rows),
    }


def print_report(s: dict, rows: list[dict]) -> None:
    labels = (*EFFECT_NAMES, "none")
    print("\nconfusion matrix (rows: withheld effect; columns: first accepted effect)")
    body = [[t] + [s["confusion"][t][d] or "." for d in labels] for t in labels]
    print(table(body, ["truth \\ diagnosis", *labels]))
    print()
    rows_s = [[k, v["cases"], f"{100 * v['top1']:.0f} %", f"{100 * v['accepted_correct']:.0f} %",
               f"{100 * v['gap_closed_median']:.0f} %", f"{v['gap_over_noise_median']:.2g}"]
              for k, v in s["by_strength"].items()]
    print(table(rows_s, ["strength", "cases", "top-1", "accepted = truth", "gap closed (median)",
                         "gap / noise (median)"]))
    print()
    rows_e = [[k, v["cases"], f"{100 * v['top1']:.0f} %", f"{100 * v['accepted_correct']:.0f} %"]
              for k, v in s["by_effect"].items()]
    print(table(rows_e, ["effect", "cases", "top-1", "accepted = truth"]))
    print()
    print(f"top-1 accuracy:                     {100 * s['top1_accuracy']:.1f} % (goal >= 90 %)")
    print(f"accepted effect = withheld effect:  {100 * s['accepted_correct']:.1f} %")
    print(f"wrong effect accepted:              {100 * s['wrong_acceptance']:.1f} %")
    print(f"false acceptance on clean records:  {100 * s['false_acceptance_clean']:.1f} % "
          f"(goal <= 10 %)")
    if s["gap_closed_median_when_correct"] is not None:
        print(f"gap closed when correct (median):   "
              f"{100 * s['gap_closed_median_when_correct']:.0f} %")
    print(f"median time per diagnosis:          {s['median_seconds']:.1f} s")


if __name__ == "__main__":
    main()
