"""The search coordinates of a refit: ``z`` <-> (nominal parameters, effect vector), with the
bounds of every effect parameter, the ranges that may be widened and how, and which fitted
parameters sit at a bound (:class:`Parametrisation`, used by :mod:`hystid.diagnose.refit`).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from ..identify.offline import _Reparam
from ..model import DuhemSandwich
from .effects import EFFECTS, FIXED_SLOTS, LOG_STEP, MAX_DELAY, N_LOG, N_SLOTS
from .sensitivities import sensitivity_columns

__all__ = ["AT_BOUND", "NOMINAL_SLOTS", "PHYSICAL_BOUNDS", "WIDENABLE", "Parametrisation"]

#: Effect-vector slots that belong to the nominal model: the sensor offset.
NOMINAL_SLOTS = (EFFECTS["offset"].slots[0],)

#: A fitted parameter within this share of its range's width from a bound is at the bound.
AT_BOUND = 1e-3
#: Bounds that are physics (a creep gain is not negative, a curve stays monotone, a dead time
#: stays within the kernel's buffer, a time constant within the record), never widened.
PHYSICAL_BOUNDS = frozenset({0, 1, 7, 11, 15, 16, 17, 18, 23, 24})
#: How a guessed range widens by a factor ``w``: gains and asymmetries linearly about zero (an
#: asymmetry stays below 1), log-ranges by ``log w`` upwards (a damping at most 1).
WIDENABLE = {
    4: lambda lo, hi, w: (lo * w, hi * w),
    19: lambda lo, hi, w: (lo * w, hi * w),
    6: lambda lo, hi, w: (lo, min(hi + np.log(w), 0.0)),
    10: lambda lo, hi, w: (lo - np.log(w), hi + np.log(w)),
    22: lambda lo, hi, w: (lo - np.log(w), hi + np.log(w)),
}


class Parametrisation:
    """``z`` <-> (theta, phi) for the nominal parameters and a set of active effects.

    Parameters
    ----------
    model : DuhemSandwich
        Gives the structure and the sampling rate.
    active : sequence of str
        Names of the forms whose parameters are free.
    duration : float
        Length of the fitting record in seconds (bounds of the time constants).
    step_scale : float
        Largest input-driven change of ``w1`` per sample (scale of the slew limit).
    w1_scale : float
        Largest ``|w1|`` (scale of the saturation's and the level-dependent loop's
        coefficients).
    free_theta : bool
        Whether the nominal parameters are free (False: the effects' parameters alone). With
        them, the sensor offset (:data:`NOMINAL_SLOTS`) is free too: it is a parameter of the
        nominal model, as in :func:`hystid.identify.offline.fit_output_error`.
    widen : float
        Factor on the search ranges of the forms whose bounds are a guess, not physics
        (:data:`WIDENABLE`: mode gains and damping, rate limits); 1 for the default ranges.
    """

    def __init__(self, model: DuhemSandwich, active: Sequence[str], duration: float,
                 step_scale: float = 1.0, w1_scale: float = 1.0, free_theta: bool = True,
                 widen: float = 1.0) -> None:
        self.widen = float(widen)
        self.structure = model.structure
        self.fs = model.fs
        self.active = tuple(active)
        self.reparam = _Reparam(self.structure)
        self.ialpha = self.reparam.ialpha
        self.ntheta = self.reparam.n if free_theta else 0
        self.theta_fixed = np.array(model.theta, float)
        self.duration = float(duration)
        self.step_scale = float(max(step_scale, 1e-12))
        self.w1_scale = float(max(w1_scale, 1e-12))
        self.slots = [s for name in self.active for s in EFFECTS[name].slots
                      if s not in FIXED_SLOTS]
        if free_theta:
            self.slots = [s for s in NOMINAL_SLOTS if s not in self.slots] + self.slots
        if len(set(self.slots)) != len(self.slots):
            raise ValueError(f"forms {self.active} share parameters: at most one form per family")
        self.n = self.ntheta + len(self.slots)

    # transformed coordinates of the effect slots
    def _tau_floor(self) -> float:
        return max(0.5 / self.fs, 5e-3)

    def _fwd(self, slot: int, v: float) -> float:
        if slot in (1, 16):
            return float(np.log(max(v, self._tau_floor())))
        if slot == 18:
            return float(np.log(max(v, 0.5 / self.fs)))
        if slot in (5, 6):
            return float(np.log(max(v, 1e-6)))
        if slot in (10, 22):
            return float(np.log(max(v * self.fs * self.step_scale, 1e-6)))
        if slot == 11:
            return float(v * self.w1_scale**2)
        if slot in (14, 20):
            return float(v * self.w1_scale)
        return float(v)

    def _inv(self, slot: int, z: float) -> float:
        if slot in (1, 5, 6, 16, 18):
            return float(np.exp(z))
        if slot in (10, 22):
            return float(np.exp(z) / (self.fs * self.step_scale))
        if slot == 11:
            return float(z / self.w1_scale**2)
        if slot in (14, 20):
            return float(z / self.w1_scale)
        return float(z)

    def _dinv(self, slot: int, z: float) -> float:
        """``d _inv(slot, z) / dz``."""
        if slot in (1, 5, 6, 16, 18):
            return float(np.exp(z))
        if slot in (10, 22):
            return float(np.exp(z) / (self.fs * self.step_scale))
        if slot == 11:
            return 1.0 / self.w1_scale**2
        if slot in (14, 20):
            return 1.0 / self.w1_scale
        return 1.0

    def columns(self) -> tuple[np.ndarray, int]:
        """The sensitivity columns of :func:`simulate_fit_data_sens` for these coordinates.

        Returns
        -------
        tuple
            ``(cols, ntc)``: the column of each effect slot (-1 when held) and the number of
            leading columns that are the nominal parameters.
        """
        return sensitivity_columns(self.slots, self.ntheta), self.ntheta

    def chain(self, z: np.ndarray) -> np.ndarray:
        """``d (theta, free slots) / dz``: the sensitivity columns' map to ``z``.

        Parameters
        ----------
        z : ndarray
            Search coordinates.

        Returns
        -------
        ndarray
            Square, ``len(z)`` on a side (theta's columns first when free).
        """
        D = np.zeros((self.n, self.n))
        if self.ntheta:
            D[: self.ntheta, : self.ntheta] = self.reparam.to_theta(
                np.asarray(z[: self.ntheta], float))[1]
        for i, s in enumerate(self.slots):
            j = self.ntheta + i
            D[j, j] = self._dinv(s, z[j])
        return D

    def _bounds(self, slot: int) -> tuple[float, float]:
        T = self.duration
        table = {
            # creep goes on in the direction of the drive (gain >= 0) and is slow (tau >= 5 ms)
            0: (0.0, 1.0),
            1: (np.log(self._tau_floor()), np.log(100.0 * T)),
            4: (-2.0, 2.0),
            5: (np.log(max(5.0 / T, 20.0)), np.log(0.49 * self.fs)),
            6: (np.log(1e-3), np.log(0.3)),
            7: (0.0, MAX_DELAY - 1.0),
            8: (-0.95, 0.95),
            9: (-0.95, 0.95),
            10: (np.log(0.3), np.log(1e3)),
            # f stays monotone (Assumption 2) while 1 + 3 c w1^2 > 0
            11: (-0.3, 3.0),
            13: (-0.95, 0.95),
            14: (-0.9, 0.9),
            15: (0.0, 1.0),
            16: (np.log(self._tau_floor()), np.log(100.0 * T)),
            17: (0.0, 1.0),
            # the bank spans tau .. tau 10^(LOG_STEP (N_LOG - 1))
            18: (np.log(0.5 / self.fs),
                 np.log(max(10.0 * T / 10 ** (LOG_STEP * (N_LOG - 1)), 1.0 / self.fs))),
            19: (-1.0, 2.0),
            20: (-0.9, 0.9),
            # input rate limit relative to the largest input step (about w1's over L1's gain)
            22: (np.log(0.05), np.log(1e3)),
            # the curve stays monotone over the span
            23: (-0.6, 0.6),
            24: (-0.3, 0.3),
            27: (-0.95, 0.95),
            28: (-0.95, 0.95),
            29: (-0.95, 0.95),
        }
        lo, hi = table.get(slot, (-np.inf, np.inf))
        if self.widen != 1.0 and slot in WIDENABLE:
            lo, hi = WIDENABLE[slot](lo, hi, self.widen)
        return lo, hi

    def at_bound(self, z: np.ndarray, share: float = AT_BOUND) -> list[str]:
        """The effect parameters that sit at a bound of their search range.

        Parameters
        ----------
        z : ndarray
            Search coordinates.
        share : float
            Closeness to a bound, as a share of the range's width.

        Returns
        -------
        list of str
            ``"form.param (value at its upper|lower bound)"`` for each such parameter of the
            active forms.
        """
        lo, hi = self.bounds()
        out = []
        for form in self.active:
            e = EFFECTS[form]
            for name, slot in zip(e.params, e.slots, strict=True):
                if slot not in self.slots:
                    continue
                i = self.ntheta + self.slots.index(slot)
                a, b = lo[i], hi[i]
                if not (np.isfinite(a) and np.isfinite(b)) or slot in PHYSICAL_BOUNDS:
                    continue
                side = ("upper" if z[i] >= b - share * (b - a) else
                        "lower" if z[i] <= a + share * (b - a) else "")
                if side:
                    out.append(f"{form}.{name} ({self._inv(slot, z[i]):.4g} at its {side} "
                               "bound)")
        return out

    def to_z(self, theta: np.ndarray, phi: np.ndarray) -> np.ndarray:
        """Search coordinates of a parameter pair.

        Parameters
        ----------
        theta, phi : ndarray
            Nominal parameters and effect vector.

        Returns
        -------
        ndarray
            ``z``, clipped into the bounds.
        """
        z = self.reparam.to_z(np.asarray(theta, float))[: self.ntheta]
        ze = [self._fwd(s, phi[s]) for s in self.slots]
        z = np.concatenate([z, ze])
        lo, hi = self.bounds()
        return np.clip(z, lo, hi)

    def to_values(
        self, z: np.ndarray, base_phi: np.ndarray | None = None
    ) -> tuple[np.ndarray, np.ndarray]:
        """``(theta, phi)`` from search coordinates; inactive slots keep ``base_phi``.

        Parameters
        ----------
        z : ndarray
            Search coordinates.
        base_phi : ndarray, optional
            Effect vector of the slots that are not free (zero by default).

        Returns
        -------
        tuple of ndarray
            Nominal parameters and effect vector.
        """
        if self.ntheta:
            theta = self.reparam.to_theta(np.asarray(z[: self.ntheta], float),
                                          jacobian=False)[0]
        else:
            theta = self.theta_fixed.copy()
        phi = np.zeros(N_SLOTS) if base_phi is None else np.array(base_phi, float)
        for s, v in zip(self.slots, z[self.ntheta:], strict=True):
            phi[s] = self._inv(s, v)
        return theta, phi

    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """Lower and upper bounds of ``z``.

        Returns
        -------
        tuple of ndarray
            ``(lo, hi)``.
        """
        lo, hi = self.reparam.bounds()
        lo, hi = lo[: self.ntheta], hi[: self.ntheta]
        eb = [self._bounds(s) for s in self.slots]
        lo = np.concatenate([lo, [b[0] for b in eb]])
        hi = np.concatenate([hi, [b[1] for b in eb]])
        return lo, hi
