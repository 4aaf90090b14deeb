"""The greedy rounds of a diagnosis, stage by stage.

Each round (:meth:`GreedyRounds.round`): the forms left to try; the round is skipped when the
reduction it needs would go below the noise; the current model (refitted over the head of the
train part when the forms are compared there) is the base; the drift is refitted beside the
screen; the screen plans the refits; the refits run and are tested on the held-out part; the
forms that pass are ordered (a further form of an accepted family first, the drift last unless
it wins like with like); the best is polished on the whole train part and must pass again; it
joins the model. :func:`hystid.diagnose.diagnosis.diagnose` sets the rounds up and reads their
outcome.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from concurrent.futures import Executor
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from ..model import DuhemSandwich
from .effects import effect_dict, family_of
from .refit import FitData, RefitResult
from .result import EffectOutcome
from .rounds import (
    NOISE_REACH,
    _candidate_info,
    _drift_last,
    _Evaluation,
    _Evaluator,
    _extends,
    _Greedy,
    _join,
    _mark_alike,
    _parsimonious,
    _plan,
    _Progress,
    _record_screen,
    _refit_round,
)
from .screen import ScreenResult, screen
from .where import Where, localise

Refitted = dict[str, tuple[RefitResult, dict, _Evaluation]]


@dataclass
class Settings:
    """A diagnosis' checked options (see :func:`~hystid.diagnose.diagnosis.diagnose`).

    Parameters
    ----------
    names : list of str
        The candidate forms.
    alpha : float
        Significance level of a round (shared by the forms it tests).
    min_reduction : float
        Smallest relative reduction of the held-out RMS a form must bring.
    max_rounds : int
        Most rounds.
    min_gap_share, min_gap_share_later : float
        Share of the gap to the floor a form must close in the first round and later.
    refit_all : bool
        Refit every excited form, not only the promising ones.
    require_excitation : bool
        Raise when a form cannot be shown by the records.
    time_budget : float or None
        Seconds for further forms from the first round's refits (set from
        ``budget_factor`` there when None).
    budget_factor : float or None
        The budget as a multiple of the nominal fit's time.
    workers : int
        Threads.
    """

    names: list[str]
    alpha: float
    min_reduction: float
    max_rounds: int
    min_gap_share: float
    min_gap_share_later: float
    refit_all: bool
    require_excitation: bool
    time_budget: float | None
    budget_factor: float | None
    workers: int


@dataclass
class Start:
    """What the rounds start from.

    Parameters
    ----------
    tr, tr_c : FitData
        The train part, and its head the forms are compared on (``tr`` itself by default).
    ev, ev_c : _Evaluator
        Simulations over the train part (or its head) and the held-out parts.
    model : DuhemSandwich
        The nominal model, refitted with the candidates' cost and initial state.
    phi : ndarray
        Its effect vector (the sensor offset).
    nom : _Evaluation
        Its figures.
    where : Where
        Where its held-out error lies.
    floor_rms : float
        The floor of the gap.
    t_nominal : float
        Seconds the nominal fit took.
    unit : str
        The output's unit as the progress lines say it (" um").
    """

    tr: FitData
    tr_c: FitData
    ev: _Evaluator
    ev_c: _Evaluator
    model: DuhemSandwich
    phi: np.ndarray
    nom: _Evaluation
    where: Where
    floor_rms: float
    t_nominal: float
    unit: str


@dataclass
class GreedyRounds:
    """The rounds' state: the current model, every form's outcome, a record per round.

    Parameters
    ----------
    s : Settings
        The options.
    start : Start
        The nominal stage.
    jobs : Executor
        Threads for the refits, the screen and the drift refit.
    say : _Progress
        Progress lines (said from the calling thread only).
    after_first_refits : callable
        Called once the first round's refits are all started (the member fits queue behind
        them).

    Attributes
    ----------
    state : _Greedy
        The current model, its effect vector and figures, the forms accepted.
    outcomes : dict
        Every form's :class:`~hystid.diagnose.result.EffectOutcome`.
    rounds : list of dict
        A record per round.
    noise_estimates : list of float
        The noise floor as each localisation estimated it.
    cand_errs : dict
        The held-out errors of each form refitted in the first round.
    budget_end : float or None
        When the time for further forms runs out (``time.perf_counter()``).
    """

    s: Settings
    start: Start
    jobs: Executor
    say: _Progress
    after_first_refits: Callable[[], None]
    state: _Greedy = field(init=False)
    outcomes: dict[str, EffectOutcome] = field(init=False)
    rounds: list[dict[str, Any]] = field(default_factory=list, init=False)
    noise_estimates: list[float] = field(init=False)
    cand_errs: dict[str, list[np.ndarray]] = field(default_factory=dict, init=False)
    budget_end: float | None = field(default=None, init=False)

    def __post_init__(self) -> None:
        st = self.start
        self.state = _Greedy(st.model, st.phi, st.nom, st.where)
        self.outcomes = {n: EffectOutcome(n, "screened out", family=family_of(n))
                         for n in self.s.names}
        self.noise_estimates = [st.where.noise["rms"]]
        self.promising = 0.25 * (1.0 - (1.0 - self.s.min_reduction) ** 2)

    def run(self) -> GreedyRounds:
        """Run rounds until one accepts nothing or ``max_rounds`` have run.

        Returns
        -------
        GreedyRounds
            Itself, its state, outcomes and rounds filled in.
        """
        for rnd in range(1, self.s.max_rounds + 1):
            if not self.round(rnd):
                break
        return self

    # ----------------------------------------------------------------- one round
    def round(self, rnd: int) -> bool:
        """One round.

        Parameters
        ----------
        rnd : int
            Its number, from 1.

        Returns
        -------
        bool
            Whether a form was accepted (and another round may follow).
        """
        remaining = self._remaining()
        if not remaining or (rnd > 1 and self._below_noise(rnd)):
            return False
        base, scr, drift_result, others = self._screen(rnd, remaining)
        plan, ruled_out = _plan(scr, others, self.promising, self.s.refit_all)
        if rnd == 1:
            _record_screen(self.outcomes, scr, ruled_out, self.s.require_excitation)
            self._start_budget()
        info: dict[str, Any] = {"round": rnd, "rms_val_base": self.state.ev.rms_val,
                                "findings": self.state.where.findings, "accepted": None,
                                "ruled_out": ruled_out, "candidates": {}}
        if not plan and drift_result is None:
            self.rounds.append(info)
            return False
        results = self._refits(rnd, base, plan, scr, drift_result, info)
        level, needed, passing = self._passing(rnd, results, info)
        if not passing:
            self.rounds.append(info)
            self.say(f"round {rnd}: no candidate passes (level {level:.2g}, "
                     f"minimum reduction {100 * self.s.min_reduction:.0f} %)")
            return False
        pool = self._ordered(rnd, passing, results, level, info)
        chosen = self._confirmed(rnd, pool, results, level, needed, info)
        if chosen is None:
            self.rounds.append(info)
            return False
        self._accept(rnd, *chosen, info)
        return True

    def _remaining(self) -> list[str]:
        state = self.state
        return [n for n in self.s.names if n not in state.active
                and (family_of(n) not in state.families or _extends(n, state.active))]

    def _below_noise(self, rnd: int) -> bool:
        """Whether the reduction a further form needs would take the held-out error below the
        noise, which no model of the stage explains (the round is then not run)."""
        s, st = self.s, self.start
        later = max(s.min_gap_share, s.min_gap_share_later) * max(st.nom.rms_val
                                                                  - st.floor_rms, 0.0)
        if self.state.ev.rms_val - later >= NOISE_REACH * st.floor_rms:
            return False
        self.rounds[-1]["next_round"] = (
            f"not run: a further form must lower the held-out RMS by {later:.4g}, from "
            f"{self.state.ev.rms_val:.4g}, below the floor of {st.floor_rms:.4g}")
        self.say(f"round {rnd}: {self.rounds[-1]['next_round']}")
        return True

    def _screen(self, rnd: int, remaining: list[str],
                ) -> tuple[_Greedy, dict[str, ScreenResult], tuple | None, list[str]]:
        """The base of the round, the screen of the forms and the drift's refit beside it."""
        st, state = self.start, self.state
        base = state if st.tr_c is st.tr else state.on_window(st.tr_c, st.ev_c, self.say)
        drift_job = None
        if "drift" in remaining:
            # the drift is a nuisance of every record: refitted with the train record's own
            # drift, judged with each held-out record's own drift re-estimated (beside the
            # screen, on workspaces of its own)
            self.say("refitting with the train record's own drift (a nuisance of every "
                     "record)")
            drift_job = self.jobs.submit(base.with_drift, replace(st.tr_c), st.ev_c.private())
        others = [n for n in remaining if n != "drift"]
        self.say(f"round {rnd}: screening {', '.join(others)}")
        scr = screen(base.model, base.phi, base.active, st.tr_c, others,
                     step_scale=base.ev.scales[0], w1_scale=base.ev.scales[1],
                     peaks_hz=state.where.frequency["peaks_hz"]
                     + [state.where.frequency["peak_hz"]], pool=self.jobs)
        drift_result = drift_job.result() if drift_job is not None else None
        if drift_result is not None:
            scr["drift"] = drift_result[3]
        return base, scr, drift_result, others

    def _start_budget(self) -> None:
        """The time budget for further forms starts with the first round's refits."""
        s = self.s
        if s.time_budget is None and s.budget_factor is not None:
            s.time_budget = s.budget_factor * self.start.t_nominal
        if s.time_budget is not None:
            self.budget_end = time.perf_counter() + s.time_budget

    def _refits(self, rnd: int, base: _Greedy, plan: list[tuple[str, bool]],
                scr: dict[str, ScreenResult], drift_result: tuple | None,
                info: dict[str, Any]) -> Refitted:
        """The planned forms refitted and tested (the drift's refit joins them); the first
        round records every form's outcome."""
        st = self.start
        results = _refit_round(base, plan, scr, st.tr_c, st.ev_c, info, self.say, rnd,
                               self.budget_end, self.jobs, self.s.workers,
                               then=self.after_first_refits)
        if drift_result is not None:
            results["drift"] = drift_result[:3]
            info["candidates"]["drift"] = _candidate_info("drift", *drift_result[:3])
        if rnd == 1:
            self._record_first(results, info)
        return results

    def _record_first(self, results: Refitted, info: dict[str, Any]) -> None:
        outcomes = self.outcomes
        for n, (rf, test, ev_n) in results.items():
            o = outcomes[n]
            o.status = "rejected"
            o.params = effect_dict(rf.phi, [n])[n]
            o.rms_train_after, o.rms_val_after, o.test = ev_n.rms_train, ev_n.rms_val, test
            self.cand_errs[n] = ev_n.errs
        for n, c in info["candidates"].items():
            if c["status"] in ("failed", "not refitted"):
                outcomes[n].status = c["status"]
                outcomes[n].message = _join(outcomes[n].message, c["message"])
        _mark_alike(outcomes, self.state.ev.errs, self.cand_errs)

    def _passing(self, rnd: int, results: Refitted,
                 info: dict[str, Any]) -> tuple[float, float, list[str]]:
        """The round's test level (Bonferroni over the forms tried), the reduction a form
        must reach, and the forms that pass."""
        s, st = self.s, self.start
        level = s.alpha / max(len(results) + sum(
            c["status"] == "failed" for c in info["candidates"].values()), 1)
        info["test_level"] = level
        share = s.min_gap_share if rnd == 1 else max(s.min_gap_share, s.min_gap_share_later)
        needed = share * max(st.nom.rms_val - st.floor_rms, 0.0)
        info["rms_reduction_needed"] = needed
        passing = [n for n, (_, t, _) in results.items() if self._passes(t, level, needed)]
        return level, needed, passing

    def _passes(self, test: dict, level: float, needed: float) -> bool:
        return (test["p_value"] < level and test["rel_reduction"] >= self.s.min_reduction
                and test["rms_base"] - test["rms_cand"] >= needed)

    def _ordered(self, rnd: int, passing: list[str], results: Refitted, level: float,
                 info: dict[str, Any]) -> list[str]:
        """The forms to choose from: a further form of a family already accepted goes first
        (the first form did not catch the whole effect), a new family next; a record's own
        drift (re-estimated on the held-out records themselves) only when no input-tied form
        beats it like with like."""
        pool = [n for n in passing if family_of(n) in self.state.families]
        if pool:
            return pool
        pool, order = _drift_last(passing, results, level, self.s.min_reduction)
        if order:
            info["drift_order"] = order
            self.say(f"round {rnd}: {order['text']}")
            for n in ("drift", order["form"]):
                self.outcomes[n].message = _join(self.outcomes[n].message,
                                                 f"round {rnd}: {order['text']}")
        return pool

    def _confirmed(self, rnd: int, pool: list[str], results: Refitted, level: float,
                   needed: float, info: dict[str, Any],
                   ) -> tuple[str, RefitResult, dict, _Evaluation] | None:
        """The best form (the simplest one no other beats), polished on the whole train part
        (longer than the screening refits, so that a later round does not pick up what an
        unfinished fit left); it must pass the same test again, else the next one is tried."""
        while pool:
            best = min(pool, key=lambda n: results[n][1]["rms_cand"])
            best = _parsimonious(best, pool, {n: (r[0], r[1], r[2].errs)
                                              for n, r in results.items()}, level,
                                 self.s.min_reduction)
            rf, test, ev_best = self.state.refit_whole(best, results[best][0], self.start.tr,
                                                       self.start.ev, results[best], self.say)
            if self._passes(test, level, needed):
                return best, rf, test, ev_best
            info["candidates"][best].update({
                "status": "not confirmed",
                "message": f"passed on its screening refit, not once polished on the whole "
                           f"train part (held-out RMS {test['rms_cand']:.4g}, p = "
                           f"{test['p_value']:.2g})"})
            self.say(f"round {rnd}: {best} not confirmed on the whole train part")
            pool.remove(best)
        return None

    def _accept(self, rnd: int, best: str, rf: RefitResult, test: dict, ev_best: _Evaluation,
                info: dict[str, Any]) -> None:
        """The form joins the model; its outcome and the round's record say so."""
        state = self.state
        rms_before = state.ev.rms_val
        state.accept(best, rf, ev_best, localise(ev_best.segments))
        self.noise_estimates.append(state.where.noise["rms"])
        o = self.outcomes[best]
        o.status, o.round = "accepted", rnd
        o.params = effect_dict(rf.phi, [best])[best]
        o.at_bound = [b for b in rf.at_bound if b.startswith(f"{best}.")]
        o.rms_train_after, o.rms_val_after, o.test = ev_best.rms_train, ev_best.rms_val, test
        o.cumulative = {"rms_val_before": rms_before, "rms_val": ev_best.rms_val,
                        "p_value": test["p_value"], "rel_reduction": test["rel_reduction"]}
        info.update({"accepted": best, "rms_val_after": ev_best.rms_val})
        self.rounds.append(info)
        self.say(f"round {rnd}: accepted {best}: held-out RMS {ev_best.rms_val:.4g}"
                 f"{self.start.unit}")

