"""Identification on records as they come: held-out RMS against the baselines, per method.

Records: the shared measured piezo (identify on the first 60 %, score the held-out end,
simulated on from the identification part), the as-measured suite of the independent
simulator (``hystid.testing.as_measured_suite``: offset, units, not at rest, 10 kHz, outlier,
end glitch, each with a held-out record of another seed), a stage-A look-alike (10 kHz, Bouc-Wen
hysteresis, -100..+74 V, offset, rest at a level, flexure mode) and the Bouc-Wen benchmark
(train.h5 -> each test signal). Time per fit is compared with the single-start fit in the same
process (``linear_init=False, offset=False``: one start, no offset).

    python benchmarks/bench_real_records.py [--quick]
"""

from __future__ import annotations

import argparse
import time
import warnings
from pathlib import Path

import numpy as np
from _common import table, write_json
from figures import fit_and_compare

from hystid.identify.offline import fit_output_error
from hystid.records import load_record
from hystid.testing import as_measured_suite, stage_a_like

SHARED = Path(__file__).resolve().parents[2] / "shared" / "data"
PIEZO = SHARED / "real" / "piezo_sine_150V_1Hz" / "hysteresis_v_150_1hz.csv"
BOUC_WEN = SHARED / "benchmarks" / "bouc_wen"


def cases(quick: bool) -> list[tuple[str, object, list]]:
    """(label, training record, held-out items) for every record set."""
    out = []
    if PIEZO.exists():
        rec = load_record(PIEZO, columns={"t": 1, "u": 3, "y": 2})
        k = int(round(0.6 * rec.n))
        out.append(("measured piezo 150 V 1 Hz", rec[:k], [(rec, k)]))
    suite = {r.name: r for r in as_measured_suite(0, seconds=0.2)}
    for name in [n for n in suite if not n.endswith("/heldout")]:
        out.append((f"as measured: {name}", suite[name], [suite[f"{name}/heldout"]]))
    if not quick:
        train = stage_a_like("prbn", seconds=1.0, rest_seconds=0.5, seed=0)
        held = [stage_a_like(kind, seconds=1.0, rest_seconds=0.5, seed=1)
                for kind in ("sine50", "tri100", "large_sine")]
        out.append(("stage A look-alike (PRBN -> sines)", train, held))
        if BOUC_WEN.exists():
            train = load_record(f"{BOUC_WEN / 'train.h5'}:multisine")
            tests = [load_record(f"{BOUC_WEN / 'test.h5'}:{g}") for g in ("multisine",
                                                                          "sinesweep")]
            out.append(("Bouc-Wen benchmark", train, tests))
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--quick", action="store_true", help="measured piezo and suite only")
    parser.add_argument("--methods", default="batch,online")
    args = parser.parse_args()
    rows, payload = [], []
    for label, train, held in cases(args.quick):
        for method in args.methods.split(","):
            try:
                result, comparison, seconds = fit_and_compare(train, held, method)
            except ValueError as err:
                rows.append([label, method, "-", "-", "-", "-", f"error: {err}"[:60]])
                continue
            single = np.nan
            if method == "batch":
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore")
                    t0 = time.perf_counter()
                    fit_output_error(train, linear_init=False, offset=False)
                    single = time.perf_counter() - t0
            for r in comparison.rows:
                model = "diverged" if not np.isfinite(r["model"]) else f"{r['model']:.4g}"
                rows.append([label, method, r["record"][:30], model, f"{r['static_line']:.4g}",
                             f"{r['linear']:.4g}",
                             ("yes" if r["beats"] else "NO") + f", {seconds:.1f} s"
                             + (f" ({seconds / single:.1f}x one start)" if single == single
                                else "")])
            payload.append({"case": label, "method": method, "seconds": seconds,
                            "single_start_seconds": None if single != single else single,
                            "warnings": result.info.get("warnings", []),
                            "comparison": comparison.to_dict()})
    print(table(rows, ["records", "method", "held out", "model RMS", "static line",
                       "linear", "beats both, time"]))
    print(f"\nwritten {write_json('real_records', {'cases': payload})}")


if __name__ == "__main__":
    main()
