"""Identified on a record cut mid-motion, used on records that begin at rest.

A record that does not begin at rest gives the model a rest level it never saw (the record's
first input, a point of its motion). Each case below is identified with defaults on the whole
record and on pieces of it cut where the input is at neither end of its range, and scored
(:func:`hystid.baselines.compare`) on held-out records that begin at rest, beside the static
line and the linear model fitted on the same record; ``before`` is the same model started as
it was before it knew that its rest was unseen (from that rest, ramped to the record's rest
level: ``envelope.from_rest`` set true).

Measured stage A (``../shared/data/real/stageA/``, when present): ``prbn_1`` (1 s of rest, 1 s
of excitation) cut at five points of its excitation, the other five records held out. The other
records come from ``hystid.testing``'s simulators, written apart from the model code: the
stage-A look-alike (Bouc-Wen hysteresis, a 740 Hz mode, 10 kHz; a 50 Hz triangle of seed 0,
held out its PRBN, 50 Hz sine and triangle and large sine of seed 1) and the paper-like stage at
30 kHz with a Preisach, a Maxwell-slip or a Duhem loop (the paper's excitation, 0.3 s, seed 7,
held out seeds 8 and 9).

    OPENBLAS_NUM_THREADS=1 python benchmarks/bench_rest_unseen.py
"""

from __future__ import annotations

import argparse
import dataclasses
import warnings
from pathlib import Path

import numpy as np
from _common import table, write_json

from hystid.baselines import compare
from hystid.identify import identify
from hystid.identify.members import member
from hystid.identify.prepare import rest_level
from hystid.records import Record
from hystid.testing import crop_start, simulate_stage, stage_a_like, with_offset

README_BLOCKS = {"rest-unseen": "render"}
COMMAND = "OPENBLAS_NUM_THREADS=1 python benchmarks/bench_rest_unseen.py"
#: Where the training records are cut [s] (after the look-alike's 1 s rest; from the start of
#: the paper's excitation).
CUTS = {"stage-A look-alike": (1.0567, 1.2033), "paper-like": (0.0713, 0.1237),
        "measured stage A": (1.05, 1.1111, 1.2345, 1.3, 1.4)}
STAGE_A = Path(__file__).resolve().parents[2] / "shared" / "data" / "real" / "stageA"
LOOPS = ("preisach", "maxwell", "duhem")


def _paper_like(loop: str, seed: int) -> Record:
    from hystid.reference import paper_excitation

    u = paper_excitation(9000, 30_000.0, seed=seed)
    y = simulate_stage(u, 30_000.0, hysteresis=loop, seed=seed)["y"]
    y = y + 1e-3 * np.random.default_rng(seed).standard_normal(len(u))
    return with_offset(Record(u, y, 30_000.0, units={"u": "V", "y": "um"},
                              name=f"paper-like {loop} {seed}"), -0.7)


def _measured_stage_a() -> list[tuple[str, Record, list[Record], tuple[float, ...]]]:
    """Measured stage A, ``prbn_1`` cut, the other five records held out (none without the
    data)."""
    from hystid.records import load_record

    if not STAGE_A.exists():
        return []
    recs = {p.stem: load_record(p) for p in sorted(STAGE_A.glob("*.csv"))}
    train = recs.pop("prbn_1")
    return [("measured stage A, prbn_1", train, list(recs.values()), CUTS["measured stage A"])]


def cases() -> list[tuple[str, Record, list[Record], tuple[float, ...]]]:
    """(label, training record, held-out records, cuts) of every case."""
    out = [*_measured_stage_a(),
           ("stage-A look-alike, Bouc-Wen loop", stage_a_like("tri50", seconds=1.0, seed=0),
            [stage_a_like(k, seconds=1.0, rest_seconds=0.5, seed=1)
             for k in ("prbn", "sine50", "tri50", "large_sine")], CUTS["stage-A look-alike"])]
    for loop in LOOPS:
        out.append((f"paper-like, {loop} loop", _paper_like(loop, 7),
                    [_paper_like(loop, s) for s in (8, 9)], CUTS["paper-like"]))
    return out


def _scores(model, train: Record, held: list[Record]) -> dict:
    rows = compare(model, train, held).rows
    return {key: [r[key] for r in rows] for key in ("model", "linear", "static_line")}


def measure(quick: bool = False) -> dict:
    """Identify every case on its whole record and on its cuts; score on its held-out records.

    Parameters
    ----------
    quick : bool
        The first cut of each case only.

    Returns
    -------
    dict
        ``cases``: per case the whole record's scores and, per cut, the member chosen, the
        scores now and ``before`` (RMS in um per held-out record), the on-line identifier's
        (``method="online"``, its member and scores), and the ``pi-stage``
        member's fit on the cut (its scores and the drift of the sensor's zero it estimated,
        um/s).
    """
    out = []
    for label, whole, held, cuts in cases():
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            ref = identify(whole)
            row = {"case": label, "whole": _scores(ref.model, whole, held),
                   "whole_member": ref.info.get("model"), "cuts": []}
            for cut in cuts[:1] if quick else cuts:
                train = crop_start(whole, cut)
                if rest_level(train.u)[1]:
                    raise RuntimeError(f"{label}: the cut at {cut} s is taken as a rest")
                result = identify(train)
                now = _scores(result.model, train, held)
                model = result.model
                model.envelope = dataclasses.replace(model.envelope, from_rest=True)
                before = _scores(model, train, held)["model"]
                online = identify(train, method="online")
                pi = member("pi-stage").fit(train)
                row["cuts"].append({"seconds": cut, "member": result.info.get("model"),
                                    "u0": float(train.u[0]), **now, "before": before,
                                    "online": _scores(online.model, train, held)["model"],
                                    "online_member": online.info.get("model"),
                                    "pi_stage": _scores(pi.model, train, held)["model"],
                                    "pi_stage_drift": pi.info["drift_per_second"]})
        out.append(row)
    return {"cases": out}


def _span(values: list[float]) -> str:
    lo, hi = min(values), max(values)
    return f"{lo:.3g}" if f"{lo:.3g}" == f"{hi:.3g}" else f"{lo:.3g}-{hi:.3g}"


def render(payload: dict) -> str:
    """The table: per case, the held-out RMS ranges before, now, whole record, both baselines.

    Parameters
    ----------
    payload : dict
        :func:`measure`'s output.

    Returns
    -------
    str
        Markdown.
    """
    rows, lines = [], []
    for c in payload["cases"]:
        cuts = c["cuts"]
        now = [v for k in cuts for v in k["model"]]
        before = [v for k in cuts for v in k["before"]]
        linear = [v for k in cuts for v in k["linear"]]
        static = [v for k in cuts for v in k["static_line"]]
        beats = sum(m < lin for k in cuts for m, lin in zip(k["model"], k["linear"],
                                                             strict=True))
        beats_line = sum(m < s for k in cuts for m, s in zip(k["model"], k["static_line"],
                                                            strict=True))
        better = sum(m < b for k in cuts for m, b in zip(k["model"], k["before"], strict=True))
        online = [v for k in cuts for v in k["online"]]
        ratio = max(o / m for k in cuts for o, m in zip(k["online"], k["model"], strict=True))
        online_line = sum(o < s for k in cuts for o, s in zip(k["online"], k["static_line"],
                                                              strict=True))
        rows.append([c["case"], ", ".join(f"{k['seconds']:.4g}" for k in cuts),
                     _span(before), f"**{_span(now)}**", _span(c["whole"]["model"]),
                     _span(static), _span(linear), f"{better} of {len(now)}",
                     f"{beats_line} / {beats} of {len(now)}",
                     f"{_span(online)} ({ratio:.2f}x; {online_line} of {len(now)})",
                     ", ".join(sorted({k["member"] for k in cuts}))])
        worse = [(k["seconds"], i) for k in cuts
                 for i, (m, lin) in enumerate(zip(k["model"], k["linear"], strict=True))
                 if m >= lin]
        if worse:
            lines.append(f"* {c['case']}: loses to the linear model on "
                         f"{len(worse)} of {len(now)} (cut, record) pairs.")
        if beats_line < len(now) or online_line < len(now):
            lines.append(f"* {c['case']}: loses to the static line on "
                         f"{len(now) - beats_line} of {len(now)} (cut, record) pairs, on-line "
                         f"on {len(now) - online_line}.")
        pi = [v for k in cuts for v in k["pi_stage"]]
        if all(k["member"] != "pi-stage" for k in cuts):
            drifts = [abs(k["pi_stage_drift"]) for k in cuts]
            lines.append(f"* {c['case']}: `pi-stage` fitted on the cuts (not chosen) is "
                         f"{_span(pi)} um off, with a drift of the sensor's zero of "
                         f"{_span(drifts)} um/s estimated.")
    head = ["case", "cut at [s]", "before [um]", "now [um]", "whole record [um]",
            "static line [um]", "linear [um]", "better than before",
            "beats static line / linear", "on-line [um] (worst ratio to now; beats static line)",
            "chosen"]
    return "\n".join([table(rows, head), *([""] + lines if lines else [])])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--quick", action="store_true", help="the first cut of each case")
    args = parser.parse_args()
    payload = measure(quick=args.quick)
    print(render(payload))
    print(f"\nwritten {write_json('rest_unseen', payload)}")


if __name__ == "__main__":
    main()
