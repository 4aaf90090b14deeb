"""Compiled kernels for the L1 - Duhem - L2 sandwich (eqs. 1, 2 and 7).

All kernels work on *extended* signal arrays: the first ``P`` entries of ``U, W1, W2, Y`` hold the
past (most recent last) and sample ``k`` is written at index ``P + k``. The same step function
serves the batch simulation, the off-line Jacobian and the on-line identifiers, which call it on
short windows that they shift by one sample after each step.

The parameter vector ``theta`` is in the paper's order (eq. 13)::

    [b21..b2n2b, alpha, (f0), f1, b11..b1n1b, g0, a11..a1n1a, a21..a2n2a]

and ``layout = [n1a, n1b, n2a, n2b, q1, q2, has_f0, nf, ng, directional]`` describes it.

The generalised Duhem block (:class:`hystid.model.Structure` with ``f_order``, ``g_order`` or
``directional``) appends its shape parameters after ``a2``::

    [..., a21..a2n2a, f2..f(1+nf), g1..g(ng), (ad, gd)]

and eq. (7) becomes, with ``d = dw1(k)``, ``s = sgn(d)`` and ``v = w1(k-1)``::

    w2(k) = w2(k-1) + alpha (1 + ad s) [F(v) - w2(k-1)] |d| + [G(v) + gd s] d
    F(v)  = f0 sgn(v) + f1 v + f2 v^2 + f3 v^3        (the anhysteretic curve)
    G(v)  = g0 + g1 v + g2 v^2                        (the reversible slope)

With ``nf = ng = directional = 0`` every kernel computes the paper's eq. (7) exactly as before.
"""

from __future__ import annotations

import numpy as np
from numba import njit

__all__ = ["advance", "as_layout", "duhem_sens_row", "duhem_w2", "filter_output", "is_plain",
           "jacobian_block", "l1_sens_direct", "l1_sens_propagate", "l1_sens_row",
           "l2_output_sens", "l2_sens_direct", "l2_sens_propagate", "l2_sens_row",
           "monic_output", "offsets", "sens_rows", "shape_offsets", "shape_terms",
           "simulate_into", "sensitivities_into", "step", "step_sens", "step_sens_row"]


@njit(cache=True, nogil=True)
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


@njit(cache=True, nogil=True)
def shape_offsets(layout):
    """Index of the generalised Duhem block's parameters: (f2, g1, ad); -1 where absent."""
    nf, ng, directional = layout[7], layout[8], layout[9]
    i_ext = offsets(layout)[7] + layout[2]
    i_f2 = i_ext if nf > 0 else -1
    i_g1 = i_ext + nf if ng > 0 else -1
    i_ad = i_ext + nf + ng if directional else -1
    return i_f2, i_g1, i_ad


@njit(cache=True, inline="always")
def shape_terms(theta, layout, w1p, sd):
    """The generalised eq. (7)'s coefficients at ``w1(k-1) = w1p``, direction ``sd``.

    Returns ``(A, F, G, dF, dG)``: the rate ``alpha (1 + ad s)``, the anhysteretic curve
    ``F(w1p)`` without its ``f0 sgn`` part, the slope ``G(w1p) + gd s`` and the derivatives of
    ``F`` and ``G`` with respect to ``w1p``.
    """
    i_b2, i_alpha, i_f0, i_f1, i_b1, i_g0, i_a1, i_a2 = offsets(layout)
    i_f2, i_g1, i_ad = shape_offsets(layout)
    A = theta[i_alpha]
    F = theta[i_f1] * w1p
    dF = theta[i_f1]
    G = theta[i_g0]
    dG = 0.0
    pw = w1p
    for j in range(layout[7]):  # f2 v^2, f3 v^3
        dF += (j + 2) * theta[i_f2 + j] * pw
        pw *= w1p
        F += theta[i_f2 + j] * pw
    pw = 1.0
    for j in range(layout[8]):  # g1 v, g2 v^2
        dG += (j + 1) * theta[i_g1 + j] * pw
        pw *= w1p
        G += theta[i_g1 + j] * pw
    if i_ad >= 0:
        A = A * (1.0 + theta[i_ad] * sd)
        G += theta[i_ad + 1] * sd
    return A, F, G, dF, dG


@njit(cache=True, inline="always")
def is_plain(layout):
    """Whether the layout is the paper's eq. (7) (no generalised shape terms)."""
    return layout[7] == 0 and layout[8] == 0 and layout[9] == 0


@njit(cache=True, inline="always")
def sgn(x):
    # eq. (6): sgn(0) = 0
    if x > 0.0:
        return 1.0
    if x < 0.0:
        return -1.0
    return 0.0


@njit(cache=True, inline="always")
def duhem_w2(alpha, f0, f1, g0, w1p, w2p, dw1):
    """The paper's eq. (7): ``w2(k)`` from ``w2(k-1)``, ``w1(k-1)`` and ``dw1(k)``.

    The one compiled writing of the plain block's step: :func:`step` and the Duhem inverse
    (:mod:`hystid.compensate.duhem_inverse`) call it.
    """
    return w2p + alpha * (f0 * sgn(w1p) + f1 * w1p - w2p) * abs(dw1) + g0 * dw1


@njit(cache=True, inline="always")
def step(theta, layout, U, W1, W2, Y, k):
    """Compute w1(k), w2(k), y(k) at index ``k`` from the entries before it (eqs. 1, 7, 2)."""
    advance(theta, layout, U, W1, W2, Y, k, k + 1)


@njit(cache=True, inline="always")
def advance(theta, layout, U, W1, W2, Y, start, stop):
    """Compute w1(k), w2(k), y(k) for ``start <= k < stop``, each from the entries before it.

    The one writing of eqs. (1), (7), (2) sample by sample. What it reads of ``theta`` and
    ``layout`` is read once, before the loop (7x faster on the reference stage than reading it
    again at every sample).
    """
    n1a, n1b, n2a, n2b, q1, q2 = layout[0], layout[1], layout[2], layout[3], layout[4], layout[5]
    i_b2, i_alpha, i_f0, i_f1, i_b1, i_g0, i_a1, i_a2 = offsets(layout)
    alpha = theta[i_alpha]
    f0 = theta[i_f0] if i_f0 >= 0 else 0.0
    f1 = theta[i_f1]
    g0 = theta[i_g0]
    plain = is_plain(layout)
    for k in range(start, stop):
        w1 = monic_output(theta, i_b1, n1b, i_a1, n1a, q1, U, W1, k)  # eq. (1), b10 = 1
        W1[k] = w1
        # eq. (7)
        w1p = W1[k - 1]
        w2p = W2[k - 1]
        dw1 = w1 - w1p
        if plain:
            W2[k] = duhem_w2(alpha, f0, f1, g0, w1p, w2p, dw1)
        else:
            A, F, G, dF, dG = shape_terms(theta, layout, w1p, sgn(dw1))
            W2[k] = w2p + A * (f0 * sgn(w1p) + F - w2p) * abs(dw1) + G * dw1
        Y[k] = monic_output(theta, i_b2, n2b, i_a2, n2a, q2, W2, Y, k)  # eq. (2), b20 = 1


@njit(cache=True, inline="always")
def step_sens(theta, layout, U, W1, W2, Y, S1, S2, SY, k):
    """One step of eqs. (1), (7), (2) with the parameter sensitivities d(.)/d(theta).

    ``S1[k], S2[k], SY[k]`` are the gradients of w1(k), w2(k), y(k) with respect to ``theta``
    (forward-mode differentiation through the recursions; d|x|/dx = sgn(x) and d sgn/dx = 0).
    """
    step_sens_row(theta, layout, U, W1, W2, Y, S1, S2, SY, k, k)


@njit(cache=True, inline="always")
def step_sens_row(theta, layout, U, W1, W2, Y, S1, S2, SY, k, ks):
    """:func:`step_sens` with the sensitivities of sample ``k`` at row ``ks`` of ``S1, S2, SY``
    (the rows before ``ks`` hold those of the samples before ``k``)."""
    sens_rows(theta, layout, U, W1, W2, Y, S1, S2, SY, k, ks, 1)


@njit(cache=True, inline="always")
def sens_rows(theta, layout, U, W1, W2, Y, S1, S2, SY, k0, ks0, count):
    """:func:`step_sens_row` for ``count`` consecutive samples from ``k0`` (rows from ``ks0``).

    The one writing of the sensitivity recursions. The samples are simulated first
    (:func:`advance`; they do not depend on the sensitivities), then the rows are propagated
    with what they read of ``theta`` and ``layout`` read once.
    """
    advance(theta, layout, U, W1, W2, Y, k0, k0 + count)
    i_b2, i_alpha, i_f0, i_f1, i_b1, i_g0, i_a1, i_a2 = offsets(layout)
    npar = theta.shape[0]
    alpha = theta[i_alpha]
    f0 = theta[i_f0] if i_f0 >= 0 else 0.0
    f1 = theta[i_f1]
    g0 = theta[i_g0]
    plain = is_plain(layout)
    for i in range(count):
        k = k0 + i
        ks = ks0 + i
        w1p = W1[k - 1]
        w2p = W2[k - 1]
        dw1 = W1[k] - w1p
        G = f0 * sgn(w1p) + f1 * w1p - w2p
        l1_sens_row(theta, layout, U, W1, S1, k, ks, npar, True)
        sd = sgn(dw1)
        absd = abs(dw1)
        if plain:
            for p in range(npar):
                ddw1 = S1[ks, p] - S1[ks - 1, p]
                dG = f1 * S1[ks - 1, p] - S2[ks - 1, p]
                S2[ks, p] = S2[ks - 1, p] + alpha * (dG * absd + G * sd * ddw1) + g0 * ddw1
            S2[ks, i_alpha] += G * absd
            S2[ks, i_f1] += alpha * w1p * absd
            if i_f0 >= 0:
                S2[ks, i_f0] += alpha * sgn(w1p) * absd
            S2[ks, i_g0] += dw1
        else:
            _shape_sens(theta, layout, S1, S2, ks, w1p, w2p, dw1)
        l2_sens_row(theta, layout, W2, Y, S2, SY, k, ks, npar, True)


@njit(cache=True, inline="always")
def l1_sens_row(theta, layout, U, W1, S1, k, ks, ncol, direct):
    """Row ``ks`` of ``S1``, the sensitivities of eq. (1)'s ``w1(k)``, from the rows before it.

    Columns ``0 .. ncol-1`` are propagated through L1's denominator
    (:func:`l1_sens_propagate`); with ``direct`` the first columns are those of ``theta`` and
    receive eq. (1)'s own terms (:func:`l1_sens_direct`; ``U`` may be any input L1 is driven
    by: the augmented sandwich's delayed input). Terms of parameters acting on the input are
    the caller's to add. A kernel whose ``direct`` is decided at run time calls the two parts
    itself, the second under its own ``if``: an array argument an inlined helper uses only
    under a branch costs a reference count per sample (atomic, about 30 ns here).
    """
    l1_sens_propagate(theta, layout, S1, ks, ncol)
    if direct:
        l1_sens_direct(theta, layout, U, W1, S1, k, ks)


@njit(cache=True, inline="always")
def l1_sens_propagate(theta, layout, S1, ks, ncol):
    """Row ``ks`` of ``S1`` through L1's denominator alone (columns ``0 .. ncol-1``)."""
    n1a = layout[0]
    i_a1 = offsets(layout)[6]
    for p in range(ncol):
        s1 = 0.0
        for i in range(1, n1a + 1):
            s1 -= theta[i_a1 + i - 1] * S1[ks - i, p]
        S1[ks, p] = s1


@njit(cache=True, inline="always")
def l1_sens_direct(theta, layout, U, W1, S1, k, ks):
    """Eq. (1)'s own terms added to row ``ks`` of ``S1`` (the columns of ``theta``)."""
    n1a, n1b, q1 = layout[0], layout[1], layout[4]
    o = offsets(layout)
    i_b1, i_a1 = o[4], o[6]
    for j in range(1, n1b + 1):
        S1[ks, i_b1 + j - 1] += U[k - q1 - j]
    for i in range(1, n1a + 1):
        S1[ks, i_a1 + i - 1] -= W1[k - i]


@njit(cache=True, inline="always")
def l2_sens_row(theta, layout, W2, Y, S2, SY, k, ks, ncol, direct):
    """Row ``ks`` of ``SY``, the sensitivities of eq. (2)'s ``y(k)``, from those of its input.

    ``W2, S2`` are L2's input and its sensitivities (the augmented sandwich drives L2 with
    ``w2`` plus creep); columns and the two parts (:func:`l2_sens_propagate`,
    :func:`l2_sens_direct`) as in :func:`l1_sens_row`.
    """
    l2_sens_propagate(theta, layout, S2, SY, ks, ncol)
    if direct:
        l2_sens_direct(theta, layout, W2, Y, SY, k, ks)


@njit(cache=True, inline="always")
def l2_sens_propagate(theta, layout, S2, SY, ks, ncol):
    """Row ``ks`` of ``SY`` from its input's sensitivities through L2 (columns ``0 .. ncol-1``)."""
    n2a, n2b, q2 = layout[2], layout[3], layout[5]
    o = offsets(layout)
    i_b2, i_a2 = o[0], o[7]
    for p in range(ncol):
        sy = S2[ks - q2, p]
        for j in range(1, n2b + 1):
            sy += theta[i_b2 + j - 1] * S2[ks - q2 - j, p]
        for i in range(1, n2a + 1):
            sy -= theta[i_a2 + i - 1] * SY[ks - i, p]
        SY[ks, p] = sy


@njit(cache=True, inline="always")
def l2_sens_direct(theta, layout, W2, Y, SY, k, ks):
    """Eq. (2)'s own terms added to row ``ks`` of ``SY`` (the columns of ``theta``)."""
    n2a, n2b, q2 = layout[2], layout[3], layout[5]
    o = offsets(layout)
    i_b2, i_a2 = o[0], o[7]
    for j in range(1, n2b + 1):
        SY[ks, i_b2 + j - 1] += W2[k - q2 - j]
    for i in range(1, n2a + 1):
        SY[ks, i_a2 + i - 1] -= Y[k - i]


@njit(cache=True, inline="always")
def duhem_sens_row(S1, S2, ks, ncol, A, E, G, dF, dA, dG, absd, sd, dw1):
    """Row ``ks`` of ``S2`` propagated through a generalised eq. (7) step.

    For ``w2(k) = w2(k-1) + A E |dw1| + G dw1`` with ``E = F(w1(k-1)) - w2(k-1)`` and the
    coefficients ``A, G`` depending on ``w1(k-1)`` (derivatives ``dA, dG``; ``dF`` that of
    ``F``), the sensitivities of columns ``0 .. ncol-1`` from those of ``w1`` (rows ``ks``
    and ``ks - 1`` of ``S1``) and ``w2(k-1)``. The terms of the parameters in ``A, F, G``
    themselves are the caller's to add.
    """
    for p in range(ncol):
        s1p = S1[ks - 1, p]
        ddw1 = S1[ks, p] - s1p
        dE = dF * s1p - S2[ks - 1, p]
        S2[ks, p] = (S2[ks - 1, p] + A * (dE * absd + E * sd * ddw1) + G * ddw1
                     + dG * s1p * dw1)
        if dA != 0.0:
            S2[ks, p] += dA * s1p * E * absd


@njit(cache=True, inline="always")
def _shape_sens(theta, layout, S1, S2, ks, w1p, w2p, dw1):
    """Row ``ks`` of ``S2`` for the generalised eq. (7) (see the module docstring)."""
    i_b2, i_alpha, i_f0, i_f1, i_b1, i_g0, i_a1, i_a2 = offsets(layout)
    i_f2, i_g1, i_ad = shape_offsets(layout)
    npar = theta.shape[0]
    sd = sgn(dw1)
    absd = abs(dw1)
    A, F, G, dF, dG = shape_terms(theta, layout, w1p, sd)
    f0 = theta[i_f0] if i_f0 >= 0 else 0.0
    E = f0 * sgn(w1p) + F - w2p
    duhem_sens_row(S1, S2, ks, npar, A, E, G, dF, 0.0, dG, absd, sd, dw1)
    rate = 1.0 + theta[i_ad] * sd if i_ad >= 0 else 1.0
    S2[ks, i_alpha] += rate * E * absd
    S2[ks, i_f1] += A * w1p * absd
    if i_f0 >= 0:
        S2[ks, i_f0] += A * sgn(w1p) * absd
    S2[ks, i_g0] += dw1
    pw = w1p
    for j in range(layout[7]):
        pw *= w1p
        S2[ks, i_f2 + j] += A * pw * absd
    pw = 1.0
    for j in range(layout[8]):
        pw *= w1p
        S2[ks, i_g1 + j] += pw * dw1
    if i_ad >= 0:
        S2[ks, i_ad] += theta[i_alpha] * sd * E * absd
        S2[ks, i_ad + 1] += sd * dw1


@njit(cache=True, inline="always")
def monic_output(theta, ib, nb, ia, na, q, X, Y, k):
    """``y(k)`` of eq. (1) or (2), whose numerator's leading coefficient is 1:
    ``x(k-q) + sum_j theta[ib+j-1] x(k-q-j) - sum_i theta[ia+i-1] y(k-i)`` (``j, i`` from 1 to
    ``nb``, ``na``); returned, not written (a caller may limit it first)."""
    y = X[k - q]
    for j in range(1, nb + 1):
        y += theta[ib + j - 1] * X[k - q - j]
    for i in range(1, na + 1):
        y -= theta[ia + i - 1] * Y[k - i]
    return y


@njit(cache=True, inline="always")
def filter_output(c, ib, nb, ia, na, q, X, Y, k):
    """``y(k)`` of a filter whose whole numerator ``c[ib:ib+nb]`` is given (the unit-gain
    members' L1 and L2, eqs. 29, 31): ``sum_j c[ib+j] x(k-q-j) - sum_i c[ia+i] y(k-1-i)``;
    returned, not written."""
    y = 0.0
    for j in range(nb):
        y += c[ib + j] * X[k - q - j]
    for i in range(na):
        y -= c[ia + i] * Y[k - 1 - i]
    return y


@njit(cache=True, inline="always")
def l2_output_sens(c, ib2, n2b, ia2, n2a, q2, W2, Y, SW2, SY, k, nc):
    """L2's :func:`filter_output` written to ``Y[k]``, with the sensitivities ``SY[k, :nc]`` from
    those of ``w2``."""
    Y[k] = filter_output(c, ib2, n2b, ia2, n2a, q2, W2, Y, k)
    # a term at a time over the whole row (each column summed in the same order as a column
    # at a time, so the same to the last bit; the row's loop is the one that vectorises)
    for q in range(nc):
        SY[k, q] = 0.0
    for j in range(n2b):
        b = c[ib2 + j]
        for q in range(nc):
            SY[k, q] += b * SW2[k - q2 - j, q]
    for i in range(n2a):
        a = c[ia2 + i]
        for q in range(nc):
            SY[k, q] -= a * SY[k - 1 - i, q]
    for i in range(n2a):
        SY[k, ia2 + i] -= Y[k - 1 - i]
    for j in range(n2b):
        SY[k, ib2 + j] += W2[k - q2 - j]


@njit(cache=True, nogil=True)
def simulate_into(theta, layout, U, W1, W2, Y, start):
    """Run :func:`step` for every index from ``start`` to the end of ``U``."""
    advance(theta, layout, U, W1, W2, Y, start, U.shape[0])


@njit(cache=True, nogil=True)
def sensitivities_into(theta, layout, U, W1, W2, Y, S1, S2, SY, start):
    """Run :func:`step_sens` for every index from ``start`` to the end of ``U``."""
    sens_rows(theta, layout, U, W1, W2, Y, S1, S2, SY, start, start, U.shape[0] - start)


@njit(cache=True, nogil=True)
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
    sens_rows(theta, layout, U, W1, W2, Y, S1, S2, SY, k0, P, nb)
    for i in range(nb):
        ks = P + i
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


def as_layout(n1a: int, n1b: int, n2a: int, n2b: int, q1: int, q2: int, f0: bool,
              nf: int = 0, ng: int = 0, directional: bool = False) -> np.ndarray:
    """Pack a structure into the integer layout the kernels take.

    Parameters
    ----------
    n1a, n1b, n2a, n2b, q1, q2 : int
        Orders and delays of L1 and L2.
    f0 : bool
        Whether the ``f0 sgn`` term is in the model.
    nf, ng : int
        Number of ``f2, f3 ..`` and ``g1, g2 ..`` terms of the generalised Duhem block.
    directional : bool
        Whether the block has the direction-dependent ``ad, gd``.

    Returns
    -------
    ndarray
        Ten integers.
    """
    return np.array([n1a, n1b, n2a, n2b, q1, q2, int(bool(f0)), nf, ng, int(bool(directional))],
                    dtype=np.int64)
