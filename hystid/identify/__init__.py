"""Identification of the sandwich model: off-line reference and on-line estimators.

:func:`identify` is the one entry point; ``method`` picks the estimator.
"""

from __future__ import annotations

from collections.abc import Callable

from ..model import Structure
from ..records import Record
from .offline import fit_output_error
from .result import IdentificationResult, converged_at

__all__ = ["METHODS", "IdentificationResult", "converged_at", "fit_output_error", "identify"]

METHODS = ("batch",)


def identify(
    record: Record,
    method: str = "batch",
    structure: Structure | None = None,
    *,
    progress: Callable[[int, int], None] | None = None,
    **settings,
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
    if method == "batch":
        return fit_output_error(record, structure, **settings)
    raise AssertionError(method)  # pragma: no cover
