"""The choice of a member: does ``model="auto"`` keep the plain model where it suffices, and
what does it cost?

* On the paper's stage (a Duhem sandwich, 0.2 s records of 20 seeds) the choice should keep the
  plain Duhem model: a richer member cannot beat the right one.
* On a stage-A look-alike (Bouc-Wen hysteresis, none of the members' forms) it reports which
  member it takes, per seed.
* Speed: ``model="auto"`` against the default Duhem fit on the same 20 001-sample record
  (measured stage A's ``prbn_1`` when ``../shared/data`` is there, else the look-alike), best of
  three in one process, as a ratio.

    OPENBLAS_NUM_THREADS=1 python benchmarks/bench_members.py [--seeds 20]
"""

from __future__ import annotations

import argparse
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


def _best_seconds(rec, model: str, rounds: int = 3) -> float:
    best = float("inf")
    for _ in range(rounds):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            t0 = time.perf_counter()
            identify(rec, model=model)
            best = min(best, time.perf_counter() - t0)
    return best


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
                      "duhem_s": t_duhem, "ratio": t_auto / t_duhem}}


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
            f"{s['duhem_s']:.1f} s, best of three in one process.")


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
