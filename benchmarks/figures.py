"""The accuracy figures of the regression benchmarks, each computed in this one place.

The asv suite (``benchmarks/suite``, its ``track_*``), the accuracy gate (``benchmarks/gate.py``,
``tests/test_accuracy_gate.py``), the scripts (``bench_identify.py`` ...) and the README's
``accuracy`` block (through the gate) call these functions. Every figure is a function of its
seeds alone: the records come from seeded generators and nothing depends on the clock (the
diagnosis runs with a fixed refit budget, not a time budget).

Figure families:

* :func:`reference_identification` -- a method on the reference stage: max relative parameter
  error, held-out RMS on a fresh record (the rows of ``bench_identify.py``);
* :func:`as_measured` -- a method on a case of :func:`hystid.testing.as_measured_suite`
  (independent simulator; offset, units, 10 kHz, outlier...): held-out RMS next to the
  baselines of :func:`hystid.baselines.compare`, and the parameter error where the truth is
  known in the record's units;
* :func:`start_up_run` / :func:`wrong_basin` -- where the on-line start-up lands;
* :func:`withheld_effects` -- the blind diagnosis of withheld effects, in-form and cross-form
  (``bench_withheld_effects.py``'s cases and summary);
* :func:`tracking_cut` -- what the feed-forward inverse of an identified model takes off the
  tracking error.

``python benchmarks/gate.py`` computes the gate's set of them; the README's ``accuracy`` block is
rendered from its baseline by ``python benchmarks/readme.py``.
"""

from __future__ import annotations

import contextlib
import functools
import sys
import warnings
from collections.abc import Iterator, Sequence
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
if str(HERE) not in sys.path:  # the scripts beside this one import each other by name
    sys.path.insert(0, str(HERE))

if __name__ == "__main__":  # run as a script: measure the checkout this file belongs to
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from hystid.reference import PAPER_PARAMS, reference_record  # noqa: E402

#: The reference stage's parameters in the paper's order (eqs. 26-28).
TRUTH = np.array(list(PAPER_PARAMS.values()))
#: Methods of :func:`hystid.identify.identify` and the PI sandwich's recursive identifier.
METHODS = ("batch", "online", "eria", "ekf", "pi")
#: Cases of :func:`hystid.testing.as_measured_suite` (each with its ``/heldout`` record).
AS_MEASURED = ("offset", "units", "mid_motion", "held_level", "10kHz", "outlier", "end_glitch")
#: A run of the on-line start-up is in a wrong basin above this max relative parameter error.
WRONG_BASIN = 0.2


@contextlib.contextmanager
def quiet() -> Iterator[None]:
    """Silence the warnings identification raises on purpose (restarts, admissibility)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        yield


def max_relative_error(theta: np.ndarray, truth: np.ndarray = TRUTH) -> float:
    """Largest relative parameter error ``max |theta - truth| / |truth|``.

    Parameters
    ----------
    theta : ndarray
        Estimate, in the order of ``truth``.
    truth : ndarray, optional
        True parameters, by default the reference stage's.

    Returns
    -------
    float
    """
    return float(np.max(np.abs(np.asarray(theta) - truth) / np.abs(truth)))


def samples_to(err: np.ndarray, bound: float) -> int | None:
    """First sample count after which ``err`` stays below ``bound``.

    Parameters
    ----------
    err : ndarray
        Error per sample.
    bound : float
        Level to stay under.

    Returns
    -------
    int or None
        None when the error ends above ``bound``.
    """
    above = np.flatnonzero(err > bound)
    if len(above) == 0:
        return 1
    k = int(above[-1]) + 2
    return k if k <= len(err) else None


def _identify(record, method: str, **settings):
    """Identify ``record`` with ``method`` (``"pi"``: the PI sandwich's recursive identifier;
    ``"auto"``: the batch fit of the member chosen on held-out data, ``hystid identify``'s
    default)."""
    from hystid.identify import identify
    from hystid.identify.pi_recursive import identify_pi

    with quiet():
        if method == "pi":
            return identify_pi(record, method="recursive", **settings)
        if method == "auto":
            return identify(record, model="auto", **settings)
        return identify(record, method=method, **{"model": "duhem", **settings})


def fit_and_compare(train, held: Sequence, method: str, **settings) -> tuple:
    """Identify ``train`` with ``method`` and score it and the baselines on ``held``.

    Parameters
    ----------
    train : Record
        The identification record.
    held : sequence of Record or (Record, int)
        Held-out records, as :func:`hystid.baselines.compare` takes them.
    method : str
        As :func:`_identify`.
    **settings
        Passed to the identifier.

    Returns
    -------
    tuple
        ``(result, comparison, seconds)``: the identification result, the
        :class:`hystid.baselines.BaselineComparison` and the identification's time.
    """
    import time

    from hystid.baselines import compare

    t0 = time.perf_counter()
    res = _identify(train, method, **settings)
    seconds = time.perf_counter() - t0
    with quiet():
        comparison = compare(res.model, train, held)
    return res, comparison, seconds


def reference_identification(method: str, seed: int = 0, noise: float = 1e-3,
                             samples: int = 30_000) -> dict:
    """Identify a reference-stage record from rest and validate on a fresh one.

    The identification record is ``reference_record(samples / 30 kHz, seed, noise)`` from
    theta(0) = 0.01, the validation record 0.5 s of seed ``10 000 + seed``. ERIA is given
    the truth for its diagnostics only.

    Parameters
    ----------
    method : str
        One of :data:`METHODS`.
    seed : int
        Seed of the identification record.
    noise : float
        Sensor noise RMS, um.
    samples : int
        Length of the identification record.

    Returns
    -------
    dict
        ``final_err`` (max relative parameter error; None for the PI sandwich, whose
        parameters are not the stage's), ``val_min``, ``val_max``, ``val_rms`` (um; absent
        when the model is unstable), ``restarts``, ``seconds``, ``converged`` (1.0 when
        ``final_err`` is finite and under 10 %, else 0.0; None for the PI sandwich), and for
        recursive methods
        ``to_2pc``, ``to_01pc`` (samples until the error stays within 2 % / 0.1 %),
        ``err_at_1000`` and ``nan``.
    """
    import time

    from hystid.metrics import validate

    rec = reference_record(samples / 30_000.0, seed=seed, noise=noise)
    val = reference_record(0.5, seed=10_000 + seed, noise=noise)
    settings = {"truth": PAPER_PARAMS} if method == "eria" else {}
    t0 = time.perf_counter()
    res = _identify(rec, method, **settings)
    row = {"method": method, "seed": seed, "noise_nm": noise * 1e3,
           "seconds": time.perf_counter() - t0, "restarts": res.info.get("n_recoveries", 0),
           "final_err": None if method == "pi" else max_relative_error(res.model.theta)}
    # converged: a well-conditioned yes/no where final_err is not (a diverging run ends
    # wherever round-off takes it, which differs from one CPU or instruction set to another)
    row["converged"] = (None if row["final_err"] is None else
                        float(bool(np.isfinite(row["final_err"]) and row["final_err"] < 0.1)))
    row["samples_per_s"] = samples / row["seconds"]
    if res.history is not None and method != "pi":
        err = np.max(np.abs(res.history - TRUTH) / np.abs(TRUTH), axis=1)
        row.update(to_2pc=samples_to(err, 0.02), to_01pc=samples_to(err, 1e-3),
                   err_at_1000=float(err[min(999, samples - 1)]), nan=bool(np.isnan(err).any()))
    if np.all(np.isfinite(res.model.theta)) and res.model.is_stable():
        with quiet():
            v = validate(val.y, res.model.simulate(val.u).y, val.fs)
        row.update(val_min=v.err_min, val_max=v.err_max, val_rms=v.rms)
    return row


@functools.lru_cache(maxsize=4)
def _suite(seed: int, seconds: float) -> dict:
    from hystid.testing import as_measured_suite

    return {r.name: r for r in as_measured_suite(seed, seconds=seconds)}


def truth_in_units(record) -> np.ndarray | None:
    """The reference stage's parameters in a record's units, or None where they are unknown.

    The input scales ``w1`` and the output ``w2``: ``alpha`` goes as 1 / input unit, ``f1``
    and ``g0`` as output unit / input unit, the linear blocks do not change. At a rate other
    than 30 kHz the discrete parameters are another stage's: None.

    Parameters
    ----------
    record : Record
        A record of :func:`hystid.testing.as_measured_suite`.

    Returns
    -------
    ndarray or None
    """
    from hystid.testing import UNIT_FACTORS

    if record.fs != 30_000.0:
        return None
    su = UNIT_FACTORS[record.units.get("u", "V")]
    sy = UNIT_FACTORS[record.units.get("y", "um")]
    scale = {"alpha": su, "f1": su / sy, "g0": su / sy}
    return np.array([v * scale.get(k, 1.0) for k, v in PAPER_PARAMS.items()])


def as_measured(method: str, case: str, seed: int = 0, seconds: float = 0.2) -> dict:
    """Identify an as-measured record and score its held-out record against the baselines.

    Parameters
    ----------
    method : str
        ``"batch"``, ``"online"``, ``"eria"`` or ``"ekf"``.
    case : str
        One of :data:`AS_MEASURED`.
    seed : int
        Seed of the suite (the held-out record has ``seed + 1``).
    seconds : float
        Length of the suite's excitations.

    Returns
    -------
    dict
        ``heldout_rms``, ``static_line``, ``linear`` (held-out RMS in the record's output
        unit, the model's and the two baselines'), ``beats`` (the model beats both),
        ``param_err`` (max relative parameter error, None where the truth is not known in the
        record's units), ``warnings``.
    """

    suite = _suite(seed, seconds)
    train, held = suite[case], suite[f"{case}/heldout"]
    res, comparison, _ = fit_and_compare(train, [held], method)
    row = comparison.rows[0]
    truth = None if method == "pi" else truth_in_units(train)
    return {"method": method, "case": case, "heldout_rms": float(row["model"]),
            "static_line": float(row["static_line"]), "linear": float(row["linear"]),
            "beats": bool(row["beats"]),
            "param_err": None if truth is None else max_relative_error(res.model.theta, truth),
            "warnings": list(res.info.get("warnings", []))}


def start_up_run(source: str, noise: float, seed: int, seconds: float = 1.0) -> dict:
    """One on-line identification from rest: does its start-up land in the right basin?

    Parameters
    ----------
    source : {"reference", "stages"}
        ``reference``: :func:`hystid.reference.reference_record`; ``stages``: the independently
        written paper stage and excitation of :mod:`hystid.testing.stages` (noise seed
        ``10 000 + seed``).
    noise : float
        White sensor noise RMS, um.
    seed : int
        Seed of the excitation.
    seconds : float
        Record length.

    Returns
    -------
    dict
        ``final_err``, ``wrong_basin`` (``final_err`` above :data:`WRONG_BASIN`), ``warned``
        (the result carries a warning), ``start_samples``, ``checks``.
    """
    from hystid.identify.online import OnlineIdentifier
    from hystid.records import Record
    from hystid.testing import paper_excitation as stage_excitation
    from hystid.testing import paper_stage

    if source == "reference":
        rec = reference_record(seconds, seed=seed, noise=noise)
    elif source == "stages":
        u = stage_excitation(seconds, seed=seed)
        rng = np.random.default_rng(10_000 + seed)
        y = paper_stage().simulate(u)["y"] + noise * rng.standard_normal(len(u))
        rec = Record(u, y, 30_000.0, name=f"stages seed {seed}")
    else:
        raise ValueError(f"source: expected 'reference' or 'stages', got {source!r}")
    with quiet():
        res = OnlineIdentifier().fit(rec)
    err = max_relative_error(res.model.theta)
    start = res.info["start_up"]
    return {"source": source, "noise_nm": noise * 1e3, "seed": seed, "final_err": err,
            "start_samples": start["samples"], "checks": start["checks"],
            "warned": bool(res.info["warnings"]), "wrong_basin": err > WRONG_BASIN}


def wrong_basin(seeds: Sequence[int], noises: Sequence[float] = (0.0, 1e-3, 1e-2),
                sources: Sequence[str] = ("reference", "stages")) -> dict:
    """Wrong-basin rate of the on-line start-up over seeds, noise levels and simulators.

    Parameters
    ----------
    seeds : sequence of int
        Excitation seeds.
    noises : sequence of float
        Sensor noise levels, um.
    sources : sequence of str
        Simulators (see :func:`start_up_run`).

    Returns
    -------
    dict
        ``rate`` (share of runs in a wrong basin), ``silent_rate`` (... without a warning),
        ``worst_err`` (largest final error), ``runs`` (every run's row).
    """
    runs = [start_up_run(src, noise, seed) for src in sources for noise in noises
            for seed in seeds]
    return {"rate": float(np.mean([r["wrong_basin"] for r in runs])),
            "silent_rate": float(np.mean([r["wrong_basin"] and not r["warned"] for r in runs])),
            "worst_err": float(max(r["final_err"] for r in runs)), "runs": runs}


def withheld_effects(in_form: int = 3, cross_form: int = 3, clean: int = 1,
                     seconds: float = 0.3, seed: int = 2024) -> dict:
    """Blind diagnosis of withheld effects on a small, seeded draw of cases.

    The cases are those of ``bench_withheld_effects.py`` (its draw with ``seed``, one draw per
    form at three strengths): the first ``in_form`` and ``cross_form`` cases with an effect,
    and ``clean`` clean records per source. The diagnosis refits the most promising form of
    every family the screen keeps and no further one (``time_budget=0``), so that the
    figures do not depend on the machine's speed.

    Parameters
    ----------
    in_form, cross_form : int
        Cases with an effect, per source.
    clean : int
        Clean records per source.
    seconds : float
        Length of each train and held-out record.
    seed : int
        Seed of the draw.

    Returns
    -------
    dict
        Per source (``"in-form"``, ``"cross-form"``): ``bench_withheld_effects.summarise``'s
        summary (``top1_accuracy``, ``false_acceptance_clean``, ``wrong_acceptance``...);
        ``cases``: every case's row.
    """
    import bench_withheld_effects as bw

    n = int(round(seconds * bw.FS))
    rng = np.random.default_rng(seed)
    jobs = (_pick(bw.jobs_in_form(1, clean, rng, later=False), in_form, clean)
            + _pick(bw.jobs_cross_form(1, clean, rng), cross_form, clean))
    with quiet():
        rows = [bw.diagnose_job(job, n, time_budget=0.0) for job in jobs]
    out = {src: bw.summarise([r for r in rows if r["source"] == src])
           for src in ("in-form", "cross-form")}
    out["cases"] = rows
    return out


def _pick(jobs: list[tuple], effects: int, clean: int) -> list[tuple]:
    """``effects`` cases with an effect spread over the draw (medium strength first), and the
    ``clean`` clean ones."""
    with_effect = [j for j in jobs if j[1] != "none" and j[1] not in ("asymmetry/offset",)]
    medium = [j for j in with_effect if j[2] == 1]
    step = max(len(medium) // max(effects, 1), 1)
    return medium[::step][:effects] + [j for j in jobs if j[1] == "none"][:clean]


def tracking_cut(kind: str = "triangle", frequency: float = 10.0, train_seconds: float = 0.1,
                 seed: int = 0) -> dict:
    """Tracking error of the reference stage without and with the feed-forward inverse.

    The model is identified off-line on ``train_seconds`` of the reference stage (1 nm noise,
    ``seed``); the stage itself is driven. ``none`` is the linear feed-forward (static
    inversion of the gains), ``inverse`` the model's exact inverse sandwich
    (:func:`hystid.compensate.simulate_closed_loop`, no feedback).

    Parameters
    ----------
    kind : {"triangle", "sine"}
        Scan waveform (:func:`hystid.compensate.scan_reference`, 1-8 um).
    frequency : float
        Scan frequency, Hz.
    train_seconds : float
        Length of the identification record.
    seed : int
        Seed of the identification record.

    Returns
    -------
    dict
        ``max_none``, ``max_inverse``, ``rms_none``, ``rms_inverse`` (um) and ``cut`` (max error
        without / with the inverse).
    """
    import hystid.compensate as hc
    from hystid.identify.offline import fit_output_error
    from hystid.reference import reference_model

    truth = reference_model()
    with quiet():
        model = fit_output_error(reference_record(train_seconds, seed=seed)).model
    ref = hc.scan_reference(kind, frequency)
    out = {}
    for label, ff in (("none", "linear"), ("inverse", True)):
        with quiet():
            run = hc.simulate_closed_loop(model, ref.y, None, feedforward=ff, plant=truth)
        m = run.metrics(ref.skip)
        out[f"max_{label}"], out[f"rms_{label}"] = float(m.max_error), float(m.rms_error)
    out["cut"] = out["max_none"] / out["max_inverse"]
    return out


#: Measured stage A's development records (``../shared/data``; absent on some machines).
STAGE_A = Path(__file__).resolve().parents[2] / "shared" / "data" / "real" / "stageA"


def stage_a_default() -> dict:
    """``identify(prbn_1)`` with the default choice (``model="auto"``), run free on stage A's
    other records, zeroed on each record's rest output (:func:`hystid.baselines.compare`).

    Returns
    -------
    dict
        ``max_heldout_rms`` (um, the worst record), ``share_under_60pc_linear`` (records where
        the model's RMS is under 0.6 of the linear model's), ``pi_stage`` (1.0 when the choice
        is the ``pi-stage`` member); empty when the records are absent.
    """
    from hystid.baselines import compare
    from hystid.identify import identify
    from hystid.records import load_record

    if not STAGE_A.exists():
        return {}
    recs = {p.stem: load_record(p) for p in sorted(STAGE_A.glob("*.csv"))}
    train = recs.pop("prbn_1")
    with quiet():
        res = identify(train, model="auto")
        rows = compare(res.model, train, list(recs.values())).rows
    return {"max_heldout_rms": max(r["model"] for r in rows),
            "share_under_60pc_linear": float(np.mean([r["model"] < 0.6 * r["linear"]
                                                      for r in rows])),
            "pi_stage": float(res.info.get("model") == "pi-stage")}
