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

import math
import sys
import time
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

from ..baselines import repeat_floor
from ..identify.prepare import prepare
from ..identify.result import IdentificationResult
from ..model import DuhemSandwich, Structure
from ..records import Record
from .effects import EFFECT_NAMES, EFFECTS, FAMILIES, AugmentedSandwich, effect_dict, family_of
from .refit import FitData, RefitResult, duhem_margin, refit, simulate_fit_data
from .screen import ScreenResult, compare_losses, effect_names_check, screen, zero_vector
from .structure import delay_as_structure
from .structure import head as _head
from .structure import identify_nominal as _identify
from .where import Segment, Where, localise

if TYPE_CHECKING:  # pragma: no cover
    import os
    from pathlib import Path

__all__ = [
    "ALIKE",
    "DEFAULT_EFFECTS",
    "IN_NOMINAL",
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
#: Forms that are parameters of the nominal model (the sensor offset is estimated by every fit).
IN_NOMINAL = ("offset",)
#: The candidates by default: every form that is not part of the nominal model.
DEFAULT_EFFECTS = tuple(n for n in EFFECT_NAMES if n not in IN_NOMINAL)


#: A later round runs only when the reduction it needs leaves the held-out RMS above this share
#: of the floor (no model explains the sensor noise).
NOISE_REACH = 0.9

#: Fewest samples in the train part and in the held-out part.
MIN_TRAIN_SAMPLES = 2000
MIN_VAL_SAMPLES = 1000


class DiagnosisError(ValueError):
    """Bad input for a diagnosis (too short, not excited, mismatched sampling rates...)."""


@dataclass
class EffectOutcome:
    """What the diagnosis found for one candidate effect.

    Figures ``*_after`` are those of the candidate added alone to the nominal model (round 1);
    those of an accepted candidate are of the round in which it was accepted (added to the
    forms accepted before it), and ``cumulative`` holds that round's held-out RMS before and
    after it.

    Attributes
    ----------
    name : str
        Form name.
    status : str
        ``accepted``, ``rejected`` (refit, not significant or not worth having),
        ``screened out``, ``not excited``, ``not refitted`` (time budget) or ``failed`` (the
        refit failed; ``message`` says why).
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
    family : str
        The effect family the form belongs to.
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
    family: str = ""

    @property
    def accepted(self) -> bool:
        """True when the effect joined the model."""
        return self.status == "accepted"

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready figures.

        Returns
        -------
        dict
            The outcome's figures by name.
        """
        return _clean({
            "name": self.name,
            "family": self.family or self.name,
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
    series : dict
        Error arrays for the figures.
    floor : dict
        The floor of the gap: ``noise_floor_rms``, ``repeat_floor_rms`` (None without
        repeats), ``rms`` (the larger) and ``kind``.
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
    floor: dict[str, Any] = field(default_factory=dict)

    def __iter__(self) -> Iterator[Any]:
        yield self.where
        yield self.effects
        yield self.accepted

    @property
    def best(self) -> str:
        """Family of the first accepted form (the one that explains most), or ``"none"``."""
        return family_of(self.accepted[0]) if self.accepted else "none"

    @property
    def families(self) -> list[str]:
        """Families of the accepted forms, in order."""
        return [family_of(n) for n in self.accepted]

    def to_dict(self) -> dict[str, Any]:
        """The issue's JSON object (``noise_floor_rms``, ``nominal``, ``where``, ``effects``...).

        Returns
        -------
        dict
            The report, JSON-ready.
        """
        return _clean({
            "noise_floor_rms": self.noise_floor_rms,
            "nominal": self.nominal,
            "where": self.where.to_dict(),
            "effects": [e.to_dict() for e in self.effects],
            "accepted": list(self.accepted),
            "accepted_families": self.families,
            "best": self.best,
            "floor": self.floor,
            "final": self.final,
            "rounds": self.rounds,
            "settings": self.settings,
        })

    def summary(self) -> str:
        """A readable summary (what ``hystid diagnose`` prints).

        Returns
        -------
        str
            Several lines of text.
        """
        from .report import summary_text

        return summary_text(self)

    def plot(self, out_dir: str | os.PathLike[str]) -> list[Path]:
        """Write the figures (error in time, spectrum, branches, gap per candidate) to
        ``out_dir``; returns their paths.

        Parameters
        ----------
        out_dir : path-like
            Folder the PNG files are written into.

        Returns
        -------
        list of Path
            The files written.
        """
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
    budget_factor: float | None = 1.0,
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
        (1.0 by default; None for no limit). Forms left out are reported as
        ``not refitted``.
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
        names = effect_names_check(_expand_families(effects))
    except ValueError as err:
        raise DiagnosisError(str(err)) from err
    if initial not in ("auto", "rest", "level"):
        raise DiagnosisError(f"initial: expected 'auto', 'rest' or 'level', got {initial!r}")
    if not 0 < alpha < 1:
        raise DiagnosisError(f"alpha: expected a level in (0, 1), got {alpha}")
    if not 0 <= min_reduction < 1:
        raise DiagnosisError(f"min_reduction: expected a fraction in [0, 1), got {min_reduction}")
    if refit_samples is not None and refit_samples < MIN_TRAIN_SAMPLES:
        raise DiagnosisError(f"refit_samples: expected at least {MIN_TRAIN_SAMPLES}, got "
                             f"{refit_samples}")
    if time_budget is not None and not time_budget >= 0:
        raise DiagnosisError(f"time_budget: expected seconds >= 0, got {time_budget}")
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
        raise DiagnosisError(f"model: expected a DuhemSandwich, got {type(model).__name__}")
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
        if "drift" in remaining:
            # the drift is a nuisance of every record: refitted with the train record's own
            # drift, judged with each held-out record's own drift re-estimated
            drift_result = window.with_drift(tr_c, ev_c, say)
        others = [n for n in remaining if n != "drift"]
        say(f"round {rnd}: screening {', '.join(others)}")
        scr = screen(base.model, base.phi, base.active, tr_c, others,
                     step_scale=base.ev.scales[0], w1_scale=base.ev.scales[1],
                     peaks_hz=state.where.frequency["peaks_hz"]
                     + [state.where.frequency["peak_hz"]])
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
        results = _refit_round(base, plan, scr, tr_c, ev_c, info, say, rnd, budget_end)
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
        o.rms_train_after, o.rms_val_after, o.test = ev_best.rms_train, ev_best.rms_val, test
        o.cumulative = {"rms_val_before": rms_before, "rms_val": ev_best.rms_val,
                        "p_value": test["p_value"], "rel_reduction": test["rel_reduction"]}
        info.update({"accepted": best, "rms_val_after": ev_best.rms_val})
        rounds.append(info)
        say(f"round {rnd}: accepted {best}: held-out RMS {ev_best.rms_val:.4g}{yu}")

    # ----------------------------------------------------------------- figures of merit
    nf = float(min(nf_estimates))
    floor = {"noise_floor_rms": nf, "repeat_floor_rms": repeat,
             "rms": max(nf, repeat) if repeat is not None else nf,
             "kind": "repeatability" if repeat is not None and repeat > nf else "sensor noise"}
    gap = nom.rms_val - floor["rms"]

    def closed(rms):
        return float((nom.rms_val - rms) / gap) if gap > 0 else 0.0

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
    nominal_info = {"rms_val": nom.rms_val, "rms_train": nom.rms_train, "gap": gap,
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
                           base_placed, aug, state.where, settings, series, floor)


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
        skip = int(round(transient * fs))
        vds = [FitData(v.u - u_rest, v.y, fs, level(v, f"val[{i}]"), slice(skip, None))
               for i, v in enumerate(vals)]
        return tr, vds, [skip / fs] * len(vds), "held-out records"
    k = int(round((1 - holdout) * train.n))
    lev = level(train, "train")
    tr = FitData(train.u[:k] - u_rest, train.y[:k], fs, lev, slice(skip_tr, None))
    vds = [FitData(train.u - u_rest, train.y, fs, lev, slice(k, None))]
    return tr, vds, [k / fs], f"last {100 * holdout:.0f} % of the train record"


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

    def with_drift(self, tr_c: FitData, ev_c: _Evaluator, say: _Progress) -> tuple | None:
        """The drift candidate: the current model refitted with the train record's own drift,
        judged with each held-out record's own drift re-estimated. Returns ``(refit, test,
        evaluation, screen entry)``, or None when the refit fails."""
        say("refitting with the train record's own drift (a nuisance of every record)")
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


def _refit_round(state: _Greedy, plan: list[tuple[str, bool]], scr: dict[str, ScreenResult],
                 tr: FitData, ev: _Evaluator, info: dict, say: _Progress, rnd: int,
                 budget_end: float | None) -> dict[str, tuple[RefitResult, dict, _Evaluation]]:
    """Refit the planned forms on top of the current model and test each on the held-out
    part; failures and forms left out by the time budget are recorded in ``info``."""
    results = {}
    for n, must in plan:
        if not must and budget_end is not None and time.perf_counter() > budget_end:
            info["candidates"][n] = {"status": "not refitted",
                                     "message": "not refitted: the time budget was spent on "
                                                "more promising forms"}
            continue
        say(f"round {rnd}: refitting {n} (screen score {scr[n].score:.3g})")
        rf = refit(state.model, tr, state.active + [n], scr[n].starts, base_phi=state.phi,
                   step_scale=state.ev.scales[0], w1_scale=state.ev.scales[1],
                   joint_starts=len(scr[n].starts) if n == "delay" else 1,
                   profile=scr[n].profile)
        if n == "delay" and all(a == "drift" for a in state.active):
            rf = delay_as_structure(state.model, state.phi, state.active, tr, rf,
                                    state.ev.scales, say, refit)
        ev_n = None
        if rf.ok:
            ev_n = ev(DuhemSandwich(rf.theta, state.model.structure, fs=state.model.fs),
                      rf.phi, drift=state.drift or n == "drift")
            if not ev_n.finite:
                rf.ok, rf.message = False, "the refitted model diverges on the held-out records"
        if not rf.ok:
            info["candidates"][n] = {"status": "failed", "message": f"refit failed: {rf.message}"}
            say(f"round {rnd}: {n}: refit failed ({rf.message})")
            continue
        test = _held_out_test(state, n, ev_n)
        results[n] = (rf, test, ev_n)
        info["candidates"][n] = _candidate_info(n, rf, test, ev_n)
        say(f"round {rnd}: {n}: held-out RMS {test['rms_cand']:.4g} "
            f"({100 * test['rel_reduction']:+.1f} %), p = {test['p_value']:.2g}")
    return results


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
    return {"status": "refitted", "rms_val_after": ev.rms_val, "p_value": test["p_value"],
            "rel_reduction": test["rel_reduction"], "params": effect_dict(rf.phi, [name])[name]}


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
        ``branch`` (loop-width and common shares) and ``text`` (one line each).
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
    text.append(f"branches: loop-width part {100 * b['width_fraction']:.0f} %, common part "
                f"{100 * b['common_fraction']:.0f} % of the excess")
    return {"rms": where.rms, "excess_rms": excess, "band_hz": f["band_hz"],
            "peak_hz": f["peak_hz"], "periodic": h or None,
            "offset_fraction": t["mean_fraction"], "trend_fraction": t["trend_fraction"],
            "worst_zone": z, "branch": {"width_fraction": b["width_fraction"],
                                        "common_fraction": b["common_fraction"]},
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
