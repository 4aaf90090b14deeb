"""Robustness of a design: stages that are not the model, and the margins a design keeps on them.

* :func:`perturbed_stage` -- a stage whose physical parameters differ from an identified model
  (Duhem coefficients, L1's pole, the flexure mode's frequency and damping) at the same static
  gains of L1 and L2, so that a +-20 % change means a physical change, not a change of a small
  difference such as ``1 + a21 + a22``.
* :func:`margins_on` -- the margins a feedback design keeps on such a stage (python-control,
  the stage linearised along a hysteresis branch).
"""

from __future__ import annotations

import warnings
from collections.abc import Mapping
from dataclasses import dataclass

import control as ct
import numpy as np

from ..model import DuhemSandwich
from .feedback import FeedbackDesign, _pair, flexure_mode, linear_plant

__all__ = ["PERTURBABLE", "LoopMargins", "margins_on", "perturbed_stage"]

#: The factors :func:`perturbed_stage` takes, by name.
PERTURBABLE = ("alpha", "f1", "g0", "a11", "mode frequency", "mode damping")


def _factors(factors: Mapping[str, float]) -> dict[str, float]:
    unknown = sorted(set(factors) - set(PERTURBABLE))
    if unknown:
        raise ValueError(f"factors: unknown name(s) {', '.join(unknown)}; expected some of "
                         f"{', '.join(PERTURBABLE)}")
    out = {name: float(factors.get(name, 1.0)) for name in PERTURBABLE}
    bad = [f"{name}={value!r}" for name, value in out.items()
           if not (np.isfinite(value) and value > 0)]
    if bad:
        raise ValueError(f"factors: expected positive finite scale factors, got {', '.join(bad)}")
    return out


def perturbed_stage(model: DuhemSandwich, factors: Mapping[str, float]) -> DuhemSandwich:
    """A stage whose physical parameters are those of ``model`` scaled by ``factors``.

    * ``alpha``, ``f1``, ``g0`` are scaled as given (``f1`` sets the static gain of the
      hysteresis branches);
    * ``a11`` (L1's pole) is scaled at the same static gain of L1: with ``c1`` the ratio of the
      new to the old L1(1), ``w1`` scales by ``c1`` and eq. (7) is unchanged when ``alpha``,
      ``f1`` and ``g0`` are divided by ``c1``;
    * the flexure mode (L2's pole pair, :func:`~hystid.compensate.flexure_mode`) moves in
      frequency and damping ratio at the same static gain of L2 (``f1``, ``g0`` divided by the
      ratio ``c2`` of the new to the old ``1 / (1 + a21 + a22)``; ``w2`` and the state at rest
      scale by ``1 / c2``).

    Parameters
    ----------
    model : DuhemSandwich
        The identified stage, with a first-order L1 denominator (``a11``) and a second-order
        L2 denominator (``a21``, ``a22``), as the paper's experimental structure.
    factors : mapping
        Scale factors by name (see :data:`PERTURBABLE`); a name left out keeps its value.

    Returns
    -------
    DuhemSandwich
        The perturbed stage (same structure, sampling rate and placement as ``model``).

    Raises
    ------
    ValueError
        An unknown name or a factor that is not positive; a structure without ``a11`` or with
        an L2 denominator that is not second order; a perturbed stage that is not admissible
        (L1, L2 unstable or ``alpha <= 0``).
    """
    f = _factors(factors)
    if model.structure.n1a != 1 or model.structure.n2a != 2:
        raise ValueError(f"model: expected an L1 denominator of order 1 and an L2 denominator "
                         f"of order 2, got {model.structure.n1a} and {model.structure.n2a}")
    p = model.params
    for name in ("alpha", "f1", "g0"):
        p[name] *= f[name]
    a11 = p["a11"] * f["a11"]
    c1 = (1 + p["a11"]) / (1 + a11)
    p["a11"] = a11
    for name in ("alpha", "f1", "g0"):
        p[name] /= c1
    freq, zeta = flexure_mode(model)
    a = _pair(freq * f["mode frequency"], zeta * f["mode damping"], model.dt)
    c2 = (1 + p["a21"] + p["a22"]) / (1 + a[1] + a[2])
    p["a21"], p["a22"] = float(a[1]), float(a[2])
    for name in ("f1", "g0", "f0"):  # w2 scales by 1 / c2: eq. (7) is linear in it
        if name in p:
            p[name] /= c2
    stage = DuhemSandwich(p, model.structure, fs=model.fs, name=f"{model.name} (perturbed)",
                          u_rest=model.u_rest, offset=model.offset, units=model.units,
                          rest_memory=model.rest_memory / c2)
    if not stage.is_stable():
        raise ValueError(f"factors: the perturbed stage is not admissible (L1, L2 stable and "
                         f"minimum phase, alpha > 0); got {stage.params}")
    return stage


@dataclass(frozen=True)
class LoopMargins:
    """Margins of a feedback loop closed around a stage.

    Attributes
    ----------
    stable : bool
        All closed-loop poles inside the unit circle.
    gain_margin_db : float
        Gain margin in dB (``inf`` when the phase never crosses -180 degrees).
    phase_margin : float
        Phase margin in degrees.
    """

    stable: bool
    gain_margin_db: float
    phase_margin: float


def margins_on(design: FeedbackDesign, stage: DuhemSandwich) -> LoopMargins:
    """The margins ``design`` keeps when it drives ``stage`` instead of the model it was made on.

    Parameters
    ----------
    design : FeedbackDesign
        A design from :func:`~hystid.compensate.design_feedback`.
    stage : DuhemSandwich
        The stage, linearised along a hysteresis branch (:func:`linear_plant`).

    Returns
    -------
    LoopMargins
        Stability of the closed loop, gain margin (dB) and phase margin (degrees).
    """
    loop = design.controller * linear_plant(stage)
    stable = bool(np.max(np.abs(ct.feedback(loop, 1).poles())) < 1.0)
    with warnings.catch_warnings():  # 'best' may fall back to 'frd' with a warning
        warnings.simplefilter("ignore", UserWarning)
        gm, pm, *_ = ct.stability_margins(loop)
    gm_db = float(20 * np.log10(gm)) if np.isfinite(gm) and gm > 0 else float("inf")
    return LoopMargins(stable, gm_db, float(pm))
