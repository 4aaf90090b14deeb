"""The diagnosis ends in a model: the nominal one with its accepted effects, or another member.

After the rounds of :func:`~hystid.diagnose.diagnosis.diagnose`, the candidates for the
hysteresis itself are the other members of the model family
(:data:`hystid.identify.members.MEMBERS`: a PI operator between a static L1 and a third-order
L2, ...). Each is identified on the train record and every candidate - the nominal model, the
nominal model with the accepted effects (:class:`~hystid.diagnose.effects.AugmentedSandwich`)
and the members - is run free on the held-out records and scored alike
(:func:`hystid.baselines.compare`'s rule: each prediction zeroed on the record's own output at
rest). The model with the lowest mean held-out RMS is the diagnosis' model: ``hystid diagnose
--out DIR`` writes it as ``DIR/model.json`` and the report's ``final_model`` gives its held-out
error and the share of the gap between the nominal model and the floor it closes. When a member
wins, the verdict says that the hysteresis operator itself is what the nominal model gets wrong.
"""

from __future__ import annotations

import warnings
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..baselines import rest_zero, simulate_from_rest
from ..metrics import gap_closed
from ..records import Record
from .rounds import held_out_skip

__all__ = ["FINAL_MEMBERS", "FinalModel", "final_model", "fit_member", "member_records"]

#: The members tried as the hysteresis itself (besides the nominal Duhem sandwich). ``gduhem``
#: (the generalised Duhem block) is left out by default: on stage A it closes 57-58 % of the
#: gap where ``pi-stage`` closes 80-89 %, and its fit would treble the final model's time
#: (``final_model(..., members=("gduhem", "pi-stage"))`` tries both).
FINAL_MEMBERS = ("pi-stage",)
#: A candidate replaces a simpler one only when it is better by more than this share.
MARGIN = 0.1
#: A nominal model whose held-out RMS is within this factor of the floor is at the floor: the
#: summary then compares the candidates with its RMS instead of giving shares of a gap of
#: nothing (the localisation's "nothing to localise" uses the same factor).
AT_FLOOR = 1.05


@dataclass
class FinalModel:
    """The diagnosis' model and how every candidate did on the held-out records.

    Attributes
    ----------
    rows : list of dict
        One per candidate: ``candidate``, ``what``, ``rms`` (per held-out record, output
        units), ``mean_rms`` and ``gap_closed`` (share of the nominal model's gap to the floor).
    chosen : str
        The candidate kept.
    model : object
        Its model (a sandwich, or an :class:`~hystid.diagnose.effects.AugmentedSandwich`).
    floor : float
        The floor the gap is measured to (output units).
    verdict : str
        One sentence: what the diagnosis ends in and why.
    records : list of str
        Names of the held-out records.
    """

    rows: list[dict[str, Any]]
    chosen: str
    model: Any
    floor: float
    verdict: str
    records: list[str] = field(default_factory=list)

    def to_dict(self) -> dict[str, Any]:
        """Plain, JSON-ready form.

        Returns
        -------
        dict
        """
        chosen = next(r for r in self.rows if r["candidate"] == self.chosen)
        return {"chosen": self.chosen, "heldout_rms": chosen["mean_rms"],
                "gap_closed": chosen["gap_closed"], "floor": self.floor,
                "verdict": self.verdict, "records": list(self.records),
                "candidates": [dict(r) for r in self.rows]}

    def summary_lines(self, unit: str = "") -> list[str]:
        """Lines for the diagnosis' summary.

        Parameters
        ----------
        unit : str
            The output's unit.

        Returns
        -------
        list of str
        """
        lines = ["model the diagnosis ends in (mean held-out RMS, each record run whole from rest "
                 "and zeroed on its rest output, a record that begins in motion scored after its "
                 "burn-in, as hystid.baselines.compare scores; the rounds above score after the "
                 "transient, from the record's level, so their RMS and gap closed differ for the "
                 "same model):"]
        nominal = self.rows[0]["mean_rms"]
        at_floor = nominal <= AT_FLOOR * self.floor
        if at_floor:  # a share of a gap this small would say -900000 % for a worse candidate
            lines.append(f"  (the nominal model is at the floor of {self.floor:.4g} {unit}: no "
                         "gap to close; each candidate is compared with the nominal's RMS)")
        for r in self.rows:
            mark = "  <- model.json" if r["candidate"] == self.chosen else ""
            how = (f"{r['mean_rms'] / nominal:.3g} x the nominal's RMS" if at_floor else
                   f"{100 * r['gap_closed']:.0f} % of the gap to the floor "
                   f"({self.floor:.4g} {unit})")
            lines.append(f"  {r['candidate']:<28} {r['mean_rms']:.4g} {unit}, {how}{mark}")
        lines.append(self.verdict)
        chosen = next(r for r in self.rows if r["candidate"] == self.chosen)
        gap = ("" if at_floor else
               f", {100 * chosen['gap_closed']:.0f} % of the gap to the floor closed")
        lines.append(f"final: model.json holds {self.chosen}: held-out RMS "
                     f"{chosen['mean_rms']:.4g} {unit} against the nominal model's "
                     f"{nominal:.4g} {unit}{gap} (scored as the table above)")
        return lines


def _predict(model: Any, u: np.ndarray) -> np.ndarray:
    with warnings.catch_warnings(), np.errstate(all="ignore"):
        warnings.simplefilter("ignore")
        return simulate_from_rest(model, u, check=False)


def _scores(model: Any, held: Sequence[tuple[Record, int]]) -> list[float]:
    out = []
    for rec, k in held:
        p = _predict(model, rec.u)
        # zeroed on the record's rest (a tail shares its zero; a record in motion has no rest)
        e = (p + (rest_zero(p, rec) if k == 0 else 0.0) - rec.y)[k:]
        r = float(np.sqrt(np.mean(e ** 2)))
        out.append(r if np.isfinite(r) else float("inf"))
    return out


def member_records(train: Record, vals: Sequence[Record],
                   holdout: float = 0.4) -> tuple[Record, list[tuple[Record, int]]]:
    """The record the members are fitted on and the held-out records they are scored on.

    Parameters
    ----------
    train : Record
        The train record.
    vals : sequence of Record
        Held-out records; without them the train record's first ``1 - holdout`` of its
        excitation is fitted and the rest scored.
    holdout : float
        Share of the train record held out when there are no held-out records.

    Returns
    -------
    tuple
        The record to fit on and ``[(record, first scored sample), ...]``.
    """
    if vals:  # a record that begins in motion is scored after its burn-in, as compare does
        return train, [(v, held_out_skip(v, 0.0)) for v in vals]
    from ..identify.prepare import held_out_from

    k = held_out_from(train.u, holdout)
    return train[:k], [(train, k)]


def fit_member(name: str, record: Record) -> Any:
    """A member of the family identified on ``record`` with its default options.

    Parameters
    ----------
    name : str
        A member of :data:`hystid.identify.members.MEMBERS`.
    record : Record
        The record to fit on (:func:`member_records`).

    Returns
    -------
    object
        The identified model.
    """
    from ..identify import identify

    return identify(record, model=name).model


def final_model(
    result: Any,
    train: Record,
    vals: Sequence[Record],
    *,
    members: Sequence[str] = FINAL_MEMBERS,
    margin: float = MARGIN,
    holdout: float = 0.4,
    given: tuple[str, Any] | None = None,
    progress: Callable[[str], None] | None = None,
) -> FinalModel:
    """Score the nominal model, the nominal model with its effects and the members; keep one.

    Parameters
    ----------
    result : DiagnosisResult
        From :func:`~hystid.diagnose.diagnosis.diagnose` (its ``model``, ``augmented``,
        ``accepted`` and ``floor``; its ``members``, when the diagnosis fitted them beside its
        rounds, are taken as they are).
    train : Record
        The train record.
    vals : sequence of Record
        Held-out records; without them the members are fitted on the train record's first
        ``1 - holdout`` and every candidate is scored on the rest.
    members : sequence of str
        Members of :data:`hystid.identify.members.MEMBERS` tried as the hysteresis.
    margin : float
        Share by which a candidate must beat the simpler ones to be kept (the nominal model,
        then the nominal model with effects, then the members in the order given).
    holdout : float
        Share of the train record held out when there are no held-out records.
    given : (str, model), optional
        A model the user has (any member, e.g. the ``pi-stage`` model ``hystid identify``
        writes by default) and its label: scored alike, after the nominal model, and the
        incumbent: the others replace it only when better by ``margin``.
    progress : callable, optional
        ``progress(message)`` before each fit.

    Returns
    -------
    FinalModel
    """
    from ..identify.members import member

    say = progress or (lambda message: None)
    fit_on, held = member_records(train, vals, holdout)
    candidates: list[tuple[str, str, Any]] = [("nominal", "the nominal model", result.model)]
    if given is not None:
        candidates.append((given[0], "the model given", given[1]))
    if result.accepted:
        candidates.append((f"nominal + {' + '.join(result.accepted)}",
                           "the nominal model with the accepted effects", result.augmented))
    fitted = getattr(result, "members", None) or {}
    for name in members:
        if name not in fitted:
            say(f"final model: fitting the {name} member on {fit_on.name!r}")
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                fitted = {**fitted, name: fit_member(name, fit_on)}
        candidates.append((name, member(name).what, fitted[name]))
    floor = float(result.floor.get("rms", 0.0))
    rows = []
    for name, what, model in candidates:
        rms = _scores(model, held)
        rows.append({"candidate": name, "what": what, "rms": rms,
                     "mean_rms": float(np.mean(rms))})
    for r in rows:
        r["gap_closed"] = gap_closed(rows[0]["mean_rms"], r["mean_rms"], floor)
    incumbent = rows[1] if given is not None else rows[0]
    chosen = incumbent
    for r in rows:
        if r is not incumbent and r["mean_rms"] < (1.0 - margin) * chosen["mean_rms"]:
            chosen = r
    model = next(m for name, _, m in candidates if name == chosen["candidate"])
    verdict = _verdict(chosen, rows, members, given[0] if given is not None else None)
    return FinalModel(rows, chosen["candidate"], model, floor, verdict,
                      [f"{rec.name}" + (f" [{k}:]" if k else "") for rec, k in held])


def _verdict(chosen: dict, rows: list[dict], members: Sequence[str],
             given: str | None = None) -> str:
    name = chosen["candidate"]
    share = f"{100 * chosen['gap_closed']:.0f} %"
    if name == given:
        return (f"the model given stays: it closes {share} of the nominal model's gap to the "
                "floor, and neither an effect nor another member beats it by the margin")
    if name in members:
        return (f"the hysteresis operator is what the nominal model gets wrong: the {name} "
                f"member closes {share} of the gap to the floor, more than any effect around "
                "the nominal operator")
    if name != "nominal":
        return f"the accepted effects close {share} of the gap; no member does better"
    if given is not None:
        return ("the nominal model beats the model given by the margin, and neither an effect "
                "nor another member beats it")
    return "neither an effect nor another member beats the nominal model by the margin"
