"""The diagnosis of the sim-to-real gap: where it lies, which effect causes it, how far it shrinks.

:func:`diagnose` identifies (or takes) the nominal sandwich on a train record, localises its
held-out simulation error (:mod:`.where`), screens the candidate effects (:mod:`.effects`,
:mod:`.screen`), refits the promising ones from the nominal estimate (:mod:`.refit`) and accepts
one only when it lowers the held-out error significantly for coloured residuals and by a margin
worth having. Greedy: the best accepted effect (the simplest one that no other beats) joins the
model, the error is localised again and the remaining candidates are screened against it, until
none passes.

The drift is a nuisance of every record, re-estimated on each held-out record, while the other
forms are fixed from the train record. When both pass, they are compared like with like: the
drift goes first only when the best input-tied form neither explains anything beyond each
record's own drift (both fitted on the held-out samples) nor predicts the held-out records
better than a drift scored on samples it was not fitted on (neither fitted on the samples
scored; :func:`_drift_out_of_sample`). A creep follows the input and is predicted; a drift is
not.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable, Sequence
from concurrent.futures import Future, ThreadPoolExecutor
from contextvars import copy_context
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from ..blas import one_blas_thread
from ..identify.result import IdentificationResult
from ..metrics import gap_closed
from ..model import DuhemSandwich, Structure
from ..records import Record
from ..threads import cancellable, side_by_side, worker_count
from ..validate import check_plain_duhem
from .effects import EFFECTS, AugmentedSandwich, effect_dict
from .final_model import fit_member, member_records
from .greedy import GreedyRounds, Settings, Start
from .refit import FitData, refit
from .result import DiagnosisResult, EffectOutcome
from .rounds import (
    ALIKE,
    DEFAULT_EFFECTS,
    IN_NOMINAL,
    MIN_TRAIN_SAMPLES,
    MIN_VAL_SAMPLES,
    DiagnosisError,
    _admissibility,
    _as_records,
    _check_inputs,
    _cost_mask,
    _Evaluator,
    _expand_families,
    _Progress,
    _rank,
    _repeat_floor,
    _split,
    describe_unexplained,
)
from .screen import effect_names_check, zero_vector
from .structure import head as _head
from .structure import identify_nominal as _identify
from .where import localise

__all__ = [
    "ALIKE",
    "DEFAULT_EFFECTS",
    "IN_NOMINAL",
    "MAX_ROUNDS",
    "MIN_TRAIN_SAMPLES",
    "MIN_VAL_SAMPLES",
    "DiagnosisError",
    "DiagnosisResult",
    "EffectOutcome",
    "diagnose",
]

#: Most greedy rounds a diagnosis runs (``max_rounds``; ``hystid diagnose --max-rounds``).
MAX_ROUNDS = 20

# --------------------------------------------------------------------------- main entry
#: Round 1's time for further forms, as a multiple of the nominal identification's time. With
#: the refits' compiled sensitivities and folded solve, half the nominal fit's time holds 11-12
#: refits on measured stage A (20 001 + 20 001 samples), more than the whole of it held before
#: them (8-10); the accepted effect and every final figure are the same at 1.0, 0.5 and 0
#: (each family's most promising form only), and the diagnosis with its final model took
#: 2.97-3.04x the nominal fit against 3.29-3.39x at 1.0
#: (``python benchmarks/bench_stage_a_diagnosis.py``). Since the plain sandwich's kernels run
#: their sample loop in one compiled function the nominal fit is twice as fast and the ratio
#: was 4.3-4.8x: the refits' augmented kernel did not speed up alike. The refits now run side
#: by side (:data:`~hystid.threads.MAX_WORKERS`), so within the budget more of them are
#: started on two cores than on one.
BUDGET_FACTOR = 0.5


@one_blas_thread
def diagnose(
    train: Record,
    val: Record | Sequence[Record] | None = None,
    model: DuhemSandwich | IdentificationResult | None = None,
    *,
    structure: Structure | None = None,
    effects: Sequence[str] = DEFAULT_EFFECTS,
    repeats: Sequence[Record] | None = None,
    holdout: float = 0.4,
    alpha: float = 0.01,
    min_reduction: float = 0.02,
    max_rounds: int = 3,
    transient: float = 0.0017,
    train_skip: float = 0.0,
    initial: str = "auto",
    refit_all: bool = False,
    min_gap_share: float = 0.1,
    min_gap_share_later: float = 0.25,
    refit_samples: int | None = None,
    time_budget: float | None = None,
    budget_factor: float | None = BUDGET_FACTOR,
    require_excitation: bool = False,
    members: Sequence[str] = (),
    workers: int | None = None,
    progress: bool | Callable[[str], None] = True,
) -> DiagnosisResult:
    """Diagnose the sim-to-real gap of the Duhem sandwich on measured records.

    Parameters
    ----------
    train : Record
        Record to identify on (it starts at rest unless ``initial='level'``).
    val : Record or sequence of Record, optional
        Held-out records. Without them the last ``holdout`` share of ``train``'s excitation
        (after its leading rest, :func:`~hystid.identify.prepare.held_out_from`) is held out
        (the model runs through the whole record; only the head is fitted).
    model : DuhemSandwich or IdentificationResult, optional
        The model to diagnose; identified on ``train`` by :func:`hystid.identify.identify`
        (batch: sensor offset and rest level estimated) when omitted. It is then refitted
        alone, so that candidates are compared with a model fitted the same way. Its
        ``u_rest`` is taken off the input and its ``offset`` is the sensor-offset parameter.
    structure : Structure, optional
        Structure for the identification; the paper's experimental one by default.
    effects : sequence of str
        Candidate families or forms (all of :data:`DEFAULT_EFFECTS` by default); a family name
        stands for all its forms. The sensor offset is a parameter of the nominal model.
    repeats : sequence of Record, optional
        Records of the same input as ``train`` or a held-out record: the floor of the gap is
        then the repeatability (:func:`hystid.baselines.repeat_floor`) when it is above the
        sensor noise.
    holdout : float
        Share of ``train``'s excitation held out when no ``val`` is given.
    alpha : float
        Family-wise level of the held-out test in each round (Bonferroni over the candidates
        refitted in that round).
    min_reduction : float
        Smallest relative reduction of the held-out RMS worth having (0.02 = 2 %).
    max_rounds : int
        Greedy rounds at most (1 to :data:`MAX_ROUNDS`).
    transient : float
        Seconds dropped at the start of each separate held-out record (the paper's 0.0017 s).
    train_skip : float
        Seconds at the start of the train record simulated but left out of the refits' cost
        (an initial state the model cannot represent); the nominal model is then refitted alone
        with the same cost before the candidates are compared with it.
    initial : {'auto', 'rest', 'level'}
        ``rest``: records start at rest at zero output. ``level``: at rest at the mean output
        measured before the input first moves (the Duhem state holds the remanent value, as
        the identification's fitted state at rest). ``auto`` (default): ``level`` for a record
        that starts with 10 samples at rest, ``rest`` otherwise.
    refit_all : bool
        Refit every excited form, not only the promising ones.
    min_gap_share : float
        Smallest share of the nominal model's gap (to the floor) a form must close to be
        accepted in the first round.
    min_gap_share_later : float
        The same in later rounds: a further effect must explain a good part of the gap, not
        what the first form's imperfect fit leaves.
    refit_samples : int, optional
        Compare the forms on refits over the first ``refit_samples`` train samples only (the
        model they are compared with refitted on the same span); an accepted form is then
        refitted on the whole train part and must pass again. Bounds the cost on long records
        whose head is well excited (all samples by default).
    time_budget : float, optional
        Seconds from the start of the first round's refits after which no further form is
        refitted; the most promising form of every family that the screen cannot rule out is
        refitted in any case, most promising first.
    budget_factor : float or None
        Without ``time_budget``: that time as a multiple of the nominal identification's
        (:data:`BUDGET_FACTOR` by default; None for no limit). Forms left out are reported as
        ``not refitted``.
    require_excitation : bool
        Raise :class:`DiagnosisError` when a candidate cannot be shown by the records instead
        of reporting it as not excited.
    members : sequence of str
        Members of :data:`hystid.identify.members.MEMBERS` to identify beside the rounds, as
        candidates for the hysteresis itself (on the train record, or its head without
        held-out records); the result's ``members`` hold them for
        :func:`~hystid.diagnose.final_model.final_model` (``hystid diagnose --out`` passes
        its members). None by default.
    workers : int, optional
        Threads the member fits and each round's refits run in (the cores, at most
        :data:`~hystid.threads.MAX_WORKERS`, by default). The result does not depend on it,
        except through the time budget.
    progress : bool or callable
        Periodic progress lines on stderr (True), none (False), or a function taking a line.

    Returns
    -------
    DiagnosisResult
        Unpacks as ``where, effects, accepted``; ``to_dict()`` is the JSON report.

    Raises
    ------
    DiagnosisError
        Too-short records, a constant input, mismatched sampling rates, unknown effects.
    """
    say = _Progress(progress)
    vals = _as_records(val)
    _check_inputs(train, vals, holdout, transient)
    model = model.model if isinstance(model, IdentificationResult) else model
    s = _checked(train, vals, model, structure, effects, initial=initial, alpha=alpha,
                 max_rounds=max_rounds, min_reduction=min_reduction, refit_all=refit_all,
                 refit_samples=refit_samples, time_budget=time_budget,
                 budget_factor=budget_factor, require_excitation=require_excitation,
                 min_gap_share=min_gap_share, min_gap_share_later=min_gap_share_later,
                 workers=workers)
    members = _member_names(members)
    skip_tr = _checked_skip(train, vals, holdout, train_skip)
    repeat = _repeat_floor(train, vals, repeats)
    split = _Split(train, vals, holdout, transient, skip_tr, initial)

    # the members fitted and the candidates refitted in threads (the kernels release the
    # interpreter): the members beside the nominal fit and the rounds (on one thread, behind
    # the first round's refits), each round's refits beside each other
    with side_by_side(s.workers, "hystid-diagnose") as jobs:
        members_beside = _MembersBeside(members, member_records(train, vals, holdout)[0],
                                        jobs, say)
        if s.workers > 1:
            members_beside.start()
        try:
            start, nominal, data = _nominal_stage(split, model, structure, refit_samples,
                                                  repeat, s.names, effects, say)
            greedy = GreedyRounds(s, start, jobs, say, members_beside.start).run()
        except BaseException:
            members_beside.cancel.set()  # an error, Ctrl-C: not kept waiting for the members
            raise
        fitted = members_beside.fitted()
    settings = {"alpha": alpha, "min_reduction": min_reduction, "min_gap_share": min_gap_share,
                "min_gap_share_later": min_gap_share_later,
                "refit_samples": refit_samples, "max_rounds": max_rounds,
                "holdout": None if vals else holdout, "transient_s": transient,
                "train_skip_s": train_skip, "initial": initial, "candidates": list(s.names),
                "fs": train.fs, "train_samples": len(start.tr.u), "time_budget_s": s.time_budget,
                "budget_factor": budget_factor,
                "val_samples": int(sum(len(v.u[v.weight]) for v in data.vds)),
                "units": dict(train.units), "u_rest": data.u_rest,
                "nominal_seconds": start.t_nominal}
    return _result(train, start, nominal, data, greedy, repeat, settings, fitted, say)


@dataclass
class _Split:
    """How the records are split into the train and held-out parts (:func:`_split`)."""

    train: Record
    vals: list[Record]
    holdout: float
    transient: float
    skip_tr: int
    initial: str

    def at(self, u_rest: float) -> tuple:
        """The parts for a stage resting at input ``u_rest``."""
        return _split(self.train, self.vals, self.holdout, self.transient, self.skip_tr,
                      self.initial, u_rest)


@dataclass
class _Data:
    """The held-out parts, their start times, how they were taken, the rest input, and the
    nominal model as given or identified (and its figures before its refit, if refitted)."""

    vds: list[FitData]
    t0s: list[float]
    held: str
    u_rest: float
    first_fit: dict[str, Any] | None
    admissibility: list[str]


def _checked(train: Record, vals: list[Record], model: Any, structure: Structure | None,
             effects: Sequence[str], *, initial: str, alpha: float, max_rounds: int,
             min_reduction: float, refit_all: bool, refit_samples: int | None,
             time_budget: float | None, budget_factor: float | None,
             require_excitation: bool, min_gap_share: float, min_gap_share_later: float,
             workers: int | None) -> Settings:
    """The options checked before any fit; each error names the option."""
    try:
        names = effect_names_check(_expand_families(effects))
    except ValueError as err:
        raise DiagnosisError(str(err)) from err
    if initial not in ("auto", "rest", "level"):
        raise DiagnosisError(f"initial: expected 'auto', 'rest' or 'level', got {initial!r}")
    if not 0 < alpha < 1:
        raise DiagnosisError(f"alpha: expected a level in (0, 1), got {alpha}")
    if isinstance(max_rounds, bool) or not isinstance(max_rounds, int | np.integer) \
            or not 1 <= max_rounds <= MAX_ROUNDS:
        raise DiagnosisError(f"max_rounds: expected a whole number of rounds in 1..{MAX_ROUNDS}, "
                             f"got {max_rounds!r}")
    if not 0 <= min_reduction < 1:
        raise DiagnosisError(f"min_reduction: expected a fraction in [0, 1), got {min_reduction}")
    if refit_samples is not None and refit_samples < MIN_TRAIN_SAMPLES:
        raise DiagnosisError(f"refit_samples: expected at least {MIN_TRAIN_SAMPLES}, got "
                             f"{refit_samples}")
    if time_budget is not None and not time_budget >= 0:
        raise DiagnosisError(f"time_budget: expected seconds >= 0, got {time_budget}")
    n_workers = worker_count(workers, DiagnosisError)
    if budget_factor is not None and not budget_factor >= 0:
        raise DiagnosisError(f"budget_factor: expected a multiple >= 0, got {budget_factor}")
    fs = train.fs
    if model is not None and not isinstance(model, DuhemSandwich):
        raise DiagnosisError(
            f"model: expected a DuhemSandwich, got {type(model).__name__} (the effects extend "
            "eq. 7: diagnose without model=, then score yours beside the result with "
            "hystid.diagnose.final_model.final_model(result, train, val, given=(name, model)))")
    try:  # before any fit: the augmented sandwich takes only the plain Duhem
        for given in (model.structure if model is not None else None, structure):
            if given is not None:
                check_plain_duhem(given.layout, "diagnose")
    except ValueError as err:
        raise DiagnosisError(str(err)) from err
    if model is not None and not np.isclose(model.fs, fs, rtol=1e-9):
        raise DiagnosisError(f"model: sampling rate {model.fs:g} Hz differs from the records' "
                             f"{fs:g} Hz")
    for label, v in (("min_gap_share", min_gap_share),
                     ("min_gap_share_later", min_gap_share_later)):
        if not 0 <= v < 1:
            raise DiagnosisError(f"{label}: expected a fraction in [0, 1), got {v}")
    return Settings(names, alpha, min_reduction, max_rounds, min_gap_share,
                    min_gap_share_later, refit_all, require_excitation, time_budget,
                    budget_factor, n_workers)


def _unit_said(record: Record) -> str:
    """The output's unit as the progress lines say it (" um")."""
    return (" " + str(record.units.get("y", ""))).rstrip()


def _checked_skip(train: Record, vals: list[Record], holdout: float, train_skip: float) -> int:
    """``train_skip`` in samples, checked."""
    skip_tr = int(round(train_skip * train.fs))
    if train_skip < 0 or skip_tr > 0.5 * train.n * (1 if vals else 1 - holdout):
        raise DiagnosisError(f"train_skip: expected 0 <= train_skip <= half the train part, got "
                             f"{train_skip} s")
    return skip_tr


def _nominal_stage(split: _Split, model: DuhemSandwich | None, structure: Structure | None,
                   refit_samples: int | None, repeat: float | None, names: list[str],
                   effects: Sequence[str], say: _Progress) -> tuple[Start, Any, _Data]:
    """The records split, the nominal model identified (or taken) and refitted with the
    candidates' cost and initial state, its held-out figures, where its error lies and the
    floor: what the rounds start from."""
    train = split.train
    fs = train.fs
    u_rest = model.u_rest if model is not None else 0.0
    tr, vds, t0s, held = split.at(u_rest)
    say(f"{len(tr.u)} train samples, {sum(len(v.u[v.weight]) for v in vds)} held-out samples "
        f"({held}) at {fs:g} Hz; candidates: {', '.join(names)}")
    if any(n in IN_NOMINAL for n in effects):
        say("offset: the sensor offset is a parameter of the nominal model, not a candidate")
    t_nominal = time.perf_counter()
    if model is None:
        say("identifying the nominal sandwich (hystid.identify, batch: offset and rest level "
            "estimated)")
        jumps: list[dict] = []
        nominal = _identify(tr, structure, jumps, say)
        if nominal.u_rest != 0.0:
            u_rest = nominal.u_rest
            tr, vds, t0s, held = split.at(u_rest)
        for jump in jumps:  # the rounds see the train part as the nominal model was fitted
            tr = replace(tr, y=np.r_[tr.y[:jump["sample"]],
                                     tr.y[jump["sample"]:] - jump["size"]])
            say(f"the train part's output steps by {jump['size']:+.4g}{_unit_said(train)} at its "
                f"sample {jump['sample']} where the input does not (a sensor zero that "
                "moved?): taken off the samples after it, as the identification did")
    else:
        nominal = model
    left_out = _cost_mask(tr, u_rest)
    if left_out is not None:
        say(f"{int(np.count_nonzero(~left_out))} train samples simulated but left out of every "
            "cost, as the identification leaves them out (burn-in, jumps, outliers, a "
            "saturated sensor)")
    phi0 = zero_vector()
    phi0[EFFECTS["offset"].slots[0]] = getattr(nominal, "offset", 0.0)
    ev = _Evaluator(tr, vds, t0s)
    tr_c = tr if refit_samples is None else _head(tr, refit_samples)
    ev_c = ev if tr_c is tr else _Evaluator(tr_c, vds, t0s)
    first = ev(nominal, phi0, drift=False)
    if not first.finite:
        raise DiagnosisError("the nominal model's simulation diverges on these records (the "
                             "Duhem stability condition (8) fails): scale the input down")
    yu = _unit_said(train)  # the unit of every RMS said
    say(f"nominal model: train RMS {first.rms_train:.4g}{yu}, held-out RMS {first.rms_val:.4g}{yu}")
    base_model, first_fit = nominal, None
    # the candidates are refitted with this cost and initial state: so is the base
    say("refitting the nominal model alone (the base the candidates are compared with)")
    rb = refit(nominal, tr, [], [phi0])
    if rb.ok and rb.cost <= first.rms_train**2:
        base_model = DuhemSandwich(rb.theta, nominal.structure, fs=fs, name=nominal.name)
        phi0 = rb.phi
        first_fit = {"rms_val": first.rms_val, "rms_train": first.rms_train,
                     "params": nominal.params,
                     "note": "the given or identified model; the nominal figures are those of "
                             "its refit with the candidates' cost and initial state"}
    t_nominal = time.perf_counter() - t_nominal
    nom = ev(base_model, phi0, drift=False) if first_fit is not None else first
    if first_fit is not None:
        say(f"nominal model refitted: train RMS {nom.rms_train:.4g}{yu}, held-out RMS "
            f"{nom.rms_val:.4g}{yu}")
    admissibility = _admissibility(base_model, nom, vds)
    for m in admissibility:
        say(f"the nominal model is not admissible on the held-out input: {m}")
    where0 = localise(nom.segments)
    floor_rms = max(where0.noise["rms"], repeat or 0.0)
    say(f"noise floor {where0.noise['rms']:.4g}{yu} RMS; " + "; ".join(where0.findings[1:3]))
    start = Start(tr, tr_c, ev, ev_c, base_model, phi0, nom, where0, floor_rms, t_nominal, yu)
    return start, nominal, _Data(vds, t0s, held, u_rest, first_fit, admissibility)


class _MembersBeside:
    """The members' fits, started beside the nominal fit, which leaves the other cores idle
    (on one thread, queued behind the first round's refits: the rounds' critical path goes
    first). They do not depend on the nominal model: on stage A's ``prbn_1`` the diagnosis
    took 2.9-3.1x the nominal fit's time with them queued behind the first round's refits."""

    def __init__(self, members: list[str], fit_on: Record, jobs: ThreadPoolExecutor,
                 say: _Progress) -> None:
        self.members, self.fit_on, self.jobs, self.say = members, fit_on, jobs, say
        self.running: dict[str, Future] = {}
        self.cancel = threading.Event()  # set: the fits end at their next evaluation

    def start(self) -> None:
        """Queue every member's fit not queued yet."""
        for name in self.members:
            if name not in self.running:
                self.say(f"fitting the {name} member on {self.fit_on.name!r} beside the "
                         "rounds (a candidate for the hysteresis itself)")
                fit = cancellable(lambda name=name: fit_member(name, self.fit_on), self.cancel)
                self.running[name] = self.jobs.submit(copy_context().run, fit)

    def fitted(self) -> dict[str, Any]:
        """The members fitted; one whose fit failed is said and left to
        :func:`~hystid.diagnose.final_model.final_model` to fit (and report) again."""
        self.start()
        fitted = {}
        for name, job in self.running.items():
            try:
                fitted[name] = job.result()
            except (ValueError, ArithmeticError, np.linalg.LinAlgError) as err:
                self.say(f"the {name} member's fit failed: {err}")
                continue
            self.say(f"the {name} member fitted")
        return fitted


def _result(train: Record, start: Start, nominal: DuhemSandwich, data: _Data,
            greedy: GreedyRounds, repeat: float | None, settings: dict[str, Any],
            fitted: dict[str, Any], say: _Progress) -> DiagnosisResult:
    """The figures of merit against the floor, the models placed in record units, the
    report."""
    state, nom = greedy.state, start.nom
    nf = float(min(greedy.noise_estimates))
    floor = {"noise_floor_rms": nf, "repeat_floor_rms": repeat,
             "rms": max(nf, repeat) if repeat is not None else nf,
             "kind": "repeatability" if repeat is not None and repeat > nf else "sensor noise"}

    def closed(rms):
        return gap_closed(nom.rms_val, rms, floor["rms"])

    for o in greedy.outcomes.values():
        if o.rms_val_after is not None:
            o.gap_closed = closed(o.rms_val_after)
        if o.cumulative is not None:
            o.cumulative["gap_closed"] = closed(o.cumulative["rms_val"])
    accepted = list(state.active)
    ranked = _rank(greedy.outcomes, accepted)
    final_effects = effect_dict(state.phi, accepted) if accepted else {}
    offset_slot = EFFECTS["offset"].slots[0]

    def placed(m: DuhemSandwich, phi: np.ndarray) -> DuhemSandwich:
        # the model in record units: its rest level, the fitted sensor offset, its envelope
        return DuhemSandwich(m.theta, m.structure, fs=train.fs, name=nominal.name,
                             u_rest=data.u_rest, offset=float(phi[offset_slot]),
                             envelope=getattr(nominal, "envelope", None), units=train.units)

    base_placed = placed(start.model, start.phi)
    aug = AugmentedSandwich(placed(state.model, state.phi), final_effects)
    nominal_info = {"rms_val": nom.rms_val, "rms_train": nom.rms_train,
                    "gap": nom.rms_val - floor["rms"],
                    "params": start.model.params, "name": nominal.name,
                    "admissibility": data.admissibility, "margin_val": nom.margin_val}
    if data.first_fit is not None:
        nominal_info["first_fit"] = data.first_fit
    final = {"rms_val": state.ev.rms_val, "rms_train": state.ev.rms_train,
             "gap_closed": closed(state.ev.rms_val), "effects": final_effects,
             "params": state.model.params,
             "unexplained": describe_unexplained(state.where, floor["rms"])}
    settings = {**settings, "elapsed_s": time.perf_counter() - say.t0}
    series = {"errs_nominal": nom.errs, "errs_final": state.ev.errs,
              "candidate_errs": greedy.cand_errs, "t0s": data.t0s}
    say(f"done: {', '.join(accepted) if accepted else 'none'} accepted; held-out RMS "
        f"{nom.rms_val:.4g} -> {state.ev.rms_val:.4g} ({floor['kind']} floor "
        f"{floor['rms']:.4g})")
    return DiagnosisResult(nf, nominal_info, start.where, ranked, accepted, final,
                           greedy.rounds, base_placed, aug, state.where, settings, series,
                           floor, fitted)


def _member_names(members: Sequence[str]) -> list[str]:
    from ..identify.members import MEMBERS

    names = [members] if isinstance(members, str) else list(members)
    for name in names:
        if name not in MEMBERS:
            raise DiagnosisError(f"members: expected names of {', '.join(MEMBERS)}, got "
                                 f"{name!r}")
    return names


