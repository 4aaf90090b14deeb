"""The ``pi-stage`` on-line identifier's arrival cost and the drift of the sensor's zero (see
:mod:`hystid.identify.pi_online`): the prior's decay at every re-solve and, on a record that
begins in motion, the drift's clock, moved at every chunk boundary, with its coordinates
marginalised out of the arrival cost.

:class:`ArrivalAndDrift` holds these steps of
:class:`~hystid.identify.pi_online.PIStageOnline`, which inherits them.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from .pi_batch import DRIFT_KNOT_SECONDS

__all__ = ["ARRIVAL_DECAY", "ArrivalAndDrift"]

#: Default factor on the arrival cost's information at every re-solve
#: (:class:`PIStageOnline`'s ``arrival_decay``): the information of a chunk halves with every
#: ``every`` samples after it left the window. A chunk is folded in linearised at the
#: estimate of the time, and the slow branch's share and pole trade off along a curved valley:
#: kept whole, that quadratic held the estimate where it was folded. On the helper's
#: Maxwell-slip stage (20 kHz, 1 s of excitation) the re-solve's window cost at the batch
#: fit's estimate was 0.35 against 1.18 at the on-line one, its arrival cost 22 against 1.1:
#: the on-line model stayed 1.31-1.53x the batch fit off held-out records, 0.96-1.05x with
#: the decay. On measured stage A (its 1 s of excitation fits in one window) nothing changes.
ARRIVAL_DECAY = 0.5


class ArrivalAndDrift:
    """The arrival cost's decay and the drift of
    :class:`~hystid.identify.pi_online.PIStageOnline` (a mixin: the state is the
    identifier's)."""

    @property
    def drift_per_second_(self) -> float:
        """The drift of the output's zero over the last window, output units per second (see
        the class)."""
        if not self._tracks_drift:
            return 0.0
        return float(self._phi[len(self.names) + 1]) * self._tick * self._sy * self.fs

    @property
    def drift_range_(self) -> float:
        """How far the output's zero moved (its largest less its least value) over the samples
        so far, output units: the warm-up's straight line, then the zero at each chunk's end."""
        return (self._zeros[1] - self._zeros[0]) * self._sy

    @property
    def _tracks_drift(self) -> bool:
        """Whether the offset and the drift are search coordinates (a record in motion)."""
        return self._phi is not None and len(self._phi) > len(self.names)

    def _start_clock(self, fit: Any, y: np.ndarray, st0: np.ndarray) -> float:
        """Start the drift's clock in ``st0`` (0 at the middle of the warm-up's fitted samples,
        1 over the window) and return the warm-up's rate per unit of it. The window spans at
        most :data:`~hystid.identify.pi_batch.DRIFT_KNOT_SECONDS` (the batch fit's straight
        pieces): the drift is a straight line over the window."""
        n = self._n_weights
        knot = max(1, int(round(DRIFT_KNOT_SECONDS * self.fs / self._every)))
        self._span = self._every * min(self._keep(), knot)
        self._tick = 1.0 / self._span
        rows = np.flatnonzero(np.isfinite(y))
        middle = 0.5 * (rows[0] + rows[-1])
        st0[0, n], st0[1, n] = -middle * self._tick, self._tick
        rate = fit.drift / fit.span / self._tick
        first = fit.y0 - rate * middle * self._tick
        last = fit.y0 + rate * (len(y) - 1 - middle) * self._tick
        self._zeros = (min(first, last), max(first, last))
        return rate

    def _rereference(self, *others: np.ndarray) -> list[np.ndarray]:
        """Move the drift's clock to 0 at the next sample (the offset coordinate becomes the
        zero there): the estimates, the arrival cost, the covariance and the states move with
        it, and so do ``others`` (returned). Without a drift, nothing moves."""
        if not self._tracks_drift:
            return list(others)
        n, c = self._n_weights, len(self.names)
        shift = float(self._st[0, n])
        T = np.eye(len(self._phi))
        T[c, c + 1] = shift  # c' = c + d shift
        Ti = np.eye(len(self._phi))
        Ti[c, c + 1] = -shift
        self._phi, self._solved = T @ self._phi, T @ self._solved
        phi_a, R_a = self._arrival
        self._arrival = (T @ phi_a, Ti.T @ R_a @ Ti)
        self._P = T @ self._P @ T.T
        for st in (self._st, self._wstate):
            st[0, n] -= shift
        zero = float(self._phi[c])
        self._zeros = (min(self._zeros[0], zero), max(self._zeros[1], zero))
        return [T @ v for v in others]

    def _forget(self, arrival: tuple[np.ndarray, np.ndarray]) -> tuple[np.ndarray,
                                                                       np.ndarray]:
        """The arrival cost once the chunks leaving the window are folded in and before the
        window is solved: its information times :attr:`arrival_decay`, and the offset and the
        drift's rate marginalised out (their prior restored), so that the window alone fixes
        the drift's straight line: a rate that changes is followed once the window has passed
        the change."""
        phi_a, R = arrival
        R = R * self.arrival_decay
        if not self._tracks_drift:
            return phi_a, R
        c = len(self.names)
        m, d = slice(0, c), slice(c, c + 2)
        out = np.zeros_like(R)
        out[m, m] = R[m, m] - R[m, d] @ np.linalg.solve(R[d, d], R[d, m])
        out[d, d] = np.eye(2) * self._prior
        return phi_a, out
