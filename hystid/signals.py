"""The one validator of sampled signals (and of single numbers) in hystid.

Every function that takes samples -- a :class:`~hystid.records.Record`, a record file's column,
the input of a simulation, a reference to track, a record given to an estimator -- checks them
with :func:`finite_signal`: real, 1-D, long enough and finite, or an error that says where the
first bad value sits. Without a locator the message names the signal and the 0-based sample
(``u has a non-finite value nan at sample 7 (expected finite numbers)``); a file reader passes a
``locate`` callable that turns the sample index into the file, line and column (or array and
index) of its own error class.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

__all__ = ["finite_number", "finite_signal", "kept_samples"]


def finite_signal(
    values: Any,
    argname: str,
    *,
    min_size: int = 0,
    copy: bool = False,
    locate: Callable[[int], dict[str, Any]] | None = None,
    raw: Sequence[str] | None = None,
    error: Callable[..., Exception] = ValueError,
) -> np.ndarray:
    """A 1-D float64 signal with every sample finite, or an error naming the first bad one.

    Parameters
    ----------
    values : array_like
        The samples.
    argname : str
        Name of the signal in messages (``"u"``, ``"record 'x': u"``, a column name).
    min_size : int
        Fewest samples accepted.
    copy : bool
        Always return a new array (otherwise ``values`` itself when it is already a contiguous
        float64 vector).
    locate : callable, optional
        ``locate(k)`` gives the keyword arguments of ``error`` that place sample ``k`` (for
        example ``file``, ``line`` and ``column`` of a :class:`~hystid.records.RecordError`);
        the message then says only what the value is.
    raw : sequence of str, optional
        The samples as they were written (a text file's fields), shown instead of the number.
    error : callable
        Exception class (``ValueError`` or a subclass).

    Returns
    -------
    ndarray
        The samples as a contiguous float64 array.

    Raises
    ------
    ValueError
        (or ``error``) for complex or non-numeric values, another shape than 1-D, fewer than
        ``min_size`` samples, or a non-finite sample.
    """
    if np.iscomplexobj(values):
        raise error(f"{argname} is complex (expected real numbers)")
    try:
        arr = np.array(values, dtype=np.float64, copy=copy or None, order="C")
    except (TypeError, ValueError) as err:
        raise error(f"{argname} is not numeric (expected real numbers)") from err
    if arr.ndim != 1:
        raise error(f"{argname} has shape {arr.shape} (expected a 1-D array of samples; use "
                    "np.ravel for a single column)")
    if arr.size < min_size:
        held = "is empty" if arr.size == 0 else f"has {arr.size} samples"
        raise error(f"{argname} {held} (expected at least {min_size} "
                    f"sample{'s' if min_size > 1 else ''})")
    bad = np.flatnonzero(~np.isfinite(arr))
    if bad.size:
        k = int(bad[0])
        shown = repr(raw[k].strip()) if raw is not None else str(arr[k])
        if locate is not None:
            where = locate(k)
            more = ""
            if bad.size > 1:  # every bad line named (the first few), not only the first
                key = "line" if "line" in where else "index"
                others = [str(locate(int(j)).get(key)) for j in bad[1:6]]
                more = (f"; {bad.size - 1} more further on ({key}s {', '.join(others)}"
                        f"{', ...' if bad.size > 6 else ''})")
            raise error(f"value {shown} is not finite (expected a finite number){more}", **where)
        raise error(f"{argname} has a non-finite value {shown} at sample {k} "
                    "(expected finite numbers)")
    return arr


def finite_number(value: Any, argname: str, *, error: Callable[..., Exception] = ValueError
                  ) -> float:
    """One finite number as a float, or an error naming it.

    Parameters
    ----------
    value : float
        The number.
    argname : str
        Its name in the message.
    error : callable
        Exception class (``ValueError`` or a subclass).

    Returns
    -------
    float
        ``float(value)``.
    """
    try:
        v = float(value)
    except (TypeError, ValueError) as err:
        raise error(f"{argname}: expected a finite number, got {value!r}") from err
    if not math.isfinite(v):
        raise error(f"{argname}: expected a finite number, got {value!r}")
    return v


def kept_samples(n: int, left_out: Sequence[tuple[int, int]], argname: str = "left_out",
                 ) -> np.ndarray:
    """Which of ``n`` samples a fit learns from when the spans ``left_out`` are left out.

    Parameters
    ----------
    n : int
        Number of samples.
    left_out : sequence of (int, int)
        Spans ``[first, stop)`` of sample indices, ``0 <= first < stop <= n``.
    argname : str
        Name of the option in messages.

    Returns
    -------
    ndarray of bool
        ``True`` where a sample is kept.

    Raises
    ------
    ValueError
        Naming ``argname`` and the span, for a span that is not two integers inside the samples.
    """
    kept = np.ones(n, bool)
    for span in left_out:
        try:
            first, stop = (int(v) for v in span)
            whole = all(int(v) == v for v in span)
        except (TypeError, ValueError):
            whole = False
        if not whole or not 0 <= first < stop <= n:
            raise ValueError(f"{argname}: expected spans (first, stop) of sample indices with "
                             f"0 <= first < stop <= {n}, got {span!r}")
        kept[first:stop] = False
    return kept
