"""On-line vs batch identification of the ``pi-stage`` member.

Each training record is identified by the batch fit and by the on-line identifier
(:class:`hystid.identify.pi_online.PIStageOnline`, through ``identify(method="online")``, with
its default window, with shorter ones and with re-solves every 500 samples instead of 2 000
(:data:`OFTEN`)), and every model is scored free-run from rest on the
held-out records (:func:`hystid.baselines.compare`, zeroed on each record's rest output).
Measured stage A (trained on ``prbn_1``, the five other records held out; left out when
``../shared/data`` is absent) and the Bouc-Wen look-alike of stage A
(:func:`hystid.testing.stage_a_like`, 1 s of excitation, trained on PRBN seed 0, held out on
PRBN, 50 Hz sine and triangle, seed 1).

Then the on-line identifier's speed (:func:`throughput`): started on the training record, its
samples per second over the first held-out record (``partial_fit``), the re-solves' share of
that time, the warm-ups fitted again in it (one call's work each, and the rate without that
call; ``prbn_2``'s leading rest, where the sensor's zero moved, took one before such a chunk was
left unchecked), the model's held-out RMS on the other records before and after it, and
the time of each ``update()`` call over 3 000 samples (median, 99th percentile
and worst: the re-solve runs in steps beside the recursion, and takes over at a chunk's
boundary), with :data:`OFTEN` too, beside the Duhem on-line identifier on the same
samples in the same process.

    OPENBLAS_NUM_THREADS=1 python benchmarks/bench_pi_online.py
"""

from __future__ import annotations

import time
import warnings

import numpy as np
from _common import table, write_json
from bench_stage_a import TRAIN, records

from hystid.baselines import compare
from hystid.identify import identify
from hystid.identify.members import member
from hystid.identify.online import OnlineIdentifier
from hystid.testing import stage_a_like

#: On-line settings compared: the default window (10 000 samples) and shorter ones, and
#: re-solves 4x more often (:data:`OFTEN`).
VARIANTS = {"online": {}, "online, window 7000": {"window": 7000},
            "online, window 5000": {"window": 5000}, "online, window 3000": {"window": 3000}}
#: The defaults before 2026-11-26: a re-solve every 500 samples, 150 simulated samples of its
#: work per sample.
OFTEN = {"every": 500, "resolve_rate": 150.0}
VARIANTS["online, every 500"] = OFTEN


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


def throughput(train, held: list, calls: int = 3000) -> dict:
    """Steady-state speed of the ``pi-stage`` and Duhem on-line identifiers on one record.

    Parameters
    ----------
    train : Record
        Record each identifier starts on (``fit``).
    held : list of Record
        ``partial_fit`` runs over the first; ``update()`` over the first ``calls`` samples
        of the second after its first sample (the first record again when there is one only).
    calls : int
        ``update()`` calls timed one by one.

    Returns
    -------
    dict
        Per identifier: ``samples_per_s`` (``partial_fit``), ``resolve_share`` (``pi-stage``:
        the re-solves' share of that time, ``resolve_work``: their mean work in simulated
        samples, ``warmup_s``: the warm-up fit's seconds, in the call that completes it,
        ``choice_s``: the seconds of the call that chooses between the two starts),
        ``update_median_us``, ``update_p99_us`` and ``update_max_us``; and
        ``fs``, the records' sampling rate.
    """
    out = {"fs": train.fs}
    second = held[1] if len(held) > 1 else held[0]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        # offset=None: the identifier takes the output at rest from the record's leading rest
        # (online_estimator's offset=0.0 is for the record less its rest, as identify gives it)
        for name, make in (("pi-stage",
                            lambda: member("pi-stage").online_estimator(train, offset=None)),
                           ("pi-stage, every 500",
                            lambda: member("pi-stage").online_estimator(train, offset=None,
                                                                        **OFTEN)),
                           ("duhem", lambda: OnlineIdentifier(fs=train.fs))):
            warm = make()  # a first run compiles what the timed one calls
            warm.fit(train)
            warm.partial_fit(held[0][:2000])
            est = make()
            est.fit(train)
            warmup = getattr(est, "warmup_seconds_", None)
            choice = getattr(est, "choice_seconds_", None)
            before = getattr(est, "resolve_seconds_", 0.0)
            work0, n0 = getattr(est, "resolve_work_", 0.0), getattr(est, "n_resolves", 0)
            rewarms0 = getattr(est, "n_rewarms", 0)
            before_rms = _others_rms(est.model, train, held[1:])
            t0 = time.perf_counter()
            est.partial_fit(held[0])
            seconds = time.perf_counter() - t0
            after_rms = _others_rms(est.model, train, held[1:])
            rewarms = getattr(est, "n_rewarms", 0) - rewarms0
            # a warm-up fitted again in the run (its model predicted nothing) is one call's work
            rewarm_s = getattr(est, "warmup_seconds_", 0.0) if rewarms else 0.0
            share = (getattr(est, "resolve_seconds_", 0.0) - before) / seconds
            resolves = getattr(est, "n_resolves", 0) - n0
            work = ((getattr(est, "resolve_work_", 0.0) - work0) / resolves if resolves
                    else None)
            est.update(float(second.u[0]), float(second.y[0]))  # its first call untimed
            times = np.empty(min(calls, second.n - 1))
            for i, (u_k, y_k) in enumerate(zip(second.u[1:len(times) + 1].tolist(),
                                               second.y[1:len(times) + 1].tolist(),
                                               strict=True)):
                t0 = time.perf_counter()
                est.update(u_k, y_k)
                times[i] = time.perf_counter() - t0
            out[name] = {"samples_per_s": held[0].n / seconds, "rewarms": rewarms,
                         "samples_per_s_without_rewarm": held[0].n / (seconds - rewarm_s),
                         "resolve_share": share,
                         "resolve_work": work, "warmup_s": warmup, "choice_s": choice,
                         "update_median_us": float(np.median(times) * 1e6),
                         "update_p99_us": float(np.percentile(times, 99) * 1e6),
                         "update_max_us": float(np.max(times) * 1e6),
                         "held_out_nm_before": before_rms, "held_out_nm_after": after_rms}
    return out


def _others_rms(model, train, others: list) -> list[float]:
    """Held-out RMS (nm, zeroed on each record's rest) of an on-line model on the records
    after the one it is continued on."""
    return [1e3 * r["model"] for r in compare(model, train, others).rows]


def render_speed(speed: dict) -> str:
    """The speed table of :func:`throughput`.

    Parameters
    ----------
    speed : dict
        From :func:`throughput`.

    Returns
    -------
    str
    """
    fs = speed["fs"]
    rows = [[name, f"{e['samples_per_s']:,.0f}", str(e.get("rewarms", "")),
             f"{e.get('samples_per_s_without_rewarm', e['samples_per_s']):,.0f}",
             f"{e['samples_per_s'] / fs:.2g}x",
             f"{e['samples_per_s'] / speed['duhem']['samples_per_s']:.3g}",
             f"{100 * e['resolve_share']:.0f} %",
             "" if e.get("resolve_work") is None else f"{e['resolve_work']:,.0f}",
             "" if e.get("warmup_s") is None else f"{e['warmup_s']:.2f}",
             "" if e.get("choice_s") is None else f"{e['choice_s']:.2f}",
             f"{e['update_median_us']:.1f}",
             f"{e['update_p99_us']:.0f}", f"{e['update_max_us']:,.0f}",
             _nm_range(e.get("held_out_nm_before")), _nm_range(e.get("held_out_nm_after"))]
            for name, e in speed.items() if name != "fs"]
    return table(rows, ["on-line identifier", "samples/s (partial_fit)", "re-warms",
                        "samples/s without the re-warm's call",
                        f"x real time at {fs:g} Hz", "ratio to duhem", "re-solves' share",
                        "work per re-solve [simulated samples]", "warm-up fit [s]",
                        "choice of start [s]",
                        "update() median [us]", "update() 99th percentile [us]",
                        "update() worst [us]", "held out before [nm]",
                        "held out after [nm]"])


def _nm_range(values: list[float] | None) -> str:
    return "" if not values else " / ".join(f"{v:.0f}" for v in values)


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
    speed = payload.get("speed")
    for case, e in payload.items():
        if case in ("speed", "through_rest"):
            continue
        batch = np.array(e["rms"]["batch"])
        rows = [[m, *(f"{1e3 * v:.1f}" for v in r),
                 f"{np.max(np.array(r) / batch):.2f}"] for m, r in e["rms"].items()]
        text += [f"{case}: held-out RMS [nm]", "",
                 table(rows, ["method", *e["records"], "worst ratio to batch"]), ""]
    if speed is not None:
        text += ["Speed in steady state (one process):", "", render_speed(speed), ""]
    return "\n".join(text)


def through_rest(train, held: list) -> dict:
    """The ``pi-stage`` on-line model after its training record, and after the same record's
    leading rest fed once more (a stage left at rest): held-out RMS (nm) on the records after
    the first held-out one."""
    from hystid.identify.prepare import rest_level

    n_rest = rest_level(train.u)[2]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        est = member("pi-stage").online_estimator(train, offset=None)
        est.fit(train)
        before = _others_rms(est.model, train, held[1:])
        est.partial_fit(train[:n_rest])
        return {"rest_samples": int(n_rest), "before": before,
                "after": _others_rms(est.model, train, held[1:])}


def main() -> None:
    payload = measure()
    train, held = next(iter(_cases().values()))
    payload["speed"] = throughput(train, held)
    payload["through_rest"] = through_rest(train, held)
    print(render(payload))
    r = payload["through_rest"]
    print(f"Through a rest ({r['rest_samples']} samples of the training record's rest fed again "
          f"after it): held out {_nm_range(r['before'])} nm before, {_nm_range(r['after'])} nm "
          "after.")
    print(f"written {write_json('pi_online', payload)}")


if __name__ == "__main__":
    main()
