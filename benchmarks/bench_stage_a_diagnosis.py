"""Measured stage A diagnosed as ``hystid diagnose`` does it, and the model it ends in.

For each held-out input (the 50 Hz triangle and the 50 Hz sine), train on ``prbn_1``, hold out
``<input>_1`` with ``<input>_2`` as its repeat (the floor), default options; then the final model
(:func:`hystid.diagnose.final_model.final_model`): the nominal model, the nominal model with the
accepted effects and the family's members scored alike (each record zeroed on its rest output).
The diagnosis' time is given as a ratio to its own nominal fit's (one process); ``--breakdown``
prints where it goes (each progress line of the diagnosis and the final model with the seconds
until the next one, also as a multiple of the nominal fit). The same as

    hystid diagnose prbn_1.csv --val tri50_1.csv --repeat tri50_2.csv --out DIR

    OPENBLAS_NUM_THREADS=1 python benchmarks/bench_stage_a_diagnosis.py
"""

from __future__ import annotations

import argparse
import os
import time
import warnings

from _common import table, write_json
from bench_stage_a import STAGE_A

from hystid.diagnose import diagnose
from hystid.diagnose.final_model import FINAL_MEMBERS, final_model
from hystid.records import load_record

#: The README blocks this script renders (see ``benchmarks/readme.py``).
README_BLOCKS = {"stage-a-diagnosis": "render"}
COMMAND = "OPENBLAS_NUM_THREADS=1 python benchmarks/bench_stage_a_diagnosis.py"


def measure(quick: bool = False, members: tuple[str, ...] = FINAL_MEMBERS,
            workers: int | None = None) -> dict:
    """Diagnose prbn_1 against each held-out input and keep the final model's figures.

    Parameters
    ----------
    quick : bool
        The triangle only.
    members : tuple of str
        The members tried as the hysteresis itself (the diagnosis' default by default), fitted
        beside the rounds.
    workers : int, optional
        The diagnosis' threads (its default, the cores up to 4, by default).

    Returns
    -------
    dict
        Per held-out input: accepted effects, the diagnosis' own figures, the final model's
        candidates and choice, the floor, the seconds (diagnosis, nominal fit, final model) and
        the ``timeline``: ``[seconds from the start, progress line]`` of the diagnosis and the
        final model.
    """
    if not STAGE_A.exists():
        return {"error": f"{STAGE_A} is absent"}
    train = load_record(STAGE_A / "prbn_1.csv")
    rows = []
    for name in ("tri50",) if quick else ("tri50", "sine50"):
        val = load_record(STAGE_A / f"{name}_1.csv")
        rep = load_record(STAGE_A / f"{name}_2.csv")
        timeline: list[list] = []
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            t0 = time.perf_counter()

            def note(message: str, t0: float = t0, timeline: list = timeline) -> None:
                timeline.append([time.perf_counter() - t0, message])

            res = diagnose(train, [val], repeats=[rep], progress=note, members=members,
                           workers=workers)
            t1 = time.perf_counter()
            note("final model: the members identified, every candidate scored")
            final = final_model(res, train, [val], members=members, progress=note)
            t2 = time.perf_counter()
            note("end")
        rows.append({"val": val.name, "accepted": list(res.accepted),
                     "diagnosis": {"nominal": res.nominal["rms_val"],
                                   "final": res.final["rms_val"],
                                   "gap_closed": res.final["gap_closed"]},
                     "final_model": final.to_dict(), "floor": final.floor,
                     "seconds": {"diagnosis": t1 - t0, "final_model": t2 - t1,
                                 "nominal_fit": res.settings.get("nominal_seconds")},
                     "timeline": timeline})
    return {"train": train.name, "cases": rows, "workers": workers,
            "cores": os.cpu_count()}


def render(payload: dict) -> str:
    """The final model's candidates per held-out input, in nm, as Markdown.

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
    out = []
    for case in payload["cases"]:
        f = case["final_model"]
        rows = [[c["candidate"] + (" (model.json)" if c["candidate"] == f["chosen"] else ""),
                 f"{1e3 * c['mean_rms']:.1f}", f"{100 * c['gap_closed']:.0f} %"]
                for c in f["candidates"]]
        s = case["seconds"]
        ratio = (s["diagnosis"] + s["final_model"]) / s["nominal_fit"] if s["nominal_fit"] \
            else float("nan")
        out += [f"Held out `{case['val']}` (floor {1e3 * case['floor']:.1f} nm from its repeat, "
                f"offset removed); accepted effects: {', '.join(case['accepted']) or 'none'}; "
                f"diagnosis and final model {s['diagnosis'] + s['final_model']:.0f} s, "
                f"{ratio:.1f}x the nominal fit:", "",
                table(rows, ["candidate", "held-out RMS [nm]", "gap to the floor closed"]),
                "", f"{f['verdict']}.", ""]
    return "\n".join(out).rstrip()


def breakdown(payload: dict) -> str:
    """Where the time of each case goes: every progress line with the seconds until the next.

    Parameters
    ----------
    payload : dict
        From :func:`measure`.

    Returns
    -------
    str
        Per case, lines ``seconds  x nominal  progress line`` (the nominal fit's own share is
        the time up to the line that reports the nominal model refitted).
    """
    out = []
    for case in payload.get("cases", []):
        nominal = case["seconds"]["nominal_fit"] or float("nan")
        out.append(f"{case['val']}: nominal fit {nominal:.2f} s")
        steps = case.get("timeline", [])
        for (t, message), (t_next, _) in zip(steps[:-1], steps[1:], strict=True):
            out.append(f"  {t_next - t:6.2f} s {(t_next - t) / nominal:5.2f}x  {message[:90]}")
    return "\n".join(out)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--quick", action="store_true", help="the triangle only")
    parser.add_argument("--members", default=",".join(FINAL_MEMBERS),
                        help="members tried as the hysteresis itself, comma-separated (default "
                        f"{','.join(FINAL_MEMBERS)}; the README block is of the default)")
    parser.add_argument("--workers", type=int, default=None,
                        help="the diagnosis' threads (default: its own, the cores up to 4)")
    parser.add_argument("--breakdown", action="store_true",
                        help="print where the time goes (each progress line with its seconds)")
    args = parser.parse_args()
    members = tuple(m.strip() for m in args.members.split(",") if m.strip())
    payload = measure(args.quick, members, args.workers)
    if args.breakdown:
        print(breakdown(payload), end="\n\n")
    print(render(payload))
    name = "stage_a_diagnosis" if members == FINAL_MEMBERS else "stage_a_diagnosis_members"
    print(f"\nwritten {write_json(name, payload)}")


if __name__ == "__main__":
    main()
