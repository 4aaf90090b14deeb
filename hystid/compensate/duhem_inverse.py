"""Per-sample inverse of the discrete Duhem operator (eq. 7), with a preview planner.

The problem
-----------
Given the state ``w1(k-1), w2(k-1)`` and a desired ``w2(k)``, find ``w1(k)``. With
``d = w1(k) - w1(k-1)``, ``Delta = w2(k) - w2(k-1)`` and the *gap*

    G = f0 sgn(w1(k-1)) + f1 w1(k-1) - w2(k-1)                          (eqs. 5-7)

eq. (7) reads ``Delta = phi(d) = alpha G |d| + g0 d``: piecewise linear in ``d``, with slope
``s+ = g0 + alpha G`` for ``d > 0`` and ``s- = g0 - alpha G`` for ``d < 0``.

Existence and uniqueness
------------------------
* If ``alpha |G| < g0`` both slopes are positive: ``phi`` is a strictly increasing bijection and
  the solution is unique (``d = Delta / s+`` or ``Delta / s-`` by the sign of ``Delta``).
* If ``alpha |G| > g0`` the slopes have opposite signs, ``phi`` keeps one sign, so: for
  ``Delta`` of that sign there are **two** solutions (one per sign of ``d``), for the other
  sign there is **none**.

Under the paper's Assumption 2 with ``f = f1 w1, g = g0`` (condition 3 reads ``f1 - g0 <= g0``)
and ``alpha |d| <= 1``, the gap stays in ``|G| <= (f1 - g0) / alpha <= g0 / alpha``, because
``G(k) - Gb = (G(k-1) - Gb) (1 - alpha d)`` with ``Gb = (f1 - g0) / alpha`` for ``d > 0``
(and the mirror image for ``d < 0``): the inverse is then unique at every sample (strictly
so for ``f1 < 2 g0``). The same relation shows what the stability condition (8) secures:
``|1 - alpha |d|| < 1``, a contraction of the gap towards the branch. The paper's identified
stage (f1 = 0.1354 > 2 g0 = 0.0084) violates Assumption 2, and on its branches
``alpha |G| = f1 - g0 = 0.131 >> g0``: after a reversal of ``w1``, ``w2`` keeps moving the old way
for a while. So ``w2`` can only reverse once the gap has been brought across
``alpha |G| < g0``, which the input must start *before* the reversal of ``w2``.

The rules used here
-------------------
* **near** branch (default): of the solutions, the one with the smallest ``|d|`` (for two
  solutions this is ``sign(d) = sign(Delta)``, the motion along the current branch; it keeps
  ``alpha |d|`` smallest, away from the bound (8)).
* **far** branch (only with preview, :func:`plan_step`): the other solution; it reverses ``w1``
  while ``w2`` still goes on, which drives the gap towards the band ``alpha |G| < g0``. Along an
  exactly tracked ``w2`` the gap is the only free state and each branch is a monotone-by-pieces
  1-D map of it, so the set of gaps from which the coming reversal is reachable *exactly* is a
  union of intervals, propagated backwards through the preview window in closed form. The near
  step is kept whenever it lands in that set (the far branch is entered as late as possible),
  else the far step if it does. The sets are shrunk by a margin (1e-11) so that round-off
  cannot push a plan off its path, and trimmed to the widest intervals when they fragment
  (an inner approximation, so a plan the planner accepts is one it can follow; the ``f0``
  jumps are left out of the planning and any mismatch shows as a non-exact status).
* **bound**: a step with ``alpha |d|`` above ``bound`` (< 2, condition 8) is clipped to it
  (status ``BOUND``); the error is made up in the following samples.
* **unreachable** (no preview, or no plan found): the step moves ``w1`` so that the gap goes to
  zero, the middle of the band where the inverse is unique (status ``UNREACHABLE``), clipped to
  the bound.

Run once a sample over a moving window (the compensator), :func:`plan_memo` keeps what the
previous sample's call found: the near-branch path of the look-ahead (reused whole when the
state is where its first step led, to the last bit) and the backward sets (which depend on the
window and the target sample only). Its results are :func:`plan_step`'s, bit for bit; only the
work changes: from the whole preview every sample to about one step a sample while the stage
follows the plan.

Numba caches compiled functions per file; the callers of these kernels in other modules are
compiled without cache so that they never run a stale copy.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from ..kernels import duhem_w2, sgn

__all__ = [
    "BOUND",
    "EXACT",
    "MEMO_INTERVALS",
    "UNREACHABLE",
    "check_bound",
    "duhem_forward",
    "duhem_gap",
    "duhem_inverse_step",
    "duhem_solutions",
    "plan_memo",
    "plan_step",
    "planner_memo",
]

#: Step statuses (bit flags, combined with ``SATURATED`` by the compensator).
EXACT = 0
BOUND = 1
UNREACHABLE = 2

# a requested change of w2 this small is round-off of the reference path, not a reversal
_ROUND_OFF = 1e-13


@njit(cache=True)
def duhem_gap(w1p, w2p, f0, f1):
    """The gap ``G = f0 sgn(w1p) + f1 w1p - w2p`` of eq. (7)."""
    return f0 * sgn(w1p) + f1 * w1p - w2p


@njit(cache=True)
def duhem_forward(w1, w1p, w2p, alpha, f0, f1, g0):
    """``w2(k)`` from ``w1(k)`` and the state ``w1(k-1), w2(k-1)`` (eq. 7)."""
    return duhem_w2(alpha, f0, f1, g0, w1p, w2p, w1 - w1p)


@njit(cache=True)
def duhem_solutions(w2d, w1p, w2p, alpha, f0, f1, g0):
    """All increments ``d = w1(k) - w1(k-1)`` that give ``w2(k) = w2d`` exactly.

    Returns
    -------
    n : int
        Number of solutions (0, 1 or 2).
    near, far : float
        The solution with the smallest ``|d|`` and, when ``n == 2``, the other one.
    """
    G = duhem_gap(w1p, w2p, f0, f1)
    delta = w2d - w2p
    if abs(delta) <= _ROUND_OFF * (1.0 + abs(w2d)):
        return 1, 0.0, 0.0  # w2 stays (within round-off): d = 0
    s_pos = g0 + alpha * G  # slope of phi for d > 0
    s_neg = g0 - alpha * G  # slope of phi for d < 0
    n = 0
    near = 0.0
    far = 0.0
    if s_pos != 0.0:
        d = delta / s_pos
        if d > 0.0:
            near = d
            n = 1
    if s_neg != 0.0:
        d = delta / s_neg
        if d < 0.0:
            if n == 0:
                near = d
                n = 1
            else:
                n = 2
                if abs(d) < abs(near):
                    far = near
                    near = d
                else:
                    far = d
    return n, near, far


@njit(cache=True)
def _towards_band(w2d, w1p, w2p, alpha, f0, f1, g0, bound):
    """Step for an unreachable ``w2d``: move the gap to zero (unique inverse there)."""
    G = duhem_gap(w1p, w2p, f0, f1)
    direction = sgn(w2d - w2p)
    rate = f1 - g0 + alpha * abs(G)  # |dG/dd| on the side that shrinks |G|
    dmax = bound / alpha
    if rate > 0.0 and G != 0.0:
        d = direction * min(abs(G) / rate, dmax)
    else:
        d = direction * dmax
    return d


@njit(cache=True)
def duhem_inverse_step(w2d, w1p, w2p, alpha, f0, f1, g0, bound):
    """The near-branch inverse of eq. (7) for one sample.

    Returns
    -------
    d : float
        Increment of ``w1``: exact near solution, or the clipped / fallback step.
    status : int
        ``EXACT``, ``BOUND`` (clipped to ``alpha |d| = bound``) or ``UNREACHABLE``.
    """
    n, near, far = duhem_solutions(w2d, w1p, w2p, alpha, f0, f1, g0)
    if n == 0:
        return _towards_band(w2d, w1p, w2p, alpha, f0, f1, g0, bound), UNREACHABLE
    if alpha * abs(near) > bound:
        return sgn(near) * bound / alpha, BOUND
    return near, EXACT


# --------------------------------------------------------------------------- planning
# Along an exactly tracked path w2 = W the only free state is the gap G (eq. 7 with w2 fixed),
# and one step with increment Delta on the branch sigma = sign(d) is the 1-D map
#     x = g0 + sigma alpha G  (the slope of phi on that side),  d = Delta / x,
#     G' = G - Delta + f1 d                                  (f0 jumps ignored in planning)
# valid when sigma Delta x > 0 and |d| <= bound / alpha. Writing G' as a function of x,
#     G'(x) = sigma (x - g0) / alpha - Delta + f1 Delta / x,
#     dG'/dx = sigma / alpha - f1 Delta / x^2,
# which is monotone on at most two pieces (split at x^2 = sigma alpha f1 Delta). The planner
# propagates the set of gaps from which the reversal is reachable backwards through the window
# (a union of intervals: preimages of intervals under monotone pieces, in closed form).

_BIG = 1e30
_K = 32  # most intervals kept per set
_MARGIN = 1e-11  # every set is shrunk by this much: round-off cannot push a plan off its path


@njit(cache=True)
def _gap_map(x, sigma, delta, alpha, f1, g0):
    return sigma * (x - g0) / alpha - delta + f1 * delta / x


@njit(cache=True)
def _solve_piece(c, xa, xb, sigma, delta, alpha, f1, g0):
    """The x in [xa, xb] (one monotone piece) with G'(x) = c: a root of
    sigma x^2 - (sigma g0 + alpha (Delta + c)) x + alpha f1 Delta = 0."""
    a = sigma
    b = -(sigma * g0 + alpha * (delta + c))
    cc = alpha * f1 * delta
    disc = b * b - 4.0 * a * cc
    if disc < 0.0:
        disc = 0.0
    sq = np.sqrt(disc)
    q = -0.5 * (b + sq) if b >= 0.0 else -0.5 * (b - sq)
    r1 = q / a
    r2 = cc / q if q != 0.0 else r1
    best = r1
    lo, hi = min(xa, xb), max(xa, xb)
    e1 = max(lo - r1, r1 - hi, 0.0)
    e2 = max(lo - r2, r2 - hi, 0.0)
    if e2 < e1:
        best = r2
    return min(max(best, lo), hi)


@njit(cache=True)
def _add_interval(lo_out, hi_out, n, lo, hi):
    if hi < lo:
        return n
    if n < lo_out.shape[0]:
        lo_out[n] = lo
        hi_out[n] = hi
        return n + 1
    # full: keep the widest intervals (dropping keeps the set an inner approximation, so a
    # step accepted by the planner is always followed by an exact one)
    narrow = 0
    for i in range(1, n):
        if hi_out[i] - lo_out[i] < hi_out[narrow] - lo_out[narrow]:
            narrow = i
    if hi - lo > hi_out[narrow] - lo_out[narrow]:
        lo_out[narrow] = lo
        hi_out[narrow] = hi
    return n


@njit(cache=True)
def _normalise(lo, hi, n):
    """Sort and merge overlapping intervals in place; returns the new count."""
    for i in range(1, n):
        a, b = lo[i], hi[i]
        j = i - 1
        while j >= 0 and lo[j] > a:
            lo[j + 1] = lo[j]
            hi[j + 1] = hi[j]
            j -= 1
        lo[j + 1] = a
        hi[j + 1] = b
    m = 0
    for i in range(n):
        if m > 0 and lo[i] <= hi[m - 1] + 1e-15 * (1.0 + abs(hi[m - 1])):
            hi[m - 1] = max(hi[m - 1], hi[i])
        else:
            lo[m] = lo[i]
            hi[m] = hi[i]
            m += 1
    return m


@njit(cache=True)
def _preimage(lo, hi, n, delta, alpha, f1, g0, bound, lo_out, hi_out):
    """Gaps G (before a step of increment ``delta``) whose exact step lands in the set."""
    m = 0
    if delta == 0.0:  # d = 0, G' = G
        for i in range(n):
            lo_out[i] = lo[i]
            hi_out[i] = hi[i]
        return n
    xmin = alpha * abs(delta) / bound  # |x| >= xmin: the bound of condition (8)
    for sgm in range(2):
        sigma = 1.0 if sgm == 0 else -1.0
        tau = 1.0 if sigma * delta > 0.0 else -1.0  # sign of x on the valid domain
        # monotone pieces in x (as [start, end] along increasing |x|)
        xs = np.empty(3)
        npieces = 1
        xs[0] = tau * xmin
        if tau > 0.0:
            xc = np.sqrt(alpha * f1 * abs(delta)) if f1 > 0.0 else 0.0
            if xc > xmin:
                xs[1] = xc
                npieces = 2
        xs[npieces] = tau * _BIG
        for p in range(npieces):
            xa, xb = xs[p], xs[p + 1]
            ga = _gap_map(xa, sigma, delta, alpha, f1, g0)
            gb = _gap_map(xb, sigma, delta, alpha, f1, g0)
            glo, ghi = min(ga, gb), max(ga, gb)
            for i in range(n):
                l = max(lo[i], glo)
                h = min(hi[i], ghi)
                if l > h:
                    continue
                x1 = _solve_piece(l, xa, xb, sigma, delta, alpha, f1, g0)
                x2 = _solve_piece(h, xa, xb, sigma, delta, alpha, f1, g0)
                G1 = sigma * (x1 - g0) / alpha
                G2 = sigma * (x2 - g0) / alpha
                m = _add_interval(lo_out, hi_out, m, min(G1, G2) + _MARGIN,
                                  max(G1, G2) - _MARGIN)
    return _normalise(lo_out, hi_out, m)


@njit(cache=True)
def _inside(G, lo, hi, n):
    for i in range(n):
        if lo[i] <= G <= hi[i]:
            return True
    return False


@njit(cache=True)
def _target(delta, alpha, g0, bound, lo, hi):
    """Gaps from which a step of increment ``delta`` has an exact near solution."""
    if delta < 0.0:  # needs g0 - alpha G >= alpha |delta| / bound
        lo[0] = -_BIG
        hi[0] = (g0 - alpha * abs(delta) / bound) / alpha - _MARGIN
    elif delta > 0.0:
        lo[0] = (-g0 + alpha * abs(delta) / bound) / alpha + _MARGIN
        hi[0] = _BIG
    else:
        lo[0] = -_BIG
        hi[0] = _BIG
    return 1 if hi[0] >= lo[0] else 0


#: Intervals per window sample the memo of :func:`planner_memo` has room for, for the sets of the
#: backward pass (a set has a few; once the room is used up, further sets are computed afresh at
#: every sample: the room changes the speed only, never a result).
MEMO_INTERVALS = 8
# planner_memo's integers (sample indices relative to the window of the last call): the ring
# slot of the next call's W[0], whether the key state holds, the last sample the kept
# near-branch path reaches, its first unreachable sample (-1 if none), the target the kept
# sets lead to (-1 if none), how many sets are kept, where the last backward pass stopped early
# (-1 if it did not), how much of the room the kept sets use; then, for each kept set, its
# count of intervals and its place in the room
_M_BASE, _M_KEY, _M_END, _M_J, _M_TARGET, _M_SETS, _M_EXIT, _M_FILL, _M_HEAD = range(9)


@njit(cache=True)
def planner_memo(n):
    """A fresh memo for :func:`plan_memo` over windows of ``n`` samples.

    Parameters
    ----------
    n : int
        Window length (preview + 1).

    Returns
    -------
    mi : ndarray of int64
        Indices and flags, then the counts of intervals and places of the kept sets.
    mf : ndarray of float64
        The key state, the state at the end of the kept path, then the path's gaps (a ring of
        ``n`` samples).
    ms : ndarray of float64
        Two scratch sets (lower then upper ends, 32 intervals each), then the room for the kept
        sets (:data:`MEMO_INTERVALS` intervals per window sample).
    """
    n = max(n, 1)
    mi = np.zeros(_M_HEAD + 2 * n, np.int64)
    mi[_M_J] = -1
    mi[_M_TARGET] = -1
    mi[_M_EXIT] = -1
    mf = np.zeros(4 + n)
    ms = np.zeros(4 * _K + 2 * MEMO_INTERVALS * n)
    return mi, mf, ms


@njit(cache=True)
def plan_memo(W, w1p, w2p, alpha, f0, f1, g0, bound, mi, mf, ms):
    """:func:`plan_step`, reusing what the previous sample's call found (same results, bit for bit).

    ``mi, mf, ms`` come from :func:`planner_memo` and are updated in place; each call must see
    the window of the previous call moved on by one sample (``W[0]`` now was ``W[1]`` then, the
    same values, the same length). What is kept, all of it exact:

    * the near-branch path of the look-ahead scan. When the state ``w1p, w2p`` is the one that
      path reached after its first step (the near step was taken and the internal model landed
      on it to the last bit), the new scan is the old one less its first sample: only the new
      last sample of the window is simulated (none when the old scan had stopped at an
      unreachable sample). The backward pass then stops where it stopped before, if that is
      still ahead: its answer is the same (near step) without running it again;
    * the sets of the backward pass. They depend on the window's values and on the target
      sample (the first unreachable one) only, not on the state: while the target stays, each
      set is computed once (as many as the room holds, :data:`MEMO_INTERVALS`).

    Parameters
    ----------
    W, w1p, w2p, alpha, f0, f1, g0, bound
        As for :func:`plan_step`.
    mi, mf, ms : ndarray
        The memo (:func:`planner_memo`).

    Returns
    -------
    d : float
        Increment of ``w1``.
    status : int
        ``EXACT``, ``BOUND`` or ``UNREACHABLE``.
    far : bool
        Whether the far branch was taken.
    """
    n = W.shape[0]
    base = mi[_M_BASE]  # ring slot of W[0]
    mi[_M_BASE] = base + 1 if base + 1 < n else 0
    if mi[_M_TARGET] >= 0:
        mi[_M_TARGET] -= 1
    stop = mi[_M_EXIT]
    mi[_M_EXIT] = -1
    d0, st0 = duhem_inverse_step(W[0], w1p, w2p, alpha, f0, f1, g0, bound)
    if st0 == UNREACHABLE or n < 3:
        mi[_M_KEY] = 0
        return d0, st0, False
    w1a = w1p + d0
    w2a = duhem_forward(w1a, w1p, w2p, alpha, f0, f1, g0)
    gaps = mf[4:4 + n]  # gaps[(base + i) % n]: the near-branch path's gap before W[i]
    same = mi[_M_KEY] == 1 and w1p == mf[0] and w2p == mf[1]
    if same:
        # the state is where the kept path went after its first step: it goes on alike
        j = mi[_M_J]
        if j >= 0:
            j -= 1
        i = mi[_M_END] - 1
        a1 = mf[2]
        a2 = mf[3]
    else:
        j = -1
        i = 0
        a1 = w1a
        a2 = w2a
    if j < 0:  # the near-branch path from a1, a2 on, up to the end of the window
        while i < n - 1:
            i += 1
            slot = base + i
            if slot >= n:
                slot -= n
            gaps[slot] = duhem_gap(a1, a2, f0, f1)
            d, st = duhem_inverse_step(W[i], a1, a2, alpha, f0, f1, g0, bound)
            if st == UNREACHABLE:
                j = i
                break
            w1 = a1 + d
            a2 = duhem_forward(w1, a1, a2, alpha, f0, f1, g0)
            a1 = w1
    mi[_M_KEY] = 1
    mf[0] = w1a
    mf[1] = w2a
    mi[_M_END] = i
    mi[_M_J] = j
    mf[2] = a1
    mf[3] = a2
    if j < 0:
        return d0, st0, False
    if same and stop >= 2:
        # the same path, target and sets: the pass below would stop at W[stop - 1] again (at
        # W[1], the gap there is the near step's, the final test passes alike)
        if stop > 2:
            mi[_M_EXIT] = stop - 1
        return d0, st0, False
    # backward from the target j: the gaps before W[i] from which W[j] is reachable exactly
    if mi[_M_TARGET] != j:
        mi[_M_TARGET] = j
        mi[_M_SETS] = 0
        mi[_M_FILL] = 0
    kept = mi[_M_SETS]
    fill = mi[_M_FILL]
    count = mi[_M_HEAD:_M_HEAD + n]
    place = mi[_M_HEAD + n:_M_HEAD + 2 * n]
    room = ms[4 * _K:]
    scratch = 0
    if kept == 0:
        m = _target(W[j] - W[j - 1], alpha, g0, bound, ms[0:_K], ms[_K:2 * _K])
        lo = ms[0:_K]
        hi = ms[_K:2 * _K]
        scratch = 1
        if 2 * m <= room.shape[0]:
            room[0:m] = lo[:m]
            room[m:2 * m] = hi[:m]
            count[0] = m
            place[0] = 0
            lo = room[0:m]
            hi = room[m:2 * m]
            fill = 2 * m
            kept = 1
    else:
        m = count[0]
        lo = room[place[0]:place[0] + m]
        hi = room[place[0] + m:place[0] + 2 * m]
    i = j
    r = 0  # sets kept: r = j - i
    while True:
        if m == 0:  # no exact plan: keep going, the reversal will be approximate
            break
        if i > 1:
            slot = base + i
            if slot >= n:
                slot -= n
            if _inside(gaps[slot], lo, hi, m):
                break  # the near-branch path reaches the set by itself: waiting is safe
        else:
            mi[_M_SETS] = kept
            mi[_M_FILL] = fill
            # gap after the near step, relative to W[0]
            if _inside(duhem_gap(w1a, w2a, f0, f1), lo, hi, m):
                return d0, st0, False
            n_sol, near, far = duhem_solutions(W[0], w1p, w2p, alpha, f0, f1, g0)
            if n_sol == 2 and alpha * abs(far) <= bound:
                w1f = w1p + far
                w2f = duhem_forward(w1f, w1p, w2p, alpha, f0, f1, g0)
                if _inside(duhem_gap(w1f, w2f, f0, f1), lo, hi, m):
                    return far, EXACT, True
            return d0, st0, False
        i -= 1
        r += 1
        if r < kept:
            m = count[r]
            lo = room[place[r]:place[r] + m]
            hi = room[place[r] + m:place[r] + 2 * m]
            continue
        out_lo = ms[2 * scratch * _K:(2 * scratch + 1) * _K]
        out_hi = ms[(2 * scratch + 1) * _K:(2 * scratch + 2) * _K]
        scratch = 1 - scratch
        m = _preimage(lo, hi, m, W[i] - W[i - 1], alpha, f1, g0, bound, out_lo, out_hi)
        if r == kept and fill + 2 * m <= room.shape[0]:
            room[fill:fill + m] = out_lo[:m]
            room[fill + m:fill + 2 * m] = out_hi[:m]
            count[r] = m
            place[r] = fill
            lo = room[fill:fill + m]
            hi = room[fill + m:fill + 2 * m]
            fill += 2 * m
            kept = r + 1
        else:
            lo = out_lo
            hi = out_hi
    if i >= 2:
        mi[_M_EXIT] = i
    mi[_M_SETS] = kept
    mi[_M_FILL] = fill
    return d0, st0, False


@njit(cache=True)
def plan_step(W, w1p, w2p, alpha, f0, f1, g0, bound):
    """Inverse of eq. (7) for the first sample of the window ``W``, with preview of the rest.

    The near branch is taken unless the near-branch path runs, within the window, into a
    sample it cannot reach (a reversal of ``w2`` while the gap is on the wrong side). Then the
    set of gaps from which that sample is reachable exactly is propagated backwards to the next
    sample, and the near step is kept if it lands in the set (so the far branch is entered as
    late as possible); otherwise the far step is taken if it lands in the set. Run once per
    sample over a moving window, :func:`plan_memo` gives the same results for less work.

    Parameters
    ----------
    W : ndarray
        Desired ``w2`` from the current sample on (``W[0]`` is the target now); length 1 means
        no preview.
    w1p, w2p : float
        State ``w1(k-1), w2(k-1)``.
    alpha, f0, f1, g0 : float
        Duhem coefficients.
    bound : float
        Largest ``alpha |d|`` allowed (below 2, condition 8).

    Returns
    -------
    d : float
        Increment of ``w1``.
    status : int
        ``EXACT``, ``BOUND`` or ``UNREACHABLE``.
    far : bool
        Whether the far branch was taken.
    """
    mi, mf, ms = planner_memo(W.shape[0])
    return plan_memo(W, w1p, w2p, alpha, f0, f1, g0, bound, mi, mf, ms)


def check_bound(bound: float) -> float:
    """Validate the step bound ``alpha |dw1| <= bound`` (condition 8 needs ``0 < bound < 2``).

    Parameters
    ----------
    bound : float
        The largest ``alpha |dw1|`` per sample asked for.

    Returns
    -------
    float
        ``bound`` as a float.

    Raises
    ------
    ValueError
        When ``bound`` is not in (0, 2).
    """
    bound = float(bound)
    if not (np.isfinite(bound) and 0.0 < bound < 2.0):
        raise ValueError(
            f"duhem_bound: expected 0 < bound < 2 (stability condition 8, alpha |dw1| < 2), "
            f"got {bound!r}"
        )
    return bound
