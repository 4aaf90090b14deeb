"""Tracking with the compensators: feed-forward inverse, feedback designs, robustness.

The controllers are built from a model identified on 0.1 s of noisy reference-stage data
(``fit_output_error(reference_record(0.1 s, seed=0))``) and drive the true reference stage
(``reference_model()``), as in notebooks 2 and 3:

* tracking: triangle and sine scans over 1-8 um at 10, 50 and 200 Hz, with no compensation
  (``hc.linear_feedforward``: L1 and L2 inverted, the hysteresis replaced by its central line),
  the feed-forward inverse, feedback only (integral + notch, ``hc.design_feedback``) and both;
  maximum / RMS error and the loop width left over the second period (``out.metrics``); and the
  triangles again with a smoothed reference (corners rounded over 7 samples) and the dynamic L2
  inverse;
* feedback designs: integral + notch, a wide notch, and PI + notch (``pi_zero`` 3 and 5), their
  crossover, margins and tracking with the feed-forward inverse;
* robustness: the integral + notch and the wide-notch designs on eight stages whose physical
  parameters differ by +-20 % from the identified ones (``hc.perturbed_stage``: all +20 %, all
  -20 %, six mixed corners drawn from seed 2024), their margins (``hc.margins_on``) and the
  tracking of 50 Hz scans over 1-6 um with the wide notch.

Usage: python benchmarks/bench_tracking.py [--quick]
"""

from __future__ import annotations

import argparse
import warnings

import numpy as np
from _common import table, write_json

import hystid.compensate as hc
from hystid.identify import fit_output_error
from hystid.reference import reference_model, reference_record

#: The README blocks this script renders (see ``benchmarks/readme.py``).
README_BLOCKS = {"feedback-designs": "render_designs", "tracking": "render_tracking",
                 "robustness": "render_robustness"}
COMMAND = "OPENBLAS_NUM_THREADS=1 python benchmarks/bench_tracking.py"

SCANS = tuple((kind, f) for kind in ("triangle", "sine") for f in (10.0, 50.0, 200.0))
#: configuration -> (feedforward, with the feedback design)
CONFIGS = {"none": ("linear", False), "feed-forward inverse": (True, False),
           "feedback only": (False, True), "both": (True, True)}
#: design label -> design_feedback keywords
DESIGNS = {"integral + notch": {}, "wide notch": {"notch_width": 0.3, "notch_damping": 1.0},
           "PI + notch, pi_zero=3": {"pi_zero": 3.0}, "PI + notch, pi_zero=5": {"pi_zero": 5.0}}
DESIGN_SCANS = (("triangle", 50.0), ("sine", 200.0))
SMOOTHING_SAMPLES = 7
ROBUST_HIGH, ROBUST_FREQUENCY, ROBUST_SEED, ROBUST_MIXED = 6.0, 50.0, 2024, 6


def identified_model():
    """The model the controllers are built from: 0.1 s of noisy reference-stage data."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return fit_output_error(reference_record(seconds=0.1, seed=0)).model


def _figures(m: hc.TrackingMetrics) -> dict[str, float]:
    """Tracking figures in nm."""
    return {"max_nm": 1e3 * m.max_error, "rms_nm": 1e3 * m.rms_error,
            "width_nm": 1e3 * m.loop_width}


def _run(model, ref, config: str, design, plant, **kw) -> hc.TrackingMetrics:
    ff, fb = CONFIGS[config]
    out = hc.simulate_closed_loop(model, ref.y, design if fb else None, feedforward=ff,
                                  plant=plant, **kw)
    return out.metrics(ref.skip)


# ---------------------------------------------------------------------------------------------
# the measurements


def measure_designs(model, stage) -> dict[str, dict]:
    """Each design of :data:`DESIGNS`: gains, crossover, margins, tracking with feed-forward.

    Parameters
    ----------
    model : DuhemSandwich
        The identified model the designs are made on.
    stage : DuhemSandwich
        The stage driven.

    Returns
    -------
    dict
        Label -> ``ki``, ``kp``, ``crossover_hz``, ``phase_margin_deg``, ``gain_margin_db`` and,
        per scan of :data:`DESIGN_SCANS`, ``"{kind}_{f}_max_rms_nm"``: [max, RMS] in nm.
    """
    out = {}
    for label, kw in DESIGNS.items():
        design = hc.design_feedback(model, **kw)
        figures = {"ki": design.ki, "kp": design.kp, "crossover_hz": design.crossover_hz,
                   "phase_margin_deg": design.phase_margin,
                   "gain_margin_db": design.gain_margin_db}
        for kind, f in DESIGN_SCANS:
            m = _run(model, hc.scan_reference(kind, f), "both", design, stage)
            figures[f"{kind}_{f:g}_max_rms_nm"] = [1e3 * m.max_error, 1e3 * m.rms_error]
        out[label] = figures
    return out


def measure_tracking(model, stage, design, scans=SCANS) -> list[dict]:
    """The four configurations on every scan.

    Parameters
    ----------
    model, stage : DuhemSandwich
        Identified model and the stage driven.
    design : FeedbackDesign
        The feedback of "feedback only" and "both".
    scans : sequence of (kind, frequency)

    Returns
    -------
    list of dict
        ``kind``, ``frequency``, ``config``, ``max_nm``, ``rms_nm``, ``width_nm``.
    """
    rows = []
    for kind, f in scans:
        ref = hc.scan_reference(kind, f)
        for config in CONFIGS:
            rows.append({"kind": kind, "frequency": f, "config": config,
                         **_figures(_run(model, ref, config, design, stage))})
    return rows


def measure_smoothed(model, stage, frequencies=(10.0, 50.0)) -> list[dict]:
    """Triangles: max error without and with the inverse, static vs smoothed + dynamic L2 inverse.

    Parameters
    ----------
    model, stage : DuhemSandwich
    frequencies : sequence of float

    Returns
    -------
    list of dict
        ``frequency``, ``l2_inverse`` ("static" or "smoothed + dynamic"), ``none_max_nm``,
        ``inverse_max_nm`` (against the reference) and ``inverse_max_to_yd_nm`` (against the
        smoothed reference the compensator aims at).
    """
    rows = []
    smoothing = hc.smoothing_model(SMOOTHING_SAMPLES, model.dt)
    for f in frequencies:
        ref = hc.scan_reference("triangle", f)
        for label, ref_model in (("static", None), ("smoothed + dynamic", smoothing)):
            runs = {ff: hc.simulate_closed_loop(model, ref.y, None, feedforward=ff, plant=stage,
                                                reference_model=ref_model)
                    for ff in ("linear", True)}
            rows.append({"frequency": f, "l2_inverse": label,
                         "none_max_nm": 1e3 * runs["linear"].metrics(ref.skip).max_error,
                         "inverse_max_nm": 1e3 * runs[True].metrics(ref.skip).max_error,
                         "inverse_max_to_yd_nm":
                             1e3 * runs[True].metrics(ref.skip, against="yd").max_error})
    return rows


def perturbed_cases(seed: int = ROBUST_SEED, mixed: int = ROBUST_MIXED) -> dict[str, dict]:
    """The corners of the +-20 % box: all up, all down, and ``mixed`` drawn from ``seed``."""
    names = hc.PERTURBABLE
    cases = {"all +20 %": dict.fromkeys(names, 1.2), "all -20 %": dict.fromkeys(names, 0.8)}
    rng = np.random.default_rng(seed)
    for i in range(mixed):
        cases[f"mixed {i + 1}"] = dict(zip(names, map(float, rng.choice([0.8, 1.2], len(names))),
                                           strict=True))
    return cases


def measure_robustness(model, quick: bool = False) -> dict:
    """Margins of two designs and tracking with the wide notch on the perturbed stages.

    Parameters
    ----------
    model : DuhemSandwich
        The identified model (the designs are made on it; the stages are perturbed from it).
    quick : bool
        The two uniform corners only (no mixed ones).

    Returns
    -------
    dict
        ``cases`` (stage -> factors), ``margins`` (one row per stage and design) and
        ``tracking`` (per scan, configuration and stage: max, RMS, loop width in nm).
    """
    designs = {"integral + notch": hc.design_feedback(model),
               "wide notch": hc.design_feedback(model, **DESIGNS["wide notch"])}
    cases = perturbed_cases(mixed=0 if quick else ROBUST_MIXED)
    stages = {"identified": model, **{n: hc.perturbed_stage(model, f) for n, f in cases.items()}}
    margins = []
    for name, stage in stages.items():
        for label, design in designs.items():
            m = hc.margins_on(design, stage)
            margins.append({"stage": name, "design": label, "stable": m.stable,
                            "gain_margin_db": m.gain_margin_db, "phase_margin_deg": m.phase_margin})
    tracking = []
    for kind in ("triangle", "sine"):
        ref = hc.scan_reference(kind, ROBUST_FREQUENCY, high=ROBUST_HIGH)
        for config in CONFIGS:
            for name, stage in stages.items():
                m = _run(model, ref, config, designs["wide notch"], stage)
                tracking.append({"kind": kind, "config": config, "stage": name, **_figures(m)})
    return {"cases": cases, "margins": margins, "tracking": tracking,
            "frequency": ROBUST_FREQUENCY, "high": ROBUST_HIGH}


def measure(quick: bool = False) -> dict:
    """Every figure of the three README blocks, from one identified model.

    Parameters
    ----------
    quick : bool
        The 50 Hz scans only and the two uniform corners of the robustness study.

    Returns
    -------
    dict
        ``flexure_hz`` (the identified flexure mode), ``designs`` (:func:`measure_designs`),
        ``tracking`` (:func:`measure_tracking`),
        ``smoothed`` (:func:`measure_smoothed`), ``robustness`` (:func:`measure_robustness`).
    """
    stage, model = reference_model(), identified_model()
    design = hc.design_feedback(model)
    scans = tuple(s for s in SCANS if s[1] == 50.0) if quick else SCANS
    return {"quick": quick, "flexure_hz": hc.flexure_mode(model)[0],
            "designs": measure_designs(model, stage),
            "tracking": measure_tracking(model, stage, design, scans),
            "smoothed": measure_smoothed(model, stage, (50.0,) if quick else (10.0, 50.0)),
            "robustness": measure_robustness(model, quick)}


# ---------------------------------------------------------------------------------------------
# the README's blocks


def _nm(x: float) -> str:
    """A figure in nm: three significant digits, no powers of ten."""
    return "nan" if not np.isfinite(x) else f"{x:.3g}" if abs(x) < 1000 else f"{x:.0f}"


def _cell(row: dict) -> str:
    return f"{_nm(row['max_nm'])} / {_nm(row['rms_nm'])}, {_nm(row['width_nm'])}"


def _design_scans(figures: dict) -> list[str]:
    return [" / ".join(_nm(x) for x in figures[f"{kind}_{f:g}_max_rms_nm"])
            for kind, f in DESIGN_SCANS]


def render_designs(payload: dict) -> str:
    """The feedback designs: gains, crossover, margins and tracking (Markdown).

    Parameters
    ----------
    payload : dict
        What :func:`measure` returns.

    Returns
    -------
    str
    """
    designs = payload["designs"]
    rows = [[label, f"{d['kp']:.2g}", f"{d['crossover_hz']:.0f}", f"{d['phase_margin_deg']:.0f}",
             f"{d['gain_margin_db']:.1f}", *_design_scans(d)] for label, d in designs.items()]
    out = table(rows, ["design", "kp [V/um]", "crossover [Hz]", "phase margin [deg]",
                       "gain margin [dB]",
                       *(f"{k} {f:g} Hz with feed-forward: max / RMS [nm]"
                         for k, f in DESIGN_SCANS)])
    base, wide = designs["integral + notch"], designs["wide notch"]
    pi5 = designs["PI + notch, pi_zero=5"]
    (b_max, b_rms), (p_max, p_rms) = (base["sine_200_max_rms_nm"], pi5["sine_200_max_rms_nm"])
    verb = "falls" if p_rms < b_rms else "rises"
    tri_b, tri_p = base["triangle_50_max_rms_nm"], pi5["triangle_50_max_rms_nm"]
    out += "\n\n"
    if "flexure_hz" in payload:
        out += (f"The notch sits on the identified flexure mode, "
                f"{payload['flexure_hz'] / 1e3:.2f} kHz. ")
    out += (f"The wide notch trades bandwidth ({wide['crossover_hz']:.0f} Hz against "
            f"{base['crossover_hz']:.0f} Hz) for margins ({wide['phase_margin_deg']:.0f} deg, "
            f"{wide['gain_margin_db']:.1f} dB). With the proportional part (`pi_zero=5`, `kp` = "
            f"{pi5['kp']:.2g} V/um) the crossover moves to {pi5['crossover_hz']:.0f} Hz and, with "
            f"the feed-forward inverse, the 200 Hz sine's error {verb} from {_nm(b_max)} / "
            f"{_nm(b_rms)} to {_nm(p_max)} / {_nm(p_rms)} nm (max / RMS; 50 Hz triangle "
            f"{_nm(tri_p[0])} / {_nm(tri_p[1])} against {_nm(tri_b[0])} / {_nm(tri_b[1])} nm).")
    return out


def _find(rows: list[dict], **keys) -> dict:
    return next(r for r in rows if all(r[k] == v for k, v in keys.items()))


def render_tracking(payload: dict) -> str:
    """The tracking table and the sentences that quote it (Markdown).

    Parameters
    ----------
    payload : dict
        What :func:`measure` returns.

    Returns
    -------
    str
    """
    rows, scans = payload["tracking"], []
    for r in rows:
        if (r["kind"], r["frequency"]) not in scans:
            scans.append((r["kind"], r["frequency"]))
    body = [[f"{kind} {f:g} Hz",
             *(_cell(_find(rows, kind=kind, frequency=f, config=c)) for c in CONFIGS)]
            for kind, f in scans]
    out = table(body, ["scan", *CONFIGS])

    def cut(kind, f):
        none = _find(rows, kind=kind, frequency=f, config="none")["max_nm"]
        return none / _find(rows, kind=kind, frequency=f, config="feed-forward inverse")["max_nm"]

    sentences = []
    if ("triangle", 10.0) in scans:
        sentences.append(f"The feed-forward inverse cuts the maximum tracking error "
                         f"{cut('triangle', 10.0):.0f}x on the 10 Hz triangle.")
    smooth = {(r["frequency"], r["l2_inverse"]): r["none_max_nm"] / r["inverse_max_nm"]
              for r in payload["smoothed"]}
    if (50.0, "static") in smooth:
        text = (f"On the 50 Hz triangle the static L2 inverse gives {smooth[50.0, 'static']:.2g}x "
                f"(the flexure's lag, not the hysteresis, is what is left); with a smoothed "
                f"reference (corners rounded over {SMOOTHING_SAMPLES} samples) and the dynamic "
                f"L2 inverse the cut is {smooth[50.0, 'smoothed + dynamic']:.0f}x")
        if (10.0, "smoothed + dynamic") in smooth:
            text += f" ({smooth[10.0, 'smoothed + dynamic']:.0f}x at 10 Hz)"
        sentences.append(text + ".")
    fast = [s for s in scans if s[1] == 200.0]
    if fast:
        cuts = [cut(*s) for s in fast]
        fb_worse = all(_find(rows, kind=k, frequency=f, config="feedback only")["max_nm"]
                       > _find(rows, kind=k, frequency=f, config="none")["max_nm"]
                       for k, f in fast)
        crossover = payload["designs"]["integral + notch"]["crossover_hz"]
        sentences.append(
            f"At 200 Hz the inverse still gains {min(cuts):.1f}-{max(cuts):.1f}x; feedback alone "
            f"is {'worse than nothing' if fb_worse else 'not always worse than nothing'} there, "
            f"the loop's crossover being {crossover:.0f} Hz.")
    return out + "\n\n" + " ".join(sentences)


def _span(values: list[float]) -> str:
    lo, hi = min(values), max(values)
    return f"{lo:.0f}" if round(lo) == round(hi) else f"{lo:.0f}-{hi:.0f}"


def render_robustness(payload: dict) -> str:
    """Tracking on the perturbed stages and the margins the two designs keep (Markdown).

    Parameters
    ----------
    payload : dict
        What :func:`measure` returns.

    Returns
    -------
    str
    """
    rob = payload["robustness"]
    n = len(rob["cases"])
    body, both_med, both_worst = [], [], []
    for kind in ("triangle", "sine"):
        for config in CONFIGS:
            runs = [r for r in rob["tracking"] if r["kind"] == kind and r["config"] == config]
            nominal = next(r for r in runs if r["stage"] == "identified")
            pert = [r for r in runs if r["stage"] != "identified"]
            cells = [f"{kind} {rob['frequency']:g} Hz", config, _nm(nominal["rms_nm"])]
            for key in ("rms_nm", "max_nm", "width_nm"):
                v = np.array([r[key] for r in pert])
                cells.append(f"{_nm(float(np.median(v)))} / {_nm(float(v.max()))}")
                if config == "both" and key == "rms_nm":
                    both_med.append(float(np.median(v)))
                    both_worst.append(float(v.max()))
            body.append(cells)
    out = table(body, ["scan (1-6 um)", "configuration", "RMS, identified stage [nm]",
                       f"RMS, median / worst of {n} [nm]", f"max, median / worst of {n} [nm]",
                       f"loop width, median / worst of {n} [nm]"])
    out += (f"\n\nFeed-forward + feedback (wide notch) stays at {_span(both_med)} nm RMS over the "
            f"{n} perturbed stages (median; worst {_span(both_worst)} nm).")
    for label in ("integral + notch", "wide notch"):
        pert = [m for m in rob["margins"] if m["design"] == label and m["stage"] != "identified"]
        unstable = [m["stage"] for m in pert if not m["stable"]]
        gm = min(m["gain_margin_db"] for m in pert)
        pm = min(m["phase_margin_deg"] for m in pert)
        weak = sum(m["gain_margin_db"] < 1.0 for m in pert)
        text = (f" The {label} design keeps every perturbed loop stable" if not unstable else
                f" The {label} design leaves {len(unstable)} of the {n} loops unstable "
                f"({', '.join(unstable)})")
        text += f"; its smallest gain margin is {gm:.1f} dB, its smallest phase margin {pm:.0f} deg"
        if weak:
            text += f" ({weak} of the {n} stages below 1 dB of gain margin)"
        out += text + "."
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--quick", action="store_true",
                        help="50 Hz scans only, two perturbed stages")
    args = parser.parse_args()
    payload = measure(args.quick)
    for render in (render_designs, render_tracking, render_robustness):
        print(render(payload), end="\n\n")
    print(f"wrote {write_json('tracking', payload)}")


if __name__ == "__main__":
    main()
