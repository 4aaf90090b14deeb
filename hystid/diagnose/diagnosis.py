"""The diagnosis of the sim-to-real gap: where it lies, which effect causes it, how far it shrinks.

:func:`diagnose` identifies (or takes) the nominal sandwich on a train record, localises its
held-out simulation error (:mod:`.where`), screens the candidate effects (:mod:`.effects`,
:mod:`.screen`), refits the promising ones from the nominal estimate (:mod:`.refit`) and accepts
one only when it lowers the held-out error significantly for coloured residuals and by a margin
worth having. Greedy: the best accepted effect (the simplest one that no other beats) joins the
model, the error is localised again and the remaining candidates are screened against it, until
none passes.
"""

from __future__ import annotations

import math
import sys
import time
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

from ..identify.offline import fit_output_error
from ..identify.result import IdentificationResult
from ..model import DuhemSandwich, Structure
from ..records import Record
from .effects import EFFECT_NAMES, EFFECTS, AugmentedSandwich, effect_dict
from .refit import FitData, RefitResult, initial_state, refit, simulate_fit_data
from .screen import compare_losses, effect_names_check, screen, zero_vector
from .where import Segment, Where, localise

if TYPE_CHECKING:  # pragma: no cover
    import os
    from pathlib import Path

__all__ = [
    "ALIKE",
    "MIN_TRAIN_SAMPLES",
    "MIN_VAL_SAMPLES",
    "DiagnosisError",
    "DiagnosisResult",
    "EffectOutcome",
    "diagnose",
]

#: Two candidates' held-out corrections ``da, db`` count as alike when
#: ``1 - |da - db| / max(|da|, |db|)`` exceeds this.
ALIKE = 0.75
#: Fewest samples in the train part and in the held-out part.
MIN_TRAIN_SAMPLES = 2000
MIN_VAL_SAMPLES = 1000


class DiagnosisError(ValueError):
    """Bad input for a diagnosis (too short, not excited, mismatched sampling rates...)."""


@dataclass
class EffectOutcome:
    """What the diagnosis found for one candidate effect.

    Figures ``*_after`` are those of the candidate added alone to the nominal model (round 1);
    an accepted candidate also carries the cumulative figures of the accepted set up to it.

    Attributes
    ----------
    name : str
        Effect name.
    status : str
        ``accepted``, ``rejected`` (refit, not significant or not worth having),
        ``screened out``, ``not excited`` or ``failed`` (the refit failed).
    screen_score : float
        Share of the train residual its signature matches.
    separation : float
        Share of its signature the nominal model cannot absorb.
    params : dict or None
        Fitted effect parameters.
    rms_train_after, rms_val_after : float or None
        RMS errors after the refit.
    gap_closed : float or None
        ``(rms_val_nominal - rms_val_after) / (rms_val_nominal - noise_floor_rms)``.
    test : dict
        The held-out loss-differential test (:func:`~hystid.diagnose.screen.compare_losses`).
    message : str
        Why it was not excited or why the refit failed.
    round : int or None
        Greedy round in which it was accepted.
    cumulative : dict or None
        ``rms_val`` and ``gap_closed`` of the accepted set up to this effect.
    alike : dict
        Other candidates whose held-out correction is nearly this one's (similarity above
        :data:`ALIKE`): the records cannot tell them apart.
    """

    name: str
    status: str
    screen_score: float = 0.0
    separation: float = 0.0
    params: dict[str, float] | None = None
    rms_train_after: float | None = None
    rms_val_after: float | None = None
    gap_closed: float | None = None
    test: dict[str, float] = field(default_factory=dict)
    message: str = ""
    round: int | None = None
    cumulative: dict[str, float] | None = None
    alike: dict[str, float] = field(default_factory=dict)

    @property
    def accepted(self) -> bool:
        """True when the effect joined the model."""
        return self.status == "accepted"

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready figures."""
        return _clean({
            "name": self.name,
            "accepted": self.accepted,
            "status": self.status,
            "rms_val_after": self.rms_val_after,
            "gap_closed": self.gap_closed,
            "rms_train_after": self.rms_train_after,
            "rel_reduction": self.test.get("rel_reduction"),
            "p_value": self.test.get("p_value"),
            "screen_score": self.screen_score,
            "separation": self.separation,
            "params": self.params,
            "test": self.test,
            "round": self.round,
            "cumulative": self.cumulative,
            "alike": self.alike,
            "message": self.message,
        })


@dataclass
class DiagnosisResult:
    """Result of :func:`diagnose`. Unpacks as ``where, effects, accepted``.

    Attributes
    ----------
    noise_floor_rms : float
        Sensor noise floor estimated from the data.
    nominal : dict
        ``rms_val`` and ``rms_train`` of the nominal model, its parameters and name.
    where : Where
        Localisation of the nominal model's held-out error.
    effects : list of EffectOutcome
        Candidates, best first (accepted ones first, in the order they were accepted).
    accepted : list of str
        Accepted effects in order.
    final : dict
        Held-out RMS and gap closed by the accepted set; its parameters.
    rounds : list of dict
        One entry per greedy round (base RMS, findings, accepted effect).
    model : DuhemSandwich
        The nominal model the candidates were compared with (refitted with their cost and
        initial state when a model was given, ``initial='level'`` or ``train_skip``).
    augmented : AugmentedSandwich
        The final model with the accepted effects.
    where_final : Where
        Localisation after the accepted effects.
    settings : dict
        Settings of the run.
    """

    noise_floor_rms: float
    nominal: dict[str, Any]
    where: Where
    effects: list[EffectOutcome]
    accepted: list[str]
    final: dict[str, Any]
    rounds: list[dict[str, Any]]
    model: DuhemSandwich
    augmented: AugmentedSandwich
    where_final: Where
    settings: dict[str, Any] = field(default_factory=dict)
    series: dict[str, Any] = field(default_factory=dict, repr=False)

    def __iter__(self) -> Iterator[Any]:
        yield self.where
        yield self.effects
        yield self.accepted

    @property
    def best(self) -> str:
        """Name of the accepted effect that explains most, or ``"none"``."""
        return self.accepted[0] if self.accepted else "none"

    def to_dict(self) -> dict[str, Any]:
        """The issue's JSON object (``noise_floor_rms``, ``nominal``, ``where``, ``effects``...)."""
        return _clean({
            "noise_floor_rms": self.noise_floor_rms,
            "nominal": self.nominal,
            "where": self.where.to_dict(),
            "effects": [e.to_dict() for e in self.effects],
            "accepted": list(self.accepted),
            "best": self.best,
            "final": self.final,
            "rounds": self.rounds,
            "settings": self.settings,
        })

    def summary(self) -> str:
        """A readable summary (what ``hystid diagnose`` prints)."""
        from .report import summary_text

        return summary_text(self)

    def plot(self, out_dir: str | os.PathLike[str]) -> list[Path]:
        """Write the figures (error in time, spectrum, branches, gap per candidate) to
        ``out_dir``; returns their paths."""
        from .report import plot_diagnosis

        return plot_diagnosis(self, out_dir)


def _clean(obj):
    """Make a structure JSON-safe: numpy scalars to Python, non-finite floats to None."""
    if isinstance(obj, dict):
        return {str(k): _clean(v) for k, v in obj.items()}
    if isinstance(obj, list | tuple):
        return [_clean(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return [_clean(v) for v in obj.tolist()]
    if isinstance(obj, bool | np.bool_):
        return bool(obj)
    if isinstance(obj, int | np.integer):
        return int(obj)
    if isinstance(obj, float | np.floating):
        return float(obj) if math.isfinite(obj) else None
    return obj


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


def _rest_level(rec: Record, label: str) -> float:
    moved = np.flatnonzero(rec.u != rec.u[0])
    k = int(moved[0]) if len(moved) else rec.n
    if k < 10:
        raise DiagnosisError(
            f"{label} {rec.name!r}: initial='level' needs at least 10 samples at rest before "
            f"the input first moves, found {k}")
    return float(np.mean(rec.y[:k]))


def _check_inputs(train: Record, vals: list[Record], holdout: float, transient: float) -> None:
    if not isinstance(train, Record):
        raise DiagnosisError(f"train: expected a Record, got {type(train).__name__}")
    for i, v in enumerate(vals):
        if not np.isclose(v.fs, train.fs, rtol=1e-9):
            raise DiagnosisError(
                f"val[{i}] {v.name!r}: sampling rate {v.fs:g} Hz differs from the train record's "
                f"{train.fs:g} Hz (expected the same rate)")
    if vals:
        if train.n < MIN_TRAIN_SAMPLES:
            raise DiagnosisError(
                f"train {train.name!r}: {train.n} samples is too short (expected at least "
                f"{MIN_TRAIN_SAMPLES})")
        skip = int(round(transient * train.fs))
        for i, v in enumerate(vals):
            if v.n - skip < MIN_VAL_SAMPLES:
                raise DiagnosisError(
                    f"val[{i}] {v.name!r}: {v.n} samples is too short (expected at least "
                    f"{MIN_VAL_SAMPLES} after the {skip}-sample transient)")
    else:
        if not 0.05 <= holdout <= 0.8:
            raise DiagnosisError(f"holdout: expected a fraction in [0.05, 0.8], got {holdout}")
        k = int(round((1 - holdout) * train.n))
        if k < MIN_TRAIN_SAMPLES or train.n - k < MIN_VAL_SAMPLES:
            raise DiagnosisError(
                f"train {train.name!r}: {train.n} samples is too short to hold out "
                f"{100 * holdout:.0f} % (expected at least {MIN_TRAIN_SAMPLES} train and "
                f"{MIN_VAL_SAMPLES} held-out samples)")
    for label, rec in [("train", train)] + [(f"val[{i}]", v) for i, v in enumerate(vals)]:
        if np.ptp(rec.u) == 0:
            raise DiagnosisError(f"{label} {rec.name!r}: the input is constant; nothing excites "
                                 "the stage (expected a varying input)")
        if np.ptp(rec.y) == 0:
            raise DiagnosisError(f"{label} {rec.name!r}: the output is constant (expected a "
                                 "measured response)")


# --------------------------------------------------------------------------- main entry
def diagnose(
    train: Record,
    val: Record | Sequence[Record] | None = None,
    model: DuhemSandwich | IdentificationResult | None = None,
    *,
    structure: Structure | None = None,
    effects: Sequence[str] = EFFECT_NAMES,
    holdout: float = 0.4,
    alpha: float = 0.01,
    min_reduction: float = 0.02,
    max_rounds: int = 3,
    transient: float = 0.0017,
    train_skip: float = 0.0,
    initial: str = "rest",
    refit_all: bool = False,
    require_excitation: bool = False,
    progress: bool | Callable[[str], None] = True,
) -> DiagnosisResult:
    """Diagnose the sim-to-real gap of the Duhem sandwich on measured records.

    Parameters
    ----------
    train : Record
        Record to identify on (it starts at rest unless ``initial='level'``).
    val : Record or sequence of Record, optional
        Held-out records. Without them the last ``holdout`` share of ``train`` is held out (the
        model runs through the whole record; only the head is fitted).
    model : DuhemSandwich or IdentificationResult, optional
        The model to diagnose; identified on ``train`` by output-error least squares when
        omitted. A given model is also refitted alone, so that candidates are compared with a
        model fitted the same way.
    structure : Structure, optional
        Structure for the identification; the paper's experimental one by default.
    effects : sequence of str
        Candidate effects (all of :data:`~hystid.diagnose.effects.EFFECT_NAMES` by default).
    holdout : float
        Share of ``train`` held out when no ``val`` is given.
    alpha : float
        Family-wise level of the held-out test in each round (Bonferroni over the candidates
        refitted in that round).
    min_reduction : float
        Smallest relative reduction of the held-out RMS worth having (0.02 = 2 %).
    max_rounds : int
        Greedy rounds at most.
    transient : float
        Seconds dropped at the start of each separate held-out record (the paper's 0.0017 s).
    train_skip : float
        Seconds at the start of the train record simulated but left out of the refits' cost
        (an initial state the model cannot represent); the nominal model is then refitted alone
        with the same cost before the candidates are compared with it.
    initial : {'rest', 'level'}
        ``rest``: records start at rest at zero output. ``level``: at rest at the mean output
        measured before the input first moves (the Duhem state holds the remanent value).
    refit_all : bool
        Refit every excited candidate, not only the promising ones.
    require_excitation : bool
        Raise :class:`DiagnosisError` when a candidate cannot be shown by the records instead
        of reporting it as not excited.
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
        names = effect_names_check(effects)
    except ValueError as err:
        raise DiagnosisError(str(err)) from err
    if initial not in ("rest", "level"):
        raise DiagnosisError(f"initial: expected 'rest' or 'level', got {initial!r}")
    if not 0 < alpha < 1:
        raise DiagnosisError(f"alpha: expected a level in (0, 1), got {alpha}")
    if not 0 <= min_reduction < 1:
        raise DiagnosisError(f"min_reduction: expected a fraction in [0, 1), got {min_reduction}")
    fs = train.fs
    skip_tr = int(round(train_skip * fs))
    if train_skip < 0 or skip_tr > 0.5 * train.n * (1 if vals else 1 - holdout):
        raise DiagnosisError(f"train_skip: expected 0 <= train_skip <= half the train part, got "
                             f"{train_skip} s")
    level = (lambda r, lab: _rest_level(r, lab)) if initial == "level" else (lambda r, lab: None)

    # ----------------------------------------------------------------- data
    if vals:
        tr = FitData(train.u, train.y, fs, level(train, "train"), slice(skip_tr, None))
        skip = int(round(transient * fs))
        vds = [FitData(v.u, v.y, fs, level(v, f"val[{i}]"), slice(skip, None))
               for i, v in enumerate(vals)]
        t0s = [skip / fs] * len(vds)
        held = "held-out records"
    else:
        k = int(round((1 - holdout) * train.n))
        lev = level(train, "train")
        tr = FitData(train.u[:k], train.y[:k], fs, lev, slice(skip_tr, None))
        vds = [FitData(train.u, train.y, fs, lev, slice(k, None))]
        t0s = [k / fs]
        held = f"last {100 * holdout:.0f} % of the train record"
    say(f"{len(tr.u)} train samples, {sum(len(v.u[v.weight]) for v in vds)} held-out samples "
        f"({held}) at {fs:g} Hz; candidates: {', '.join(names)}")

    # ----------------------------------------------------------------- nominal model
    given = model is not None
    if isinstance(model, IdentificationResult):
        model = model.model
    if model is not None and not isinstance(model, DuhemSandwich):
        raise DiagnosisError(f"model: expected a DuhemSandwich, got {type(model).__name__}")
    if model is not None and not np.isclose(model.fs, fs, rtol=1e-9):
        raise DiagnosisError(f"model: sampling rate {model.fs:g} Hz differs from the records' "
                             f"{fs:g} Hz")
    if model is None:
        say("identifying the nominal sandwich (output-error least squares)")
        nominal = _identify(tr, structure)
    else:
        nominal = model
    phi0 = zero_vector()

    def evaluate(m: DuhemSandwich, phi: np.ndarray):
        w1, _, yh = simulate_fit_data(m, phi, tr)
        e_tr = tr.y[tr.weight] - yh[tr.weight]
        errs, segs = [], []
        for vd, t0 in zip(vds, t0s, strict=True):
            w1v, _, yv = simulate_fit_data(m, phi, vd)
            sl = vd.weight
            errs.append((vd.y[sl] - yv[sl]).copy())
            segs.append(Segment(vd.u[sl], vd.y[sl], yv[sl].copy(), w1v[sl].copy(), fs, t0))
        scales = (float(np.max(np.abs(np.diff(w1)))), float(np.max(np.abs(w1))))
        return float(np.sqrt(np.mean(e_tr**2))), errs, segs, scales

    rms_tr_first, errs_first, _, _ = evaluate(nominal, phi0)
    if not all(np.all(np.isfinite(e)) for e in errs_first) or not np.isfinite(rms_tr_first):
        raise DiagnosisError("the nominal model's simulation diverges on these records (the "
                             "Duhem stability condition (8) fails): scale the input down")
    rms_val_first = _rms(errs_first)
    say(f"nominal model: train RMS {rms_tr_first:.4g}, held-out RMS {rms_val_first:.4g}")

    base_model, base_phi, base_active = nominal, phi0, []
    first_fit = None
    if given or initial == "level" or skip_tr > 0:
        # the candidates are refitted with this cost and initial state: so is the base
        say("refitting the nominal model alone (the base the candidates are compared with)")
        rb = refit(nominal, tr, [], [phi0])
        if rb.ok and rb.cost <= rms_tr_first**2:
            base_model = DuhemSandwich(rb.theta, nominal.structure, fs=fs, name=nominal.name)
            first_fit = {"rms_val": rms_val_first, "rms_train": rms_tr_first,
                         "params": nominal.params,
                         "note": "the given or first-identified model; the nominal figures are "
                                 "those of its refit with the candidates' cost and initial state"}
    rms_tr_nom, errs_nom, segs_nom, (step_scale, w1_scale) = evaluate(base_model, base_phi)
    rms_val_nom = _rms(errs_nom)
    if first_fit is not None:
        say(f"nominal model refitted: train RMS {rms_tr_nom:.4g}, held-out RMS "
            f"{rms_val_nom:.4g}")
    where0 = localise(segs_nom)
    say(f"noise floor {where0.noise['rms']:.4g}; " + "; ".join(where0.findings[1:3]))
    errs_base, rms_tr_base = errs_nom, rms_tr_nom

    # ----------------------------------------------------------------- greedy rounds
    base_model_nominal = base_model
    outcomes: dict[str, EffectOutcome] = {n: EffectOutcome(n, "screened out") for n in names}
    accepted: list[str] = []
    rounds: list[dict[str, Any]] = []
    nf_estimates = [where0.noise["rms"]]
    where_cur = where0
    errs_cur, rms_tr_cur = errs_base, rms_tr_base
    promising = 0.25 * (1.0 - (1.0 - min_reduction) ** 2)
    cand_errs: dict[str, list[np.ndarray]] = {}
    for rnd in range(1, max_rounds + 1):
        remaining = [n for n in names if n not in accepted]
        if not remaining:
            break
        say(f"round {rnd}: screening {', '.join(remaining)}")
        scr = screen(base_model, base_phi, base_active, tr, remaining, step_scale=step_scale,
                     w1_scale=w1_scale,
                     peaks_hz=where_cur.frequency["peaks_hz"] + [where_cur.frequency["peak_hz"]])
        order = sorted(remaining, key=lambda n: -scr[n].score)
        to_fit = [n for n in order if scr[n].excited
                  and (refit_all or scr[n].score >= promising or n in order[:2])]
        if rnd == 1:
            for n in remaining:
                o = outcomes[n]
                o.screen_score, o.separation = scr[n].score, scr[n].separation
                o.message = scr[n].message
                if not scr[n].excited:
                    o.status = "not excited"
                    if require_excitation:
                        raise DiagnosisError(scr[n].message)
        if not to_fit:
            rounds.append({"round": rnd, "rms_val_base": _rms(errs_cur), "accepted": None,
                           "refitted": [], "findings": where_cur.findings})
            break
        results: dict[str, tuple[RefitResult, dict, list]] = {}
        for n in to_fit:
            say(f"round {rnd}: refitting {n} (screen score {scr[n].score:.3g})")
            rf = refit(base_model, tr, base_active + [n], scr[n].starts, base_phi=base_phi,
                       step_scale=step_scale, w1_scale=w1_scale)
            if not rf.ok:
                if rnd == 1:
                    outcomes[n].status = "failed"
                    outcomes[n].message = f"refit failed: {rf.message}"
                say(f"round {rnd}: {n}: refit failed ({rf.message})")
                continue
            m = DuhemSandwich(rf.theta, base_model.structure, fs=fs, name=base_model.name)
            rms_tr, errs, _, _ = evaluate(m, rf.phi)
            if not all(np.all(np.isfinite(e)) for e in errs):
                if rnd == 1:
                    outcomes[n].status = "failed"
                    outcomes[n].message = "refit diverges on the held-out records"
                continue
            test = compare_losses(errs_cur, errs)
            results[n] = (rf, test, errs)
            say(f"round {rnd}: {n}: held-out RMS {test['rms_cand']:.4g} "
                f"({100 * test['rel_reduction']:+.1f} %), p = {test['p_value']:.2g}")
            if rnd == 1:
                o = outcomes[n]
                o.status = "rejected"
                o.params = effect_dict(rf.phi, [n])[n]
                o.rms_train_after = rms_tr
                o.rms_val_after = test["rms_cand"]
                o.test = test
                cand_errs[n] = errs
        if rnd == 1:
            _mark_alike(outcomes, errs_cur, cand_errs)
        level_r = alpha / max(len(to_fit), 1)
        passing = [n for n, (_, t, _) in results.items()
                   if t["p_value"] < level_r and t["rel_reduction"] >= min_reduction]
        info = {"round": rnd, "rms_val_base": _rms(errs_cur), "refitted": list(results),
                "test_level": level_r, "findings": where_cur.findings, "accepted": None}
        if not passing:
            rounds.append(info)
            say(f"round {rnd}: no candidate passes (level {level_r:.2g}, "
                f"minimum reduction {100 * min_reduction:.0f} %)")
            break
        best = min(passing, key=lambda n: results[n][1]["rms_cand"])
        best = _parsimonious(best, passing, results, level_r, min_reduction)
        rf, test, errs = results[best]
        base_model = DuhemSandwich(rf.theta, base_model.structure, fs=fs, name=base_model.name)
        base_phi = rf.phi
        base_active = base_active + [best]
        accepted.append(best)
        rms_tr_cur, errs_cur, segs_cur, (step_scale, w1_scale) = evaluate(base_model, base_phi)
        where_cur = localise(segs_cur)
        nf_estimates.append(where_cur.noise["rms"])
        o = outcomes[best]
        o.status, o.round = "accepted", rnd
        o.cumulative = {"rms_val": _rms(errs_cur), "p_value": test["p_value"],
                        "rel_reduction": test["rel_reduction"]}
        info.update({"accepted": best, "rms_val_after": _rms(errs_cur)})
        rounds.append(info)
        say(f"round {rnd}: accepted {best}: held-out RMS {_rms(errs_cur):.4g}")

    # ----------------------------------------------------------------- figures of merit
    nf = float(min(nf_estimates))
    gap = rms_val_nom - nf

    def closed(rms):
        return float((rms_val_nom - rms) / gap) if gap > 0 else 0.0

    for o in outcomes.values():
        if o.rms_val_after is not None:
            o.gap_closed = closed(o.rms_val_after)
        if o.cumulative is not None:
            o.cumulative["gap_closed"] = closed(o.cumulative["rms_val"])
    ranked = [outcomes[n] for n in accepted]
    rest = [o for n, o in outcomes.items() if n not in accepted]
    status_rank = {"rejected": 0, "screened out": 1, "failed": 2, "not excited": 3}
    rest.sort(key=lambda o: (status_rank.get(o.status, 4),
                             o.rms_val_after if o.rms_val_after is not None else np.inf,
                             -o.screen_score))
    ranked += rest
    rms_final = _rms(errs_cur)
    final_effects = effect_dict(base_phi, accepted) if accepted else {}
    aug = AugmentedSandwich(base_model, final_effects)
    nominal_info = {
        "rms_val": rms_val_nom,
        "rms_train": rms_tr_nom,
        "gap": gap,
        "params": base_model_nominal.params,
        "name": nominal.name,
    }
    if first_fit is not None:
        nominal_info["first_fit"] = first_fit
    final = {"rms_val": rms_final, "rms_train": rms_tr_cur, "gap_closed": closed(rms_final),
             "effects": final_effects, "params": base_model.params}
    settings = {"alpha": alpha, "min_reduction": min_reduction, "max_rounds": max_rounds,
                "holdout": None if vals else holdout, "transient_s": transient,
                "train_skip_s": train_skip,
                "initial": initial, "candidates": list(names), "fs": fs,
                "train_samples": len(tr.u),
                "val_samples": int(sum(len(v.u[v.weight]) for v in vds)),
                "elapsed_s": time.perf_counter() - say.t0}
    series = {"errs_nominal": errs_nom, "errs_final": errs_cur, "candidate_errs": cand_errs,
              "t0s": t0s}
    say(f"done: {', '.join(accepted) if accepted else 'none'} accepted; held-out RMS "
        f"{rms_val_nom:.4g} -> {rms_final:.4g} (noise floor {nf:.4g})")
    return DiagnosisResult(nf, nominal_info, where0, ranked, accepted, final, rounds,
                           base_model_nominal,
                           aug, where_cur, settings, series)


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
            others = ", ".join(f"{k} ({100 * v:.0f} %)" for k, v in o.alike.items())
            note = f"{n} corrects the held-out error like {others}: these records cannot " \
                   f"tell them apart"
            o.message = (o.message + "; " if o.message else "") + note


def _rms(errs: list[np.ndarray]) -> float:
    return float(np.sqrt(np.mean(np.concatenate(errs) ** 2)))


def _identify(tr: FitData, structure: Structure | None) -> DuhemSandwich:
    """The nominal identification: output-error least squares on the train part.

    With an initial output level, a first fit from rest gives the L2 gain that sets the
    initial Duhem state, and a second fit starts from it.
    """
    rec = Record(tr.u, tr.y, tr.fs, name="train")
    res = fit_output_error(rec, structure)
    if tr.level is not None:
        P = res.model.structure.history
        x0 = initial_state(res.model, tr.level, float(tr.u[0]), P)
        res = fit_output_error(rec, structure, res.model.theta, x0=x0, linear_init=False)
    model = res.model
    model.name = "nominal sandwich"
    return model

