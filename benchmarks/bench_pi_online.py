"""On-line vs batch identification of the ``pi-stage`` member.

Each training record is identified by the batch fit and by the on-line identifier
(:class:`hystid.identify.pi_online.PIStageOnline`, through ``identify(method="online")``, with
its default window and with shorter ones), and every model is scored free-run from rest on the
held-out records (:func:`hystid.baselines.compare`, zeroed on each record's rest output).
Measured stage A (trained on ``prbn_1``, the five other records held out; left out when
``../shared/data`` is absent) and the Bouc-Wen look-alike of stage A
(:func:`hystid.testing.stage_a_like`, 1 s of excitation, trained on PRBN seed 0, held out on
PRBN, 50 Hz sine and triangle, seed 1).

    OPENBLAS_NUM_THREADS=1 python benchmarks/bench_pi_online.py
"""

from __future__ import annotations

import warnings

import numpy as np
from _common import table, write_json
from bench_stage_a import TRAIN, records

from hystid.baselines import compare
from hystid.identify import identify
from hystid.testing import stage_a_like

#: On-line settings compared: the default window (10 000 samples) and shorter ones.
VARIANTS = {"online": {}, "online, window 7000": {"window": 7000},
            "online, window 5000": {"window": 5000}, "online, window 3000": {"window": 3000}}


def _cases() -> dict:
    cases = {}
    recs = records()
    if recs:
        cases["stage A"] = (recs[TRAIN], [r for n, r in recs.items() if n != TRAIN])
    cases["look-alike"] = (stage_a_like("prbn", seconds=1.0, seed=0),
                           [stage_a_like(k, seconds=1.0, seed=1)
                            for k in ("prbn", "sine50", "tri50")])
    return cases


def measure() -> dict:
    """Held-out RMS of the batch fit and of each on-line variant, per case.

    Returns
    -------
    dict
        Per case: ``records`` (held-out names) and ``rms`` (per method, RMS per record).
    """
    out = {}
    for case, (train, held) in _cases().items():
        rms = {}
        for label, settings in {"batch": None, **VARIANTS}.items():
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                res = (identify(train, model="pi-stage") if settings is None else
                       identify(train, model="pi-stage", method="online", **settings))
                rms[label] = [r["model"] for r in compare(res.model, train, held).rows]
        out[case] = {"records": [r.name for r in held], "rms": rms}
    return out


def render(payload: dict) -> str:
    """Held-out RMS in nm and the ratio to the batch fit, one table per case.

    Parameters
    ----------
    payload : dict
        From :func:`measure`.

    Returns
    -------
    str
    """
    text = []
    for case, e in payload.items():
        batch = np.array(e["rms"]["batch"])
        rows = [[m, *(f"{1e3 * v:.1f}" for v in r),
                 f"{np.max(np.array(r) / batch):.2f}"] for m, r in e["rms"].items()]
        text += [f"{case}: held-out RMS [nm]", "",
                 table(rows, ["method", *e["records"], "worst ratio to batch"]), ""]
    return "\n".join(text)


def main() -> None:
    payload = measure()
    print(render(payload))
    print(f"written {write_json('pi_online', payload)}")


if __name__ == "__main__":
    main()
