"""Exact sensitivities of the augmented sandwich (:func:`hystid.diagnose.effects.augmented_into`).

Forward-mode differentiation through the augmented recursions, as :mod:`hystid.kernels` does
for the plain sandwich (``d|x|/dx = sgn(x)``, ``d sgn/dx = 0``, a clipped step follows its
limit): L1 and L2 are the two parts of :func:`hystid.kernels.l1_sens_row` and
:func:`hystid.kernels.l2_sens_row` (their own terms under this kernel's ``direct``), the Duhem
step :func:`hystid.kernels.duhem_sens_row` with the effects' direction- and level-dependent
coefficients; the effects add their own terms around them. The signals come
from :func:`~hystid.diagnose.effects.augmented_into` itself (called first), so the simulated
output is the one a refit without sensitivities sees, bit for bit.

The sensitivity columns are the nominal parameters ``theta`` (the first ``ntc`` columns, all or
none of them) and any subset of the effect vector's slots (``cols[slot]``, -1 for a slot held).
Every form has them; a form's derivative at a zero parameter is taken too (a creep gain of
zero still has a direction in which the creep grows).
"""

from __future__ import annotations

import numpy as np
from numba import njit

from ..kernels import (
    duhem_sens_row,
    l1_sens_direct,
    l1_sens_propagate,
    l2_sens_direct,
    l2_sens_propagate,
    offsets,
    sgn,
)
from .effects import LOG_STEP, N_LOG, N_SLOTS, augmented_into, l2_dc_terms

__all__ = ["augmented_sens_into", "sensitivity_columns"]


def sensitivity_columns(slots, ntc: int) -> np.ndarray:
    """The column map of :func:`augmented_sens_into`: ``cols[slot]`` for each effect slot.

    Parameters
    ----------
    slots : sequence of int
        The free effect slots, in column order.
    ntc : int
        Columns before them (the nominal parameters' count, or 0 when they are held).

    Returns
    -------
    ndarray
        :data:`~hystid.diagnose.effects.N_SLOTS` integers: the column of each free slot,
        -1 elsewhere.
    """
    cols = np.full(N_SLOTS, -1, dtype=np.int64)
    for i, s in enumerate(slots):
        cols[s] = ntc + i
    return cols


@njit(cache=True, inline="always")
def _add(S, k, c, v):
    if c >= 0:
        S[k, c] += v


@njit(cache=True, nogil=True)
def augmented_sens_into(theta, layout, phi, cols, ntc, U, UD, W1, W2, V, C, YL, M, Y,
                        S1, S2, SV, SYL, SY, start, dt):
    """Simulate the augmented sandwich and its output sensitivities from index ``start`` on.

    The signal arrays are those of :func:`~hystid.diagnose.effects.augmented_into` (called
    first, with the same arguments). ``S1, S2, SV, SYL`` (rows as the signal arrays,
    ``ntc + number of free slots`` columns) are the sensitivities of ``w1``, ``w2``, ``v`` and
    L2's output; their rows before ``start`` are the past's (zero for a past that does not
    depend on the parameters) and are read, never written. ``SY`` receives those of ``y``
    from ``start`` on, at row ``k - start`` (any memory layout: a refit has it written into
    the matrix it factorises).

    Parameters
    ----------
    theta, layout, phi
        Nominal parameters, their layout (the plain Duhem sandwich) and the effect vector.
    cols : ndarray of int
        Column of each effect slot, -1 for a held one (:func:`sensitivity_columns`).
    ntc : int
        Number of leading columns that are ``theta`` (its length, or 0).
    U, UD, W1, W2, V, C, YL, M, Y : ndarray
        The extended signal arrays.
    S1, S2, SV, SYL : ndarray
        Sensitivity arrays, shape ``(len(U), ncol)``.
    SY : ndarray
        Output sensitivities, shape ``(len(U) - start, ncol)``.
    start : int
        First index simulated.
    dt : float
        Sampling period.
    """
    augmented_into(theta, layout, phi, U, UD, W1, W2, V, C, YL, M, Y, start, dt)
    n = U.shape[0]
    ncol = S1.shape[1]
    direct = ntc > 0
    n1b, n2a, n2b, q1 = layout[1], layout[2], layout[3], layout[4]
    i_b2, i_alpha, i_f0, i_f1, i_b1, i_g0, i_a1, i_a2 = offsets(layout)
    alpha = theta[i_alpha]
    f0 = theta[i_f0] if i_f0 >= 0 else 0.0
    f1 = theta[i_f1]
    g0 = theta[i_g0]
    kappa, tau, d1c, d2c = phi[0], phi[1], cols[2], cols[3]
    gm, fm, zeta = phi[4], phi[5], phi[6]
    e_a, e_g, inv_rate, cubic = phi[8], phi[9], phi[10], phi[11]
    e_f, l_a, kappa2, tau2, k_log, tau_log = phi[13], phi[14], phi[15], phi[16], phi[17], phi[18]
    g_ser, l_g, inv_rate_u = phi[19], phi[20], phi[22]
    c2o, c3o, y_c, y_s = phi[23], phi[24], phi[25], phi[26]
    e_au, e_gu, e_fu = phi[27], phi[28], phi[29]

    # ------------------------------------------------------------ the input: delay, rate limit
    # dUD/d(delay) and dUD/d(inv_rate_u), rows as U
    c_del, c_ru = cols[7], cols[22]
    input_sens = c_del >= 0 or c_ru >= 0
    SUD = np.zeros((n, 2))
    if input_sens:
        nd = int(np.floor(phi[7]))
        lim_u = dt / inv_rate_u if inv_rate_u > 0.0 else 0.0
        dlim_u = -dt / (inv_rate_u * inv_rate_u) if inv_rate_u > 0.0 else 0.0
        for k in range(n):
            i0 = k - nd
            i1 = k - nd - 1
            a0 = U[i0] if i0 >= 0 else U[0]
            a1 = U[i1] if i1 >= 0 else U[0]
            SUD[k, 0] = a1 - a0
            if inv_rate_u > 0.0 and k > 0:
                du = UD[k] - UD[k - 1]
                if abs(du) >= lim_u * (1.0 - 1e-12):  # on the limit: it follows the limit
                    SUD[k, 0] = SUD[k - 1, 0]
                    SUD[k, 1] = SUD[k - 1, 1] + sgn(du) * dlim_u

    # ------------------------------------------------------------ creep lags
    lam = 1.0 - np.exp(-dt / tau) if tau > 0.0 else 1.0
    dlam = -(1.0 - lam) * dt / (tau * tau) if tau > 0.0 else 0.0
    lam2 = 1.0 - np.exp(-dt / tau2) if tau2 > 0.0 else 1.0
    dlam2 = -(1.0 - lam2) * dt / (tau2 * tau2) if tau2 > 0.0 else 0.0
    lam_log = np.empty(N_LOG)
    dlam_log = np.zeros(N_LOG)
    for j in range(N_LOG):
        tj = tau_log * 10.0 ** (LOG_STEP * j)
        lam_log[j] = 1.0 - np.exp(-dt / tj) if tj > 0.0 else 1.0
        if tj > 0.0:  # d lam_j / d tau_log
            dlam_log[j] = -(1.0 - lam_log[j]) * dt / (tj * tj) * 10.0 ** (LOG_STEP * j)
    creep1 = kappa != 0.0 or cols[0] >= 0 or cols[1] >= 0
    creep2 = kappa2 != 0.0 or cols[15] >= 0 or cols[16] >= 0
    creepl = k_log != 0.0 or cols[17] >= 0 or cols[18] >= 0
    sC = np.zeros(ncol)
    c2 = 0.0
    sc2 = np.zeros(ncol)
    c_log = np.zeros(N_LOG)
    sclog = np.zeros((N_LOG, ncol))

    # ------------------------------------------------------------ modes
    par_mode = gm != 0.0 or cols[4] >= 0
    ser_mode = g_ser != 0.0 or cols[19] >= 0
    p1 = 0.0
    p2 = 0.0
    bm = 0.0
    dp1 = np.zeros(ncol)
    dp2 = np.zeros(ncol)
    dbm = np.zeros(ncol)
    if par_mode or ser_mode:
        w = 2.0 * np.pi * fm
        r = np.exp(-zeta * w * dt)
        sq = np.sqrt(1.0 - zeta * zeta)
        wd = w * dt * sq
        p1 = 2.0 * r * np.cos(wd)
        p2 = -r * r
        for c, dr, dwd in ((cols[5], -zeta * 2.0 * np.pi * dt * r, 2.0 * np.pi * dt * sq),
                           (cols[6], -w * dt * r, -w * dt * zeta / sq)):
            if c >= 0:
                dp1[c] = 2.0 * np.cos(wd) * dr - 2.0 * r * np.sin(wd) * dwd
                dp2[c] = -2.0 * r * dr
        num2, den2 = l2_dc_terms(theta, i_b2, n2b, i_a2, n2a)
        K2 = num2 / den2
        bm = gm * K2 * (1.0 - p1 - p2)
        for c in range(ncol):
            dbm[c] = -gm * K2 * (dp1[c] + dp2[c])
        if cols[4] >= 0:
            dbm[cols[4]] += K2 * (1.0 - p1 - p2)
        if direct:
            for j in range(n2b):
                dbm[i_b2 + j] += gm * (1.0 - p1 - p2) / den2
            for i in range(n2a):
                dbm[i_a2 + i] -= gm * K2 * (1.0 - p1 - p2) / den2
    sM1 = np.zeros(ncol)
    sM2 = np.zeros(ncol)
    ys1 = YL[start - 1]
    ys2 = YL[start - 2] if start >= 2 else ys1
    sys1 = SYL[start - 1].copy()
    sys2 = SYL[start - 2].copy() if start >= 2 else sys1.copy()
    sout = np.zeros(ncol)
    curve = (c2o != 0.0 or c3o != 0.0 or cols[23] >= 0 or cols[24] >= 0) and y_s > 0.0
    lim = dt / inv_rate if inv_rate > 0.0 else 0.0
    dlim = -dt / (inv_rate * inv_rate) if inv_rate > 0.0 else 0.0

    for k in range(start, n):
        # -------------------------------------------------------- eq. (1) on the delayed input
        l1_sens_propagate(theta, layout, S1, k, ncol)
        if direct:  # the parts apart: see l1_sens_row
            l1_sens_direct(theta, layout, UD, W1, S1, k, k)
        if input_sens:
            for m in range(2):
                c = c_del if m == 0 else c_ru
                if c >= 0:
                    s = SUD[k - q1, m]
                    for j in range(1, n1b + 1):
                        s += theta[i_b1 + j - 1] * SUD[k - q1 - j, m]
                    S1[k, c] += s
        w1p = W1[k - 1]
        dw1 = W1[k] - w1p
        if inv_rate > 0.0 and abs(dw1) >= lim * (1.0 - 1e-12):  # the rate limit holds w1
            for p in range(ncol):
                S1[k, p] = S1[k - 1, p]
            _add(S1, k, cols[10], sgn(dw1) * dlim)
        # -------------------------------------------------------- eq. (7), effects' coefficients
        w2p = W2[k - 1]
        s = sgn(dw1)
        su = sgn(UD[k] - UD[k - 1]) if k >= 1 else 0.0
        absd = abs(dw1)
        dir_a = 1.0 + e_a * s + e_au * su
        dir_g = 1.0 + e_g * s + e_gu * su
        dir_f = 1.0 + e_f * s + e_fu * su
        lev_a = 1.0 + l_a * w1p
        lev_g = 1.0 + l_g * w1p
        A = alpha * dir_a * lev_a
        G = g0 * dir_g * lev_g
        bend = 1.0 + cubic * w1p * w1p
        E = f0 * sgn(w1p) + f1 * dir_f * w1p * bend - w2p
        dF = f1 * dir_f * (1.0 + 3.0 * cubic * w1p * w1p)
        duhem_sens_row(S1, S2, k, ncol, A, E, G, dF, alpha * dir_a * l_a, g0 * dir_g * l_g,
                       absd, s, dw1)
        if direct:
            S2[k, i_alpha] += dir_a * lev_a * E * absd
            S2[k, i_f1] += A * dir_f * w1p * bend * absd
            if i_f0 >= 0:
                S2[k, i_f0] += A * sgn(w1p) * absd
            S2[k, i_g0] += dir_g * lev_g * dw1
        _add(S2, k, cols[8], alpha * s * lev_a * E * absd)
        _add(S2, k, cols[27], alpha * su * lev_a * E * absd)
        _add(S2, k, cols[14], alpha * dir_a * w1p * E * absd)
        _add(S2, k, cols[9], g0 * s * lev_g * dw1)
        _add(S2, k, cols[28], g0 * su * lev_g * dw1)
        _add(S2, k, cols[20], g0 * dir_g * w1p * dw1)
        _add(S2, k, cols[13], A * f1 * s * w1p * bend * absd)
        _add(S2, k, cols[29], A * f1 * su * w1p * bend * absd)
        _add(S2, k, cols[11], A * f1 * dir_f * w1p * w1p * w1p * absd)
        # -------------------------------------------------------- creep: v = w2 + lags
        w2 = W2[k]
        for p in range(ncol):
            SV[k, p] = S2[k, p]
        if creep1:
            cp = C[k - 1]
            for p in range(ncol):
                sC[p] += lam * (kappa * S2[k, p] - sC[p])
            if cols[0] >= 0:
                sC[cols[0]] += lam * w2
            if cols[1] >= 0:
                sC[cols[1]] += dlam * (kappa * w2 - cp)
            for p in range(ncol):
                SV[k, p] += sC[p]
        if creep2:
            for p in range(ncol):
                sc2[p] += lam2 * (kappa2 * S2[k, p] - sc2[p])
            if cols[15] >= 0:
                sc2[cols[15]] += lam2 * w2
            if cols[16] >= 0:
                sc2[cols[16]] += dlam2 * (kappa2 * w2 - c2)
            c2 += lam2 * (kappa2 * w2 - c2)
            for p in range(ncol):
                SV[k, p] += sc2[p]
        if creepl:
            for j in range(N_LOG):
                for p in range(ncol):
                    sclog[j, p] += lam_log[j] * (k_log / N_LOG * S2[k, p] - sclog[j, p])
                if cols[17] >= 0:
                    sclog[j, cols[17]] += lam_log[j] * w2 / N_LOG
                if cols[18] >= 0:
                    sclog[j, cols[18]] += dlam_log[j] * (k_log / N_LOG * w2 - c_log[j])
                c_log[j] += lam_log[j] * (k_log / N_LOG * w2 - c_log[j])
                for p in range(ncol):
                    SV[k, p] += sclog[j, p]
        # -------------------------------------------------------- eq. (2) on v
        l2_sens_propagate(theta, layout, SV, SYL, k, ncol)
        if direct:
            l2_sens_direct(theta, layout, V, YL, SYL, k, k)
        for p in range(ncol):
            sout[p] = SYL[k, p]
        out = YL[k]
        # -------------------------------------------------------- modes
        if par_mode:
            for p in range(ncol):
                sm = (dp1[p] * M[k - 1] + p1 * sM1[p] + dp2[p] * M[k - 2] + p2 * sM2[p]
                      + dbm[p] * V[k] + bm * SV[k, p])
                sM2[p] = sM1[p]
                sM1[p] = sm
                sout[p] += sm
            out += M[k]
        if ser_mode:
            ys = p1 * ys1 + p2 * ys2 + (1.0 - p1 - p2) * YL[k]
            for p in range(ncol):
                sy = (dp1[p] * ys1 + p1 * sys1[p] + dp2[p] * ys2 + p2 * sys2[p]
                      - (dp1[p] + dp2[p]) * YL[k] + (1.0 - p1 - p2) * SYL[k, p])
                sys2[p] = sys1[p]
                sys1[p] = sy
                sout[p] += g_ser * (sy - SYL[k, p])
            if cols[19] >= 0:
                sout[cols[19]] += ys - YL[k]
            out += g_ser * (ys - YL[k])
            ys2 = ys1
            ys1 = ys
        # -------------------------------------------------------- the output curve
        if curve:
            x = (out - y_c) / y_s
            gain = 1.0 + x * (2.0 * c2o + 3.0 * c3o * x)
            for p in range(ncol):
                sout[p] *= gain
            if cols[23] >= 0:
                sout[cols[23]] += y_s * x * x
            if cols[24] >= 0:
                sout[cols[24]] += y_s * x * x * x
        # -------------------------------------------------------- drift and offset
        for p in range(ncol):
            SY[k - start, p] = sout[p]
        t = (k - start) * dt
        _add(SY, k - start, d1c, t)
        _add(SY, k - start, d2c, t * t)
        _add(SY, k - start, cols[21], t * t * t)
        _add(SY, k - start, cols[12], 1.0)
