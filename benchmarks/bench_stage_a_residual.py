"""What the default model leaves on measured stage A, and whether a slow term could remove it.

The model ``hystid identify`` chooses on ``prbn_1`` (defaults) runs free on every other record of
``../shared/data/real/stageA/``, its prediction put on the record's own output at rest (as every
accuracy table of the project scores it). Over each record's excitation (from the first sample
that leaves the rest, the wrapped last sample left out) the residual is split into frequency
bands (shares of its power; the mean, the sensor's zero that moved, apart) and the share at
the harmonics of a periodic input's fundamental (50 Hz) is given, with the RMS of its means over
whole periods of that fundamental (its slow part), and, for records of different inputs on the
same slow input, how alike their slow parts are. Then three slow terms are
fitted by least squares, with a free constant:

* ``creep (prbn_1)``: five first-order lags of the input (3 ms to 3 s, log-spaced, each less
  the input itself: what a creep branch adds), fitted on ``prbn_1``'s own residual and carried
  to the record (what a creep branch identified on the training record could do);
* ``creep (oracle)``: the same lags fitted on the held-out record's own residual;
* ``drift (oracle)``: a cubic in time fitted on the held-out record's own residual.

The oracles are fitted on the data they are scored on: a bound on what such a term could
explain, not a model. Where even they leave the error far above the repeatability floor, the
error is not a slow term of the input or of time.

    OPENBLAS_NUM_THREADS=1 python benchmarks/bench_stage_a_residual.py
"""

from __future__ import annotations

import argparse
import warnings

import numpy as np
from _common import table, write_json
from bench_stage_a import STAGE_A, TRAIN, records
from scipy import signal

from hystid.baselines import repeat_floor, rest_zero, simulate_from_rest
from hystid.identify import identify
from hystid.identify.prepare import rest_level

#: The README blocks this script renders (see ``benchmarks/readme.py``).
README_BLOCKS = {"stage-a-residual": "render"}
COMMAND = "OPENBLAS_NUM_THREADS=1 python benchmarks/bench_stage_a_residual.py"
#: Frequency bands of the residual's power [Hz].
BANDS = ((0.5, 5.0), (5.0, 30.0), (30.0, 70.0), (70.0, 1000.0), (1000.0, np.inf))
#: Time constants of the creep lags [s].
CREEP_TAUS = tuple(np.logspace(np.log10(0.003), np.log10(3.0), 5))
FUNDAMENTAL = 50.0  # Hz, the sines' and triangles' frequency


def excitation(rec) -> slice:
    """The record's excitation: from the end of its leading rest, the wrapped last out."""
    return slice(rest_level(rec.u)[2], rec.n - 2)


def residual(model, rec) -> np.ndarray:
    """Measured less predicted output, the prediction on the record's own output at rest."""
    yhat = simulate_from_rest(model, rec.u, check=False)
    return rec.y - (yhat + rest_zero(yhat, rec))


def creep_terms(u: np.ndarray, u_ref: float, fs: float) -> np.ndarray:
    """Columns ``lag_tau(u) - u`` (each lag settled at the first input), one per tau."""
    cols = []
    for tau in CREEP_TAUS:
        a = np.exp(-1.0 / (tau * fs))
        lag, _ = signal.lfilter([1.0 - a], [1.0, -a], u - u_ref, zi=[a * (u[0] - u_ref)])
        cols.append(lag - (u - u_ref))
    return np.column_stack(cols)


def _with_constant(columns: np.ndarray) -> np.ndarray:
    return np.column_stack([columns, np.ones(len(columns))])


def _fit(columns: np.ndarray, e: np.ndarray) -> np.ndarray:
    """Least-squares coefficients of ``columns`` plus a constant for ``e``."""
    coef, *_ = np.linalg.lstsq(_with_constant(columns), e, rcond=None)
    return coef


def _rms(e: np.ndarray) -> float:
    return float(np.sqrt(np.mean(e ** 2)))


def band_shares(e: np.ndarray, fs: float) -> dict:
    """Shares of the residual's power per band of :data:`BANDS` and at the harmonics of
    :data:`FUNDAMENTAL` (within 1.5 Hz)."""
    f = np.fft.rfftfreq(e.size, 1.0 / fs)
    p = np.abs(np.fft.rfft(e)) ** 2
    p[1:(e.size + 1) // 2] *= 2.0  # one-sided: every bin but 0 (and Nyquist) counts twice
    p = p / p.sum()
    shares = {"mean": float(p[0])}
    shares.update({f"{lo:g}-{hi:g} Hz": float(p[(f >= lo) & (f < hi) & (f > 0)].sum())
                   for lo, hi in BANDS})
    near = np.abs(f / FUNDAMENTAL - np.round(f / FUNDAMENTAL)) * FUNDAMENTAL < 1.5
    shares["harmonics"] = float(p[near & (f > 1.0)].sum())
    return shares


def period_means(x: np.ndarray, fs: float) -> np.ndarray:
    """Means of ``x`` over whole periods of :data:`FUNDAMENTAL` (its slow part)."""
    m = int(round(fs / FUNDAMENTAL))
    n = len(x) // m
    return x[:n * m].reshape(n, m).mean(axis=1)


def shared_slow_error(slow: dict) -> list[dict]:
    """For each pair of records of different inputs whose slow inputs agree (correlation of
    their per-period means above 0.99): the correlation of their residuals' per-period means.

    Parameters
    ----------
    slow : dict
        Per record: ``u`` and ``e``, the per-period means of input and residual.

    Returns
    -------
    list of dict
        ``pair``, ``r_input`` and ``r_residual``.
    """
    out = []
    names = sorted(slow)
    for i, a in enumerate(names):
        for b in names[i + 1:]:
            if a.rsplit("_", 1)[0] == b.rsplit("_", 1)[0]:
                continue  # repeats of one input: their agreement is the floor's business
            n = min(len(slow[a]["u"]), len(slow[b]["u"]))
            r_u = float(np.corrcoef(slow[a]["u"][:n], slow[b]["u"][:n])[0, 1])
            if r_u > 0.99:
                r_e = float(np.corrcoef(slow[a]["e"][:n], slow[b]["e"][:n])[0, 1])
                out.append({"pair": [a, b], "r_input": r_u, "r_residual": r_e})
    return out


def measure() -> dict:
    """Identify with defaults on ``prbn_1`` and describe the residual on the other records.

    Returns
    -------
    dict
        ``member`` and, per record, the residual RMS over the excitation, the band shares, the
        RMS left by each slow term and the repeat floor.
    """
    recs = records()
    train = recs[TRAIN]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        result = identify(train)
    model = result.model
    u_ref = float(model.u_rest)
    k = excitation(train)
    e_train = residual(model, train)[k]
    cols_train = creep_terms(train.u, u_ref, train.fs)[k]
    creep = _fit(cols_train, e_train)
    rows, slow = [], {}
    for name, rec in recs.items():
        if name == TRAIN:
            continue
        k = excitation(rec)
        e = residual(model, rec)[k]
        slow[name] = {"u": period_means(rec.u[k], rec.fs), "e": period_means(e, rec.fs)}
        cols = creep_terms(rec.u, u_ref, rec.fs)[k]
        carried = cols @ creep[:-1]
        carried = carried - np.mean(carried - e)  # its constant refitted: a zero that moved
        oracle = _with_constant(cols) @ _fit(cols, e)
        t = np.linspace(-1.0, 1.0, len(e))
        cubic = np.column_stack([t, t ** 2, t ** 3])
        drift = _with_constant(cubic) @ _fit(cubic, e)
        twin = f"{name.rsplit('_', 1)[0]}_{'2' if name.endswith('_1') else '1'}"
        floor = repeat_floor([rec, recs[twin]]) if twin in recs else None
        rows.append({"record": name, "rms": _rms(e), "rms_less_mean": _rms(e - np.mean(e)),
                     "bands": band_shares(e, rec.fs),
                     "slow_part": _rms(slow[name]["e"] - np.mean(slow[name]["e"])),
                     "slow_input_span": float(np.ptp(slow[name]["u"])),
                     "creep_carried": _rms(e - carried), "creep_oracle": _rms(e - oracle),
                     "drift_oracle": _rms(e - drift), "floor": floor})
    return {"train": TRAIN, "member": result.info.get("model"), "creep_taus_s": CREEP_TAUS,
            "train_rms": _rms(e_train),
            "train_rms_with_creep": _rms(e_train - _with_constant(cols_train) @ creep),
            "rows": rows, "shared_slow_error": shared_slow_error(slow),
            "u_unit": train.units.get("u", ""), "command": COMMAND}


def render(payload: dict) -> str:
    """The residual table and its reading.

    Parameters
    ----------
    payload : dict
        Output of :func:`measure`.

    Returns
    -------
    str
        Markdown.
    """
    nm = 1e3
    bands = list(payload["rows"][0]["bands"])
    rows = [[r["record"], f"{r['rms'] * nm:.0f}", f"{r['rms_less_mean'] * nm:.0f}",
             f"{r['slow_part'] * nm:.0f}", *[f"{100 * r['bands'][b]:.0f} %" for b in bands],
             f"{r['creep_carried'] * nm:.0f}", f"{r['creep_oracle'] * nm:.0f}",
             f"{r['drift_oracle'] * nm:.0f}",
             "" if r["floor"] is None else f"{r['floor'] * nm:.0f}"] for r in payload["rows"]]
    head = ["record", "RMS over the excitation [nm]", "less its mean [nm]",
            "per-period means [nm]", *bands,
            "creep (prbn_1) [nm]", "creep (oracle) [nm]", "drift (oracle) [nm]",
            "repeat floor [nm]"]
    pairs = payload.get("shared_slow_error", [])
    span = [r["slow_input_span"] for r in payload["rows"]]
    shared = ("" if not pairs else
              f"\n\nThe per-period means of the input span {min(span):.0f}-{max(span):.0f} "
              f"{payload.get('u_unit', 'V')} on these records." +
              " Records of different inputs on the same slow input (per-period means of `u` "
              "correlating above 0.99) leave the same slow error: their residuals' per-period "
              "means correlate at " + ", ".join(
                  f"{p['r_residual']:.2f} ({p['pair'][0]} / {p['pair'][1]})" for p in pairs)
              + ".")
    return (f"Identified on {payload['train']} with the defaults (`{payload['member']}`); on "
            f"{payload['train']} itself the creep lags take its residual from "
            f"{payload['train_rms'] * nm:.1f} to {payload['train_rms_with_creep'] * nm:.1f} nm.\n\n"
            + table(rows, head) + shared)


def main() -> None:
    argparse.ArgumentParser(description=__doc__).parse_args()
    if not STAGE_A.exists():
        raise SystemExit(f"stage A records not found in {STAGE_A} (../shared/data)")
    payload = measure()
    print(render(payload))
    print(f"\nwritten {write_json('stage_a_residual', payload)}")


if __name__ == "__main__":
    main()
