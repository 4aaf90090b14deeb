"""The ``pi-stage`` member in the search coordinates of its on-line identifier.

:mod:`hystid.identify.pi_online` runs the member's L2 in parallel form, a slow first-order
branch beside a second-order (flexure mode) branch, both of unit DC gain, in coordinates
``phi = [mu_0..mu_N-1, g, xp, x1, x2, m1]`` for which L2 is stable whatever their values (see
that module's docstring). Here: whether a structure is the member's shape
(:func:`is_stage_structure`), the member's parameters of the coordinates and back
(:func:`theta_from_stage`, :func:`stage_from_theta`), and weights moved into the admissible set
(:func:`admissible_weights`).
"""

from __future__ import annotations

import numpy as np

from ..pi import PIStructure
from ..pi_operator import admissible_weights
from .pi_online_kernels import _KMAX, _theta_rows

__all__ = ["admissible_weights", "is_stage_structure", "stage_from_theta", "theta_from_stage"]


def is_stage_structure(structure: PIStructure) -> bool:
    """Whether a PI structure is the ``pi-stage`` shape this identifier runs.

    Parameters
    ----------
    structure : PIStructure
        Orders and delays.

    Returns
    -------
    bool
        True for a static L1 (``n1a=0, n1b=1, q1=0``) and a third-order L2 with three
        numerator coefficients and one input delay (``n2a=3, n2b=3, q2=1``), with or without
        polynomial terms beside the plays (``pi-poly``).
    """
    s = structure
    return (s.n1a, s.n1b, s.q1, s.n2a, s.n2b, s.q2) == (0, 1, 0, 3, 3, 1)


# =========================================================================== coordinates
def theta_from_stage(phi: np.ndarray, n_operators: int) -> np.ndarray:
    """The member's parameters ``[mu.., a21, a22, a23, b22, b23]`` from search coordinates.

    Parameters
    ----------
    phi : ndarray
        ``[mu_0..mu_N-1, g, xp, x1, x2, m1]`` (see the module docstring), or one such row per
        sample.
    n_operators : int
        Number of weights ``N`` (of the plays, and of the polynomial terms after them).

    Returns
    -------
    ndarray
        Parameters in the order of ``PIStructure.names`` for the stage structure (a row per
        row of ``phi``).
    """
    phi = np.asarray(phi, dtype=float)
    rows = np.ascontiguousarray(phi.reshape(-1, phi.shape[-1]))
    out = np.empty((rows.shape[0], n_operators + 5))
    _theta_rows(rows, int(n_operators), out)
    return out.reshape(phi.shape[:-1] + (n_operators + 5,))


def stage_from_theta(theta: np.ndarray, n_operators: int) -> np.ndarray:
    """Search coordinates of the member's parameters (the inverse of :func:`theta_from_stage`).

    The slow pole is the largest real root of ``A``; the rest of ``A`` is the mode; ``g`` and
    ``m1`` follow from ``B`` by least squares (exact for a stable ``A`` with distinct roots).

    Parameters
    ----------
    theta : ndarray
        ``[mu.., a21, a22, a23, b22, b23]`` with a stable L2.
    n_operators : int
        Number of weights ``N`` (of the plays, and of the polynomial terms after them).

    Returns
    -------
    ndarray
        ``[mu.., g, xp, x1, x2, m1]``.
    """
    n = n_operators
    a = np.asarray(theta[n:n + 3], dtype=float)
    b = np.r_[1.0 + a.sum() - theta[n + 3] - theta[n + 4], theta[n + 3:n + 5]]
    roots = np.roots(np.r_[1.0, a])
    real = roots[np.abs(roots.imag) <= 1e-9 * np.maximum(1.0, np.abs(roots))].real
    lim = _KMAX * (1.0 - 1e-12)
    p = float(np.clip(real.max(), -lim, lim))
    q = np.polydiv(np.r_[1.0, a], [1.0, -p])[0].real
    c1, c2 = float(q[1]), float(np.clip(q[2], -lim, lim))
    k1 = float(np.clip(c1 / (1.0 + c2), -lim, lim))
    s = 1.0 + c1 + c2
    # b = g (1-p) [1, c1, c2] + h [m0, m1 - p m0, -p m1] with h = 1 - g, m0 = s - m1; in
    # h and n1 = h m1 it is linear: b - (1-p)[1,c1,c2] = h (-(1-p)[1,c1,c2] + s [1, -p, 0])
    #                                                     + n1 [-1, 1 + p, -p]
    base = (1.0 - p) * np.array([1.0, c1, c2])
    A = np.column_stack([-base + s * np.array([1.0, -p, 0.0]), [-1.0, 1.0 + p, -p]])
    (h, n1), *_ = np.linalg.lstsq(A, b - base, rcond=None)
    m1 = n1 / h if abs(h) > 1e-12 else 0.0
    return np.r_[theta[:n], 1.0 - h, np.arctanh(np.array([p, k1, c2]) / _KMAX), m1]
