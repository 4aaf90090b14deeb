"""Feedback designs compared: integral + notch (the default) and PI + notch (``pi_zero``).

Controllers designed on a model identified from 0.1 s of noisy reference-stage data (as in
notebook 2), driving the true stage with the feed-forward inverse; tracking after the first period.

Usage: python benchmarks/feedback_designs.py
"""

from __future__ import annotations

import warnings

from _common import table, write_json

import hystid.compensate as hc
from hystid.identify import fit_output_error
from hystid.reference import reference_model, reference_record

SCANS = (("triangle", 50.0), ("sine", 200.0))


def main() -> None:
    stage = reference_model()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        model = fit_output_error(reference_record(seconds=0.1, seed=0)).model
    rows, payload = [], {}
    for pi_zero in (None, 3.0, 5.0):
        design = hc.design_feedback(model, pi_zero=pi_zero)
        label = "integral + notch" if pi_zero is None else f"PI + notch, pi_zero={pi_zero:g}"
        figures = {"ki": design.ki, "kp": design.kp, "crossover_hz": design.crossover_hz,
                   "phase_margin_deg": design.phase_margin,
                   "gain_margin_db": design.gain_margin_db}
        cells = [label, f"{design.kp:.3g}", f"{design.crossover_hz:.0f}",
                 f"{design.phase_margin:.1f}", f"{design.gain_margin_db:.1f}"]
        for kind, f in SCANS:
            ref = hc.scan_reference(kind, f)
            m = hc.simulate_closed_loop(model, ref.y, design, plant=stage).metrics(ref.skip)
            figures[f"{kind}_{f:g}_max_rms_nm"] = [1e3 * m.max_error, 1e3 * m.rms_error]
            cells.append(f"{1e3 * m.max_error:.1f} / {1e3 * m.rms_error:.1f}")
        rows.append(cells)
        payload[label] = figures
    print("Feedback designs on the identified model, driving the reference stage "
          "(feed-forward inverse + feedback)")
    print(table(rows, ["design", "kp [V/um]", "crossover [Hz]", "PM [deg]", "GM [dB]",
                       *(f"{k} {f:g} Hz max / RMS [nm]" for k, f in SCANS)]))
    print(f"wrote {write_json('feedback_designs', payload)}")


if __name__ == "__main__":
    main()
