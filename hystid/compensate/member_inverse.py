"""Per-sample inverses of the generalised Duhem block, of the parallel Duhem operators and of
a PI block with polynomial terms.

The members ``gduhem`` (:class:`~hystid.model.DuhemSandwich` with a generalised block, see
:mod:`hystid.kernels`) and ``mduhem`` (:class:`~hystid.mduhem.MultiDuhemSandwich`, see
:mod:`hystid.mduhem_kernels`) step their hysteresis like the paper's eq. (7): the coefficients
are evaluated at the previous sample and the step is affine in ``d = w1(k) - w1(k-1)`` once its
direction ``s = sgn d`` is fixed. With ``v = w1(k-1)``:

* generalised block, ``E = f0 sgn(v) + F(v) - w2(k-1)``::

      Delta = w2(k) - w2(k-1) = (G(v) + gd s + s alpha (1 + ad s) E) d = S_s d

* parallel operators, ``E_j = f1_j v - w2_j(k-1)``::

      Delta = sum_j (g0_j + s alpha_j E_j) d = S_s d

The inverse step
----------------
For a wanted ``w2(k)`` the increment on direction ``s`` is ``d = Delta / S_s``, a solution when
its sign is ``s``. As for the plain block (:func:`~hystid.compensate.duhem_inverse.
duhem_solutions`) there are zero, one or two solutions; of two, the one with the smallest
``|d|`` (the motion along the current branch) is taken.

* **bound**: the step obeys condition (8) with the member's rate on its direction,
  ``alpha (1 + ad s) |d| <= bound`` or ``max_j alpha_j |d| <= bound``; a solution beyond it is
  clipped to it on the direction that then comes closest to the wanted ``w2`` (status
  ``BOUND``).
* **unreachable**: with neither direction reaching the wanted ``w2`` (a reversal the block
  cannot make in one step: on both directions ``w2`` moves away), every step but ``d = 0``
  moves away from it, and ``d = 0`` would keep the state, and the same reversal unreachable,
  for as long as the reference goes on that way. The step taken is the one that comes closest
  to making the reversal: ``w1`` moves the way the reference asks, by the increment that brings
  the rate term of that direction to zero (``E = 0``; ``sum_j alpha_j E_j = 0``), where the
  slope ``S_s`` is the reversible one (``G + gd s``, ``sum_j g0_j``) and the next samples can
  follow the reference again; clipped to the bound (status ``UNREACHABLE``). It is the plain
  inverse's rule (``duhem_inverse._towards_band``) on these blocks. The sample is flagged not
  exact; the error it leaves is made up by the next exact step, which aims at the wanted
  ``w2`` itself.

No look-ahead. The plain Duhem inverse prepares reversals of a block whose branches do not let
``w2`` reverse at once (``alpha |G| > g0``) with a reversal planner over a preview of the
reference (:func:`~hystid.compensate.duhem_inverse.plan_memo`): it enters the far branch early
so that the reversal is exact when it comes. That planner is written for the plain block's
one-dimensional gap and is not generalised here: these inverses are causal (no preview), and on
such a block a reversal is approximate for the few samples the fallback above needs (status
``UNREACHABLE``, listed in :attr:`~hystid.compensate.Compensation.warnings`). Where every
reversal is reachable in one step (the reversible slope larger than the rate term on the
branches, e.g. ``f1 < 2 g0`` for the plain block) every step is exact.

A PI block with polynomial terms (``pi-poly``, ``w2 = sum_i mu_i p_i + sum_j c_j w1^j``) has
no inverse PI operator; its ``w2`` is continuous and, on an invertible model
(:meth:`hystid.pi.PISandwich.is_invertible`: every branch rises over the envelope), increasing
in ``w1(k)`` for the plays' states at ``k-1``. :func:`pi_poly_inverse` brackets the wanted
``w2`` from ``w1(k-1)`` and bisects to round-off: exact up to the last bits wherever the
model is invertible (status ``UNREACHABLE`` where the bracket is not found).

The kernels take the model's own parameter arrays: the generalised block its ``theta`` and
``layout`` (its coefficients from :func:`hystid.kernels.shape_terms`, its forward step written
as :func:`hystid.kernels.step` writes it), the parallel operators their rates, ``f1_j`` and
``g0_j`` (the forward step as :func:`hystid.mduhem_kernels.mduhem_step` writes it), so that the
compensator's internal model follows ``model.simulate`` to the last bit. The C export writes
the same functions with the same operations in the same order (``FF_MEMBER``, ``FF_GDUHEM`` and
``FF_MDUHEM`` of :mod:`hystid.export._c_ff_members`): a change here is a change there
(``tests/test_export.py`` compares them sample by sample).
"""

from __future__ import annotations

from numba import njit

from ..kernels import offsets, sgn, shape_terms
from ..pi_operator import play, poly_terms
from .duhem_inverse import BOUND, EXACT, UNREACHABLE

__all__ = [
    "affine_step",
    "gduhem_forward",
    "gduhem_inverse_step",
    "gduhem_slopes",
    "mduhem_forward",
    "mduhem_inverse_step",
    "mduhem_slopes",
    "pi_poly_inverse",
]

# a requested change of w2 this small is round-off of the reference path (as duhem_inverse's)
_ROUND_OFF = 1e-13


@njit(cache=True)
def affine_step(delta, s_pos, s_neg, r_pos, r_neg, bound):
    """The inverse step of a block whose step is ``Delta = S_s d`` on each direction ``s``.

    Parameters
    ----------
    delta : float
        Wanted change of ``w2``.
    s_pos, s_neg : float
        Slopes ``S_+`` (for ``d > 0``) and ``S_-`` (for ``d < 0``).
    r_pos, r_neg : float
        The rates condition (8) bounds on each direction (``rate |d| <= bound``).
    bound : float
        Largest ``rate |d|`` allowed.

    Returns
    -------
    n : int
        Number of exact solutions (0, 1 or 2), within the bound or not.
    d : float
        The near solution (smallest ``|d|``), clipped to the bound on the direction that comes
        closest when it is beyond it; 0 when ``n == 0``.
    status : int
        ``EXACT``, ``BOUND`` or, when ``n == 0``, ``UNREACHABLE``.
    """
    d_pos = 0.0
    d_neg = 0.0
    ok_pos = False
    ok_neg = False
    if s_pos != 0.0:
        d_pos = delta / s_pos
        ok_pos = d_pos > 0.0
    if s_neg != 0.0:
        d_neg = delta / s_neg
        ok_neg = d_neg < 0.0
    n = int(ok_pos) + int(ok_neg)
    if n == 0:
        return 0, 0.0, UNREACHABLE
    if ok_pos and (not ok_neg or d_pos <= -d_neg):
        near, rate, slope = d_pos, r_pos, s_pos
        other, o_rate, o_slope = d_neg, r_neg, s_neg
    else:
        near, rate, slope = d_neg, r_neg, s_neg
        other, o_rate, o_slope = d_pos, r_pos, s_pos
    if rate * abs(near) <= bound:
        return n, near, EXACT
    # beyond the bound: the clipped step that comes closest to the wanted w2
    d = sgn(near) * bound / rate
    miss = abs(delta - slope * d)
    if n == 2:
        d2 = sgn(other) * min(abs(other), bound / o_rate)
        if abs(delta - o_slope * d2) < miss:
            if o_rate * abs(other) <= bound:
                return n, other, EXACT
            d = d2
    return n, d, BOUND


@njit(cache=True)
def _towards(direction, q, rate_q, dmax):
    """Increment on ``direction`` that brings a rate term ``q`` (changing by ``rate_q`` per unit
    of ``d``) to zero, at most ``dmax`` long; the whole ``dmax`` when it cannot."""
    if rate_q != 0.0:
        d = -q / rate_q
        if d * direction > 0.0:
            return direction * min(abs(d), dmax)
    return direction * dmax


# --------------------------------------------------------------------------- generalised block
@njit(cache=True)
def gduhem_slopes(theta, layout, w1p, w2p):
    """Slopes and rates of the generalised eq. (7) on both directions at ``w1p, w2p``.

    Parameters
    ----------
    theta : ndarray
        The model's parameter vector (:attr:`hystid.model.DuhemSandwich.theta`).
    layout : ndarray of int
        Its kernel layout (:attr:`hystid.model.Structure.layout`).
    w1p, w2p : float
        ``w1(k-1), w2(k-1)``.

    Returns
    -------
    s_pos, s_neg : float
        ``S_+``, ``S_-`` (``Delta = S_s d`` on direction ``s``).
    a_pos, a_neg : float
        The rates ``alpha (1 + ad s)``.
    e_pos, e_neg : float
        The rate terms' gap ``E = f0 sgn(v) + F(v) - w2(k-1)`` (the same on both directions).
    df : float
        ``F'(v)``.
    """
    i_f0 = offsets(layout)[2]
    f0 = theta[i_f0] if i_f0 >= 0 else 0.0
    a_pos, F, g_pos, dF, _ = shape_terms(theta, layout, w1p, 1.0)
    a_neg, _, g_neg, _, _ = shape_terms(theta, layout, w1p, -1.0)
    E = f0 * sgn(w1p) + F - w2p
    return g_pos + a_pos * E, g_neg - a_neg * E, a_pos, a_neg, E, E, dF


@njit(cache=True)
def gduhem_forward(theta, layout, w1, w1p, w2p):
    """``w2(k)`` of the generalised eq. (7) from ``w1(k)`` and ``w1(k-1), w2(k-1)``.

    Written as :func:`hystid.kernels.step` writes it (the same operations in the same order).

    Parameters
    ----------
    theta, layout : ndarray
        As for :func:`gduhem_slopes`.
    w1, w1p, w2p : float
        ``w1(k)``, ``w1(k-1)``, ``w2(k-1)``.

    Returns
    -------
    float
        ``w2(k)``.
    """
    i_f0 = offsets(layout)[2]
    f0 = theta[i_f0] if i_f0 >= 0 else 0.0
    dw1 = w1 - w1p
    A, F, G, dF, dG = shape_terms(theta, layout, w1p, sgn(dw1))
    return w2p + A * (f0 * sgn(w1p) + F - w2p) * abs(dw1) + G * dw1


@njit(cache=True)
def gduhem_inverse_step(w2d, w1p, w2p, theta, layout, bound):
    """The inverse of the generalised eq. (7) for one sample (see the module docstring).

    Parameters
    ----------
    w2d : float
        Wanted ``w2(k)``.
    w1p, w2p : float
        ``w1(k-1), w2(k-1)``.
    theta, layout : ndarray
        As for :func:`gduhem_slopes`.
    bound : float
        Largest ``alpha (1 + ad s) |d|`` allowed (below 2, condition 8).

    Returns
    -------
    d : float
        Increment of ``w1``.
    status : int
        ``EXACT``, ``BOUND`` or ``UNREACHABLE``.
    """
    delta = w2d - w2p
    if abs(delta) <= _ROUND_OFF * (1.0 + abs(w2d)):
        return 0.0, EXACT
    s_pos, s_neg, a_pos, a_neg, E, _, dF = gduhem_slopes(theta, layout, w1p, w2p)
    n, d, status = affine_step(delta, s_pos, s_neg, a_pos, a_neg, bound)
    if n > 0:
        return d, status
    # unreachable: move w1 the way w2 is asked to go, until E = 0 (linearised: dE/dd = F' - S_s)
    if delta > 0.0:
        return _towards(1.0, E, dF - s_pos, bound / a_pos), UNREACHABLE
    return _towards(-1.0, E, dF - s_neg, bound / a_neg), UNREACHABLE


# --------------------------------------------------------------------------- parallel operators
@njit(cache=True)
def mduhem_slopes(w1p, p, rates, f1, g0):
    """Slopes of the sum of Duhem operators on both directions, and their rate terms.

    Parameters
    ----------
    w1p : float
        ``w1(k-1)``.
    p : ndarray
        The operators' states ``w2_j(k-1)``.
    rates, f1, g0 : ndarray
        ``alpha_j, f1_j, g0_j``.

    Returns
    -------
    s_pos, s_neg : float
        ``S_+ = sum_j g0_j + Q``, ``S_- = sum_j g0_j - Q``.
    q : float
        The rate term ``Q = sum_j alpha_j E_j``, ``E_j = f1_j v - w2_j(k-1)``.
    dq_pos, dq_neg : float
        How ``Q`` changes per unit of ``d`` on each direction (exactly: ``Q`` after the step is
        ``Q + dq_s d``).
    """
    g = 0.0
    q = 0.0
    c = 0.0
    c2 = 0.0
    for j in range(p.shape[0]):
        e = f1[j] * w1p - p[j]
        g += g0[j]
        q += rates[j] * e
        c += rates[j] * (f1[j] - g0[j])
        c2 += rates[j] * rates[j] * e
    return g + q, g - q, q, c - c2, c + c2


@njit(cache=True)
def mduhem_forward(p, w1, w1p, rates, f1, g0):
    """Move the operators' states ``p`` on to ``w1(k)`` (in place); returns ``w2(k)``.

    Written as :func:`hystid.mduhem_kernels.mduhem_step` writes it.

    Parameters
    ----------
    p : ndarray
        ``w2_j(k-1)``, overwritten with ``w2_j(k)``.
    w1, w1p : float
        ``w1(k)``, ``w1(k-1)``.
    rates, f1, g0 : ndarray
        ``alpha_j, f1_j, g0_j``.

    Returns
    -------
    float
        ``w2(k) = sum_j w2_j(k)``.
    """
    d = w1 - w1p
    ad = abs(d)
    w2 = 0.0
    for j in range(p.shape[0]):
        p[j] = p[j] + rates[j] * (f1[j] * w1p - p[j]) * ad + g0[j] * d
        w2 += p[j]
    return w2


@njit(cache=True)
def mduhem_inverse_step(w2d, w1p, p, rates, f1, g0, bound):
    """The inverse of the parallel Duhem operators for one sample (see the module docstring).

    Parameters
    ----------
    w2d : float
        Wanted ``w2(k) = sum_j w2_j(k)``.
    w1p : float
        ``w1(k-1)``.
    p : ndarray
        The operators' states ``w2_j(k-1)`` (not changed).
    rates, f1, g0 : ndarray
        ``alpha_j, f1_j, g0_j``.
    bound : float
        Largest ``max_j alpha_j |d|`` allowed (below 2, condition 8).

    Returns
    -------
    d : float
        Increment of ``w1``.
    status : int
        ``EXACT``, ``BOUND`` or ``UNREACHABLE``.
    """
    w2p = 0.0
    rmax = 0.0
    for j in range(p.shape[0]):
        w2p += p[j]
        rmax = max(rmax, rates[j])
    delta = w2d - w2p
    if abs(delta) <= _ROUND_OFF * (1.0 + abs(w2d)):
        return 0.0, EXACT
    s_pos, s_neg, q, dq_pos, dq_neg = mduhem_slopes(w1p, p, rates, f1, g0)
    n, d, status = affine_step(delta, s_pos, s_neg, rmax, rmax, bound)
    if n > 0:
        return d, status
    if delta > 0.0:
        return _towards(1.0, q, dq_pos, bound / rmax), UNREACHABLE
    return _towards(-1.0, q, dq_neg, bound / rmax), UNREACHABLE


# =========================================================================== PI with polynomial
#: Doublings of the bracket's width before a wanted ``w2`` is taken as unreachable.
BRACKET_DOUBLINGS = 80


@njit(cache=True)
def _pi_poly_gap(w, w2d, p, r, mu, c):
    # w2 after a move of the plays (states p at k-1, not changed) to w, less the wanted w2
    acc = 0.0
    for i in range(r.shape[0]):
        acc += mu[i] * play(w, p[i], r[i])
    return acc + poly_terms(w, c)[0] - w2d


@njit(cache=True)
def pi_poly_inverse(w2d, w1p, p, r, mu, c):
    """The inverse of a PI block with polynomial terms for one sample.

    Parameters
    ----------
    w2d : float
        Wanted ``w2(k)``.
    w1p : float
        ``w1(k-1)``.
    p : ndarray
        The plays' states ``p_i(k-1)`` (not changed).
    r, mu : ndarray
        Thresholds and weights.
    c : ndarray
        The polynomial terms' coefficients ``c_2, c_3, ..``.

    Returns
    -------
    w1 : float
        ``w1(k)``.
    status : int
        ``EXACT``, or ``UNREACHABLE`` when no bracket was found (a block that does not rise
        there): then the last point tried on the way.
    """
    g0 = _pi_poly_gap(w1p, w2d, p, r, mu, c)
    if abs(g0) <= _ROUND_OFF * (1.0 + abs(w2d)):
        return w1p, EXACT
    way = -1.0 if g0 > 0.0 else 1.0  # an invertible block rises with w1
    slope = abs(poly_terms(w1p, c)[1])
    for i in range(mu.shape[0]):
        slope += abs(mu[i])
    width = abs(g0) / slope if slope > 0.0 else 1.0
    near, far = w1p, w1p + way * width
    found = False
    for _ in range(BRACKET_DOUBLINGS):
        if _pi_poly_gap(far, w2d, p, r, mu, c) * way >= 0.0:  # crossed: g(far) has left g0's sign
            found = True
            break
        near = far
        width *= 2.0
        far = w1p + way * width
    if not found:
        return far, UNREACHABLE
    lo, hi = (near, far) if near < far else (far, near)
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        if mid <= lo or mid >= hi:
            break
        if _pi_poly_gap(mid, w2d, p, r, mu, c) < 0.0:
            lo = mid
        else:
            hi = mid
    return 0.5 * (lo + hi), EXACT
