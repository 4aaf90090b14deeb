"""The timed workloads of the regression benchmarks, shared by the asv suite and
``compare_commits.py``.

:func:`make` prepares a workload (records, models, compiled kernels) and returns the call to
time; preparing it is never part of the time. Every record is seeded.
"""

from __future__ import annotations

import copy
from collections.abc import Callable

from figures import quiet

from hystid.reference import reference_model, reference_record

#: Workload name -> what one call does.
WORKLOADS = {
    "simulate": "DuhemSandwich.simulate, 30 000 samples of the reference stage",
    "identify_batch": "off-line output error, 3 000 samples",
    "identify_online": "on-line RPEM fit, 30 000 samples (start-up solve included)",
    "identify_eria": "the paper's ERIA, 30 000 samples",
    "identify_ekf": "filterpy EKF, 3 000 samples",
    "identify_pi": "PI sandwich, recursive identifier, 6 000 samples",
    "online_update": "on-line identifier, 3 000 calls of update(u, y) after start-up",
    "online_partial_fit": "on-line identifier, partial_fit over the same 3 000 samples",
    "diagnose": "diagnosis of a 0.2 s + 0.2 s creep case, one refit per family",
    "compensate": "feed-forward inverse of a 1 s 50 Hz triangle, compiled",
    "closed_loop": "compiled closed loop (inverse + feedback), 1 s 50 Hz triangle",
}


def _identify(method: str, samples: int) -> Callable[[], object]:
    from figures import _identify as run

    rec = reference_record(samples / 30_000.0, seed=0, noise=1e-3)
    run(rec, method)  # compile outside the timing
    return lambda: run(rec, method)


def _online(per_sample: bool) -> Callable[[], object]:
    from hystid.identify.online import OnlineIdentifier

    rec = reference_record(0.2, seed=99)
    warm, rest = rec[:3_000], rec[3_000:]
    base = OnlineIdentifier()
    with quiet():
        base.fit(warm)
    u, y = rest.u.tolist(), rest.y.tolist()

    def steps() -> None:
        est = copy.deepcopy(base)
        update = est.update
        for a, b in zip(u, y, strict=True):
            update(a, b)

    def chunk() -> None:
        copy.deepcopy(base).partial_fit(rest)

    return steps if per_sample else chunk


def _diagnose() -> Callable[[], object]:
    import bench_withheld_effects as bw

    case = bw.make(("in-form", "creep", 1, 7), int(0.2 * bw.FS))
    with quiet():
        bw.run_case(case, "in-form", "medium", 7, time_budget=0.0)  # compile

    def run() -> None:
        with quiet():
            bw.run_case(case, "in-form", "medium", 7, time_budget=0.0)

    return run


def _compensate(closed: bool) -> Callable[[], object]:
    import hystid.compensate as hc

    model = reference_model()
    ref = hc.scan_reference("triangle", 50, periods=50)
    if closed:
        design = hc.design_feedback(model)
        hc.simulate_closed_loop(model, ref.y[:600], design)
        return lambda: hc.simulate_closed_loop(model, ref.y, design)
    hc.feedforward(model, ref.y[:600])
    return lambda: hc.feedforward(model, ref.y)


def make(name: str) -> Callable[[], object]:
    """Prepare workload ``name`` (a key of :data:`WORKLOADS`) and return the call to time.

    Parameters
    ----------
    name : str
        Workload.

    Returns
    -------
    callable
        Takes no argument.
    """
    if name == "simulate":
        model, u = reference_model(), reference_record(1.0, seed=0).u
        model.simulate(u)
        return lambda: model.simulate(u)
    if name.startswith("identify_"):
        method = name.split("_", 1)[1]
        samples = {"batch": 3_000, "ekf": 3_000, "pi": 6_000}.get(method, 30_000)
        return _identify(method, samples)
    if name in ("online_update", "online_partial_fit"):
        return _online(name == "online_update")
    if name == "diagnose":
        return _diagnose()
    if name in ("compensate", "closed_loop"):
        return _compensate(name == "closed_loop")
    raise ValueError(f"workload: expected one of {', '.join(WORKLOADS)}, got {name!r}")

