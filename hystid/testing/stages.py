"""Simulated positioning stages L1 -> H -> L2 written from the equations, for tests and benchmarks.

A stage is a :class:`SandwichStage`: an input linear block :class:`Linear` (the amplifier and its
filter), a hysteresis block (the piezo actuator) and an output linear block (the flexure and its
load). Four hysteresis forms are provided (in :mod:`hystid.testing.hysteresis`), only the first
of which belongs to the paper's family:

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

import numpy as np
from numba import njit

from .hysteresis import BoucWen, Duhem, Hysteresis, MaxwellSlip, Preisach

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
