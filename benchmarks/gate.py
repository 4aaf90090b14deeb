"""The accuracy gate: a reduced set of the accuracy figures against a committed baseline.

The figures come from :mod:`figures` for fixed seeds and are the same on every run (they do not
depend on the clock; see the README's "Regression benchmarks" for what was checked across runs
and BLAS thread counts). ``benchmarks/accuracy_baseline.json`` holds, per figure, the value,
which way is better and the tolerance (relative ``rtol`` and absolute ``atol``: a figure
regresses when it gets worse than the baseline by more than ``max(atol, rtol |baseline|)``).
A regression fails, naming the figure, the baseline and the change; a figure that improves
beyond its tolerance is reported so that the baseline is updated deliberately, in the same
commit as the change that improved it. Usage::

    python benchmarks/gate.py            # compare with the baseline; exit 1 on a regression
    python benchmarks/gate.py --update   # rewrite the baseline's values (tolerances kept)

``tests/test_accuracy_gate.py`` runs the comparison in the test suite; it never writes the
baseline.
"""

from __future__ import annotations

import argparse
import functools
import json
import math
import sys
import time
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from pathlib import Path

if __name__ == "__main__":  # run as a script: measure the checkout this file belongs to
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
import figures  # noqa: E402
from _common import table  # noqa: E402

#: The README blocks rendered from the baseline (see ``benchmarks/readme.py``).
README_BLOCKS = {"accuracy": "render"}
COMMAND = "python benchmarks/gate.py --update"


BASELINE = Path(__file__).resolve().parent / "accuracy_baseline.json"

#: Each group is one computation; several figures read its result.
GROUPS: dict[str, Callable[[], dict]] = {
    **{f"reference/{m}": functools.partial(figures.reference_identification, m, seed=0,
                                           samples=30_000 if m == "online" else 6_000)
       for m in figures.METHODS},
    **{f"as_measured/{m}/{c}": functools.partial(figures.as_measured, m, c)
       for m, cases in (("batch", ("offset", "units", "held_level", "outlier")),
                        ("online", ("offset", "units", "10kHz", "outlier", "end_glitch")))
       for c in cases},
    "wrong_basin": functools.partial(figures.wrong_basin, range(3)),
    "withheld": functools.partial(figures.withheld_effects, in_form=2, cross_form=2, clean=1),
    "tracking": figures.tracking_cut,
    "stage_a": figures.stage_a_default,
}

#: Groups that read ``../shared/data``: their figures are checked by a test of their own, which
#: skips with the reason where the data is absent.
NEEDS_SHARED_DATA = ("stage_a",)


@dataclass(frozen=True)
class Spec:
    """A figure of the gate and its default tolerance.

    Attributes
    ----------
    name : str
        ``group/key``.
    better : {"lower", "higher"}
        Which way is an improvement.
    rtol, atol : float
        Default tolerance (the baseline file's own values win once written).
    what : str
        What the figure is, for the baseline file and the messages.
    why : str
        Why the tolerance is what it is (how the figure moves from machine to machine).
    """

    name: str
    better: str
    rtol: float
    atol: float
    what: str
    why: str = ""

    @property
    def group(self) -> str:
        """The computation in :data:`GROUPS` the figure comes from."""
        return self.name.rsplit("/", 1)[0]

    @property
    def key(self) -> str:
        """The field of the group's result (``a.b`` for a nested one)."""
        return self.name.rsplit("/", 1)[1]


#: Why each kind of tolerance is what it is (the baseline file and the README repeat it).
WHY = {
    "param": "a converged fit: the estimate moves with round-off (BLAS, instruction set, "
             "thread count) by far less than 50 %; atol covers errors near zero",
    "rms": "a held-out RMS of a converged fit sits at the noise floor; 5 % covers round-off "
           "and a changed local optimum of equal quality",
    "samples": "a count of samples: 25 % covers a start-up that crosses 2 % a few steps later",
    "verdict": "a yes/no or a share of runs: well conditioned, any change is a real change",
    "diverges": "ERIA as published diverges; where it ends is chaotic and differs between "
                "CPUs, so only whether it converged is gated, never its final value",
    "ratio": "a ratio of two tracking errors of one compensated run: 10 % covers round-off",
    "measured": "a fit on a measured record: 10 % covers round-off and another local optimum "
                "of equal quality (the records never change)",
}


def _specs() -> list[Spec]:
    out = []
    for m in figures.METHODS:
        g = f"reference/{m}"
        if m == "eria":
            out.append(Spec(f"{g}/converged", "higher", 0.0, 0.0,
                            "eria: converged to within 10 % (1) or not (0), reference stage",
                            WHY["diverges"]))
        elif m != "pi":
            out.append(Spec(f"{g}/final_err", "lower", 0.5, 2e-4,
                            f"{m}: max relative parameter error, reference stage", WHY["param"]))
        if m != "eria":
            out.append(Spec(f"{g}/val_rms", "lower", 0.05, 0.0,
                            f"{m}: held-out RMS (um), reference stage", WHY["rms"]))
    out.append(Spec("reference/online/to_2pc", "lower", 0.25, 0.0,
                    "online: samples until the estimate stays within 2 %", WHY["samples"]))
    for g in GROUPS:
        if g.startswith("as_measured/"):
            case = g.split("/")[2]
            out.append(Spec(f"{g}/heldout_rms", "lower", 0.05, 0.0,
                            f"held-out RMS in the record's output unit, as measured: {case}",
                            WHY["rms"]))
            if case != "10kHz":
                out.append(Spec(f"{g}/param_err", "lower", 0.5, 5e-4,
                                f"max relative parameter error, as measured: {case}",
                                WHY["param"]))
    verdicts = [
        ("wrong_basin/rate", "lower", "on-line start-up in a wrong basin, share of 18 runs"),
        ("withheld/in-form.top1_accuracy", "higher", "withheld effect top-1, in-form"),
        ("withheld/cross-form.top1_accuracy", "higher", "withheld effect top-1, cross-form"),
        ("withheld/in-form.false_acceptance_clean", "lower",
         "effect accepted on a clean record, in-form"),
        ("withheld/cross-form.false_acceptance_clean", "lower",
         "effect accepted on a clean record, cross-form"),
        ("withheld/cross-form.wrong_acceptance", "lower", "wrong family accepted, cross-form"),
    ]
    out.append(Spec("wrong_basin/worst_err", "lower", 0.5, 1e-3,
                    "on-line start-up: worst final parameter error of 18 runs", WHY["param"]))
    out += [Spec(name, better, 0.0, 0.0, what, WHY["verdict"]) for name, better, what in verdicts]
    out.append(Spec("tracking/cut", "higher", 0.1, 0.0,
                    "max tracking error without / with the feed-forward inverse, 10 Hz triangle",
                    WHY["ratio"]))
    out += [
        Spec("stage_a/max_heldout_rms", "lower", 0.1, 0.0,
             "measured stage A, default identify on prbn_1: worst held-out RMS (um) of the "
             "other five records", WHY["measured"]),
        Spec("stage_a/share_under_60pc_linear", "higher", 0.0, 0.0,
             "measured stage A: share of held-out records under 0.6x the linear model",
             WHY["verdict"]),
        Spec("stage_a/pi_stage", "higher", 0.0, 0.0,
             "measured stage A: the default choice is the pi-stage member (1) or not (0)",
             WHY["verdict"]),
    ]
    return out


SPECS = _specs()


def _field(result: dict, key: str) -> float | None:
    value: object = result
    for part in key.split("."):
        if not isinstance(value, dict) or part not in value:
            return None
        value = value[part]
    if value is None or isinstance(value, bool):
        return None if value is None else float(value)
    value = float(value)
    return value if math.isfinite(value) else None


def compute(names: Iterable[str] | None = None, progress: bool = False) -> dict[str, float | None]:
    """Compute the gate's figures (each group once).

    Parameters
    ----------
    names : iterable of str, optional
        Figures to compute, by default all of :data:`SPECS`.
    progress : bool
        Print each group's time on stderr.

    Returns
    -------
    dict
        Figure name -> value (None when the run gives none, e.g. an unstable model).
    """
    wanted = [s for s in SPECS if names is None or s.name in set(names)]
    out: dict[str, float | None] = {}
    for group in dict.fromkeys(s.group for s in wanted):
        t0 = time.perf_counter()
        result = GROUPS[group]()
        if progress:
            print(f"  {group}: {time.perf_counter() - t0:.1f} s", file=sys.stderr, flush=True)
        for s in wanted:
            if s.group == group:
                out[s.name] = _field(result, s.key)
    return out


@dataclass
class Finding:
    """One figure against its baseline.

    Attributes
    ----------
    name : str
    baseline, value : float or None
    allowed : float
        The change allowed in the worse direction.
    status : {"ok", "regressed", "improved", "missing", "new"}
    """

    name: str
    baseline: float | None
    value: float | None
    allowed: float
    status: str

    def message(self) -> str:
        """One line: figure, baseline, value, change and what is allowed."""
        if self.status == "new":
            return f"{self.name}: {self.value!r} has no baseline (run gate.py --update)"
        if self.status == "missing":
            return f"{self.name}: in the baseline, not computed"
        if self.value is None or self.baseline is None:
            return f"{self.name}: baseline {self.baseline!r}, now {self.value!r}"
        change = self.value - self.baseline
        rel = f" ({100 * change / abs(self.baseline):+.1f} %)" if self.baseline else ""
        return (f"{self.name}: baseline {self.baseline:.6g}, now {self.value:.6g}, change "
                f"{change:+.3g}{rel}, allowed {self.allowed:.3g} ({self.status})")


def check(values: dict[str, float | None], baseline: dict) -> list[Finding]:
    """Compare figures with the baseline's entries.

    Parameters
    ----------
    values : dict
        Figure name -> value, from :func:`compute`.
    baseline : dict
        The baseline file's ``figures``: name -> ``value``, ``better``, ``rtol``, ``atol``.

    Returns
    -------
    list of Finding
        One per figure in either; ``regressed`` when worse by more than
        ``max(atol, rtol |baseline|)`` (or no longer computable), ``improved`` when better by
        more than that.
    """
    out = []
    for name in dict.fromkeys([*baseline, *values]):
        if name not in baseline:
            out.append(Finding(name, None, values[name], 0.0, "new"))
            continue
        entry = baseline[name]
        if name not in values:
            out.append(Finding(name, entry["value"], None, 0.0, "missing"))
            continue
        base, now = entry["value"], values[name]
        allowed = 0.0 if base is None else max(entry["atol"], entry["rtol"] * abs(base))
        if base is None or now is None:
            status = "ok" if base is None and now is None else (
                "regressed" if now is None else "improved")
        else:
            worse = (now - base) if entry["better"] == "lower" else (base - now)
            status = ("regressed" if worse > allowed else
                      "improved" if -worse > allowed else "ok")
        out.append(Finding(name, base, now, allowed, status))
    return out


def load_baseline(path: Path = BASELINE) -> dict:
    """Read the baseline file's figures.

    Parameters
    ----------
    path : Path
        The baseline file.

    Returns
    -------
    dict
        Name -> entry.

    Raises
    ------
    ValueError
        When the file is missing or not a baseline, naming it and what was expected.
    """
    try:
        data = json.loads(path.read_text())
    except FileNotFoundError:
        raise ValueError(f"{path}: no baseline yet; write one with "
                         "'python benchmarks/gate.py --update'") from None
    except json.JSONDecodeError as err:
        raise ValueError(f"{path}: line {err.lineno}: not JSON ({err.msg})") from None
    figs = data.get("figures") if isinstance(data, dict) else None
    if not isinstance(figs, dict):
        raise ValueError(f"{path}: expected an object with a 'figures' mapping")
    for name, entry in figs.items():
        missing = {"value", "better", "rtol", "atol"} - set(entry)
        if missing or entry["better"] not in ("lower", "higher"):
            raise ValueError(f"{path}: figure {name!r}: expected keys value, better "
                             f"('lower' or 'higher'), rtol, atol; got {sorted(entry)}")
    return figs


def write_baseline(values: dict[str, float | None], path: Path = BASELINE) -> None:
    """Write the baseline: the values now, the tolerances already in the file (or the defaults).

    Parameters
    ----------
    values : dict
        Figure name -> value.
    path : Path
        The baseline file.
    """
    old = load_baseline(path) if path.exists() else {}
    specs = {s.name: s for s in SPECS}
    figs = {}
    for name, value in values.items():
        s = specs[name]
        prev = old.get(name, {})
        figs[name] = {"value": value, "better": s.better, "rtol": prev.get("rtol", s.rtol),
                      "atol": prev.get("atol", s.atol), "what": s.what, "why": s.why}
    payload = {"about": "Accuracy gate of hystid: figures for fixed seeds (benchmarks/gate.py). "
                        "A figure regresses when it is worse than 'value' by more than "
                        "max(atol, rtol * |value|). Rewrite the values with "
                        "'python benchmarks/gate.py --update'; edit the tolerances here.",
               "figures": figs}
    path.write_text(json.dumps(payload, indent=2) + "\n")


def render(figures_: dict) -> str:
    """The baseline's figures as a Markdown table (the README's ``accuracy`` block).

    Parameters
    ----------
    figures_ : dict
        The baseline's figures (:func:`load_baseline`).

    Returns
    -------
    str
    """
    rows = []
    for name, e in figures_.items():
        v = e["value"]
        allowed = None if v is None else max(e["atol"], e["rtol"] * abs(v))
        rows.append([f"`{name}`", e.get("what", ""), "-" if v is None else f"{v:.4g}",
                     ("any change" if allowed == 0 else
                      "-" if allowed is None else f"{'+' if e['better'] == 'lower' else '-'}"
                      f"{allowed:.2g}")])
    reasons = dict.fromkeys(e["why"] for e in figures_.values() if e.get("why"))
    why = "".join(f"\n- {r}" for r in reasons)
    return (table(rows, ["figure", "what", "baseline", "fails when worse by more than"])
            + ("\n\nWhy the tolerances are what they are:" + why if why else ""))


def report(findings: list[Finding]) -> str:
    """The findings as a table, worst first."""
    order = {"regressed": 0, "missing": 1, "new": 2, "improved": 3, "ok": 4}
    rows = sorted(findings, key=lambda f: order[f.status])
    width = max(len(f.name) for f in rows)
    return "\n".join(f"{f.status:9s}  {f.message() if f.status != 'ok' else f.name:{width}s}"
                     for f in rows)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--update", action="store_true",
                        help=f"rewrite {BASELINE.name} with the figures computed now")
    parser.add_argument("--json", type=Path, default=None,
                        help="also write the figures computed now to this file")
    args = parser.parse_args()
    t0 = time.perf_counter()
    absent = [] if figures.STAGE_A.exists() else list(NEEDS_SHARED_DATA)
    if absent:
        print(f"not computed (no {figures.STAGE_A}): {', '.join(absent)}")
    values = compute([s.name for s in SPECS if s.group not in absent], progress=True)
    print(f"{len(values)} figures in {time.perf_counter() - t0:.0f} s")
    if args.json is not None:
        args.json.write_text(json.dumps(values, indent=2) + "\n")
    if args.update:
        kept = {k: e["value"] for k, e in (load_baseline() if BASELINE.exists() else {}).items()
                if k.rsplit("/", 1)[0] in absent}  # figures not computed here stay as they are
        write_baseline({**kept, **values})
        print(f"wrote {BASELINE}")
        return
    try:
        baseline = load_baseline()
    except ValueError as err:
        sys.exit(str(err))
    findings = check(values, {k: v for k, v in baseline.items()
                              if k.rsplit("/", 1)[0] not in absent})
    print(report(findings))
    if any(f.status in ("regressed", "missing") for f in findings):
        sys.exit(1)


if __name__ == "__main__":
    main()
