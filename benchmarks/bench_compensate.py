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

#: The README blocks this script renders (see ``benchmarks/readme.py``).
README_BLOCKS = {"compensate-speed": "render"}
COMMAND = "OPENBLAS_NUM_THREADS=1 python benchmarks/bench_compensate.py"


def measure(quick: bool = False, samples: int | None = None) -> dict:
    """Time the closed loop both ways on a 50 Hz triangle, and the compiled parts per sample.

    Parameters
    ----------
    quick : bool
        600 python-control samples and a 0.1 s scan instead of 3 000 / 1 s.
    samples : int, optional
        Samples of the python-control run.

    Returns
    -------
    dict
        ``samples_python_control``, ``samples_scan``, ``seconds`` (per run), the ratio of
        compiled to python-control, the feed-forward's fraction of the sampling period, the
        sampling period and the largest difference between the two loops.
    """
    n_ct = samples or (600 if quick else 3_000)
    scan_s = 0.1 if quick else 1.0
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
    return {
        "samples_python_control": n_ct, "samples_scan": n, "sampling_period_s": period,
        "seconds": {"closed_loop_python_control": t_ct, "closed_loop_compiled_short": t_fast,
                    "feedforward": t_ff, "closed_loop_compiled": t_cl, "linear": t_lin},
        "ratio_compiled_vs_control": t_ct / t_fast,
        "feedforward_fraction_of_sampling_period": t_ff / n / period,
        "max_abs_difference_um": agree,
    }


def _table(payload: dict) -> str:
    s, n_ct, n = payload["seconds"], payload["samples_python_control"], payload["samples_scan"]
    ratio = payload["ratio_compiled_vs_control"]
    rows = [
        [f"closed loop, python-control ({n_ct} samples)",
         f"{s['closed_loop_python_control'] / n_ct * 1e6:.1f}", "1"],
        [f"closed loop, compiled ({n_ct} samples)",
         f"{s['closed_loop_compiled_short'] / n_ct * 1e6:.2f}", f"{ratio:.0f}"],
        [f"feed-forward inverse, compiled ({n} samples)", f"{s['feedforward'] / n * 1e6:.2f}", ""],
        [f"closed loop, compiled ({n} samples)", f"{s['closed_loop_compiled'] / n * 1e6:.2f}", ""],
        [f"linear baseline, compiled ({n} samples)", f"{s['linear'] / n * 1e6:.3f}", ""],
    ]
    return table(rows, ["run", "us per sample", "speed-up vs python-control"])


def render(payload: dict) -> str:
    """The closed loop's speed as a sentence (Markdown).

    Parameters
    ----------
    payload : dict
        What :func:`measure` returns.

    Returns
    -------
    str
    """
    s, n = payload["seconds"], payload["samples_scan"]
    return (f"The compiled closed loop (feed-forward inverse + feedback + stage, 50 Hz triangle "
            f"of {n} samples) runs {s['closed_loop_compiled'] / n * 1e6:.1f} us per sample (of a "
            f"{payload['sampling_period_s'] * 1e6:.0f} us sampling period), "
            f"{payload['ratio_compiled_vs_control']:.0f}x faster than the same loop through "
            f"python-control, which it matches to {payload['max_abs_difference_um']:.0e} um.")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--quick", action="store_true",
                        help="600 python-control samples and a 0.1 s scan instead of 3 000 / 1 s")
    parser.add_argument("--samples", type=int, default=None,
                        help="samples of the python-control run")
    args = parser.parse_args()
    payload = measure(args.quick, args.samples)
    print(f"50 Hz triangle on the reference stage (max |y| difference python-control vs "
          f"compiled: {payload['max_abs_difference_um']:.1e} um); sampling period "
          f"{payload['sampling_period_s'] * 1e6:.1f} us")
    print(_table(payload))
    print()
    print(render(payload))
    print(f"wrote {write_json('compensate', payload)}")


if __name__ == "__main__":
    main()
