"""Simulation speed: compiled kernel vs control.input_output_response vs a plain Python loop.

Usage: python benchmarks/bench_simulate.py [--quick] [--samples N]
"""

from __future__ import annotations

import argparse

import control as ct
import numpy as np
from _common import best_time, table, write_json

from hystid.reference import paper_excitation, reference_model


def plain_loop(p: dict, u: np.ndarray) -> np.ndarray:
    """Eqs. (24)-(25) sample by sample in plain Python (the experimental structure)."""
    w1p = w2p = y1 = y2 = up = 0.0
    y = np.empty(len(u))
    for k in range(len(u)):
        w1 = -p["a11"] * w1p + up
        dw1 = w1 - w1p
        w2 = w2p + p["alpha"] * (p["f1"] * w1p - w2p) * abs(dw1) + p["g0"] * dw1
        yk = -p["a21"] * y1 - p["a22"] * y2 + w2
        y[k] = yk
        w1p, w2p, y2, y1, up = w1, w2, y1, yk, u[k]
    return y


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--quick", action="store_true", help="3 000 samples instead of 30 000")
    parser.add_argument("--samples", type=int, default=None)
    args = parser.parse_args()
    n = args.samples or (3_000 if args.quick else 30_000)
    model = reference_model()
    u = paper_excitation(n, seed=0)
    sys = model.to_control()
    t = np.arange(n) / model.fs
    x0 = model.control_state()

    model.simulate(u)  # compile outside the timing
    fast = model.simulate(u).y
    ref = ct.input_output_response(sys, t, u, X0=x0).outputs[0]
    agree = float(np.max(np.abs(ref - fast)) / np.max(np.abs(fast)))
    t_ct = best_time(lambda: ct.input_output_response(sys, t, u, X0=x0), repeat=1, min_time=0)
    t_py = best_time(lambda: plain_loop(model.params, u), repeat=3)
    t_fast = best_time(lambda: model.simulate(u), repeat=7)
    rows = [
        ["control.input_output_response", f"{t_ct * 1e3:.1f}", "1"],
        ["plain Python loop", f"{t_py * 1e3:.2f}", f"{t_ct / t_py:.0f}"],
        ["DuhemSandwich.simulate (numba)", f"{t_fast * 1e3:.3f}", f"{t_ct / t_fast:.0f}"],
    ]
    print(f"Simulation of the reference stage, {n} samples (max relative difference "
          f"compiled vs python-control: {agree:.1e})")
    print(table(rows, ["method", "time [ms]", "speed-up vs input_output_response"]))
    path = write_json("simulate", {
        "samples": n, "seconds": {"input_output_response": t_ct, "plain_loop": t_py,
                                  "compiled": t_fast},
        "ratio_compiled_vs_control": t_ct / t_fast, "ratio_plain_vs_control": t_ct / t_py,
        "max_relative_difference": agree, "target_ratio": 1000,
    })
    print(f"wrote {path}")
    short_inputs(model)


def short_inputs(model, n: int = 100) -> None:
    """Cost of ``simulate`` on a short input: the compiled kernel alone vs the whole call."""
    from hystid.kernels import simulate_into

    u = paper_excitation(n, seed=1)
    P = model.structure.history
    layout = model.structure.layout

    def kernel_only():
        U, W1, W2, Y = (np.zeros(P + n) for _ in range(4))
        U[P:] = u
        simulate_into(model.theta, layout, U, W1, W2, Y, P)

    t_kernel = best_time(kernel_only, repeat=7)
    t_plain = best_time(lambda: model.simulate(u, check=False), repeat=7)
    t_checked = best_time(lambda: model.simulate(u), repeat=7)
    rows = [
        ["kernel on preallocated arrays", f"{t_kernel * 1e6:.1f}", "1"],
        ["simulate(check=False) -> response", f"{t_plain * 1e6:.1f}",
         f"{t_plain / t_kernel:.1f}"],
        ["simulate() with the admissibility check", f"{t_checked * 1e6:.1f}",
         f"{t_checked / t_kernel:.1f}"],
    ]
    print(f"\nShort input ({n} samples): what a call costs beyond the kernel")
    print(table(rows, ["call", "time [us]", "ratio to the kernel"]))
    path = write_json("simulate_short", {
        "samples": n, "seconds": {"kernel": t_kernel, "simulate_unchecked": t_plain,
                                  "simulate_checked": t_checked},
        "ratio_unchecked_vs_kernel": t_plain / t_kernel,
        "ratio_checked_vs_kernel": t_checked / t_kernel,
    })
    print(f"wrote {path}")


if __name__ == "__main__":
    main()
