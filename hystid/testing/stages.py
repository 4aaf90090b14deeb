"""Simulated positioning stages L1 -> H -> L2 written from the equations, for tests and benchmarks.

A stage is a :class:`SandwichStage`: an input linear block :class:`Linear` (the amplifier and its
filter), a hysteresis block (the piezo actuator) and an output linear block (the flexure and its
load). Four hysteresis forms are provided, only the first of which belongs to the paper's family:

- :class:`Duhem` -- the discrete Duhem model of eqs. (7) and (24),
- :class:`BoucWen` -- a Bouc-Wen differential equation integrated between samples,
- :class:`Preisach` -- a weighted grid of relay hysterons,
- :class:`MaxwellSlip` -- elasto-slip elements (weighted play operators).

The blocks are simulated one after the other (there is no feedback around the sandwich), each with
a compiled loop. Every block starts at rest: the input is taken to have been held at ``u_rest``
(the first input sample unless stated) for ever before the record.

:func:`paper_stage` builds the reference stage of eqs. (26)-(28); :func:`paper_stage_loop` is a
literal transcription of those three equations used to check the general machinery;
:func:`paper_excitation` builds an input like the paper's (a decaying, frequency-swept sine whose
amplitude is modulated by a PRBS, around 5.3 V, ramped up from rest).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import Protocol

import numpy as np
from numba import njit

__all__ = [
    "PAPER",
    "BoucWen",
    "Duhem",
    "Hysteresis",
    "Linear",
    "MaxwellSlip",
    "Preisach",
    "SandwichStage",
    "continuous_linear",
    "make_hysteresis",
    "paper_excitation",
    "paper_like_stage",
    "paper_stage",
    "paper_stage_loop",
    "prbs",
]

#: Coefficients of the paper's identified stage, eqs. (26)-(28), sampled at ``fs`` = 30 kHz.
PAPER: dict[str, float] = {
    "a11": -0.529,
    "alpha": 0.8365,
    "f1": 0.1354,
    "g0": 0.0042,
    "a21": -1.6049,
    "a22": 0.9226,
    "fs": 30_000.0,
}


# --------------------------------------------------------------------------- compiled loops
@njit(cache=True)
def _difference_equation(b, a, delay, x, x_rest, w_rest):  # pragma: no cover - compiled
    # w(k) = sum_j b[j] x(k - delay - j) - sum_i a[i] w(k - 1 - i), with x = x_rest and
    # w = w_rest before k = 0.
    n = x.size
    w = np.empty(n)
    for k in range(n):
        acc = 0.0
        for j in range(b.size):
            m = k - delay - j
            acc += b[j] * (x[m] if m >= 0 else x_rest)
        for i in range(a.size):
            m = k - 1 - i
            acc -= a[i] * (w[m] if m >= 0 else w_rest)
        w[k] = acc
    return w


@njit(cache=True)
def _paper_loop(u, a11, alpha, f1, g0, a21, a22):  # pragma: no cover - compiled
    # Eqs. (26)-(28) verbatim; everything is zero before k = 0 (rest at u = 0).
    n = u.size
    w1 = np.zeros(n)
    w2 = np.zeros(n)
    y = np.zeros(n)
    w1_prev = 0.0
    w2_prev = 0.0
    y_prev = 0.0
    y_prev2 = 0.0
    u_prev = 0.0
    for k in range(n):
        w1_k = -a11 * w1_prev + u_prev
        dw1 = w1_k - w1_prev
        w2_k = w2_prev + alpha * (f1 * w1_prev - w2_prev) * abs(dw1) + g0 * dw1
        y_k = -a21 * y_prev - a22 * y_prev2 + w2_k
        w1[k] = w1_k
        w2[k] = w2_k
        y[k] = y_k
        u_prev = u[k]
        w1_prev = w1_k
        w2_prev = w2_k
        y_prev2 = y_prev
        y_prev = y_k
    return w1, w2, y


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


# --------------------------------------------------------------------------- linear blocks
@dataclass(frozen=True)
class Linear:
    """A discrete linear block ``w(k) = sum_j b_j x(k - delay - j) - sum_i a_i w(k - i)``.

    This is eq. (1) / eq. (2) of the paper with ``b = (b_0, b_1, ...)``, ``a = (a_1, a_2, ...)``
    and ``delay`` = q.

    Parameters
    ----------
    b : tuple of float
        Numerator coefficients ``b_0, b_1, ...`` (the paper fixes ``b_0 = 1``).
    a : tuple of float
        Denominator coefficients ``a_1, a_2, ...`` (the leading 1 omitted).
    delay : int, optional
        Pure delay q in samples, by default 0.
    """

    b: tuple[float, ...]
    a: tuple[float, ...] = ()
    delay: int = 0

    @property
    def dc_gain(self) -> float:
        """float: Static gain ``sum(b) / (1 + sum(a))``."""
        return float(sum(self.b) / (1.0 + sum(self.a)))

    def filter(self, x: np.ndarray, x_rest: float | None = None) -> np.ndarray:
        """Run the difference equation from rest.

        Parameters
        ----------
        x : numpy.ndarray
            Input samples.
        x_rest : float, optional
            Input level held before the first sample, by default ``x[0]``; the output starts at
            the matching equilibrium ``dc_gain * x_rest``.

        Returns
        -------
        numpy.ndarray
            Output samples, same length as ``x``.
        """
        x = np.ascontiguousarray(x, dtype=float)
        rest = float(x[0]) if x_rest is None else float(x_rest)
        return _difference_equation(
            np.asarray(self.b, float), np.asarray(self.a, float), int(self.delay), x, rest,
            self.dc_gain * rest,
        )


def continuous_linear(
    fs: float,
    *,
    gain: float = 1.0,
    pole_hz: float | None = None,
    mode_hz: float | None = None,
    damping: float = 0.05,
    delay: int = 0,
) -> Linear:
    """Discretise a first-order lag or a second-order mode by pole matching ``z = exp(s / fs)``.

    Parameters
    ----------
    fs : float
        Sampling rate in Hz.
    gain : float, optional
        Static gain of the block, by default 1.
    pole_hz : float, optional
        Corner frequency of a first-order lag (give this or ``mode_hz``).
    mode_hz : float, optional
        Natural frequency of a second-order mode.
    damping : float, optional
        Damping ratio of the mode, by default 0.05.
    delay : int, optional
        Samples of pure delay; a first-order lag gets at least one (``b_0`` acts on x(k - 1)).

    Returns
    -------
    Linear
        The discrete block with numerator ``b_0`` only, scaled for the requested static gain.
    """
    if (pole_hz is None) == (mode_hz is None):
        raise ValueError("give exactly one of pole_hz and mode_hz")
    if pole_hz is not None:
        p = math.exp(-2 * math.pi * pole_hz / fs)
        a: tuple[float, ...] = (-p,)
    else:
        wn = 2 * math.pi * float(mode_hz)
        r = math.exp(-damping * wn / fs)
        theta = wn * math.sqrt(1.0 - damping**2) / fs
        a = (-2 * r * math.cos(theta), r * r)
    return Linear(b=(gain * (1.0 + sum(a)),), a=a, delay=delay)


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


# --------------------------------------------------------------------------- the stage
@dataclass(frozen=True)
class SandwichStage:
    """A stage ``u -> L1 -> w1 -> H -> w2 -> L2 -> y`` at one sampling rate.

    Parameters
    ----------
    l1 : Linear
        Input block (amplifier and filter), eq. (1).
    hysteresis : Hysteresis
        Actuator block, e.g. :class:`Duhem` or :class:`BoucWen`.
    l2 : Linear
        Output block (flexure and load), eq. (2).
    fs : float
        Sampling rate in Hz the coefficients are designed for.
    name : str, optional
        Label, by default ``"stage"``.
    """

    l1: Linear
    hysteresis: Hysteresis
    l2: Linear
    fs: float
    name: str = field(default="stage")

    def simulate(self, u: np.ndarray, *, u_rest: float | None = None) -> dict[str, np.ndarray]:
        """Simulate the stage from rest.

        Parameters
        ----------
        u : numpy.ndarray
            Input samples.
        u_rest : float, optional
            Input held before the record, by default ``u[0]``.

        Returns
        -------
        dict
            ``"u"``, ``"w1"``, ``"w2"`` and ``"y"``, arrays of the length of ``u``.
        """
        u = np.ascontiguousarray(u, dtype=float)
        rest = float(u[0]) if u_rest is None else float(u_rest)
        w1 = self.l1.filter(u, rest)
        w1_rest = self.l1.dc_gain * rest
        w2 = self.hysteresis.response(w1, self.fs, w1_rest)
        y = self.l2.filter(w2, self.hysteresis.rest_output(w1_rest))
        return {"u": u, "w1": w1, "w2": w2, "y": y}

    def with_hysteresis(self, hysteresis: Hysteresis) -> SandwichStage:
        """Return the same stage with another hysteresis block.

        Parameters
        ----------
        hysteresis : Hysteresis
            The new block.

        Returns
        -------
        SandwichStage
            A copy.
        """
        return replace(self, hysteresis=hysteresis)


def paper_stage(*, n1: int = 1, n2: int = 2, q1: int = 1, q2: int = 0) -> SandwichStage:
    """Return the reference stage of eqs. (26)-(28) at 30 kHz, optionally with other orders/delays.

    Parameters
    ----------
    n1 : int, optional
        Order of L1 (1 is the paper's). Extra poles are added at z = 0.2 (a fast filter).
    n2 : int, optional
        Order of L2 (2 is the paper's). Extra poles are added at z = 0.3.
    q1 : int, optional
        Delay of L1 in samples (1 is the paper's: ``w1(k)`` depends on ``u(k-1)``).
    q2 : int, optional
        Delay of L2 in samples (0 is the paper's).

    Returns
    -------
    SandwichStage
        With extra poles the numerator is rescaled so the static gains stay 2.12 and 3.15.
    """
    p = PAPER
    den1 = np.poly1d([1.0, p["a11"]])
    for _ in range(n1 - 1):
        den1 = den1 * np.poly1d([1.0, -0.2])
    den2 = np.poly1d([1.0, p["a21"], p["a22"]])
    for _ in range(n2 - 2):
        den2 = den2 * np.poly1d([1.0, -0.3])
    a1 = tuple(float(v) for v in den1.coeffs[1:])
    a2 = tuple(float(v) for v in den2.coeffs[1:])
    g1 = 1.0 / (1 + p["a11"])
    g2 = 1.0 / (1 + p["a21"] + p["a22"])
    l1 = Linear(b=(g1 * (1 + sum(a1)),), a=a1, delay=q1)
    l2 = Linear(b=(g2 * (1 + sum(a2)),), a=a2, delay=q2)
    if n1 == 1:
        l1 = Linear(b=(1.0,), a=a1, delay=q1)
    if n2 == 2:
        l2 = Linear(b=(1.0,), a=a2, delay=q2)
    h = Duhem(alpha=p["alpha"], f1=p["f1"], g0=p["g0"])
    return SandwichStage(l1, h, l2, p["fs"], name="paper")


def paper_stage_loop(u: np.ndarray) -> dict[str, np.ndarray]:
    """Simulate eqs. (26)-(28) literally, from rest at ``u = 0``.

    Parameters
    ----------
    u : numpy.ndarray
        Input at 30 kHz, in volts.

    Returns
    -------
    dict
        ``"w1"``, ``"w2"``, ``"y"`` (micrometres).
    """
    p = PAPER
    w1, w2, y = _paper_loop(np.ascontiguousarray(u, float), p["a11"], p["alpha"], p["f1"],
                            p["g0"], p["a21"], p["a22"])
    return {"w1": w1, "w2": w2, "y": y}


def make_hysteresis(kind: str, *, x_low: float = 0.0, x_high: float = 21.2,
                    rate: float | None = None) -> Hysteresis:
    """Return a hysteresis block of the given kind sized like the paper's actuator.

    The non-Duhem forms are scaled so that, over an input ``w1`` of a few units around the paper's
    operating point (``w1`` about 11), they give a slope near ``f1 = 0.135`` and branches a few
    tenths apart, like eq. (27).

    Parameters
    ----------
    kind : {"duhem", "bouc_wen", "preisach", "maxwell"}
        The form.
    x_low, x_high : float, optional
        Input range the actuator is made for (relay centres of the Preisach form), by default
        0 to 21.2 (0-10 V through L1's gain of 2.12).
    rate : float, optional
        Rate dependence (see each class), by default 0.3 for Bouc-Wen and 0.2 for Preisach and
        Maxwell-slip; ignored for Duhem.

    Returns
    -------
    Hysteresis
        The block.
    """
    p = PAPER
    if kind == "duhem":
        return Duhem(alpha=p["alpha"], f1=p["f1"], g0=p["g0"])
    if kind == "bouc_wen":
        return BoucWen(k=0.122, a=0.09, beta=0.45, gamma=0.15,
                       rate=0.3 if rate is None else rate, rate_ref=3000.0)
    if kind == "preisach":
        span = 0.065 * (x_high - x_low)
        return Preisach(k=0.07, x_low=x_low, x_high=x_high, relay_span=span, h_max=2.0,
                        h_decay=1.0, offset=0.5 * span, rate=0.2 if rate is None else rate,
                        rate_ref=3000.0)
    if kind == "maxwell":
        return MaxwellSlip(k=0.12, slip_stiffness=0.12, r_max=3.0, r_decay=1.0,
                           rate=0.2 if rate is None else rate, rate_ref=3000.0)
    raise ValueError(f"unknown hysteresis {kind!r} (expected duhem, bouc_wen, preisach, maxwell)")


def paper_like_stage(fs: float = 30_000.0, hysteresis: str | Hysteresis = "duhem") -> SandwichStage:
    """Return the paper's stage redesigned for another rate and/or another hysteresis.

    L1's pole (3.04 kHz) and L2's mode (2.78 kHz, damping 0.013) are mapped to ``fs`` with
    ``z = exp(s / fs)`` and the static gains (2.12, 3.15) are kept, so at 30 kHz with Duhem
    hysteresis the stage is eqs. (26)-(28) up to round-off.

    Parameters
    ----------
    fs : float, optional
        Sampling rate in Hz, by default 30 kHz.
    hysteresis : str or Hysteresis, optional
        A kind for :func:`make_hysteresis` or a block, by default ``"duhem"``.

    Returns
    -------
    SandwichStage
        The stage.
    """
    p = PAPER
    s1 = math.log(-p["a11"]) * p["fs"]  # negative real pole of L1 in rad/s
    roots = np.roots([1.0, p["a21"], p["a22"]])
    s2 = np.log(roots[0]) * p["fs"]
    wn = abs(s2)
    zeta = -s2.real / wn
    g1 = 1.0 / (1 + p["a11"])
    g2 = 1.0 / (1 + p["a21"] + p["a22"])
    l1 = continuous_linear(fs, gain=g1, pole_hz=-s1 / (2 * math.pi), delay=1)
    l2 = continuous_linear(fs, gain=g2, mode_hz=wn / (2 * math.pi), damping=zeta)
    h = make_hysteresis(hysteresis) if isinstance(hysteresis, str) else hysteresis
    return SandwichStage(l1, h, l2, float(fs), name=f"paper-like {fs / 1000:g} kHz")


# --------------------------------------------------------------------------- excitation
def prbs(n_bits: int, *, order: int = 9, seed: int = 0) -> np.ndarray:
    """Return a maximal-length pseudo-random binary sequence of 0 / 1 from a linear shift register.

    Parameters
    ----------
    n_bits : int
        Number of bits wanted (the 2^order - 1 periodic sequence is repeated as needed).
    order : int, optional
        Register length, one of 7, 9, 10, 11, by default 9.
    seed : int, optional
        Picks the non-zero starting state of the register.

    Returns
    -------
    numpy.ndarray
        ``n_bits`` values in {0, 1}.
    """
    taps = {7: (7, 6), 9: (9, 5), 10: (10, 7), 11: (11, 9)}[order]
    rng = np.random.default_rng(seed)
    state = int(rng.integers(1, 2**order))
    out = np.empty(n_bits)
    for i in range(n_bits):
        bit = ((state >> (taps[0] - 1)) ^ (state >> (taps[1] - 1))) & 1
        state = ((state << 1) | bit) & (2**order - 1)
        out[i] = bit
    return out


def paper_excitation(
    seconds: float = 1.0,
    fs: float = 30_000.0,
    *,
    level: float = 5.3,
    amplitude: tuple[float, float] = (2.3, 1.7),
    frequency: tuple[float, float] = (500.0, 40.0),
    prbs_levels: tuple[float, float] = (0.4, 0.6),
    bit_seconds: float = 1e-3,
    ramp_seconds: float = 0.01,
    seed: int = 0,
) -> np.ndarray:
    """Return an input like the paper's: ``level + r(t) p(t) A(t) sin(phi(t))``.

    ``p(t)`` is a PRBS between 0.4 and 0.6 (one bit every ``bit_seconds``), ``A(t)`` decays
    exponentially from ``amplitude[0]`` to ``amplitude[1]`` volts, the frequency decays
    exponentially from 500 Hz, and ``r(t)`` ramps the whole input (level included) up from 0 V
    with a raised cosine over ``ramp_seconds``, so the record starts at rest and the Duhem
    stability condition (8) holds.

    Parameters
    ----------
    seconds : float, optional
        Duration, by default 1 s.
    fs : float, optional
        Sampling rate in Hz, by default 30 kHz.
    level : float, optional
        Operating point in volts, by default 5.3.
    amplitude : tuple of float, optional
        Sine amplitude at the start and at the end, by default (2.3, 1.7) V.
    frequency : tuple of float, optional
        Sine frequency at the start and at the end, by default (500, 40) Hz.
    prbs_levels : tuple of float, optional
        The two PRBS values, by default (0.4, 0.6).
    bit_seconds : float, optional
        PRBS bit duration, by default 1 ms.
    ramp_seconds : float, optional
        Ramp-up from 0 V, by default 10 ms.
    seed : int, optional
        Seed of the PRBS register state and of the sine phase.

    Returns
    -------
    numpy.ndarray
        The input in volts, ``round(seconds * fs)`` samples.
    """
    n = int(round(seconds * fs))
    t = np.arange(n) / fs
    frac = t / max(seconds, 1e-12)
    amp = amplitude[0] * (amplitude[1] / amplitude[0]) ** frac
    freq = frequency[0] * (frequency[1] / frequency[0]) ** frac
    rng = np.random.default_rng(seed)
    phase = 2 * np.pi * np.cumsum(freq) / fs + rng.uniform(0, 2 * np.pi)
    bit_len = max(1, int(round(bit_seconds * fs)))
    bits = prbs(n // bit_len + 1, seed=int(rng.integers(2**31)))
    p = np.where(np.repeat(bits, bit_len)[:n] > 0, prbs_levels[1], prbs_levels[0])
    ramp = np.clip(t / ramp_seconds, 0, 1) if ramp_seconds > 0 else np.ones(n)
    ramp = 0.5 - 0.5 * np.cos(np.pi * ramp)
    return ramp * (level + p * amp * np.sin(phase))
