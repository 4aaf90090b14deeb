"""Feedback design on the identified linear part, with stated margins.

The plant seen by a feedback loop around the stage is, for motions along a hysteresis branch,
``P(z) = L1(z) k_H L2(z)`` with ``k_H`` the slope of the branches (``f1`` for the Duhem block:
its ascending and descending branches are ``w2 = f1 w1 -+ (f1 - g0) / alpha``). The design is

    C(z) = (ki T z / (z - 1) + kp) N(z)

The identified plant is flat from DC up to the flexure mode (L1's pole is near 3 kHz), so the
loop is shaped by the integral term (-20 dB/decade through the crossover, zero static error,
and the slow hysteresis drift removed); a proportional part ``kp = ki / wz`` is optional with its
zero ``wz`` *above* the crossover (``pi_zero`` times it), where it adds phase lead. ``N`` is an
optional notch at the flexure mode: its zeros sit on L2's lightly damped poles and its poles at
the same frequency with damping ``notch_damping`` (unit static gain). The crossover is the
highest one (on a log grid) whose loop meets the requested phase and gain margins with a stable
closed loop; python-control's :func:`control.stability_margins` states them.

Windup: :meth:`FeedbackDesign.anti_windup` realises ``C`` with a second input ``du`` (applied
minus commanded voltage, zero unless the amplifier limits are hit) fed back into the integrator
(back-calculation), so the integral stops growing while the command is clipped.
"""

from __future__ import annotations

import warnings
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import control as ct
import numpy as np

from .compensator import hysteresis_gain

if TYPE_CHECKING:  # pragma: no cover
    from matplotlib.axes import Axes

    from ..model import DuhemSandwich
    from ..pi import PISandwich

__all__ = ["FeedbackDesign", "design_feedback", "flexure_mode", "linear_plant"]


def linear_plant(
    model: DuhemSandwich | PISandwich, gain: float | None = None
) -> ct.TransferFunction:
    """The stage linearised along a hysteresis branch: ``u -> y = L1 k_H L2``.

    Parameters
    ----------
    model : DuhemSandwich or PISandwich
        The identified stage.
    gain : float, optional
        Incremental gain of the hysteresis block; :func:`hysteresis_gain` (``f1``) by default.

    Returns
    -------
    control.TransferFunction
        Discrete ``u -> y``.
    """
    k = hysteresis_gain(model) if gain is None else float(gain)
    if not (np.isfinite(k) and k != 0):
        raise ValueError(f"gain: expected a finite non-zero hysteresis gain, got {k!r}")
    plant = model.L1 * model.L2 * k
    return ct.tf(plant.num[0][0], plant.den[0][0], model.dt, inputs="u", outputs="y",
                 name="plant")


def flexure_mode(model: DuhemSandwich | PISandwich) -> tuple[float, float]:
    """Natural frequency (Hz) and damping ratio of L2's most lightly damped pole pair.

    The z-plane pole ``p`` maps to ``s = ln(p) / T``; ``f = |s| / 2 pi``, ``zeta = -Re(s)/|s|``.

    Parameters
    ----------
    model : DuhemSandwich or PISandwich
        The identified stage.

    Returns
    -------
    tuple of float
        Frequency in Hz and damping ratio.
    """
    poles = np.roots(np.asarray(model.L2.den[0][0], float))
    pairs = poles[np.imag(poles) > 0]
    if len(pairs) == 0:
        raise ValueError("model: L2 has no complex pole pair (no flexure mode to notch)")
    s = np.log(pairs) / model.dt
    zeta = -np.real(s) / np.abs(s)
    i = int(np.argmin(zeta))
    return float(np.abs(s[i]) / (2 * np.pi)), float(zeta[i])


def _pair(freq: float, zeta: float, dt: float) -> np.ndarray:
    """``z^2 + c1 z + c2`` with the discrete image of the s-plane pair (freq, zeta)."""
    w = 2 * np.pi * freq
    s = -zeta * w + 1j * w * np.sqrt(max(1.0 - zeta**2, 0.0))
    z = np.exp(s * dt)
    return np.real(np.poly([z, np.conj(z)]))


def _notch(model, damping: float, width: float | None) -> ct.TransferFunction:
    freq, zeta = flexure_mode(model)
    zeros = _pair(freq, zeta if width is None else max(width, zeta), model.dt)
    poles = _pair(freq, damping, model.dt)
    k = np.polyval(poles, 1.0) / np.polyval(zeros, 1.0)
    return ct.tf(k * zeros, poles, model.dt, name="notch")


@dataclass
class FeedbackDesign:
    """A feedback controller and its margins. Unpacks as ``controller, gain_margin_db,
    phase_margin``.

    Attributes
    ----------
    controller : control.TransferFunction
        ``C(z)``, input ``e`` (reference minus measured output), output ``u_fb`` (volts).
    plant : control.TransferFunction
        The linearised plant it was designed on (see :func:`linear_plant`).
    loop : control.TransferFunction
        ``C P``.
    ki, kp : float
        Integral gain (V/(um s)) and proportional gain (V/um).
    notch : control.TransferFunction or None
        The notch filter at the flexure mode.
    gain_margin, gain_margin_db : float
        Gain margin (ratio, dB); ``inf`` when the phase never crosses -180 degrees.
    phase_margin : float
        Phase margin in degrees.
    stability_margin : float
        Smallest distance of the Nyquist curve from -1 (``1 / max |S|``).
    crossover_hz, phase_crossover_hz : float
        Gain and phase crossover frequencies in Hz.
    closed_loop_poles : ndarray
        Poles of ``CP / (1 + CP)`` (inside the unit circle).
    settings : dict
        The design request.
    """

    controller: ct.TransferFunction
    plant: ct.TransferFunction
    loop: ct.TransferFunction
    ki: float
    kp: float
    notch: ct.TransferFunction | None
    gain_margin: float
    gain_margin_db: float
    phase_margin: float
    stability_margin: float
    crossover_hz: float
    phase_crossover_hz: float
    closed_loop_poles: np.ndarray
    settings: dict = field(default_factory=dict)

    def __iter__(self) -> Iterator:
        yield self.controller
        yield self.gain_margin_db
        yield self.phase_margin

    @property
    def dt(self) -> float:
        """Sampling period of the controller in seconds."""
        return float(self.controller.dt)

    def anti_windup(self, name: str = "C") -> ct.StateSpace:
        """``C`` realised with back-calculation anti-windup.

        Returns
        -------
        control.StateSpace
            Inputs ``e`` and ``du`` (applied minus commanded voltage), output ``u_fb``; states
            those of the notch and the integrator ``x_I`` (``x_I(k+1) = x_I(k) + ki T v(k) +
            du(k)``, ``v`` the notch output). With ``du = 0`` it is :attr:`controller`.

        Parameters
        ----------
        name : str
            System name.
        """
        T = self.dt
        ki = self.ki * T
        if self.notch is not None:
            ns = ct.tf2ss(self.notch, method="scipy")
            An, Bn, Cn, Dn = (np.asarray(m, float) for m in (ns.A, ns.B, ns.C, ns.D))
        else:
            An, Bn, Cn, Dn = np.zeros((0, 0)), np.zeros((0, 1)), np.zeros((1, 0)), np.eye(1)
        nn = An.shape[0]
        A = np.zeros((nn + 1, nn + 1))
        A[:nn, :nn] = An
        A[nn, :nn] = ki * Cn[0]
        A[nn, nn] = 1.0
        B = np.zeros((nn + 1, 2))
        B[:nn, 0] = Bn[:, 0]
        B[nn, 0] = ki * Dn[0, 0]
        B[nn, 1] = 1.0
        C = np.zeros((1, nn + 1))
        C[0, :nn] = (self.kp + ki) * Cn[0]
        C[0, nn] = 1.0
        D = np.array([[(self.kp + ki) * Dn[0, 0], 0.0]])
        states = [f"notch{i}" for i in range(nn)] + ["x_I"]
        return ct.ss(A, B, C, D, T, inputs=["e", "du"], outputs=["u_fb"], states=states,
                     name=name)

    def plot(self, ax: Sequence[Axes] | np.ndarray | None = None) -> Sequence[Axes] | np.ndarray:
        """Bode plot of the loop with the margins in the title.

        Parameters
        ----------
        ax : two matplotlib axes, optional
            Where to draw; a new figure (not registered with pyplot) by default.

        Returns
        -------
        sequence of matplotlib.axes.Axes
            The magnitude and phase axes.
        """
        if ax is None:
            from matplotlib.figure import Figure

            ax = Figure(figsize=(7, 5), layout="constrained").subplots(2, 1, sharex=True)
        f = np.geomspace(1.0, 0.49 / self.dt, 600)
        resp = self.loop(np.exp(2j * np.pi * f * self.dt))
        ax[0].loglog(f, np.abs(resp))
        ax[0].axhline(1.0, color="0.6", lw=0.8)
        ax[0].set_ylabel("|C P|")
        ax[1].semilogx(f, np.degrees(np.unwrap(np.angle(resp))))
        ax[1].axhline(-180.0, color="0.6", lw=0.8)
        ax[1].set_ylabel("phase [deg]")
        ax[1].set_xlabel("frequency [Hz]")
        ax[0].set_title(
            f"crossover {self.crossover_hz:.0f} Hz, PM {self.phase_margin:.0f} deg, "
            f"GM {self.gain_margin_db:.1f} dB"
        )
        return ax


def _evaluate(plant, notch, fc: float, pi_zero: float | None, dt: float):
    """I(+P)(+notch) with crossover ``fc``: the design and its margins (None if unstable)."""
    wc = 2 * np.pi * fc
    z = ct.tf([1, 0], [1], dt)
    shape = dt * z / (z - 1)  # integral, unit ki
    if pi_zero is not None:
        shape = shape + 1.0 / (pi_zero * wc)  # kp = ki / wz
    if notch is not None:
        shape = shape * notch
    mag = abs((shape * plant)(np.exp(1j * wc * dt)))
    if not (np.isfinite(mag) and mag > 0):
        return None
    ki = 1.0 / mag
    kp = ki / (pi_zero * wc) if pi_zero is not None else 0.0
    controller = ki * shape
    loop = controller * plant
    poles = ct.feedback(loop, 1).poles()
    if np.any(np.abs(poles) >= 1.0):
        return None
    with warnings.catch_warnings():  # 'best' may fall back to 'frd' with a warning
        warnings.simplefilter("ignore", UserWarning)
        gm, pm, sm, wpc, wgc, _ = ct.stability_margins(loop)
    return ki, kp, controller, loop, poles, float(gm), float(pm), float(sm), wpc, wgc


def design_feedback(
    model: DuhemSandwich | PISandwich,
    *,
    crossover: float | None = None,
    phase_margin: float = 60.0,
    gain_margin: float = 10.0,
    pi_zero: float | None = None,
    notch: bool = True,
    notch_damping: float = 0.7,
    notch_width: float | None = None,
    hysteresis_slope: float | None = None,
) -> FeedbackDesign:
    """An integral (or PI) controller with a notch at the flexure mode, by loop shaping.

    Parameters
    ----------
    model : DuhemSandwich or PISandwich
        The identified stage; the design uses :func:`linear_plant`.
    crossover : float, optional
        Gain crossover in Hz. By default the highest crossover on a log grid (20 Hz to fs/20)
        that meets ``phase_margin`` and ``gain_margin`` with a stable closed loop.
    phase_margin : float
        Required phase margin in degrees.
    gain_margin : float
        Required gain margin in dB.
    pi_zero : float, optional
        Add a proportional part whose zero sits at ``pi_zero`` times the crossover (> 1: it
        adds phase lead above the crossover); pure integral action by default.
    notch : bool
        Put a notch at L2's flexure mode (zeros on its poles).
    notch_damping : float
        Damping ratio of the notch's poles (sets its width).
    notch_width : float, optional
        Damping ratio of the notch's zeros when larger than the mode's (a shallower, wider notch
        for a mode that is not known exactly); on the mode by default.
    hysteresis_slope : float, optional
        Incremental gain of the hysteresis block; :func:`~hystid.compensate.compensator.
        hysteresis_gain` by default.

    Returns
    -------
    FeedbackDesign
        Controller, margins (gain, phase, stability), crossovers, closed-loop poles.

    Raises
    ------
    ValueError
        When no crossover meets the margins (or the given crossover does not).
    """
    if not 0 < phase_margin < 90:
        raise ValueError(f"phase_margin: expected degrees in (0, 90), got {phase_margin!r}")
    if not gain_margin > 0:
        raise ValueError(f"gain_margin: expected a positive number of dB, got {gain_margin!r}")
    if pi_zero is not None and not pi_zero > 0:
        raise ValueError(f"pi_zero: expected a positive multiple of the crossover, got "
                         f"{pi_zero!r}")
    if not 0 < notch_damping < 1.5:
        raise ValueError(f"notch_damping: expected a damping ratio in (0, 1.5), got "
                         f"{notch_damping!r}")
    dt = model.dt
    plant = linear_plant(model, hysteresis_slope)
    n_filter = _notch(model, notch_damping, notch_width) if notch else None
    nyquist = 0.5 / dt
    if crossover is not None:
        if not 0 < crossover < nyquist:
            raise ValueError(f"crossover: expected a frequency in (0, {nyquist:g}) Hz, "
                             f"got {crossover!r}")
        grid = [float(crossover)]
    else:
        grid = list(np.geomspace(20.0, nyquist / 10.0, 60)[::-1])
    gm_min = 10 ** (gain_margin / 20.0)
    best = None
    for fc in grid:
        found = _evaluate(plant, n_filter, fc, pi_zero, dt)
        if found is None:
            continue
        gm, pm = found[5], found[6]
        if pm >= phase_margin and gm >= gm_min:
            best = (fc, found)
            break
    if best is None:
        raise ValueError(
            f"no crossover meets phase margin {phase_margin:g} deg and gain margin "
            f"{gain_margin:g} dB on this plant (try smaller margins or notch=True)"
        )
    fc, (ki, kp, controller, loop, poles, gm, pm, sm, wpc, wgc) = best
    controller = ct.tf(controller.num[0][0], controller.den[0][0], dt, inputs="e",
                       outputs="u_fb", name="C")
    settings = {
        "phase_margin": phase_margin, "gain_margin": gain_margin,
        "pi_zero": pi_zero, "notch": notch, "notch_damping": notch_damping,
        "notch_width": notch_width, "requested_crossover": crossover,
        "hysteresis_slope": hysteresis_gain(model) if hysteresis_slope is None
        else hysteresis_slope,
    }
    return FeedbackDesign(
        controller, plant, loop, float(ki), float(kp), n_filter, gm,
        float(20 * np.log10(gm)) if np.isfinite(gm) else float("inf"), pm, sm,
        float(wgc) / (2 * np.pi), float(wpc) / (2 * np.pi) if np.isfinite(wpc) else float("nan"),
        np.asarray(poles), settings,
    )
