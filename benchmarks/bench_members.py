"""The choice of a member: does ``model="auto"`` keep the plain model where it suffices, and
what does it cost?

* On the paper's stage (a Duhem sandwich, 0.2 s records of 20 seeds) the choice should keep the
  plain Duhem model: a richer member cannot beat the right one.
* On a stage-A look-alike (Bouc-Wen hysteresis, none of the members' forms) it reports which
  member it takes, per seed.
* Speed: ``model="auto"`` against the default Duhem fit on the same 20 001-sample record
  (measured stage A's ``prbn_1`` when ``../shared/data`` is there, else the look-alike), best of
  three in one process, as a ratio; and on each of stage A's six records, best of two, with
  the choice's fits side by side in threads (the default) and in one thread (``workers=1``).

    OPENBLAS_NUM_THREADS=1 python benchmarks/bench_members.py [--seeds 20]
"""

from __future__ import annotations

import argparse
import os
import time
import warnings
from collections import Counter

from _common import table, write_json
from bench_stage_a import STAGE_A

from hystid.identify import identify
from hystid.records import load_record
from hystid.reference import reference_record
from hystid.testing import stage_a_like


def _chosen(rec) -> str:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return identify(rec, model="auto").info["model"]


def _best_seconds(rec, model: str, rounds: int = 3, **options) -> float:
    best = float("inf")
    for _ in range(rounds):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            t0 = time.perf_counter()
            identify(rec, model=model, **options)
            best = min(best, time.perf_counter() - t0)
    return best


def stage_a_speed(rounds: int = 2) -> list[dict]:
    """``model="auto"`` against the Duhem fit on each of stage A's six records (empty when
    they are absent): seconds, best of ``rounds``, threads as the default and one."""
    rows = []
    for name in ("prbn_1", "prbn_2", "sine50_1", "sine50_2", "tri50_1", "tri50_2"):
        path = STAGE_A / f"{name}.csv"
        if not path.exists():
            return []
        rec = load_record(path)
        duhem = _best_seconds(rec, "duhem", rounds)
        rows.append({"record": name, "duhem_s": duhem,
                     "auto_s": _best_seconds(rec, "auto", rounds),
                     "auto_one_thread_s": _best_seconds(rec, "auto", rounds, workers=1),
                     "chosen": _chosen(rec)})
    return rows


def measure(seeds: int = 20) -> dict:
    """Choices on both stages and the speed ratio.

    Parameters
    ----------
    seeds : int
        Seeds per stage.

    Returns
    -------
    dict
        ``duhem_stage`` and ``bouc_wen_stage``: the member chosen per seed; ``speed``: the
        record, both times and their ratio.
    """
    duhem = [_chosen(reference_record(0.2, seed=s)) for s in range(seeds)]
    bouc = [_chosen(stage_a_like("prbn", seconds=0.5, rest_seconds=0.2, seed=s))
            for s in range(min(seeds, 5))]
    path = STAGE_A / "prbn_1.csv"
    rec = load_record(path) if path.exists() else stage_a_like("prbn", seconds=1.0)
    t_auto, t_duhem = _best_seconds(rec, "auto"), _best_seconds(rec, "duhem")
    return {"duhem_stage": duhem, "bouc_wen_stage": bouc,
            "speed": {"record": rec.name, "samples": rec.n, "auto_s": t_auto,
                      "duhem_s": t_duhem, "ratio": t_auto / t_duhem},
            "stage_a_speed": stage_a_speed(), "cores": os.cpu_count()}


def render(payload: dict) -> str:
    """The choices and the speed ratio as Markdown."""
    rows = []
    for key, label in (("duhem_stage", "paper's stage (Duhem), 0.2 s"),
                       ("bouc_wen_stage", "stage-A look-alike (Bouc-Wen), 0.7 s")):
        counts = Counter(payload[key])
        rows.append([label, str(len(payload[key])),
                     ", ".join(f"{m} {n}" for m, n in counts.most_common())])
    s = payload["speed"]
    return (table(rows, ["records", "seeds", "member chosen (times)"])
            + f"\n\n`model=\"auto\"` takes {s['ratio']:.1f}x the default Duhem fit on "
            f"{s['record']} ({s['samples']} samples): {s['auto_s']:.1f} s against "
            f"{s['duhem_s']:.1f} s, best of three in one process.") + _render_speed(payload)


def _render_speed(payload: dict) -> str:
    rows = payload.get("stage_a_speed") or []
    if not rows:
        return ""
    body = [[r["record"], r["chosen"], f"{r['duhem_s']:.2f}", f"{r['auto_s']:.2f}",
             f"{r['auto_s'] / r['duhem_s']:.1f}x", f"{r['auto_one_thread_s']:.2f}",
             f"{r['auto_one_thread_s'] / r['duhem_s']:.1f}x"] for r in rows]
    ratios = [r["auto_s"] / r["duhem_s"] for r in rows]
    return ("\n\nOn each record of stage A (best of two, "
            f"{payload.get('cores')} cores; the goal: at most 3x):\n\n"
            + table(body, ["record", "auto chose", "duhem [s]", "auto [s]", "ratio",
                           "auto, one thread [s]", "ratio"])
            + f"\n\n`auto` takes {min(ratios):.1f}-{max(ratios):.1f}x the Duhem fit.")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--seeds", type=int, default=20)
    args = parser.parse_args()
    payload = measure(args.seeds)
    print(render(payload))
    print(f"\nwritten {write_json('members', payload)}")


if __name__ == "__main__":
    main()
