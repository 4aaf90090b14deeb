"""Whether a record determines its model: candidates that agree on it, compared elsewhere.

The member choice (:func:`hystid.identify.members.select_member`) scores every candidate on a
block held out in the record, which repeats the record's own pattern of reversals. Two candidates
can agree there and differ widely on an input with other reversals inside the same range: the
record then does not determine the model, whichever is chosen. Measured on stage A
(``../shared/data/real/stageA/``, ``python benchmarks/bench_stage_a.py --train tri50_1``):
identified on a triangle record the Duhem sandwich was 62 nm off that record's held-out end
(the choice's part until 2026-11) and ``pi-stage`` 70, and off the PRBN records 453-455 nm and
75-76.

:func:`probe_input` draws such an input (random levels inside the record's input range, each
reached by a ramp and held, seeded); :func:`disagreement` is the RMS difference of two models'
outputs on it.
"""

from __future__ import annotations

from typing import Any

import numpy as np

__all__ = ["PROBE_SECONDS", "disagreement", "probe_input"]

#: Length of the probe input, in seconds, and its least number of samples.
PROBE_SECONDS = 1.0
PROBE_SAMPLES = 2000
#: Shortest and longest ramp or hold of the probe, in seconds (at least 2 and 4 samples).
STEP_SECONDS = (0.002, 0.02)


def probe_input(u: np.ndarray, fs: float, seed: int = 0) -> np.ndarray:
    """An input with reversals of every size inside a record's input range.

    From the record's first input value (the models' rest) to random levels drawn uniformly
    between the 1st and 99th percentiles of its input, each reached by a ramp and held, the
    ramps and holds of random lengths within :data:`STEP_SECONDS`.

    Parameters
    ----------
    u : ndarray
        The record's input.
    fs : float
        Sampling rate in Hz.
    seed : int
        Seed of the random levels and lengths.

    Returns
    -------
    ndarray
        At least ``max(PROBE_SAMPLES, PROBE_SECONDS fs)`` samples.
    """
    u = np.asarray(u, dtype=float)
    seen = u[np.isfinite(u)]
    lo, hi = (float(v) for v in np.percentile(seen, [1, 99]))
    rng = np.random.default_rng(seed)
    n = max(PROBE_SAMPLES, int(round(PROBE_SECONDS * fs)))
    shortest = max(2, int(round(STEP_SECONDS[0] * fs)))
    longest = max(shortest + 2, int(round(STEP_SECONDS[1] * fs)))
    pieces, level, total = [np.array([seen[0]])], float(seen[0]), 1
    while total < n:
        step = (hi - lo) * 10.0 ** rng.uniform(-2.0, 0.0) * rng.choice((-1.0, 1.0))
        target = _reflect(level + step, lo, hi)
        ramp, hold = rng.integers(shortest, longest + 1, size=2)
        pieces += [np.linspace(level, target, ramp + 1)[1:], np.full(hold, target)]
        total += ramp + hold
        level = target
    return np.concatenate(pieces)[:n]


def _reflect(x: float, lo: float, hi: float) -> float:
    """``x`` folded back into ``[lo, hi]`` at its ends."""
    span = hi - lo
    if not span > 0:
        return lo
    r = (x - lo) % (2.0 * span)
    return lo + (r if r <= span else 2.0 * span - r)


def disagreement(first: Any, second: Any, u: np.ndarray, fs: float, seed: int = 0) -> float:
    """RMS difference of two models' outputs on :func:`probe_input`, both from rest.

    The first tenth of the probe is left out (the starts settle).

    Parameters
    ----------
    first, second : Sandwich
        Any members, placed.
    u : ndarray
        The record's input.
    fs : float
        Sampling rate in Hz.
    seed : int
        Seed of the probe.

    Returns
    -------
    float
        In output units; inf when a simulation is not finite.
    """
    from ..baselines import simulate_from_rest

    probe = probe_input(u, fs, seed)
    with np.errstate(all="ignore"):
        a = simulate_from_rest(first, probe, check=False)
        b = simulate_from_rest(second, probe, check=False)
    d = a[len(probe) // 10:] - b[len(probe) // 10:]
    rms = float(np.sqrt(np.mean(d ** 2)))
    return rms if np.isfinite(rms) else float("inf")
