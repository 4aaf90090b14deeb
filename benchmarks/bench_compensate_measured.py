"""Inverse-model check on measured stage A: the command computed for a measured displacement
against the voltage that was really applied.

The Duhem sandwich is identified on ``prbn_1`` with the defaults (``hystid identify``); for every
other record of ``../shared/data/real/stageA/`` the compensator (:func:`hystid.compensate.
compensate`, placed in the record's units, limits from the model's envelope, L2 inverted by its
stable inverse) computes the command for the record's measured displacement. Its RMS distance
to the applied voltage is set beside two linear inverses given the same desired output: the
sandwich with its hysteresis replaced by the central line (``compensation="linear"``), and the
output-error linear model of the sandwich's orders fitted on ``prbn_1`` (the baseline of
``hystid identify``), inverted by its stable inverse; and a static inverse, the least-squares
line ``y = k u + c`` fitted on ``prbn_1``, inverted (the central line passes through the
rest point; on an independently simulated stage a least-squares line's inverse tracked better
than it).

The measured displacement is asked for smoothed over ``--smooth`` samples without lag (a
Hann window; the sensor noise would otherwise dither the hysteresis inverse, which wipes the
Duhem block's memory); the raw one is reported too. Self-consistency: the model driven by its
own command reproduces the asked output (relative RMS about the rest output); ``exact`` is the
raw measured displacement with the rest anchored at its first sample (every step exact), over
the whole record and from sample ``settle`` on; ``as used`` the configuration of the command
columns (the reference starts off the model's rest, so its first samples cannot be reproduced).
``settle`` is 0 for a minimum-phase L2; with zeros outside the unit circle (the ``pi-stage``
member) L2's inverse needs pre-actuation, and what of it would fall before the record's first
sample, where the stage rests, is made up over the first ``settle`` samples: only there can the
output miss the reference (its noise moves from the second sample on).

Goals (issue 23): within 2.5 V RMS of the applied voltage and at most half the linear inverse's
error; the model reproduces the reference to 1e-6 relative where L2 is invertible (from sample
``settle`` on).

    OPENBLAS_NUM_THREADS=1 python benchmarks/bench_compensate_measured.py [--smooth 21]
        [--model auto|duhem|gduhem|pi-stage|mduhem] [--zero model|rest] [--out FILE.json]
"""

from __future__ import annotations

import argparse
import json
import warnings
from pathlib import Path

import control as ct
import numpy as np
from _common import table, write_json

from hystid.baselines import LinearModel, StaticLine
from hystid.compensate import compensate, smoothing_model, stable_inverse
from hystid.identify import identify
from hystid.records import Record, load_record

SHARED = Path(__file__).resolve().parents[2] / "shared" / "data"
STAGE_A = SHARED / "real" / "stageA"
TRAIN = "prbn_1"
HELD_OUT = ("prbn_2", "sine50_1", "sine50_2", "tri50_1", "tri50_2")
GOAL_VOLTS, GOAL_RATIO, GOAL_SELF = 2.5, 0.5, 1e-6
COMMAND = "OPENBLAS_NUM_THREADS=1 python benchmarks/bench_compensate_measured.py"


def _rms(e: np.ndarray) -> float:
    return float(np.sqrt(np.mean(np.square(e))))


def _excited(u: np.ndarray) -> int:
    """First sample where the input leaves its first value (the end of the rest)."""
    moved = np.flatnonzero(u != u[0])
    return int(moved[0]) if moved.size else 0


def linear_model_inverse(lin: LinearModel, y_des: np.ndarray, dt: float) -> np.ndarray:
    """The command a linear model needs for ``y_des`` (its stable inverse, from its rest)."""
    num, den = np.r_[np.zeros(lin.q), lin.b], np.asarray(lin.a, float)
    n = max(num.size, den.size)  # powers of z^-1 -> of z: pad both to one length
    tf = ct.tf(np.r_[num, np.zeros(n - num.size)], np.r_[den, np.zeros(n - den.size)], dt)
    w = stable_inverse(tf, y_des - lin.offset).signal
    return w + lin.u_rest


def rest_shift(model, rec) -> float:
    """How far the record's output at rest sits from the model's at the same input: the
    sensor's zero moved between records (:func:`hystid.baselines.rest_zero`, the zero every
    accuracy table of the project puts predictions on)."""
    from hystid.baselines import rest_zero, simulate_from_rest

    return rest_zero(simulate_from_rest(model, rec.u, check=False), rec)


def measure(smooth: int = 21, member: str = "auto", zero: str = "model") -> dict:
    """Identify on ``prbn_1``, compute the commands for the other records and compare.

    Parameters
    ----------
    smooth : int
        Length of the lag-free smoother the measured displacement is asked through (0: none).
    member : str
        ``model=`` of :func:`hystid.identify.identify` (``"auto"``: what ``hystid identify``
        chooses by default).
    zero : {"model", "rest"}
        ``"model"``: the measured displacement asked as recorded (the model's sensor offset
        from ``prbn_1``); ``"rest"``: less its shift at rest from the model's output there
        (:func:`rest_shift`, the sensor zero that moved between records), for every inverse.

    Returns
    -------
    dict
        Per record: RMS distances to the applied voltage (whole record and excited part) of
        the compensator, the central-line inverse and the linear model's inverse, the raw
        (unsmoothed) compensator's, the self-consistency figures and the goals met.
    """
    train = load_record(STAGE_A / f"{TRAIN}.csv")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        model = identify(train, model=member).model
    s = model.structure
    lin_model = LinearModel.fit(train, s.n1a + s.n2a, s.n1b + s.n2b, s.q1 + s.q2)
    line = StaticLine.fit(train)
    smoother = smoothing_model(smooth, model.dt) if smooth else None
    rows = []
    for name in HELD_OUT:
        rec = load_record(STAGE_A / f"{name}.csv")
        shift = rest_shift(model, rec) if zero == "rest" else 0.0
        rec = Record(rec.u, rec.y - shift, rec.fs, rec.units, rec.name)
        k0 = _excited(rec.u)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            inv = compensate(model, rec.y, reference_model=smoother)
            central = compensate(model, rec.y, reference_model=smoother, compensation="linear")
            raw = compensate(model, rec.y)
            exact = compensate(model, rec.y, anchor="reference")
        u_lin = linear_model_inverse(lin_model, inv.y_des, model.dt)
        u_line = (inv.y_des - line.offset) / line.gain  # the least-squares line, inverted
        errs = {k: rec.u - u for k, u in (("inverse", inv.u), ("central_line", central.u),
                                           ("linear_model", u_lin), ("static_line", u_line),
                                           ("inverse_raw", raw.u))}
        row = {"record": name, "rest_samples": k0, "zero_shift": shift,
               "rms_V": {k: _rms(e) for k, e in errs.items()},
               "rms_V_excited": {k: _rms(e[k0:]) for k, e in errs.items()},
               "self_relative": {"exact": exact.relative_error,
                                 "exact_settled": exact.settled_relative_error,
                                 "as_used": inv.relative_error},
               "settle": exact.settle,
               "self_miss_first_samples": float(np.max(np.abs(exact.y_pred - exact.y_des)[
                   :max(exact.settle, 1)])),
               "exact_share": float(np.mean(inv.exact)),
               "warnings": inv.warnings}
        v = row["rms_V"]
        row["ratio"] = {k: v["inverse"] / v[k]
                        for k in ("central_line", "linear_model", "static_line")}
        row["goals"] = {
            "within_2.5_V": v["inverse"] <= GOAL_VOLTS,
            "half_central_line": row["ratio"]["central_line"] <= GOAL_RATIO,
            "half_linear_model": row["ratio"]["linear_model"] <= GOAL_RATIO,
            "self_1e-6": row["self_relative"]["exact_settled"] <= GOAL_SELF,
        }
        rows.append(row)
    return {"train": TRAIN, "model": repr(model), "smooth": smooth, "zero": zero,
            "u_limits": list(inv.u_limits), "linear_model": {"a": lin_model.a.tolist(),
                                                              "b": lin_model.b.tolist(),
                                                              "q": lin_model.q},
            "goals": {"rms_V": GOAL_VOLTS, "ratio_to_linear": GOAL_RATIO,
                      "self_relative": GOAL_SELF},
            "records": rows, "command": COMMAND}


def render(payload: dict) -> str:
    """The table of :func:`measure`'s payload.

    Parameters
    ----------
    payload : dict
        Output of :func:`measure`.

    Returns
    -------
    str
        A Markdown table.
    """
    out = []
    for r in payload["records"]:
        v, ve, ratio = r["rms_V"], r["rms_V_excited"], r["ratio"]
        out.append([r["record"], f"{v['inverse']:.2f} ({ve['inverse']:.2f})",
                    f"{v['central_line']:.2f} ({ve['central_line']:.2f})",
                    f"{v['linear_model']:.2f} ({ve['linear_model']:.2f})",
                    f"{v['static_line']:.2f} ({ve['static_line']:.2f})",
                    f"{ratio['central_line']:.2f} / {ratio['linear_model']:.2f} / "
                    f"{ratio['static_line']:.2f}",
                    f"{v['inverse_raw']:.2f}",
                    f"{r['self_relative']['exact']:.1e}",
                    f"{r['self_relative']['exact_settled']:.1e} ({r['settle']})",
                    f"{r['self_relative']['as_used']:.1e}",
                    "yes" if all(r["goals"].values()) else
                    "no: " + ", ".join(k for k, ok in r["goals"].items() if not ok)])
    return table(out, ["record", "inverse: V RMS (excited part)", "central line",
                       "linear model", "static line",
                       "inverse / central line / linear model / static line",
                       "inverse, raw y", "self exact", "self exact from settle (settle)",
                       "self as used", "goals met"])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--smooth", type=int, default=21,
                        help="lag-free smoother of the measured displacement, samples (0: none)")
    parser.add_argument("--model", default="auto",
                        help="member identified on prbn_1 (default auto, as hystid identify)")
    parser.add_argument("--zero", choices=("model", "rest"), default="model",
                        help="ask the displacement as recorded (model: the offset identified "
                        "on prbn_1) or less its shift at rest (rest: the sensor zero moved)")
    parser.add_argument("--out", type=Path, default=None,
                        help="JSON file (default benchmarks/results/compensate_measured.json)")
    args = parser.parse_args()
    if not STAGE_A.exists():
        raise SystemExit(f"stage A records not found in {STAGE_A} (../shared/data)")
    payload = measure(args.smooth, args.model, args.zero)
    print(f"identified on {TRAIN}: {payload['model']}")
    print(f"command limits {payload['u_limits'][0]:.4g} .. {payload['u_limits'][1]:.4g} V "
          f"(envelope + 10 %), reference smoothed over {args.smooth} samples\n")
    print(render(payload))
    if args.out is None:
        path = write_json("compensate_measured", payload)
    else:
        path = args.out
        path.write_text(json.dumps(payload, indent=2))
    print(f"\nwritten {path}")


if __name__ == "__main__":
    main()
