"""Compiled kernels of the multi-Duhem sandwich (:mod:`hystid.mduhem`): simulation and forward
sensitivities.

The kernels work on the *full* coefficient vector ``c`` and the layout
``lay = [n1a, n1b, m, n2a, n2b, q1, q2]``::

    c = [a11..a1n1a | b11..b1n1b | alpha_0..alpha_(m-1) | f1_0.. | g0_0.. | a21..a2n2a |
         b21..b2n2b]

(every numerator coefficient, the derived ones included, and the rates), and on *extended*
signal arrays as :mod:`hystid.kernels` does: the first ``P`` entries of ``U, W1, W2, Y`` hold the
past (most recent last) and sample ``k`` is written at index ``P + k``. One step::

    w1(k)   = sum_j b1j u(k-q1-j+1) - sum_i a1i w1(k-i)
    d       = w1(k) - w1(k-1)
    w2_j(k) = w2_j(k-1) + alpha_j [f1_j w1(k-1) - w2_j(k-1)] |d| + g0_j d      (eq. 7, each j)
    w2(k)   = sum_j w2_j(k)
    y(k)    = sum_j b2j w2(k-q2-j+1) - sum_i a2i y(k-i)

The operator states ``w2_j`` live in a separate array ``p`` (updated in place), since only their
sum is a signal of the sandwich.
"""

from __future__ import annotations

from numba import njit

from .kernels import filter_output, l2_output_sens

__all__ = ["coefficient_offsets", "mduhem_advance", "mduhem_sensitivities_into",
           "mduhem_simulate_into", "mduhem_step"]


@njit(cache=True)
def coefficient_offsets(lay):
    """Index of each group in ``c``: ``(a1, b1, alpha, f1, g0, a2, b2, nc)``.

    Parameters
    ----------
    lay : ndarray of int
        ``[n1a, n1b, m, n2a, n2b, q1, q2]``.

    Returns
    -------
    tuple of int
        The start of each group and the length of ``c``.
    """
    n1a, n1b, m, n2a, n2b = lay[0], lay[1], lay[2], lay[3], lay[4]
    ia1 = 0
    ib1 = n1a
    ial = ib1 + n1b
    if1 = ial + m
    ig0 = if1 + m
    ia2 = ig0 + m
    ib2 = ia2 + n2a
    return ia1, ib1, ial, if1, ig0, ia2, ib2, ib2 + n2b


@njit(cache=True, inline="always")
def _sgn(x):
    if x > 0.0:
        return 1.0
    if x < 0.0:
        return -1.0
    return 0.0


@njit(cache=True)
def mduhem_step(c, lay, U, W1, W2, Y, p, k):
    """Compute ``w1(k), w2(k), y(k)`` at index ``k`` and move the operator states ``p`` on.

    Parameters
    ----------
    c : ndarray
        Full coefficient vector (see the module docstring).
    lay : ndarray of int
        ``[n1a, n1b, m, n2a, n2b, q1, q2]``.
    U, W1, W2, Y : ndarray
        Extended signal arrays, filled before index ``k``.
    p : ndarray
        Operator states ``w2_j(k-1)``; overwritten with ``w2_j(k)``.
    k : int
        Index to compute.
    """
    mduhem_advance(c, lay, U, W1, W2, Y, p, k, k + 1)


@njit(cache=True)
def mduhem_advance(c, lay, U, W1, W2, Y, p, start, stop):
    """:func:`mduhem_step` for every index ``start <= k < stop``: the one writing of the
    recursion, with the layout read once before the loop."""
    n1a, n1b, m, n2a, n2b, q1, q2 = lay[0], lay[1], lay[2], lay[3], lay[4], lay[5], lay[6]
    ia1, ib1, ial, if1, ig0, ia2, ib2, nc = coefficient_offsets(lay)
    for k in range(start, stop):
        w1 = filter_output(c, ib1, n1b, ia1, n1a, q1, U, W1, k)
        W1[k] = w1
        v = W1[k - 1]
        d = w1 - v
        ad = abs(d)
        w2 = 0.0
        for j in range(m):
            p[j] = p[j] + c[ial + j] * (c[if1 + j] * v - p[j]) * ad + c[ig0 + j] * d
            w2 += p[j]
        W2[k] = w2
        Y[k] = filter_output(c, ib2, n2b, ia2, n2a, q2, W2, Y, k)


@njit(cache=True)
def mduhem_simulate_into(c, lay, U, W1, W2, Y, p, start):
    """Run :func:`mduhem_step` from index ``start`` to the end of ``U``.

    Parameters
    ----------
    c : ndarray
        Full coefficient vector.
    lay : ndarray of int
        The layout.
    U, W1, W2, Y : ndarray
        Extended signal arrays (the past in the first ``start`` entries).
    p : ndarray
        Operator states at ``start - 1``; left at the last sample's.
    start : int
        First index computed.
    """
    mduhem_advance(c, lay, U, W1, W2, Y, p, start, U.shape[0])


@njit(cache=True)
def mduhem_sensitivities_into(c, lay, U, W1, W2, Y, p, S1, SW2, SY, SP, start):
    """:func:`mduhem_simulate_into` with the sensitivities of every signal to ``c``.

    Forward-mode differentiation through the recursions (``d|x|/dx = sgn(x)``). ``S1, SW2, SY``
    are ``len(U) x len(c)`` arrays whose first ``start`` rows hold the sensitivities of the
    past (zero for a past that does not depend on ``c``); ``SP`` (``m x (n1a + n1b + 3)``)
    holds each operator state's sensitivity to the coefficients of L1 and to its own
    ``alpha_j, f1_j, g0_j`` (the only ones it depends on) and is updated in place.

    Parameters
    ----------
    c : ndarray
        Full coefficient vector.
    lay : ndarray of int
        The layout.
    U, W1, W2, Y : ndarray
        Extended signal arrays.
    p : ndarray
        Operator states, updated in place.
    S1, SW2, SY : ndarray
        Sensitivities of ``w1``, ``w2`` and ``y``, filled from row ``start`` on.
    SP : ndarray
        Operator-state sensitivities, updated in place.
    start : int
        First index computed.
    """
    n1a, n1b, m, n2a, n2b, q1, q2 = lay[0], lay[1], lay[2], lay[3], lay[4], lay[5], lay[6]
    ia1, ib1, ial, if1, ig0, ia2, ib2, nc = coefficient_offsets(lay)
    n1 = n1a + n1b
    for k in range(start, U.shape[0]):
        # L1 and its sensitivities (only to a1, b1)
        w1 = filter_output(c, ib1, n1b, ia1, n1a, q1, U, W1, k)
        W1[k] = w1
        for q in range(nc):
            S1[k, q] = 0.0
        for q in range(n1):
            s = 0.0
            for i in range(n1a):
                s -= c[ia1 + i] * S1[k - 1 - i, q]
            S1[k, q] = s
        for i in range(n1a):
            S1[k, ia1 + i] -= W1[k - 1 - i]
        for j in range(n1b):
            S1[k, ib1 + j] += U[k - q1 - j]
        # the operators (eq. 7 each) and their sum
        v = W1[k - 1]
        d = w1 - v
        ad = abs(d)
        sd = _sgn(d)
        for q in range(nc):
            SW2[k, q] = 0.0
        w2 = 0.0
        for j in range(m):
            alpha, f1, g0 = c[ial + j], c[if1 + j], c[ig0 + j]
            e = f1 * v - p[j]
            keep = 1.0 - alpha * ad
            for q in range(n1):
                ddw = S1[k, q] - S1[k - 1, q]
                SP[j, q] = (keep * SP[j, q] + alpha * f1 * S1[k - 1, q] * ad
                            + (alpha * e * sd + g0) * ddw)
                SW2[k, q] += SP[j, q]
            SP[j, n1] = keep * SP[j, n1] + e * ad            # d / d alpha_j
            SP[j, n1 + 1] = keep * SP[j, n1 + 1] + alpha * v * ad  # d / d f1_j
            SP[j, n1 + 2] = keep * SP[j, n1 + 2] + d         # d / d g0_j
            SW2[k, ial + j] = SP[j, n1]
            SW2[k, if1 + j] = SP[j, n1 + 1]
            SW2[k, ig0 + j] = SP[j, n1 + 2]
            p[j] = p[j] + alpha * e * ad + g0 * d
            w2 += p[j]
        W2[k] = w2
        # L2
        l2_output_sens(c, ib2, n2b, ia2, n2a, q2, W2, Y, SW2, SY, k, nc)
