"""The linear side of the inverse sandwich: the blocks' coefficients, reference models, and
the stable inverse of L2.

* :func:`linear_parts` reads the coefficients of L1 and L2 of either sandwich class;
  :func:`hysteresis_gain` the hysteresis block's central slope.
* :func:`dc_delay` and :func:`smoothing_model`: reference models ``M`` for the compensator.
* :func:`stable_inverse` inverts a discrete transfer function over a whole signal: the
  minimum-phase part of its numerator causally, the zeros outside the unit circle anti-causally
  (backward in time, which is stable for them), the delay by reading the signal ahead. For a
  minimum-phase block it is the exact inverse; with zeros outside the unit circle it is the
  exact *stable* inverse, which acts before the signal moves (pre-actuation, as long as the
  slowest of those zeros needs: :attr:`StableInverse.preview`).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import control as ct
import numpy as np
from scipy import signal

from ..model import DuhemSandwich
from ..poly import roots_inside

if TYPE_CHECKING:  # pragma: no cover
    from ..pi import PISandwich

__all__ = ["StableInverse", "dc_delay", "hysteresis_gain", "smoothing_model", "stable_inverse"]

#: Zeros closer to the unit circle than this have no usable stable inverse.
UNIT_CIRCLE_MARGIN = 1e-6
#: The anti-causal part is run until its impulse response has decayed below this.
ANTICAUSAL_DECAY = 1e-15
#: Longest anti-causal run-out, in samples (zeros very near the unit circle are cut there).
MAX_RUNOUT = 1_000_000


def _min_phase(poly: np.ndarray, label: str) -> None:
    """Raise ``ValueError`` when ``poly`` (in ``z^-1``) has a root on or outside the circle."""
    if not roots_inside(poly):
        raise ValueError(
            f"model: {label} is not minimum phase (a zero on or outside the unit circle); "
            "its inverse would be unstable (Assumption 1)"
        )
def _reference_model(reference_model, dt: float):
    """``(l2mode, AM, BM, CM, DM)`` for None / 'exact' / a discrete SISO LTI system."""
    empty = (np.zeros((0, 0)), np.zeros(0), np.zeros(0), 0.0)
    if reference_model is None:
        return 0, *empty
    if isinstance(reference_model, str):
        if reference_model != "exact":
            raise ValueError(
                f"reference_model: expected None, 'exact' or a discrete transfer function, "
                f"got {reference_model!r}"
            )
        return 1, *empty
    if not isinstance(reference_model, ct.LTI) or reference_model.ninputs != 1 \
            or reference_model.noutputs != 1:
        raise ValueError(
            f"reference_model: expected None, 'exact' or a SISO control.TransferFunction / "
            f"StateSpace, got {reference_model!r}"
        )
    if not reference_model.dt or not np.isclose(float(reference_model.dt), dt):
        raise ValueError(
            f"reference_model: must be discrete with dt = {dt:g} s like the model, "
            f"got dt = {reference_model.dt!r}"
        )
    ss = reference_model if isinstance(reference_model, ct.StateSpace) else \
        ct.tf2ss(reference_model, method="scipy")
    A, B, C, D = (np.asarray(m, float) for m in (ss.A, ss.B, ss.C, ss.D))
    if A.size and np.max(np.abs(np.linalg.eigvals(A))) >= 1.0:
        raise ValueError("reference_model: must be stable (poles inside the unit circle)")
    return 1, A, B[:, 0].copy(), C[0].copy(), float(D[0, 0])


def dc_delay(reference_model: ct.LTI | str | None) -> int:
    """The reference model's group delay at DC, rounded to samples (0 for None / 'exact').

    For ``M(z) = N(z) / D(z)`` it is ``D'(1)/D(1) - N'(1)/N(1)``; a linear-phase FIR smoother
    of length ``L`` has ``(L - 1) / 2``.

    Parameters
    ----------
    reference_model : None, str or control.LTI
        As for :func:`inverse`.

    Returns
    -------
    int
        The delay in samples (negative delays count as 0).
    """
    if reference_model is None or isinstance(reference_model, str):
        return 0
    tf = reference_model if isinstance(reference_model, ct.TransferFunction) else \
        ct.ss2tf(reference_model)
    num = np.asarray(tf.num[0][0], float)
    den = np.asarray(tf.den[0][0], float)
    n1, d1 = np.polyval(num, 1.0), np.polyval(den, 1.0)
    if n1 == 0 or d1 == 0:
        raise ValueError("reference_model: needs a finite non-zero static gain")
    tau = np.polyval(np.polyder(den), 1.0) / d1 - np.polyval(np.polyder(num), 1.0) / n1
    return max(int(round(tau)), 0)


def smoothing_model(samples: int, dt: float) -> ct.TransferFunction:
    """A linear-phase smoother for references with corners (triangles): a Hann-window FIR.

    With ``reference_model=smoothing_model(L, dt)`` the compensator asks for ``y`` equal to the
    reference smoothed over ``L`` samples, *without* lag: the smoother's delay ``(L-1)/2`` is
    taken from the preview (``reference_lead``). A triangle's corners then stay within reach
    of the hysteresis inverse (an exact inverse of L2 at a sharp corner would ask ``w2`` for a
    reversal of a few nanometres that eq. 7 cannot make).

    Parameters
    ----------
    samples : int
        Odd window length ``L >= 3``.
    dt : float
        Sampling period in seconds.

    Returns
    -------
    control.TransferFunction
        Unit static gain, ``(L-1)/2`` samples of delay.
    """
    if int(samples) != samples or samples < 3 or samples % 2 == 0:
        raise ValueError(f"samples: expected an odd window length >= 3, got {samples!r}")
    L = int(samples)
    h = np.hanning(L + 2)[1:-1]
    h /= h.sum()
    den = np.zeros(L)
    den[0] = 1.0
    return ct.tf(h, den, dt, inputs="y_ref", outputs="y_M", name="smoother")


def _pi_parts(model):
    from ..pi_operator import pi_inverse_parameters

    if not model.is_invertible():
        raise ValueError(
            "model: the PI operator has no exact inverse (first weight or a partial sum of "
            "the weights is not positive)"
        )
    r_inv, mu_inv = pi_inverse_parameters(model.thresholds, model.mu)
    return model.thresholds.copy(), model.mu.copy(), r_inv, mu_inv


def _linear_parts(model):
    """``(a1, b1lead, b1tail, q1, a2, b2lead, b2tail, q2)`` of either sandwich class."""
    s = model.structure
    if isinstance(model, DuhemSandwich):
        return model.a1, 1.0, model.b1, s.q1, model.a2, 1.0, model.b2, s.q2
    b1, b2 = model.b1, model.b2
    return model.a1, float(b1[0]), b1[1:], s.q1, model.a2, float(b2[0]), b2[1:], s.q2


def hysteresis_gain(model: DuhemSandwich | PISandwich) -> float:
    """Slope of the hysteresis block's central (anhysteretic) line, ``dw2/dw1``.

    ``f1`` for the Duhem block (its ascending and descending branches are
    ``w2 = f1 w1 -+ (f1 - g0) / alpha``); for a PI block the secant of the loading curve over the
    largest threshold.

    Parameters
    ----------
    model : DuhemSandwich or PISandwich
        The identified stage.

    Returns
    -------
    float
        The slope ``dw2/dw1`` of the central line.
    """
    if isinstance(model, DuhemSandwich):
        return float(model.params["f1"])
    r, mu = model.thresholds, model.mu
    a = float(r[-1] + (r[1] - r[0] if len(r) > 1 else 1.0))
    return float(np.sum(mu * np.maximum(a - r, 0.0)) / a)




# =========================================================================== stable inverse
@dataclass(frozen=True)
class StableInverse:
    """The input that makes a linear block give a wanted output; made by :func:`stable_inverse`.

    Attributes
    ----------
    signal : ndarray
        The block's input, as long as the wanted output plus the ``extra`` samples asked for.
    delay : int
        The block's delay (relative degree) in samples, read ahead.
    outside : ndarray
        The block's zeros outside the unit circle, inverted anti-causally (empty for a
        minimum-phase block).
    preview : int
        Samples of the wanted output needed ahead of each input sample: the delay, plus the
        anti-causal part's length until its response has decayed below
        :data:`ANTICAUSAL_DECAY` (pre-actuation).
    """

    signal: np.ndarray
    delay: int
    outside: np.ndarray
    preview: int

    @property
    def minimum_phase(self) -> bool:
        """Whether the inverse is causal apart from the delay (no zero outside the circle)."""
        return self.outside.size == 0


def _z_inverse(block: ct.TransferFunction) -> tuple[np.ndarray, np.ndarray, int]:
    """``(b, a, d)`` with ``block = z^-d b(z^-1) / a(z^-1)``, ``a[0] = 1``, ``b[0] != 0``."""
    if not isinstance(block, ct.TransferFunction) or block.ninputs != 1 \
            or block.noutputs != 1 or not block.dt:
        raise ValueError(f"block: expected a discrete SISO control.TransferFunction, got "
                         f"{block!r}")
    num = np.trim_zeros(np.asarray(block.num[0][0], float), "f")
    den = np.trim_zeros(np.asarray(block.den[0][0], float), "f")
    if num.size == 0 or den.size == 0:
        raise ValueError("block: the transfer function is zero")
    d = den.size - num.size
    if d < 0:
        raise ValueError("block: not causal (more zeros than poles)")
    return num / den[0], den / den[0], d


def stable_inverse(block: ct.TransferFunction, y: np.ndarray, *, extra: int = 0,
                   y_rest: float = 0.0) -> StableInverse:
    """The input ``w`` for which ``block`` outputs ``y``, by the block's stable inverse.

    The block is factored ``z^-d b_in(z^-1) b_out(z^-1) / a(z^-1)``, with ``b_in`` holding the
    zeros inside the unit circle and ``b_out`` those outside. ``a / b_in`` runs forward in time
    from rest, ``1 / b_out`` backward in time from the held end (stable both ways), and the
    delay ``d`` is read ahead: ``block`` driven by ``w`` from rest gives ``y`` exactly where
    ``y`` starts at rest and the anti-causal part has room before the first move.

    Parameters
    ----------
    block : control.TransferFunction
        A discrete SISO block with no zero on the unit circle.
    y : ndarray
        The wanted output, one value per sample (held at its last value afterwards).
    extra : int
        Samples of ``w`` wanted beyond the end of ``y`` (on the held output).
    y_rest : float
        The output at rest: ``w`` is ``y_rest / block(1)`` before ``y`` moves. Deviations
        from it are inverted, so the block's state at rest is its steady state there.

    Returns
    -------
    StableInverse
        The input signal (``len(y) + extra`` samples) and how it was obtained.

    Raises
    ------
    ValueError
        For a zero on the unit circle (no stable inverse: give a reference model instead) or
        a block that is not a discrete SISO transfer function.
    """
    b, a, d = _z_inverse(block)
    y = np.asarray(y, float)
    zeros = np.roots(b) if b.size > 1 else np.zeros(0)
    on = np.abs(np.abs(zeros) - 1.0) <= UNIT_CIRCLE_MARGIN
    if np.any(on):
        listed = ", ".join(f"{z:.6g}" for z in zeros[on])
        raise ValueError(f"block: zeros on the unit circle ({listed}) have no stable inverse; "
                         "give a reference model that keeps them")
    inside, outside = zeros[np.abs(zeros) < 1.0], zeros[np.abs(zeros) > 1.0]
    b_in = np.real(b[0] * np.poly(inside)) if inside.size else np.array([b[0]])
    runout = 0
    if outside.size:
        slowest = float(np.max(1.0 / np.abs(outside)))
        runout = min(int(np.ceil(np.log(ANTICAUSAL_DECAY) / np.log(slowest))), MAX_RUNOUT)
        runout = max(runout, outside.size)
    n = y.size + extra
    dev = np.concatenate([y, np.full(extra + d + runout, y[-1])]) - y_rest
    k = float(np.sum(b) / np.sum(a))
    if not (np.isfinite(k) and k != 0.0):
        raise ValueError(f"block: no finite non-zero static gain ({k!r})")
    v = signal.lfilter(a, b_in, dev[d:])  # forward: the delay read ahead, then a / b_in
    if outside.size:
        c = np.real(np.poly(1.0 / outside))  # prod (1 - z / z_i) in powers of z
        back = v[::-1]
        zi = signal.lfilter_zi([1.0], c) * back[0]
        g = signal.lfilter([1.0], c, back, zi=zi)[0][::-1]
        v = np.real(g[outside.size:] / np.prod(-outside))
    w = v[:n] + y_rest / k
    return StableInverse(np.ascontiguousarray(w), d, outside, d + outside.size + runout)
