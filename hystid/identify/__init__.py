"""Identification of the sandwich model: off-line reference and on-line estimators.

:func:`identify` is the one entry point; ``method`` picks the estimator.
"""

from __future__ import annotations

import warnings
from collections.abc import Callable
from typing import Any

from ..blas import one_blas_thread
from ..model import Structure
from ..records import Record
from .offline import fit_output_error
from .result import IdentificationResult, converged_at

__all__ = ["AUTO_SETTINGS", "METHODS", "IdentificationResult", "converged_at", "default_model",
           "fit_output_error", "identify", "min_samples", "place_after_run"]

METHODS = ("batch", "eria", "online", "ekf")
SAMPLES_PER_PARAMETER = 10


def min_samples(method: str, structure: Structure | None = None, **settings: Any) -> int:
    """Fewest samples a record must hold for ``method`` to return an estimate.

    Ten samples per parameter for every method, and for the on-line identifier at least one
    more than its start-up window (``n_start``): its estimate stays at ``theta0`` until the
    window is full.

    Parameters
    ----------
    method : str
        One of :data:`METHODS`.
    structure : Structure, optional
        The model structure; the paper's by default.
    **settings
        The method's settings (``n_start`` for the on-line identifier).

    Returns
    -------
    int
        The number of samples.
    """
    need = SAMPLES_PER_PARAMETER * len((structure or Structure()).names)
    if method == "online":
        from .online import N_START

        need = max(need, int(settings.get("n_start", N_START)) + 1)
    return need


@one_blas_thread
def identify(
    record: Record,
    method: str = "batch",
    structure: Structure | str | None = None,
    *,
    model: str | None = None,
    progress: Callable[[int, int], None] | None = None,
    workers: int | None = None,
    **settings: Any,
) -> IdentificationResult:
    """Identify a sandwich model from a record.

    Parameters
    ----------
    record : Record
        Input ``u`` and measured output ``y``, starting at rest.
    method : str
        ``"batch"`` (off-line output error), ``"eria"`` (the paper's recursion, eqs. 15-19),
        ``"online"`` (the converging on-line identifier) or ``"ekf"`` (filterpy baseline).
    structure : Structure or "auto", optional
        Model structure; the paper's experimental one by default; ``"auto"`` chooses orders
        and delays on held-out error (:func:`~hystid.identify.structure.select_structure`,
        its table in ``result.info["structure_selection"]``).
    model : str, optional
        The member of the model family (:data:`hystid.identify.members.MEMBERS`): ``"duhem"``
        (the paper's sandwich), ``"gduhem"``, ``"pi"``, ``"pi-stage"``, ``"mduhem"`` (batch
        only), or ``"auto"`` to choose between
        :data:`~hystid.identify.members.AUTO_CANDIDATES` on data held out inside the record
        (:func:`~hystid.identify.members.select_member`, its table in
        ``result.info["member_selection"]``; for ``method="online"`` the member is chosen as
        for the batch fit and identified on-line over the whole record). ``structure``
        applies to the Duhem sandwich. By default (None) ``"auto"``, as ``hystid identify``
        chooses, unless the call is tied to the Duhem sandwich (:func:`default_model`).
    progress : callable, optional
        Called as ``progress(k, n)`` while a long run goes on.
    workers : int, optional
        Threads the model choice (``model="auto"``) runs its candidates' fits in: the cores,
        at most :data:`~hystid.threads.MAX_WORKERS`, by default. The choice and the model do
        not depend on it. A forced member is fitted in the calling thread.
    **settings
        Passed to the estimator's constructor (for example ``theta0``, ``P0``, ``epsilon``).

    Returns
    -------
    IdentificationResult
        The model is placed at the record's rest level and sensor offset, in its units, with
        the input envelope it was identified on; ``result.info["warnings"]`` says what was
        found in the record and whether the model is admissible on it.

    Notes
    -----
    ``batch`` estimates the offset and the hysteresis state at rest itself. The recursive
    methods run on the record less its rest level (input) and its output at rest, which is
    taken from the leading rest segment (see :mod:`hystid.identify.prepare`).
    """
    _check_call(record, structure)
    if progress is not None and not callable(progress):
        raise TypeError(f"progress: expected a callable progress(k, n) or None, got "
                        f"{type(progress).__name__} {progress!r:.40}")
    if not isinstance(method, str) or method not in METHODS:
        raise ValueError(f"method: expected one of {', '.join(METHODS)}, got {method!r}")
    if workers is not None:
        from ..threads import worker_count
        from .members import CHOICE_WORKERS

        held = CHOICE_WORKERS.set(worker_count(workers))
        try:
            return identify(record, method, structure, model=model, progress=progress,
                            **settings)
        finally:
            CHOICE_WORKERS.reset(held)
    from .output_jumps import CHECKING
    from .prepare import without_input_glitches

    record, mended = without_input_glitches(record)
    if not CHECKING.get():  # a fit inside another identify(): the outermost one checks
        return _identify_record(record, method, structure, model, progress, settings, mended)
    token = CHECKING.set(False)
    try:
        result = _identify_record(record, method, structure, model, progress, settings, mended)
        result = _after_output_jump(record, result, method, structure, model, progress,
                                    settings, mended)
        result.info["warnings"] = list(result.info.get("warnings", [])) + _rate_notes(
            record, result)
        return result
    except TypeError as err:
        unknown = _unknown_setting(err, settings)
        if unknown is None:
            raise
        raise ValueError(f"{unknown}: not a setting of method={method!r}, model={model!r} "
                         f"(it was passed on as {err}; see the estimator's parameters)") from err
    finally:
        CHECKING.reset(token)


def _unknown_setting(err: TypeError, settings: dict[str, Any]) -> str | None:
    """The setting a :class:`TypeError` says the estimator does not take, or None (a
    setting the user gave was named as an internal function's unexpected keyword)."""
    import re

    found = re.search(r"unexpected keyword argument '([^']+)'", str(err))
    return found.group(1) if found and found.group(1) in settings else None


def _identify_record(record: Record, method: str, structure: Any, model: str | None,
                     progress: Callable[[int, int], None] | None, settings: dict,
                     mended: list[str]) -> IdentificationResult:
    """:func:`identify` on a record whose input glitches are mended (``mended`` says what)."""
    model, notes = _resolved_model(record, method, structure, model, settings)
    mended = notes + mended
    if model != "duhem":
        result = _identify_member(record, method, structure, model, progress, settings)
    else:
        result = _identify_duhem(record, method, structure, progress, settings)
    if mended:
        result.info["warnings"] = mended + list(result.info.get("warnings", []))
    return result


def _rate_notes(record: Record, result: IdentificationResult) -> list[str]:
    """On a record driven at one rate, what the model's dependence on the rate says of it
    (:func:`hystid.identify.rates.rate_note`; the member choice's figure of the model it
    returned, when it measured one); nothing on any other record."""
    from .rates import rate_note

    return rate_note(result.model, record.u, record.y, record.fs,
                     result.info.get("rate_dependence"))


def _after_output_jump(record: Record, result: IdentificationResult, method: str,
                       structure: Any, model: str | None,
                       progress: Callable[[int, int], None] | None, settings: dict,
                       mended: list[str]) -> IdentificationResult:
    """The result, or, when its residual shows a step of the measured output that the input
    does not cause (:mod:`hystid.identify.output_jumps`), the identification again on the
    record with the step taken off, said first among its warnings."""
    from .output_jumps import find_output_jump, residual_after_rest, without_jump

    jump = find_output_jump(residual_after_rest(record, result.model), record.u, record.fs)
    if jump is None:
        return result
    result = _identify_record(without_jump(record, jump), method, structure, model, progress,
                              settings, mended)
    result.info["warnings"] = [jump.note(record)] + list(result.info.get("warnings", []))
    result.info["output_jump"] = jump.to_dict()
    return result


#: Settings every member's fit takes, so that ``model="auto"`` can pass them to each candidate.
AUTO_SETTINGS = frozenset({"offset", "skip"})


def default_model(method: str, structure: Any = None,
                  settings: dict[str, Any] | None = None) -> str:
    """The member :func:`identify` fits when no ``model`` is given.

    ``"auto"`` (the member chosen on data held out inside the record, as ``hystid identify``
    chooses by default), unless the call is tied to the Duhem sandwich: a ``structure`` given,
    a method only the Duhem sandwich has (``"eria"``, ``"ekf"``), or settings of the Duhem
    estimators (``theta0``, ``P0``, ``n_start``..., anything beyond :data:`AUTO_SETTINGS`).

    Parameters
    ----------
    method : str
        One of :data:`METHODS`.
    structure : Structure or "auto", optional
        The structure asked for.
    settings : dict, optional
        The estimator's settings asked for.

    Returns
    -------
    str
        ``"auto"`` or ``"duhem"``.
    """
    tied = (structure is not None or method in ("eria", "ekf")
            or bool(set(settings or {}) - AUTO_SETTINGS))
    return "duhem" if tied else "auto"


def _resolved_model(record: Record, method: str, structure: Any, model: str | None,
                    settings: dict[str, Any]) -> tuple[str, list[str]]:
    """The member to fit: ``model`` as given, else :func:`default_model`, which falls back to
    the Duhem sandwich (and says so) on a record too short to choose a member on."""
    if model is not None:
        return model, []
    model = default_model(method, structure, settings)
    if model == "auto":
        from .members import choice_shortfall

        short = choice_shortfall(record)
        if short is not None:
            return "duhem", [f"{short}: the Duhem sandwich is fitted without a choice"]
    return model, []


def _identify_duhem(record: Record, method: str, structure: Any,
                    progress: Callable[[int, int], None] | None,
                    settings: dict) -> IdentificationResult:
    """``identify`` for the Duhem sandwich (its structure given, or chosen with ``"auto"``)."""
    from ..validate import check_delays_fit

    selection = None
    if isinstance(structure, str):
        if structure != "auto":
            raise ValueError(f"structure: expected a Structure or 'auto', got {structure!r}")
        from .structure import select_structure

        structure, selection = select_structure(record)
    need = min_samples(method, structure, **settings)
    if record.n < need:
        raise ValueError(
            f"record {record.name!r}: {record.n} samples are too few for method={method!r} "
            f"(expected at least {need})")
    check_delays_fit(structure or Structure(), record.n, f"record {record.name!r}")
    if method == "batch":
        if progress is not None:
            progress(0, record.n)
        result = fit_output_error(record, structure, **settings)
    else:
        result = _run_recursive(record, method, structure, progress, settings)
    if selection is not None:
        result.info["structure_selection"] = selection
    result.info.setdefault("model", "duhem")
    return result


def _identify_member(record: Record, method: str, structure: Any, model: str,
                     progress: Callable[[int, int], None] | None,
                     settings: dict) -> IdentificationResult:
    """``identify`` for a member other than the default Duhem sandwich, or ``"auto"``."""
    from .members import member, select_member

    if structure is not None:
        raise ValueError(f"structure: applies to model='duhem' only (got model={model!r}); a "
                         "member fixes its own structure")
    if model == "auto":
        if method == "online":
            return _online_auto(record, progress, settings)
        if method != "batch":
            raise ValueError(f"model='auto' chooses on batch fits, for method 'batch' or "
                             f"'online' (got method={method!r}); pass model='duhem' for "
                             f"method={method!r}")
        return select_member(record, progress=progress, **settings)
    chosen = member(model)
    if chosen.kind == "pi" and method not in ("batch", "online"):
        raise ValueError(f"method: the PI sandwich is identified by 'batch' or 'online' (its "
                         f"recursive identifier), got {method!r}")
    result = chosen.fit(record, method, progress=progress, **settings)
    result.info["model"] = chosen.name
    return result


def _online_auto(record: Record, progress: Callable[[int, int], None] | None,
                 settings: dict) -> IdentificationResult:
    """``model="auto"`` on-line: the member chosen as for the batch fit
    (:func:`~hystid.identify.members.select_member` on the record: the structure is chosen
    off-line, on the record's held-out block), then identified on-line over the whole record
    (its parameters estimated sample by sample from the record's start).

    It chose on the record's first half before. On measured stage A trained on a triangle
    record that choice took the Duhem sandwich where the batch fit takes ``pi-stage``, and the
    on-line model was 1.7-2.6x the batch fit's held-out error (1.0-1.2x with the batch
    choice); over the six records as training records, 15 of 30 pairs were above 1.25x, 10 of
    30 with the batch choice (all from a sine record, where the on-line Duhem sandwich was
    1.6-2.0x its batch fit: its recursion started from the loop's centre, not from its start-up
    solve's state at rest), none now (0.96-1.22x; ``benchmarks/bench_stage_a.py --train``).
    A PI choice's swing before the rest is held by its on-line identifier
    (:func:`_held_state`)."""
    from .members import member, select_member

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the candidates' fits are only compared
        choice = select_member(record, progress=progress)
    name = choice.info["model"]
    say = getattr(progress, "say", None)
    held = _held_state(choice.model)
    if say is not None:
        say(f"model choice (as for the batch fit): {name}; its on-line identifier runs over "
            "the whole record" + (f", its plays from the batch fit's swing before the rest "
                                  f"({held['rest_swing']:.4g})" if held.get("rest_swing")
                                  else ""))
    result = member(name).fit(record, "online", progress=progress, **{**held, **settings})
    astray = _online_astray(result.model, choice.model, record)
    if astray:
        say = getattr(progress, "say", None)
        if say is not None:
            say(f"warning: {astray}")
        choice.info["warnings"] = list(choice.info.get("warnings", [])) + [astray]
        choice.info["online_result"] = {"warnings": result.info.get("warnings", [])}
        result = choice
    result.info["member_selection"] = {**choice.info["member_selection"],
                                       "on_samples": record.n}
    undetermined = choice.info["member_selection"].get("undetermined")
    if undetermined:
        result.info["warnings"] = list(result.info.get("warnings", [])) + [undetermined]
    result.info["model"] = name
    return result


def _held_state(model: Any) -> dict[str, float]:
    """The batch choice's state at rest its on-line identifier holds: a PI model's swing
    before the rest (:attr:`hystid.pi.PISandwich.rest_swing`, 0 when the batch fit kept none),
    not estimated again on-line.

    On the stage-A look-alike swung before its rest, the on-line ``pi-stage`` identifier from
    the virgin state was 0.6-12x its batch fit's held-out error; estimating the swing itself
    when its window fills, 0.12-2.8x; given the batch choice's swing, 0.1-1.2x
    (``benchmarks/bench_rest_swing.py``). The Duhem identifier's start-up solve fits its own
    state at rest."""
    swing = getattr(model, "rest_swing", None)
    return {} if swing is None else {"rest_swing": float(swing)}


def _scored(record: Record, prep: Any) -> Any:
    """The samples the batch fit scores on ``record`` (its fitted span, the weighted samples
    with a finite output), as a boolean mask."""
    import numpy as np

    scored = np.zeros(record.n, bool)
    scored[prep.fitted] = True
    return scored & np.asarray(prep.weight, bool) & np.isfinite(record.y)


#: The on-line model of ``model="auto"`` is given up for the batch fit of the choice when its
#: error on its own record (simulated from rest, over the samples the fit scores) exceeds this
#: many times the batch fit's.
ONLINE_ASTRAY = 3.0


def _online_astray(model: Any, batch: Any, record: Record) -> str | None:
    """Why the on-line model of ``model="auto"`` is given up, or None: it is
    :data:`ONLINE_ASTRAY` times the choice's batch fit off the
    record both ran on. On a piece of stage A's ``prbn_1`` cut 0.23 s into its excitation the
    on-line ``pi-stage`` identifier took the slow pole for a drift of the sensor's zero
    (-157 um/s) and was 85 um off its own record and 3.1-3.2 um off the other records."""
    import numpy as np

    from ..baselines import simulate_from_rest
    from .prepare import prepare

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        prep = prepare(record)
    scored = _scored(record, prep)
    rms = []
    for m in (model, batch):
        with np.errstate(all="ignore"), warnings.catch_warnings():
            warnings.simplefilter("ignore")
            e = (simulate_from_rest(m, record.u, check=False) - record.y)[scored]
        value = float(np.sqrt(np.mean(e ** 2))) if e.size else 0.0
        rms.append(value if np.isfinite(value) else float("inf"))
    if not rms[0] > ONLINE_ASTRAY * rms[1]:
        return None
    unit = record.units.get("y", "")
    return (f"the on-line model is {rms[0]:.3g} {unit} off its own record, {rms[0] / rms[1]:.0f}"
            f"x the batch fit the choice made on its first part ({rms[1]:.3g} {unit}): the "
            "on-line identifier went astray, and that batch fit is returned instead")


def _run_recursive(record: Record, method: str, structure: Structure | None,
               progress: Callable[[int, int], None] | None, settings: dict) -> IdentificationResult:
    """A recursive estimator of the Duhem sandwich, placed (:func:`run_placed`)."""
    if method == "eria":
        from .eria import ERIA as estimator
    elif method == "online":
        from .online import OnlineIdentifier as estimator
    else:
        from .ekf import KalmanIdentifier, ScaledRun, stated_in_units

        return run_placed(record, lambda relative: ScaledRun(
            KalmanIdentifier(structure, record.fs, **settings), relative,
            scale=not stated_in_units(settings)), progress)
    return run_placed(record, lambda relative: estimator(structure, record.fs, **settings),
                      progress)


def run_placed(record: Record, make: Callable[[Record], Any],
               progress: Callable[[int, int], None] | None = None, *,
               zero_at_start: bool = False) -> IdentificationResult:
    """Run a recursive estimator on the record less its rest level and place the model back.

    The estimator sees ``u - u_rest`` and ``y - y_ref`` (the rest level and the output at rest
    of :func:`~hystid.identify.prepare.prepare`); the model it returns is moved to the
    record's rest level and sensor offset, given the input envelope and the record's units, as
    the batch fits place theirs.

    Parameters
    ----------
    record : Record
        Input and measured output, in any units.
    make : callable
        ``make(relative_record) -> estimator`` with a ``fit(record, progress=...)`` method.
    progress : callable, optional
        ``progress(k, n)`` during the run.
    zero_at_start : bool
        For an estimator without an offset that starts its model at zero: when the record
        does not start at rest, its output is taken relative to its first samples (not to its
        median); the offset is fitted after the run (:func:`place_after_run`).

    Returns
    -------
    IdentificationResult
        The placed model; ``info["warnings"]`` adds what the preparation found and whether the
        model is admissible on the record.
    """
    import numpy as np

    from .prepare import prepare

    prep = prepare(record)
    y_ref = prep.y_ref
    if zero_at_start and not prep.at_rest:
        head = record.y[:START_SAMPLES]
        head = head[np.isfinite(head)]
        y_ref = float(np.median(head)) if head.size else y_ref
    relative = Record(record.u - prep.u_rest, record.y - y_ref, record.fs, record.units,
                      record.name)
    result = make(relative).fit(relative, progress=progress)
    model = result.model
    model.u_rest, model.offset = prep.u_rest + model.u_rest, y_ref + model.offset
    model.envelope, model.units = prep.envelope, dict(record.units)
    # the paper's ERIA is kept as published: its model is not placed beyond its own offset
    placed = None if result.method == "eria" else place_after_run(model, record, prep)
    if placed is not None:
        result.info["placement"] = placed
    problems = (model.admissibility(record.u) if hasattr(model, "admissibility")
                else model.envelope.violations(record.u))
    notes = list(prep.notes) + [f"on the identification record: {w}" for w in problems
                                if "condition" in w or "diverged" in w]
    result.info["warnings"] = list(result.info.get("warnings", [])) + notes
    return result


#: Leading samples whose median is the output's zero for an estimator without an offset
#: (``run_placed(zero_at_start=True)``) on a record that does not start at rest.
START_SAMPLES = 5


#: A model whose error on its own record exceeds this many times the output's spread has run
#: away (condition 8); :func:`place_after_run` leaves it as it is (its warnings say why).
DIVERGED_SPREAD = 10.0


def place_after_run(model: Any, record: Record, prep: Any) -> dict[str, float] | None:
    """Fit the sensor offset (and a Duhem model's state at rest) to a record after a recursive
    run, as the batch fit does.

    A recursive estimator learns the parameters; the offset it tracks (or has none of) and the
    Duhem state the stage held at rest before the record
    (:attr:`~hystid.model.DuhemSandwich.rest_memory`: a stage brought to a held level sits on
    one branch of its loop) are not those of the model simulated from rest over the whole
    record, and a model started from the loop's centre carries that branch gap through the
    record. Eq. (7) is affine in ``w2`` given ``w1``, so the output on the record is affine in
    the rest memory: two simulations and a least-squares solve of two unknowns (the memory and
    the offset; the offset alone for the other members) over the samples the batch fit would
    score place the model exactly. The placement is kept only when it lowers that RMS. A PI
    model's plays at rest (:attr:`~hystid.pi.PISandwich.rest_swing`, the stage's last excursion
    before the record) are set first, with its parameters held
    (:func:`~hystid.identify.pi_rest_swing.place_rest_swing`). On a record that does not begin
    at rest only the offset is fitted: there is no rest to remember.

    Parameters
    ----------
    model : Sandwich
        The placed model (changed in place).
    record : Record
        The record the model was identified on.
    prep : Prepared
        Its preparation (:func:`~hystid.identify.prepare.prepare`): the samples scored.

    Returns
    -------
    dict or None
        ``offset_change`` and ``rest_memory`` (output units; 0 for a member without one) and
        the RMS over the scored samples ``before`` and ``after``; for a PI model whose swing
        was set, ``rest_swing`` (input units) and ``before_swing`` (the RMS before it, the
        offset refitted); None when the model is not finite, the record leaves nothing to fit
        or the placement does not lower the RMS.
    """
    import numpy as np

    from ..baselines import simulate_from_rest
    from ..model import DuhemSandwich
    from ..pi import PISandwich
    from .pi_rest_swing import place_rest_swing

    if not np.all(np.isfinite(model.theta)):
        return None
    # a record that does not begin at rest shows no state at rest: the model starts other
    # records at its loop's centre, which forgets the memory (fitted there, it took any value:
    # -6.6e7 um on a piece of stage A's prbn_1 cut mid-motion, and the model ran away from rest)
    duhem = isinstance(model, DuhemSandwich) and bool(prep.at_rest)
    scored = _scored(record, prep)
    if np.count_nonzero(scored) < 3:
        return None
    swing = None
    if isinstance(model, PISandwich) and prep.at_rest:  # the plays' state at rest
        swing = place_rest_swing(model, record.u, record.y, scored)
    unit = float(prep.y_scale)
    memory = model.rest_memory if duhem else 0.0
    columns = [np.ones(record.n)]
    with np.errstate(all="ignore"), warnings.catch_warnings():
        warnings.simplefilter("ignore")
        y0 = simulate_from_rest(model, record.u, check=False)
        if duhem:
            model.rest_memory = memory + unit
            columns.append((simulate_from_rest(model, record.u, check=False) - y0) / unit)
            model.rest_memory = memory
    a = np.column_stack(columns)[scored]
    r = (record.y - y0)[scored]
    if not (np.all(np.isfinite(a)) and np.all(np.isfinite(r))):
        return None
    if np.sqrt(np.mean(r ** 2)) > DIVERGED_SPREAD * max(float(np.std(record.y[scored])), 1e-300):
        return None  # the model runs away on its own record: nothing to place
    x, *_ = np.linalg.lstsq(a, r, rcond=None)
    after = float(np.sqrt(np.mean((r - a @ x) ** 2)))
    before = float(np.sqrt(np.mean(r ** 2)))
    if not np.all(np.isfinite(x)) or after >= before:
        if swing is None:
            return None
        x, after = np.zeros(len(columns)), before
    model.offset += float(x[0])
    if duhem:
        model.rest_memory = memory + float(x[1])
    placed = {"offset_change": float(x[0]),
              "rest_memory": memory + float(x[-1]) if duhem else 0.0,
              "before": before, "after": after}
    if swing is not None:  # the RMS before the swing was set, with its best offset
        placed.update(rest_swing=swing["rest_swing"], before_swing=swing["before"])
    return placed


def _check_call(record: Any, structure: Any = None) -> None:
    """Refuse what :func:`hystid.identify.identify` cannot take, saying what it takes.

    Parameters
    ----------
    record : object
        Expected a :class:`~hystid.records.Record`.
    structure : object
        Expected None, ``"auto"`` or a :class:`~hystid.model.Structure`.

    Raises
    ------
    TypeError
        For a path, an array, None or anything else in place of a record, or a structure of
        another type.
    ValueError
        For a record with values beyond :data:`hystid.validate.MAX_MAGNITUDE`
        (:func:`~hystid.validate.check_magnitudes`).
    """
    import os

    import numpy as np

    from ..validate import check_magnitudes

    if not isinstance(record, Record):
        if isinstance(record, str | os.PathLike):
            hint = (f"got the path {os.fspath(record)!r}; load it first: "
                    f"hystid.records.load_record({os.fspath(record)!r}) (add fs=... when the "
                    "file has no time column)")
        elif isinstance(record, np.ndarray):
            hint = (f"got an array of shape {record.shape}; wrap it: "
                    "hystid.records.Record(u, y, fs)")
        else:
            hint = f"got {type(record).__name__}"
        raise TypeError(f"record: expected a hystid.records.Record, {hint}")
    check_magnitudes(record)
    if structure is not None and not isinstance(structure, Structure | str):
        raise TypeError(f"structure: expected a hystid.Structure, 'auto' or None, got "
                        f"{type(structure).__name__} {structure!r}")
