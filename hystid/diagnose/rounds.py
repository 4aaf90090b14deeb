"""The parts of a diagnosis around its main loop: its settings and errors, the checks of its
inputs, progress lines, splitting the records, evaluating a model on them (drift scored out of
sample), the admissibility check and the greedy acceptance of effects.
:func:`hystid.diagnose.diagnosis.diagnose` runs them.
"""

from __future__ import annotations

import sys
import time
from collections import deque
from collections.abc import Callable, Sequence
from concurrent.futures import Executor, Future
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from ..baselines import repeat_floor
from ..errors import DiagnosisError
from ..identify.prepare import burn_in, held_out_from, prepare, rest_level
from ..model import DuhemSandwich
from ..records import Record
from .effects import EFFECT_NAMES, EFFECTS, FAMILIES, effect_dict, family_of
from .refit import FitData, RefitResult, duhem_margin, refit, simulate_fit_data
from .result import EffectOutcome
from .screen import ScreenResult, compare_losses
from .structure import delay_as_structure
from .where import Segment, Where

# --------------------------------------------------------------------------- settings
#: Two candidates' held-out corrections ``da, db`` count as alike when
#: ``1 - |da - db| / max(|da|, |db|)`` exceeds this.
ALIKE = 0.75
#: Forms that are parameters of the nominal model (the sensor offset is estimated by every fit).
IN_NOMINAL = ("offset",)
#: The candidates by default: every form that is not part of the nominal model.
DEFAULT_EFFECTS = tuple(n for n in EFFECT_NAMES if n not in IN_NOMINAL)


#: A later round runs only when the reduction it needs leaves the held-out RMS above this share
#: of the floor (no model explains the sensor noise).
NOISE_REACH = 0.9
#: Factor an accepted form's guessed search ranges widen by when a parameter ends at a bound.
WIDEN = 4.0

#: Fewest samples in the train part and in the held-out part (after its transient or burn-in).
#: A 200 Hz stage's record of four 1 Hz cycles has 800 (the stage-B look-alike,
#: ``tests/test_diagnose_in_motion.py``), some 40 per parameter of the nominal model and an
#: effect.
MIN_TRAIN_SAMPLES = 500
MIN_VAL_SAMPLES = 250


# --------------------------------------------------------------------------- progress
class _Progress:
    def __init__(self, progress: bool | Callable[[str], None]):
        self.t0 = time.perf_counter()
        if callable(progress):
            self.fn = progress
        elif progress:
            self.fn = lambda m: print(f"[{time.perf_counter() - self.t0:6.1f} s] diagnose: {m}",
                                      file=sys.stderr, flush=True)
        else:
            self.fn = None

    def __call__(self, message: str) -> None:
        if self.fn is not None:
            self.fn(message)


# --------------------------------------------------------------------------- input checks
def _as_records(val) -> list[Record]:
    if val is None:
        return []
    if isinstance(val, Record):
        return [val]
    out = list(val)
    for i, v in enumerate(out):
        if not isinstance(v, Record):
            raise DiagnosisError(f"val[{i}]: expected a Record, got {type(v).__name__}")
    return out


def _rest_level(rec: Record, label: str, required: bool = True) -> float | None:
    """Mean output before the input first moves (None, when not required, for a record that
    does not start with 10 samples at rest)."""
    moved = np.flatnonzero(rec.u != rec.u[0])
    k = int(moved[0]) if len(moved) else rec.n
    if k < 10:
        if not required:
            return None
        raise DiagnosisError(
            f"{label} {rec.name!r}: initial='level' needs at least 10 samples at rest before "
            f"the input first moves, found {k}")
    return float(np.mean(rec.y[:k]))


def _check_inputs(train: Record, vals: list[Record], holdout: float, transient: float) -> None:
    if not isinstance(train, Record):
        raise DiagnosisError(f"train: expected a Record, got {type(train).__name__}")
    for i, v in enumerate(vals):
        if not isinstance(v, Record):
            raise DiagnosisError(f"val[{i}]: expected a Record, got {type(v).__name__}")
        if not np.isclose(v.fs, train.fs, rtol=1e-9):
            raise DiagnosisError(
                f"val[{i}] {v.name!r}: sampling rate {v.fs:g} Hz differs from the train record's "
                f"{train.fs:g} Hz (expected the same rate)")
        if v.units != train.units:
            raise DiagnosisError(
                f"val[{i}] {v.name!r}: in u={v.units.get('u')}, y={v.units.get('y')} but the "
                f"train record in u={train.units.get('u')}, y={train.units.get('y')} (expected "
                "records in one set of units)")
    for label, rec in [("train", train)] + [(f"val[{i}]", v) for i, v in enumerate(vals)]:
        if np.ptp(rec.u) == 0:
            raise DiagnosisError(f"{label} {rec.name!r}: the input is constant; nothing excites "
                                 "the stage (expected a varying input)")
        if np.ptp(rec.y) == 0:
            raise DiagnosisError(f"{label} {rec.name!r}: the output is constant (expected a "
                                 "measured response)")
    if vals:
        if train.n < MIN_TRAIN_SAMPLES:
            raise DiagnosisError(
                f"train {train.name!r}: {train.n} samples is too short (expected at least "
                f"{MIN_TRAIN_SAMPLES})")
        for i, v in enumerate(vals):
            skip = held_out_skip(v, transient)
            if v.n - skip < MIN_VAL_SAMPLES:
                what = ("transient" if rest_level(v.u)[1] else
                        "burn-in (it begins in motion)")
                raise DiagnosisError(
                    f"val[{i}] {v.name!r}: {v.n} samples is too short (expected at least "
                    f"{MIN_VAL_SAMPLES} after the {skip}-sample {what})")
    else:
        if not 0.05 <= holdout <= 0.8:
            raise DiagnosisError(f"holdout: expected a fraction in [0.05, 0.8], got {holdout}")
        k = held_out_from(train.u, holdout)
        if k < MIN_TRAIN_SAMPLES or train.n - k < MIN_VAL_SAMPLES:
            raise DiagnosisError(
                f"train {train.name!r}: {train.n} samples is too short to hold out "
                f"{100 * holdout:.0f} % of its excitation ({k} train and {train.n - k} held-out "
                f"samples; expected at least {MIN_TRAIN_SAMPLES} train and {MIN_VAL_SAMPLES} "
                "held-out samples)")


# --------------------------------------------------------------------------- stages
def _expand_families(effects: Sequence[str]) -> list[str]:
    """Family names stand for all their forms (``creep`` -> ``creep, creep_2tau, ...``); forms
    that are part of the nominal model are left out (an error when nothing else is asked)."""
    out: list[str] = []
    for n in effects:
        forms = [f for f in FAMILIES.get(n, (n,)) if f not in IN_NOMINAL]
        out += [f for f in forms if f not in out]
    if not out and any(n in IN_NOMINAL for n in effects):
        raise ValueError(f"effects: {', '.join(n for n in effects if n in IN_NOMINAL)} is a "
                         "parameter of the nominal model (the sensor offset is estimated with "
                         "it), not a candidate; name others")
    return out


def _join(a: str, b: str) -> str:
    return f"{a}; {b}" if a and b else (a or b)


def _repeat_floor(train: Record, vals: list[Record],
                  repeats: Sequence[Record] | None) -> float | None:
    """Repeatability of the records of one input, or None without repeats."""
    if not repeats:
        return None
    reps = _as_records(repeats)
    for ref in [train, *vals]:
        if ref.n == reps[0].n and np.allclose(ref.u, reps[0].u,
                                              atol=1e-3 * (np.ptp(ref.u) or 1.0)):
            try:
                return repeat_floor([ref, *reps])
            except ValueError as err:
                raise DiagnosisError(f"repeats: {err}") from err
    raise DiagnosisError(f"repeats {reps[0].name!r}: its input is not that of the train record "
                         "or of a held-out record (expected repeats of one of their inputs, "
                         "equally long)")


def held_out_skip(rec: Record, transient: float) -> int:
    """Leading samples of a held-out record left out of its score: the ``transient`` (seconds)
    of a record that starts at rest, the burn-in (:func:`~hystid.identify.prepare.burn_in`)
    of one that begins in motion, as :func:`hystid.baselines.compare` scores it.

    Parameters
    ----------
    rec : Record
        A held-out record.
    transient : float
        Seconds dropped at the start of a record.

    Returns
    -------
    int
        The first sample scored.
    """
    return max(int(round(transient * rec.fs)), burn_in(rec.u, rest_level(rec.u)[1]))


def _split(train: Record, vals: list[Record], holdout: float, transient: float, skip_tr: int,
           initial: str, u_rest: float) -> tuple[FitData, list[FitData], list[float], str]:
    """The train part and the held-out parts as :class:`FitData` (input less ``u_rest``)."""
    fs = train.fs

    def level(rec: Record, label: str) -> float | None:
        if initial == "rest":
            return None
        return _rest_level(rec, label, required=initial == "level")

    if vals:
        tr = FitData(train.u - u_rest, train.y, fs, level(train, "train"),
                     slice(skip_tr, None))
        skips = [held_out_skip(v, transient) for v in vals]
        vds = [FitData(v.u - u_rest, v.y, fs, level(v, f"val[{i}]"), slice(k, None))
               for i, (v, k) in enumerate(zip(vals, skips, strict=True))]
        return tr, vds, [k / fs for k in skips], "held-out records"
    k = held_out_from(train.u, holdout)
    lev = level(train, "train")
    tr = FitData(train.u[:k] - u_rest, train.y[:k], fs, lev, slice(skip_tr, None))
    vds = [FitData(train.u - u_rest, train.y, fs, lev, slice(k, None))]
    return tr, vds, [k / fs], f"last {100 * holdout:.0f} % of the train record's excitation"


@dataclass
class _Evaluation:
    """Train and held-out errors of one model (drift re-estimated per record when on)."""

    rms_train: float
    errs: list[np.ndarray]
    segments: list[Segment]
    scales: tuple[float, float]
    margin_val: float
    finite: bool
    #: Held-out errors with each record's drift scored out of sample
    #: (:func:`_drift_out_of_sample`); the errors themselves without the drift.
    errs_oos: list[np.ndarray] = field(default_factory=list)

    @property
    def rms_val(self) -> float:
        return _rms(self.errs)


class _Evaluator:
    """Simulates a model over the train and held-out parts.

    The drift is a nuisance of each record: its parameters (fitted on the train record) are
    zero on the held-out records; with ``drift`` on, a drift ``d1 t + d2 t^2 + d3 t^3`` is
    re-estimated on each of them by least squares, so the held-out error is what the model
    explains beyond it.
    """

    def __init__(self, tr: FitData, vds: list[FitData], t0s: list[float]) -> None:
        self.tr, self.vds, self.t0s = tr, vds, t0s
        self.drift_slots = list(EFFECTS["drift"].slots)

    def private(self) -> _Evaluator:
        """The same evaluator on simulation workspaces of its own (for another thread)."""
        return _Evaluator(replace(self.tr), [replace(v) for v in self.vds], self.t0s)

    def __call__(self, m: DuhemSandwich, phi: np.ndarray, drift: bool) -> _Evaluation:
        tr = self.tr
        w1, _, yh = simulate_fit_data(m, phi, tr)
        e_tr = tr.y[tr.weight] - yh[tr.weight]
        scales = (float(np.max(np.abs(np.diff(w1)))), float(np.max(np.abs(w1))))
        phi_val = np.array(phi, float)
        phi_val[self.drift_slots] = 0.0
        errs, errs_oos, segs, margin = [], [], [], 0.0
        for vd, t0 in zip(self.vds, self.t0s, strict=True):
            w1v, _, yv = simulate_fit_data(m, phi_val, vd)
            sl = vd.weight
            yv = yv.copy()
            raw = vd.y[sl] - yv[sl]
            if drift:
                t = np.arange(len(vd.u))[sl] / vd.fs
                yv[sl] += _drift_fit(t, raw)
                errs_oos.append(raw - _drift_out_of_sample(t, raw))
            errs.append(vd.y[sl] - yv[sl])
            if not drift:
                errs_oos.append(errs[-1])
            segs.append(Segment(vd.u[sl], vd.y[sl], yv[sl], w1v[sl].copy(), vd.fs, t0))
            margin = max(margin, duhem_margin(m.theta, m.structure, phi_val, w1v[sl]))
        finite = bool(np.isfinite(e_tr).all() and all(np.isfinite(e).all() for e in errs))
        rms_tr = float(np.sqrt(np.mean(e_tr**2)))
        return _Evaluation(rms_tr, errs, segs, scales, margin, finite, errs_oos)


def _drift_basis(t: np.ndarray) -> np.ndarray:
    """Columns ``t, t^2, t^3`` of the drift (zero at the record's start)."""
    return np.column_stack([t, t * t, t**3])


def _drift_fit(t: np.ndarray, e: np.ndarray) -> np.ndarray:
    """Least-squares drift ``d1 t + d2 t^2 + d3 t^3`` of a record's error (the record's own
    drift, zero at its start)."""
    A = _drift_basis(t)
    coef = np.linalg.lstsq(A, e, rcond=None)[0]
    return A @ coef


#: Contiguous blocks of a held-out record for its drift scored out of sample.
DRIFT_BLOCKS = 4


def _drift_out_of_sample(t: np.ndarray, e: np.ndarray,
                         blocks: int = DRIFT_BLOCKS) -> np.ndarray:
    """A record's drift scored on samples it was not fitted on: on each of ``blocks``
    contiguous blocks, the least-squares drift (:func:`_drift_fit`'s form) of the other blocks.

    A drift is not predictable from the input; a creep is. Fitted on the very samples it is
    scored on, a drift follows any slow error, a creep's transient too; fitted elsewhere on the
    record, it extends the record's slow trend and no more.
    """
    A = _drift_basis(t)
    edges = np.linspace(0, len(t), blocks + 1).astype(int)
    out = np.empty(len(t))
    for a, b in zip(edges[:-1], edges[1:], strict=True):
        rest = np.r_[0:a, b:len(t)]
        coef = np.linalg.lstsq(A[rest], e[rest], rcond=None)[0]
        out[a:b] = A[a:b] @ coef
    return out


def _admissibility(model: DuhemSandwich, ev: _Evaluation, vds: list[FitData]) -> list[str]:
    """Why the nominal model cannot be trusted on the held-out input (empty when it can)."""
    out = []
    env = getattr(model, "envelope", None)
    if env is not None:
        for i, vd in enumerate(vds):
            out += [f"held-out record {i}: {m}" for m in env.violations(vd.u + model.u_rest)]
    if not ev.finite:
        out.append("the simulation diverges on the held-out input")
    elif not ev.margin_val < 2.0:
        out.append(f"condition (8) fails on the held-out input: alpha |dw1| reaches "
                   f"{ev.margin_val:.3g} (expected < 2), so the Duhem recursion amplifies there "
                   "and the held-out error is partly the model's own instability")
    return out


class _Greedy:
    """The model the greedy search has reached: nominal parameters, effect vector, accepted
    forms, their families, the evaluation and the localisation."""

    def __init__(self, model: DuhemSandwich, phi: np.ndarray, ev: _Evaluation,
                 where: Where) -> None:
        self.model, self.phi, self.ev, self.where = model, phi, ev, where
        self.active: list[str] = []
        self.families: list[str] = []

    @property
    def drift(self) -> bool:
        """Whether the drift is accepted (re-estimated on every held-out record)."""
        return "drift" in self.active

    def _copy(self, model: DuhemSandwich, phi: np.ndarray, ev: _Evaluation) -> _Greedy:
        out = _Greedy(model, phi, ev, self.where)
        out.active, out.families = list(self.active), list(self.families)
        return out

    def with_drift(self, tr_c: FitData, ev_c: _Evaluator) -> tuple | None:
        """The drift candidate: the current model refitted with the train record's own drift,
        judged with each held-out record's own drift re-estimated. Returns ``(refit, test,
        evaluation, screen entry)``, or None when the refit fails."""
        w1, _, yh = simulate_fit_data(self.model, self.phi, tr_c)
        sl = tr_c.weight
        t = np.arange(len(tr_c.u))[sl] / tr_c.fs
        A = _drift_basis(t)
        coef = np.linalg.lstsq(A, tr_c.y[sl] - yh[sl], rcond=None)[0]
        start = np.array(self.phi, float)
        start[list(EFFECTS["drift"].slots)] = coef
        rf = refit(self.model, tr_c, self.active + ["drift"], [start], base_phi=start,
                   step_scale=self.ev.scales[0], w1_scale=self.ev.scales[1])
        if not rf.ok:
            return None
        m = DuhemSandwich(rf.theta, self.model.structure, fs=self.model.fs, name=self.model.name)
        ev = ev_c(m, rf.phi, drift=True)
        if not ev.finite:
            return None
        score = float(max(0.0, 1.0 - rf.cost / max(self.ev.rms_train**2, 1e-300)))
        entry = ScreenResult("drift", score, 1.0, True, [start])
        return rf, compare_losses(self.ev.errs, ev.errs), ev, entry

    def on_window(self, tr_c: FitData, ev_c: _Evaluator, say: _Progress) -> _Greedy:
        """The current model refitted over the head of the train part (itself when the head
        is the whole part): the base the forms refitted over the head are compared with."""
        say(f"refitting the current model over the first {len(tr_c.u)} train samples")
        rf = refit(self.model, tr_c, self.active, [self.phi], base_phi=self.phi,
                   step_scale=self.ev.scales[0], w1_scale=self.ev.scales[1])
        if not rf.ok:
            return self
        m = DuhemSandwich(rf.theta, self.model.structure, fs=self.model.fs, name=self.model.name)
        return self._copy(m, rf.phi, ev_c(m, rf.phi, self.drift))

    def refit_whole(self, name: str, rf: RefitResult, tr: FitData, ev: _Evaluator,
                    head: tuple[RefitResult, dict, _Evaluation], say: _Progress,
                    ) -> tuple[RefitResult, dict, _Evaluation]:
        """Polish an accepted form on the whole train part from its screening refit (three
        times the evaluations); the test is then taken again against the current model (the
        screening refit's figures are kept when the polish fails)."""
        say(f"polishing {name} on the whole train part")
        start = DuhemSandwich(rf.theta, self.model.structure, fs=self.model.fs)
        active = [n for n in self.active if n != name] + [name]
        whole = refit(start, tr, active, [rf.phi], base_phi=rf.phi,
                      step_scale=self.ev.scales[0], w1_scale=self.ev.scales[1],
                      max_nfev=60)
        if not whole.ok:
            return head
        if any(b.startswith(f"{name}.") for b in whole.at_bound):
            say(f"{name}: {'; '.join(whole.at_bound)}; refitting with the ranges widened "
                f"{WIDEN:g}x")
            wide = refit(start, tr, active, [whole.phi], base_phi=whole.phi,
                         step_scale=self.ev.scales[0], w1_scale=self.ev.scales[1],
                         max_nfev=60, widen=WIDEN)
            if wide.ok and wide.cost < whole.cost:
                whole = wide
            else:
                whole.widen = WIDEN  # tried: the wider range did not fit better
        m = DuhemSandwich(whole.theta, self.model.structure, fs=self.model.fs)
        ev_w = ev(m, whole.phi, self.drift or name == "drift")
        if not ev_w.finite:
            return head
        return whole, _held_out_test(self, name, ev_w), ev_w

    def accept(self, name: str, rf: RefitResult, ev: _Evaluation, where: Where) -> None:
        """Add an accepted form with its refit, evaluation and localisation."""
        self.model = DuhemSandwich(rf.theta, self.model.structure, fs=self.model.fs,
                                   name=self.model.name)
        self.phi = rf.phi
        self.active.append(name)
        self.families.append(family_of(name))
        self.ev, self.where = ev, where


def _plan(scr: dict[str, ScreenResult], remaining: list[str], promising: float,
          refit_all: bool) -> tuple[list[tuple[str, bool]], dict[str, str]]:
    """Which forms to refit, most promising first, and the families the screen rules out.

    A family is ruled out only when none of its forms is excited or every excited form's
    signature matches less than a quarter of what a useful reduction needs. Every other family
    has its best form refitted (``must`` True); its further forms follow when promising.
    """
    by_family: dict[str, list[str]] = {}
    for n in remaining:
        by_family.setdefault(family_of(n), []).append(n)
    must, extra, ruled_out = [], [], {}
    for fam, forms in by_family.items():
        excited = sorted((n for n in forms if scr[n].excited), key=lambda n: -scr[n].score)
        if not excited:
            ruled_out[fam] = "not excited"
            continue
        top = excited[0]
        if not refit_all and scr[top].score < 0.25 * promising:
            ruled_out[fam] = (f"its signature matches {100 * scr[top].score:.2g} % of the train "
                              f"residual (a useful reduction needs {100 * promising:.2g} %)")
            continue
        must.append(top)
        extra += [n for n in excited[1:] if refit_all or scr[n].score >= promising]
    must.sort(key=lambda n: -scr[n].score)
    extra.sort(key=lambda n: -scr[n].score)
    return [(n, True) for n in must] + [(n, False) for n in extra], ruled_out


def _record_screen(outcomes: dict[str, EffectOutcome], scr: dict[str, ScreenResult],
                   ruled_out: dict[str, str], require_excitation: bool) -> None:
    for n, o in outcomes.items():
        if n not in scr:
            continue
        o.screen_score, o.separation = scr[n].score, scr[n].separation
        o.message = scr[n].message
        if not scr[n].excited:
            o.status = "not excited"
            if require_excitation:
                raise DiagnosisError(scr[n].message)
        elif o.family in ruled_out:
            o.message = _join(o.message, f"screened out: {ruled_out[o.family]}")


def _refit_one(state: _Greedy, name: str, scr: ScreenResult,
               tr: FitData) -> tuple[RefitResult, list[str]]:
    """One form refitted on top of the current model, on a workspace of its own (refits run
    side by side); returns the refit and its progress lines, kept for the round to say in
    order."""
    own = replace(tr)  # the record's arrays shared, its simulation workspace not
    lines: list[str] = []
    rf = refit(state.model, own, state.active + [name], scr.starts, base_phi=state.phi,
               step_scale=state.ev.scales[0], w1_scale=state.ev.scales[1],
               joint_starts=len(scr.starts) if name == "delay" else 1, profile=scr.profile)
    if name == "delay" and all(a == "drift" for a in state.active):
        rf = delay_as_structure(state.model, state.phi, state.active, own, rf,
                                state.ev.scales, lines.append, refit)
    return rf, lines


def _refit_round(state: _Greedy, plan: list[tuple[str, bool]], scr: dict[str, ScreenResult],
                 tr: FitData, ev: _Evaluator, info: dict, say: _Progress, rnd: int,
                 budget_end: float | None, pool: Executor, width: int,
                 then: Callable[[], None] | None = None,
                 ) -> dict[str, tuple[RefitResult, dict, _Evaluation]]:
    """Refit the planned forms on top of the current model and test each on the held-out
    part; failures and forms left out by the time budget are recorded in ``info``.

    The refits run in ``pool``, at most ``width`` at a time (its workers), started in the
    plan's order (a form that is not a must is started only while the budget lasts) and
    judged in that order: the results do not depend on the number of workers. ``then`` is
    called once every refit is started (to queue more work behind them)."""
    results: dict[str, tuple[RefitResult, dict, _Evaluation]] = {}
    running: deque[tuple[str, Future]] = deque()
    for n, must in plan:
        while len(running) >= width:
            _judge_refit(state, *running.popleft(), ev, info, say, rnd, results)
        if not must and budget_end is not None and time.perf_counter() > budget_end:
            info["candidates"][n] = {"status": "not refitted",
                                     "message": "not refitted: the time budget was spent on "
                                                "more promising forms"}
            continue
        say(f"round {rnd}: refitting {n} (screen score {scr[n].score:.3g})")
        running.append((n, pool.submit(_refit_one, state, n, scr[n], tr)))
    if then is not None:
        then()
    while running:
        _judge_refit(state, *running.popleft(), ev, info, say, rnd, results)
    return results


def _judge_refit(state: _Greedy, n: str, job: Future, ev: _Evaluator, info: dict,
                 say: _Progress, rnd: int,
                 results: dict[str, tuple[RefitResult, dict, _Evaluation]]) -> None:
    """A finished refit's progress lines, held-out test and record in ``info``."""
    rf, lines = job.result()
    for line in lines:
        say(line)
    ev_n = None
    if rf.ok:
        ev_n = ev(DuhemSandwich(rf.theta, state.model.structure, fs=state.model.fs),
                  rf.phi, drift=state.drift or n == "drift")
        if not ev_n.finite:
            rf.ok, rf.message = False, "the refitted model diverges on the held-out records"
    if not rf.ok:
        info["candidates"][n] = {"status": "failed", "message": f"refit failed: {rf.message}"}
        say(f"round {rnd}: {n}: refit failed ({rf.message})")
        return
    test = _held_out_test(state, n, ev_n)
    results[n] = (rf, test, ev_n)
    info["candidates"][n] = _candidate_info(n, rf, test, ev_n)
    say(f"round {rnd}: {n}: held-out RMS {test['rms_cand']:.4g} "
        f"({100 * test['rel_reduction']:+.1f} %), p = {test['p_value']:.2g}")


def _drift_last(passing: list[str], results: dict, level: float,
                min_reduction: float) -> tuple[list[str], dict[str, Any] | None]:
    """Whether a record's own drift goes before the input-tied forms, compared like with like.

    The drift is re-estimated on every held-out record, while an input-tied form is fixed
    from the train record: scored on the very samples it was fitted on, the drift has an
    advantage no prediction has. Two fair comparisons of the best input-tied form ``X``:

    * *beyond drift*: ``X`` with each held-out record's own drift as well against the drift
      alone (both fitted on the held-out samples): ``X`` explains what a drift does not;
    * *out of sample*: ``X`` against the drift scored on samples it was not fitted on
      (:func:`_drift_out_of_sample`; neither fitted on the samples scored): ``X`` predicts
      the slow error that a drift can only fit after the fact (creep follows the input).

    ``X`` goes first when it wins either test (level ``level``, relative reduction
    ``min_reduction``); the drift goes first otherwise. Returns the pool to choose from and
    the verdict (``form``, the figures and ``text``), or None when there was nothing to
    compare.
    """
    others = [n for n in passing if n != "drift"]
    if "drift" not in passing or not others:
        return list(passing), None
    best = min(others, key=lambda n: results[n][1]["rms_cand"])
    ev_x, ev_d = results[best][2], results["drift"][2]

    def wins(base: list[np.ndarray], cand: list[np.ndarray]) -> tuple[bool, dict]:
        t = compare_losses(base, cand)
        return t["p_value"] < level and t["rel_reduction"] >= min_reduction, t

    beyond, tb = wins(ev_d.errs, _beyond_drift(ev_x))
    predicts, to = wins(ev_d.errs_oos, ev_x.errs)
    order = {"form": best, "drift_first": not (beyond or predicts),
             "rms_drift": tb["rms_base"], "rms_drift_out_of_sample": to["rms_base"],
             "rms_form": to["rms_cand"], "rms_form_beyond_drift": tb["rms_cand"],
             "p_beyond_drift": tb["p_value"], "p_out_of_sample": to["p_value"]}
    figures_b = (f"with each held-out record's own drift as well, held-out RMS "
                 f"{tb['rms_base']:.4g} -> {tb['rms_cand']:.4g} (p = {tb['p_value']:.2g})")
    figures_o = (f"fitted on the train record alone {to['rms_cand']:.4g} against "
                 f"{to['rms_base']:.4g} for a drift fitted on the rest of each held-out record "
                 f"(p = {to['p_value']:.2g}; {tb['rms_base']:.4g} when the drift is scored on "
                 "the samples it was fitted on)")
    if beyond:
        order["text"] = (f"{best} goes before the drift: it explains what each record's own "
                         f"drift does not ({figures_b})")
    elif predicts:
        order["text"] = (f"{best} goes before the drift: it predicts the held-out records' "
                         f"slow error better than a drift can ({figures_o})")
    else:
        order["text"] = (f"the drift goes before {best}: {best} explains no more than each "
                         f"record's own drift ({figures_b}) and predicts the held-out records "
                         f"no better than a drift scored out of sample ({figures_o})")
    return (["drift"] if order["drift_first"] else others), order


def _beyond_drift(ev: _Evaluation) -> list[np.ndarray]:
    """Held-out errors less each record's own least-squares drift."""
    out = []
    for e, seg in zip(ev.errs, ev.segments, strict=True):
        t = seg.t0 + np.arange(len(e)) / seg.fs
        out.append(e - _drift_fit(t, e))
    return out


def _extends(name: str, active: list[str]) -> bool:
    """Whether a form of an accepted family can join the accepted forms (no shared
    parameters): a further form of the same effect."""
    taken = {s for a in active for s in EFFECTS[a].slots}
    return not taken & set(EFFECTS[name].slots)


def _candidate_info(name: str, rf: RefitResult, test: dict, ev: _Evaluation) -> dict[str, Any]:
    """A refitted form's figures in a round's record."""
    out = {"status": "refitted", "rms_val_after": ev.rms_val, "p_value": test["p_value"],
           "rel_reduction": test["rel_reduction"], "params": effect_dict(rf.phi, [name])[name]}
    if rf.at_bound:
        out["at_bound"] = list(rf.at_bound)
    if rf.widen != 1.0:
        out["widened"] = rf.widen
    return out


def _held_out_test(state: _Greedy, name: str, ev: _Evaluation) -> dict[str, float]:
    """The held-out loss test of a form against the current model, on the held-out errors as
    they are (both beyond each record's own drift once the drift is accepted)."""
    return compare_losses(state.ev.errs, ev.errs)


def _rank(outcomes: dict[str, EffectOutcome], accepted: list[str]) -> list[EffectOutcome]:
    """Accepted forms in order, then the others: refitted by held-out RMS, then the rest."""
    ranked = [outcomes[n] for n in accepted]
    rest = [o for n, o in outcomes.items() if n not in accepted]
    status_rank = {"rejected": 0, "screened out": 1, "not refitted": 2, "failed": 3,
                   "not excited": 4}
    rest.sort(key=lambda o: (status_rank.get(o.status, 5),
                             o.rms_val_after if o.rms_val_after is not None else np.inf,
                             -o.screen_score))
    return ranked + rest


def describe_unexplained(where: Where, floor: float) -> dict[str, Any]:
    """What the error left above the floor looks like: band, periodicity, zone, branch.

    Parameters
    ----------
    where : Where
        Localisation of the error left.
    floor : float
        The floor the gap is measured against.

    Returns
    -------
    dict
        ``rms``, ``excess_rms``, ``band_hz``, ``peak_hz``, ``periodic`` (harmonics of a
        repeating input, or None), ``offset_fraction``, ``trend_fraction``, ``worst_zone`` and
        ``branch`` (loop-width and common shares, and the error after the input's turning
        points) and ``text`` (one line each).
    """
    f, t, b, z = where.frequency, where.time, where.branch, where.zone["worst"]
    excess = float(np.sqrt(max(where.rms**2 - floor**2, 0.0)))
    h = f.get("harmonics")
    text = [f"{excess:.3g} RMS above the floor of {floor:.3g}",
            f"band {f['band_hz'][0]:.4g}-{f['band_hz'][1]:.4g} Hz (peak {f['peak_hz']:.4g} Hz)"]
    if h:
        text.append(f"{100 * h['harmonic_fraction']:.0f} % periodic with the input "
                    f"({1 / h['f0_hz']:.4g} s)")
    text.append(f"worst zone: {z['by']} in [{z['bin'][0]:.3g}, {z['bin'][1]:.3g}] "
                f"({z['rms_ratio']:.1f}x the overall RMS)")
    if excess > 0:
        text.append(f"branches: loop-width part {100 * b['width_fraction']:.0f} %, common part "
                    f"{100 * b['common_fraction']:.0f} % of the excess")
    else:
        text.append("branches: no error above the floor to share between them")
    turning = b.get("turning", {})
    if excess > 0 and np.isfinite(turning.get("rms_ratio", np.nan)):
        text.append(f"after the input's turning points ({100 * turning['share_samples']:.0f} % "
                    f"of the samples): RMS {turning['rms_ratio']:.2g}x the rest's, "
                    f"{100 * turning['excess_share']:.0f} % of the excess")
    return {"rms": where.rms, "excess_rms": excess, "band_hz": f["band_hz"],
            "peak_hz": f["peak_hz"], "periodic": h or None,
            "offset_fraction": t["mean_fraction"], "trend_fraction": t["trend_fraction"],
            "worst_zone": z, "branch": {"width_fraction": b["width_fraction"],
                                        "common_fraction": b["common_fraction"],
                                        "turning": b.get("turning", {})},
            "text": text}


def _parsimonious(best: str, passing: list[str], results: dict, level: float,
                  min_reduction: float) -> str:
    """The passing candidate with the fewest parameters that ``best`` does not beat.

    ``best`` has the lowest held-out RMS; a passing candidate with fewer new parameters is
    preferred unless ``best`` lowers the held-out error below *its* error by the same test
    (level ``level``, relative reduction ``min_reduction``). Two effects that correct the error
    alike (an offset and an asymmetry that mostly shifts the output, say) then resolve to the
    simpler one; the greedy search can still add the other in a later round.
    """
    size = len(EFFECTS[best].params)
    simpler = sorted((n for n in passing if len(EFFECTS[n].params) < size),
                     key=lambda n: (len(EFFECTS[n].params), results[n][1]["rms_cand"]))
    for n in simpler:
        t = compare_losses(results[n][2], results[best][2])
        if not (t["p_value"] < level and t["rel_reduction"] >= min_reduction):
            return n
    return best


def _mark_alike(outcomes: dict[str, EffectOutcome], base: list[np.ndarray],
                cand: dict[str, list[np.ndarray]]) -> None:
    """Note the pairs of candidates whose corrections of the held-out error are alike."""
    eb = np.concatenate(base)
    deltas = {n: eb - np.concatenate(e) for n, e in cand.items()}
    names = list(deltas)
    for i, a in enumerate(names):
        for b in names[i + 1:]:
            scale = max(np.linalg.norm(deltas[a]), np.linalg.norm(deltas[b]))
            if scale == 0:
                continue
            alike = 1.0 - float(np.linalg.norm(deltas[a] - deltas[b]) / scale)
            if alike > ALIKE:
                outcomes[a].alike[b] = alike
                outcomes[b].alike[a] = alike
    for n in names:
        o = outcomes[n]
        if o.alike:
            top = sorted(o.alike.items(), key=lambda kv: -kv[1])[:3]
            others = ", ".join(f"{k} ({100 * v:.0f} %)" for k, v in top)
            note = f"{n} corrects the held-out error like {others}: these records cannot " \
                   f"tell them apart"
            o.message = (o.message + "; " if o.message else "") + note


def _rms(errs: list[np.ndarray]) -> float:
    return float(np.sqrt(np.mean(np.concatenate(errs) ** 2)))


def _cost_mask(tr: FitData, u_rest: float) -> np.ndarray | None:
    """Make the train part's cost leave out what the identification leaves out
    (:func:`hystid.identify.prepare.prepare`: burn-in, samples after an input jump, outliers,
    a saturated sensor); returns the samples kept, or None when all are kept (or the record
    cannot be prepared)."""
    try:
        prep = prepare(Record(tr.u + u_rest, tr.y, tr.fs, name="train"))
    except ValueError:
        return None
    keep = np.asarray(prep.weight, bool).copy()
    own = np.zeros(len(tr.u), bool)
    own[tr.weight] = True
    keep &= own
    if keep.all() or keep.sum() < MIN_TRAIN_SAMPLES // 2:
        return None
    tr.weight = keep
    return keep
