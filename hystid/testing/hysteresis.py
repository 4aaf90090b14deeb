"""Independent hysteresis operators for the test stages: a generalised Duhem loop, Bouc-Wen,
Preisach (relays) and Maxwell-slip (plays), each compiled and written apart from the models.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol

import numpy as np
from numba import njit


# --------------------------------------------------------------------------- compiled hysteresis
@njit(cache=True)
def _duhem(x, x_rest, w_rest, alpha_rise, alpha_fall, f0, f1, g0, width_slope, width_centre,
           width_scale):  # pragma: no cover - compiled
    # w(k) = w(k-1) + alpha [f0 sgn x(k-1) + f1 x(k-1) - w(k-1)] |dx(k)| + g0 dx(k),
    # alpha chosen by the sign of dx (rising / falling branch) and divided by a level-dependent
    # loop-width factor 1 + width_slope (x(k-1) - width_centre) / width_scale (at least 0.1).
    n = x.size
    w = np.empty(n)
    x_prev = x_rest
    w_prev = w_rest
    for k in range(n):
        dx = x[k] - x_prev
        alpha = alpha_rise if dx >= 0.0 else alpha_fall
        width = 1.0 + width_slope * (x_prev - width_centre) / width_scale
        if width < 0.1:
            width = 0.1
        anhysteretic = f0 * np.sign(x_prev) + f1 * x_prev
        w_k = w_prev + (alpha / width) * (anhysteretic - w_prev) * abs(dx) + g0 * dx
        w[k] = w_k
        x_prev = x[k]
        w_prev = w_k
    return w


@njit(cache=True)
def _bouc_wen(x, x_rest, z_rest, k_lin, a_rise, a_fall, beta, gamma, power, rate, rate_ref, fs,
              width_slope, width_centre, width_scale):  # pragma: no cover - compiled
    # dz = A dx - beta |dx| |z|^(n-1) z - gamma dx |z|^n, integrated with explicit Euler sub-steps
    # small enough that (|A| + beta + gamma) |dx-step| stays below 0.05; w = k_lin x + z.
    n = x.size
    w = np.empty(n)
    x_prev = x_rest
    z = z_rest
    for k in range(n):
        dx = x[k] - x_prev
        a_coef = a_rise if dx >= 0.0 else a_fall
        speed = abs(dx) * fs / rate_ref
        width = 1.0 + width_slope * (x_prev - width_centre) / width_scale
        if width < 0.1:
            width = 0.1
        fast = 1.0 + rate * speed
        a_coef = a_coef * fast
        b_eff = beta * fast / width
        g_eff = gamma * fast / width
        zmag = abs(z) if abs(z) > 1.0 else 1.0
        steps = 1 + int(abs(dx) * (abs(b_eff) + abs(g_eff) + abs(a_coef)) * zmag ** (power - 1)
                        / 0.05)
        h = dx / steps
        for _ in range(steps):
            az = abs(z)
            z = z + a_coef * h - b_eff * abs(h) * az ** (power - 1.0) * z \
                - g_eff * h * az ** power
        w[k] = k_lin * x[k] + z
        x_prev = x[k]
    return w


@njit(cache=True)
def _relays(x, x_rest, centres, halfwidths, weights, rise_scale, fall_scale, rate, rate_ref,
            fs):  # pragma: no cover - compiled
    # Preisach sum of relays: relay i switches up when x >= c_i + h_i rise_scale s, down when
    # x <= c_i - h_i fall_scale s, with s = 1 + rate |dx/dt| / rate_ref (wider at speed).
    n = x.size
    m = centres.size
    state = np.empty(m)
    for i in range(m):
        state[i] = 1.0 if x_rest > centres[i] else -1.0
    out = np.empty(n)
    x_prev = x_rest
    for k in range(n):
        dx = x[k] - x_prev
        s = 1.0 + rate * abs(dx) * fs / rate_ref
        acc = 0.0
        for i in range(m):
            if x[k] >= centres[i] + halfwidths[i] * rise_scale * s:
                state[i] = 1.0
            elif x[k] <= centres[i] - halfwidths[i] * fall_scale * s:
                state[i] = -1.0
            acc += weights[i] * state[i]
        out[k] = acc
        x_prev = x[k]
    return out


@njit(cache=True)
def _plays(x, x_rest, radii, weights, rise_scale, fall_scale, rate, rate_ref, fs, width_slope,
           width_centre, width_scale):  # pragma: no cover - compiled
    # Maxwell-slip: element i sticks while |x - p_i| < r_i and slips (p_i follows x at the
    # distance r_i) otherwise; its force is weights[i] (x - p_i). Radii grow with speed and with
    # level (width factor), and differ on rising / falling motion (rise_scale, fall_scale).
    n = x.size
    m = radii.size
    p = np.full(m, x_rest)
    out = np.empty(n)
    x_prev = x_rest
    for k in range(n):
        dx = x[k] - x_prev
        s = 1.0 + rate * abs(dx) * fs / rate_ref
        width = 1.0 + width_slope * (x[k] - width_centre) / width_scale
        if width < 0.1:
            width = 0.1
        acc = 0.0
        for i in range(m):
            r_up = radii[i] * rise_scale * s * width
            r_dn = radii[i] * fall_scale * s * width
            if x[k] - p[i] > r_up:
                p[i] = x[k] - r_up
            elif p[i] - x[k] > r_dn:
                p[i] = x[k] + r_dn
            acc += weights[i] * (x[k] - p[i])
        out[k] = acc
        x_prev = x[k]
    return out


# --------------------------------------------------------------------------- hysteresis blocks
class Hysteresis(Protocol):
    """A hysteresis block: maps the actuator input ``x = w1`` to its output ``w2``."""

    def response(self, x: np.ndarray, fs: float, x_rest: float) -> np.ndarray:
        """Output for the input ``x``, starting at rest at ``x_rest``.

        Parameters
        ----------
        x : ndarray
            Input samples.
        fs : float
            Sampling rate in Hz.
        x_rest : float
            Input level at rest before the first sample.

        Returns
        -------
        ndarray
            The output, as long as ``x``.
        """
        ...

    def rest_output(self, x_rest: float) -> float:
        """Output at rest at ``x_rest``.

        Parameters
        ----------
        x_rest : float
            Input level at rest.

        Returns
        -------
        float
            The output there.
        """
        ...


class _SpringAtRest:
    """Hysteresis whose memory term is zero at rest: the output there is ``k x_rest + offset``."""

    k: float
    offset: float

    def rest_output(self, x_rest: float) -> float:
        """Return ``k x_rest + offset`` (the memory term relaxed at rest).

        Parameters
        ----------
        x_rest : float
            Input at rest.

        Returns
        -------
        float
            Output at rest.
        """
        return float(self.k * x_rest + self.offset)


@dataclass(frozen=True)
class Duhem:
    """Discrete Duhem hysteresis of eqs. (7) / (24), with optional asymmetry.

    ``w2(k) = w2(k-1) + alpha [f0 sgn w1(k-1) + f1 w1(k-1) - w2(k-1)] |dw1(k)| + g0 dw1(k)``.

    Parameters
    ----------
    alpha, f1, g0 : float
        Coefficients of eq. (24).
    f0 : float, optional
        The sign term of eq. (7), by default 0 (as in eq. 24).
    asymmetry : float, optional
        Branch asymmetry a: alpha is ``alpha (1 + a)`` while w1 rises and ``alpha (1 - a)``
        while it falls, by default 0.
    width_slope : float, optional
        Level-dependent loop width: alpha is divided by
        ``1 + width_slope (w1 - width_centre) / width_scale``, by default 0.
    width_centre, width_scale : float, optional
        Reference level and scale of the width law, by default 0 and 1.
    """

    alpha: float
    f1: float
    g0: float
    f0: float = 0.0
    asymmetry: float = 0.0
    width_slope: float = 0.0
    width_centre: float = 0.0
    width_scale: float = 1.0

    def rest_output(self, x_rest: float) -> float:
        """Return the anhysteretic output ``f0 sgn(x) + f1 x`` taken as the rest state.

        Parameters
        ----------
        x_rest : float
            Input at rest.

        Returns
        -------
        float
            Output at rest.
        """
        return float(self.f0 * np.sign(x_rest) + self.f1 * x_rest)

    def response(self, x: np.ndarray, fs: float, x_rest: float) -> np.ndarray:
        """Simulate the Duhem recursion.

        Parameters
        ----------
        x : numpy.ndarray
            Input ``w1``.
        fs : float
            Sampling rate (unused: the discrete Duhem model is defined per sample).
        x_rest : float
            Input held before the first sample.

        Returns
        -------
        numpy.ndarray
            Output ``w2``.
        """
        return _duhem(
            np.ascontiguousarray(x, float), float(x_rest), self.rest_output(x_rest),
            self.alpha * (1 + self.asymmetry), self.alpha * (1 - self.asymmetry), self.f0,
            self.f1, self.g0, self.width_slope, self.width_centre, self.width_scale,
        )


@dataclass(frozen=True)
class BoucWen(_SpringAtRest):
    """Bouc-Wen hysteresis ``w2 = k x + z + offset``.

    ``dz = A dx - beta |dx| |z|^(n-1) z - gamma dx |z|^n``.

    The ordinary differential equation is integrated between samples along the straight line
    from ``x(k-1)`` to ``x(k)`` with enough explicit Euler sub-steps to be accurate. Loops of
    ``z`` saturate at ``(A / (beta + gamma))^(1/n)``.

    Parameters
    ----------
    k : float
        Reversible (linear) slope.
    a : float
        Bouc-Wen ``A``.
    beta, gamma : float
        Shape coefficients (``beta > |gamma|`` gives the usual counter-clockwise loops).
    power : float, optional
        Exponent ``n``, by default 1.
    offset : float, optional
        Constant added to the output, by default 0.
    rate : float, optional
        Rate dependence c: A, beta and gamma are multiplied by ``1 + c |dx/dt| / rate_ref``, so
        ``z`` reaches its bound ``A / (beta + gamma)`` over a shorter stroke and loops open up
        (become squarer) at speed, by default 0.
    rate_ref : float, optional
        Reference speed of ``x`` per second, by default 1000.
    asymmetry : float, optional
        ``A`` is ``A (1 + a)`` on rising and ``A (1 - a)`` on falling motion, by default 0.
    width_slope, width_centre, width_scale : float, optional
        Level-dependent loop width: beta and gamma are divided by
        ``1 + width_slope (x - width_centre) / width_scale``, by default 0, 0, 1.
    """

    k: float
    a: float
    beta: float
    gamma: float
    power: float = 1.0
    offset: float = 0.0
    rate: float = 0.0
    rate_ref: float = 1000.0
    asymmetry: float = 0.0
    width_slope: float = 0.0
    width_centre: float = 0.0
    width_scale: float = 1.0

    def response(self, x: np.ndarray, fs: float, x_rest: float) -> np.ndarray:
        """Integrate the Bouc-Wen equation.

        Parameters
        ----------
        x : numpy.ndarray
            Input ``w1``.
        fs : float
            Sampling rate in Hz (for the rate dependence).
        x_rest : float
            Input held before the first sample.

        Returns
        -------
        numpy.ndarray
            Output ``w2``.
        """
        return self.offset + _bouc_wen(
            np.ascontiguousarray(x, float), float(x_rest), 0.0, self.k,
            self.a * (1 + self.asymmetry), self.a * (1 - self.asymmetry), self.beta, self.gamma,
            float(self.power), self.rate, self.rate_ref, float(fs), self.width_slope,
            self.width_centre, self.width_scale,
        )


@dataclass(frozen=True)
class Preisach:
    """Preisach hysteresis: a linear term plus a grid of weighted relays.

    Relay ``(c, h)`` is +1 once ``x >= c + h`` and -1 once ``x <= c - h``; centres ``c`` cover
    ``[x_low, x_high]`` uniformly, half-widths ``h`` cover ``(0, h_max]``, and the weight of a
    relay is ``exp(-h / h_decay)`` times ``1 + width_slope (c - width_centre) / width_scale``,
    all scaled so that the relays together span ``relay_span`` of output.

    Parameters
    ----------
    k : float
        Reversible slope.
    x_low, x_high : float
        Range of relay centres (the input range the actuator is made for).
    relay_span : float
        Output change from all relays down to all relays up.
    h_max, h_decay : float
        Largest half-width and decay length of the weights over half-width.
    n_centres, n_widths : int, optional
        Grid size, by default 120 and 8.
    offset : float, optional
        Constant added to the output, by default 0.
    rate, rate_ref : float, optional
        Thresholds move away from the centre by the factor ``1 + rate |dx/dt| / rate_ref``.
    asymmetry : float, optional
        Up-thresholds use ``h (1 + a)``, down-thresholds ``h (1 - a)``, by default 0.
    width_slope, width_centre, width_scale : float, optional
        Level dependence of the relay weights (loop width), by default 0, 0, 1.
    """

    k: float
    x_low: float
    x_high: float
    relay_span: float
    h_max: float
    h_decay: float
    n_centres: int = 120
    n_widths: int = 8
    offset: float = 0.0
    rate: float = 0.0
    rate_ref: float = 1000.0
    asymmetry: float = 0.0
    width_slope: float = 0.0
    width_centre: float = 0.0
    width_scale: float = 1.0

    def _grid(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        centres = np.linspace(self.x_low, self.x_high, self.n_centres)
        halfwidths = self.h_max * (np.arange(self.n_widths) + 0.5) / self.n_widths
        c, h = (g.ravel() for g in np.meshgrid(centres, halfwidths, indexing="ij"))
        weights = np.exp(-h / self.h_decay)
        weights = weights * np.clip(
            1 + self.width_slope * (c - self.width_centre) / self.width_scale, 0.1, None
        )
        weights *= 0.5 * self.relay_span / weights.sum()
        return c, h, weights

    def rest_output(self, x_rest: float) -> float:
        """Return the output with every relay set by the side of its centre ``x_rest`` lies on.

        Parameters
        ----------
        x_rest : float
            Input at rest.

        Returns
        -------
        float
            Output at rest.
        """
        c, _, weights = self._grid()
        return float(self.k * x_rest + self.offset + np.sum(weights * np.where(x_rest > c, 1, -1)))

    def response(self, x: np.ndarray, fs: float, x_rest: float) -> np.ndarray:
        """Switch the relays along ``x``.

        Parameters
        ----------
        x : numpy.ndarray
            Input ``w1``.
        fs : float
            Sampling rate in Hz (for the rate dependence).
        x_rest : float
            Input held before the first sample.

        Returns
        -------
        numpy.ndarray
            Output ``w2``.
        """
        x = np.ascontiguousarray(x, float)
        c, h, weights = self._grid()
        relays = _relays(x, float(x_rest), c, h, weights, 1 + self.asymmetry,
                         1 - self.asymmetry, self.rate, self.rate_ref, float(fs))
        return self.k * x + self.offset + relays


@dataclass(frozen=True)
class MaxwellSlip(_SpringAtRest):
    """Maxwell-slip hysteresis: elasto-slip elements in parallel with a spring.

    Element i is a spring of stiffness ``s_i`` in series with a slider that slips once the spring
    stretches by ``r_i``; ``w2 = k x + sum_i s_i (x - p_i)`` with ``p_i`` the slider positions
    (a weighted sum of play operators). Radii are ``r_max (i + 1) / m``; stiffnesses decay as
    ``exp(-r_i / r_decay)`` and are scaled so that they add to ``slip_stiffness``.

    Parameters
    ----------
    k : float
        Stiffness of the spring that never slips (slope of the loop far from reversals).
    slip_stiffness : float
        Sum of the element stiffnesses (extra slope just after a reversal).
    r_max, r_decay : float
        Largest slip distance and decay length of the stiffnesses.
    n_elements : int, optional
        Number of elements, by default 16.
    offset : float, optional
        Constant added to the output, by default 0.
    rate, rate_ref : float, optional
        Slip distances grow by ``1 + rate |dx/dt| / rate_ref`` (viscous sliders), by default 0.
    asymmetry : float, optional
        Slip distance ``r (1 + a)`` on rising and ``r (1 - a)`` on falling motion, by default 0.
    width_slope, width_centre, width_scale : float, optional
        Slip distances scale with ``1 + width_slope (x - width_centre) / width_scale``.
    """

    k: float
    slip_stiffness: float
    r_max: float
    r_decay: float
    n_elements: int = 16
    offset: float = 0.0
    rate: float = 0.0
    rate_ref: float = 1000.0
    asymmetry: float = 0.0
    width_slope: float = 0.0
    width_centre: float = 0.0
    width_scale: float = 1.0

    def _elements(self) -> tuple[np.ndarray, np.ndarray]:
        radii = self.r_max * (np.arange(self.n_elements) + 1) / self.n_elements
        stiff = np.exp(-radii / self.r_decay)
        return radii, stiff * self.slip_stiffness / stiff.sum()

    def response(self, x: np.ndarray, fs: float, x_rest: float) -> np.ndarray:
        """Move the sliders along ``x``.

        Parameters
        ----------
        x : numpy.ndarray
            Input ``w1``.
        fs : float
            Sampling rate in Hz (for the rate dependence).
        x_rest : float
            Input held before the first sample.

        Returns
        -------
        numpy.ndarray
            Output ``w2``.
        """
        x = np.ascontiguousarray(x, float)
        radii, stiff = self._elements()
        plays = _plays(x, float(x_rest), radii, stiff, 1 + self.asymmetry, 1 - self.asymmetry,
                       self.rate, self.rate_ref, float(fs), self.width_slope, self.width_centre,
                       self.width_scale)
        return self.k * x + self.offset + plays


