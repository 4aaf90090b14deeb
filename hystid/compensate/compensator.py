"""The inverse sandwich: a reference for ``y`` becomes an amplifier voltage ``u``.

The compensator runs the sandwich backwards, one sample at a time::

    y_ref --M--> y_M --L2^-1--> w2d --H^-1 (planned)--> w1c --L1^-1--> u_cmd --sat--> u

* ``M`` is the *reference model*: ``None`` inverts L2 through its static gain only
  (``w2d = y_ref / L2(1)``), ``"exact"`` inverts L2 whole (``y = y_ref``), and a discrete
  transfer function asks for ``y = M y_ref``. L2 is minimum phase (Assumption 1), so its
  inverse is stable.
* ``H^-1`` is the per-sample inverse of eq. (7) with the reversal planner of
  :mod:`~hystid.compensate.duhem_inverse` (or the exact inverse Prandtl-Ishlinskii operator for a
  :class:`~hystid.pi.PISandwich`, or the per-sample inverse of the generalised Duhem block or of
  the parallel Duhem operators of a :class:`~hystid.mduhem.MultiDuhemSandwich`, without
  look-ahead, :mod:`~hystid.compensate.member_inverse`, or the anhysteretic line
  ``w1 = w2 / f1`` for the uncompensated baseline).
* ``L1^-1``: ``u(k) = w1(k+q1) - sum b1j u(k-j) + sum a1i w1(k+q1-i)`` (divided by the
  leading numerator coefficient for the PI sandwich), stable because L1 is minimum phase
  (Assumption 1).

Preview. ``u(k)`` acts on ``y`` at ``k + q`` at the earliest (``q = q1 + q2``: the delays of L1
and L2), and the reversal planner looks ``P`` samples further ahead. The compensator therefore
reads the reference *advanced* by ``q + P`` samples: its input is ``r(k) = y_ref(k + q + P)``
(see :attr:`HysteresisInverse.advance`) and its output ``yd(k) = (M y_ref)(k)`` is the desired
output aligned with the stage's ``y(k)``, for a feedback loop. A reference model with a delay
(a linear-phase smoother) takes that delay from the preview as well (``reference_lead``), so
``yd`` has no lag.

No windup. The compensator keeps its own copy of L1 and of the hysteresis block and drives it
with the *saturated* command it actually applies. After a saturated stretch the hysteresis
state is where the real actuator is, so the next samples steer from there (no stale memory, no
integrating state). The reference path (``M``, ``L2^-1``) only depends on the reference.

State layout (flat vector, the python-control system's states)::

    [x_M | y_M line | w2d line | past u | past w1 | hysteresis state]

with the hysteresis state ``w2(k+q1-1)`` for the Duhem block (plain or generalised), the
operators' states ``w2_j(k+q1-1)`` for the parallel Duhem operators or the play-operator states
``p_i`` for the PI block. The Duhem planner's memo
(:func:`~hystid.compensate.duhem_inverse.plan_memo`: the previous sample's look-ahead, reused
while the state follows it) is not part of the state: it saves work and changes no result, and
a run starts it fresh.
"""

from __future__ import annotations

import hashlib
import inspect
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Literal

import control as ct
import numpy as np
from numba import njit
from numba.core.dispatcher import Dispatcher

from ..model import DuhemSandwich
from ..pi_operator import play
from ..signals import finite_signal
from .duhem_inverse import check_bound, duhem_forward, plan_memo, planner_memo
from .linear_parts import (
    _linear_parts,
    _min_phase,
    _pi_parts,
    _reference_model,
    dc_delay,
    hysteresis_gain,
    smoothing_model,
)
from .member_inverse import (
    gduhem_forward,
    gduhem_inverse_step,
    mduhem_forward,
    mduhem_inverse_step,
    pi_poly_inverse,
)

if TYPE_CHECKING:  # pragma: no cover
    from ..pi import PISandwich

__all__ = [
    "COMPENSATIONS",
    "DEFAULT_PREVIEW",
    "DUHEM_BOUND",
    "NOT_EXACT",
    "SATURATED",
    "TURNING",
    "Feedforward",
    "feedforward",
    "dc_delay",
    "hysteresis_gain",
    "linear_feedforward",
    "smoothing_model",
]

#: Samples of preview the reversal planner uses by default (10 ms at 30 kHz).
DEFAULT_PREVIEW = 300
#: Longest planner preview accepted, in seconds (the planner's buffers grow with it).
MAX_PREVIEW_SECONDS = 0.1
#: Default largest ``alpha |dw1|`` per sample (condition 8 needs it below 2).
DUHEM_BOUND = 1.5
#: Status flag: the command was clipped to the input limits.
SATURATED = 4
#: Status flag (not an error): the compensator is turning the hysteresis round (a far-branch
#: step: ``w1`` already reverses while ``w2`` still goes on), so the stage's incremental gain is
#: far from the branch slope (small, or of the other sign); a feedback integrator holds then.
TURNING = 8
#: Status bits that mean the sample was not exact.
NOT_EXACT = 1 | 2 | 4

KIND_DUHEM, KIND_PI, KIND_LINEAR, KIND_NONE, KIND_GDUHEM, KIND_MDUHEM = 0, 1, 2, 3, 4, 5
#: ``compensation`` names accepted by :func:`inverse` and the closed-loop helpers.
COMPENSATIONS = {"inverse": KIND_DUHEM, "linear": KIND_LINEAR, "none": KIND_NONE}

# ispec indices
(_KIND, _N1A, _N1B, _Q1, _N2A, _N2B, _Q2, _NM, _L2MODE, _P, _LY, _LW, _NPI,
 _OFF_M, _OFF_Y, _OFF_W, _OFF_U, _OFF_W1, _OFF_H, _NX, _H1, _Q) = range(22)
# fpar indices
(_ALPHA, _F0, _F1, _G0, _BOUND, _UMIN, _UMAX, _B1LEAD, _B2LEAD, _K2, _KH) = range(11)
# the members' hysteresis parameters follow: the generalised block's theta after fpar[_NF]
# (its layout after ispec[_NI]); the parallel operators' rates, f1_j, g0_j (ispec[_NPI] of each)
_NI, _NF = 22, 11


# =========================================================================== compiled chain
@njit(cache=True)
def _push_reference(x, r, ispec, fpar, a2, b2t, AM, BM, CM, DM):
    """Feed one reference sample through ``M`` and ``L2^-1`` into the lines (in place)."""
    nM, LY, LW = ispec[_NM], ispec[_LY], ispec[_LW]
    oM, oY, oW = ispec[_OFF_M], ispec[_OFF_Y], ispec[_OFF_W]
    # reference model M (state space); y_M = r when there is none
    if nM > 0:
        ym = DM * r
        for i in range(nM):
            ym += CM[i] * x[oM + i]
        xm_new = np.empty(nM)
        for i in range(nM):
            acc = BM[i] * r
            for j in range(nM):
                acc += AM[i, j] * x[oM + j]
            xm_new[i] = acc
        for i in range(nM):
            x[oM + i] = xm_new[i]
    else:
        ym = r
    for i in range(LY - 1):
        x[oY + i] = x[oY + i + 1]
    x[oY + LY - 1] = ym
    # L2^-1 (eq. 2 solved for w2(t), t = newest y_M time - q2)
    if ispec[_L2MODE] == 0:
        w2 = ym / fpar[_K2]
    else:
        w2 = ym
        for i in range(1, ispec[_N2A] + 1):
            w2 += a2[i - 1] * x[oY + LY - 1 - i]
        for j in range(1, ispec[_N2B] + 1):
            w2 -= b2t[j - 1] * x[oW + LW - j]
        w2 /= fpar[_B2LEAD]
    for i in range(LW - 1):
        x[oW + i] = x[oW + i + 1]
    x[oW + LW - 1] = w2


def source_stamp(*kernels: Dispatcher) -> int:
    """A number that changes whenever the source of ``kernels``, or of a kernel they call, does.

    numba's cache checks the source file of the cached function only. A cached kernel that
    calls kernels of other modules closes over this stamp instead (the values it closes over
    are part of numba's cache key), so editing any kernel it reaches compiles it afresh.

    Parameters
    ----------
    *kernels : numba dispatcher
        The compiled functions called across modules; the kernels they call are followed.

    Returns
    -------
    int
        A hash of the source files of every kernel reached (56 bits).
    """
    files: set[str] = set()
    todo = [k.py_func for k in kernels]
    seen: set[object] = set()
    while todo:
        func = todo.pop()
        if func in seen:
            continue
        seen.add(func)
        files.add(inspect.getfile(func))
        todo += [obj.py_func for name in func.__code__.co_names
                 if isinstance(obj := func.__globals__.get(name), Dispatcher)]
    digest = hashlib.sha256()
    for path in sorted(files):
        digest.update(Path(path).read_bytes())
    return int.from_bytes(digest.digest()[:7], "little")


def _stamped_chain_step(stamp: int) -> Dispatcher:
    """:func:`chain_step` compiled with the source ``stamp`` of the kernels it calls."""

    @njit(cache=True)
    def chain_step(x, r, ispec, fpar, a1, b1t, a2, b2t, AM, BM, CM, DM, r_pi, mu_pi, r_inv,
                   mu_inv, mi, mf, ms):
        """One sample of the compensator: returns ``(x_next, u, yd, status)`` (``x`` untouched).

        ``mi, mf, ms``: the reversal planner's memo (:func:`~hystid.compensate.duhem_inverse.
        planner_memo`), updated in place; fresh, or the one of the call for the previous sample
        (``x`` then the state that call returned). It changes the work done, not the result.
        """
        _ = stamp  # in numba's cache key: see source_stamp
        xn = x.copy()
        _push_reference(xn, r, ispec, fpar, a2, b2t, AM, BM, CM, DM)
        kind, P, LY, LW = ispec[_KIND], ispec[_P], ispec[_LY], ispec[_LW]
        oW, oU, oW1 = ispec[_OFF_W], ispec[_OFF_U], ispec[_OFF_W1]
        oH, H1 = ispec[_OFF_H], ispec[_H1]
        n1a, n1b = ispec[_N1A], ispec[_N1B]
        yd = xn[ispec[_OFF_Y] + LY - 1 - (ispec[_Q] + P)]
        if kind == KIND_NONE:  # reference path only (a feedback loop without feed-forward)
            return xn, 0.0, yd, 0
        window = xn[oW + LW - 1 - P : oW + LW]  # w2d(k+q1) .. w2d(k+q1+P)
        w2d = window[0]
        w1p = xn[oW1 + H1 - 1]  # w1(k+q1-1) of the internal model
        status = 0
        alpha, f0, f1, g0 = fpar[_ALPHA], fpar[_F0], fpar[_F1], fpar[_G0]
        # hysteresis inverse -> w1c = w1(k+q1)
        if kind == KIND_DUHEM:
            d, status, far = plan_memo(window, w1p, xn[oH], alpha, f0, f1, g0, fpar[_BOUND],
                                       mi, mf, ms)
            if far:
                status |= 8
            w1c = w1p + d
        elif kind == KIND_GDUHEM:
            d, status = gduhem_inverse_step(w2d, w1p, xn[oH], fpar[_NF:], ispec[_NI:],
                                            fpar[_BOUND])
            w1c = w1p + d
        elif kind == KIND_MDUHEM:
            m = ispec[_NPI]
            d, status = mduhem_inverse_step(w2d, w1p, xn[oH:oH + m], fpar[_NF:_NF + m],
                                            fpar[_NF + m:_NF + 2 * m],
                                            fpar[_NF + 2 * m:_NF + 3 * m], fpar[_BOUND])
            w1c = w1p + d
        elif kind == KIND_PI and ispec.shape[0] > _NI:  # polynomial terms: no inverse PI
            n = ispec[_NPI]
            w1c, status = pi_poly_inverse(w2d, w1p, xn[oH:oH + n], r_pi, mu_pi,
                                          fpar[_NF:_NF + ispec[_NI]])
        elif kind == KIND_PI:
            n = ispec[_NPI]
            # inverse-operator states matching the forward states p (pi_inverse_state)
            tail = 0.0
            pinv = np.empty(n)
            for i in range(n - 1, -1, -1):
                pinv[i] = tail
                tail += mu_pi[i] * xn[oH + i]
            cum = 0.0
            for i in range(n):
                cum += mu_pi[i]
                pinv[i] += cum * xn[oH + i]
            w1c = 0.0
            for i in range(n):
                w1c += mu_inv[i] * play(w2d, pinv[i], r_inv[i])
        else:
            w1c = w2d / fpar[_KH]
        # L1^-1 (eq. 1 solved for u(k))
        u = w1c
        for j in range(1, n1b + 1):
            u -= b1t[j - 1] * xn[oU + n1b - j]
        for i in range(1, n1a + 1):
            u += a1[i - 1] * xn[oW1 + H1 - i]
        u /= fpar[_B1LEAD]
        if u > fpar[_UMAX]:
            u = fpar[_UMAX]
            status |= 4
        elif u < fpar[_UMIN]:
            u = fpar[_UMIN]
            status |= 4
        # internal model driven by the applied (saturated) command: no windup
        w1 = fpar[_B1LEAD] * u
        for j in range(1, n1b + 1):
            w1 += b1t[j - 1] * xn[oU + n1b - j]
        for i in range(1, n1a + 1):
            w1 -= a1[i - 1] * xn[oW1 + H1 - i]
        if kind == KIND_DUHEM:
            xn[oH] = duhem_forward(w1, w1p, xn[oH], alpha, f0, f1, g0)
        elif kind == KIND_GDUHEM:
            xn[oH] = gduhem_forward(fpar[_NF:], ispec[_NI:], w1, w1p, xn[oH])
        elif kind == KIND_MDUHEM:
            m = ispec[_NPI]
            mduhem_forward(xn[oH:oH + m], w1, w1p, fpar[_NF:_NF + m], fpar[_NF + m:_NF + 2 * m],
                           fpar[_NF + 2 * m:_NF + 3 * m])
        elif kind == KIND_PI:
            for i in range(ispec[_NPI]):
                xn[oH + i] = play(w1, xn[oH + i], r_pi[i])
        for i in range(H1 - 1):
            xn[oW1 + i] = xn[oW1 + i + 1]
        xn[oW1 + H1 - 1] = w1
        for i in range(n1b - 1):
            xn[oU + i] = xn[oU + i + 1]
        if n1b > 0:
            xn[oU + n1b - 1] = u
        return xn, u, yd, status

    return chain_step


chain_step = _stamped_chain_step(source_stamp(plan_memo, duhem_forward, play, gduhem_inverse_step,
                                              gduhem_forward, mduhem_inverse_step,
                                              mduhem_forward, pi_poly_inverse))


@njit(cache=True)
def chain_prime(x, rs, ispec, fpar, a2, b2t, AM, BM, CM, DM):
    """Push the first ``q + P`` reference samples (in place), the plant still at rest."""
    for k in range(rs.shape[0]):
        _push_reference(x, rs[k], ispec, fpar, a2, b2t, AM, BM, CM, DM)


def _stamped_chain_run(stamp: int) -> Dispatcher:
    """:func:`chain_run` compiled with the source ``stamp`` of the kernels it calls."""

    @njit(cache=True)
    def chain_run(x, rs, ispec, fpar, a1, b1t, a2, b2t, AM, BM, CM, DM, r_pi, mu_pi, r_inv,
                  mu_inv, u, yd, status):
        """Run :func:`chain_step` over the advanced reference ``rs``; returns the final state."""
        _ = stamp  # in numba's cache key: see source_stamp
        mi, mf, ms = planner_memo(ispec[_P] + 1)
        for k in range(rs.shape[0]):
            x, u[k], yd[k], status[k] = chain_step(x, rs[k], ispec, fpar, a1, b1t, a2, b2t, AM,
                                                   BM, CM, DM, r_pi, mu_pi, r_inv, mu_inv, mi,
                                                   mf, ms)
        return x

    return chain_run


chain_run = _stamped_chain_run(source_stamp(chain_step, planner_memo))


# =========================================================================== configuration
@dataclass(frozen=True)
class _Chain:
    """Arrays the compiled chain takes, and the state names."""

    ispec: np.ndarray
    fpar: np.ndarray
    a1: np.ndarray
    b1t: np.ndarray
    a2: np.ndarray
    b2t: np.ndarray
    AM: np.ndarray
    BM: np.ndarray
    CM: np.ndarray
    DM: float
    r_pi: np.ndarray
    mu_pi: np.ndarray
    r_inv: np.ndarray
    mu_inv: np.ndarray
    states: tuple[str, ...]
    lead: int = 0

    @property
    def delay(self) -> int:
        """``q = q1 + q2``: samples from ``u`` to ``y``."""
        return int(self.ispec[_Q])

    @property
    def preview(self) -> int:
        """Planner preview ``P`` in samples."""
        return int(self.ispec[_P])

    @property
    def advance(self) -> int:
        """Samples the input reference is ahead of ``y``: ``q + P + lead``."""
        return self.delay + self.preview + self.lead

    def args(self):
        return (self.ispec, self.fpar, self.a1, self.b1t, self.a2, self.b2t, self.AM, self.BM,
                self.CM, self.DM, self.r_pi, self.mu_pi, self.r_inv, self.mu_inv)

    def prime_args(self):
        return (self.ispec, self.fpar, self.a2, self.b2t, self.AM, self.BM, self.CM, self.DM)

    def initial_state(self, y_ref: np.ndarray | None = None, rest: float = 0.0,
                      plays: np.ndarray | None = None) -> np.ndarray:
        """At rest (the hysteresis block's output at ``rest``, ``w1 = 0``), primed on ``y_ref``.

        ``rest`` is only meaningful with L2 left out (``l2_identity``): the reference lines
        then hold ``w2`` and start settled at ``rest``, like the Duhem state; a PI block's
        plays then start at ``plays`` (:attr:`hystid.pi.PISandwich.rest_plays`).
        """
        x = np.zeros(int(self.ispec[_NX]))
        pi = plays is not None and len(plays) > 0
        if rest or pi:
            kinds = (KIND_PI,) if pi else (KIND_DUHEM, KIND_GDUHEM)
            if self.ispec[_KIND] not in kinds or self.ispec[_NM] \
                    or self.ispec[_N2A] or self.ispec[_N2B] or self.ispec[_Q2]:
                raise ValueError("rest: a remembered hysteresis state needs the Duhem or PI "
                                 "inverse with L2 left out of the chain")
            x[self.ispec[_OFF_Y]:self.ispec[_OFF_U]] = rest  # y_M and w2d lines; u, w1: 0
            if pi:
                x[self.ispec[_OFF_H]:self.ispec[_OFF_H] + len(plays)] = plays
            else:
                x[self.ispec[_OFF_H]] = rest
        if y_ref is not None:
            head = _pad_hold(np.asarray(y_ref, float), self.advance)[: self.advance]
            chain_prime(x, np.ascontiguousarray(head), *self.prime_args())
        return x


def _build(model, *, kind: int, u_limits, reference_model, preview, duhem_bound,
           reference_lead: int | None = None, l2_identity: bool = False) -> _Chain:
    if not hasattr(model, "structure") or not hasattr(model, "L1"):
        raise ValueError(f"model: expected a DuhemSandwich, MultiDuhemSandwich or PISandwich, "
                         f"got {model!r}")
    umin, umax = (float(v) for v in u_limits)
    if not (np.isfinite(umin) and np.isfinite(umax) and umin < umax):
        raise ValueError(f"u_limits: expected (low, high) with low < high, got {u_limits!r}")
    duhem = isinstance(model, DuhemSandwich)
    multi = getattr(type(model), "kind", None) == "mduhem"
    if kind == KIND_DUHEM:  # "inverse": the member's own hysteresis inverse
        if multi:
            kind = KIND_MDUHEM
        elif not duhem:
            kind = KIND_PI
        elif not model.structure.is_plain:
            kind = KIND_GDUHEM
    if kind in (KIND_DUHEM, KIND_GDUHEM) and not model.params["alpha"] > 0:
        raise ValueError(f"model: alpha must be positive, got {model.params['alpha']!r}")
    if kind == KIND_GDUHEM and not abs(model.params.get("ad", 0.0)) < 1:
        raise ValueError(f"model: expected |ad| < 1 (a positive rate on both directions), got "
                         f"{model.params['ad']!r}")
    bound = check_bound(duhem_bound)
    if kind in (KIND_GDUHEM, KIND_MDUHEM) and preview:
        member = "multi-Duhem sandwich (mduhem)" if multi else "generalised Duhem block (gduhem)"
        raise ValueError(f"preview: the {member} is inverted without look-ahead (the reversal "
                         f"planner is the plain Duhem block's); expected 0 or None, got "
                         f"{preview!r}")
    if kind in (KIND_LINEAR, KIND_NONE):
        preview = 0  # nothing to plan
    elif preview is None:
        preview = DEFAULT_PREVIEW if kind == KIND_DUHEM else 0
    longest = max(DEFAULT_PREVIEW, int(MAX_PREVIEW_SECONDS * model.fs))
    if (isinstance(preview, bool) or not isinstance(preview, int | float | np.integer | np.floating)
            or not np.isfinite(preview) or int(preview) != preview or not 0 <= preview <= longest):
        raise ValueError(f"preview: expected a whole number of samples in 0..{longest} "
                         f"({MAX_PREVIEW_SECONDS:g} s at {model.fs:g} Hz), got {preview!r}")
    P = int(preview)
    if reference_lead is None:
        reference_lead = dc_delay(reference_model)
    if int(reference_lead) != reference_lead or reference_lead < 0:
        raise ValueError(
            f"reference_lead: expected a non-negative number of samples, got {reference_lead!r}"
        )
    if reference_lead and (reference_model is None or isinstance(reference_model, str)):
        raise ValueError("reference_lead: only meaningful with a reference model M (its delay)")
    a1, b1lead, b1t, q1, a2, b2lead, b2t, q2 = _linear_parts(model)
    if l2_identity:  # L2 inverted outside the chain: its reference is w2 itself
        a2, b2lead, b2t, q2 = np.zeros(0), 1.0, np.zeros(0), 0
    _min_phase(np.r_[b1lead, b1t], "L1")
    l2mode, AM, BM, CM, DM = _reference_model(reference_model, model.dt)
    if l2mode == 1:
        _min_phase(np.r_[b2lead, b2t], "L2")
    k2 = float((b2lead + np.sum(b2t)) / (1.0 + np.sum(a2)))
    if not (np.isfinite(k2) and k2 != 0):
        raise ValueError(f"model: L2 has no finite non-zero static gain ({k2!r})")
    kh = hysteresis_gain(model)
    if kind == KIND_LINEAR and not (np.isfinite(kh) and kh != 0):
        raise ValueError(f"model: the hysteresis block's central slope is {kh!r}")
    q = q1 + q2
    nM = AM.shape[0]
    LY = max(q + P + 1, len(a2) + 1)
    LW = max(P + 1, len(b2t) + 1)
    H1 = max(len(a1), 1)
    r_pi = mu_pi = r_inv = mu_inv = np.zeros(0)
    n_ops = 0  # play operators, or parallel Duhem operators
    ipar: np.ndarray = np.zeros(0, np.int64)
    hpar: np.ndarray = np.zeros(0)
    if kind == KIND_PI:
        r_pi, mu_pi, r_inv, mu_inv = _pi_parts(model)
        n_ops = len(r_pi)
        if len(model.poly):  # inverted sample by sample (pi_poly_inverse)
            ipar, hpar = np.array([len(model.poly)], np.int64), model.poly
        hyst_states = tuple(f"p{i}" for i in range(n_ops))
    elif kind == KIND_MDUHEM:
        n_ops = model.structure.n_operators
        hpar = np.concatenate([model.rates, model.f1, model.g0])
        hyst_states = tuple(f"w2_model{j}" for j in range(n_ops))
    elif kind == KIND_GDUHEM:
        ipar, hpar = model.structure.layout, model.theta
        hyst_states = ("w2_model",)
    else:
        hyst_states = ("w2_model",) if kind == KIND_DUHEM else ()
    states = (
        tuple(f"xM{i}" for i in range(nM))
        + tuple(f"yM{i}" for i in range(LY))
        + tuple(f"w2d{i}" for i in range(LW))
        + tuple(f"u_past{j}" for j in range(len(b1t), 0, -1))
        + tuple(f"w1_model{i}" for i in range(H1, 0, -1))
        + hyst_states
    )
    offs = np.cumsum([0, nM, LY, LW, len(b1t), H1, len(hyst_states)])
    ispec = np.array(
        [kind, len(a1), len(b1t), q1, len(a2), len(b2t), q2, nM, l2mode, P, LY, LW, n_ops,
         offs[0], offs[1], offs[2], offs[3], offs[4], offs[5], offs[6], H1, q, *ipar],
        dtype=np.int64,
    )
    p = model.params if duhem else {}
    fpar = np.array([
        p.get("alpha", 1.0), p.get("f0", 0.0), p.get("f1", 0.0), p.get("g0", 0.0), bound,
        umin, umax, b1lead, b2lead, k2, kh, *hpar,
    ])
    f = np.ascontiguousarray
    return _Chain(ispec, fpar, f(a1, float), f(b1t, float), f(a2, float), f(b2t, float),
                  f(AM.reshape(nM, nM)), f(BM), f(CM), float(DM), f(r_pi), f(mu_pi), f(r_inv),
                  f(mu_inv), states, int(reference_lead))


def _pad_hold(y: np.ndarray, n: int) -> np.ndarray:
    """``y`` followed by ``n`` copies of its last value."""
    return np.concatenate([y, np.full(n, y[-1])]) if n else y


def _as_reference(y_ref, name: str = "y_ref") -> np.ndarray:
    return finite_signal(y_ref, name, min_size=1)


# =========================================================================== python-control
def _functions(chain: _Chain):
    args = chain.args()

    n = int(chain.ispec[_P]) + 1

    # python-control may call these with any state: a fresh planner memo every time
    def update(t, x, u, params):
        xn, _, _, _ = chain_step(np.asarray(x, float), float(u[0]), *args, *planner_memo(n))
        return xn

    def output(t, x, u, params):
        _, uc, yd, status = chain_step(np.asarray(x, float), float(u[0]), *args,
                                       *planner_memo(n))
        return np.array([uc, yd, float(status)])

    return update, output


# =========================================================================== fast path
@dataclass
class Feedforward:
    """Feed-forward commands for a reference. Unpacks as ``u, yd``.

    Attributes
    ----------
    u : ndarray
        Command, one value per reference sample.
    yd : ndarray
        Desired output aligned with ``y`` (``M y_ref``, or ``y_ref`` itself).
    status : ndarray
        Per-sample status flags: 1 clipped to the bound of condition 8; 2 no exact step;
        4 saturated (see :attr:`exact`); 8 turning the hysteresis round (:data:`TURNING`).
    preview, delay : int
        Planner preview and ``q1 + q2``.
    """

    u: np.ndarray
    yd: np.ndarray
    status: np.ndarray
    preview: int
    delay: int

    def __iter__(self):
        yield self.u
        yield self.yd

    @property
    def exact(self) -> np.ndarray:
        """Samples where the inverse step was exact and unsaturated."""
        return (self.status & NOT_EXACT) == 0


def _run(chain: _Chain, y_ref: np.ndarray, n: int | None = None,
         rest: float = 0.0, plays: np.ndarray | None = None) -> Feedforward:
    """Run the chain over ``y_ref`` (``n`` samples; ``y_ref`` may run further, for the preview)
    from rest (the hysteresis block's output ``rest``, a PI block's ``plays``)."""
    n = len(y_ref) if n is None else n
    x = chain.initial_state(y_ref, rest, plays)
    rs = _pad_hold(y_ref, chain.advance)[chain.advance:chain.advance + n]
    u, yd, status = np.empty(n), np.empty(n), np.empty(n, dtype=np.int64)
    chain_run(x, np.ascontiguousarray(rs), *chain.args(), u, yd, status)
    return Feedforward(u, yd, status, chain.preview, chain.delay)


def feedforward(
    model: DuhemSandwich | PISandwich,
    y_ref: np.ndarray | Sequence[float],
    *,
    u_limits: tuple[float, float] = (0.0, 10.0),
    reference_model: ct.LTI | Literal["exact"] | None = None,
    reference_lead: int | None = None,
    preview: int | None = None,
    duhem_bound: float = DUHEM_BOUND,
    full_output: bool = False,
) -> np.ndarray | Feedforward:
    """Feed-forward command for a whole reference, compiled; the same as :func:`inverse`.

    Runs the compensator of :func:`inverse` over ``y_ref`` (with the preview taken from
    ``y_ref`` itself, its last value held at the end) so that ``model.simulate(u).y`` tracks
    ``y_ref`` (or ``M y_ref``). The reference should start at rest (``y_ref[0] = 0``, the stage's
    state at rest). It works on the sandwich's own signals: for a model identified on a record
    (rest level, sensor offset, envelope, units) use :func:`~hystid.compensate.compensate`.

    Parameters
    ----------
    model : DuhemSandwich, MultiDuhemSandwich or PISandwich
        The identified stage.
    y_ref : array_like
        Desired output, one value per sample.
    u_limits, reference_model, reference_lead, preview, duhem_bound
        As for :func:`inverse`.
    full_output : bool
        Return a :class:`Feedforward` (command, aligned desired output, status) instead of
        the command alone.

    Returns
    -------
    ndarray or Feedforward
        The command ``u``.
    """
    chain = _build(model, kind=KIND_DUHEM, u_limits=u_limits, reference_model=reference_model,
                   preview=preview, duhem_bound=duhem_bound, reference_lead=reference_lead)
    result = _run(chain, _as_reference(y_ref))
    return result if full_output else result.u


def linear_feedforward(
    model: DuhemSandwich | PISandwich,
    y_ref: np.ndarray | Sequence[float],
    *,
    u_limits: tuple[float, float] = (0.0, 10.0),
    reference_model: ct.LTI | Literal["exact"] | None = None,
    reference_lead: int | None = None,
    full_output: bool = False,
) -> np.ndarray | Feedforward:
    """The uncompensated baseline: the same inverse with the hysteresis replaced by its
    central line ``w1 = w2 / hysteresis_gain(model)``.

    L1 and L2 are inverted exactly as in :func:`feedforward`, so the difference between the two
    tracking errors is the error hysteresis causes.

    Parameters
    ----------
    model : DuhemSandwich, MultiDuhemSandwich or PISandwich
        The identified stage.
    y_ref : array_like
        Desired output, one value per sample.
    u_limits, reference_model, reference_lead
        As for :func:`inverse`.
    full_output : bool
        Return a :class:`Feedforward` instead of the command alone.

    Returns
    -------
    ndarray or Feedforward
        The command ``u``.
    """
    chain = _build(model, kind=KIND_LINEAR, u_limits=u_limits, reference_model=reference_model,
                   preview=0, duhem_bound=DUHEM_BOUND, reference_lead=reference_lead)
    result = _run(chain, _as_reference(y_ref))
    return result if full_output else result.u
