"""Polynomials in ``z^-1``: the one stability (Schur-Cohn) test of hystid.

A polynomial ``p_0 + p_1 z^-1 + ... + p_n z^-n`` with ``p_0 != 0`` has every root strictly
inside the unit circle iff the reflection coefficients ``k_n, ..., k_1`` of its monic form
``1 + c_1 z^-1 + ... + c_n z^-n`` (``c_i = p_i / p_0``) all satisfy ``|k_m| < 1``; the
step-down (Schur-Cohn) recursion computes them without roots::

    k_m = c_m^(m),   c_i^(m-1) = (c_i^(m) - k_m c_(m-i)^(m)) / (1 - k_m^2),   i = 1..m-1

Every stability test of the package -- the poles of L1 and L2, their zeros (minimum phase,
Assumption 1), the linear baseline, the compensator's inverse -- goes through
:func:`schur_cohn_into`, with the one margin :data:`STABILITY_MARGIN`: a polynomial counts as
stable when every ``|k_m| < 1 - STABILITY_MARGIN``. The margin sits below the identifiers'
search box (``hystid.identify.constraints.K_MAX = 1 - 1e-6``), so every iterate of a fit counts
as stable, and far above the round-off of the recursion at the orders used here, so a pole on
the circle (``|k| = 1`` up to round-off) does not.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numba import njit

__all__ = ["KMAX_STABLE", "STABILITY_MARGIN", "is_stable", "roots_inside", "schur_cohn_into",
           "schur_stable"]

#: Distance from 1 below which every reflection coefficient of a stable polynomial must stay.
STABILITY_MARGIN = 1e-9
#: The bound on ``|k_m|`` that :data:`STABILITY_MARGIN` gives.
KMAX_STABLE = 1.0 - STABILITY_MARGIN


@njit(cache=True, nogil=True)
def schur_cohn_into(c, start, n, kmax, work):
    """Schur-Cohn test of ``1 + c_1 z^-1 + ... + c_n z^-n`` without allocating.

    Parameters
    ----------
    c : ndarray
        Array holding the coefficients ``c_1..c_n`` at ``c[start:start + n]``.
    start : int
        Index of ``c_1`` in ``c``.
    n : int
        Order of the polynomial (0 is stable).
    kmax : float
        Bound on the reflection coefficients, for example :data:`KMAX_STABLE`.
    work : ndarray
        Scratch array of at least ``n`` entries (overwritten).

    Returns
    -------
    bool
        True when every reflection coefficient satisfies ``|k_m| < kmax`` (False for a
        non-finite coefficient).
    """
    for i in range(n):
        work[i] = c[start + i]
    for m in range(n, 0, -1):
        km = work[m - 1]
        if not abs(km) < kmax:
            return False
        d = 1.0 - km * km
        for i in range(m // 2):
            a, b = work[i], work[m - 2 - i]
            work[i] = (a - km * b) / d
            work[m - 2 - i] = (b - km * a) / d
    return True


@njit(cache=True, nogil=True)
def schur_stable(c, kmax=KMAX_STABLE):
    """True when ``1 + c_1 z^-1 + ... + c_n z^-n`` has its roots inside the unit circle.

    Parameters
    ----------
    c : ndarray
        The coefficients ``c_1..c_n`` (float64, 1-D).
    kmax : float
        Bound on the reflection coefficients (:data:`KMAX_STABLE` by default).

    Returns
    -------
    bool
        The result of :func:`schur_cohn_into`.
    """
    return schur_cohn_into(c, 0, c.shape[0], kmax, np.empty(c.shape[0]))


def is_stable(*tails: Any) -> bool:
    """True when every monic polynomial ``1 + c_1 z^-1 + ...`` given is stable.

    Parameters
    ----------
    *tails : array_like
        The coefficients ``c_1..c_n`` of each polynomial (the leading 1 left out); an empty one
        is stable.

    Returns
    -------
    bool
        True when all are finite and pass :func:`schur_stable` with :data:`KMAX_STABLE`.
    """
    for tail in tails:
        c = np.ascontiguousarray(tail, dtype=float).ravel()
        if c.size and not schur_stable(c):
            return False
    return True


def roots_inside(poly: Any) -> bool:
    """True when the polynomial ``p_0 + p_1 z^-1 + ... + p_n z^-n`` is stable.

    Parameters
    ----------
    poly : array_like
        Coefficients ``p_0..p_n``, highest power of ``z`` first (numpy's ``np.roots`` order);
        leading zeros are dropped.

    Returns
    -------
    bool
        True when every root lies inside the unit circle (:func:`is_stable` of the monic form);
        a polynomial with no non-zero coefficient raises ``ValueError``.
    """
    p = np.trim_zeros(np.asarray(poly, dtype=float).ravel(), "f")
    if p.size == 0:
        raise ValueError("poly: expected a polynomial with a non-zero coefficient")
    return is_stable(p[1:] / p[0])
