"""What a diagnosis returns: the outcome of every candidate effect and the result as a whole,
JSON-ready, and its readable summary and figures.

Figures (PNG): ``error_time.png`` (held-out error in time, rolling RMS, slow trend, noise floor,
error after input steps), ``spectrum.png`` (residual spectrum against the noise floor, input-
residual coherence with its bound), ``branch.png`` (error on ascending and descending branches),
``gap.png`` (held-out RMS before and after each candidate) and ``correlation.png`` (correlation
tests with their coloured-signal bands).
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from ..model import DuhemSandwich
from .effects import AugmentedSandwich, family_of
from .where import Where

if TYPE_CHECKING:  # pragma: no cover
    import os

__all__ = ["DiagnosisResult", "EffectOutcome", "plot_diagnosis", "summary_text"]


# --------------------------------------------------------------------------- result
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
    at_bound : list of str
        Its fitted parameters that ended at a bound of their search range, after the guessed
        ranges were widened (:data:`hystid.diagnose.rounds.WIDEN`): the form does not fit the
        data well, whatever it stands for.
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
    at_bound: list[str] = field(default_factory=list)

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
            "at_bound": self.at_bound,
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
    members : dict
        The members fitted beside the rounds as candidates for the hysteresis itself
        (``diagnose(..., members=...)``): name to model, for
        :func:`~hystid.diagnose.final_model.final_model` to score.
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
    members: dict[str, Any] = field(default_factory=dict, repr=False)

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


# --------------------------------------------------------------------------- report
def _fmt_params(params: dict | None) -> str:
    if not params:
        return ""
    return ", ".join(f"{k}={v:.4g}" for k, v in params.items())


def _pct(x) -> str:
    return "-" if x is None else f"{100 * x:.0f} %"


def _num(x) -> str:
    return "-" if x is None else f"{x:.4g}"


def _unit(result: DiagnosisResult) -> str:
    return str(result.settings.get("units", {}).get("y", "") or "")


def summary_text(result: DiagnosisResult) -> str:
    """The diagnosis as readable text: admissibility first, then where, which, how far.

    Parameters
    ----------
    result : DiagnosisResult
        A finished diagnosis.

    Returns
    -------
    str
        The summary ``hystid diagnose`` prints.
    """
    s = result.settings
    u = _unit(result)
    unit = f" {u}" if u else ""
    lines = []
    for m in result.nominal.get("admissibility", []):
        lines.append(f"WARNING: the nominal model is not admissible on the held-out input: {m}")
    if lines:
        lines.append("")
    floor = result.floor or {"rms": result.noise_floor_rms, "kind": "sensor noise",
                             "repeat_floor_rms": None}
    lines += [
        f"Sim-to-real gap diagnosis: {s['train_samples']} train samples, {s['val_samples']} "
        f"held-out samples at {s['fs']:g} Hz",
        f"nominal model: held-out RMS {result.nominal['rms_val']:.4g}{unit} (train "
        f"{result.nominal['rms_train']:.4g}{unit}); noise floor {result.noise_floor_rms:.4g}{unit}"
        + (f"; repeatability {floor['repeat_floor_rms']:.4g}{unit}"
           if floor.get("repeat_floor_rms") is not None else "")
        + f"; gap {result.nominal['gap']:.4g}{unit} to the {floor['kind']} floor",
    ]
    if "first_fit" in result.nominal:
        r = result.nominal["first_fit"]
        lines.append(f"  (before its refit with the candidates' cost and initial state: held-out "
                     f"RMS {r['rms_val']:.4g}, train {r['rms_train']:.4g})")
    lines.append("")
    lines.append("Where the error lies:")
    lines += [f"  - {f}" for f in result.where.findings[1:]] or ["  - (nothing stands out)"]
    lines.append("")
    lines.append("Which effect (candidate forms, best first; figures of the round in which a "
                 "form was accepted, of round 1 otherwise):")
    header = ["form", "family", "status", "held-out RMS", "gap closed", "p-value", "screen",
              "params"]
    rows = []
    for e in result.effects:
        rows.append([e.name, e.family or e.name, e.status, _num(e.rms_val_after),
                     _pct(e.gap_closed),
                     "-" if "p_value" not in e.test else f"{e.test['p_value']:.2g}",
                     f"{e.screen_score:.3f}", _fmt_params(e.params)])
    widths = [max(len(str(r[i])) for r in [header, *rows]) for i in range(len(header))]
    lines.append("  " + "  ".join(h.ljust(w) for h, w in zip(header, widths, strict=True)))
    for r in rows:
        lines.append("  " + "  ".join(str(c).ljust(w) for c, w in zip(r, widths, strict=True)))
    for e in result.effects:
        if e.message:  # a screen's message names its form already (it is also an error's)
            lines.append(f"  {e.name}: {e.message.removeprefix(f'{e.name}: ')}")
    for rnd in result.rounds[1:]:
        for n, c in rnd.get("candidates", {}).items():
            if c["status"] in ("failed", "not confirmed"):
                lines.append(f"  {n} (round {rnd['round']}): {c['message']}")
    said: set[str] = set(result.accepted)  # an accepted form's bounds are said below
    for rnd in result.rounds:
        for n, c in rnd.get("candidates", {}).items():
            if c.get("at_bound") and n not in said:
                said.add(n)
                lines.append(f"  {n} (round {rnd['round']}, not accepted): at a bound of its "
                             f"range: {'; '.join(c['at_bound'])}")
    lines.append("")
    if result.accepted:
        lines.append("How far it shrinks (accepted, in order; each with its round's test):")
        for e in result.effects:
            if e.accepted and e.cumulative:
                c = e.cumulative
                lines.append(f"  round {e.round}: + {e.name} ({e.family}): held-out RMS "
                             f"{c['rms_val_before']:.4g} -> {c['rms_val']:.4g}{unit} "
                             f"({100 * c['rel_reduction']:+.1f} %, p = {c['p_value']:.2g}); "
                             f"gap closed so far {_pct(c.get('gap_closed'))}")
                if e.at_bound:
                    lines.append(f"    at a bound of its range (widened): "
                                 f"{'; '.join(e.at_bound)} -- the form does not fit the data "
                                 "well; it may stand in for something else")
        lines.append(f"with every accepted effect (the rounds' scoring): held-out RMS "
                     f"{result.nominal['rms_val']:.4g} -> {result.final['rms_val']:.4g}{unit} "
                     f"({_pct(result.final['gap_closed'])} of the gap to the {floor['kind']} "
                     "floor closed)")
    else:
        first = result.rounds[0] if result.rounds else {}
        tried = first.get("candidates", {})
        failed = [n for n, c in tried.items() if c["status"] == "failed"]
        if tried and len(failed) == len(tried):
            lines.append(f"accepted: none -- every refit failed ({len(failed)} of "
                         f"{len(tried)}; reasons above): the candidates could not be tested")
        else:
            lines.append("accepted: none (no candidate lowers the held-out error significantly, "
                         f"by at least {100 * s['min_reduction']:.0f} % and by "
                         f"{100 * s.get('min_gap_share', 0):.0f} % of the gap"
                         + (f"; {len(failed)} refits failed" if failed else "") + ")")
    unexplained = result.final.get("unexplained")
    if unexplained and result.final["gap_closed"] < 0.9:
        lines.append("What is left unexplained: " + "; ".join(unexplained["text"]))
    return "\n".join(lines)


def plot_diagnosis(result: DiagnosisResult, out_dir: str | os.PathLike[str]) -> list[Path]:
    """Write the diagnosis figures to ``out_dir`` (created if missing); returns the paths.

    Parameters
    ----------
    result : DiagnosisResult
        The diagnosis.
    out_dir : path-like
        Folder of the PNG files.

    Returns
    -------
    list of Path
        The files written.
    """
    from matplotlib.figure import Figure

    from ..metrics import error_scale

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    paths = []
    unit = _unit(result)
    k, u = error_scale(unit) if unit else (1.0, "")  # errors of a length are drawn in nm
    yu = f" [{u}]" if u else ""
    out_u = f" [{unit}]" if unit else ""
    psd_u = f" [{u}^2/Hz]" if u else " [unit^2/Hz]"
    w0, wf = result.where, result.where_final
    nf = k * result.noise_floor_rms
    ts = w0.series["time"]

    # ---------------------------------------------------------------- error in time
    fig = Figure(figsize=(9, 6), layout="constrained")
    ax = fig.subplots(2, 1)
    t = ts["t"]
    ax[0].plot(t, k * ts["e"], lw=0.4, color="0.6", label="error (nominal)")
    ax[0].plot(t, k * ts["rolling_rms"], lw=1.2, color="C3", label="rolling RMS")
    ax[0].plot(t, k * ts["trend"], lw=1.2, color="C0", label="slow trend")
    if result.accepted:
        ax[0].plot(t, k * wf.series["time"]["e"], lw=0.4, color="C2", alpha=0.7,
                   label="error (with " + " + ".join(result.accepted) + ")")
    for sgn in (1, -1):
        ax[0].axhline(sgn * nf, ls="--", color="k", lw=0.8)
    ax[0].set_xlabel("time in its record [s]")
    ax[0].set_ylabel("y - yhat" + yu)
    ax[0].set_title(f"held-out simulation error (dashed: noise floor, {nf:.3g} {u} RMS)")
    ax[0].legend(loc="best", fontsize=7)
    lag = ts["step_lags"]
    if w0.time["steps"]:
        ax[1].axhline(0, color="k", lw=0.5)
        ax[1].plot(lag, k * ts["step_avg"], "o-", ms=3, label="nominal")
        if result.accepted:
            ax[1].plot(lag, k * wf.series["time"]["step_avg"], "o-", ms=3, label="final")
        ax[1].axvline(0, color="k", ls=":", lw=0.8)
        ax[1].set_xlabel("samples after an input step")
        ax[1].set_ylabel("mean error x sign(step)" + yu)
        ax[1].set_title(f"error after input steps ({w0.time['steps']} steps)")
        ax[1].legend(fontsize=7)
    else:  # nothing to average: say so rather than draw empty axes
        ax[1].axis("off")
        ax[1].text(0.5, 0.5, "no input steps in the held-out records: no step response to "
                   "average", ha="center", va="center", transform=ax[1].transAxes)
    paths.append(_save(fig, out / "error_time.png"))

    # ---------------------------------------------------------------- spectrum
    fser = w0.series["frequency"]
    fig = Figure(figsize=(9, 6), layout="constrained")
    ax = fig.subplots(2, 1, sharex=True)
    f = fser["f"]
    ax[0].loglog(f[1:], k**2 * fser["psd"][1:], lw=1, label="residual (nominal)")
    if result.accepted:
        ax[0].loglog(f[1:], k**2 * wf.series["frequency"]["psd"][1:], lw=1,
                     label="residual (with " + " + ".join(result.accepted) + ")")
    ax[0].axhline(2 * nf**2 / w0.series["fs"], color="k", ls="--", lw=1,
                  label=f"noise floor ({nf:.3g} {u} RMS)")
    band = w0.frequency["band_hz"]
    if band[1] > band[0]:
        ax[0].axvspan(max(band[0], f[1]), band[1], color="C3", alpha=0.08,
                      label="10-90 % of the excess power")
    ax[0].set_ylabel("PSD" + psd_u)
    ax[0].legend(fontsize=7)
    ax[0].set_title("residual spectrum against the noise floor")
    ax[1].semilogx(f[1:], fser["coherence"][1:], lw=1)
    ax[1].axhline(fser["coherence_bound"], color="C3", ls="--", lw=1, label="1 % bound")
    ax[1].set_ylim(0, 1)
    ax[1].set_xlabel("frequency [Hz]")
    ax[1].set_ylabel("coherence u - e")
    ax[1].legend(fontsize=7)
    paths.append(_save(fig, out / "spectrum.png"))

    # ---------------------------------------------------------------- branches
    bs = w0.series["branch"]
    fig = Figure(figsize=(10, 4), layout="constrained")
    ax = fig.subplots(1, 2)
    y, e, up = bs["y"], k * bs["e"], bs["up"]
    rising, falling = k * bs["ascending"], k * bs["descending"]
    step = max(1, len(y) // 6000)
    ax[0].plot(y[::step][up[::step]], e[::step][up[::step]], ".", ms=1, alpha=0.4, color="C0",
               label="ascending")
    ax[0].plot(y[::step][~up[::step]], e[::step][~up[::step]], ".", ms=1, alpha=0.4,
               color="C1", label="descending")
    centres = 0.5 * (bs["edges"][1:] + bs["edges"][:-1])
    ax[0].plot(centres, rising, "o-", color="C0")
    ax[0].plot(centres, falling, "s-", color="C1")
    ax[0].set_xlabel("simulated output" + out_u)
    ax[0].set_ylabel("error" + yu)
    ax[0].set_title("error by branch")
    ax[0].legend(fontsize=7, markerscale=8)
    ax[1].plot(centres, 0.5 * (rising + falling), "o-", label="common")
    ax[1].plot(centres, 0.5 * (rising - falling), "s-", label="loop width")
    ax[1].axhline(0, color="k", lw=0.5)
    ax[1].set_xlabel("simulated output" + out_u)
    ax[1].set_ylabel("error" + yu)
    ax[1].set_title("common vs loop-width error")
    ax[1].legend(fontsize=7)
    paths.append(_save(fig, out / "branch.png"))

    # ---------------------------------------------------------------- gap per candidate
    fig = Figure(figsize=(8, 0.6 * len(result.effects) + 1.5), layout="constrained")
    ax = fig.subplots()
    names = [e.name for e in result.effects]
    before = k * result.nominal["rms_val"]
    after = [k * e.rms_val_after if e.rms_val_after is not None else np.nan
             for e in result.effects]
    yk = np.arange(len(names))[::-1]
    ax.barh(yk + 0.2, [before] * len(names), height=0.4, color="0.7", label="nominal")
    colors = ["C2" if e.accepted else "C0" for e in result.effects]
    ax.barh(yk - 0.2, np.nan_to_num(after), height=0.4, color=colors, label="with the effect")
    for row, e in zip(yk, result.effects, strict=True):
        text = e.status if e.gap_closed is None else f"{e.status}, {_pct(e.gap_closed)} closed"
        ax.text(before * 1.01, row, text, va="center", fontsize=7)
    # (the rows once took the name of the unit scale k: the floor was drawn at zero, unseen)
    kind = (result.floor or {}).get("kind", "sensor noise")
    ax.axvline(k * (result.floor or {}).get("rms", result.noise_floor_rms), color="k", ls="--",
               lw=1, label=f"{kind} floor")
    if kind != "sensor noise":
        ax.axvline(nf, color="0.4", ls=":", lw=1, label="sensor noise floor")
    ax.set_yticks(yk)
    ax.set_yticklabels(names)
    ax.set_xlabel("held-out RMS error" + yu)
    ax.set_xlim(0, before * 1.45)
    ax.set_title("gap before/after per candidate (green: accepted)")
    ax.legend(fontsize=7, loc="lower right")
    paths.append(_save(fig, out / "gap.png"))

    # ---------------------------------------------------------------- correlation tests
    cs = w0.series["correlation"]
    fig = Figure(figsize=(3 * len(cs), 3), layout="constrained")
    axs = fig.subplots(1, len(cs), sharey=True)
    for a, (name, res) in zip(np.atleast_1d(axs), cs.items(), strict=True):
        a.plot(res["lags"], res["rho"], lw=0.8)
        a.axhline(res["band"], color="C3", ls="--", lw=0.8)
        a.axhline(-res["band"], color="C3", ls="--", lw=0.8)
        a.set_title(name, fontsize=8)
        a.set_xlabel("lag [samples]")
    np.atleast_1d(axs)[0].set_ylabel("correlation (99 % band)")
    paths.append(_save(fig, out / "correlation.png"))
    return paths


def _save(fig, path: Path) -> Path:
    fig.savefig(path, dpi=110)
    return path
