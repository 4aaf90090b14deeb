"""Identification of the sandwich model: off-line reference and on-line estimators.

:func:`identify` is the one entry point; ``method`` picks the estimator.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from ..model import Structure
from ..records import Record
from .offline import fit_output_error
from .result import IdentificationResult, converged_at

__all__ = ["METHODS", "IdentificationResult", "converged_at", "fit_output_error", "identify",
           "min_samples"]

METHODS = ("batch", "eria", "online", "ekf")
SAMPLES_PER_PARAMETER = 10


def min_samples(method: str, structure: Structure | None = None, **settings: Any) -> int:
    """Fewest samples a record must hold for ``method`` to return an estimate.

    Ten samples per parameter for every method, and for the on-line identifier at least one
    more than its start-up window (``n_start``): its estimate stays at ``theta0`` until the
    window is full.
    """
    need = SAMPLES_PER_PARAMETER * len((structure or Structure()).names)
    if method == "online":
        from .online import N_START

        need = max(need, int(settings.get("n_start", N_START)) + 1)
    return need


def identify(
    record: Record,
    method: str = "batch",
    structure: Structure | None = None,
    *,
    progress: Callable[[int, int], None] | None = None,
    **settings: Any,
) -> IdentificationResult:
    """Identify the Duhem sandwich from a record.

    Parameters
    ----------
    record : Record
        Input ``u`` and measured output ``y``, starting at rest.
    method : str
        ``"batch"`` (off-line output error), ``"eria"`` (the paper's recursion, eqs. 15-19),
        ``"online"`` (the converging on-line identifier) or ``"ekf"`` (filterpy baseline).
    structure : Structure, optional
        Model structure; the paper's experimental one by default.
    progress : callable, optional
        Called as ``progress(k, n)`` while a long run goes on.
    **settings
        Passed to the estimator's constructor (for example ``theta0``, ``P0``, ``epsilon``).
    """
    if method not in METHODS:
        raise ValueError(f"method: expected one of {', '.join(METHODS)}, got {method!r}")
    need = min_samples(method, structure, **settings)
    if record.n < need:
        raise ValueError(
            f"record {record.name!r}: {record.n} samples are too few for method={method!r} "
            f"(expected at least {need})")
    if method == "batch":
        if progress is not None:
            progress(0, record.n)
        return fit_output_error(record, structure, **settings)
    if method == "eria":
        from .eria import ERIA as estimator
    elif method == "online":
        from .online import OnlineIdentifier as estimator
    else:
        from .ekf import KalmanIdentifier as estimator
    return estimator(structure, record.fs, **settings).fit(record, progress=progress)
