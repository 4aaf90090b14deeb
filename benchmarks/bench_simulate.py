"""Simulation speed: compiled kernel vs control.input_output_response vs a plain Python loop.

Usage: python benchmarks/bench_simulate.py [--quick] [--samples N]
"""

from __future__ import annotations

import argparse

import control as ct
import numpy as np
from _common import best_time, table, write_json

from hystid.reference import paper_excitation, reference_model

#: The README blocks this script renders (see ``benchmarks/readme.py``).
README_BLOCKS = {"simulate": "render"}



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


def measure(quick: bool = False, samples: int | None = None) -> dict:
    """Time the three ways through the reference stage and a short input's overhead.

    Parameters
    ----------
    quick : bool
        3 000 samples instead of 30 000.
    samples : int, optional
        Record length (overrides ``quick``).

    Returns
    -------
    dict
        Seconds per run, ratios to ``input_output_response`` and the agreement.
    """
    n = samples or (3_000 if quick else 30_000)
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
    return {"samples": n, "seconds": {"input_output_response": t_ct, "plain_loop": t_py,
                                      "compiled": t_fast},
            "ratio_compiled_vs_control": t_ct / t_fast, "ratio_plain_vs_control": t_ct / t_py,
            "max_relative_difference": agree, "target_ratio": 1000,
            "short": short_inputs(model)}


def render(payload: dict) -> str:
    """The figures as Markdown.

    Parameters
    ----------
    payload : dict
        From :func:`measure`.

    Returns
    -------
    str
    """
    s, short = payload["seconds"], payload["short"]
    rows = [["`control.input_output_response`", f"{s['input_output_response']:.3g} s", "1"],
            ["plain Python loop", f"{s['plain_loop'] * 1e3:.3g} ms",
             f"{payload['ratio_plain_vs_control']:.0f}"],
            ["`DuhemSandwich.simulate` (numba)", f"{s['compiled'] * 1e3:.3g} ms",
             f"{payload['ratio_compiled_vs_control']:.0f}"]]
    k = short["seconds"]
    rows_short = [["kernel on preallocated arrays", f"{k['kernel'] * 1e6:.1f}", "1"],
                  ["`simulate(check=False)` -> response", f"{k['simulate_unchecked'] * 1e6:.1f}",
                   f"{short['ratio_unchecked_vs_kernel']:.1f}"],
                  ["`simulate()` with the admissibility check",
                   f"{k['simulate_checked'] * 1e6:.1f}", f"{short['ratio_checked_vs_kernel']:.1f}"]]
    return "\n".join([
        f"{payload['samples']} samples of the reference stage through the same interconnected "
        f"system; the compiled kernel agrees with `control.input_output_response` to "
        f"{payload['max_relative_difference']:.1e} relative.", "",
        table(rows, ["run", "time", "speed-up vs `input_output_response`"]), "",
        f"On a short input ({short['samples']} samples) what a call costs beyond the compiled "
        "kernel (building the `TimeResponseData`, checking the envelope):", "",
        table(rows_short, ["call", "time [us]", "ratio to the kernel"])])


def short_inputs(model, n: int = 100) -> dict:
    """Cost of ``simulate`` on a short input: the compiled kernel alone vs the whole call.

    Parameters
    ----------
    model : DuhemSandwich
        The model to simulate.
    n : int
        Input length.

    Returns
    -------
    dict
        Seconds per call and ratios to the kernel.
    """
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
    return {"samples": n, "seconds": {"kernel": t_kernel, "simulate_unchecked": t_plain,
                                      "simulate_checked": t_checked},
            "ratio_unchecked_vs_kernel": t_plain / t_kernel,
            "ratio_checked_vs_kernel": t_checked / t_kernel}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--quick", action="store_true", help="3 000 samples instead of 30 000")
    parser.add_argument("--samples", type=int, default=None)
    args = parser.parse_args()
    payload = measure(args.quick, args.samples)
    print(render(payload))
    print(f"wrote {write_json('simulate', payload)}")


if __name__ == "__main__":
    main()
