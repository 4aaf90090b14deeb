"""Candidate unmodelled effects: augmentations of the Duhem sandwich (eqs. 1, 2, 7).

Each candidate *form* adds a few parameters to the nominal sandwich and reduces to it *exactly*
(bit for bit) when they are zero. Forms are grouped in *families* (the physical effect a
diagnosis names); a family has one or several forms so that an effect whose functional form
differs from any single parametrisation is still found. With ``ud`` the delayed input,
``v = w2 + c`` the actuator displacement with creep, ``yL`` the output of L2 and ``t`` the time
since the start of the record::

    delay        ud(k) = (1 - phi) u(k - n) + phi u(k - n - 1),   n + phi = d (samples): the
                 dead time q1 of eq. (1) (several samples), fractional
    slew_limit   w1(k) = w1(k-1) + clip(w1_L1(k) - w1(k-1), -1/s, 1/s),   s = inv_rate * fs
    slew_input   the same limit on the input before L1 (the amplifier's own slew rate)
    saturation   f(w1) = f0 sgn(w1) + f1 w1 (1 + c w1^2) in eq. (7): the anhysteretic curve bends
    output_curve y = v + c2 x^2 / S + c3 x^3 / S^2, x = v - centre: a curved sensor or
                 actuator characteristic at the output (``centre`` and span ``S`` are fixed
                 by the records, not fitted)
    offset       y(k) = ... + y0: a constant offset of the sensor's zero
    asymmetry    alpha_k = alpha (1 + e_a s_k), g_k = g0 (1 + e_g s_k), f1_k = f1 (1 + e_f s_k),
                 s_k = sgn dw1(k): ascending and descending branches differ
    asymmetry_input  the same with s_k = sgn dud(k), the direction of the (delayed) input:
                 coefficients switched by the commanded motion, not by w1's
    loop_level   alpha_k = alpha (1 + l_a w1(k-1)), g_k = g0 (1 + l_g w1(k-1)): the loop's
                 shape changes with the level
    creep        c(k) = c(k-1) + lam (kappa w2(k) - c(k-1)),   lam = 1 - exp(-dt / tau)
    creep_2tau   creep plus a second lag (kappa2, tau2): several time constants
    creep_log    a bank of five lags, time constants tau * 10^(0.75 j), j = 0..4, gains
                 kappa / 5: a logarithmic creep over three decades
    extra_mode   m(k) = 2 r cos(W) m(k-1) - r^2 m(k-2) + g K2 (1 - 2 r cos W + r^2) v(k), added
                 to yL: a further mode in parallel with L2 (n2 + 2)
    mode_series  ys(k) = 2 r cos(W) ys(k-1) - r^2 ys(k-2) + (1 - 2 r cos W + r^2) yL(k),
                 y = yL + g (ys - yL): a mode in series with L2 (unit static gain)
    drift        y(k) = yL(k) + m(k) + d1 t + d2 t^2 + d3 t^3  (+ y0 with the offset)

where ``w1_L1`` is eq. (1) driven by ``ud``, ``K2`` the static gain of L2, and the modes have
the natural frequency ``freq`` and damping ``zeta`` (``r = exp(-zeta w dt)``,
``W = w dt sqrt(1 - zeta^2)``). All forms share one compiled kernel, so any set of them can be
active at once (the greedy search adds them one by one, one form per family).

The diagnosis treats ``drift`` as a record-specific nuisance (re-estimated on every record); its
kernel form serves :func:`simulate_with_effect`.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np
from numba import njit

from ..kernels import monic_output, offsets, sgn
from ..model import DuhemSandwich, InitialCondition, SandwichResponse
from ..signals import finite_signal
from ..validate import check_plain_duhem

__all__ = [
    "EFFECTS",
    "EFFECT_NAMES",
    "FAMILIES",
    "AugmentedSandwich",
    "Effect",
    "augmented_into",
    "augmented_output",
    "effect_dict",
    "effect_vector",
    "family_of",
    "simulate_with_effect",
]

#: Longest input dead time the kernel accepts, in samples.
MAX_DELAY = 64
#: The augmented model, as named when it refuses a structure richer than the plain Duhem.
_OPTION = "the diagnosis' augmented sandwich (AugmentedSandwich, diagnose)"
#: Lags of the logarithmic creep bank and the decades between their time constants.
N_LOG = 5
LOG_STEP = 0.75


@dataclass(frozen=True)
class Effect:
    """One candidate form of an effect: its parameters, units, bounds and meaning.

    Attributes
    ----------
    name : str
        Form name (``creep``, ``creep_log``, ...).
    params : tuple of str
        Names of its new parameters; all zero gives the nominal sandwich.
    units : tuple of str
        Units of each parameter (``y`` and ``u`` stand for the record's units).
    slots : tuple of int
        Positions of the parameters in the kernel's effect vector.
    description : str
        One line for reports.
    family : str
        The effect the form stands for (``creep`` for ``creep_log``); the form's name by
        default.
    """

    name: str
    params: tuple[str, ...]
    units: tuple[str, ...]
    slots: tuple[int, ...]
    description: str
    family: str = ""

    def __post_init__(self) -> None:
        if not self.family:
            object.__setattr__(self, "family", self.name)


# kernel effect vector:
# [kappa, tau, d1, d2, gm, fm, zeta, delay, e_alpha, e_g, inv_rate, cubic, y0,
#  e_f, l_alpha, kappa2, tau2, kappa_log, tau_log, g_series, l_g, d3, inv_rate_u,
#  c2, c3, centre, span, e_alpha_u, e_g_u, e_f_u]
EFFECTS: dict[str, Effect] = {
    e.name: e
    for e in (
        Effect("creep", ("gain", "tau"), ("1", "s"), (0, 1),
               "slow creep of the actuator: first-order lag of gain*w2 added to w2"),
        Effect("creep_2tau", ("gain", "tau", "gain2", "tau2"), ("1", "s", "1", "s"),
               (0, 1, 15, 16), "creep with two time constants", "creep"),
        Effect("creep_log", ("gain", "tau"), ("1", "s"), (17, 18),
               "logarithmic creep: five lags over three decades from tau", "creep"),
        Effect("drift", ("rate", "accel", "jerk"), ("y/s", "y/s^2", "y/s^3"), (2, 3, 21),
               "slow output drift not tied to the input, different on every record"),
        Effect("extra_mode", ("gain", "freq", "zeta"), ("1", "Hz", "1"), (4, 5, 6),
               "a further structural resonance in parallel with L2 (order n2 + 2)"),
        Effect("mode_series", ("gain", "freq", "zeta"), ("1", "Hz", "1"), (19, 5, 6),
               "a further structural resonance in series with L2 (order n2 + 2)", "extra_mode"),
        Effect("delay", ("samples",), ("samples",), (7,),
               "input dead time (q1 of eq. 1, several samples, fractional)"),
        Effect("asymmetry", ("alpha", "g0", "f1"), ("1", "1", "1"), (8, 9, 13),
               "ascending and descending branches differ: alpha, g0, f1 scaled by 1 +/- e"),
        Effect("asymmetry_input", ("alpha", "g0", "f1"), ("1", "1", "1"), (27, 28, 29),
               "rising and falling input differ: alpha, g0, f1 scaled by 1 +/- e with the "
               "direction of the commanded input", "asymmetry"),
        Effect("loop_level", ("alpha", "g0"), ("1/u", "1/u"), (14, 20),
               "the loop changes with the level: alpha, g0 scaled by 1 + l w1", "asymmetry"),
        Effect("slew_limit", ("inv_rate",), ("s/u",), (10,),
               "amplifier rate limit |dw1/dt| <= 1/inv_rate"),
        Effect("slew_input", ("inv_rate",), ("s/u",), (22,),
               "amplifier rate limit on the input |du/dt| <= 1/inv_rate", "slew_limit"),
        Effect("saturation", ("cubic",), ("1/u^2",), (11,),
               "the anhysteretic curve of eq. (7) bends: f1 w1 (1 + cubic w1^2)"),
        Effect("output_curve", ("quadratic", "cubic", "centre", "span"), ("1", "1", "y", "y"),
               (23, 24, 25, 26), "a curved characteristic at the output (sensor or actuator "
               "range)", "saturation"),
        Effect("offset", ("y0",), ("y",), (12,),
               "a constant offset of the output (the sensor's zero, or a loop shifted as a "
               "whole)", "asymmetry"),
    )
}
EFFECT_NAMES: tuple[str, ...] = tuple(EFFECTS)
#: Families in order, each with its forms.
FAMILIES: dict[str, tuple[str, ...]] = {}
for _e in EFFECTS.values():
    FAMILIES[_e.family] = (*FAMILIES.get(_e.family, ()), _e.name)
N_SLOTS = 30
#: Slots set from the records and never fitted (the output curve's centre and span).
FIXED_SLOTS = (25, 26)


def family_of(name: str) -> str:
    """The family of a form (a family name maps to itself).

    Parameters
    ----------
    name : str
        A form or family name.

    Returns
    -------
    str
        The family's name.
    """
    if name in FAMILIES:
        return name
    return EFFECTS[name].family


def effect_vector(effects: Mapping[str, Mapping[str, float]] | None) -> np.ndarray:
    """Pack ``{"creep": {"gain": .., "tau": ..}, ...}`` into the kernel's effect vector.

    Parameters
    ----------
    effects : mapping or None
        Forms and their parameter values; missing parameters are zero.

    Returns
    -------
    ndarray
        The effect vector (:data:`N_SLOTS` entries).
    """
    phi = np.zeros(N_SLOTS)
    for name, values in (effects or {}).items():
        if name not in EFFECTS:
            raise ValueError(f"effects: unknown effect {name!r}; expected one of {EFFECT_NAMES}")
        eff = EFFECTS[name]
        unknown = [k for k in values if k not in eff.params]
        if unknown:
            raise ValueError(
                f"effects[{name!r}]: unknown parameters {unknown}; expected {list(eff.params)}"
            )
        for p, slot in zip(eff.params, eff.slots, strict=True):
            v = float(values.get(p, 0.0))
            if not np.isfinite(v):
                raise ValueError(f"effects[{name!r}][{p!r}]: expected a finite number, got {v}")
            phi[slot] = v
    _check_vector(phi)
    return phi


def _check_vector(phi: np.ndarray) -> None:
    for g, tau, label in ((0, 1, "creep"), (15, 16, "creep_2tau"), (17, 18, "creep_log")):
        if phi[tau] < 0:
            raise ValueError(f"{label} tau must be >= 0 s, got {phi[tau]}")
        if phi[g] < 0:
            raise ValueError(f"{label} gain must be >= 0 (creep goes on in the direction of "
                             f"the drive), got {phi[g]}")
    if phi[6] < 0 or phi[6] >= 1:
        raise ValueError(f"extra_mode zeta must be in [0, 1), got {phi[6]}")
    if phi[5] < 0:
        raise ValueError(f"extra_mode freq must be >= 0 Hz, got {phi[5]}")
    if not 0 <= phi[7] <= MAX_DELAY - 1:
        raise ValueError(f"delay samples must be in [0, {MAX_DELAY - 1}], got {phi[7]}")
    for label, slots in (("asymmetry", (8, 9, 13)), ("asymmetry_input", (27, 28, 29))):
        if max(abs(phi[i]) for i in slots) >= 1:
            raise ValueError(f"{label} alpha, g0, f1 must be in (-1, 1), got "
                             f"{', '.join(str(phi[i]) for i in slots)}")
    if phi[10] < 0 or phi[22] < 0:
        raise ValueError(f"slew_limit inv_rate must be >= 0, got {phi[10]}, {phi[22]}")
    if (phi[23] != 0 or phi[24] != 0) and not phi[26] > 0:
        raise ValueError(f"output_curve span must be > 0, got {phi[26]}")


def effect_dict(phi: np.ndarray, names: Sequence[str] | None = None) -> dict[str, dict]:
    """Unpack an effect vector into ``{name: {param: value}}`` for the given forms.

    Parameters
    ----------
    phi : ndarray
        Effect vector.
    names : sequence of str, optional
        Forms to unpack (all by default).

    Returns
    -------
    dict
        Parameter values by form.
    """
    names = EFFECT_NAMES if names is None else names
    return {
        n: {p: float(phi[s]) for p, s in zip(EFFECTS[n].params, EFFECTS[n].slots, strict=True)}
        for n in names
    }


# --------------------------------------------------------------------------- compiled kernel
@njit(cache=True, nogil=True)
def _lag_coefficient(tau, dt):
    return 1.0 - np.exp(-dt / tau) if tau > 0.0 else 1.0


@njit(cache=True, inline="always")
def l2_dc_terms(theta, i_b2, n2b, i_a2, n2a):
    """L2's static gain as ``(1 + sum b2, 1 + sum a2)``, numerator and denominator (eq. 2,
    ``b20 = 1``)."""
    num2 = 1.0
    for j in range(n2b):
        num2 += theta[i_b2 + j]
    den2 = 1.0
    for i in range(n2a):
        den2 += theta[i_a2 + i]
    return num2, den2


@njit(cache=True, nogil=True)
def augmented_into(theta, layout, phi, U, UD, W1, W2, V, C, YL, M, Y, start, dt):
    """Simulate the augmented sandwich from index ``start`` on (extended arrays, past first).

    ``U`` is the input, ``UD`` the delayed input, ``V = W2 + C`` the drive of L2, ``C`` the
    creep, ``YL`` the output of L2, ``M`` the extra modes and ``Y`` the measured-like output.
    Entries before ``start`` are the past and are read, never written (except ``UD``, rebuilt
    from ``U``). The creep lags start at zero, the series mode at rest at ``YL[start - 1]``.

    The sandwich's step (:func:`hystid.kernels.step`) is fused here with the effects that act
    inside it; with every effect off (``phi`` zero) this kernel is that step on ``U``, which
    ``tests/test_step_once.py`` checks against :func:`hystid.kernels.simulate_into` to 1e-12.
    Only the plain Duhem sandwich's layout is read (:func:`hystid.validate.check_plain_duhem`).
    The input's delay and rate limit, the first creep lag, the parallel mode and the drift are
    skipped while their parameters are zero (they would add exact zeros; a refit simulates
    thousands of times with most effects off).
    """
    n1a, n1b, n2a, n2b, q1, q2 = layout[0], layout[1], layout[2], layout[3], layout[4], layout[5]
    i_b2, i_alpha, i_f0, i_f1, i_b1, i_g0, i_a1, i_a2 = offsets(layout)
    alpha = theta[i_alpha]
    f0 = theta[i_f0] if i_f0 >= 0 else 0.0
    f1 = theta[i_f1]
    g0 = theta[i_g0]
    kappa, d1, d2 = phi[0], phi[2], phi[3]
    gm, fm, zeta = phi[4], phi[5], phi[6]
    e_a, e_g, inv_rate, cubic, y_off = phi[8], phi[9], phi[10], phi[11], phi[12]
    e_f, l_a, kappa2, k_log, g_ser, l_g = phi[13], phi[14], phi[15], phi[17], phi[19], phi[20]
    d3 = phi[21]
    inv_rate_u, c2o, c3o, y_c, y_s = phi[22], phi[23], phi[24], phi[25], phi[26]
    e_au, e_gu, e_fu = phi[27], phi[28], phi[29]
    # creep: first-order lags, lam = 1 - exp(-dt / tau)
    lam = _lag_coefficient(phi[1], dt)
    lam2 = _lag_coefficient(phi[16], dt)
    lam_log = np.empty(N_LOG)
    for j in range(N_LOG):
        lam_log[j] = _lag_coefficient(phi[18] * 10.0 ** (LOG_STEP * j), dt)
    c_log = np.zeros(N_LOG)
    c2 = 0.0
    # modes: poles r exp(+-jW); the parallel one has the static gain gm * K2
    p1 = 0.0
    p2 = 0.0
    bm = 0.0
    if gm != 0.0 or g_ser != 0.0:
        w = 2.0 * np.pi * fm
        r = np.exp(-zeta * w * dt)
        wd = w * dt * np.sqrt(1.0 - zeta * zeta)
        p1 = 2.0 * r * np.cos(wd)
        p2 = -r * r
        num2, den2 = l2_dc_terms(theta, i_b2, n2b, i_a2, n2a)
        bm = gm * (num2 / den2) * (1.0 - p1 - p2)
    ys1 = YL[start - 1]
    ys2 = YL[start - 2] if start >= 2 else ys1
    # delay: ud(k) = (1 - frac) u(k - nd) + frac u(k - nd - 1)
    nd = int(np.floor(phi[7]))
    frac = phi[7] - nd
    plain_input = nd == 0 and frac == 0.0 and not inv_rate_u > 0.0
    for k in range(U.shape[0]):
        if plain_input:  # (1 - 0) u(k) + 0 u(k - 1), no limit: the input itself
            UD[k] = U[k]
            continue
        i0 = k - nd
        i1 = k - nd - 1
        a0 = U[i0] if i0 >= 0 else U[0]
        a1 = U[i1] if i1 >= 0 else U[0]
        UD[k] = (1.0 - frac) * a0 + frac * a1
        if inv_rate_u > 0.0 and k > 0:
            lim_u = dt / inv_rate_u
            step_u = UD[k] - UD[k - 1]
            if step_u > lim_u:
                UD[k] = UD[k - 1] + lim_u
            elif step_u < -lim_u:
                UD[k] = UD[k - 1] - lim_u
    lim = 1.0 / (inv_rate / dt) if inv_rate > 0.0 else 0.0
    drifts = d1 != 0.0 or d2 != 0.0 or d3 != 0.0
    for k in range(start, U.shape[0]):
        # eq. (1) on the delayed input
        w1 = monic_output(theta, i_b1, n1b, i_a1, n1a, q1, UD, W1, k)
        if inv_rate > 0.0:
            step = w1 - W1[k - 1]
            if step > lim:
                w1 = W1[k - 1] + lim
            elif step < -lim:
                w1 = W1[k - 1] - lim
        W1[k] = w1
        # eq. (7) with direction- and level-dependent coefficients
        w1p = W1[k - 1]
        w2p = W2[k - 1]
        dw1 = w1 - w1p
        s = sgn(dw1)
        su = sgn(UD[k] - UD[k - 1]) if k >= 1 else 0.0
        alpha_k = alpha * (1.0 + e_a * s + e_au * su) * (1.0 + l_a * w1p)
        g_k = g0 * (1.0 + e_g * s + e_gu * su) * (1.0 + l_g * w1p)
        f = f0 * sgn(w1p) + f1 * (1.0 + e_f * s + e_fu * su) * w1p * (1.0 + cubic * w1p * w1p)
        W2[k] = w2p + alpha_k * (f - w2p) * abs(dw1) + g_k * dw1
        # creep of the actuator: one lag, a second lag, a logarithmic bank
        if kappa != 0.0:
            C[k] = C[k - 1] + lam * (kappa * W2[k] - C[k - 1])
            v = W2[k] + C[k]
        else:  # no first lag: C stays at its start, zero
            C[k] = 0.0
            v = W2[k]
        if kappa2 != 0.0:
            c2 += lam2 * (kappa2 * W2[k] - c2)
            v += c2
        if k_log != 0.0:
            for j in range(N_LOG):
                c_log[j] += lam_log[j] * (k_log / N_LOG * W2[k] - c_log[j])
                v += c_log[j]
        V[k] = v
        YL[k] = monic_output(theta, i_b2, n2b, i_a2, n2a, q2, V, YL, k)  # eq. (2) on v
        # extra modes, in parallel with L2 and in series after it
        if bm != 0.0:
            M[k] = p1 * M[k - 1] + p2 * M[k - 2] + bm * V[k]
            out = YL[k] + M[k]
        else:  # no parallel mode: M stays at its start, zero
            M[k] = 0.0
            out = YL[k]
        if g_ser != 0.0:
            ys = p1 * ys1 + p2 * ys2 + (1.0 - p1 - p2) * YL[k]
            ys2 = ys1
            ys1 = ys
            out += g_ser * (ys - YL[k])
        if c2o != 0.0 or c3o != 0.0:
            x = (out - y_c) / y_s
            out += y_s * x * x * (c2o + c3o * x)
        # drift, t from the start of the record, and the sensor offset
        if drifts:
            t = (k - start) * dt
            out += t * (d1 + t * (d2 + t * d3))
        Y[k] = out + y_off


class _Workspace:
    """Extended arrays for one input signal, reused across simulations (the refits call the
    kernel thousands of times)."""

    def __init__(self, u: np.ndarray, P: int, x0: InitialCondition | None):
        x0 = x0 or InitialCondition()
        n = len(u)
        self.P = P
        self.n = n
        self.U = np.concatenate([x0.window("u", P), np.asarray(u, float)])
        self.past = {k: x0.window(k, P) for k in ("w1", "w2", "y")}
        self.arrays = [np.zeros(P + n) for _ in range(8)]

    def start(self, layout) -> list[np.ndarray]:
        """The arrays with their past rows set (the input past is in :attr:`U`), ready for
        :func:`augmented_into` or :func:`hystid.diagnose.sensitivities.augmented_sens_into`."""
        check_plain_duhem(layout, _OPTION)
        UD, W1, W2, V, C, YL, M, Y = self.arrays
        P = self.P
        W1[:P] = self.past["w1"]
        W2[:P] = self.past["w2"]
        V[:P] = self.past["w2"]
        YL[:P] = self.past["y"]
        Y[:P] = self.past["y"]
        C[:P] = 0.0
        M[:P] = 0.0
        return self.arrays

    def run(self, theta, layout, phi, dt) -> tuple[np.ndarray, ...]:
        """Simulate: ``w1``, ``w2`` and ``y`` after the past rows."""
        UD, W1, W2, V, C, YL, M, Y = self.start(layout)
        P = self.P
        augmented_into(theta, layout, phi, self.U, UD, W1, W2, V, C, YL, M, Y, P, dt)
        return W1[P:], W2[P:], Y[P:]


def _history(model: DuhemSandwich) -> int:
    return max(model.structure.history, 2)


def augmented_output(
    model: DuhemSandwich,
    phi: np.ndarray,
    u: np.ndarray,
    x0: InitialCondition | None = None,
) -> np.ndarray:
    """Output of the augmented sandwich for the effect vector ``phi`` (fast path, no checks).

    Parameters
    ----------
    model : DuhemSandwich
        Nominal stage.
    phi : ndarray
        The effect vector (zero: the nominal stage).
    u : ndarray
        Input samples.
    x0 : InitialCondition, optional
        Past signal values; at rest by default.

    Returns
    -------
    ndarray
        The output ``y``.
    """
    ws = _Workspace(u, _history(model), x0)
    return ws.run(model.theta, model.structure.layout, phi, model.dt)[2].copy()


class AugmentedSandwich:
    """The Duhem sandwich with unmodelled effects switched on.

    Parameters
    ----------
    model : DuhemSandwich
        The nominal sandwich (L1 -> Duhem H -> L2).
    effects : mapping
        ``{effect name: {parameter: value}}``, see :data:`EFFECTS`; missing parameters are zero.
    name : str, optional
        Name for responses; by default the nominal model's name plus the effects.

    Attributes
    ----------
    phi : ndarray
        The effect vector used by the compiled kernel.
    """

    #: The model file's ``kind``: a Duhem model file with ``effects``.
    kind = "duhem"

    def __init__(
        self,
        model: DuhemSandwich,
        effects: Mapping[str, Mapping[str, float]] | None = None,
        name: str | None = None,
    ) -> None:
        if not isinstance(model, DuhemSandwich):
            raise TypeError(f"model: expected a DuhemSandwich, got {type(model).__name__}")
        check_plain_duhem(model.structure.layout, _OPTION)
        self.model = model
        self.effects = {k: dict(v) for k, v in (effects or {}).items()}
        self.phi = effect_vector(self.effects)
        if name is None:
            name = model.name + (f" + {' + '.join(self.effects)}" if self.effects else "")
        self.name = name

    @property
    def fs(self) -> float:
        """Sampling rate in Hz."""
        return self.model.fs

    @property
    def structure(self):
        """The nominal model's structure."""
        return self.model.structure

    @property
    def u_rest(self) -> float:
        """The nominal model's rest level (record units)."""
        return self.model.u_rest

    @property
    def offset(self) -> float:
        """The nominal model's sensor offset (record units)."""
        return self.model.offset

    @property
    def envelope(self):
        """The input envelope the nominal model was identified on (or None)."""
        return self.model.envelope

    @property
    def units(self) -> dict[str, str]:
        """Units of the input and output."""
        return self.model.units

    def simulate(
        self, u: np.ndarray | Sequence[float], x0: InitialCondition | None = None,
        check: bool = False,
    ) -> SandwichResponse:
        """Simulate from the past ``x0`` (at rest by default); ``t = 0`` at the first sample.

        The nominal model's ``u_rest`` is taken off the input and its ``offset`` added to the
        output, as :meth:`DuhemSandwich.simulate` does.

        Parameters
        ----------
        u : array_like
            Input samples.
        x0 : InitialCondition, optional
            Past relative to the rest (at rest by default).
        check : bool
            Warn (:class:`~hystid.operating.AdmissibilityWarning`) where the input leaves the
            nominal model's envelope.

        Returns
        -------
        SandwichResponse
            ``t, u, w1, w2, y``; ``w2`` is the Duhem output before creep. Unpacks as ``t, y``.
        """
        u = finite_signal(u, "u")
        if check and self.envelope is not None:
            from ..operating import warn_admissibility

            warn_admissibility(self.envelope.violations(u), self.name)
        m = self.model
        ws = _Workspace(u - m.u_rest, _history(m), x0)
        w1, w2, y = ws.run(m.theta, m.structure.layout, self.phi, m.dt)
        y = y + m.offset
        t = np.arange(len(u)) / self.fs
        return SandwichResponse(t, u, w1.copy(), w2.copy(), y.copy(), name=self.name)

    def __repr__(self) -> str:
        return f"AugmentedSandwich({self.model!r}, effects={self.effects})"


def simulate_with_effect(
    model: DuhemSandwich,
    effect_name: str,
    effect_params: Mapping[str, float],
    u: np.ndarray | Sequence[float],
    *,
    noise: float = 0.0,
    seed: int | None = 0,
    x0: InitialCondition | None = None,
) -> SandwichResponse:
    """Simulate ``model`` with one unmodelled effect (and optional white sensor noise).

    Parameters
    ----------
    model : DuhemSandwich
        Nominal stage, e.g. :func:`hystid.reference.reference_model`.
    effect_name : str
        One of :data:`EFFECT_NAMES`, or ``"none"`` for the nominal stage.
    effect_params : mapping
        The effect's parameters (see :data:`EFFECTS`).
    u : array_like
        Input samples.
    noise : float
        Standard deviation of white noise added to ``y`` (output units).
    seed : int or None
        Seed of the noise.
    x0 : InitialCondition, optional
        Past signal values; at rest by default.

    Returns
    -------
    SandwichResponse
        Simulated signals; ``y`` carries the noise.
    """
    if effect_name != "none" and effect_name not in EFFECTS:
        raise ValueError(f"effect_name: expected 'none' or one of {EFFECT_NAMES}, got "
                         f"{effect_name!r}")
    if not (np.isfinite(noise) and noise >= 0):
        raise ValueError(f"noise: expected a non-negative standard deviation, got {noise!r}")
    effects = {} if effect_name == "none" else {effect_name: dict(effect_params)}
    resp = AugmentedSandwich(model, effects).simulate(u, x0)
    if noise > 0:
        resp.y = resp.y + noise * np.random.default_rng(seed).standard_normal(len(resp.y))
    return resp
