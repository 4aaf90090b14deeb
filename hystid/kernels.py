"""Compiled kernels for the L1 - Duhem - L2 sandwich (eqs. 1, 2 and 7).

All kernels work on *extended* signal arrays: the first ``P`` entries of ``U, W1, W2, Y`` hold the
past (most recent last) and sample ``k`` is written at index ``P + k``. The same step function
serves the batch simulation, the off-line Jacobian and the on-line identifiers, which call it on
short windows that they shift by one sample after each step.

The parameter vector ``theta`` is in the paper's order (eq. 13)::

    [b21..b2n2b, alpha, (f0), f1, b11..b1n1b, g0, a11..a1n1a, a21..a2n2a]

and ``layout = [n1a, n1b, n2a, n2b, q1, q2, has_f0]`` describes it.
"""

from __future__ import annotations

import numpy as np
from numba import njit

__all__ = ["jacobian_block", "offsets", "simulate_into", "sensitivities_into", "step", "step_sens",
           "step_sens_row"]


@njit(cache=True)
def offsets(layout):
    """Index of each parameter group in ``theta``: (b2, alpha, f0, f1, b1, g0, a1, a2).

    ``f0`` is -1 when the structure has no ``f0 sgn`` term.
    """
    n1a, n1b, n2b, has_f0 = layout[0], layout[1], layout[3], layout[6]
    i_b2 = 0
    i_alpha = n2b
    i_f0 = i_alpha + 1 if has_f0 else -1
    i_f1 = i_alpha + 1 + (1 if has_f0 else 0)
    i_b1 = i_f1 + 1
    i_g0 = i_b1 + n1b
    i_a1 = i_g0 + 1
    i_a2 = i_a1 + n1a
    return i_b2, i_alpha, i_f0, i_f1, i_b1, i_g0, i_a1, i_a2


@njit(cache=True, inline="always")
def sgn(x):
    # eq. (6): sgn(0) = 0
    if x > 0.0:
        return 1.0
    if x < 0.0:
        return -1.0
    return 0.0


@njit(cache=True)
def step(theta, layout, U, W1, W2, Y, k):
    """Compute w1(k), w2(k), y(k) at index ``k`` from the entries before it (eqs. 1, 7, 2)."""
    n1a, n1b, n2a, n2b, q1, q2 = layout[0], layout[1], layout[2], layout[3], layout[4], layout[5]
    i_b2, i_alpha, i_f0, i_f1, i_b1, i_g0, i_a1, i_a2 = offsets(layout)
    alpha = theta[i_alpha]
    f0 = theta[i_f0] if i_f0 >= 0 else 0.0
    f1 = theta[i_f1]
    g0 = theta[i_g0]
    # eq. (1), b10 = 1
    w1 = U[k - q1]
    for j in range(1, n1b + 1):
        w1 += theta[i_b1 + j - 1] * U[k - q1 - j]
    for i in range(1, n1a + 1):
        w1 -= theta[i_a1 + i - 1] * W1[k - i]
    W1[k] = w1
    # eq. (7)
    w1p = W1[k - 1]
    w2p = W2[k - 1]
    dw1 = w1 - w1p
    W2[k] = w2p + alpha * (f0 * sgn(w1p) + f1 * w1p - w2p) * abs(dw1) + g0 * dw1
    # eq. (2), b20 = 1
    y = W2[k - q2]
    for j in range(1, n2b + 1):
        y += theta[i_b2 + j - 1] * W2[k - q2 - j]
    for i in range(1, n2a + 1):
        y -= theta[i_a2 + i - 1] * Y[k - i]
    Y[k] = y


@njit(cache=True)
def step_sens(theta, layout, U, W1, W2, Y, S1, S2, SY, k):
    """One step of eqs. (1), (7), (2) with the parameter sensitivities d(.)/d(theta).

    ``S1[k], S2[k], SY[k]`` are the gradients of w1(k), w2(k), y(k) with respect to ``theta``
    (forward-mode differentiation through the recursions; d|x|/dx = sgn(x) and d sgn/dx = 0).
    """
    step_sens_row(theta, layout, U, W1, W2, Y, S1, S2, SY, k, k)


@njit(cache=True)
def step_sens_row(theta, layout, U, W1, W2, Y, S1, S2, SY, k, ks):
    """:func:`step_sens` with the sensitivities of sample ``k`` at row ``ks`` of ``S1, S2, SY``
    (the rows before ``ks`` hold those of the samples before ``k``)."""
    n1a, n1b, n2a, n2b, q1, q2 = layout[0], layout[1], layout[2], layout[3], layout[4], layout[5]
    i_b2, i_alpha, i_f0, i_f1, i_b1, i_g0, i_a1, i_a2 = offsets(layout)
    npar = theta.shape[0]
    step(theta, layout, U, W1, W2, Y, k)
    alpha = theta[i_alpha]
    f0 = theta[i_f0] if i_f0 >= 0 else 0.0
    f1 = theta[i_f1]
    g0 = theta[i_g0]
    w1p = W1[k - 1]
    w2p = W2[k - 1]
    dw1 = W1[k] - w1p
    G = f0 * sgn(w1p) + f1 * w1p - w2p
    for p in range(npar):
        # L1
        s1 = 0.0
        for i in range(1, n1a + 1):
            s1 -= theta[i_a1 + i - 1] * S1[ks - i, p]
        S1[ks, p] = s1
    for j in range(1, n1b + 1):
        S1[ks, i_b1 + j - 1] += U[k - q1 - j]
    for i in range(1, n1a + 1):
        S1[ks, i_a1 + i - 1] -= W1[k - i]
    sd = sgn(dw1)
    absd = abs(dw1)
    for p in range(npar):
        ddw1 = S1[ks, p] - S1[ks - 1, p]
        dG = f1 * S1[ks - 1, p] - S2[ks - 1, p]
        S2[ks, p] = S2[ks - 1, p] + alpha * (dG * absd + G * sd * ddw1) + g0 * ddw1
    S2[ks, i_alpha] += G * absd
    S2[ks, i_f1] += alpha * w1p * absd
    if i_f0 >= 0:
        S2[ks, i_f0] += alpha * sgn(w1p) * absd
    S2[ks, i_g0] += dw1
    for p in range(npar):
        sy = S2[ks - q2, p]
        for j in range(1, n2b + 1):
            sy += theta[i_b2 + j - 1] * S2[ks - q2 - j, p]
        for i in range(1, n2a + 1):
            sy -= theta[i_a2 + i - 1] * SY[ks - i, p]
        SY[ks, p] = sy
    for j in range(1, n2b + 1):
        SY[ks, i_b2 + j - 1] += W2[k - q2 - j]
    for i in range(1, n2a + 1):
        SY[ks, i_a2 + i - 1] -= Y[k - i]


@njit(cache=True)
def simulate_into(theta, layout, U, W1, W2, Y, start):
    """Run :func:`step` for every index from ``start`` to the end of ``U``."""
    for k in range(start, U.shape[0]):
        step(theta, layout, U, W1, W2, Y, k)


@njit(cache=True)
def sensitivities_into(theta, layout, U, W1, W2, Y, S1, S2, SY, start):
    """Run :func:`step_sens` for every index from ``start`` to the end of ``U``."""
    for k in range(start, U.shape[0]):
        step_sens(theta, layout, U, W1, W2, Y, S1, S2, SY, k)


@njit(cache=True)
def jacobian_block(theta, layout, U, W1, W2, Y, S1, S2, SY, P, k0, dtheta, J):
    """Output sensitivities of one block of samples, in windows of fixed length.

    Runs :func:`step_sens_row` for the ``len(J)`` indices from ``k0`` of the extended signal
    arrays ``U, W1, W2, Y`` (which must be simulated up to ``k0`` already). The sensitivity
    windows ``S1, S2, SY`` hold, in their first ``P`` rows, those of the ``P`` samples before
    ``k0`` (zero before the first block) and room for at least ``len(J)`` more; afterwards the
    last ``P`` of them are moved to the head, ready for the next block. Memory is therefore
    independent of the record's length.

    Row ``i`` of ``J`` receives ``SY(k0 + i) @ dtheta`` (``dtheta`` maps search coordinates to
    theta). Returns False as soon as a sensitivity is not finite.
    """
    npar = theta.shape[0]
    nz = dtheta.shape[1]
    nb = J.shape[0]
    for i in range(nb):
        ks = P + i
        step_sens_row(theta, layout, U, W1, W2, Y, S1, S2, SY, k0 + i, ks)
        for c in range(nz):
            acc = 0.0
            for p in range(npar):
                acc += SY[ks, p] * dtheta[p, c]
            if not np.isfinite(acc):
                return False
            J[i, c] = acc
    for i in range(P):
        for p in range(npar):
            S1[i, p] = S1[nb + i, p]
            S2[i, p] = S2[nb + i, p]
            SY[i, p] = SY[nb + i, p]
    return True


def as_layout(n1a: int, n1b: int, n2a: int, n2b: int, q1: int, q2: int, f0: bool) -> np.ndarray:
    """Pack a structure into the integer layout the kernels take."""
    return np.array([n1a, n1b, n2a, n2b, q1, q2, int(bool(f0))], dtype=np.int64)
