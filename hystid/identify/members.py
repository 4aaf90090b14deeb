"""The model family and the choice of a member by held-out error.

Every member is a sandwich with the same contract (python-control blocks, compiled simulate,
model file, placement, admissibility, an inverse for compensation); a member is a hysteresis
block, its structure and the fit that identifies it:

======================  ===================================================================
``duhem``               the paper's Duhem sandwich, experimental structure (eqs. 24-25)
``gduhem``              a generalised Duhem block (eq. 7 with a cubic anhysteretic curve
                        ``F(w1)`` and a quadratic slope ``G(w1)``, see :mod:`hystid.kernels`)
                        between a static L1 and a third-order L2
``pi``                  the paper's PI sandwich (eqs. 29-31, 40 plays), thresholds inside the
                        input's largest swing (:func:`hystid.thresholds.swing_thresholds`)
``pi-stage``            a PI operator of 20 plays between a static L1 and a third-order L2
                        (a flexure mode and a slow real pole, two zeros): the shape of a
                        5-10 kHz piezo stage, where one Duhem operator's loop is too rigid
``pi-poly``             ``pi-stage`` with memoryless terms ``c2 w1^2 + c3 w1^3`` beside the
                        plays: a sum of plays makes point-symmetric loops only, a measured
                        stage's are not (:attr:`hystid.pi.PIStructure.n_poly`)
``mduhem``              six Duhem operators of eq. (7) in parallel, their rates fixed on a
                        log grid over the training input's span and swings
                        (:mod:`hystid.mduhem`), between a first-order L1 lag and the
                        ``pi-stage`` member's L2; batch fit only
======================  ===================================================================

:func:`select_member` fits the candidates on the record but a block in the middle of its
excitation and scores their free run on that block; it keeps the simplest member that a richer
one does not beat by more than ``margin``, then fits that member on the whole record, started
from its fit without the block.
"""

from __future__ import annotations

import threading
import time
import warnings
from collections.abc import Callable, Sequence
from concurrent.futures import Future, ThreadPoolExecutor
from contextvars import ContextVar, copy_context
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..blas import one_blas_thread
from ..mduhem import MultiDuhemStructure
from ..model import Structure
from ..pi import PIStructure
from ..records import Record
from ..threads import cancellable, run_side_by_side, side_by_side, worker_count
from .result import IdentificationResult

__all__ = ["AUTO_CANDIDATES", "MEMBERS", "Member", "choice_shortfall", "member", "select_member"]


@dataclass(frozen=True)
class Member:
    """A member of the model family: a hysteresis block, its structure and its fit.

    Parameters
    ----------
    name : str
        The name ``identify(model=...)`` and ``hystid identify --model`` take.
    kind : {"duhem", "pi", "mduhem"}
        The hysteresis block.
    structure : Structure, PIStructure or MultiDuhemStructure
        Orders and delays of L1 and L2 (and the number of plays or operators).
    what : str
        One line for reports.
    settings : dict
        Settings of the batch fit (``thresholds=`` of the PI fits).
    """

    name: str
    kind: str
    structure: Structure | PIStructure | MultiDuhemStructure
    what: str
    settings: dict[str, Any] = field(default_factory=dict)

    @property
    def n_params(self) -> int:
        """Free parameters of the model (its complexity in :func:`select_member`)."""
        return len(self.structure.names)

    def fit(self, record: Record, method: str = "batch", *,
            progress: Callable[[int, int], None] | None = None,
            **settings: Any) -> IdentificationResult:
        """Identify this member on a record.

        Parameters
        ----------
        record : Record
            Input and measured output, in any units.
        method : {"batch", "online"}
            Off-line output error, or the member's on-line identifier (the ``mduhem`` member
            has none).
        progress : callable, optional
            ``progress(k, n)`` during long runs.
        **settings
            Passed to the fit (they win over the member's own settings).

        Returns
        -------
        IdentificationResult

        Raises
        ------
        ValueError
            For a method the member has no identifier for.
        """
        from . import identify

        if self.kind == "mduhem":
            if method != "batch":
                raise ValueError(f"method: the {self.name} member is identified by 'batch' "
                                 f"only (it has no on-line identifier), got {method!r}")
            from .mduhem_batch import fit_mduhem_output_error

            if "say" not in settings and callable(getattr(progress, "say", None)):
                settings = {**settings, "say": progress.say}
            return fit_mduhem_output_error(
                record, **{**self.settings, "structure": self.structure, **settings})
        if self.kind == "duhem":
            return identify(record, method=method, structure=self.structure,
                            progress=progress, **settings)
        from .pi_recursive import identify_pi

        if method == "batch":
            return identify_pi(record, "batch",
                               **{**self.settings, "structure": self.structure, **settings})
        return self._online(record, progress, settings)

    def _online(self, record: Record, progress: Callable[[int, int], None] | None,
                settings: dict[str, Any]) -> IdentificationResult:
        """The PI member's on-line identifier (:meth:`online_estimator`) on the record less its
        rest, placed back."""
        from . import run_placed

        return run_placed(record, lambda rel: self.online_estimator(record, **settings),
                          progress, zero_at_start=True)

    def online_estimator(self, record: Record, **settings: Any) -> Any:
        """The PI member's on-line identifier for a record, as ``identify(..., method="online")``
        configures it (not run); it is given the record less its rest.

        The thresholds by the member's rule over the record's fitted samples. The ``pi-stage``
        shape is :class:`~hystid.identify.pi_online.PIStageOnline` (its warm-up follows a
        short record; the model at the end of the record is its last re-solve's,
        ``settle_at_end``; no offset: the record it is given is already relative, and its
        estimate corrects it; the burn-in the batch fit leaves out of its cost, ``skip``, is
        run but not learned from), other PI
        structures the extended recursion
        :class:`~hystid.identify.pi_recursive.PIRecursiveIdentifier` (at rest at 0, no
        offset: the record it is given is already relative).

        Parameters
        ----------
        record : Record
            The record the thresholds and the warm-up are taken from.
        **settings
            Passed to the identifier's constructor.

        Returns
        -------
        PIStageOnline or PIRecursiveIdentifier
        """
        from ..thresholds import RULES
        from .pi_online import PIStageOnline
        from .pi_recursive import PIRecursiveIdentifier
        from .pi_stage_coordinates import is_stage_structure
        from .prepare import prepare

        if self.kind != "pi":
            raise ValueError(f"model: the {self.name} member has no PI on-line identifier")
        rule = self.settings.get("thresholds", "range")
        prep = prepare(record)
        r = RULES[rule](record.u[prep.fitted], self.structure.n_operators)
        base = {"thresholds": r, "structure": self.structure, "fs": record.fs}
        if is_stage_structure(self.structure):
            # the warm-up reaches past the default burn-in (a skip given is checked as given)
            warmup = short_record_warmup(record.u, self.n_params,
                                         0 if "skip" in settings else prep.skip)
            return PIStageOnline(**{**base, "warmup": warmup, "settle_at_end": True,
                                    "offset": 0.0, "skip": prep.skip,
                                    "left_out": left_out_spans(prep.weight, prep.skip),
                                    **settings})
        return PIRecursiveIdentifier(**{**base, "u_rest": 0.0, "offset": 0.0, **settings})


def left_out_spans(weight: np.ndarray, skip: int = 0) -> list[tuple[int, int]]:
    """The spans ``[first, stop)`` of samples a batch fit leaves out of its cost (``weight``
    false), after the burn-in of ``skip`` samples.

    Parameters
    ----------
    weight : ndarray of bool
        The samples the batch fit scores (:func:`~hystid.identify.prepare.prepare`).
    skip : int
        The burn-in, left out already.

    Returns
    -------
    list of (int, int)
        The spans, in order.
    """
    out = np.r_[False, ~np.asarray(weight, bool), False]
    out[1:skip + 1] = False
    edges = np.flatnonzero(np.diff(out.astype(np.int8)))
    return [(int(a), int(b)) for a, b in zip(edges[::2], edges[1::2], strict=True)]


#: Warm-up of the ``pi-stage`` on-line identifier, in excited samples (0.2 s at 10 kHz), and
#: the share of a shorter record's excitation it takes instead (a 200 Hz stage's record of a
#: few seconds holds a few hundred samples: the warm-up fit takes its first half, the recursion
#: and re-solves the rest), never under :data:`WARMUP_PER_PARAMETER` samples per parameter.
WARMUP = 2000
WARMUP_SHARE = 0.5
WARMUP_PER_PARAMETER = 5


def short_record_warmup(u: np.ndarray, n_params: int, skip: int = 0) -> int:
    """Warm-up of the ``pi-stage`` on-line identifier for a record's input.

    Parameters
    ----------
    u : ndarray
        The record's input.
    n_params : int
        Parameters of the member.
    skip : int
        Leading samples run but not learned from (the burn-in of a record that does not begin
        at rest).

    Returns
    -------
    int
        :data:`WARMUP`, or :data:`WARMUP_SHARE` of the excited samples (those from the first
        that leaves ``u[0]``) when that is fewer, but at least
        :data:`WARMUP_PER_PARAMETER` ``n_params`` of them after ``skip`` (a record too short
        for that is refused by the identifier, which says so). A piece of measured stage A's
        ``prbn_1`` cut 0.05 s into its excitation has a burn-in of 2 375 samples, longer than
        :data:`WARMUP`: the warm-up had nothing left to learn from and ``identify(...,
        method="online")`` refused the record.
    """
    u = np.asarray(u, float)
    moved = np.flatnonzero(np.abs(u - u[0]) > 0.0) if u.size else np.array([], int)
    first = int(moved[0]) if moved.size else u.size
    excited = u.size - first
    least = WARMUP_PER_PARAMETER * n_params
    return int(max(least, min(WARMUP, WARMUP_SHARE * excited), skip - first + least))


#: Evaluations of a PI member's polishing solve. On stage A's records the fit's optimum is the
#: same (to the last digit of its residual and held-out RMS) with 30, 60 or 200 evaluations;
#: with more the solver only spends time short of its 1e-8 tolerances.
PI_NFEV = 40

#: Duhem operators of the ``mduhem`` member. Six against the structure's default four: on
#: measured stage A 28-39 nm held out against 34-45 nm; on simulated Preisach and Maxwell-slip
#: stages 1-2 % less; on two Bouc-Wen stages 19-46 % less on five of six records, 16 % more on
#: one; a fit of 1-2 s either way on stage A.
MDUHEM_OPERATORS = 6

#: The members, simplest first.
MEMBERS: dict[str, Member] = {m.name: m for m in (
    Member("duhem", "duhem", Structure(),
           "Duhem sandwich, the paper's experimental structure (eqs. 24-25)"),
    Member("gduhem", "duhem",
           Structure(n1a=0, n1b=0, q1=0, n2a=3, n2b=2, q2=1, f_order=3, g_order=2),
           "generalised Duhem (cubic anhysteretic curve, quadratic slope), static L1, "
           "third-order L2"),
    Member("pi", "pi", PIStructure(),
           "PI sandwich, the paper's structure (eqs. 29-31), thresholds within the largest swing",
           {"thresholds": "swing", "max_nfev": PI_NFEV}),
    Member("pi-stage", "pi",
           PIStructure(n_operators=20, n1a=0, n1b=1, q1=0, n2a=3, n2b=3, q2=1),
           "PI operator of 20 plays, static L1, third-order L2 (mode + slow pole)",
           {"thresholds": "swing", "max_nfev": PI_NFEV}),
    Member("pi-poly", "pi",
           PIStructure(n_operators=20, n1a=0, n1b=1, q1=0, n2a=3, n2b=3, q2=1, n_poly=2),
           "the pi-stage member with quadratic and cubic terms beside the plays (asymmetric "
           "loops)", {"thresholds": "swing", "max_nfev": PI_NFEV}),
    Member("mduhem", "mduhem", MultiDuhemStructure(n_operators=MDUHEM_OPERATORS),
           f"{MDUHEM_OPERATORS} Duhem operators in parallel, rates on a log grid, first-order "
           "L1 lag, third-order L2"),
)}

#: The members ``model="auto"`` chooses between (the paper's PI sandwich is left out: on the
#: records measured so far it never beat both of these, and it is the slowest to fit; the
#: ``mduhem`` member is fast, 1-2 s on stage A's 20 001 samples, but loses to ``pi-stage``
#: there while counting fewer parameters, so the choice could take it within its margin).
AUTO_CANDIDATES = ("duhem", "pi-stage")

#: Threads :func:`select_member` runs its fits in when it is given none (None: the cores, at
#: most :data:`~hystid.threads.MAX_WORKERS`); :func:`hystid.identify.identify`'s ``workers``
#: sets it for the call.
CHOICE_WORKERS: ContextVar[int | None] = ContextVar("CHOICE_WORKERS", default=None)

#: Share of the excitation (after the leading rest) held out for the choice.
HOLDOUT = 0.3
#: Evaluations of the whole-record fit started from the fit without the held-out block (it
#: starts close).
REFIT_NFEV = 30
#: A richer member is chosen only when it beats a simpler one by more than this share.
MARGIN = 0.1


def member(name: str) -> Member:
    """The member of that name.

    Parameters
    ----------
    name : str
        A key of :data:`MEMBERS`.

    Returns
    -------
    Member

    Raises
    ------
    ValueError
        Naming the members there are.
    """
    if name not in MEMBERS:
        raise ValueError(f"model: expected 'auto' or one of {', '.join(MEMBERS)}, got {name!r}")
    return MEMBERS[name]


def _say(progress: Any, message: str) -> None:
    say = getattr(progress, "say", None)
    if say is not None:
        say(message)


def _block(record: Record, holdout: float) -> tuple[int, int, np.ndarray]:
    """The held-out block ``[first, stop)``: ``holdout`` of the samples a fit learns from after
    the leading rest, in their middle (on a record in motion, its end); and which
    of its samples the choice scores: those the record's preparation keeps (an output burst or
    spike there is left out, as the fits leave it out).

    A block in the middle is scored on inputs inside the envelope the fits learn from, with
    the state the free run brings into it, as another record of the same range is. The last
    ``holdout`` of the record, held out until 2026-11, scored extrapolation where a record's
    amplitude grows (stage A's records reach their widest swing at their end): there the
    Duhem sandwich and ``pi-stage`` came within the margin on a sine (57 against 54 nm), and
    the Duhem sandwich, chosen, was 128-130 nm off the PRBN records against ``pi-stage``'s 69;
    on the block, 24 against 20 nm (``benchmarks/bench_stage_a.py --train sine50_1``).

    A record that does not begin at rest keeps the end held out: there the fits leave out a
    burn-in and the PI members estimate a drift of the sensor's zero, and on the block of cuts
    of stage A's ``prbn_1`` and of the stage-A look-alike (``benchmarks/bench_rest_unseen.py``)
    the choice took ``pi-stage`` on four of seven, whose whole-record fits were up to 0.38 um
    (stage A) and 4.9 um (the look-alike) off records that begin at rest, where the choice on
    the end is at most 0.15 and 0.044 um off.
    """
    from .prepare import held_out_from, prepare

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        prep = prepare(record)
    stop = last = prep.fitted.stop
    first = held_out_from(record.u, holdout, stop)  # the end
    if prep.at_rest:
        start = max(held_out_from(record.u, 1.0, stop), prep.fitted.start)
        first = start + int(round(0.5 * (1.0 - holdout) * (stop - start)))
        last = min(stop, first + max(1, int(round(holdout * (stop - start)))))
    weight = np.asarray(prep.weight, bool)[first:last]
    scored = weight if np.count_nonzero(weight) >= 0.5 * len(weight) else np.ones_like(weight)
    return first, last, scored


def choice_shortfall(record: Record, candidates: Sequence[str] = AUTO_CANDIDATES,
                     holdout: float = HOLDOUT) -> str | None:
    """Why ``record`` is too short for :func:`select_member` to choose, or None.

    The choice fits every candidate on the excitation but a block of ``holdout`` of it, which
    must leave ten samples per parameter of the richest candidate.

    Parameters
    ----------
    record : Record
        The record to choose on.
    candidates : sequence of str
        Names in :data:`MEMBERS`.
    holdout : float
        Share of the excitation held out.

    Returns
    -------
    str or None
        The reason, with the figures, or None when the record is long enough.
    """
    from . import SAMPLES_PER_PARAMETER
    from .prepare import held_out_from

    lead = held_out_from(record.u, 1.0)  # the leading rest: all the excitation held out
    excited = record.n - lead
    richest = max(member(c).n_params for c in candidates)
    need = SAMPLES_PER_PARAMETER * richest
    fitted = held_out_from(record.u, holdout) - lead
    if fitted >= need:
        return None
    return (f"record {record.name!r}: {excited} samples of excitation leave {fitted} to fit the "
            f"candidates on, {holdout:.0%} held out (expected at least {need}: ten "
            f"per parameter of the richest candidate, {richest})")


def _heldout_rms(model: Any, record: Record, k: int, stop: int, scored: np.ndarray) -> float:
    from ..baselines import simulate_from_rest

    with np.errstate(all="ignore"):
        yhat = simulate_from_rest(model, record.u, check=False)
        rms = float(np.sqrt(np.mean((yhat[k:stop] - record.y[k:stop])[scored] ** 2)))
    return rms if np.isfinite(rms) else float("inf")


def _whole_fit(name: str, record: Record, block_fit: IdentificationResult,
               settings: dict, workers: int | None = None, ahead: _AheadFits | None = None,
               ) -> IdentificationResult:
    """A member fitted on the whole record; a PI member twice, started from its fit without the
    held-out block and from its own starts, keeping the fit with the lower residual (the same
    cost on the same samples).

    Started from a fit on part of the record alone, the search stayed in that fit's basin: on
    measured stage A's ``prbn_1`` with its rest cut to 0.1 s or 62 ms, a fit on the first 70 %
    of its excitation (the choice's part until 2026-11)
    put ``pi-stage``'s slow pole at 0.9993 or 0.9964 instead of 0.99987, and the whole fit
    from there left 51 or 50 nm of residual where a fit from the member's own starts leaves
    26-27 (73-107 nm held out on the other five records against 25-36). The fit from its own
    starts is taken from ``ahead`` when it was started there (:class:`_AheadFits`); else the
    two fits run side by side in ``workers`` threads (:func:`~hystid.threads.run_side_by_side`).
    """
    if MEMBERS[name].kind != "pi":
        return MEMBERS[name].fit(record, **settings)
    def from_block() -> IdentificationResult:
        return MEMBERS[name].fit(record, **{"theta0": block_fit.model.theta,
                                            "max_nfev": REFIT_NFEV, **settings})
    own = ahead.result(name) if ahead is not None else None
    if own is not None:
        fits = [from_block(), own.result()]
        if fits[1] is None:  # cancelled after all
            fits[1] = MEMBERS[name].fit(record, **settings)
    else:
        fits = run_side_by_side([from_block, lambda: MEMBERS[name].fit(record, **settings)],
                                workers, "hystid-choice")
    return min(fits, key=lambda r: r.info["rms_residual"])


class _AheadFits:
    """The whole-record fits of a choice's PI candidates from their own starts, started in the
    choice's pool behind its block fits, before the choice is made: such a fit does not depend
    on the block, and on two cores it runs while the block fits finish instead of after them
    (on stage A's ``sine50_1`` the choice took 3.5x the Duhem fit's time, ``pi-stage``'s two
    whole-record fits side by side half of it). The candidates not chosen are cancelled
    (:func:`~hystid.threads.cancellable`); the fits and so the model are the same as without.

    Parameters
    ----------
    jobs : ThreadPoolExecutor
        The choice's pool.
    members : list of Member
        The candidates; the PI ones are started.
    record : Record
        The record.
    settings : dict
        The batch fits' settings.
    """

    def __init__(self, jobs: ThreadPoolExecutor, members: list[Member], record: Record,
                 settings: dict) -> None:
        self.events: dict[str, threading.Event] = {}
        self.futures: dict[str, Future] = {}
        for m in members:
            if m.kind == "pi":
                self.events[m.name] = event = threading.Event()
                call = cancellable(lambda m=m: m.fit(record, **settings), event)
                self.futures[m.name] = jobs.submit(copy_context().run, call)

    def keep_only(self, name: str | None) -> None:
        """Cancel every fit but ``name``'s (all of them with None)."""
        for other, event in self.events.items():
            if other != name:
                event.set()

    def result(self, name: str) -> Future | None:
        """The future of ``name``'s fit, unless it was not started or was cancelled."""
        event = self.events.get(name)
        return None if event is None or event.is_set() else self.futures[name]


def _block_fits(members: list[Member], record: Record, block: tuple[int, int], settings: dict,
                progress: Callable[[int, int], None] | None, jobs: ThreadPoolExecutor,
                ) -> list[Future]:
    """Each candidate fitted on the record with the held-out ``block`` left out of its cost,
    with its own seconds, and last the linear baseline (third order) fitted alike, submitted
    to ``jobs`` (each in a copy of the caller's context, as
    :func:`~hystid.threads.run_side_by_side` runs them)."""
    from ..baselines import LinearModel

    left_out = [*settings.get("left_out", ()), block]
    def fit(m: Member) -> Callable[[], tuple[IdentificationResult, float]]:
        def run() -> tuple[IdentificationResult, float]:
            t0 = time.perf_counter()
            return (m.fit(record, **{**settings, "left_out": left_out}),
                    time.perf_counter() - t0)
        return run

    for m in members:
        _say(progress, f"model choice: fitting {m.name} with samples {block[0]}..{block[1] - 1} "
             "held out")
    return [jobs.submit(copy_context().run, call)
            for call in (*(fit(m) for m in members),
                         lambda: LinearModel.fit(record, 3, 3, 1, left_out=left_out))]


def _rate_checked(record: Record, name: str, result: IdentificationResult, chosen: dict,
                  eligible: list[dict], fits: dict, settings: dict,
                  progress: Callable[[int, int], None] | None, workers: int | None = None,
                  ahead: _AheadFits | None = None) -> tuple[str, IdentificationResult, dict]:
    """On a record at one rate: when the chosen member's whole-record fit moves with the rate
    (its fit without the block did not), the next eligible candidate by held-out RMS whose
    whole-record fit does not, if any; the chosen row records its whole fit's figure."""
    from .rates import RATE_LIMIT, rate_dependence

    chosen["rate_dependence_whole"] = rate_dependence(result.model, record.u, record.y)
    if chosen["rate_dependence_whole"] <= RATE_LIMIT:
        return name, result, chosen
    for r in sorted(eligible, key=lambda r: r["heldout_rms"]):
        if r is chosen:
            continue
        _say(progress, f"model choice: {name} fitted on the whole record moves with the rate "
             f"({chosen['rate_dependence_whole']:.2g}); trying {r['member']}")
        other = _whole_fit(r["member"], record, fits[r["member"]], settings, workers, ahead)
        r["rate_dependence_whole"] = rate_dependence(other.model, record.u, record.y)
        if r["rate_dependence_whole"] <= RATE_LIMIT:
            chosen["left_out"] = (f"fitted on the whole record, its output moves by "
                                  f"{chosen['rate_dependence_whole']:.2g} times the record's "
                                  "spread at twice or half the rate")
            return r["member"], other, r
    return name, result, chosen


def _rate_eligible(record: Record, rows: list[dict], fits: dict,
                   progress: Callable[[int, int], None] | None) -> list[dict]:
    """The candidates the choice is made among: all of them, except, on a record driven at one
    rate (:func:`~hystid.identify.rates.runs_at_one_rate`), those whose output moves with the rate
    (:func:`~hystid.identify.rates.rate_dependence` above
    :data:`~hystid.identify.rates.RATE_LIMIT`) while another's does not: the held-out block, at
    the same rate, cannot tell them apart. Each row gets its figure and, when left out, why."""
    from .rates import RATE_LIMIT, rate_dependence, runs_at_one_rate

    if not runs_at_one_rate(record.u, record.fs):
        return rows
    for r in rows:
        r["rate_dependence"] = rate_dependence(fits[r["member"]].model, record.u, record.y)
    eligible = [r for r in rows if r["rate_dependence"] <= RATE_LIMIT]
    if not eligible:
        return rows
    for r in rows:
        if r["rate_dependence"] > RATE_LIMIT:
            r["left_out"] = (f"the input runs at one rate and its output moves by "
                             f"{r['rate_dependence']:.2g} times the record's spread at twice "
                             "or half that rate")
            _say(progress, f"model choice: {r['member']} left out: {r['left_out']}")
    return eligible


#: Candidates whose held-out RMS is within this factor of the best are taken as plausible by
#: :func:`_undetermined`.
PLAUSIBLE = 1.5
#: The chosen candidate and a plausible other that differ on the probe input by more than this
#: many times the larger of their held-out RMS errors: the record does not determine the model.
#: Measured (:mod:`hystid.identify.agreement`, seed 0) on the held-out block: identified on
#: stage A's triangle and sine records 13-25 (where the
#: Duhem sandwich is 1.3-4.9x ``pi-stage`` off the other records); on its PRBN records 4.7-5.6
#: (where the two are 1.3-1.5x apart on the block, plausible, and the Duhem sandwich is 2.2-2.5x
#: ``pi-stage`` off the other records: the record does determine the model); on the Bouc-Wen
#: look-alike of stage A 1.3-5.2, and 20.6 on one sine. With the held-out end (until 2026-11)
#: the held-out errors were larger and the same pairs 2.7-10.7; the limit was 3.
DISAGREE = 8.0


def _undetermined(record: Record, chosen: dict, rows: list[dict], fits: dict) -> str | None:
    """The warning when a plausible candidate (held-out RMS within :data:`PLAUSIBLE` of the
    best) and the chosen one differ on an input with other reversals inside the record's range
    (:func:`~hystid.identify.agreement.disagreement`) by more than :data:`DISAGREE` times their
    held-out errors; each plausible row gets its figure."""
    from .agreement import disagreement

    best = min(r["heldout_rms"] for r in rows)
    worst = None
    for r in rows:
        if r is chosen or not r["heldout_rms"] <= PLAUSIBLE * best:
            continue
        d = disagreement(fits[chosen["member"]].model, fits[r["member"]].model, record.u,
                         record.fs)
        r["disagreement"] = d
        ratio = d / max(chosen["heldout_rms"], r["heldout_rms"])
        if ratio > DISAGREE and (worst is None or ratio > worst[0]):
            worst = (ratio, r, d)
    if worst is None:
        return None
    ratio, r, d = worst
    unit = record.units.get("y") or "output units"
    return (f"the record does not determine the model: {chosen['member']} and {r['member']} "
            f"are {chosen['heldout_rms']:.3g} and {r['heldout_rms']:.3g} {unit} off its held-out "
            f"block, which repeats the record's own reversals, but differ by {d:.3g} {unit} "
            f"({ratio:.1f}x) on an input with reversals of every size inside its range; "
            "validate the model on another input, or identify on one with a broad spectrum of "
            "reversals (PRBN)")


def _scored(members: list[Member], block_fits: list[tuple[IdentificationResult, float]],
            linear: Any, record: Record, block: tuple[int, int, np.ndarray],
            progress: Callable[[int, int], None] | None,
            ) -> tuple[list[dict], dict[str, IdentificationResult], dict[str, float]]:
    """The choice's table: a row per candidate with its held-out RMS on the block's scored
    samples, the fits by name, and the static line's and the linear model's held-out RMS."""
    from ..baselines import StaticLine

    k, stop, scored = block
    rows, fits = [], {}
    for m, (fit, seconds) in zip(members, block_fits, strict=True):
        fits[m.name] = fit
        rows.append({"member": m.name, "what": m.what, "n_params": m.n_params,
                     "heldout_rms": _heldout_rms(fit.model, record, k, stop, scored),
                     "seconds": seconds})
        _say(progress, f"model choice: {m.name} held-out RMS {rows[-1]['heldout_rms']:.4g} "
             f"{record.units.get('y', '')} on samples {k}..{stop - 1}")
    y = record.y[k:stop][scored]
    line = StaticLine.fit(record, left_out=[(k, stop)])
    baselines = {"static_line": line.predict(record.u)[k:stop][scored],
                 "linear": linear.predict(record.u)[k:stop][scored]}
    return rows, fits, {b: float(np.sqrt(np.mean((p - y) ** 2))) for b, p in baselines.items()}


@one_blas_thread
def select_member(
    record: Record,
    candidates: Sequence[str] = AUTO_CANDIDATES,
    *,
    holdout: float = HOLDOUT,
    margin: float = MARGIN,
    progress: Callable[[int, int], None] | None = None,
    workers: int | None = None,
    **settings: Any,
) -> IdentificationResult:
    """Choose a member by held-out error inside the record and fit it on the whole record.

    The steps:

    1. hold out a block of ``holdout`` of the samples after the leading rest, in their middle
       (:func:`_block`);
    2. fit every candidate (batch) on the rest of the record, the block simulated but left
       out of the cost, side by side in threads;
    3. score each on the block (free run of the whole record from rest), beside the static
       line and the linear model fitted on the same samples; on a record driven at one rate,
       leave out a candidate whose output moves with the rate while another's does not (the
       block cannot tell them apart; :mod:`hystid.identify.rates`);
    4. keep the simplest candidate (fewest parameters) whose held-out RMS is within
       ``1 + margin`` of the best;
    5. fit it on the whole record (a PI member from its fit without the block and from its
       own starts, the lower residual kept: :func:`_whole_fit`; on more than one thread the
       fit from its own starts runs ahead of the choice, behind the block fits, and is
       cancelled when another member is chosen: :class:`_AheadFits`);
    6. warn when a plausible candidate differs from the chosen one on an input with other
       reversals than the record's (:func:`_undetermined`).

    Parameters
    ----------
    record : Record
        Input and measured output, in any units.
    candidates : sequence of str
        Names in :data:`MEMBERS`.
    holdout : float
        Share of the excitation held out, in (0, 0.5].
    margin : float
        Relative improvement a richer member needs to be chosen.
    progress : callable, optional
        Progress lines (its ``say`` method, when it has one, gets one line per step).
    workers : int, optional
        Threads the candidates' fits (and a PI member's two whole-record fits) run in: by
        default :data:`CHOICE_WORKERS` when set, else the cores, at most
        :data:`~hystid.threads.MAX_WORKERS`. The choice and the model do not depend on it.
    **settings
        Passed to every batch fit (``offset``, ``skip``...).

    Returns
    -------
    IdentificationResult
        The chosen member's fit on the whole record; ``info["member_selection"]`` holds every
        candidate's held-out RMS, the baselines' and the choice, and ``undetermined``, the
        warning (also in ``info["warnings"]``) when a plausible candidate differs from the
        chosen one on other reversals by far more than the held-out block shows
        (:data:`DISAGREE`; :mod:`hystid.identify.agreement`).
    """

    if not 0.0 < holdout <= 0.5:
        raise ValueError(f"holdout: expected a share in (0, 0.5], got {holdout!r}")
    members = [member(c) for c in candidates]
    if not members:
        raise ValueError("candidates: expected at least one member")
    short = choice_shortfall(record, candidates, holdout)
    if short is not None:
        raise ValueError(f"{short}; a member can be fitted without the choice (model='duhem', "
                         "hystid identify --model duhem)")
    if workers is None:
        workers = CHOICE_WORKERS.get()
    k, stop, scored = _block(record, holdout)
    n_workers = worker_count(workers)
    with side_by_side(n_workers, "hystid-choice") as jobs:
        futures = _block_fits(members, record, (k, stop), settings, progress, jobs)
        # on one thread a fit ahead would only delay the choice
        ahead = _AheadFits(jobs, members, record, settings) if n_workers > 1 else None
        try:
            *block_fits, linear = (f.result() for f in futures)
            rows, fits, baseline_rms = _scored(members, block_fits, linear, record,
                                               (k, stop, scored), progress)
            eligible = _rate_eligible(record, rows, fits, progress)
            best = min(r["heldout_rms"] for r in eligible)
            chosen = min((r for r in eligible if r["heldout_rms"] <= (1.0 + margin) * best),
                         key=lambda r: r["n_params"])
            for r in rows:
                r["chosen"] = r is chosen
            name = chosen["member"]
            if ahead is not None:
                ahead.keep_only(name)
            _say(progress, f"model choice: {name}; fitting it on the whole record")
            result = _whole_fit(name, record, fits[name], settings, workers, ahead)
        finally:
            if ahead is not None:
                ahead.keep_only(None)  # on an error, no fit runs on behind it
    if "rate_dependence" in chosen:
        name, result, chosen = _rate_checked(record, name, result, chosen, eligible, fits,
                                             settings, progress, workers)
        for r in rows:
            r["chosen"] = r is chosen
        result.info["rate_dependence"] = chosen["rate_dependence_whole"]
    undetermined = _undetermined(record, chosen, rows, fits)
    if undetermined:
        result.info["warnings"] = list(result.info.get("warnings", [])) + [undetermined]
    result.info["member_selection"] = {
        "chosen": name, "holdout_from": int(k), "holdout_to": int(stop), "margin": margin,
        "candidates": rows, "baselines": baseline_rms, "undetermined": undetermined,
        "beats_baselines": bool(chosen["heldout_rms"] < min(baseline_rms.values()))}
    result.info["model"] = name
    return result
