"""A dead time of several samples found as the structure change it is.

The fractional ``delay`` candidate refitted from the nominal model stays in that model's basin:
a dead time of a few samples bends L1 and L2 of the nominal fit to mimic it, and the refit's
cost has a minimum near every whole sample. :func:`delay_as_structure` identifies the nominal
model afresh with ``q1 + d`` (eq. 1) for the few ``d`` around the one whose linear start
simulates best, refits each with the fractional delay and keeps the best. The linear start
alone picks the dead time only to within a sample (its L1 is a guess), so the neighbours are
tried too; on a long train part they are compared on its head.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import replace

import numpy as np

from ..identify import identify
from ..identify.offline import linear_start
from ..model import DuhemSandwich, Structure
from ..records import Record
from .effects import EFFECTS
from .refit import FitData, RefitResult, refit

__all__ = [
    "HEAD_SAMPLES",
    "LINEAR_GAIN",
    "STRUCTURE_DELAYS",
    "WIDE_DELAYS",
    "delay_as_structure",
    "head",
    "identify_nominal",
    "linear_delay_costs",
]

#: Dead times (samples added to q1) scanned by the linear starts.
STRUCTURE_DELAYS = 24
#: The scan goes on to this many samples when its best is the last it tried (a dead time past
#: the scan's end); a best at the end of this one is reported at a bound.
WIDE_DELAYS = 4 * STRUCTURE_DELAYS
#: A dead time is worth fresh identifications when its linear start's mean squared error is
#: below this share of the nominal structure's.
LINEAR_GAIN = 0.9
#: Samples of the train part's head on which the dead times around the linear pick are compared
#: (the whole part when shorter).
HEAD_SAMPLES = 6000


#: Samples of a leading rest kept before the excitation in a head (:func:`head`).
HEAD_REST = 500


def head(data: FitData, n: int) -> FitData:
    """The first ``n`` samples of a train part's excitation, after at most :data:`HEAD_REST`
    samples of its leading rest (the part itself when shorter).

    Measured stage A's records rest for 10 001 samples: the first 6 000 samples held a
    constant input, and ``hystid diagnose`` stopped on it with "the input u is constant".

    Parameters
    ----------
    data : FitData
        A train part.
    n : int
        Samples to keep.

    Returns
    -------
    FitData
        The head, with the weight mask's samples over it.
    """
    if len(data.u) <= n:
        return data
    moved = np.flatnonzero(data.u != data.u[0])
    first = int(moved[0]) if moved.size else 0
    start = max(0, first - HEAD_REST)
    if len(data.u) - start <= n:
        start = len(data.u) - n
    mask = np.zeros(len(data.u), bool)
    mask[data.weight] = True
    stop = start + n
    return FitData(data.u[start:stop], data.y[start:stop], data.fs, data.level,
                   mask[start:stop])


def identify_nominal(tr: FitData, structure: Structure | None,
                     jumps: list[dict] | None = None,
                     say: Callable[[str], None] | None = None) -> DuhemSandwich:
    """The nominal identification: :func:`hystid.identify.identify` (batch) on the train part,
    which places the model at the record's rest level and sensor offset.

    Its fitted Duhem state at rest is not part of the model: the diagnosis' simulations start
    at the measured rest level instead (``initial='auto'`` or ``'level'``), which sets it.

    Parameters
    ----------
    tr : FitData
        The train part.
    structure : Structure or None
        Orders and delays; the identification's default when None.
    jumps : list, optional
        Receives the step of the measured output the identification found and took off
        (:mod:`hystid.identify.output_jumps`), if any.
    say : callable, optional
        Gets a progress line as each of the fit's starts is screened and polished (the
        fit's ``say``).

    Returns
    -------
    DuhemSandwich
        The identified model, named ``nominal sandwich``.
    """
    rec = Record(tr.u, tr.y, tr.fs, name="train")
    result = identify(rec, "batch", structure, model="duhem",
                      **({"say": say} if say is not None else {}))
    if jumps is not None and "output_jump" in result.info:
        jumps.append(result.info["output_jump"])
    model = result.model
    model.name = "nominal sandwich"
    return model


def linear_delay_costs(tr: FitData, structure: Structure,
                       delays: int = STRUCTURE_DELAYS, first: int = 0) -> dict[int, float]:
    """Mean squared error of the linear start (:func:`hystid.identify.offline.linear_start`)
    simulated with ``q1 + d``, for every ``d`` from ``first`` to ``delays``.

    Parameters
    ----------
    tr : FitData
        The train part.
    structure : Structure
        The nominal structure.
    delays : int
        Largest dead time tried, in samples.
    first : int
        Smallest dead time tried, in samples.

    Returns
    -------
    dict
        ``{d: cost}`` for the ``d`` whose start exists and simulates finitely.
    """
    rec = Record(tr.u, tr.y, tr.fs, name="train")
    costs: dict[int, float] = {}
    for d in range(first, delays + 1):
        sd = replace(structure, q1=structure.q1 + d)
        lin = linear_start(rec, sd)
        if lin is None:
            continue
        with np.errstate(all="ignore"):
            y = DuhemSandwich(lin, sd, fs=tr.fs).simulate(tr.u, check=False).y
            cost = float(np.mean((y - tr.y) ** 2)) if np.all(np.isfinite(y)) else np.inf
        if np.isfinite(cost):
            costs[d] = cost
    return costs


def _fresh(d: int, data: FitData, model: DuhemSandwich, phi: np.ndarray, active: Sequence[str],
           scales: tuple[float, float], refit_fn: Callable[..., RefitResult]) -> RefitResult:
    """The nominal model identified with ``q1 + d`` on ``data``, then refitted in the original
    structure with the fractional delay starting at ``d``."""
    s = model.structure
    fresh = identify_nominal(data, replace(s, q1=s.q1 + d))
    start = np.array(phi, float)
    start[EFFECTS["delay"].slots[0]] = d
    start[EFFECTS["offset"].slots[0]] = fresh.offset
    m = DuhemSandwich(fresh.theta, s, fs=data.fs, name=model.name)
    return refit_fn(m, data, [*active, "delay"], [start], base_phi=start, step_scale=scales[0],
                    w1_scale=scales[1])


def delay_as_structure(
    model: DuhemSandwich,
    phi: np.ndarray,
    active: Sequence[str],
    tr: FitData,
    rf: RefitResult,
    scales: tuple[float, float],
    say: Callable[[str], None],
    refit_fn: Callable[..., RefitResult] = refit,
) -> RefitResult:
    """The dead time as a structure change; kept when it fits the train part better than
    ``rf``.

    The linear starts pick the dead time ``d`` (:func:`linear_delay_costs`); when it is clearly
    better than none (:data:`LINEAR_GAIN`), the nominal model is identified afresh with
    ``q1 + d - 1``, ``q1 + d`` and ``q1 + d + 1`` and each refitted with the fractional delay
    (on the head of :data:`HEAD_SAMPLES` samples when the train part is longer; the best one is
    then identified and refitted on the whole part). The scan runs to :data:`STRUCTURE_DELAYS`
    and, when its best is its end, on to :data:`WIDE_DELAYS`; a best at the widened end is
    reported in the result's ``at_bound``.

    Parameters
    ----------
    model : DuhemSandwich
        The current model (its structure is kept; the delay is a parameter).
    phi : ndarray
        Its effect vector.
    active : sequence of str
        Forms already accepted (``drift`` at most).
    tr : FitData
        The train part.
    rf : RefitResult
        The delay refitted from the current model.
    scales : tuple of float
        Slew and level scales of the refits (largest ``|dw1|`` and ``|w1|``).
    say : callable
        Progress lines.
    refit_fn : callable, optional
        The refit (:func:`hystid.diagnose.refit.refit` by default).

    Returns
    -------
    RefitResult
        The better of ``rf`` and the structure refits.
    """
    costs = linear_delay_costs(tr, model.structure)
    if not costs:
        return rf
    ref = costs.get(0, np.inf)
    pick = min(costs, key=costs.__getitem__)
    bound: list[str] = []
    if pick == STRUCTURE_DELAYS:  # the best is the scan's end: the dead time may be longer
        say(f"the dead time's scan is best at its end (q1 + {pick}); scanning on to "
            f"q1 + {WIDE_DELAYS}")
        costs.update(linear_delay_costs(tr, model.structure, WIDE_DELAYS, STRUCTURE_DELAYS + 1))
        pick = min(costs, key=costs.__getitem__)
        if pick == max(costs):
            bound = [f"delay.dead time (q1 + {pick}, the end of the widened scan)"]
            say(f"the dead time's scan is best at its widened end (q1 + {pick})")
    if pick == 0 or not costs[pick] < LINEAR_GAIN * ref:
        rf.at_bound = [*rf.at_bound, *bound]
        return rf
    tried = [d for d in (pick, pick - 1, pick + 1) if d >= 1 and d in costs]
    data = head(tr, HEAD_SAMPLES)
    say(f"identifying the nominal structure with q1 + {', '.join(map(str, tried))}"
        + ("" if data is tr else f" on the first {len(data.u)} train samples"))
    found = [(_fresh(d, data, model, phi, active, scales, refit_fn), d) for d in tried]
    found = [(c, d) for c, d in found if c.ok]
    if found:
        best, d = min(found, key=lambda cd: cd[0].cost)
        if data is not tr:
            say(f"identifying the nominal structure with q1 + {d}")
            best = _fresh(d, tr, model, phi, active, scales, refit_fn)
        if best.ok and (not rf.ok or best.cost < rf.cost):
            rf = best
    rf.at_bound = [*rf.at_bound, *bound]  # reported with the candidate, kept or not
    return rf
