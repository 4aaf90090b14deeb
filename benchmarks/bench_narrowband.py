"""A model identified on one sine, used on other inputs: what a narrow-band record identifies.

The record: 4 s of a 1 Hz sine over 0-3.6 V on the 200 Hz stage-B look-alike
(``hystid.testing.stage_b_like``: Preisach hysteresis, an amplifier lag, a mode near Nyquist, a
-111 um sensor offset), started mid-swing. Held out: the same stage (``hystid.testing.measured
.stage_b``, simulated independently of every model) driven by a 0.5 Hz, a 2 Hz and a 0.2 Hz sine
over the same range, a 1 Hz sine of two thirds the amplitude, and a 1 Hz sine started from rest
at 0 V. Each member is identified with defaults and scored like every accuracy table of the
project (:func:`hystid.baselines.compare`), beside the static line and the linear model.
A second table: ``auto`` identified on the look-alike's sine of seeds 0-4, held out on 1 Hz
sines of 1 V amplitude at other mean levels (1 V and 2.6 V): the minor loops inside the one
loop a sine shows. A third: the look-alike's sensor zero drifting by 0.3 um/s through every
record (and, second row, also starting up to 1 um off on each record), identified with
defaults batch and on-line on seed 0, held out on seeds 1-3.

    OPENBLAS_NUM_THREADS=1 python benchmarks/bench_narrowband.py
"""

from __future__ import annotations

import argparse
import warnings

import numpy as np
from _common import table, write_json

from hystid.baselines import compare
from hystid.identify import identify
from hystid.records import Record
from hystid.testing import stage_b_like
from hystid.testing.measured import stage_b

COMMAND = "OPENBLAS_NUM_THREADS=1 python benchmarks/bench_narrowband.py"
#: (label, model, method) identified on the sine.
FITS = (("duhem", "duhem", "batch"), ("pi-stage", "pi-stage", "batch"),
        ("auto", "auto", "batch"), ("auto, on-line", "auto", "online"))
#: Held-out inputs: (label, frequency Hz, amplitude V about 1.8 V, seconds, from rest at 0 V).
HELD_OUT = (("0.5 Hz", 0.5, 1.8, 8.0, False), ("2 Hz", 2.0, 1.8, 4.0, False),
            ("1 Hz, 2/3 amplitude", 1.0, 1.2, 4.0, False), ("0.2 Hz", 0.2, 1.8, 20.0, False),
            ("1 Hz from rest at 0 V", 1.0, 1.8, 6.0, True))


#: Mean levels [V] of the second table's held-out sines (1 V amplitude, 1 Hz, 4 s).
LEVELS = (1.0, 2.6)


def held_out_record(freq: float, amp: float, seconds: float, from_rest: bool,
                    seed: int, mean: float = 1.8) -> Record:
    """The stage-B look-alike driven by a sine about ``mean`` (its phase from ``seed``), as
    measured."""
    fs = 200.0
    rng = np.random.default_rng(seed)
    t = np.arange(int(round(seconds * fs))) / fs
    if from_rest:
        u = np.r_[np.zeros(int(fs)), 1.8 - amp * np.cos(2 * np.pi * freq * t)]
    else:
        u = mean + amp * np.sin(2 * np.pi * freq * t + rng.uniform(0, 2 * np.pi))
    y = stage_b().simulate(u)["y"] - 111.2 + 0.02 * rng.standard_normal(u.size)
    return Record(u=u, y=y, fs=fs, units={"u": "V", "y": "um"}, name=f"{freq:g} Hz")


def measure() -> dict:
    """Identify every fit on the sine and score it on every held-out record.

    Returns
    -------
    dict
        ``held_out`` labels and ``rows``: per fit, the member chosen, the held-out RMS [um]
        per record, and the baselines'.
    """
    train = stage_b_like(seed=0)
    held = [held_out_record(f, a, s, r, seed=i + 1)
            for i, (_, f, a, s, r) in enumerate(HELD_OUT)]
    rows = []
    for label, model, method in FITS:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            result = identify(train, model=model, method=method)
            c = compare(result.model, train, held)
        rows.append({"fit": label, "member": result.info.get("model", model),
                     "rms": [r["model"] for r in c.rows],
                     "static_line": [r["static_line"] for r in c.rows],
                     "linear": [r["linear"] for r in c.rows]})
    return {"held_out": [h[0] for h in HELD_OUT], "rows": rows, "levels": measure_levels(),
            "drift": measure_drift()}


#: The third table's drift of the sensor zero [um/s].
DRIFT = 0.3


def drifting_record(seed: int, zero: float = 0.0) -> Record:
    """The look-alike's 1 Hz sine (phase from ``seed``), its sensor zero drifting by
    :data:`DRIFT` from ``zero`` at the record's start."""
    fs = 200.0
    rng = np.random.default_rng(seed)
    t = np.arange(800) / fs
    u = 1.8 + 1.8 * np.sin(2 * np.pi * t + rng.uniform(0, 2 * np.pi))
    y = (stage_b().simulate(u)["y"] - 111.2 + zero + DRIFT * t
         + 0.05 * rng.standard_normal(t.size))
    return Record(u=u, y=y, fs=fs, units={"u": "V", "y": "um"}, name=f"drift {seed}")


def measure_drift() -> list[dict]:
    """``auto`` batch and on-line on a drifting record, scored on three more.

    Returns
    -------
    list of dict
        Per case (the zero drifting from 0, or from a random start up to 1 um off): the
        drift the batch fit estimated [um/s] and the held-out RMS [um] of the batch and the
        on-line models and of the baselines.
    """
    out = []
    for case, off in (("drifting from 0", 0.0), ("and up to 1 um off at the start", 1.0)):
        def rec(seed: int, off: float = off) -> Record:
            return drifting_record(seed, off * np.random.default_rng(100 + seed).uniform(-1, 1))

        train, held = rec(0), [rec(s) for s in (1, 2, 3)]
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            batch = identify(train)
            online = identify(train, method="online")
            c = compare(batch.model, train, held)
            c_on = compare(online.model, train, held)
        out.append({"case": case, "drift_per_second": batch.info.get("drift_per_second"),
                    "batch": [r["model"] for r in c.rows],
                    "online": [r["model"] for r in c_on.rows],
                    "linear": [r["linear"] for r in c.rows],
                    "static_line": [r["static_line"] for r in c.rows]})
    return out


def measure_levels(seeds: range = range(5)) -> list[dict]:
    """``auto`` identified on the sine of each seed, scored on sines at :data:`LEVELS`.

    Parameters
    ----------
    seeds : range
        Seeds of the identification record (the held-out records' are ``10 * (i + 1) +
        seed`` for the ``i``-th level).

    Returns
    -------
    list of dict
        Per seed: the member chosen and, per level, the model's, the linear model's and the
        static line's held-out RMS [um].
    """
    out = []
    for seed in seeds:
        train = stage_b_like(seed=seed)
        held = [held_out_record(1.0, 1.0, 4.0, False, 10 * (i + 1) + seed, mean=m)
                for i, m in enumerate(LEVELS)]
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            result = identify(train)
            c = compare(result.model, train, held)
        out.append({"seed": seed, "member": result.info.get("model"),
                    "rms": [r["model"] for r in c.rows], "linear": [r["linear"] for r in c.rows],
                    "static_line": [r["static_line"] for r in c.rows]})
    return out


def render(payload: dict) -> str:
    """The table as printed.

    Parameters
    ----------
    payload : dict
        From :func:`measure`.

    Returns
    -------
    str
    """
    head = ["held-out RMS [um], identified on a 1 Hz sine", *payload["held_out"]]
    body = [[f"`{r['fit']}`" + (f" (chose `{r['member']}`)" if r["fit"].startswith("auto")
                                 else ""), *(f"{v:.3g}" for v in r["rms"])]
            for r in payload["rows"]]
    base = payload["rows"][0]
    body.append(["static line", *(f"{v:.3g}" for v in base["static_line"])])
    body.append(["linear (duhem orders)", *(f"{v:.3g}" for v in base["linear"])])
    levels = payload["levels"]
    head2 = ["seed", "`auto` chose",
             *(f"{m:g} V mean: model / linear / line" for m in LEVELS)]
    body2 = [[r["seed"], f"`{r['member']}`",
              *(f"{a:.3g} / {b:.3g} / {c:.3g}" + (" (loses)" if a > min(b, c) else "")
                for a, b, c in zip(r["rms"], r["linear"], r["static_line"], strict=True))]
             for r in levels]
    head3 = ["sensor zero", "drift found [um/s]", "batch", "on-line", "linear", "static line"]
    body3 = [[r["case"], f"{r['drift_per_second']:.3g}",
              *(" / ".join(f"{v:.2g}" for v in r[k])
                for k in ("batch", "online", "linear", "static_line"))]
             for r in payload["drift"]]
    return (table(body, head) + "\n\nother mean levels (1 Hz, 1 V amplitude) [um]\n\n"
            + table(body2, head2) + f"\n\na sensor zero drifting by {DRIFT} um/s, seed 0 -> "
            "seeds 1 / 2 / 3 [um]\n\n" + table(body3, head3))


def main() -> None:
    """Run, print the table, write ``narrowband.json``."""
    argparse.ArgumentParser(description=__doc__.splitlines()[0]).parse_args()
    payload = measure()
    print(render(payload))
    print(f"-> {write_json('narrowband', payload)}")


if __name__ == "__main__":
    main()
