"""Identification on records as they come: held-out RMS against the baselines, per method.

Records: the shared measured piezo (identify on the first 60 %, score the held-out end,
simulated on from the identification part), the as-measured suite of the independent
simulator (``hystid.testing.as_measured_suite``: offset, units, not at rest, 10 kHz, outlier,
end glitch, each with a held-out record of another seed), a stage-A look-alike (10 kHz, Bouc-Wen
hysteresis, -100..+74 V, offset, rest at a level, flexure mode), a stage-B look-alike (200 Hz,
Preisach hysteresis, a 1 Hz sine of random phase: every record begins in motion) and the
Bouc-Wen benchmark
(train.h5 -> each test signal). Methods: ``auto`` (the member of the model family that
``hystid identify`` chooses by default), ``batch`` and ``online`` (the Duhem sandwich). Time per
fit is compared with the single-start fit in the same
process (``linear_init=False, offset=False``: one start, no offset).

    python benchmarks/bench_real_records.py [--quick]
"""

from __future__ import annotations

import argparse
import time
import warnings
from pathlib import Path

from _common import table, write_json
from figures import fit_and_compare

from hystid.identify.offline import fit_output_error
from hystid.records import load_record
from hystid.testing import as_measured_suite, stage_a_like
from hystid.testing.measured import stage_b_like

#: The README blocks this script renders (see ``benchmarks/readme.py``).
README_BLOCKS = {"real-records": "render"}
COMMAND = "OPENBLAS_NUM_THREADS=1 python benchmarks/bench_real_records.py"


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
        out.append(("stage B look-alike", stage_b_like(seed=0),
                    [stage_b_like(seed=s) for s in (1, 2, 3, 4)]))
        if BOUC_WEN.exists():
            si = {"u": "N", "y": "m"}  # the benchmark's units (its README)
            train = load_record(f"{BOUC_WEN / 'train.h5'}:multisine", units=si)
            tests = [load_record(f"{BOUC_WEN / 'test.h5'}:{g}", units=si)
                     for g in ("multisine", "sinesweep")]
            out.append(("Bouc-Wen benchmark", train, tests))
    return out


#: How the README names each case (train -> held out).
LABELS = {
    "measured piezo 150 V 1 Hz": "measured piezo, first 60 % -> last 40 %",
    "as measured: offset": "independent simulator, sensor offset",
    "as measured: units": "the same in kV / nm",
    "as measured: mid_motion": "record starting mid-motion",
    "as measured: held_level": "rest at a held level",
    "as measured: 10kHz": "10 kHz, other anti-alias filter",
    "as measured: outlier": "a 1e12 outlier and a burst",
    "as measured: end_glitch": "end glitch (last sample wrapped)",
    "stage A look-alike (PRBN -> sines)": "stage-A look-alike (Bouc-Wen loop, 10 kHz, "
                                          "-100..+74 V), PRBN -> 50 Hz sine / 100 Hz triangle "
                                          "/ large sine",
    "stage B look-alike": "stage-B look-alike (Preisach loop, 200 Hz, 1 Hz sine of random "
                          "phase), seed 0 -> seeds 1 / 2 / 3 / 4",
    "Bouc-Wen benchmark": "Bouc-Wen benchmark, train multisine -> test multisine / sine sweep",
}


def measure(quick: bool = False,
            methods: tuple[str, ...] = ("auto", "batch", "online")) -> dict:
    """Identify every record set with each method and score it against the baselines.

    Parameters
    ----------
    quick : bool
        The measured piezo and the as-measured suite only.
    methods : tuple of str
        Identification methods.

    Returns
    -------
    dict
        ``cases``: per record set and method, the comparison, the time and the single-start
        fit's time (batch), or the error.
    """
    payload = []
    for label, train, held in cases(quick):
        unit = train.units.get("y", "")
        for method in methods:
            try:
                result, comparison, seconds = fit_and_compare(train, held, method)
            except ValueError as err:
                payload.append({"case": label, "method": method, "unit": unit,
                                "error": str(err)})
                continue
            single = None
            if method == "batch":
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore")
                    t0 = time.perf_counter()
                    fit_output_error(train, linear_init=False, offset=False)
                    single = time.perf_counter() - t0
            payload.append({"case": label, "method": method, "unit": unit, "seconds": seconds,
                            "single_start_seconds": single,
                            "warnings": result.info.get("warnings", []),
                            "comparison": comparison.to_dict()})
    return {"cases": payload}


def _cell(values: list[float | None], best: list[bool]) -> str:
    text = [("diverged" if v is None else f"{v:.3g}") for v in values]
    return " / ".join(f"**{t}**" if b else t for t, b in zip(text, best, strict=True))


def render(payload: dict) -> str:
    """The held-out RMS per record set and method, the baselines beside, as Markdown.

    Parameters
    ----------
    payload : dict
        From :func:`measure`.

    Returns
    -------
    str
    """
    by_case: dict[str, dict] = {}
    for c in payload["cases"]:
        by_case.setdefault(c["case"], {"unit": c["unit"]})[c["method"]] = c
    methods = list(dict.fromkeys(c["method"] for c in payload["cases"]))
    rows, failed, close = [], [], []
    for case, entry in by_case.items():
        fits = {m: entry[m] for m in methods if m in entry and "comparison" in entry[m]}
        failed += [f"{case} ({m}): {entry[m]['error']}" for m in methods
                   if m in entry and "error" in entry[m]]
        if not fits:
            continue
        first = next(iter(fits.values()))["comparison"]["rows"]
        model = {m: [r["model"] for r in fits[m]["comparison"]["rows"]] for m in fits}
        line = [r["static_line"] for r in first]
        linear = [r["linear"] for r in first]
        best = [min(v for v in col if v is not None)
                for col in zip(*model.values(), line, linear, strict=True)]
        cells = [_cell(model[m], [v == b for v, b in zip(model[m], best, strict=True)])
                 if m in model else "-" for m in methods]
        b = entry.get("batch", {})
        seconds = (f"{b['seconds']:.2g} ({b['single_start_seconds']:.2g})"
                   if b.get("single_start_seconds") else "-")
        rows.append([f"{LABELS.get(case, case)} [{entry['unit']}]", *cells,
                     _cell(line, [v == b for v, b in zip(line, best, strict=True)]),
                     _cell(linear, [v == b for v, b in zip(linear, best, strict=True)]),
                     seconds])
        gain = [1 - m / li for m, li in zip(model.get("batch", []), linear, strict=False)
                if m is not None and li]
        where = LABELS.get(case, case).split(",")[0]
        if gain and min(gain) < 0.0:
            lost = sum(g < 0.0 for g in gain)
            close.append(f"on the {where} the batch model loses to the linear model on {lost} "
                         f"of {len(gain)} held-out records (by up to {-100 * min(gain):.0f} %; "
                         f"it beats it by {100 * max(gain):.0f} % at best)")
        elif gain and min(gain) < 0.2:
            close.append(f"on the {where} the batch model beats the linear model by only "
                         f"{100 * min(gain):.0f}-{100 * max(gain):.0f} %")
    text = [table(rows, ["records (train -> held out)", *methods, "static line", "linear",
                         "batch fit [s] (one start, no offset)"])]
    if close:
        text.append("\nAgainst the linear model: " + "; ".join(close) + ".")
    if failed:
        text.append("\nRefused: " + "; ".join(failed))
    return "\n".join(text)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--quick", action="store_true", help="measured piezo and suite only")
    parser.add_argument("--methods", default="auto,batch,online",
                        help="auto: the member hystid identify chooses; batch / online: the "
                             "Duhem sandwich")
    args = parser.parse_args()
    payload = measure(args.quick, tuple(args.methods.split(",")))
    print(render(payload))
    print(f"\nwritten {write_json('real_records', payload)}")


if __name__ == "__main__":
    main()
