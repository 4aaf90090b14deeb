"""The paper's comparison: Duhem sandwich vs Prandtl-Ishlinskii sandwich, side by side.

On the same records, for each model and identifier: samples to convergence (stop index 1e-4,
:func:`hystid.identify.result.converged_at`), free-run validation error range and RMS, number
of parameters and identification time per sample (and its ratio to the Duhem on-line
identifier, run in the same process).

Records
-------
* reference stage: identification on ``reference_record(1 s, seed=0)`` (30 kHz, 1 nm noise),
  validation on a fresh excitation (``seed=1``) simulated from rest; the first 0.0017 s of the
  validation are dropped, as in the paper.
* measured piezo (``../shared/data/real/piezo_sine_150V_1Hz``, 5 kHz, +-150 V, 1 Hz): the
  record from ``START`` (at rest, 286 samples before the sine) is cut into an identification
  part (the first ``TRAIN`` samples, 3 periods) and a validation part (the rest, 3.7 periods).
  Each identified model is simulated from rest over the whole record from ``START`` (so that the
  hysteresis memory is right) and the error is taken on the validation part only. The output is
  used as measured: its loop is symmetric about 0 (-2.98 / +2.79 um at 0 V), while the value at
  rest before the sine (-1.68 um) is a remanent state that models starting at rest do not have
  (subtracting it would shift the whole loop).
  The Duhem block sees the input as it is: the sine starts with a jump of 87 V, and condition (8)
  ``alpha |dw1| < 2`` is invariant under a scaling of the input (``alpha, f1, g0`` scale
  inversely), so scaling cannot help; the identified ``alpha`` is small enough and the margin
  ``alpha max|dw1|`` is printed.

Usage: python benchmarks/bench_pi_vs_duhem.py [--quick] [--only reference|real]
"""

from __future__ import annotations

import argparse
import time
import warnings
from pathlib import Path

import numpy as np
from _common import table, write_json

from hystid.identify import identify
from hystid.identify.pi_recursive import identify_pi
from hystid.metrics import validate
from hystid.records import Record, load_piezo_sine_150v
from hystid.reference import reference_record

#: The README blocks this script renders (see ``benchmarks/readme.py``).
README_BLOCKS = {"pi-vs-duhem": "render", "pi-vs-duhem-shows": "render_shows"}
COMMAND = "OPENBLAS_NUM_THREADS=1 python benchmarks/bench_pi_vs_duhem.py"

REAL = (Path(__file__).resolve().parents[2] / "shared" / "data" / "real" / "piezo_sine_150V_1Hz"
        / "hysteresis_v_150_1hz.csv")
START, TRAIN = 16_000, 15_000
PAPER = {
    "duhem": {"converged_at": 400, "err_min": -0.059, "err_max": 0.089, "n_params": 6},
    "pi": {"converged_at": 2698, "err_min": -0.162, "err_max": 0.198},
}


def _methods(quick: bool) -> list[tuple[str, str, str, callable]]:
    """(model, key, label, identify(record) -> result) in table order."""
    rows = [
        ("duhem", "online", "on-line (RPEM, warm start)",
         lambda rec: identify(rec, method="online", model="duhem")),
        ("pi", "recursive", "recursive (output error, warm start)",
         lambda rec: identify_pi(rec, method="recursive")),
        ("pi", "paper-key-term", "paper-like: key-term, P0=1e6, theta0=1e-3, rho=(k+1)^-9/13",
         lambda rec: identify_pi(rec, method="recursive", form="key-term", warmup=0,
                                 gamma=9 / 13)),
        ("pi", "cold-start", "output error, cold start P0=1e6, theta0=1e-3",
         lambda rec: identify_pi(rec, method="recursive", warmup=0)),
    ]
    if not quick:
        rows += [
            ("duhem", "batch", "off-line output error (reference)",
             lambda rec: identify(rec, method="batch", model="duhem")),
            ("pi", "batch", "off-line output error (reference)",
             lambda rec: identify_pi(rec, method="batch")),
        ]
    return rows


def reference_case(quick: bool):
    """Identification and validation records of the reference stage."""
    train = reference_record(0.3 if quick else 1.0, seed=0, noise=1e-3)
    val = reference_record(0.2 if quick else 0.5, seed=1, noise=1e-3, name="validation")

    def simulate(model):
        return val.y, model.simulate(val.u).y, val.fs

    return train, simulate


def real_case(quick: bool):
    """Identification part of the measured piezo record and a validation function."""
    rec = load_piezo_sine_150v(REAL)
    first = int(np.flatnonzero(rec.u != 0)[0])
    offset = float(np.mean(rec.y[:first]))
    u, y = rec.u[START:], rec.y[START:]
    train_n = 5_000 if quick else TRAIN
    val_end = train_n + (5_000 if quick else len(u) - train_n)
    train = Record(u=u[:train_n], y=y[:train_n], fs=rec.fs, units=rec.units,
                   name="piezo 150 V (identification part)")

    def simulate(model):
        yhat = model.simulate(u[:val_end]).y
        return y[train_n:val_end], yhat[train_n:], rec.fs

    return train, simulate, offset


#: Samples of the untimed first call of each identifier (compiles its kernels).
WARM_UP = 2_000
_warm: set[tuple[str, str]] = set()


def _warm_up(model_kind: str, key: str, fn, train: Record) -> None:
    """Call an identifier once on a short record, so that its time excludes compilation."""
    if (model_kind, key) in _warm:
        return
    _warm.add((model_kind, key))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        try:
            fn(train[:WARM_UP])
        except Exception:  # noqa: BLE001 - only the compilation matters here
            pass


def run_case(name: str, train: Record, simulate, quick: bool) -> list[dict]:
    """Identify with every identifier on ``train``, validate through ``simulate``."""
    out = []
    for model_kind, key, label, fn in _methods(quick):
        _warm_up(model_kind, key, fn, train)
        t0 = time.perf_counter()
        try:
            res = fn(train)
        except Exception as err:  # noqa: BLE001 - a failing identifier is a result to report
            out.append({"record": name, "model": model_kind, "key": key, "method": label,
                        "error": f"{type(err).__name__}: {err}"})
            continue
        seconds = time.perf_counter() - t0
        y, yhat, fs = simulate(res.model)
        finite = bool(np.all(np.isfinite(yhat)))
        v = validate(y, np.nan_to_num(yhat, nan=0.0, posinf=0.0, neginf=0.0), fs)
        row = {
            "record": name, "model": model_kind, "key": key, "method": label,
            "output_span": float(np.ptp(y)),
            "converged_at": res.converged_at, "samples": train.n,
            "converged_at_norm": norm_converged_at(res.history),
            "n_params": len(res.model.theta),
            "seconds": seconds, "us_per_sample": 1e6 * seconds / train.n,
            "validation": v.to_dict(), "finite": finite,
            "stable": bool(res.model.is_stable()),
        }
        if "warmup_seconds" in res.info:
            n_rec = train.n - res.info["warmup_samples"]
            row["warmup_samples"] = res.info["warmup_samples"]
            row["us_per_sample_recursion"] = (
                1e6 * (seconds - res.info["warmup_seconds"]) / max(n_rec, 1))
        if model_kind == "duhem":
            sim = res.model.simulate(train.u)
            row["duhem_margin"] = float(res.model.params["alpha"] * sim.duhem_margin)
        out.append(row)
    return out


def norm_converged_at(history: np.ndarray | None, epsilon: float = 1e-4) -> int | None:
    """First sample after which ``||theta(k) - theta(k-1)|| / ||theta(k)||`` stays within epsilon.

    A vector reading of the stop index, next to the project's per-parameter one
    (:func:`hystid.identify.result.converged_at`), which no estimate with a parameter near zero
    can meet.
    """
    if history is None or len(history) < 2:
        return None
    h = np.asarray(history, float)
    change = np.linalg.norm(np.diff(h, axis=0), axis=1) / np.maximum(
        np.linalg.norm(h[1:], axis=1), 1e-300)
    above = np.flatnonzero(~(change <= epsilon))
    if len(above) == 0:
        return 0
    k = int(above[-1]) + 1
    return k if k < len(h) - 1 else None


def _fmt_conv(row, key="converged_at"):
    if row.get("samples") is None:
        return ""
    if row.get(key) is None:
        return f"not within {row['samples']}"
    return str(row[key])


def print_table(rows: list[dict]) -> None:
    """Print every row with both readings of the stop index and the time after the warm-up."""
    base = _baseline_times(rows)
    body = []
    for r in rows:
        if "error" in r:
            body.append([r["record"], r["model"], r["method"], "failed: " + r["error"][:60],
                         "", "", "", "", "", "", ""])
            continue
        v = r["validation"]
        ratio = r["us_per_sample"] / base[r["record"]] if r["record"] in base else float("nan")
        rec_only = r.get("us_per_sample_recursion")
        body.append([
            r["record"], r["model"], r["method"], _fmt_conv(r), _fmt_conv(r, "converged_at_norm"),
            f"{v['err_min']:.3g} .. {v['err_max']:.3g}", f"{v['rms']:.3g}", r["n_params"],
            f"{r['us_per_sample']:.1f}", "" if rec_only is None else f"{rec_only:.1f}",
            f"{ratio:.2f}",
        ])
    print(table(body, ["record", "model", "identifier", "converged (each param)",
                       "converged (norm)", "validation error [um]", "RMS [um]", "params",
                       "us/sample", "us/sample after warm-up", "time vs Duhem on-line"]))


# ---------------------------------------------------------------------------------------------
# measurement and the README's blocks


def measure(quick: bool = False, only: str | None = None) -> dict:
    """Identify both sandwiches with every identifier on both records and validate them.

    Parameters
    ----------
    quick : bool
        Short records, no off-line rows.
    only : {"reference", "real"}, optional
        One record only.

    Returns
    -------
    dict
        ``quick``, ``paper`` (the paper's figures), ``notes`` and ``rows`` (one dict per record
        and identifier: convergence, validation figures, parameters, seconds).
    """
    rows: list[dict] = []
    notes: dict = {}
    if only != "real":
        train, simulate = reference_case(quick)
        rows += run_case("reference stage", train, simulate, quick)
    if only != "reference":
        if REAL.exists():
            train, simulate, offset = real_case(quick)
            notes["real_output_at_rest_um"] = offset
            rows += run_case("piezo 150 V", train, simulate, quick)
        else:
            notes["real"] = f"skipped: {REAL} not found"
    return {"quick": quick, "paper": PAPER, "notes": notes, "rows": rows}


NAMES = {("duhem", "online"): "Duhem, on-line", ("duhem", "batch"): "Duhem, off-line",
         ("pi", "recursive"): "PI, recursive (warm start)",
         ("pi", "paper-key-term"): "PI, paper's cold start (key-term)",
         ("pi", "cold-start"): "PI, cold start (output error)", ("pi", "batch"): "PI, off-line"}
PHRASES = {("duhem", "online"): "on-line Duhem sandwich",
           ("duhem", "batch"): "off-line Duhem sandwich",
           ("pi", "recursive"): "recursive PI sandwich (warm start)",
           ("pi", "paper-key-term"): "PI sandwich from the paper's cold start",
           ("pi", "cold-start"): "PI sandwich from a cold start",
           ("pi", "batch"): "off-line PI sandwich"}


def _baseline_times(rows: list[dict]) -> dict[str, float]:
    """Per record, the Duhem on-line identifier's time per sample (the ratios' baseline)."""
    return {r["record"]: r["us_per_sample"] for r in rows
            if r["model"] == "duhem" and r.get("key") == "online" and "error" not in r}


def _num(x: float) -> str:
    """A figure for the tables: three significant digits, powers of ten when huge."""
    if not np.isfinite(x):
        return str(x)
    if abs(x) >= 1e4:
        return f"{x:.0e}".replace("e+", "e")
    return f"{x:.0f}" if abs(x) >= 1e3 else f"{x:.3g}"


def _int(n: int) -> str:
    """A count with thin spaces between thousands (``29 967``)."""
    return f"{n:,}".replace(",", " ")


def diverged(row: dict) -> bool:
    """A model whose free run leaves the record: not finite, or an RMS error above its span."""
    return "error" not in row and (not row["finite"]
                                   or row["validation"]["rms"] > row["output_span"])


def _find(rows: list[dict], record: str, model: str, key: str) -> dict | None:
    for r in rows:
        if (r["record"], r["model"], r.get("key")) == (record, model, key) and "error" not in r:
            return r
    return None


def render(payload: dict) -> str:
    """The comparison table (Markdown): the paper's figures, then every measured row.

    Parameters
    ----------
    payload : dict
        What :func:`measure` returns.

    Returns
    -------
    str
    """
    paper = payload["paper"]
    body = [["paper", "Duhem, ERIA", paper["duhem"]["converged_at"],
             f"{paper['duhem']['err_min']} .. {paper['duhem']['err_max']}", "-",
             paper["duhem"]["n_params"], "-", "-"],
            ["paper", "PI, recursive", _int(paper["pi"]["converged_at"]),
             f"{paper['pi']['err_min']} .. {paper['pi']['err_max']}", "-", "41 weights + 8",
             "-", "-"]]
    base = _baseline_times(payload["rows"])
    for r in payload["rows"]:
        name = NAMES.get((r["model"], r.get("key")), f"{r['model']}, {r['method']}")
        if "error" in r:
            body.append([r["record"], name, "failed: " + r["error"][:60], "", "", "", "", ""])
            continue
        v = r["validation"]
        if r.get("key") == "batch":
            conv = "-"
        elif r["converged_at"] is None:
            conv = f"not within {_int(r['samples'])}"
        else:
            conv = _int(r["converged_at"])
        if diverged(r):
            conv += ", yet diverged" if r["converged_at"] is not None else ", diverged"
        ratio = r["us_per_sample"] / base[r["record"]] if r["record"] in base else float("nan")
        body.append([r["record"], name, conv, f"{_num(v['err_min'])} .. {_num(v['err_max'])}",
                     _num(v["rms"]), r["n_params"], _num(r["us_per_sample"]),
                     f"{ratio:.2g}"])
    out = table(body, ["record", "model, identifier", "converged (stop index 1e-4)",
                       "validation error [um]", "RMS [um]", "parameters", "us / sample",
                       "time vs Duhem on-line"])
    if "real" in payload["notes"]:
        out += f"\n\nMeasured piezo record {payload['notes']['real']}."
    return out


def _reference_sentence(rows: list[dict]) -> str | None:
    rec = "reference stage"
    d_on, d_off = _find(rows, rec, "duhem", "online"), _find(rows, rec, "duhem", "batch")
    pis = [r for r in rows if r["record"] == rec and r["model"] == "pi"
           and "error" not in r and not diverged(r)]
    if d_on is None or not pis:
        return None
    best = min(pis, key=lambda r: r["validation"]["rms"])
    pi_rec = _find(rows, rec, "pi", "recursive")
    d_rms = d_on["validation"]["rms"]
    ratio = best["validation"]["rms"] / d_rms
    text = (f"On the reference stage, which *is* a Duhem sandwich, the Duhem on-line estimate "
            f"validates at {d_rms:.2g} um RMS (the record's noise is 0.001 um)")
    if d_off is not None:
        text += f", the off-line fit at {d_off['validation']['rms']:.2g} um"
    text += (f"; the best PI sandwich (the {PHRASES[('pi', best['key'])]}) at "
             f"{best['validation']['rms']:.2g} um RMS, {ratio:.0f}x "
             f"{'more' if ratio > 1 else 'less'}, with {best['n_params']} parameters against "
             f"{d_on['n_params']}.")
    if pi_rec is not None:
        conv = (f"not within its {_int(pi_rec['samples'])} samples"
                if pi_rec["converged_at"] is None else f"at sample {_int(pi_rec['converged_at'])}")
        d_conv = ("not within its samples" if d_on["converged_at"] is None
                  else f"at sample {_int(d_on['converged_at'])}")
        text += (f" The Duhem on-line identifier meets the stop index {d_conv}, the recursive PI "
                 f"identifier {conv}.")
    return text


def _piezo_sentences(rows: list[dict]) -> list[str]:
    rec = "piezo 150 V"
    ok = [r for r in rows if r["record"] == rec and "error" not in r and not diverged(r)]
    if not ok:
        return []
    best = min(ok, key=lambda r: r["validation"]["rms"])
    out = [f"On the measured piezo (+-150 V, 1 Hz, +-19.7 um; 3.7 held-out periods) the "
           f"{PHRASES[(best['model'], best['key'])]} validates best, at "
           f"{best['validation']['rms']:.2g} um RMS with {best['n_params']} parameters"]
    others = [r for r in ok if r is not best and r.get("key") in ("batch", "recursive")]
    if others:
        out[0] += "; " + ", ".join(f"{PHRASES[(r['model'], r['key'])]} {r['validation']['rms']:.2g}"
                                   f" um ({r['n_params']} parameters)" for r in others)
    out[0] += "."
    d_on, d_off = _find(rows, rec, "duhem", "online"), _find(rows, rec, "duhem", "batch")
    if d_on is not None and d_off is not None:
        verdict = ("use the batch fit" if d_off["validation"]["rms"] < d_on["validation"]["rms"]
                   else "the on-line estimate is as good as the batch fit")
        out.append(f"The Duhem on-line estimate there validates at {d_on['validation']['rms']:.2g}"
                   f" um RMS against {d_off['validation']['rms']:.2g} um off-line, and its alpha "
                   f"max|dw1| reaches {d_on['duhem_margin']:.3g} over the identification part "
                   f"(condition 8 asks < 2) against {d_off['duhem_margin']:.2g} off-line: on this "
                   f"record, {verdict}.")
    return out


def _paper_settings_sentence(rows: list[dict]) -> str | None:
    parts = []
    for key, what in (("cold-start", "the output-error recursion"),
                      ("paper-key-term", "the key-term recursion with the paper's gain rho")):
        cases = [(r["record"], r) for r in rows if r.get("key") == key and "error" not in r]
        if not cases:
            continue
        said = [f"{'diverges' if diverged(r) else 'stays finite'} on the {rec} "
                f"({_num(r['validation']['rms'])} um RMS)" for rec, r in cases]
        parts.append(f"{what} " + " and ".join(said))
    if not parts:
        return None
    return ("Started cold with the paper's PI settings (P(0) = 1e6 I, theta(0) = 0.001), "
            + "; ".join(parts) + ".")


def _stop_index_sentence(rows: list[dict]) -> str | None:
    fooled = [r for r in rows if diverged(r) and r.get("converged_at") is not None]
    if not fooled:
        return None
    r = max(fooled, key=lambda r: r["validation"]["rms"])
    return (f"\"Converged\" by the stop index alone says little: the "
            f"{PHRASES[(r['model'], r['key'])]} on the {r['record']} meets it at sample "
            f"{_int(r['converged_at'])} with a model {_num(r['validation']['rms'])} um RMS off.")


def render_shows(payload: dict) -> str:
    """What the comparison shows, as generated bullets (Markdown).

    Parameters
    ----------
    payload : dict
        What :func:`measure` returns.

    Returns
    -------
    str
    """
    rows = payload["rows"]
    found = [_reference_sentence(rows), *_piezo_sentences(rows), _paper_settings_sentence(rows),
             _stop_index_sentence(rows)]
    return "\n".join(f"* {s}" for s in found if s)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--quick", action="store_true", help="short records, no off-line rows")
    parser.add_argument("--only", choices=("reference", "real"), help="run one record only")
    args = parser.parse_args()
    payload = measure(args.quick, args.only)
    if "real" in payload["notes"]:
        print(f"measured record {payload['notes']['real']}")
    print_table(payload["rows"])
    for r in payload["rows"]:
        if "duhem_margin" in r:
            print(f"{r['record']}: Duhem {r['method']}: alpha max|dw1| = {r['duhem_margin']:.3g}"
                  " (condition 8 asks < 2)")
    print()
    print(render(payload))
    print()
    print(render_shows(payload))
    suffix = f"_{args.only}" if args.only else ""
    print(f"wrote {write_json('pi_vs_duhem' + suffix, payload)}")


if __name__ == "__main__":
    main()
