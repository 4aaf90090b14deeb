"""The PI sandwich on records of a stage that rests on a branch of its loop.

``hystid.testing.stage_a_like`` (Bouc-Wen hysteresis, a 740 Hz mode: not the model's form) with
the stage swung by 90 % of its half-range up or down before its rest, and not swung; 1 s of
excitation after 1 s of rest. Each record kind is identified with ``model="pi-stage"`` from the
virgin state (``rest_swing=False``), with the swing estimated (the default), on-line (the swing
estimated when its window fills, and set again after the run with the parameters held; and
holding the swing the batch fit found, ``PIStageOnline(rest_swing=...)``), and with the
default ``model="auto"``, batch and
on-line (its on-line identifier holds the swing its batch choice found), then scored
on a PRBN, a sine and a triangle record of another seed swung alike, beside the linear model
and the static line. Prints a table and writes ``benchmarks/results/rest_swing.json``.

Run: ``OPENBLAS_NUM_THREADS=1 python benchmarks/bench_rest_swing.py``
"""

from __future__ import annotations

import warnings

from _common import table, write_json

from hystid.baselines import compare
from hystid.identify import identify
from hystid.testing import stage_a_like

README_BLOCKS = {"rest-swing": "render"}

HELD = ("prbn", "sine50", "tri50")
#: Stands for the swing the ``pi-stage`` batch fit found on the same record.
BATCH_SWING = "the batch fit's"
FITS = {"pi-stage, virgin": {"model": "pi-stage", "rest_swing": False},
        "pi-stage": {"model": "pi-stage"},
        "pi-stage on-line": {"model": "pi-stage", "method": "online"},
        "pi-stage on-line, swing given": {"model": "pi-stage", "method": "online",
                                          "rest_swing": BATCH_SWING},
        "auto": {},
        "auto on-line": {"method": "online"}}


def measure(quick: bool = False) -> dict:
    """One row per training record: every fit's held-out RMS (nm) and the baselines'."""
    rows = []
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        for swing in (0.9, -0.9, 0.0):
            records = {"seconds": 1.0, "swing_before": swing}
            held = [stage_a_like(k, seed=2, repeat=1, **records) for k in HELD]
            for kind in ("prbn",) if quick else ("prbn", "sine50", "tri50"):
                train = stage_a_like(kind, seed=1, **records)
                row: dict = {"swing_before": swing, "train": kind}
                for label, options in FITS.items():
                    if options.get("rest_swing") is BATCH_SWING:
                        options = {**options, "rest_swing": row["pi-stage swing"]}
                    res = identify(train, **options)
                    c = compare(res.model, train, held).rows
                    row[label] = [1e3 * r["model"] for r in c]
                    row[f"{label} swing"] = float(getattr(res.model, "rest_swing", 0.0))
                    row[f"{label} member"] = res.info.get("model", options.get("model"))
                row["linear"] = [1e3 * r["linear"] for r in c]
                row["static line"] = [1e3 * r["static_line"] for r in c]
                rows.append(row)
    return {"held_out": list(HELD), "rows": rows}


def render(payload: dict) -> str:
    """The table: held-out RMS per fit on PRBN / sine / triangle, the swing found."""
    fmt = lambda v: " / ".join(f"{x:.0f}" for x in v)  # noqa: E731
    labels = [*FITS, "linear", "static line"]
    return table([[f"{r['swing_before']:+.1f}", r["train"], *(fmt(r[k]) for k in labels),
                   f"{r['pi-stage swing']:.1f}", str(r["auto member"])]
                  for r in payload["rows"]],
                 ["swing", "trained on", *(f"{k} [nm]" for k in labels), "swing found [V]",
                  "auto chose"])


def main() -> None:
    payload = measure()
    print(render(payload))
    print(f"written {write_json('rest_swing', payload)}")


if __name__ == "__main__":
    main()
