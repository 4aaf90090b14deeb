"""Compiled kernels of the on-line identifier: the recursive prediction-error step with its
safeguards (covariance check, resynchronisation, the sliding buffers), sample by sample, and the
layouts of the arrays they share with :class:`~hystid.identify.online.OnlineIdentifier`.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
from numba import njit

from ..kernels import offsets, step_sens
from ._recursive import admissible_into

if TYPE_CHECKING:  # pragma: no cover
    pass



#: Columns of the diagnostics array kept per sample.
DIAGNOSTICS = ("e", "sigma", "lambda", "trace_P", "rms_short", "rms_long", "offset")

# scal layout
(_K, _LAM, _SIG, _SHORT, _LONG, _NPROJ, _NCLIP, _NREC, _FIRST, _HOLD, _GOODAGE,
 _NPRESET, _DW1MAX) = range(13)
_NSCAL = 13
#: The projection caps alpha at this share of condition (8)'s bound over the largest |dw1| seen.
ALPHA_MARGIN = 0.95
# settings layout
(_S_LAM_INF, _S_LAM_RATE, _S_CLIP, _S_TRACE, _S_DIV_RATIO, _S_DIV_HOLD, _S_PRESET, _S_KMAX,
 _S_SHORT, _S_LONG, _S_SIG, _S_TRACK) = range(12)
_NSET = 12
# ints layout: the structure's layout (7 entries), then sizes and the cursor
_I_NPAR, _I_W, _I_CAP, _I_POS = 10, 11, 12, 13
_NINTS = 14


# =========================================================================== compiled kernels
@njit(cache=True)
def _resync(theta, layout, W1, W2, Yh, Ym, S1, S2, SY, lo, L):
    """After a restart: the model output takes the measured output, w2 follows from inverting
    L2 (eq. 2) on it, non-finite w1 are cleared and the sensitivities restart from zero."""
    n2a, n2b, q2 = layout[2], layout[3], layout[5]
    i_b2, i_a2 = 0, offsets(layout)[7]
    for i in range(lo, L + 1):
        Yh[i] = Ym[i]
        if not np.isfinite(W1[i]):
            W1[i] = 0.0
        S1[i, :] = 0.0
        S2[i, :] = 0.0
        SY[i, :] = 0.0
    for i in range(lo + max(n2a, q2 + n2b), L + 1):
        w2 = Ym[i]
        for j in range(1, n2a + 1):
            w2 += theta[i_a2 + j - 1] * Ym[i - j]
        for j in range(1, n2b + 1):
            w2 -= theta[i_b2 + j - 1] * W2[i - q2 - j]
        W2[i - q2] = w2


@njit(cache=True)
def _covariance_ok(P, trace_max):
    """P is finite, has a positive diagonal, |P_ij|^2 <= P_ii P_jj and trace below the cap."""
    n = P.shape[0]
    tr = 0.0
    for i in range(n):
        if not (P[i, i] >= 0.0) or not np.isfinite(P[i, i]):
            return False
        tr += P[i, i]
        for j in range(i):
            if not (P[i, j] * P[i, j] <= P[i, i] * P[j, j]):
                return False
    return tr < trace_max and tr > 0.0


@njit(cache=True)
def _views(buf, ints):
    """The named arrays of the packed state (views into ``buf``, no copy)."""
    npar, w, cap = ints[_I_NPAR], ints[_I_W], ints[_I_CAP]
    ne = npar + 1
    o = 0
    est = buf[o:o + ne]
    o += ne
    P = buf[o:o + ne * ne].reshape((ne, ne))
    o += ne * ne
    est_good = buf[o:o + ne]
    o += ne
    P_good = buf[o:o + ne * ne].reshape((ne, ne))
    o += ne * ne
    scal = buf[o:o + _NSCAL]
    o += _NSCAL
    sett = buf[o:o + _NSET]
    o += _NSET
    diag = buf[o:o + len(DIAGNOSTICS)]
    o += len(DIAGNOSTICS)
    PH = buf[o:o + ne]
    o += ne
    cand = buf[o:o + ne]
    o += ne
    work = buf[o:o + ne]
    o += ne
    U = buf[o:o + cap]
    o += cap
    W1 = buf[o:o + cap]
    o += cap
    W2 = buf[o:o + cap]
    o += cap
    Yh = buf[o:o + cap]
    o += cap
    Ym = buf[o:o + cap]
    o += cap
    S1 = buf[o:o + cap * npar].reshape((cap, npar))
    o += cap * npar
    S2 = buf[o:o + cap * npar].reshape((cap, npar))
    o += cap * npar
    SY = buf[o:o + cap * npar].reshape((cap, npar))
    return (est, P, est_good, P_good, scal, sett, diag, PH, cand, work, U, W1, W2, Yh, Ym,
            S1, S2, SY, w)


def _buffer_size(npar: int, cap: int) -> int:
    ne = npar + 1
    return (2 * ne + 2 * ne * ne + _NSCAL + _NSET + len(DIAGNOSTICS) + 3 * ne + 5 * cap
            + 3 * cap * npar)


@njit(cache=True)
def _slide(ints, U, W1, W2, Yh, Ym, S1, S2, SY, w):
    """The windows are full: move their last ``w`` samples to the front."""
    cap = ints[_I_CAP]
    for a in (U, W1, W2, Yh, Ym):
        a[:w] = a[cap - w:cap]
    for a in (S1, S2, SY):
        a[:w] = a[cap - w:cap]
    ints[_I_POS] = w


@njit(cache=True)
def _rpem_sample(est, P, est_good, P_good, scal, sett, diag, PH, cand, work, U, W1, W2, Yh, Ym,
                 S1, S2, SY, w, ints, layout, u, y):
    """One sample of the recursion (see the module docstring); fills the diagnostics view."""
    npar = ints[_I_NPAR]
    ne = npar + 1
    if ints[_I_POS] >= ints[_I_CAP]:
        _slide(ints, U, W1, W2, Yh, Ym, S1, S2, SY, w)
    L = ints[_I_POS]
    theta = est[:npar]
    clip, trace_max, kmax = sett[_S_CLIP], sett[_S_TRACE], sett[_S_KMAX]
    a_short, a_long, a_sig = sett[_S_SHORT], sett[_S_LONG], sett[_S_SIG]
    div_ratio, div_hold, track = sett[_S_DIV_RATIO], sett[_S_DIV_HOLD], sett[_S_TRACK]
    i_alpha = offsets(layout)[1]
    finite_y = np.isfinite(y)
    U[L] = u
    # 1. model step with theta(k-1) and the exact sensitivities psi(k)
    step_sens(theta, layout, U, W1, W2, Yh, S1, S2, SY, L)
    Ym[L] = y - est[npar] if finite_y else Yh[L - 1]
    psi = SY[L]
    scal[_LAM] = sett[_S_LAM_INF] - (sett[_S_LAM_INF] - scal[_LAM]) * sett[_S_LAM_RATE]
    lam = scal[_LAM]
    e = np.nan
    restart = not np.isfinite(Yh[L])
    if finite_y and not restart:
        e = y - Yh[L] - est[npar]
        # 2. clipped residual, robust scale, short- and long-term residual levels
        sig = scal[_SIG]
        ec = e
        if abs(e) > clip * sig:
            ec = clip * sig if e > 0 else -clip * sig
            scal[_NCLIP] += 1.0
        scal[_SIG] = np.sqrt((1.0 - a_sig) * sig * sig + a_sig * ec * ec) + 1e-300
        scal[_SHORT] = (1.0 - a_short) * scal[_SHORT] + a_short * e * e
        alarm = scal[_SHORT] > div_ratio * div_ratio * scal[_LONG]
        if not alarm:
            scal[_LONG] = (1.0 - a_long) * scal[_LONG] + a_long * scal[_SHORT]
        # 3. Gauss-Newton step with forgetting; the offset's sensitivity is 1
        hPh = 0.0
        for i in range(ne):
            s = P[i, npar]
            for j in range(npar):
                s += P[i, j] * psi[j]
            PH[i] = s
            hPh += (psi[i] if i < npar else 1.0) * s
        denom = lam + hPh
        for i in range(ne):
            cand[i] = est[i] + PH[i] * (ec / denom)
        # 4. projection onto the admissible set (Assumption 1; condition 8 over the largest
        #    |dw1| seen so far: alpha capped below 2 / max|dw1|)
        dw1 = abs(W1[L] - W1[L - 1])
        if dw1 > scal[_DW1MAX]:
            scal[_DW1MAX] = dw1
        if admissible_into(cand[:npar], layout, kmax, work):
            cap_alpha = 2.0 * ALPHA_MARGIN / scal[_DW1MAX] if scal[_DW1MAX] > 0 else np.inf
            if cand[i_alpha] >= cap_alpha:
                cand[i_alpha] = cap_alpha
                scal[_NPROJ] += 1.0
            est[:] = cand
        else:
            scal[_NPROJ] += 1.0
        for i in range(ne):
            for j in range(i + 1):
                v = (P[i, j] - PH[i] * PH[j] / denom) / lam
                P[i, j] = v
                P[j, i] = v
        if not _covariance_ok(P, trace_max):
            scal[_NPRESET] += 1.0
            for i in range(ne):
                for j in range(ne):
                    P[i, j] = 0.0
                P[i, i] = sett[_S_PRESET] if i < npar else sett[_S_PRESET] * track
        # divergence watch
        if alarm:
            scal[_HOLD] += 1.0
        else:
            scal[_HOLD] = 0.0
            if scal[_SHORT] < 4.0 * scal[_LONG]:
                scal[_GOODAGE] += 1.0
                if scal[_GOODAGE] > div_hold:
                    est_good[:] = est
                    P_good[:, :] = P
                    scal[_GOODAGE] = 0.0
        restart = scal[_HOLD] > div_hold
    if restart:
        scal[_NREC] += 1.0
        if scal[_FIRST] < 0:
            scal[_FIRST] = scal[_K] + 1.0
        est[:] = est_good
        P[:, :] = P_good
        _resync(est[:npar], layout, W1, W2, Yh, Ym, S1, S2, SY, max(0, L - w + 1), L)
        scal[_HOLD] = 0.0
        scal[_GOODAGE] = 0.0
        scal[_SHORT] = scal[_LONG]
        scal[_SIG] = np.sqrt(scal[_LONG])
    scal[_K] += 1.0
    ints[_I_POS] = L + 1
    tr = 0.0
    for i in range(ne):
        tr += P[i, i]
    diag[0] = e
    diag[1] = scal[_SIG]
    diag[2] = lam
    diag[3] = tr
    diag[4] = np.sqrt(scal[_SHORT])
    diag[5] = np.sqrt(scal[_LONG])
    diag[6] = est[npar]


@njit(cache=True)
def rpem_run(buf, ints, u_in, y_in, history, diagnostics):
    """The recursion over a chunk: :func:`_rpem_sample` per sample, rows of history kept."""
    (est, P, est_good, P_good, scal, sett, diag, PH, cand, work, U, W1, W2, Yh, Ym, S1, S2,
     SY, w) = _views(buf, ints)
    layout = ints[:10].copy()
    npar = ints[_I_NPAR]
    nd = diagnostics.shape[1]
    for n in range(u_in.shape[0]):
        _rpem_sample(est, P, est_good, P_good, scal, sett, diag, PH, cand, work, U, W1, W2, Yh,
                     Ym, S1, S2, SY, w, ints, layout, u_in[n], y_in[n])
        for i in range(npar):
            history[n, i] = est[i]
        for i in range(nd):
            diagnostics[n, i] = diag[i]


@njit(cache=True)
def rpem_one(buf, ints, u, y):
    """The recursion for one sample; returns the restart count (the estimate is in ``buf``)."""
    (est, P, est_good, P_good, scal, sett, diag, PH, cand, work, U, W1, W2, Yh, Ym, S1, S2,
     SY, w) = _views(buf, ints)
    _rpem_sample(est, P, est_good, P_good, scal, sett, diag, PH, cand, work, U, W1, W2, Yh, Ym,
                 S1, S2, SY, w, ints, ints[:10], u, y)
    return int(scal[_NREC])


