"""Checks shared by the loaders: the sampling rate from a time column or a stated one."""

from __future__ import annotations

import numpy as np

from ..errors import RecordError
from .record import FS_RTOL, T_UNIFORM_RTOL, Locator, _as_fs


# --------------------------------------------------------------------------- shared checks
def _fs_from_time(t: np.ndarray, stated: float | None, stated_by: str, locate: Locator,
                  file: str) -> float:
    """Check that ``t`` is increasing and uniform; return the sampling rate it implies.

    ``stated`` (described by ``stated_by``) is returned instead when it agrees with ``t``.
    """
    if t.size < 2:
        if stated is None:
            raise RecordError("a single sample of t does not define fs (pass fs=... or --fs)",
                              file=file)
        return stated
    dt = np.diff(t)
    bad = np.flatnonzero(dt <= 0)
    if bad.size:
        k = int(bad[0]) + 1
        what = "repeats" if dt[k - 1] == 0 else "decreases"
        raise RecordError(
            f"t {what}: {float(t[k])!r} after {float(t[k - 1])!r} (expected strictly "
            "increasing times)", **locate(k)
        )
    step = float(np.median(dt))
    off = np.flatnonzero(np.abs(dt - step) > T_UNIFORM_RTOL * step)
    if off.size:
        k = int(off[0]) + 1
        raise RecordError(
            f"t is not uniform: step {float(dt[k - 1])!r} s from the previous sample differs "
            f"from the median step {step!r} s by {abs(dt[k - 1] / step - 1):.3g} (expected at most "
            f"{T_UNIFORM_RTOL:g} relative)", **locate(k)
        )
    derived = (t.size - 1) / float(t[-1] - t[0])
    if stated is None:
        return derived
    if abs(stated - derived) > FS_RTOL * derived:
        raise RecordError(
            f"fs mismatch: {stated_by}{stated!r} Hz but t gives {derived!r} Hz "
            f"(expected agreement within {FS_RTOL:g} relative)", file=file
        )
    return stated


def _stated_fs(fs: float | None, file: str) -> float | None:
    if fs is None:
        return None
    return _as_fs(fs, f"{file}: argument fs")


