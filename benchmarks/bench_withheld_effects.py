"""Withheld-effect check of the sim-to-real gap diagnosis, in-form and cross-form.

Two sources of records, each a train record and a held-out record with another excitation (the
paper's excitation with random seed, offset and amplitudes, plus slow level steps so that creep
can be told from drift), white sensor noise, one effect hidden or none:

* **in-form**: the reference stage (the paper's eqs. 26-28) with one of the candidates' own
  forms (:func:`hystid.diagnose.simulate_with_effect`): the diagnosis looks for what made the
  data;
* **cross-form**: the independent stage simulator :func:`hystid.testing.simulate_stage`, whose
  effects come in two or three forms each, written apart from the candidates (a logarithmic
  creep kernel, a random-walk or thermal drift, a dead time followed by a lag, a clipping
  sensor, a current-limited amplifier...); one record of twice the length, its second half
  held out (the simulator scales some effects to the record's own range).

The diagnosis runs blind on each case. Printed per source: the confusion matrix (true family
vs the first accepted family, ``none`` when nothing is accepted), top-1 accuracy (family of the
best-ranked candidate), the share where a wrong family is accepted, the false-acceptance rate on
clean records, and per form. Goals: cross-form top-1 >= 90 %, false acceptance on clean records
<= 5 %, wrong effect accepted <= 5 %. Last, the budget: 45 000 + 45 000 samples with all
candidates, as a ratio to the nominal identification alone in the same process. Usage:

    python benchmarks/bench_withheld_effects.py [--quick] [--draws N] [--clean N] [--seconds S]
        [--only in-form|cross-form] [--no-budget] [--workers N | --scheduler tcp://HOST:PORT]

With ``--workers`` or ``--scheduler`` every case is a Dask task (:func:`hystid.fleet.map_seeds`);
the cases and their results are the same as in the serial loop.
"""

from __future__ import annotations

import argparse
import time

import numpy as np
from _common import table, write_json

from hystid.diagnose import FAMILIES, diagnose, family_of, simulate_with_effect
from hystid.diagnose.diagnosis import DEFAULT_EFFECTS
from hystid.identify import identify
from hystid.records import Record
from hystid.reference import paper_excitation, reference_model

#: The README blocks this script renders (see ``benchmarks/readme.py``).
README_BLOCKS = {"withheld-effects": "render", "diagnosis-speed": "render_budget"}
COMMAND = "OPENBLAS_NUM_THREADS=1 python benchmarks/bench_withheld_effects.py"

FS = 30_000.0
STRENGTHS = ("weak", "medium", "strong")
#: Families of the independent simulator under the diagnosis' names.
CROSS_FAMILY = {"creep": "creep", "drift": "drift", "delay": "delay", "asymmetry": "asymmetry",
                "slew": "slew_limit", "saturation": "saturation", "mode": "extra_mode"}
#: Forms whose effect is a constant output offset: the nominal model estimates the sensor
#: offset, so nothing is left for a candidate (reported apart, not in the accuracy).
ABSORBED = ("asymmetry/offset",)
#: Strength of the independent simulator's forms, as multiples of their default.
CROSS_SCALE = (0.5, 1.0, 2.0)


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


def _peak_w1(u: np.ndarray) -> tuple[float, float]:
    w1 = reference_model(FS).simulate(u, check=False).w1
    return float(np.max(np.abs(np.diff(w1)))), float(np.max(np.abs(w1)))


def effect_params(name: str, strength: int, rng: np.random.Generator, u: np.ndarray) -> dict:
    """Random parameters of the candidate form ``name`` at strength 0 (weak), 1, 2 (strong)."""
    sign = rng.choice([-1.0, 1.0])
    k = strength
    if name in ("creep", "creep_2tau", "creep_log"):
        gain = (0.005, 0.015, 0.04)[k]
        tau = float(np.exp(rng.uniform(np.log(0.02), np.log(0.3))))
        if name == "creep":
            return {"gain": gain, "tau": tau}
        if name == "creep_2tau":
            return {"gain": gain / 2, "tau": tau / 4, "gain2": gain / 2, "tau2": tau * 2}
        return {"gain": gain, "tau": tau / 100}
    if name == "drift":
        return {"rate": sign * (0.005, 0.015, 0.04)[k],
                "accel": sign * rng.uniform(0.0, 0.01) * (1, 2, 4)[k]}
    if name in ("extra_mode", "mode_series"):
        gain = (0.002, 0.005, 0.015)[k] if name == "extra_mode" else (0.05, 0.1, 0.3)[k]
        return {"gain": gain, "freq": float(np.exp(rng.uniform(np.log(600.0), np.log(12e3)))),
                "zeta": rng.uniform(0.01, 0.05)}
    if name == "delay":
        return {"samples": (0.3, 1.0, 3.0)[k] * rng.uniform(0.8, 1.25)}
    if name in ("asymmetry", "asymmetry_input"):
        e = (0.02, 0.05, 0.15)[k]
        return {"alpha": sign * e, "g0": rng.uniform(-1.0, 1.0) * e,
                "f1": rng.uniform(-0.2, 0.2) * e}
    if name == "loop_level":
        e = (0.02, 0.05, 0.15)[k] / _peak_w1(u)[1]
        return {"alpha": sign * e, "g0": rng.uniform(-1.0, 1.0) * e}
    if name == "slew_limit":
        limit = (0.8, 0.6, 0.4)[k] * _peak_w1(u)[0]
        return {"inv_rate": 1.0 / (limit * FS)}
    if name == "slew_input":
        limit = (0.8, 0.6, 0.4)[k] * float(np.max(np.abs(np.diff(u))))
        return {"inv_rate": 1.0 / (limit * FS)}
    if name == "output_curve":
        y = reference_model(FS).simulate(u, check=False).y
        return {"quadratic": sign * (0.03, 0.1, 0.3)[k], "cubic": 0.0,
                "centre": 0.5 * float(np.max(y) + np.min(y)), "span": float(np.ptp(y))}
    if name == "saturation":
        return {"cubic": sign * (0.01, 0.03, 0.1)[k] / _peak_w1(u)[1] ** 2}
    if name == "offset":
        return {"y0": sign * (0.002, 0.005, 0.015)[k]}
    raise ValueError(name)


def make_in_form(form: str, strength: int, seed: int, n: int) -> dict:
    """Train and held-out records from the reference stage with the candidate form ``form``."""
    rng = np.random.default_rng(seed)
    model = reference_model(FS)
    noise = rng.uniform(1e-3, 5e-3)
    u_tr, u_val = excitation(n, rng), excitation(n, rng)
    params = {} if form == "none" else effect_params(form, strength, rng, u_tr)
    if form == "drift":
        # a drift of its own on every record
        params_val = effect_params(form, strength, rng, u_val)
    else:
        params_val = params
    recs = []
    for label, u, p in (("train", u_tr, params), ("val", u_val, params_val)):
        r = simulate_with_effect(model, form, p, u, noise=noise,
                                 seed=int(rng.integers(1 << 30)))
        recs.append(Record(u, r.y, FS, name=f"case {seed} {label}"))
    truth = "none" if form == "none" else family_of(form)
    return {"train": recs[0], "val": recs[1], "noise": noise, "params": params,
            "truth": truth, "form": form}


def make_cross_form(effect: str, form: str, scale: float, seed: int, n: int,
                    noise: float = 2e-3) -> dict:
    """One record of ``2 n`` samples from the independent simulator with ``effect`` / ``form``
    (``none`` for a clean stage), its second half held out; every random figure (excitation,
    drift realisation, noise) from ``seed``.

    One record rather than two: the simulator sets the slew limit, the clipping level and the
    level-dependent loop from the record's own input and output range, so two records would
    come from two different stages.
    """
    from hystid.testing import simulate_stage
    from hystid.testing.effects import EFFECTS as CROSS

    rng = np.random.default_rng(seed)
    strength = None if effect == "none" else scale * CROSS[effect][form].strength
    if effect == "slew":
        strength = min(strength, 0.8)  # the fraction of the peak rate removed stays below 1
    u = np.concatenate([excitation(n, rng), excitation(n, rng)[int(0.05 * FS):]])
    u = u[: 2 * n]
    sim = simulate_stage(u, FS, effect=None if effect == "none" else effect, form=form,
                         strength=strength, seed=int(rng.integers(1 << 30)))
    y = sim["y"] + noise * rng.standard_normal(len(u))
    truth = "none" if effect == "none" else CROSS_FAMILY[effect]
    return {"train": Record(u, y, FS, name=f"case {seed}"), "val": None, "noise": noise,
            "params": {"strength": strength}, "truth": truth, "form": f"{effect}/{form}"}


def run_case(case: dict, source: str, strength: str, seed: int, **settings) -> dict:
    """Diagnose one case blind (``settings`` go to :func:`hystid.diagnose.diagnose`)."""
    t0 = time.perf_counter()
    if case["val"] is None:
        res = diagnose(case["train"], holdout=0.5, progress=False, **settings)
    else:
        res = diagnose(case["train"], [case["val"]], progress=False, **settings)
    elapsed = time.perf_counter() - t0
    truth = case["truth"]
    return {
        "source": source,
        "truth": truth,
        "form": case["form"],
        "strength": strength,
        "seed": seed,
        "noise_nm": 1e3 * case["noise"],
        "params": case["params"],
        "diagnosis": res.best,
        "accepted": res.accepted,
        "accepted_families": res.families,
        "top1": res.effects[0].family,
        "top1_form": res.effects[0].name,
        "ranking": [e.name for e in res.effects],
        "failed": [e.name for e in res.effects if e.status == "failed"],
        "rms_val_nominal": res.nominal["rms_val"],
        "rms_val_final": res.final["rms_val"],
        "noise_floor": res.noise_floor_rms,
        "gap_closed": res.final["gap_closed"],
        "seconds": elapsed,
    }


def budget(seconds: float = 1.5) -> dict:
    """45 000 + 45 000 samples diagnosed with all candidates, as a ratio to the nominal
    identification alone (``identify(train, "batch", model="duhem")``, which the diagnosis runs
    first, on the same train record, same process)."""
    n = int(round(seconds * FS))
    case = make_in_form("creep", 1, 7, n)
    diagnose(case["train"][:6000], [case["val"][:6000]], progress=False)  # compile first
    t0 = time.perf_counter()
    identify(case["train"], "batch", model="duhem")
    t_fit = time.perf_counter() - t0
    t0 = time.perf_counter()
    res = diagnose(case["train"], [case["val"]], progress=False)
    t_diag = time.perf_counter() - t0
    return {"samples": n, "held_out_samples": n, "seconds": t_diag,
            "nominal_fit_seconds": t_fit, "ratio_to_nominal_fit": t_diag / t_fit,
            "accepted": res.accepted}


#: Candidate forms added after the draw was fixed: their cases follow the others, from a seed
#: stream of their own, so that the earlier cases (and the gate's) stay the same.
LATER_FORMS = ("asymmetry_input",)


def jobs_in_form(draws: int, n_clean: int, rng: np.random.Generator,
                 later: bool = True) -> list[tuple]:
    forms = [f for f in DEFAULT_EFFECTS if f not in LATER_FORMS]
    picks = list(rng.permutation(np.resize(np.array(forms), max(draws, 1) * len(forms))))
    seeds = rng.integers(1 << 30, size=len(picks) + n_clean)
    out = [("in-form", str(f), s, int(seeds[i])) for i, f in enumerate(picks)
           for s in range(3)][: 3 * draws * len(forms)]
    out += [("in-form", "none", 0, int(seeds[len(picks) + i])) for i in range(n_clean)]
    if later:
        more = np.random.default_rng([int(seeds[0]), len(LATER_FORMS)])
        out += [("in-form", f, s, int(more.integers(1 << 30)))
                for _ in range(max(draws, 1)) for f in LATER_FORMS for s in range(3)]
    return out


def jobs_cross_form(draws: int, n_clean: int, rng: np.random.Generator) -> list[tuple]:
    from hystid.testing import list_effects

    pairs = [f"{e}/{f}" for e, f in list_effects()]
    seeds = rng.integers(1 << 30, size=draws * len(pairs) * 3 + n_clean)
    out, i = [], 0
    for _ in range(draws):
        for p in pairs:
            for s in range(3):
                out.append(("cross-form", p, s, int(seeds[i])))
                i += 1
    out += [("cross-form", "none", 0, int(seeds[i + j])) for j in range(n_clean)]
    return out


def make(job: tuple, n: int) -> dict:
    source, what, strength, seed = job
    if source == "in-form":
        return make_in_form(what, strength, seed, n)
    if what == "none":
        return make_cross_form("none", "", 0.0, seed, n)
    effect, form = what.split("/")
    return make_cross_form(effect, form, CROSS_SCALE[strength], seed, n)


def diagnose_job(job: tuple, n: int, **settings) -> dict:
    """One case of the check, made and diagnosed blind: the unit of work, in a loop or on Dask
    (``settings`` go to :func:`hystid.diagnose.diagnose`)."""
    source, what, strength, seed = job
    label = STRENGTHS[strength] if what != "none" else "-"
    return run_case(make(job, n), source, label, seed, **settings)


def run_jobs(jobs: list[tuple], n: int, workers: int | None, scheduler: str | None) -> list[dict]:
    """Every case, serially or as Dask tasks (:func:`hystid.fleet.map_seeds`), in job order."""
    t_start = time.perf_counter()

    def say(count: int, job: tuple, r: dict) -> None:
        source, what, strength, _ = job
        label = STRENGTHS[strength] if what != "none" else "-"
        print(f"[{time.perf_counter() - t_start:6.0f} s] {count}/{len(jobs)} {source:10s} "
              f"{what:20s} {label:6s} -> accepted {','.join(r['accepted']) or 'none':24s} "
              f"top-1 {r['top1_form']:12s} ({r['seconds']:.1f} s)", flush=True)

    if workers is None and scheduler is None:
        rows = []
        for count, job in enumerate(jobs, 1):
            rows.append(diagnose_job(job, n))
            say(count, job, rows[-1])
        return rows
    import sys

    import cloudpickle

    from hystid.fleet import map_seeds

    cloudpickle.register_pickle_by_value(sys.modules[__name__])  # workers need not import it
    rows = map_seeds(diagnose_job, jobs, n, workers=workers, scheduler=scheduler,
                     progress=True)
    for count, (job, r) in enumerate(zip(jobs, rows, strict=True), 1):
        say(count, job, r)
    return rows


def measure(quick: bool = False, draws: int = 1, clean: int | None = None,
            seconds: float = 0.5, only: str | None = None, with_budget: bool = True,
            seed: int = 2024, workers: int | None = None, scheduler: str | None = None) -> dict:
    """Diagnose every case blind and summarise per source; time the 45 000-sample budget.

    Parameters
    ----------
    quick : bool
        4 clean records per source instead of 20 (unless ``clean`` is given).
    draws : int
        Draws per form, each at three strengths.
    clean : int, optional
        Clean records per source.
    seconds : float
        Length of each train and held-out record.
    only : {"in-form", "cross-form"}, optional
        One source only.
    with_budget : bool
        Also time the diagnosis of 45 000 + 45 000 samples against the nominal fit.
    seed : int
        Seed of the draws.
    workers, scheduler : int or str, optional
        Run the cases on Dask (:func:`hystid.fleet.map_seeds`).

    Returns
    -------
    dict
        ``settings``, ``summary`` per source (and ``budget``) and every case.
    """
    n_clean = clean if clean is not None else (4 if quick else 20)
    n = int(round(seconds * FS))
    rng = np.random.default_rng(seed)
    jobs = []
    if only in (None, "in-form"):
        jobs += jobs_in_form(draws, n_clean, rng)
    if only in (None, "cross-form"):
        jobs += jobs_cross_form(draws, n_clean, rng)
    jobs = [jobs[j] for j in rng.permutation(len(jobs))]
    rows = run_jobs(jobs, n, workers, scheduler)
    summary = {src: summarise([r for r in rows if r["source"] == src])
               for src in ("in-form", "cross-form") if any(r["source"] == src for r in rows)}
    if with_budget:
        summary["budget"] = budget()
    return {"settings": {"draws": draws, "clean": n_clean, "seconds": seconds, "seed": seed,
                         "quick": quick, "only": only, "cross_scale": CROSS_SCALE},
            "summary": summary, "cases": rows}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--quick", action="store_true",
                        help="one draw per form, 4 clean records per source")
    parser.add_argument("--draws", type=int, default=1,
                        help="draws per form, each at three strengths (default 1)")
    parser.add_argument("--clean", type=int, default=None,
                        help="clean records per source (default 20)")
    parser.add_argument("--seconds", type=float, default=0.5,
                        help="length of each train and held-out record (default 0.5 s)")
    parser.add_argument("--only", choices=("in-form", "cross-form"), default=None)
    parser.add_argument("--no-budget", action="store_true", help="skip the 45 000-sample budget")
    parser.add_argument("--seed", type=int, default=2024, help="seed of the draws")
    parser.add_argument("--workers", type=int, default=None,
                        help="run the cases on a local Dask cluster of N workers")
    parser.add_argument("--scheduler", default=None,
                        help="run the cases on a running Dask scheduler (tcp://HOST:PORT)")
    args = parser.parse_args()
    payload = measure(args.quick, args.draws, args.clean, args.seconds, args.only,
                      not args.no_budget, args.seed, args.workers, args.scheduler)
    for src, s in payload["summary"].items():
        if src != "budget":
            print_report(src, s)
    print("\n" + render(payload))
    print(f"\nwrote {write_json('withheld_effects', payload)}")


def summarise(rows: list[dict]) -> dict:
    """Confusion matrix (families), top-1, acceptance rates, per form and per strength."""
    labels = (*FAMILIES, "none")
    absorbed = [r for r in rows if r["form"] in ABSORBED]
    rows = [r for r in rows if r["form"] not in ABSORBED]
    conf = {t: {d: 0 for d in labels} for t in labels}
    for r in rows:
        conf[r["truth"]][r["diagnosis"]] += 1
    eff = [r for r in rows if r["truth"] != "none"]
    clean = [r for r in rows if r["truth"] == "none"]

    def rate(sub, pred):
        return float(np.mean([pred(r) for r in sub])) if sub else None

    def wrong(r):
        return any(f != r["truth"] for f in r["accepted_families"])

    by_form = {}
    for f in sorted({r["form"] for r in eff}):
        sub = [r for r in eff if r["form"] == f]
        by_form[f] = {"cases": len(sub), "top1": rate(sub, lambda r: r["top1"] == r["truth"]),
                      "accepted_correct": rate(sub, lambda r: r["diagnosis"] == r["truth"]),
                      "wrong": rate(sub, wrong)}
    by_strength = {}
    for s in STRENGTHS:
        sub = [r for r in eff if r["strength"] == s]
        if sub:
            by_strength[s] = {"cases": len(sub),
                              "top1": rate(sub, lambda r: r["top1"] == r["truth"]),
                              "accepted_correct": rate(sub, lambda r: r["diagnosis"] == r["truth"]),
                              "wrong": rate(sub, wrong)}
    return {
        "confusion": conf,
        "top1_accuracy": rate(eff, lambda r: r["top1"] == r["truth"]),
        "accepted_correct": rate(eff, lambda r: r["diagnosis"] == r["truth"]),
        "wrong_acceptance": rate(eff, wrong),
        "false_acceptance_clean": rate(clean, lambda r: bool(r["accepted"])),
        "refits_failed": rate(rows, lambda r: bool(r["failed"])),
        "by_form": by_form,
        "by_strength": by_strength,
        "median_seconds": float(np.median([r["seconds"] for r in rows])) if rows else None,
        "cases": len(rows),
        "absorbed_offset_cases": len(absorbed),
        "absorbed_offset_nothing_accepted": rate(absorbed, lambda r: not r["accepted"]),
        "effect_cases": len(eff),
        "clean_cases": len(clean),
    }


def _pct(x) -> str:
    return "-" if x is None else f"{100 * x:.0f} %"


def print_report(source: str, s: dict) -> None:
    labels = [lab for lab in (*FAMILIES, "none")
              if any(s["confusion"][lab].values()) or any(s["confusion"][t][lab]
                                                         for t in s["confusion"])]
    print(f"\n=== {source}: confusion matrix (rows: withheld family; columns: first accepted "
          "family)")
    body = [[t] + [s["confusion"][t][d] or "." for d in labels] for t in labels]
    print(table(body, ["truth \\ diagnosis", *labels]))
    print()
    rows_f = [[k, v["cases"], _pct(v["top1"]), _pct(v["accepted_correct"]), _pct(v["wrong"])]
              for k, v in s["by_form"].items()]
    print(table(rows_f, ["form", "cases", "top-1", "accepted = truth", "wrong accepted"]))
    print()
    rows_s = [[k, v["cases"], _pct(v["top1"]), _pct(v["accepted_correct"]), _pct(v["wrong"])]
              for k, v in s["by_strength"].items()]
    print(table(rows_s, ["strength", "cases", "top-1", "accepted = truth", "wrong accepted"]))
    print(f"\n{source}: top-1 {_pct(s['top1_accuracy'])} (goal >= 90 %), accepted = truth "
          f"{_pct(s['accepted_correct'])}, wrong effect accepted {_pct(s['wrong_acceptance'])} "
          f"(goal <= 5 %), false acceptance on clean records {_pct(s['false_acceptance_clean'])} "
          f"(goal <= 5 %) over {s['effect_cases']} + {s['clean_cases']} cases; a refit failed "
          f"in {_pct(s['refits_failed'])}; median {s['median_seconds']:.1f} s per diagnosis")
    if s["absorbed_offset_cases"]:
        print(f"{source}: an output offset ({', '.join(ABSORBED)}) is the nominal model's "
              f"sensor offset: nothing accepted in "
              f"{_pct(s['absorbed_offset_nothing_accepted'])} of {s['absorbed_offset_cases']}")


def _count(rate: float | None, cases: int) -> str:
    return "-" if rate is None else f"{100 * rate:.0f} % ({round(rate * cases)} of {cases})"


def render(payload: dict) -> str:
    """The accuracy per source, the misses and the offset cases, as Markdown.

    Parameters
    ----------
    payload : dict
        From :func:`measure`.

    Returns
    -------
    str
    """
    sources = [s for s in ("in-form", "cross-form") if s in payload["summary"]]
    S = {s: payload["summary"][s] for s in sources}
    goals = {"top-1 accuracy": ">= 90 % cross-form", "a wrong family accepted": "<= 5 %",
             "false acceptance on clean records": "<= 5 %"}
    rows = [["top-1 accuracy", *(_count(S[s]["top1_accuracy"], S[s]["effect_cases"])
                                 for s in sources)],
            ["first accepted family = withheld family",
             *(_pct(S[s]["accepted_correct"]) for s in sources)],
            ["a wrong family accepted", *(_count(S[s]["wrong_acceptance"], S[s]["effect_cases"])
                                          for s in sources)],
            ["false acceptance on clean records",
             *(_count(S[s]["false_acceptance_clean"], S[s]["clean_cases"]) for s in sources)],
            ["refits that failed", *(_pct(S[s]["refits_failed"]) for s in sources)],
            ["time per diagnosis (median)", *(f"{S[s]['median_seconds']:.1f} s"
                                              for s in sources)]]
    rows = [[*r, goals.get(r[0], "")] for r in rows]
    text = [table(rows, ["", *sources, "goal"])]
    for s in sources:
        by = S[s]["by_strength"]
        strengths = ", ".join(f"{_pct(v['top1'])} ({k})" for k, v in by.items())
        misses = [r for r in payload["cases"] if r["source"] == s and r["truth"] != "none"
                  and r["form"] not in ABSORBED and r["top1"] != r["truth"]]
        wrong = [r for r in payload["cases"] if r["source"] == s and r["truth"] != "none"
                 and r["form"] not in ABSORBED
                 and any(f != r["truth"] for f in r["accepted_families"])]
        line = f"\n*{s.capitalize()}*: top-1 by strength {strengths}."
        if misses:
            line += " Top-1 misses: " + "; ".join(
                f"{r['form']} ({r['strength']}) ranked {r['top1_form']}" for r in misses) + "."
        if wrong:
            line += " Wrong acceptances: " + "; ".join(
                f"{r['form']} ({r['strength']}) -> accepted {', '.join(r['accepted'])}"
                for r in wrong) + "."
        if S[s]["absorbed_offset_cases"]:
            line += (f" An output offset ({S[s]['absorbed_offset_cases']} cases, left out of "
                     f"the rates) is the nominal model's sensor offset: nothing accepted in "
                     f"{_pct(S[s]['absorbed_offset_nothing_accepted'])}.")
        text.append(line)
    st = payload["settings"]
    text.append(f"\n({st['draws']} draw(s) per form at three strengths, {st['clean']} clean "
                f"records per source, {st['seconds']:g} s + {st['seconds']:g} s records, seed "
                f"{st['seed']}; every case in `benchmarks/results/withheld_effects.json`.)")
    return "\n".join(text)


def render_budget(payload: dict) -> str:
    """The diagnosis' cost against the nominal identification, as a sentence.

    Parameters
    ----------
    payload : dict
        From :func:`measure`.

    Returns
    -------
    str
    """
    b = payload["summary"].get("budget")
    if b is None:
        return "(not measured: run without `--no-budget`)"
    return (f"{b['samples']} + {b['held_out_samples']} samples with all candidates: "
            f"{b['seconds']:.1f} s, **{b['ratio_to_nominal_fit']:.1f}x** the nominal "
            f"identification alone (`identify(train, \"batch\", model=\"duhem\")`, "
            f"{b['nominal_fit_seconds']:.2f} s, same process; goal <= 3x); accepted: "
            f"{', '.join(b['accepted']) or 'none'}.")


if __name__ == "__main__":
    main()
