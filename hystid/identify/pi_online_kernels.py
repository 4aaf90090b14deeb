"""Compiled kernels of the ``pi-stage`` on-line identifier (:mod:`hystid.identify.pi_online`).

One sample of the parallel-form branches with the prediction's gradient (:func:`_step`), the
recursive Gauss-Newton step kept admissible (:func:`_rpem_step`), a run over a block
(:func:`_run`), the member's parameters of the search coordinates (:func:`_theta_rows`) and the
admissibility tests the re-solve shares (:func:`_l2_stable`, :func:`_slope`).
"""

from __future__ import annotations

import numpy as np
from numba import njit

from ..poly import KMAX_STABLE, schur_stable

#: Rows of the branch state of one operator: p(k-1), p(k-2), xS(k-1), dxS/dp, xM(k-1),
#: xM(k-2), dxM/d(c1, c2, m1) at k-1 and at k-2, and the operator's output at rest (held; not
#: zero when the stage rests on a branch of its loop, :attr:`hystid.pi.PISandwich.rest_swing`:
#: the prediction is then relative to the output at rest, as the measured output is). A
#: column after the operators' holds the drift's clock: its value at the next sample (row 0)
#: and its step per sample (row 1).
_STATE_ROWS = 13
#: Bound on the slow pole and on the mode's reflection coefficients (``|.| < 1 - 1e-6``), so
#: that neither branch can become an integrator.
_KMAX = 1.0 - 1e-6


@njit(cache=True)
def _theta_rows(phi, n, out):
    # theta_from_stage of each row of phi (2-D), into out
    for k in range(phi.shape[0]):
        g, m1 = phi[k, n], phi[k, n + 4]
        p = _KMAX * np.tanh(phi[k, n + 1])
        c2 = _KMAX * np.tanh(phi[k, n + 3])
        c1 = _KMAX * np.tanh(phi[k, n + 2]) * (1.0 + c2)
        m0 = 1.0 + c1 + c2 - m1
        # A(z) = (1 - p z^-1)(1 + c1 z^-1 + c2 z^-2); B(z) = g (1 - p) (1 + c1 z^-1 + c2 z^-2)
        # + (1 - g)(m0 + m1 z^-1)(1 - p z^-1), both multiplied out (their leading terms 1, m0)
        gp, h = g * (1.0 - p), 1.0 - g
        for i in range(n):
            out[k, i] = phi[k, i]
        out[k, n] = c1 - p
        out[k, n + 1] = c2 - p * c1
        out[k, n + 2] = -p * c2
        out[k, n + 3] = gp * c1 + h * (m1 - p * m0)
        out[k, n + 4] = gp * c2 + h * -(p * m1)


@njit(cache=True)
def _step(phi, r, npoly, u_k, st, psi):
    # one sample: branch states at k from p(k-1), p(k-2), the prediction and its gradient
    # psi = d yhat / d phi; then the operators move with u(k). Returns yhat(k). The operators
    # are the plays (thresholds r) and, after them, npoly memoryless terms u^2, u^3, ..; a
    # coordinate phi[n + 5], when there is one, corrects the output's offset, and phi[n + 6]
    # is the drift's rate per unit of the clock st[0, n] (which then steps by st[1, n]).
    nplay = r.shape[0]
    n = nplay + npoly
    g = phi[n]
    tp, t1, t2 = np.tanh(phi[n + 1]), np.tanh(phi[n + 2]), np.tanh(phi[n + 3])
    p, k1, c2 = _KMAX * tp, _KMAX * t1, _KMAX * t2
    dp, dk1, dk2 = _KMAX * (1.0 - tp * tp), _KMAX * (1.0 - t1 * t1), _KMAX * (1.0 - t2 * t2)
    c1 = k1 * (1.0 + c2)
    m1 = phi[n + 4]
    m0 = 1.0 + c1 + c2 - m1
    offset = phi.shape[0] > n + 5
    drift = phi.shape[0] > n + 6
    yhat = phi[n + 5] if offset else 0.0
    if drift:
        yhat += phi[n + 6] * st[0, n]
    dg = 0.0
    sp = 0.0
    s0 = 0.0
    s1 = 0.0
    s2 = 0.0
    for i in range(n):
        p1, p2 = st[0, i], st[1, i]
        xs = p * st[2, i] + (1.0 - p) * p1
        ds = p * st[3, i] + st[2, i] - p1
        xm = -c1 * st[4, i] - c2 * st[5, i] + m0 * p1 + m1 * p2
        d0 = -c1 * st[6, i] - c2 * st[9, i] - st[4, i] + p1
        d1 = -c1 * st[7, i] - c2 * st[10, i] - st[5, i] + p1
        d2 = -c1 * st[8, i] - c2 * st[11, i] - p1 + p2
        st[5, i] = st[4, i]
        st[4, i] = xm
        for j in range(3):
            st[9 + j, i] = st[6 + j, i]
        st[6, i], st[7, i], st[8, i] = d0, d1, d2
        st[2, i], st[3, i] = xs, ds
        mu = phi[i]
        xi = g * xs + (1.0 - g) * xm - st[12, i]
        yhat += mu * xi
        psi[i] = xi
        dg += mu * (xs - xm)
        sp += mu * ds
        s0 += mu * d0
        s1 += mu * d1
        s2 += mu * d2
        if i < nplay:
            q = max(u_k - r[i], min(u_k + r[i], p1))     # eq. (30), w1 = u
        else:
            q = u_k ** (i - nplay + 2)                  # a polynomial term
        st[1, i] = p1
        st[0, i] = q
    psi[n] = dg
    psi[n + 1] = g * sp * dp
    dc1 = (1.0 - g) * s0
    dc2 = (1.0 - g) * s1
    psi[n + 2] = dc1 * dk1 * (1.0 + c2)
    psi[n + 3] = (dc1 * k1 + dc2) * dk2
    psi[n + 4] = (1.0 - g) * s2
    if offset:
        psi[n + 5] = 1.0
    if drift:
        psi[n + 6] = st[0, n]
        st[0, n] += st[1, n]
    return yhat


@njit(cache=True)
def _l2_stable(phi, n):
    # the multiplied-out denominator (1 - p z^-1)(1 + c1 z^-1 + c2 z^-2) passes the library's
    # stability test (its margin), not only its two factors
    p = _KMAX * np.tanh(phi[n + 1])
    c2 = _KMAX * np.tanh(phi[n + 3])
    c1 = _KMAX * np.tanh(phi[n + 2]) * (1.0 + c2)
    return schur_stable(np.array([c1 - p, c2 - p * c1, -p * c2]), KMAX_STABLE)


@njit(cache=True)
def _slope(phi, n):
    # smallest cumulative sum of the weights (the loading slope's weakest point)
    acc = 0.0
    low = np.inf
    for i in range(n):
        acc += phi[i]
        low = min(low, acc)
    return low


@njit(cache=True)
def _rpem_step(phi, P, psi, e, s2, lam, max_step, nplay, n, Pg, old):
    # recursive Gauss-Newton: K = P psi / (lam s2 + psi' P psi), a bounded, admissible step
    # (the loading slope over the nplay plays' weights, L2 after all n weights)
    npar = phi.shape[0]
    den = lam * s2
    for a in range(npar):
        acc = 0.0
        for b in range(npar):
            acc += P[a, b] * psi[b]
        Pg[a] = acc
        den += psi[a] * acc
    norm = 0.0
    for a in range(npar):
        norm += (Pg[a] / den * e) ** 2
    scale = 1.0 if norm <= max_step * max_step else max_step / np.sqrt(norm)
    for a in range(npar):
        old[a] = phi[a]
    before = _slope(phi, nplay)
    for _ in range(12):
        for a in range(npar):
            phi[a] = old[a] + scale * Pg[a] / den * e
        after = _slope(phi, nplay)
        if (after > 0.0 or after >= before) and _l2_stable(phi, n):
            break
        scale *= 0.5
    else:
        for a in range(npar):
            phi[a] = old[a]
    for a in range(npar):
        for b in range(npar):
            P[a, b] = (P[a, b] - Pg[a] * Pg[b] / den) / lam
    for a in range(npar):
        for b in range(a):
            v = 0.5 * (P[a, b] + P[b, a])
            P[a, b] = v
            P[b, a] = v


@njit(cache=True)
def _run(phi, P, s2, lam, max_step, r, npoly, u, y, st, learn, J, yhat, err, kept, nslope):
    """Run the branches over ``u`` from the state ``st`` (updated in place); the operators are
    the plays of thresholds ``r`` and ``npoly`` polynomial terms after them.

    With ``learn`` each sample with a finite ``y`` updates ``phi`` and ``P``; ``J`` (one row per
    sample, or zero rows) receives the gradients; ``yhat`` and ``err`` the predictions and the
    errors (NaN where ``y`` is not finite); ``kept`` (one row per sample, or zero rows) the
    search coordinates after each sample. A learning step keeps the smallest cumulative sum of
    the first ``nslope`` weights positive (or no lower than it was; 0: no such bound).
    """
    nplay = r.shape[0]
    n = nplay + npoly
    npar = phi.shape[0]
    psi = np.empty(npar)
    Pg = np.empty(npar)
    old = np.empty(npar)
    keep = J.shape[0] > 0
    track = kept.shape[0] > 0
    for k in range(u.shape[0]):
        yh = _step(phi, r, npoly, u[k], st, psi)
        yhat[k] = yh
        if keep:
            J[k, :] = psi
        if not np.isfinite(y[k]):
            err[k] = np.nan
        else:
            e = y[k] - yh
            err[k] = e
            if learn:
                _rpem_step(phi, P, psi, e, s2, lam, max_step, nslope, n, Pg, old)
        if track:
            kept[k, :] = phi


@njit(cache=True)
def still_mask(u, still, band, hold, out):
    """Which samples of ``u`` find the stage at rest: the input has stayed within ``band`` of
    an anchor for more than ``hold`` samples. ``still`` holds the anchor and the count so far
    (updated in place, carried from call to call); ``out`` receives the mask."""
    for k in range(u.shape[0]):
        if abs(u[k] - still[0]) > band:
            still[0] = u[k]
            still[1] = 0.0
        else:
            still[1] += 1.0
        out[k] = still[1] > hold
