"""The built-in reference stage: the paper's identified model (eqs. 26-28) at 30 kHz.

:func:`reference_model` returns the model, :func:`paper_excitation` the paper's excitation (a PRBS
of 0.4-0.6 V modulated with a sine of decaying amplitude and frequency, at most 500 Hz, around an
offset that puts y in about 3.7-6 um) and :func:`reference_record` a noisy measured-like record.
"""

from __future__ import annotations

import numpy as np

from .model import DuhemSandwich, Structure
from .records import Record

__all__ = ["PAPER_PARAMS", "paper_excitation", "reference_model", "reference_record"]

#: The paper's identified stage, eqs. (26)-(28); y in micrometres, u in volts.
PAPER_PARAMS = {
    "alpha": 0.8365,
    "f1": 0.1354,
    "g0": 0.0042,
    "a11": -0.529,
    "a21": -1.6049,
    "a22": 0.9226,
}
FS = 30_000.0


def reference_model(fs: float = FS) -> DuhemSandwich:
    """The paper's identified sandwich (eqs. 26-28) with the experimental structure (24-25).

    Parameters
    ----------
    fs : float
        Sampling rate in Hz (the paper's 30 kHz).

    Returns
    -------
    DuhemSandwich
        The model, at rest at 0 V.
    """
    return DuhemSandwich(PAPER_PARAMS, Structure(), fs=fs, name="reference stage")


def paper_excitation(
    n: int,
    fs: float = FS,
    *,
    seed: int | None = 0,
    offset: float = 5.3,
    prbs_amplitude: tuple[float, float] = (0.4, 0.6),
    prbs_bit: int = 15,
    sine_amplitude: tuple[float, float] = (1.0, 0.3),
    sine_frequency: tuple[float, float] = (500.0, 20.0),
    decay_time: float = 0.5,
    ramp_time: float = 0.01,
) -> np.ndarray:
    """The paper's excitation: PRBS modulated with a decaying sine, around an offset.

    ``u(k) = r(k) [offset + A(t) sin(phi(t))] + p(k)`` where ``p`` is a PRBS whose level
    changes every ``prbs_bit`` samples with a random amplitude in ``prbs_amplitude`` (V) and a
    random sign, the sine's amplitude ``A`` and frequency decay exponentially (time constant
    ``decay_time``) from the first to the second value of ``sine_amplitude`` and
    ``sine_frequency`` (at most 500 Hz), and ``r`` is a raised-cosine ramp from rest over
    ``ramp_time`` seconds (a step from 0 V to 5 V would violate the Duhem stability condition 8).

    Parameters
    ----------
    n : int
        Number of samples.
    fs : float
        Sampling rate in Hz.
    seed : int or None
        Seed of the PRBS (reproducible by default).
    offset : float
        Centre of the input in V.
    prbs_amplitude : tuple of float
        Range of the PRBS level's amplitude in V.
    prbs_bit : int
        Samples per PRBS level.
    sine_amplitude, sine_frequency : tuple of float
        Start and end amplitude (V) and frequency (Hz) of the decaying sine.
    decay_time : float
        Time constant of the decay in seconds.
    ramp_time : float
        Seconds of the raised-cosine ramp from rest.

    Returns
    -------
    ndarray
        Input voltage, ``n`` samples.
    """
    if int(n) != n or n < 1:
        raise ValueError(f"n: expected a positive number of samples, got {n!r}")
    if max(sine_frequency) > 500.0:
        raise ValueError("sine_frequency: the paper's excitation stays at or below 500 Hz")
    n = int(n)
    rng = np.random.default_rng(seed)
    t = np.arange(n) / fs
    nbits = -(-n // prbs_bit)
    levels = rng.uniform(*prbs_amplitude, nbits) * rng.choice([-1.0, 1.0], nbits)
    p = np.repeat(levels, prbs_bit)[:n]
    decay = np.exp(-t / decay_time)
    amp = sine_amplitude[1] + (sine_amplitude[0] - sine_amplitude[1]) * decay
    freq = sine_frequency[1] + (sine_frequency[0] - sine_frequency[1]) * decay
    phase = 2 * np.pi * np.cumsum(freq) / fs
    ramp = np.clip(t / ramp_time, 0.0, 1.0) if ramp_time > 0 else np.ones(n)
    ramp = 0.5 - 0.5 * np.cos(np.pi * ramp)
    return ramp * (offset + amp * np.sin(phase) + p)


def reference_record(
    seconds: float = 1.0,
    *,
    seed: int | None = 0,
    noise: float = 1e-3,
    model: DuhemSandwich | None = None,
    u: np.ndarray | None = None,
    name: str = "reference stage",
) -> Record:
    """A record from the reference stage: excitation, simulation from rest, sensor noise.

    Parameters
    ----------
    seconds : float
        Record length in seconds (30 000 samples per second).
    seed : int or None
        Seed for the excitation and the noise.
    noise : float
        Standard deviation of the white capacitive-sensor noise in um (1 nm by default).
    model : DuhemSandwich, optional
        Stage to simulate instead of :func:`reference_model`.
    u : ndarray, optional
        Input to use instead of :func:`paper_excitation`.
    name : str
        Name of the record.

    Returns
    -------
    Record
        ``u`` in V and ``y`` in um, starting at rest.
    """
    model = model or reference_model()
    if not (np.isfinite(noise) and noise >= 0):
        raise ValueError(f"noise: expected a non-negative standard deviation in um, got {noise!r}")
    if u is None:
        n = int(round(seconds * model.fs))
        u = paper_excitation(n, model.fs, seed=seed)
    y = model.simulate(u).y
    rng = np.random.default_rng(None if seed is None else seed + 1_000_003)
    y = y + noise * rng.standard_normal(len(y))
    return Record(u=np.asarray(u, float), y=y, fs=model.fs, units={"u": "V", "y": "um"}, name=name)
