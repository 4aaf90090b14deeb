"""The EKF baseline's model in other units, and on measured stage A.

Identifies the reference stage's record (60 % of it) with ``method="ekf"`` in V/um, mV/nm, kV/nm
and V/m and scores each model on the last 40 % beside the linear model, then stage A's
``prbn_1`` (when ``../shared/data`` is there) on three other records. Prints a table and writes
``benchmarks/results/ekf_units.json``.

Run: ``OPENBLAS_NUM_THREADS=1 python benchmarks/bench_ekf_units.py``
"""

from __future__ import annotations

import warnings
from pathlib import Path

from _common import table, write_json

from hystid.baselines import compare
from hystid.identify import identify
from hystid.records import load_record
from hystid.reference import reference_record
from hystid.testing.measured import with_units

STAGE_A = Path(__file__).resolve().parents[2] / "shared" / "data" / "real" / "stageA"


def measure() -> list[dict]:
    """One row per case: the factors applied, the model's and the linear model's RMS."""
    rows = []
    rec = reference_record(0.3)
    k = int(0.6 * rec.n)
    for uu, yy in (("V", "um"), ("mV", "nm"), ("kV", "nm"), ("V", "m")):
        r = with_units(rec, u=uu, y=yy)
        res = identify(r[:k], method="ekf")
        row = compare(res.model, r[:k], [(r, k)]).rows[0]
        rows.append({"case": f"reference stage in {uu} / {yy}", "scaled": res.info["scaled"],
                     "model": [row["model"]], "linear": [row["linear"]], "unit": yy})
    if STAGE_A.exists():
        train = load_record(STAGE_A / "prbn_1.csv")
        held = [load_record(STAGE_A / f"{n}.csv") for n in ("prbn_2", "sine50_1", "tri50_1")]
        res = identify(train, method="ekf")
        c = compare(res.model, train, held).rows
        rows.append({"case": "stage A prbn_1 -> prbn_2 / sine50_1 / tri50_1",
                     "scaled": res.info["scaled"], "model": [x["model"] for x in c],
                     "linear": [x["linear"] for x in c], "unit": "um"})
    return rows


def main() -> None:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        rows = measure()
    fmt = lambda v: " / ".join(f"{x:.4g}" for x in v)  # noqa: E731
    print(table([[r["case"], f"{r['scaled']['u']:g}, {r['scaled']['y']:g}", fmt(r["model"]),
                  fmt(r["linear"]), r["unit"]] for r in rows],
                ["record", "factors u, y", "ekf held-out RMS", "linear", "unit"]))
    print(f"written {write_json('ekf_units', {'rows': rows})}")


if __name__ == "__main__":
    main()
