"""Records "as measured": the transformations a real acquisition applies, and stage look-alikes.

Every transformation takes a :class:`~hystid.records.Record` and returns a new one, so they
compose: ``with_noise(with_offset(rec, -0.7), 0.5e-3, seed=1)``. Transformations that need the
stage itself (another sampling rate, a non-zero rest level, repeats) take the stage and the input
instead.

:func:`stage_a_like` and :func:`stage_b_like` imitate two measured stages (ranges, sampling rate,
offsets, resting start, repeat-to-repeat variation) with hysteresis forms outside the Duhem
family; :func:`as_measured_suite` returns the named records the identification tests run on.
"""

from __future__ import annotations

import math

import numpy as np
from scipy import signal

from hystid.records import Record

from .stages import (
    BoucWen,
    Preisach,
    SandwichStage,
    continuous_linear,
    paper_excitation,
    paper_like_stage,
    paper_stage,
)

__all__ = [
    "UNIT_FACTORS",
    "as_measured_suite",
    "coloured_variations",
    "crop_start",
    "hold_then_excite",
    "record_from",
    "repeats",
    "replace_name",
    "simulate_at_rate",
    "stage_a",
    "stage_a_like",
    "stage_b",
    "stage_b_like",
    "with_burst",
    "with_clipping",
    "with_end_glitch",
    "with_noise",
    "with_offset",
    "with_outliers",
    "with_units",
]

#: Value of one unit in the base unit of its quantity (volt for "u", micrometre for "y").
UNIT_FACTORS: dict[str, float] = {
    "V": 1.0,
    "kV": 1e3,
    "mV": 1e-3,
    "V/100": 100.0,  # a monitor output reading 1 for 100 V at the actuator
    "um": 1.0,
    "nm": 1e-3,
    "mm": 1e3,
    "m": 1e6,
}


def record_from(sim: dict[str, np.ndarray], fs: float, name: str) -> Record:
    """Wrap the ``"u"`` and ``"y"`` of a simulation into a record in volts and micrometres.

    Parameters
    ----------
    sim : dict
        Output of :meth:`~hystid.testing.stages.SandwichStage.simulate` or
        :func:`~hystid.testing.effects.simulate_stage`.
    fs : float
        Sampling rate in Hz.
    name : str
        Record name.

    Returns
    -------
    Record
        A new record (the arrays are copied).
    """
    return Record(u=np.array(sim["u"]), y=np.array(sim["y"]), fs=fs,
                  units={"u": "V", "y": "um"}, name=name)


def _copy(rec: Record, *, u: np.ndarray | None = None, y: np.ndarray | None = None,
          fs: float | None = None, units: dict[str, str] | None = None,
          name: str | None = None) -> Record:
    return Record(u=np.array(rec.u if u is None else u), y=np.array(rec.y if y is None else y),
                  fs=rec.fs if fs is None else fs,
                  units=dict(rec.units if units is None else units),
                  name=rec.name if name is None else name)


# --------------------------------------------------------------------------- record transforms
def with_offset(rec: Record, offset: float) -> Record:
    """Add a sensor zero offset to the output.

    Parameters
    ----------
    rec : Record
        The record.
    offset : float
        Offset in the output's units.

    Returns
    -------
    Record
        ``y + offset``.
    """
    return _copy(rec, y=rec.y + offset)


def with_units(rec: Record, *, u: str | None = None, y: str | None = None) -> Record:
    """Express the input and/or output in other units (exact scaling).

    Parameters
    ----------
    rec : Record
        The record.
    u : str, optional
        New input unit, a key of :data:`UNIT_FACTORS` (``"V"``, ``"kV"``, ``"mV"``, ``"V/100"``).
    y : str, optional
        New output unit (``"um"``, ``"nm"``, ``"mm"``, ``"m"``).

    Returns
    -------
    Record
        With ``u * factor(old) / factor(new)`` and the units updated.
    """
    units = dict(rec.units)
    new_u, new_y = rec.u, rec.y
    if u is not None:
        new_u = rec.u * (UNIT_FACTORS[units["u"]] / UNIT_FACTORS[u])
        units["u"] = u
    if y is not None:
        new_y = rec.y * (UNIT_FACTORS[units["y"]] / UNIT_FACTORS[y])
        units["y"] = y
    return _copy(rec, u=new_u, y=new_y, units=units)


def crop_start(rec: Record, seconds: float) -> Record:
    """Drop the beginning of a record, so that it starts mid-motion (not at rest).

    Parameters
    ----------
    rec : Record
        The record.
    seconds : float
        Time to drop.

    Returns
    -------
    Record
        The rest of the record.
    """
    k = int(round(seconds * rec.fs))
    return _copy(rec, u=rec.u[k:], y=rec.y[k:])


def with_outliers(rec: Record, count: int = 1, size: float = 1.0, *, seed: int = 0) -> Record:
    """Replace isolated output samples by outliers.

    Parameters
    ----------
    rec : Record
        The record.
    count : int, optional
        Number of outliers, by default 1; they are at least 10 samples apart and away from the ends.
    size : float, optional
        Outlier height in output units (random sign), by default 1.
    seed : int, optional
        Seed of the positions and signs.

    Returns
    -------
    Record
        With ``y[k] += +-size`` at ``count`` positions.
    """
    rng = np.random.default_rng(seed)
    slots = np.arange(10, rec.n - 10, 10)
    where = np.sort(rng.choice(slots, size=count, replace=False))
    y = rec.y.copy()
    y[where] += size * rng.choice([-1.0, 1.0], size=count)
    return _copy(rec, y=y)


def with_burst(rec: Record, start: float, seconds: float, size: float, *, seed: int = 0) -> Record:
    """Add a burst of large white noise to the output over a short interval.

    Parameters
    ----------
    rec : Record
        The record.
    start : float
        Start of the burst, as a fraction of the record (0 to 1).
    seconds : float
        Duration of the burst.
    size : float
        RMS of the burst in output units.
    seed : int, optional
        Seed of the noise.

    Returns
    -------
    Record
        With the burst added.
    """
    rng = np.random.default_rng(seed)
    k0 = int(start * rec.n)
    k1 = min(rec.n, k0 + max(1, int(round(seconds * rec.fs))))
    y = rec.y.copy()
    y[k0:k1] += size * rng.standard_normal(k1 - k0)
    return _copy(rec, y=y)


def with_clipping(rec: Record, low: float | None = None, high: float | None = None) -> Record:
    """Clip the output as a sensor at the end of its range does.

    Parameters
    ----------
    rec : Record
        The record.
    low, high : float, optional
        Sensor limits in output units.

    Returns
    -------
    Record
        ``clip(y, low, high)``.
    """
    return _copy(rec, y=np.clip(rec.y, low, high))


def with_end_glitch(rec: Record) -> Record:
    """Wrap the last input sample back to the first value, as some signal generators do.

    The output is kept: every stage here responds to ``u(k)`` at ``k + 1`` or later, so the
    glitch's effect falls after the record.

    Parameters
    ----------
    rec : Record
        The record.

    Returns
    -------
    Record
        With ``u[-1] = u[0]``.
    """
    u = rec.u.copy()
    u[-1] = u[0]
    return _copy(rec, u=u)


def with_noise(rec: Record, rms: float, *, seed: int = 0) -> Record:
    """Add white Gaussian sensor noise.

    Parameters
    ----------
    rec : Record
        The record.
    rms : float
        Noise standard deviation in output units.
    seed : int, optional
        Seed of the noise.

    Returns
    -------
    Record
        With the noise added.
    """
    rng = np.random.default_rng(seed)
    return _copy(rec, y=rec.y + rms * rng.standard_normal(rec.n))


# --------------------------------------------------------------------------- stage-level transforms
def hold_then_excite(u: np.ndarray, fs: float, *, level: float | None = None,
                     seconds: float = 0.05, blend_seconds: float = 0.002) -> np.ndarray:
    """Prepend a hold at a non-zero level to an input, blended smoothly into the excitation.

    Parameters
    ----------
    u : numpy.ndarray
        The excitation.
    fs : float
        Sampling rate in Hz.
    level : float, optional
        Held level, by default ``u[0]``.
    seconds : float, optional
        Hold duration, by default 50 ms.
    blend_seconds : float, optional
        Raised-cosine blend from the level into the excitation, by default 2 ms.

    Returns
    -------
    numpy.ndarray
        ``hold`` followed by the excitation.
    """
    lev = float(u[0]) if level is None else float(level)
    n_hold = int(round(seconds * fs))
    out = np.asarray(u, float).copy()
    nb = min(out.size, max(1, int(round(blend_seconds * fs))))
    s = 0.5 - 0.5 * np.cos(np.pi * np.arange(nb) / nb)
    out[:nb] = lev + s * (out[:nb] - lev)
    return np.concatenate([np.full(n_hold, lev), out])


def simulate_at_rate(stage: SandwichStage, u: np.ndarray, fs: float, *,
                     u_rest: float | None = None) -> dict[str, np.ndarray]:
    """Simulate a stage running faster than the acquisition, as a sampled continuous system.

    The input, given at ``fs``, is held (zero-order hold, like a DAC) for ``stage.fs / fs``
    stage samples; the output is low-pass filtered (an 8th-order Chebyshev type I anti-alias
    filter at 0.8 of the new Nyquist rate with unit static gain, applied forwards and
    backwards) and taken every
    ``stage.fs / fs`` samples.

    Parameters
    ----------
    stage : SandwichStage
        The stage, with ``stage.fs`` an integer multiple of ``fs``.
    u : numpy.ndarray
        Input at ``fs``.
    fs : float
        Acquisition rate in Hz.
    u_rest : float, optional
        Input held before the record, by default ``u[0]``.

    Returns
    -------
    dict
        ``"u"`` (as given) and ``"y"`` at ``fs``, plus ``"y_fast"`` at ``stage.fs``.
    """
    ratio = stage.fs / fs
    q = int(round(ratio))
    if q < 1 or abs(ratio - q) > 1e-9:
        raise ValueError(f"stage.fs / fs must be an integer (got {ratio:g})")
    u = np.asarray(u, float)
    sim = stage.simulate(np.repeat(u, q), u_rest=u_rest)
    y_fast = sim["y"]
    if q > 1:
        b, a = signal.cheby1(8, 0.05, 0.8 / q)
        b = b * (np.sum(a) / np.sum(b))  # unit static gain (even orders sit at the ripple's low)
        y_smooth = signal.filtfilt(b, a, y_fast, padlen=min(3 * max(len(a), len(b)) * 10,
                                                             y_fast.size - 1))
    else:
        y_smooth = y_fast
    return {"u": u, "y": y_smooth[::q], "y_fast": y_fast}


def coloured_variations(n: int, count: int, rms: float, fs: float, *, corner_hz: float = 3.0,
                        seed: int = 0) -> np.ndarray:
    """Return ``count`` slow random signals whose pairwise differences have RMS ``rms`` exactly.

    White noise is low-pass filtered (second order, corner ``corner_hz``), made zero-mean and
    mutually orthogonal (QR decomposition), and scaled to RMS ``rms / sqrt(2)`` each, so that
    ``rms(v_i - v_j) = rms`` for every pair.

    Parameters
    ----------
    n : int
        Samples per signal (``n > count``).
    count : int
        Number of signals.
    rms : float
        RMS of the difference of any two signals.
    fs : float
        Sampling rate in Hz.
    corner_hz : float, optional
        Corner frequency of the colouring filter, by default 3 Hz.
    seed : int, optional
        Seed of the noise.

    Returns
    -------
    numpy.ndarray
        Shape ``(count, n)``.
    """
    rng = np.random.default_rng(seed)
    b, a = signal.butter(2, min(corner_hz / (fs / 2), 0.99))
    raw = signal.lfilter(b, a, rng.standard_normal((count, n + 2000)), axis=1)[:, 2000:]
    raw -= raw.mean(axis=1, keepdims=True)
    q, _ = np.linalg.qr(raw.T)  # orthonormal columns, zero-mean (combinations of zero-mean rows)
    return q.T * (rms / math.sqrt(2.0)) * math.sqrt(n)


def repeats(stage: SandwichStage, u: np.ndarray, *, count: int = 3, rms: float = 0.027,
            corner_hz: float = 3.0, noise_rms: float = 0.0, seed: int = 0,
            name: str = "repeat") -> list[Record]:
    """Simulate the same input several times with slow repeat-to-repeat variation.

    Each repeat's output gets its own slow coloured variation (see
    :func:`coloured_variations`), so any two repeats differ by ``rms`` (plus the white sensor
    noise).

    Parameters
    ----------
    stage : SandwichStage
        The stage.
    u : numpy.ndarray
        The common input, at ``stage.fs``.
    count : int, optional
        Number of repeats, by default 3.
    rms : float, optional
        RMS of the difference between two repeats, output units, by default 0.027 (27 nm).
    corner_hz : float, optional
        Corner of the variation's spectrum, by default 3 Hz.
    noise_rms : float, optional
        White sensor noise per repeat, by default 0.
    seed : int, optional
        Seed of the variations and of the noise.

    name : str, optional
        Prefix of the record names, by default ``"repeat"``.

    Returns
    -------
    list of Record
        ``count`` records named ``f"{name}-{i}"``.
    """
    sim = stage.simulate(u)
    var = coloured_variations(len(u), count, rms, stage.fs, corner_hz=corner_hz, seed=seed)
    rng = np.random.default_rng(seed + 1)
    out = []
    for i in range(count):
        y = sim["y"] + var[i] + noise_rms * rng.standard_normal(len(u))
        out.append(Record(u=np.array(u, float), y=y, fs=stage.fs, name=f"{name}-{i}"))
    return out


# --------------------------------------------------------------------------- measured look-alikes
#: Input range of stage A, V.
STAGE_A_U = (-100.0, 74.0)


def stage_a(fs: float = 40_000.0) -> SandwichStage:
    """Return the stage behind :func:`stage_a_like`, simulated at ``fs``.

    Amplifier: first-order lag at 4 kHz with one sample of delay. Actuator: rate-dependent
    Bouc-Wen, input in volts, output in micrometres (slope 0.032 um/V far from reversals,
    branches up to 0.45 um apart). Flexure: a mode at 740 Hz with damping 0.026 (resonance gain
    about 19 times the 50 Hz gain).

    Parameters
    ----------
    fs : float, optional
        Simulation rate in Hz, by default 40 kHz (four times the 10 kHz acquisition).

    Returns
    -------
    SandwichStage
        The stage.
    """
    l1 = continuous_linear(fs, gain=1.0, pole_hz=4000.0, delay=1)
    h = BoucWen(k=0.0318, a=0.0135, beta=0.022, gamma=0.008, rate=0.15, rate_ref=20_000.0)
    l2 = continuous_linear(fs, gain=1.0, mode_hz=740.0, damping=0.026)
    return SandwichStage(l1, h, l2, fs, name="stage A look-alike")


def _stage_a_input(kind: str, seconds: float, fs: float, rng: np.random.Generator) -> np.ndarray:
    lo, hi = STAGE_A_U
    mid, half = 0.5 * (lo + hi), 0.5 * (hi - lo)
    n = int(round(seconds * fs))
    t = np.arange(n) / fs
    phase = rng.uniform(0, 2 * np.pi)
    if kind == "prbn":
        bit = max(1, int(round(fs / 500)))
        levels = rng.choice([-1.0, 1.0], size=n // bit + 1)
        b, a = signal.butter(2, 250.0 / (fs / 2))  # the generator's smoothing filter
        x = signal.lfilter(b, a, np.repeat(levels, bit)[:n]) * 0.2 * half + mid
        x += 0.7 * half * np.sin(2 * np.pi * 7 * t + phase)
    elif kind in ("sine50", "sine100"):
        f = 50.0 if kind == "sine50" else 100.0
        x = mid + 0.8 * half * np.sin(2 * np.pi * f * t + phase)
    elif kind in ("tri50", "tri100"):
        f = 50.0 if kind == "tri50" else 100.0
        x = mid + 0.8 * half * signal.sawtooth(2 * np.pi * f * t + phase, 0.5)
    elif kind == "large_sine":
        x = mid + half * np.sin(2 * np.pi * 2.0 * t + phase)
    else:
        raise ValueError(f"unknown kind {kind!r} (expected prbn, sine50, sine100, tri50, tri100, "
                         "large_sine)")
    # start from the mean level: blend the excitation in over 20 ms
    nb = min(n, int(0.02 * fs))
    x[:nb] = mid + (0.5 - 0.5 * np.cos(np.pi * np.arange(nb) / nb)) * (x[:nb] - mid)
    return np.clip(x, lo, hi)


def stage_a_like(kind: str = "prbn", *, seconds: float = 2.0, rest_seconds: float = 1.0,
                 repeat: int = 0, noise_rms: float = 0.5e-3, repeat_rms: float = 0.027,
                 offset: float = -0.7, swing_before: float = 0.0, seed: int = 0) -> Record:
    """Return a record like the measured stage A (piezo stage, capacitive sensor, 10 kHz).

    The stage (:func:`stage_a`, Bouc-Wen hysteresis and a 740 Hz flexure mode) is simulated at
    40 kHz and sampled at 10 kHz (:func:`simulate_at_rate`). The input rests at its mean level
    (-13 V) for ``rest_seconds``, then the excitation runs; the last input sample is wrapped back
    to the first value. The output carries a sensor offset, white sensor noise and a slow
    repeat-to-repeat variation: records with the same ``kind`` and ``seed`` but different
    ``repeat`` share the input and differ by ``repeat_rms`` RMS.

    Parameters
    ----------
    kind : {"prbn", "sine50", "sine100", "tri50", "tri100", "large_sine"}, optional
        Excitation: pseudo-random binary noise (2 ms bits, +-17 V, smoothed at 250 Hz) over a
        7 Hz sine (+-61 V), 50 / 100 Hz sines and triangles at 80 % of the range, or a 2 Hz sine
        over the whole -100..74 V range.
    seconds : float, optional
        Duration of the excitation, by default 2 s.
    rest_seconds : float, optional
        Rest before the excitation, by default 1 s.
    repeat : int, optional
        Repeat index, 0 to 7, by default 0.
    noise_rms : float, optional
        Sensor noise, um, by default 0.5e-3 (0.5 nm).
    repeat_rms : float, optional
        RMS difference between repeats, um, by default 0.027.
    offset : float, optional
        Sensor offset, um, by default -0.7.
    swing_before : float, optional
        Before the rest, the stage swings out and back once (a half sine of 0.1 s) by this
        share of the input's half-range, upwards when positive, downwards when negative, so
        that it rests on one branch of its loop, as a stage rests after earlier work; the swing
        is not in the record. By default 0: the stage starts at its rest.
    seed : int, optional
        Seed of the excitation; the variation and the noise use ``seed`` and ``repeat``.

    Returns
    -------
    Record
        At 10 kHz, input in V, output in um, named ``f"stage-A {kind} #{repeat}"``.
    """
    fs = 10_000.0
    rng = np.random.default_rng(seed)
    x = _stage_a_input(kind, seconds, fs, rng)
    u = hold_then_excite(x, fs, seconds=rest_seconds)
    u[-1] = u[0]  # the generator wraps its last sample back to the first value
    lo, hi = STAGE_A_U
    n_swing = int(round(0.1 * fs)) if swing_before else 0
    swing = u[0] + swing_before * 0.5 * (hi - lo) * np.sin(np.pi * np.arange(n_swing) / n_swing)
    sim = simulate_at_rate(stage_a(), np.concatenate([np.clip(swing, lo, hi), u]), fs)
    var = coloured_variations(u.size, 8, repeat_rms, fs, corner_hz=4.0, seed=seed + 1000)
    noise = np.random.default_rng([seed, repeat, 7]).standard_normal(u.size) * noise_rms
    # displacement zero: the mean input level sits near -0.35 um before the sensor offset
    y = sim["y"][n_swing:] + 0.05 + offset + var[repeat] + noise
    return Record(u=u, y=y, fs=fs, units={"u": "V", "y": "um"}, name=f"stage-A {kind} #{repeat}")


def stage_b(fs: float = 200.0) -> SandwichStage:
    """Return the stage behind :func:`stage_b_like`, simulated at ``fs``.

    Amplifier: first-order lag at 30 Hz with one sample of delay. Actuator: Preisach hysteresis
    over 0-3.6 V (about 14 um/V overall, branches up to about 9 um apart). Flexure: stiff, a mode at
    400 Hz (above the 100 Hz Nyquist rate).

    Parameters
    ----------
    fs : float, optional
        Simulation rate in Hz, by default 200 Hz.

    Returns
    -------
    SandwichStage
        The stage.
    """
    l1 = continuous_linear(fs, gain=1.0, pole_hz=30.0, delay=1)
    h = Preisach(k=7.6, x_low=-0.2, x_high=3.8, relay_span=32.0, h_max=1.0, h_decay=0.8,
                 n_centres=80, n_widths=8, rate=0.0)
    l2 = continuous_linear(fs, gain=1.0, mode_hz=400.0 if fs > 800 else 0.45 * fs, damping=0.3)
    return SandwichStage(l1, h, l2, fs, name="stage B look-alike")


def stage_b_like(*, seconds: float = 4.0, noise_rms: float = 0.02, seed: int = 0) -> Record:
    """Return a record like the measured stage B (micromanipulator, strain sensor, 200 Hz).

    A 1 Hz sine over 0-3.6 V drives :func:`stage_b`; the sensor reads about -123..-74 um (a
    large offset).

    Parameters
    ----------
    seconds : float, optional
        Duration, by default 4 s.
    noise_rms : float, optional
        Sensor noise, um, by default 0.02.
    seed : int, optional
        Seed of the sine phase and of the noise.

    Returns
    -------
    Record
        At 200 Hz, input in V, output in um.
    """
    fs = 200.0
    rng = np.random.default_rng(seed)
    t = np.arange(int(round(seconds * fs))) / fs
    phase = rng.uniform(0, 2 * np.pi)
    u = 1.8 + 1.8 * np.sin(2 * np.pi * 1.0 * t + phase)
    sim = stage_b().simulate(u)
    y = sim["y"] - 111.2 + noise_rms * rng.standard_normal(t.size)
    return Record(u=u, y=y, fs=fs, units={"u": "V", "y": "um"}, name="stage-B sine 1Hz")


# --------------------------------------------------------------------------- the suite
def _paper_record(seed: int, seconds: float, name: str, stage: SandwichStage | None = None,
                  noise_rms: float = 1e-3) -> Record:
    st = paper_stage() if stage is None else stage
    u = paper_excitation(seconds, st.fs, seed=seed)
    sim = st.simulate(u, u_rest=0.0)
    rec = record_from(sim, st.fs, name)
    return with_noise(rec, noise_rms, seed=seed + 17)


def as_measured_suite(seed: int = 0, *, seconds: float = 0.2, hysteresis: str = "duhem",
                      noise_rms: float = 1e-3) -> list[Record]:
    """Return the named "as measured" records the identification tests run on.

    Each case comes as a pair: ``"<case>"`` (to identify on, excitation seed ``seed``) and
    ``"<case>/heldout"`` (the same kind of record from seed ``seed + 1``). The stage is the
    paper's (eqs. 26-28) at 30 kHz, or the paper-like stage with another hysteresis; every record
    carries white sensor noise. Cases:

    - ``offset``: sensor offset of -0.7 um,
    - ``units``: input in kV, output in nm,
    - ``mid_motion``: the first 10 ms (ramp and the start of the excitation) dropped,
    - ``held_level``: 30 ms hold at the operating level (5.3 V, reached by a ramp before the
      record) then the excitation,
    - ``10kHz``: the 30 kHz stage sampled at 10 kHz through an anti-alias filter,
    - ``outlier``: one output sample off by 2 um,
    - ``end_glitch``: the last input sample wrapped back to the first value.

    Parameters
    ----------
    seed : int, optional
        Seed of the excitations and noises, by default 0.
    seconds : float, optional
        Duration of each excitation, by default 0.2 s (6000 samples at 30 kHz).
    hysteresis : str, optional
        ``"duhem"`` (the paper's stage) or another form of
        :func:`~hystid.testing.stages.make_hysteresis`.
    noise_rms : float, optional
        Sensor noise, um, by default 1e-3.

    Returns
    -------
    list of Record
        14 records.
    """
    stage = paper_stage() if hysteresis == "duhem" else paper_like_stage(30_000.0, hysteresis)
    out: list[Record] = []
    for tag, s in (("", seed), ("/heldout", seed + 1)):
        base = _paper_record(s, seconds, "base", stage, noise_rms)
        out.append(replace_name(with_offset(base, -0.7), f"offset{tag}"))
        out.append(replace_name(with_units(base, u="kV", y="nm"), f"units{tag}"))
        long = _paper_record(s, seconds + 0.01, "long", stage, noise_rms)
        out.append(replace_name(crop_start(long, 0.01), f"mid_motion{tag}"))
        # ramp to 5.3 V, hold, then excite; the record starts during the hold
        u_ramp = np.linspace(0.0, 5.3, 301)
        u_exc = paper_excitation(seconds, stage.fs, seed=s, ramp_seconds=0.0)
        u_all = np.concatenate([u_ramp, hold_then_excite(u_exc, stage.fs, level=5.3,
                                                         seconds=0.03 + 0.01)])
        sim = stage.simulate(u_all, u_rest=0.0)
        held = crop_start(record_from(sim, stage.fs, "held"), (301 + 300) / stage.fs)
        out.append(replace_name(with_noise(held, noise_rms, seed=s + 17), f"held_level{tag}"))
        u10 = paper_excitation(seconds, 10_000.0, seed=s)
        sim10 = simulate_at_rate(stage, u10, 10_000.0, u_rest=0.0)
        rec10 = Record(u=sim10["u"], y=sim10["y"], fs=10_000.0, name="10k")
        out.append(replace_name(with_noise(rec10, noise_rms, seed=s + 17), f"10kHz{tag}"))
        out.append(replace_name(with_outliers(base, 1, 2.0, seed=s), f"outlier{tag}"))
        out.append(replace_name(with_end_glitch(base), f"end_glitch{tag}"))
    return out


def replace_name(rec: Record, name: str) -> Record:
    """Return a copy of a record with another name.

    Parameters
    ----------
    rec : Record
        The record.
    name : str
        The new name.

    Returns
    -------
    Record
        The copy.
    """
    return _copy(rec, name=name)

