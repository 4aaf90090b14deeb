"""Compensation speed: the closed loop through python-control vs compiled, and the compensator's
cost per sample against the 30 kHz sampling period.

Usage: python benchmarks/bench_compensate.py [--quick] [--samples N]
"""

from __future__ import annotations

import argparse

import numpy as np
from _common import best_time, table, write_json

import hystid.compensate as hc
from hystid.reference import reference_model


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--quick", action="store_true",
                        help="600 python-control samples and a 0.1 s scan instead of 3 000 / 1 s")
    parser.add_argument("--samples", type=int, default=None,
                        help="samples of the python-control run")
    args = parser.parse_args()
    n_ct = args.samples or (600 if args.quick else 3_000)
    scan_s = 0.1 if args.quick else 1.0
    model = reference_model()
    design = hc.design_feedback(model)

    # the same closed loop (feed-forward + feedback + amplifier + stage), both ways
    ref = hc.scan_reference("triangle", 50, periods=50 * scan_s)
    y_short = ref.y[:n_ct]
    loop = hc.closed_loop(model, design, feedforward=True)
    hc.simulate_closed_loop(model, y_short, design)  # compile outside the timing
    slow = hc.closed_loop_response(loop, y_short)
    fast = hc.simulate_closed_loop(model, y_short, design)
    agree = float(np.max(np.abs(slow.y - fast.y)))
    t_ct = best_time(lambda: hc.closed_loop_response(loop, y_short), repeat=1, min_time=0)
    t_fast = best_time(lambda: hc.simulate_closed_loop(model, y_short, design), repeat=5)

    # per-sample cost on a whole scan (the reversal planner runs every sample)
    n = len(ref.y)
    t_ff = best_time(lambda: hc.feedforward(model, ref.y), repeat=3)
    t_cl = best_time(lambda: hc.simulate_closed_loop(model, ref.y, design), repeat=3)
    t_lin = best_time(lambda: hc.linear_feedforward(model, ref.y), repeat=3)
    period = 1.0 / model.fs
    rows = [
        [f"closed loop, python-control ({n_ct} samples)", f"{t_ct / n_ct * 1e6:.1f}", "1"],
        [f"closed loop, compiled ({n_ct} samples)", f"{t_fast / n_ct * 1e6:.2f}",
         f"{t_ct / t_fast:.0f}"],
        [f"feed-forward inverse, compiled ({n} samples)", f"{t_ff / n * 1e6:.2f}", ""],
        [f"closed loop, compiled ({n} samples)", f"{t_cl / n * 1e6:.2f}", ""],
        [f"linear baseline, compiled ({n} samples)", f"{t_lin / n * 1e6:.3f}", ""],
    ]
    print(f"50 Hz triangle on the reference stage (max |y| difference python-control vs "
          f"compiled: {agree:.1e} um); sampling period {period * 1e6:.1f} us")
    print(table(rows, ["run", "us per sample", "speed-up vs python-control"]))
    path = write_json("compensate", {
        "samples_python_control": n_ct, "samples_scan": n,
        "seconds": {"closed_loop_python_control": t_ct, "closed_loop_compiled_short": t_fast,
                    "feedforward": t_ff, "closed_loop_compiled": t_cl, "linear": t_lin},
        "ratio_compiled_vs_control": t_ct / t_fast,
        "feedforward_fraction_of_sampling_period": t_ff / n / period,
        "max_abs_difference_um": agree,
    })
    print(f"wrote {path}")


if __name__ == "__main__":
    main()
