"""Compiled solves with small symmetric positive definite matrices (Cholesky).

The moving-horizon re-solve of the on-line identifiers (:mod:`hystid.identify.horizon`) solves
a 25 x 25 system per trial step and inverts one per chunk, between simulations that stream
megabytes through the caches. Called that way, LAPACK's solve or inverse takes 50-70 us, most
of it the cold call itself; these compiled loops take 10-25 us (measured on stage A, one-off;
``benchmarks/bench_pi_online.py`` gives the identifier's speed). They return ``None`` (Python)
or NaN (compiled) when the matrix is not positive definite, and the callers fall back to numpy.
"""

from __future__ import annotations

import numpy as np
from numba import njit

__all__ = ["spd_inverse", "spd_solve"]


@njit(cache=True, nogil=True)
def _cholesky(A: np.ndarray, L: np.ndarray) -> bool:
    """``A = L L'`` into the lower triangle of ``L``; False when ``A`` is not positive
    definite (a pivot not above zero, or not finite)."""
    n = A.shape[0]
    for j in range(n):
        s = A[j, j]
        for k in range(j):
            s -= L[j, k] * L[j, k]
        if not (s > 0.0 and s < np.inf):
            return False
        d = np.sqrt(s)
        L[j, j] = d
        for i in range(j + 1, n):
            s = A[i, j]
            for k in range(j):
                s -= L[i, k] * L[j, k]
            L[i, j] = s / d
    return True


@njit(cache=True, nogil=True)
def _solve_into(A: np.ndarray, b: np.ndarray, x: np.ndarray) -> bool:
    """``A x = b`` for a positive definite ``A``: ``L y = b``, then ``L' x = y``."""
    n = A.shape[0]
    L = np.zeros((n, n))
    if not _cholesky(A, L):
        return False
    for i in range(n):
        s = b[i]
        for k in range(i):
            s -= L[i, k] * x[k]
        x[i] = s / L[i, i]
    for i in range(n - 1, -1, -1):
        s = x[i]
        for k in range(i + 1, n):
            s -= L[k, i] * x[k]
        x[i] = s / L[i, i]
    return True


@njit(cache=True, nogil=True)
def _inverse_into(A: np.ndarray, out: np.ndarray) -> bool:
    """``out = A^-1`` for a positive definite ``A``: ``L^-1``, then ``L^-T L^-1``."""
    n = A.shape[0]
    L = np.zeros((n, n))
    if not _cholesky(A, L):
        return False
    Li = np.zeros((n, n))
    for j in range(n):
        Li[j, j] = 1.0 / L[j, j]
        for i in range(j + 1, n):
            s = 0.0
            for k in range(j, i):
                s -= L[i, k] * Li[k, j]
            Li[i, j] = s / L[i, i]
    for i in range(n):
        for j in range(i + 1):
            s = 0.0
            for k in range(i, n):
                s += Li[k, i] * Li[k, j]
            out[i, j] = s
            out[j, i] = s
    return True


def spd_solve(A: np.ndarray, b: np.ndarray) -> np.ndarray | None:
    """Solve ``A x = b`` for a symmetric positive definite ``A`` (its lower triangle read).

    Parameters
    ----------
    A : ndarray
        Square matrix, float64.
    b : ndarray
        Right-hand side, one dimension.

    Returns
    -------
    ndarray or None
        ``x``; None when ``A`` is not (numerically) positive definite.
    """
    x = np.empty(len(b))
    return x if _solve_into(np.ascontiguousarray(A, dtype=float),
                            np.ascontiguousarray(b, dtype=float), x) else None


def spd_inverse(A: np.ndarray) -> np.ndarray | None:
    """The inverse of a symmetric positive definite ``A`` (its lower triangle read), symmetric.

    Parameters
    ----------
    A : ndarray
        Square matrix, float64.

    Returns
    -------
    ndarray or None
        ``A^-1``; None when ``A`` is not (numerically) positive definite.
    """
    out = np.empty_like(A, dtype=float)
    return out if _inverse_into(np.ascontiguousarray(A, dtype=float), out) else None
