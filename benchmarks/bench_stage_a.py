"""Measured stage A: every member of the model family against the baselines and a generic NARX.

Identified on ``prbn_1`` (the whole record, default options of each member), run free from rest
on every other record of ``../shared/data/real/stageA/``. Every prediction, the models', the
static line's, the linear model's and the NARX's, is put on each record's own output at rest
(:func:`hystid.baselines.rest_zero`: the sensor's zero moves between records); the models'
figures with the offset identified on ``prbn_1`` are given as well. The floor of each input is
the repeat-to-repeat RMS of its two records with their means removed
(:func:`hystid.baselines.repeat_floor`). The speed of ``model="auto"`` is a ratio to the default
Duhem fit timed in the same process, on the same record.

    OPENBLAS_NUM_THREADS=1 python benchmarks/bench_stage_a.py [--members duhem,pi-stage,auto]
        [--train tri50_1]

``pi-stage/online`` is the member identified by its on-line identifier
(``identify(train, model="pi-stage", method="online")``), scored like the batch fits (and
``pi-poly/online`` the same for ``pi-poly``);
``duhem/online`` the same for the paper's Duhem sandwich.

The NARX column needs the ``bench`` extra (SysIdentPy); without it the column is left out.
"""

from __future__ import annotations

import argparse
import time
import warnings
from pathlib import Path

import narx
import numpy as np
from _common import table, write_json

from hystid.baselines import LinearModel, StaticLine, compare, repeat_floor, rest_zero
from hystid.identify import identify
from hystid.records import load_record

#: The README blocks this script renders (see ``benchmarks/readme.py``).
README_BLOCKS = {"stage-a": "render"}
COMMAND = "OPENBLAS_NUM_THREADS=1 python benchmarks/bench_stage_a.py"

STAGE_A = Path(__file__).resolve().parents[2] / "shared" / "data" / "real" / "stageA"
TRAIN = "prbn_1"
INPUTS = ("prbn", "sine50", "tri50")
#: ``model=`` values, or ``model/method`` (``pi-stage/online``: the member's on-line identifier).
MEMBERS = ("duhem", "duhem/online", "gduhem", "mduhem", "pi", "pi-stage", "pi-poly",
           "pi-stage/online", "pi-poly/online", "auto")


def records() -> dict:
    """Stage A's records by name (empty when the shared data is absent)."""
    if not STAGE_A.exists():
        return {}
    return {f"{i}_{r}": load_record(STAGE_A / f"{i}_{r}.csv") for i in INPUTS for r in (1, 2)}


def _rms(p: np.ndarray, rec) -> float:
    e = p + rest_zero(p, rec) - rec.y
    r = float(np.sqrt(np.mean(e ** 2)))
    return r if np.isfinite(r) else float("inf")


def measure(members: tuple[str, ...] = MEMBERS, train_name: str = TRAIN) -> dict:
    """Fit each member on ``prbn_1`` and score it, the baselines and the NARX on the others.

    Parameters
    ----------
    members : tuple of str
        ``model=`` values of :func:`hystid.identify.identify`, or ``model/method``.
    train_name : str
        The record identified on (``prbn_1``; another for ``--train``).

    Returns
    -------
    dict
        ``records`` (held-out names), ``floors`` (per input, um), ``baselines`` (per baseline,
        RMS per record), ``members`` (per member: RMS per record zeroed at rest and as placed,
        seconds, chosen member for ``auto``) and ``speed`` (``auto`` / default seconds).
    """
    recs = records()
    if not recs:
        return {"error": f"{STAGE_A} is absent"}
    if train_name not in recs:
        raise SystemExit(f"--train: expected one of {', '.join(recs)}, got {train_name!r}")
    train = recs[train_name]
    held = [r for n, r in recs.items() if n != train_name]
    names = [r.name for r in held]
    floors = {i: repeat_floor([recs[f"{i}_1"], recs[f"{i}_2"]]) for i in INPUTS}
    line, linear = StaticLine.fit(train), LinearModel.fit(train, 3, 3, 1)
    base = {"static line": [_rms(line.predict(r.u), r) for r in held],
            "linear (3rd order)": [_rms(linear.predict(r.u), r) for r in held]}
    if narx.available():
        t0 = time.perf_counter()
        model = narx.NARX.fit(train)
        runs = [model.predict(r) for r in held]
        base["NARX (SysIdentPy)"] = [_rms(p, r) for p, r in zip(runs, held, strict=True)]
        base_seconds = time.perf_counter() - t0
        # as SysIdentPy runs it: from the record's own first outputs, no zero put on it
        narx_as_run = [float(np.sqrt(np.mean((p - r.y) ** 2))) for p, r in zip(runs, held,
                                                                                 strict=True)]
    else:
        base_seconds = narx_as_run = None
    out = {}
    for m in members:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            t0 = time.perf_counter()
            name, _, method = m.partition("/")
            res = identify(train, model=name, method=method or "batch")
            seconds = time.perf_counter() - t0
            rows = compare(res.model, train, held).rows
        out[m] = {"rms": [r["model"] for r in rows], "as_placed": [r["model_as_placed"]
                                                                   for r in rows],
                  "seconds": seconds, "chosen": res.info.get("model", m),
                  "selection": res.info.get("member_selection")}
    speed = (out["auto"]["seconds"] / out["duhem"]["seconds"]
             if "auto" in out and "duhem" in out else None)
    return {"train": train_name, "records": names, "floors": floors, "baselines": base,
            "narx_seconds": base_seconds, "narx_as_run": narx_as_run, "members": out,
            "speed_auto_over_duhem": speed}


def _nm(v: float) -> str:
    return "diverged" if v is None or not np.isfinite(v) else f"{1e3 * v:.0f}"


def render(payload: dict) -> str:
    """Held-out RMS in nm per record: members, baselines, NARX and the floor, as Markdown.

    Parameters
    ----------
    payload : dict
        From :func:`measure`.

    Returns
    -------
    str
    """
    if "error" in payload:
        return f"Not measured: {payload['error']}."
    names = payload["records"]
    floor = [payload["floors"][n.rsplit("_", 1)[0]] for n in names]
    rows = []
    for m, e in payload["members"].items():
        label = f"`{m}`" + (f" (chose `{e['chosen']}`)" if m == "auto" else "")
        rows.append([label, *(_nm(v) for v in e["rms"]), f"{e['seconds']:.1f}"])
    for b, v in payload["baselines"].items():
        rows.append([b, *(_nm(x) for x in v), ""])
    rows.append(["repeat floor (offset removed)", *(_nm(f) for f in floor), ""])
    train = payload.get("train", TRAIN)
    text = [table(rows, [f"held-out RMS [nm], trained on {train}", *names, "fit [s]"]), ""]
    narx_rms = payload["baselines"].get("NARX (SysIdentPy)")
    linear_rms = payload["baselines"].get("linear (3rd order)")
    for m, e in payload["members"].items():
        said = []
        for label, ref in (("the NARX", narx_rms), ("the linear model", linear_rms)):
            if ref is not None:
                wins = sum(a < b for a, b in zip(e["rms"], ref, strict=True))
                said.append(f"{label} on {wins} of {len(names)} records")
        if said:
            text.append(f"- `{m}` beats {' and '.join(said)}.")
    for m, e in payload["members"].items():
        ratio = [a / f for a, f in zip(e["rms"], floor, strict=True)]
        text.append(f"- `{m}`: {min(ratio):.1f}-{max(ratio):.1f}x the repeat floor; with the "
                    f"offset identified on {train} instead of each record's rest output "
                    f"{_nm(min(e['as_placed']))}-{_nm(max(e['as_placed']))} nm.")
    as_run = payload.get("narx_as_run")
    if as_run is not None:
        text.append(f"- Without a zero put on either: the NARX as SysIdentPy runs it (from each "
                    f"record's first measured outputs) {', '.join(_nm(v) for v in as_run)} nm; "
                    f"the members from their own rest and offset (identified on {train}):")
        for m, e in payload["members"].items():
            wins = sum(a < b for a, b in zip(e["as_placed"], as_run, strict=True))
            text.append(f"  `{m}` {', '.join(_nm(v) for v in e['as_placed'])} nm, ahead on "
                        f"{wins} of {len(names)}.")
    for m, e in payload["members"].items():
        batch = payload["members"].get(m.partition("/")[0])
        if "/" in m and batch is not None:
            ratio = [a / b for a, b in zip(e["rms"], batch["rms"], strict=True)]
            text.append(f"- `{m}`: {min(ratio):.2f}-{max(ratio):.2f}x the batch fit's held-out "
                        "RMS (the goal: at most 1.25x on every record).")
    if payload.get("speed_auto_over_duhem"):
        text.append(f"- `auto` (the default) takes {payload['speed_auto_over_duhem']:.1f}x the "
                    f"Duhem sandwich's fit on {train} (20 001 samples, one process).")
    return "\n".join(text)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--members", default=",".join(MEMBERS))
    parser.add_argument("--train", default=TRAIN,
                        help=f"the record identified on (default {TRAIN}; the README block is "
                        "of the default)")
    args = parser.parse_args()
    payload = measure(tuple(args.members.split(",")), args.train)
    print(render(payload))
    name = "stage_a" if args.train == TRAIN else f"stage_a_train_{args.train}"
    print(f"\nwritten {write_json(name, payload)}")


if __name__ == "__main__":
    main()
