"""The measured piezo record diagnosed with default options, as ``hystid diagnose`` does it.

Identify on the record's rest and the first 60 % of its excitation, hold out the last 40 %
(``--holdout``, a share of the excitation), all candidate forms, the default time
budget (as long as the nominal identification took: on a slower or loaded machine fewer
further forms are refitted). Skipped with a message when ``../shared/data`` is absent.

    python benchmarks/bench_piezo_diagnosis.py

is the same diagnosis as

    hystid diagnose ../shared/data/real/piezo_sine_150V_1Hz/hysteresis_v_150_1hz.csv \\
        --columns t=1,u=3,y=2
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

from _common import table, write_json

from hystid.diagnose import diagnose
from hystid.records import load_record, parse_columns

#: The README blocks this script renders (see ``benchmarks/readme.py``).
README_BLOCKS = {"piezo-diagnosis": "render"}

PIEZO = (Path(__file__).resolve().parents[2] / "shared" / "data" / "real"
         / "piezo_sine_150V_1Hz" / "hysteresis_v_150_1hz.csv")


def measure(quick: bool = False) -> dict:
    """Diagnose the measured piezo record with the command's defaults.

    Parameters
    ----------
    quick : bool
        Unused (the diagnosis has one size); kept for the common interface.

    Returns
    -------
    dict
        The diagnosis (``DiagnosisResult.to_dict()``), its summary text and its time.

    Raises
    ------
    FileNotFoundError
        When the shared record is absent, naming where it was looked for.
    """
    if not PIEZO.is_file():
        raise FileNotFoundError(f"{PIEZO}: measured piezo record not found "
                                "(../shared/data beside the checkout)")
    rec = load_record(PIEZO, columns=parse_columns("t=1,u=3,y=2"))
    t0 = time.perf_counter()
    res = diagnose(rec, progress=False)
    seconds = time.perf_counter() - t0
    return {"record": PIEZO.name, "seconds": seconds,
            "diagnosis": json.loads(json.dumps(res.to_dict(), default=float)),
            "summary": res.summary()}


def render(payload: dict) -> str:
    """The diagnosis as the README's bullets and candidate table.

    Parameters
    ----------
    payload : dict
        From :func:`measure`.

    Returns
    -------
    str
    """
    d = payload["diagnosis"]
    unit = d["settings"]["units"]["y"]
    nominal, floor = d["nominal"], d["noise_floor_rms"]
    admissible = ("admissible on the held-out input" if not nominal["admissibility"] else
                  "NOT admissible on the held-out input: " + "; ".join(nominal["admissibility"]))
    first = d["rounds"][0]
    where = [f for f in first["findings"] if not f.startswith("held-out RMS error")]
    rows, not_excited = [], []
    for e in d["effects"]:
        if e["status"] == "not excited":
            not_excited.append(e["name"])
        elif e.get("rms_val_after") is not None:
            rows.append([f"`{e['name']}`", e["family"], e["status"],
                         f"{e['rms_val_after']:.4g}", f"{100 * e['gap_closed']:.0f} %",
                         f"{e['p_value']:.2g}"])
    accepted = ", ".join(d["accepted"]) or "none"
    left = d["final"]["unexplained"]
    lines = [
        f"* The nominal model (offset, rest level and Duhem state at rest estimated) is "
        f"{admissible}; held-out RMS {nominal['rms_val']:.3g} {unit} against a noise floor of "
        f"{floor:.3g} {unit}: a gap of {nominal['gap']:.2g} {unit}.",
        "* Where: " + "; ".join(where) + ".",
        f"* Which: accepted {accepted}. Refitted forms (held-out RMS [{unit}], share of the gap "
        "closed, p-value of the round's test):", "",
        table(rows, ["form", "family", "status", "held-out RMS", "gap closed", "p"]), "",
    ]
    if not_excited:
        lines.append("  Not excited by this input (the model absorbs their signature): "
                     + ", ".join(f"`{n}`" for n in not_excited) + ".")
    if left and left.get("excess_rms") is not None:
        lines.append(f"* What stays: {left['excess_rms']:.2g} {unit} RMS above the floor"
                     + (f", {100 * left['periodic']['harmonic_fraction']:.0f} % periodic with "
                        "the input" if left.get("periodic") else "")
                     + (f", excess in {left['band_hz'][0]:.3g}-{left['band_hz'][1]:.3g} Hz"
                        if left.get("band_hz") else "") + ".")
    lines.append(f"* {d['settings']['train_samples']} + {d['settings']['val_samples']} samples "
                 f"in {payload['seconds']:.0f} s (nominal identification "
                 f"{d['settings']['nominal_seconds']:.0f} s).")
    return "\n".join(lines)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.parse_args()
    try:
        payload = measure()
    except FileNotFoundError as err:
        sys.exit(str(err))
    print(render(payload))
    print(f"wrote {write_json('piezo_diagnosis', payload)}")


if __name__ == "__main__":
    main()
