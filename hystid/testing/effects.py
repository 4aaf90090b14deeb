"""Unmodelled effects, each in at least two functional forms, for benchmarks of identification.

:func:`simulate_stage` runs a stage with one effect switched on and returns the nominal output
alongside, so the size of the effect can be measured; :func:`list_effects` returns every
``(effect, form)`` pair and :data:`EFFECTS` documents each form and the meaning of ``strength``.

Where each effect acts in ``u -> L1 -> w1 -> H -> w2 -> L2 -> y``:

Each entry: effect / form -- what it does [meaning of ``strength``].

- creep / log -- ``w2 += gamma sum_j dw2(j) log10(1 + (k - j) / (fs tau0))``, a logarithmic
  creep kernel (tau0 = 1 ms) that never settles [gamma, creep per decade as a fraction of a step]
- creep / lags -- ``w2 += gamma sum_i c_i lag_i(w2 - w2_rest)``, first-order lags of 5 ms, 50 ms
  and 0.5 s weighted 0.5, 0.3, 0.2, so a step creeps by gamma in the end [gamma]
- drift / walk -- slow random walk (integrated low-passed white noise) added to y [max abs dy]
- drift / poly -- cubic polynomial in time with random coefficients added to y [max abs dy]
- drift / thermal -- sine with a period of 2-5 record lengths, random phase, added to y
  [max abs dy]; every drift starts at 0 and is scaled to reach exactly ``strength``
- delay / pure -- the input arrives ``d`` samples late [d, samples]
- delay / lag -- ``d`` samples of dead time, then a first-order lag with time constant ``d``
  samples [d, samples]
- asymmetry / branch -- hysteresis coefficients ``(1 + a)`` on rising and ``(1 - a)`` on
  falling motion (Duhem alpha, Bouc-Wen A, Preisach / Maxwell-slip thresholds) [a]
- asymmetry / level -- loop width grows linearly with the level, by the factor
  ``1 + s (w1 - centre) / half-range`` over the record's range [s]
- asymmetry / offset -- constant offset of the hysteresis output [its size at y, output units]
- slew / hard -- amplifier rate limit at ``(1 - s)`` times the input's peak rate [s]
- slew / current -- a current-limited amplifier: the rate limit falls linearly from
  ``(1 - s)`` times the peak rate to 40 % of that towards the rail the motion heads for [s]
- saturation / clip -- the sensor clips the top ``s`` of the output span [s]
- saturation / tanh -- the actuator output w2 passes through ``c + W tanh((w2 - c) / W)``,
  compressing the extremes of the record by the fraction ``s`` [s]
- mode / series -- a second lightly damped mode at 4 % of fs in series after L2 [its Q]
- mode / parallel -- ``y += s L2(M(w2 - w2_rest))``, M a unit-gain mode at 4 % of fs with
  damping 0.02 [s]
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Any

import numpy as np
from scipy import signal

from .stages import (
    Linear,
    SandwichStage,
    continuous_linear,
    paper_like_stage,
    paper_stage,
)

__all__ = ["EFFECTS", "EffectForm", "list_effects", "simulate_stage"]


@dataclass(frozen=True)
class EffectForm:
    """One functional form of an unmodelled effect.

    Parameters
    ----------
    effect : str
        Effect name.
    form : str
        Form name.
    strength : float
        Default strength.
    unit : str
        Meaning / unit of the strength.
    description : str
        What the form does.
    """

    effect: str
    form: str
    strength: float
    unit: str
    description: str


_FORMS = [
    EffectForm("creep", "log", 0.01, "creep per decade, fraction of a step",
               "logarithmic creep kernel on w2 (never settles)"),
    EffectForm("creep", "lags", 0.05, "final creep, fraction of a step",
               "three first-order lags (5 ms, 50 ms, 0.5 s) on w2"),
    EffectForm("drift", "walk", 0.05, "max |dy|, output units",
               "integrated low-passed white noise added to y"),
    EffectForm("drift", "poly", 0.05, "max |dy|, output units",
               "cubic polynomial in time added to y"),
    EffectForm("drift", "thermal", 0.05, "max |dy|, output units",
               "slow sine (period 2-5 records) added to y"),
    EffectForm("delay", "pure", 3, "samples", "input arrives late"),
    EffectForm("delay", "lag", 3, "samples", "dead time then a first-order lag of the same time"),
    EffectForm("asymmetry", "branch", 0.3, "relative coefficient change",
               "different rising / falling hysteresis coefficients"),
    EffectForm("asymmetry", "level", 0.5, "relative width change per half-range",
               "loop width grows with the level"),
    EffectForm("asymmetry", "offset", 0.1, "dy, output units",
               "offset of the hysteresis output, seen at y"),
    EffectForm("slew", "hard", 0.5, "fraction of the peak input rate removed",
               "hard rate limit of the amplifier"),
    EffectForm("slew", "current", 0.5, "fraction of the peak input rate removed",
               "level-dependent rate limit (current-limited amplifier)"),
    EffectForm("saturation", "clip", 0.1, "fraction of the output span clipped",
               "sensor clips the top of the output"),
    EffectForm("saturation", "tanh", 0.1, "compression at the extremes",
               "tanh saturation of the actuator output w2"),
    EffectForm("mode", "series", 20.0, "resonance gain Q",
               "second lightly damped mode in series after L2"),
    EffectForm("mode", "parallel", 0.1, "relative weight of the parallel path",
               "lightly damped mode in parallel with L2"),
]

#: Catalogue of effects: ``EFFECTS[effect][form]`` is an :class:`EffectForm`.
EFFECTS: dict[str, dict[str, EffectForm]] = {}
for _f in _FORMS:
    EFFECTS.setdefault(_f.effect, {})[_f.form] = _f


def list_effects(*, include_none: bool = False) -> list[tuple[str | None, str | None]]:
    """Return every ``(effect, form)`` pair of the catalogue.

    Parameters
    ----------
    include_none : bool, optional
        Start the list with ``(None, None)`` (no effect), by default False.

    Returns
    -------
    list of tuple
        Pairs to pass as ``effect=``, ``form=`` to :func:`simulate_stage`.
    """
    pairs: list[tuple[str | None, str | None]] = [(None, None)] if include_none else []
    pairs += [(f.effect, f.form) for f in _FORMS]
    return pairs


# --------------------------------------------------------------------------- effect pieces
def _normalised_peak(d: np.ndarray, peak: float) -> np.ndarray:
    d = d - d[0]
    m = np.max(np.abs(d))
    return d * (peak / m) if m > 0 else d


def _drift(form: str, n: int, fs: float, peak: float, rng: np.random.Generator) -> np.ndarray:
    t = np.arange(n) / fs
    if form == "walk":
        b, a = signal.butter(1, min(20.0 / (fs / 2), 0.5))
        d = np.cumsum(signal.lfilter(b, a, rng.standard_normal(n)))
    elif form == "poly":
        x = t / max(t[-1], 1e-12)
        c = rng.uniform(-1, 1, size=3)
        d = c[0] * x + c[1] * x**2 + c[2] * x**3
    elif form == "thermal":
        period = rng.uniform(2, 5) * n / fs
        d = np.sin(2 * np.pi * t / period + rng.uniform(0, 2 * np.pi))
    else:
        raise ValueError(f"unknown drift form {form!r}")
    return _normalised_peak(d, peak)


def _rate_limit(u: np.ndarray, rest: float, up: np.ndarray, down: np.ndarray) -> np.ndarray:
    out = np.empty_like(u)
    prev = rest
    for k in range(u.size):
        step = min(max(u[k] - prev, -down[k]), up[k])
        prev = prev + step
        out[k] = prev
    return out


def _log_creep(w2: np.ndarray, fs: float, gamma: float, tau0: float = 1e-3) -> np.ndarray:
    dw = np.diff(w2, prepend=w2[0])
    kernel = np.log10(1.0 + np.arange(w2.size) / (fs * tau0))
    return gamma * signal.fftconvolve(dw, kernel)[: w2.size]


def _lag_creep(w2: np.ndarray, fs: float, gamma: float, rest: float) -> np.ndarray:
    out = np.zeros_like(w2)
    for tau, weight in ((5e-3, 0.5), (50e-3, 0.3), (0.5, 0.2)):
        lag = continuous_linear(fs, gain=1.0, pole_hz=1 / (2 * math.pi * tau))
        out += weight * lag.filter(w2 - rest, 0.0)
    return gamma * out


def _squash(w2: np.ndarray, compression: float) -> np.ndarray:
    centre = 0.5 * (w2.max() + w2.min())
    half = 0.5 * (w2.max() - w2.min())
    if half == 0 or compression <= 0:
        return w2.copy()
    # width W with W tanh(half / W) / half = 1 - compression, by bisection on log W
    lo, hi = math.log(half * 1e-3), math.log(half * 1e3)
    for _ in range(100):
        mid = 0.5 * (lo + hi)
        width = math.exp(mid)
        if width * math.tanh(half / width) / half < 1 - compression:
            lo = mid
        else:
            hi = mid
    width = math.exp(0.5 * (lo + hi))
    return centre + width * np.tanh((w2 - centre) / width)


# --------------------------------------------------------------------------- the simulator
def simulate_stage(
    u: np.ndarray,
    fs: float = 30_000.0,
    *,
    hysteresis: str = "duhem",
    effect: str | None = None,
    form: str | None = None,
    strength: float | None = None,
    seed: int = 0,
    stage: SandwichStage | None = None,
    u_rest: float | None = None,
) -> dict[str, Any]:
    """Simulate a stage with one unmodelled effect.

    Parameters
    ----------
    u : numpy.ndarray
        Input samples at ``fs``.
    fs : float, optional
        Sampling rate in Hz, by default 30 kHz.
    hysteresis : {"duhem", "bouc_wen", "preisach", "maxwell"}, optional
        Hysteresis of the default stage (the paper's at 30 kHz with Duhem, otherwise
        :func:`~hystid.testing.stages.paper_like_stage`), by default ``"duhem"``.
    effect : str, optional
        A key of :data:`EFFECTS` or None / ``"none"`` for none.
    form : str, optional
        A form of the effect, by default the first one listed.
    strength : float, optional
        Size of the effect (see :data:`EFFECTS` for its meaning), by default the form's default.
    seed : int, optional
        Seed of every random figure (drift realisations), by default 0.
    stage : SandwichStage, optional
        Stage to use instead of the default; its ``fs`` must equal ``fs``.
    u_rest : float, optional
        Input held before the record, by default ``u[0]``.

    Returns
    -------
    dict
        ``"u"`` (the commanded input), ``"w1"``, ``"w2"``, ``"y"`` (with the effect),
        ``"y_nominal"`` (the same stage without it), ``"effect"``, ``"form"``, ``"strength"``.
    """
    u = np.ascontiguousarray(u, dtype=float)
    if stage is None:
        stage = paper_stage() if (hysteresis == "duhem" and fs == 30_000.0) else \
            paper_like_stage(fs, hysteresis)
    elif stage.fs != fs:
        raise ValueError(f"stage.fs = {stage.fs} differs from fs = {fs}")
    rest = float(u[0]) if u_rest is None else float(u_rest)
    nominal = stage.simulate(u, u_rest=rest)
    out: dict[str, Any] = {"effect": None, "form": None, "strength": 0.0,
                           "y_nominal": nominal["y"]}
    if effect is None or effect == "none":
        return {**nominal, **out}
    if effect not in EFFECTS:
        raise ValueError(f"unknown effect {effect!r} (expected one of {sorted(EFFECTS)})")
    form = next(iter(EFFECTS[effect])) if form is None else form
    if form not in EFFECTS[effect]:
        raise ValueError(f"unknown form {form!r} of {effect!r} (expected {list(EFFECTS[effect])})")
    s = float(EFFECTS[effect][form].strength if strength is None else strength)
    out.update(effect=effect, form=form, strength=s)
    rng = np.random.default_rng(seed)
    h = stage.hysteresis
    w1_rest = stage.l1.dc_gain * rest
    w2_rest = h.rest_output(w1_rest)

    def through_l2(w2: np.ndarray) -> dict[str, np.ndarray]:
        return {"u": u, "w1": nominal["w1"], "w2": w2, "y": stage.l2.filter(w2, w2_rest)}

    if effect == "creep":
        extra = _log_creep(nominal["w2"], fs, s) if form == "log" else \
            _lag_creep(nominal["w2"], fs, s, w2_rest)
        sim = through_l2(nominal["w2"] + extra)
    elif effect == "drift":
        sim = {**nominal, "y": nominal["y"] + _drift(form, u.size, fs, s, rng)}
    elif effect == "delay":
        d = int(round(s))
        late = np.concatenate([np.full(d, rest), u[: u.size - d]])
        if form == "lag":
            p = math.exp(-1.0 / max(d, 1))
            late = Linear(b=(1 - p,), a=(-p,)).filter(late, rest)
        sim = {**stage.simulate(late, u_rest=rest), "u": u}
    elif effect == "asymmetry":
        if form == "branch":
            sim = stage.with_hysteresis(replace(h, asymmetry=s)).simulate(u, u_rest=rest)
        elif form == "level":
            g1 = stage.l1.dc_gain
            centre = g1 * float(np.median(u))
            scale = g1 * 0.5 * float(np.ptp(u)) or 1.0
            sim = stage.with_hysteresis(
                replace(h, width_slope=s, width_centre=centre, width_scale=scale)
            ).simulate(u, u_rest=rest)
        else:  # offset of the hysteresis output, scaled to appear as s at y
            shift = s / stage.l2.dc_gain
            w2 = nominal["w2"] + shift
            sim = {**nominal, "w2": w2, "y": stage.l2.filter(w2, w2_rest + shift)}
    elif effect == "slew":
        peak = float(np.max(np.abs(np.diff(u, prepend=rest)))) or 1.0
        limit = (1 - s) * peak
        if form == "hard":
            up = down = np.full(u.size, limit)
        else:
            lo, hi = min(rest, u.min()), max(rest, u.max())
            frac = (u - lo) / (hi - lo or 1.0)
            up = limit * (1 - 0.6 * frac)
            down = limit * (1 - 0.6 * (1 - frac))
        sim = {**stage.simulate(_rate_limit(u, rest, up, down), u_rest=rest), "u": u}
    elif effect == "saturation":
        if form == "clip":
            top = nominal["y"].max() - s * np.ptp(nominal["y"])
            sim = {**nominal, "y": np.minimum(nominal["y"], top)}
        else:
            sim = through_l2(_squash(nominal["w2"], s))
    else:  # mode
        mode_hz = 0.04 * fs
        if form == "series":
            mode = continuous_linear(fs, gain=1.0, mode_hz=mode_hz, damping=0.5 / s)
            sim = {**nominal, "y": mode.filter(nominal["y"], nominal["y"][0])}
        else:
            mode = continuous_linear(fs, gain=1.0, mode_hz=mode_hz, damping=0.02)
            extra = stage.l2.filter(mode.filter(nominal["w2"] - w2_rest, 0.0), 0.0)
            sim = {**nominal, "y": nominal["y"] + s * extra}
    return {**sim, **out}
