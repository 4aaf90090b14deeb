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

import os
import time
from collections.abc import Callable, Iterator, Sequence
from concurrent.futures import Future, ThreadPoolExecutor
from contextlib import contextmanager
from dataclasses import replace
from typing import Any

import numpy as np

from ..blas import one_blas_thread
from ..identify.result import IdentificationResult
from ..metrics import gap_closed
from ..model import DuhemSandwich, Structure
from ..records import Record
from ..validate import check_plain_duhem
from .effects import EFFECTS, AugmentedSandwich, effect_dict, family_of
from .final_model import fit_member, member_records
from .refit import refit
from .result import DiagnosisResult, EffectOutcome
from .rounds import (
    ALIKE,
    DEFAULT_EFFECTS,
    IN_NOMINAL,
    MIN_TRAIN_SAMPLES,
    MIN_VAL_SAMPLES,
    NOISE_REACH,
    DiagnosisError,
    _admissibility,
    _as_records,
    _candidate_info,
    _check_inputs,
    _cost_mask,
    _drift_last,
    _Evaluator,
    _expand_families,
    _extends,
    _Greedy,
    _join,
    _mark_alike,
    _parsimonious,
    _plan,
    _Progress,
    _rank,
    _record_screen,
    _refit_round,
    _repeat_floor,
    _split,
    describe_unexplained,
)
from .screen import effect_names_check, screen, zero_vector
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
#: by side (:data:`MAX_WORKERS`), so within the budget more of them are started on two cores
#: than on one.
BUDGET_FACTOR = 0.5
#: Most threads a diagnosis takes by default. A round has a handful of refits and the members
#: one fit each; the compiled kernels release the interpreter, the solver's own Python does
#: not, so more threads than that gain little.
MAX_WORKERS = 4


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
        :data:`MAX_WORKERS`, by default). The result does not depend on it, except through
        the time budget.
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
    n_workers = _workers(workers)
    members = _member_names(members)
    if budget_factor is not None and not budget_factor >= 0:
        raise DiagnosisError(f"budget_factor: expected a multiple >= 0, got {budget_factor}")
    fs = train.fs
    skip_tr = int(round(train_skip * fs))
    if train_skip < 0 or skip_tr > 0.5 * train.n * (1 if vals else 1 - holdout):
        raise DiagnosisError(f"train_skip: expected 0 <= train_skip <= half the train part, got "
                             f"{train_skip} s")
    if isinstance(model, IdentificationResult):
        model = model.model
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
    repeat = _repeat_floor(train, vals, repeats)
    for label, v in (("min_gap_share", min_gap_share),
                     ("min_gap_share_later", min_gap_share_later)):
        if not 0 <= v < 1:
            raise DiagnosisError(f"{label}: expected a fraction in [0, 1), got {v}")

    # ----------------------------------------------------------------- data
    u_rest = model.u_rest if model is not None else 0.0
    tr, vds, t0s, held = _split(train, vals, holdout, transient, skip_tr, initial, u_rest)
    say(f"{len(tr.u)} train samples, {sum(len(v.u[v.weight]) for v in vds)} held-out samples "
        f"({held}) at {fs:g} Hz; candidates: {', '.join(names)}")
    if any(n in IN_NOMINAL for n in effects):
        say("offset: the sensor offset is a parameter of the nominal model, not a candidate")

    # ----------------------------------------------------------------- nominal model
    t_nominal = time.perf_counter()
    if model is None:
        say("identifying the nominal sandwich (hystid.identify, batch: offset and rest level "
            "estimated)")
        nominal = _identify(tr, structure)
        if nominal.u_rest != 0.0:
            u_rest = nominal.u_rest
            tr, vds, t0s, held = _split(train, vals, holdout, transient, skip_tr, initial,
                                        u_rest)
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
    yu = (" " + str(train.units.get("y", ""))).rstrip()  # the unit of every RMS said
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

    # ----------------------------------------------------------------- side by side
    # the members fitted and the candidates refitted in threads (the kernels release the
    # interpreter): the members beside the rounds, each round's refits beside each other
    with _side_by_side(n_workers) as jobs:
        fit_on, _ = member_records(train, vals, holdout)
        member_jobs: dict[str, Future] = {}

        def start_members() -> None:
            # queued behind the first round's refits: the rounds' critical path (screen,
            # refits, polish) goes first, the member fit takes the cores they leave idle
            for name in members:
                if name not in member_jobs:
                    say(f"fitting the {name} member on {fit_on.name!r} beside the rounds (a "
                        "candidate for the hysteresis itself)")
                    member_jobs[name] = jobs.submit(fit_member, name, fit_on)
        # ----------------------------------------------------------------- greedy rounds
        state = _Greedy(base_model, phi0, nom, where0)
        outcomes: dict[str, EffectOutcome] = {
            n: EffectOutcome(n, "screened out", family=family_of(n)) for n in names}
        rounds: list[dict[str, Any]] = []
        nf_estimates = [where0.noise["rms"]]
        promising = 0.25 * (1.0 - (1.0 - min_reduction) ** 2)
        cand_errs: dict[str, list[np.ndarray]] = {}
        budget_end = None
        for rnd in range(1, max_rounds + 1):
            remaining = [n for n in names if n not in state.active
                         and (family_of(n) not in state.families or _extends(n, state.active))]
            if not remaining:
                break
            if rnd > 1:
                later = max(min_gap_share, min_gap_share_later) * max(nom.rms_val - floor_rms, 0.0)
                if state.ev.rms_val - later < NOISE_REACH * floor_rms:
                    # the reduction a further form needs would take the held-out error below the
                    # noise, which no model of the stage explains
                    rounds[-1]["next_round"] = (
                        f"not run: a further form must lower the held-out RMS by {later:.4g}, from "
                        f"{state.ev.rms_val:.4g}, below the floor of {floor_rms:.4g}")
                    say(f"round {rnd}: {rounds[-1]['next_round']}")
                    break
            window = state if tr_c is tr else state.on_window(tr_c, ev_c, say)
            drift_result, base = None, window
            drift_job = None
            if "drift" in remaining:
                # the drift is a nuisance of every record: refitted with the train record's own
                # drift, judged with each held-out record's own drift re-estimated (beside the
                # screen, on workspaces of its own)
                drift_job = jobs.submit(window.with_drift, replace(tr_c), ev_c.private(), say)
            others = [n for n in remaining if n != "drift"]
            say(f"round {rnd}: screening {', '.join(others)}")
            scr = screen(base.model, base.phi, base.active, tr_c, others,
                         step_scale=base.ev.scales[0], w1_scale=base.ev.scales[1],
                         peaks_hz=state.where.frequency["peaks_hz"]
                         + [state.where.frequency["peak_hz"]], pool=jobs)
            if drift_job is not None:
                drift_result = drift_job.result()
            if drift_result is not None:
                scr["drift"] = drift_result[3]
            plan, ruled_out = _plan(scr, others, promising, refit_all)
            if rnd == 1:
                _record_screen(outcomes, scr, ruled_out, require_excitation)
                if time_budget is None and budget_factor is not None:
                    time_budget = budget_factor * t_nominal
                if time_budget is not None:
                    budget_end = time.perf_counter() + time_budget
            info: dict[str, Any] = {"round": rnd, "rms_val_base": state.ev.rms_val,
                                    "findings": state.where.findings, "accepted": None,
                                    "ruled_out": ruled_out, "candidates": {}}
            if not plan and drift_result is None:
                rounds.append(info)
                break
            results = _refit_round(base, plan, scr, tr_c, ev_c, info, say, rnd, budget_end,
                                      jobs, n_workers, then=start_members)
            if drift_result is not None:
                results["drift"] = drift_result[:3]
                info["candidates"]["drift"] = _candidate_info("drift", *drift_result[:3])
            if rnd == 1:
                for n, (rf, test, ev_n) in results.items():
                    o = outcomes[n]
                    o.status = "rejected"
                    o.params = effect_dict(rf.phi, [n])[n]
                    o.rms_train_after, o.rms_val_after, o.test = ev_n.rms_train, ev_n.rms_val, test
                    cand_errs[n] = ev_n.errs
                for n, c in info["candidates"].items():
                    if c["status"] in ("failed", "not refitted"):
                        outcomes[n].status = c["status"]
                        outcomes[n].message = _join(outcomes[n].message, c["message"])
                _mark_alike(outcomes, state.ev.errs, cand_errs)
            level_r = alpha / max(len(results) + sum(
                c["status"] == "failed" for c in info["candidates"].values()), 1)
            info["test_level"] = level_r
            share = min_gap_share if rnd == 1 else max(min_gap_share, min_gap_share_later)
            needed = share * max(nom.rms_val - floor_rms, 0.0)
            passing = [n for n, (_, t, _) in results.items()
                       if t["p_value"] < level_r and t["rel_reduction"] >= min_reduction
                       and t["rms_base"] - t["rms_cand"] >= needed]
            info["rms_reduction_needed"] = needed
            if not passing:
                rounds.append(info)
                say(f"round {rnd}: no candidate passes (level {level_r:.2g}, "
                    f"minimum reduction {100 * min_reduction:.0f} %)")
                break
            # a further form of a family already accepted goes first (the first form did not
            # catch the whole effect), a new family next; a record's own drift (re-estimated on
            # the held-out records themselves) only when no input-tied form beats it like with
            # like
            pool = [n for n in passing if family_of(n) in state.families]
            if not pool:
                pool, order = _drift_last(passing, results, level_r, min_reduction)
                if order:
                    info["drift_order"] = order
                    say(f"round {rnd}: {order['text']}")
                    for n in ("drift", order["form"]):
                        outcomes[n].message = _join(outcomes[n].message,
                                                    f"round {rnd}: {order['text']}")
            chosen = None
            while pool and chosen is None:
                best = min(pool, key=lambda n: results[n][1]["rms_cand"])
                best = _parsimonious(best, pool, {n: (r[0], r[1], r[2].errs)
                                                  for n, r in results.items()}, level_r,
                                     min_reduction)
                rf, test, ev_best = results[best]
                # polished on the whole train part (longer than the screening refits, so that a
                # later round does not pick up what an unfinished fit left): the model that goes
                # on must pass the same test again
                rf, test, ev_best = state.refit_whole(best, rf, tr, ev, results[best], say)
                if not (test["p_value"] < level_r and test["rel_reduction"] >= min_reduction
                        and test["rms_base"] - test["rms_cand"] >= needed):
                    info["candidates"][best].update({
                        "status": "not confirmed",
                        "message": f"passed on its screening refit, not once polished on the whole "
                                   f"train part (held-out RMS {test['rms_cand']:.4g}, p = "
                                   f"{test['p_value']:.2g})"})
                    say(f"round {rnd}: {best} not confirmed on the whole train part")
                    pool.remove(best)
                    continue
                chosen = best
            if chosen is None:
                rounds.append(info)
                break
            best = chosen
            rms_before = state.ev.rms_val
            state.accept(best, rf, ev_best, localise(ev_best.segments))
            nf_estimates.append(state.where.noise["rms"])
            o = outcomes[best]
            o.status, o.round = "accepted", rnd
            o.params = effect_dict(rf.phi, [best])[best]
            o.at_bound = [b for b in rf.at_bound if b.startswith(f"{best}.")]
            o.rms_train_after, o.rms_val_after, o.test = ev_best.rms_train, ev_best.rms_val, test
            o.cumulative = {"rms_val_before": rms_before, "rms_val": ev_best.rms_val,
                            "p_value": test["p_value"], "rel_reduction": test["rel_reduction"]}
            info.update({"accepted": best, "rms_val_after": ev_best.rms_val})
            rounds.append(info)
            say(f"round {rnd}: accepted {best}: held-out RMS {ev_best.rms_val:.4g}{yu}")

        start_members()
        fitted = _fitted_members(member_jobs, say)

    # ----------------------------------------------------------------- figures of merit
    nf = float(min(nf_estimates))
    floor = {"noise_floor_rms": nf, "repeat_floor_rms": repeat,
             "rms": max(nf, repeat) if repeat is not None else nf,
             "kind": "repeatability" if repeat is not None and repeat > nf else "sensor noise"}
    def closed(rms):
        return gap_closed(nom.rms_val, rms, floor["rms"])

    for o in outcomes.values():
        if o.rms_val_after is not None:
            o.gap_closed = closed(o.rms_val_after)
        if o.cumulative is not None:
            o.cumulative["gap_closed"] = closed(o.cumulative["rms_val"])
    accepted = list(state.active)
    ranked = _rank(outcomes, accepted)
    final_effects = effect_dict(state.phi, accepted) if accepted else {}
    offset_slot = EFFECTS["offset"].slots[0]

    def placed(m: DuhemSandwich, phi: np.ndarray) -> DuhemSandwich:
        # the model in record units: its rest level, the fitted sensor offset, its envelope
        return DuhemSandwich(m.theta, m.structure, fs=fs, name=nominal.name, u_rest=u_rest,
                             offset=float(phi[offset_slot]),
                             envelope=getattr(nominal, "envelope", None), units=train.units)

    base_placed = placed(base_model, phi0)
    aug = AugmentedSandwich(placed(state.model, state.phi), final_effects)
    nominal_info = {"rms_val": nom.rms_val, "rms_train": nom.rms_train,
                    "gap": nom.rms_val - floor["rms"],
                    "params": base_model.params, "name": nominal.name,
                    "admissibility": admissibility, "margin_val": nom.margin_val}
    if first_fit is not None:
        nominal_info["first_fit"] = first_fit
    final = {"rms_val": state.ev.rms_val, "rms_train": state.ev.rms_train,
             "gap_closed": closed(state.ev.rms_val), "effects": final_effects,
             "params": state.model.params,
             "unexplained": describe_unexplained(state.where, floor["rms"])}
    settings = {"alpha": alpha, "min_reduction": min_reduction, "min_gap_share": min_gap_share,
                "min_gap_share_later": min_gap_share_later,
                "refit_samples": refit_samples, "max_rounds": max_rounds,
                "holdout": None if vals else holdout, "transient_s": transient,
                "train_skip_s": train_skip, "initial": initial, "candidates": list(names),
                "fs": fs, "train_samples": len(tr.u), "time_budget_s": time_budget,
                "budget_factor": budget_factor,
                "val_samples": int(sum(len(v.u[v.weight]) for v in vds)),
                "units": dict(train.units), "u_rest": u_rest,
                "nominal_seconds": t_nominal, "elapsed_s": time.perf_counter() - say.t0}
    series = {"errs_nominal": nom.errs, "errs_final": state.ev.errs,
              "candidate_errs": cand_errs, "t0s": t0s}
    say(f"done: {', '.join(accepted) if accepted else 'none'} accepted; held-out RMS "
        f"{nom.rms_val:.4g} -> {state.ev.rms_val:.4g} ({floor['kind']} floor "
        f"{floor['rms']:.4g})")
    return DiagnosisResult(nf, nominal_info, where0, ranked, accepted, final, rounds,
                           base_placed, aug, state.where, settings, series, floor, fitted)


@contextmanager
def _side_by_side(n_workers: int) -> Iterator[ThreadPoolExecutor]:
    """The diagnosis' threads; on the way out (an error, Ctrl-C) the work not yet started is
    dropped instead of run to the end."""
    jobs = ThreadPoolExecutor(n_workers, thread_name_prefix="hystid-diagnose")
    try:
        yield jobs
    finally:
        jobs.shutdown(wait=True, cancel_futures=True)


def _workers(workers: int | None) -> int:
    """Threads for the refits and member fits: ``workers``, else the cores up to
    :data:`MAX_WORKERS`."""
    if workers is None:
        return max(1, min(MAX_WORKERS, os.cpu_count() or 1))
    if isinstance(workers, bool) or not isinstance(workers, int | np.integer) or workers < 1:
        raise DiagnosisError(f"workers: expected a whole number >= 1, got {workers!r}")
    return int(workers)


def _member_names(members: Sequence[str]) -> list[str]:
    from ..identify.members import MEMBERS

    names = [members] if isinstance(members, str) else list(members)
    for name in names:
        if name not in MEMBERS:
            raise DiagnosisError(f"members: expected names of {', '.join(MEMBERS)}, got "
                                 f"{name!r}")
    return names


def _fitted_members(member_jobs: dict[str, Future], say: _Progress) -> dict[str, Any]:
    """The members fitted beside the rounds; one whose fit failed is said and left to
    :func:`~hystid.diagnose.final_model.final_model` to fit (and report) again."""
    fitted = {}
    for name, job in member_jobs.items():
        try:
            fitted[name] = job.result()
        except (ValueError, ArithmeticError, np.linalg.LinAlgError) as err:
            say(f"the {name} member's fit failed: {err}")
            continue
        say(f"the {name} member fitted")
    return fitted


