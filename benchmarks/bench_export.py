"""C export speed: the generated C steps against the compiled Python, in the same process.

The model is exported (``hystid.export.c_sources``), compiled with the system C compiler
(``-std=c99 -O2``) together with a small timing driver, and run on the paper's excitation; the
same input goes through ``model.simulate`` (numba) in this process. Reported: samples per second
of ``hystid_model_step`` (goal: at least one million), of ``model.simulate``, their ratio, the
largest relative difference of the outputs, and the C rates of the on-line identifier's step
(with its supervisor, as exported by default, set beside ``hystid.export.rpem_reference``, and
bare, ``-DHYSTID_RPEM_SUPERVISE=0``, beside ``rpem_run``) and of the compensator
``hystid_ff_step`` (``hystid.compensate.compensate`` one sample at a time, set beside
``compensate`` over the whole reference) for two models: the reference stage
(a Duhem sandwich: its reversal planner looks 300 samples ahead, reusing the previous sample's
look-ahead while the command follows the plan; limits 0-10 V, where the 50 Hz triangle
saturates for a third of each period and the look-ahead is simulated again) and
the ``pi-stage`` member identified on a simulated stage A (``hystid.testing``; L2 with a zero
outside the unit circle: its anti-causal inverse runs as a FIR every sample). Goal: one million
samples per second for every step. Beside the goal, the Duhem compensator on the same scan with
limits wide enough never to saturate (every sample follows the plan), and with a preview of
3 000 samples (the step's lines of the preview's length are rings: a longer preview adds no shift
per sample, only what the planner looks at). Also the model step of the ``gduhem`` member (the
generalised Duhem block: cubic curve, quadratic slope) and of the ``mduhem`` member (six Duhem
operators in parallel), identified on a simulated stage A and run on the paper's excitation
scaled into their input envelope (the gduhem member's on-line identifier step is timed too), and
their compensators (the per-sample inverses without look-ahead of
``hystid.compensate.member_inverse``) on the same kind of triangle scan as the others, within
the limits the model's envelope sets.

Usage: OPENBLAS_NUM_THREADS=1 python benchmarks/bench_export.py [--quick] [--samples N]
           [--out FILE.json]
"""

from __future__ import annotations

import argparse
import copy
import json
import platform
import shutil
import subprocess
import tempfile
import warnings
from pathlib import Path

import numpy as np
from _common import best_time, table, write_json

from hystid.cli.compensate import scan_for
from hystid.compensate import compensate
from hystid.export import c_sources, ff_options, ff_plan, rpem_reference, rpem_start
from hystid.identify.online import rpem_run
from hystid.reference import paper_excitation, reference_model

GOAL = 1e6  # C steps per second
#: The on-line identifier's step without its supervisor.
BARE = "-DHYSTID_RPEM_SUPERVISE=0"
#: The compensator's options for the reference stage (it has no input envelope).
REFERENCE_LIMITS = {"u_limits": (0.0, 10.0)}

DRIVER = r"""
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "hystid_model.h"

static double buf[2 * 4000000];

int main(int argc, char **argv)
{
    long n, k, rep, reps;
    double best = 1e300, sum = 0.0, t;
    clock_t t0;
    FILE *f;
    if (argc < 4) {
        return 2;
    }
    n = atol(argv[3]);
    reps = atol(argv[4]);
    f = fopen(argv[2], "rb");
    if (f == NULL || n > 4000000 || fread(buf, sizeof(double), 2 * (size_t)n, f)
                                     != 2 * (size_t)n) {
        return 3;
    }
    fclose(f);
    for (rep = 0; rep < reps; rep++) {
        sum = 0.0;
        if (strcmp(argv[1], "model") == 0) {
            static hystid_model_state s;
            t0 = clock();
            hystid_model_init(&s);
            for (k = 0; k < n; k++) {
                sum += hystid_model_step(&s, buf[k]);
            }
#ifndef HYSTID_NO_FF
        } else if (strcmp(argv[1], "ff") == 0) {
            static hystid_ff_state s;
            t0 = clock();
            hystid_ff_init(&s);
            for (k = 0; k < n; k++) {
                sum += hystid_ff_step(&s, buf[k]);
            }
#endif
#ifndef HYSTID_NO_RPEM
        } else if (strcmp(argv[1], "rpem") == 0) {
            static hystid_rpem_state s;
            t0 = clock();
            hystid_rpem_init(&s);
            for (k = 0; k < n; k++) {
                hystid_rpem_step(&s, buf[k], buf[n + k]);
            }
            sum = hystid_rpem_theta(&s)[0];
#endif
        } else {
            return 2;
        }
        t = (double)(clock() - t0) / CLOCKS_PER_SEC;
        if (t < best) {
            best = t;
        }
    }
    printf("%.17g %.17g\n", best, sum);
    return 0;
}
"""


def compile_export(model, folder: Path, compensator: dict | None = None,
                   defines: tuple[str, ...] = ()) -> Path:
    """Export ``model`` into ``folder`` and build the timing driver (``defines``: ``-D``
    options); returns the program."""
    cc = shutil.which("cc") or shutil.which("gcc")
    if cc is None:
        raise SystemExit("bench_export: no C compiler (cc or gcc) on PATH")
    folder.mkdir(parents=True, exist_ok=True)
    for name, text in c_sources(model, compensator=compensator).items():
        (folder / name).write_text(text)
    (folder / "bench.c").write_text(DRIVER)
    exe = folder / "bench"
    subprocess.run([cc, "-std=c99", "-O2", "-Wall", "-Wextra", "-Werror", *defines,
                    "-I", str(folder),
                    str(folder / "hystid_model.c"), str(folder / "bench.c"), "-o", str(exe),
                    "-lm"], check=True)
    return exe


def c_rate(exe: Path, folder: Path, mode: str, u: np.ndarray, y: np.ndarray,
           reps: int) -> tuple[float, float]:
    """Best seconds of ``len(u)`` C steps over ``reps`` runs, and the run's checksum."""
    data = folder / f"{mode}.bin"
    np.concatenate([u, y]).astype("<f8").tofile(data)
    out = subprocess.run([str(exe), mode, str(data), str(len(u)), str(reps)],
                         capture_output=True, text=True, check=True).stdout.split()
    return float(out[0]), float(out[1])


def pi_stage_model():
    """The ``pi-stage`` member identified on a simulated stage A (as the tests do)."""
    from hystid.identify import identify
    from hystid.testing import stage_a_like

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return identify(stage_a_like("prbn", seconds=1.0, rest_seconds=0.5, seed=0),
                        model="pi-stage").model


def member_model(name: str):
    """The ``gduhem`` or ``mduhem`` member identified on a simulated stage A."""
    from hystid.identify import identify
    from hystid.testing import stage_a_like

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return identify(stage_a_like(seconds=0.3, rest_seconds=0.1), model=name).model


def model_rates(model, folder: Path, n: int) -> dict:
    """C ``hystid_model_step`` and ``model.simulate`` on the paper's excitation scaled into the
    model's input envelope (from its rest level to 80 % of the way to the envelope's top)."""
    exe = compile_export(model, folder)
    e = np.tile(paper_excitation(30_000, seed=0), n // 30_000 + 1)[:n]
    u = model.u_rest + 0.8 * (model.envelope.u_max - model.u_rest) * e / float(np.max(e))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        y = model.simulate(u, check=False).y
        t_py = best_time(lambda: model.simulate(u, check=False), repeat=5, min_time=0)
    t_c, checksum = c_rate(exe, folder, "model", u, y, reps=5)
    out = {"c_samples_per_s": n / t_c, "python_samples_per_s": n / t_py,
           "ratio_c_vs_python": t_py / t_c,
           "checksum_relative_difference": abs(checksum - float(np.cumsum(y)[-1]))
           / float(np.sum(np.abs(y)))}
    if getattr(type(model), "kind", None) == "duhem":  # the generalised block's RPEM step
        nf = min(n, 300_000)
        t_rpem, _ = c_rate(exe, folder, "rpem", u[:nf], y[:nf], reps=3)
        out["c_rpem_samples_per_s"] = nf / t_rpem
        bare = compile_export(model, folder / "bare", defines=(BARE,))
        t_bare, _ = c_rate(bare, folder, "rpem", u[:nf], y[:nf], reps=3)
        out["c_rpem_bare_samples_per_s"] = nf / t_bare
    return out


def ff_rates(model, folder: Path, n: int, options: dict, scan_limits: tuple | None = None) -> dict:
    """C ``hystid_ff_step`` and Python ``compensate`` over a triangle scan of ``n`` samples,
    with the C output checked against Python sample by sample. The scan's amplitude is set by
    the upper limit of ``scan_limits`` (default: the compensator's limits)."""
    exe = compile_export(model, folder, options)
    kw = ff_options(model, **options)
    top = (scan_limits or kw["u_limits"])[1]
    ramp = model.simulate(np.linspace(model.u_rest, top, 5_000), check=False).y
    amp = 0.6 * abs(ramp[-1] - ramp[0])  # a scan well inside what the limits allow
    r = scan_for(model, "triangle", 50.0, amp, n / model.fs)[:n]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        res = compensate(model, r, **kw, warn=False)
        t_py = best_time(lambda: compensate(model, r, **kw, warn=False), repeat=3, min_time=0)
    D = res.preview
    rr = np.concatenate([r, np.full(D, r[-1])])
    t_c, checksum = c_rate(exe, folder, "ff", rr, rr, reps=3)
    # the driver sums the commands in order, the rest commands of the first D calls included
    expect = float(np.cumsum(np.r_[np.full(D, _rest_command(model, kw)), res.u])[-1])
    plan = ff_plan(model, **options)
    return {"c_samples_per_s": rr.size / t_c, "python_samples_per_s": r.size / t_py,
            "delay": D, "planner_preview": plan.chain.preview, "l2_fir_taps": plan.l2.fir.size,
            "samples": int(r.size),
            "checksum_relative_difference": abs(checksum - expect) / float(np.sum(np.abs(res.u)))}


def _rest_command(model, kw: dict) -> float:
    """What the C step returns while it reads the preview in (the rest level, clipped)."""
    return min(max(model.u_rest, kw["u_limits"][0]), kw["u_limits"][1])


def measure(quick: bool = False, samples: int | None = None) -> dict:
    """Time the C steps and ``model.simulate`` on the reference stage, the compensators also on
    the pi-stage member, the model steps and compensators of the gduhem and mduhem members.

    Parameters
    ----------
    quick : bool
        300 000 samples instead of 3 000 000.
    samples : int, optional
        Samples per run (overrides ``quick``; at most 4 000 000).

    Returns
    -------
    dict
        Samples per second, ratio, agreement.
    """
    n = min(samples or (300_000 if quick else 3_000_000), 4_000_000)
    model = reference_model()
    u = np.tile(paper_excitation(30_000, seed=0), n // 30_000 + 1)[:n]
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        exe = compile_export(model, folder, REFERENCE_LIMITS)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            y = model.simulate(u, check=False).y
            t_py = best_time(lambda: model.simulate(u, check=False), repeat=5, min_time=0)
        t_c, checksum = c_rate(exe, folder, "model", u, y, reps=5)
        # the C driver sums its outputs in order: so does cumsum (equal sums: equal samples,
        # barring compensating differences)
        agree = abs(checksum - float(np.cumsum(y)[-1])) / float(np.sum(np.abs(y)))
        nf = min(n, 300_000)
        t_rpem, _ = c_rate(exe, folder, "rpem", u[:nf], y[:nf], reps=3)
        bare = compile_export(model, folder / "bare", defines=(BARE,))
        t_rpem_bare, _ = c_rate(bare, folder, "rpem", u[:nf], y[:nf], reps=3)
        uu, yy = np.ascontiguousarray(u[:nf] - model.u_rest), np.ascontiguousarray(y[:nf])

        start, start_bare = rpem_start(model), rpem_start(model, supervise=False)

        def python_rpem() -> None:  # the supervised identifier, as the C step by default
            rpem_reference(copy.deepcopy(start), u[:nf], y[:nf])

        def python_rpem_bare() -> None:
            rpem_run(start_bare._buf.copy(), start_bare._ints.copy(), uu, yy,
                     np.empty((nf, len(model.theta))), np.empty((nf, 7)))

        python_rpem()
        python_rpem_bare()
        t_rpem_py = best_time(python_rpem, repeat=3, min_time=0)
        t_rpem_py_bare = best_time(python_rpem_bare, repeat=3, min_time=0)
        ff = {"duhem": ff_rates(model, folder / "duhem", nf, REFERENCE_LIMITS),
              "pi_stage": ff_rates(pi_stage_model(), folder / "pi", nf, {})}
        # the planner's cost beside the goal: the same scan without saturation (every sample
        # follows the plan), and a preview ten times as long
        context = {
            "duhem_unsaturated": ff_rates(model, folder / "wide", nf, {"u_limits": (-100, 100)},
                                          scan_limits=REFERENCE_LIMITS["u_limits"]),
            "duhem_preview_3000": ff_rates(model, folder / "p3000", nf,
                                           {**REFERENCE_LIMITS, "preview": 3000}),
        }
        member_models = {name: member_model(name) for name in ("gduhem", "mduhem")}
        members = {name: model_rates(m, folder / name, n) for name, m in member_models.items()}
        ff.update({name: ff_rates(m, folder / f"{name}_ff", nf, {})
                   for name, m in member_models.items()})
    c_rate_model = n / t_c
    py_rate = n / t_py
    rates = [c_rate_model, nf / t_rpem, nf / t_rpem_bare] \
        + [v["c_samples_per_s"] for v in ff.values()] \
        + [v[k] for v in members.values() for k in ("c_samples_per_s", "c_rpem_samples_per_s",
                                                    "c_rpem_bare_samples_per_s") if k in v]
    return {"samples": n, "goal_c_samples_per_s": GOAL,
            "c_model_samples_per_s": c_rate_model, "python_simulate_samples_per_s": py_rate,
            "ratio_c_vs_python": c_rate_model / py_rate,
            "c_rpem_samples_per_s": nf / t_rpem, "python_rpem_samples_per_s": nf / t_rpem_py,
            "c_rpem_bare_samples_per_s": nf / t_rpem_bare,
            "python_rpem_bare_samples_per_s": nf / t_rpem_py_bare,
            "ff": ff, "ff_context": context, "checksum_relative_difference": agree,
            "members": members,
            "meets_goal": bool(c_rate_model >= GOAL),
            "every_step_meets_goal": bool(min(rates) >= GOAL)}


def render(payload: dict) -> str:
    """The figures as Markdown.

    Parameters
    ----------
    payload : dict
        From :func:`measure`.

    Returns
    -------
    str
        A table.
    """
    rows = [
        ["C hystid_model_step", f"{payload['c_model_samples_per_s']:.3g}",
         f"{payload['ratio_c_vs_python']:.2g}x numba"],
        ["numba model.simulate (same process)", f"{payload['python_simulate_samples_per_s']:.3g}",
         "1"],
        ["C hystid_rpem_step (supervised)", f"{payload['c_rpem_samples_per_s']:.3g}",
         f"{payload['c_rpem_samples_per_s'] / payload['python_rpem_samples_per_s']:.2g}x "
         "rpem_reference"],
    ]
    if "c_rpem_bare_samples_per_s" in payload:
        bare = payload["c_rpem_bare_samples_per_s"]
        rows.append(["C hystid_rpem_step, bare (HYSTID_RPEM_SUPERVISE 0)", f"{bare:.3g}",
                     f"{bare / payload['python_rpem_bare_samples_per_s']:.2g}x rpem_run"])
    names = {"gduhem": "gduhem member (generalised Duhem block)",
             "mduhem": "mduhem member (6 Duhem operators)"}
    for key, m in payload.get("members", {}).items():
        rows.append([f"C hystid_model_step, {names[key]}", f"{m['c_samples_per_s']:.3g}",
                     f"{m['ratio_c_vs_python']:.2g}x numba"])
        if "c_rpem_samples_per_s" in m:
            rows.append([f"C hystid_rpem_step (supervised), {names[key]}",
                         f"{m['c_rpem_samples_per_s']:.3g}", ""])
        if "c_rpem_bare_samples_per_s" in m:
            rows.append([f"C hystid_rpem_step, bare, {names[key]}",
                         f"{m['c_rpem_bare_samples_per_s']:.3g}", ""])
    labels = {"duhem": "reference stage (Duhem", "pi_stage": "pi-stage (PI",
              "gduhem": "gduhem member (generalised Duhem, per sample",
              "mduhem": "mduhem member (6 Duhem operators, per sample",
              "duhem_unsaturated": "reference stage, limits +-100 V: no saturation (Duhem",
              "duhem_preview_3000": "reference stage (Duhem"}
    every = {**payload["ff"], **payload.get("ff_context", {})}
    for key, ff in every.items():
        rows.append([f"C hystid_ff_step, {labels[key]}, planner {ff['planner_preview']}, "
                     f"L2 FIR {ff['l2_fir_taps']} taps, delay {ff['delay']})",
                     f"{ff['c_samples_per_s']:.3g}",
                     f"{ff['c_samples_per_s'] / ff['python_samples_per_s']:.2g}x compensate"])
    goal = "met" if payload["every_step_meets_goal"] else "NOT met"
    worst = max(ff["checksum_relative_difference"] for ff in every.values())
    worst_member = max([m["checksum_relative_difference"]
                        for m in payload.get("members", {}).values()] or [0.0])
    return (table(rows, ["step", "samples/s", "ratio"])
            + f"\n\n{payload['samples']} samples of the reference stage (the identifier and the "
              f"compensators {payload['ff']['duhem']['samples']}); goal "
              f"{payload['goal_c_samples_per_s']:.0e} C samples/s for every step: {goal}; the "
              f"sums of the C and Python outputs differ by "
              f"{payload['checksum_relative_difference']:.1e} of sum |y| for the model "
              f"({worst_member:.1e} for the gduhem and mduhem members), "
              f"{worst:.1e} of sum |u| for the compensators (the tests compare sample by "
              "sample).")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--quick", action="store_true", help="300 000 samples")
    parser.add_argument("--samples", type=int, default=None, help="samples per run")
    parser.add_argument("--out", type=Path, default=None,
                        help="JSON file (default benchmarks/results/export.json)")
    args = parser.parse_args()
    payload = measure(args.quick, args.samples)
    print(render(payload))
    if args.out is None:
        path = write_json("export", payload)
    else:
        path = args.out
        doc = {"machine": {"python": platform.python_version(), "cpu": platform.processor()},
               **payload}
        path.write_text(json.dumps(doc, indent=2))
    print(f"wrote {path}")


if __name__ == "__main__":
    main()
