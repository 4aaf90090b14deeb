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
  slowest of those zeros needs: :attr:`StableInverse.preview`). A block resting before the
  first sample cannot have had the pre-actuation that falls there: the state it would have left
  is made up over the first :attr:`StableInverse.settle` samples, after which the output is
  exact.
* :func:`inverse_filter` is that inverse as a causal filter read with a fixed delay (the
  anti-causal part a FIR of its impulse response), run by :func:`inverse_run`; with
  :func:`lti_push` for the other linear stages it is what the exported C step runs too.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import control as ct
import numpy as np
from numba import njit
from scipy import signal

from ..model import DuhemSandwich
from ..poly import roots_inside

if TYPE_CHECKING:  # pragma: no cover
    from ..mduhem import MultiDuhemSandwich
    from ..pi import PISandwich

__all__ = ["InverseFilter", "StableInverse", "dc_delay", "hysteresis_gain", "inverse_filter",
           "inverse_run", "invertible_weights", "lti_push", "lti_run", "smoothing_model",
           "stable_inverse"]

#: Zeros closer to the unit circle than this have no usable stable inverse.
UNIT_CIRCLE_MARGIN = 1e-6
#: The anti-causal part is run until its impulse response has decayed below this.
ANTICAUSAL_DECAY = 1e-15
#: Longest anti-causal run-out, in samples (zeros very near the unit circle are cut there); the
#: anti-causal part costs one multiply-add per sample of it, per sample.
MAX_RUNOUT = 20_000
#: Longest stretch over which the pre-actuation cut at the start is made up, in samples.
MAX_SETTLE = 1_000


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


#: Longest reference smoother :func:`smoothing_model` makes, in seconds.
MAX_SMOOTH_SECONDS = 1.0


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
        Odd window length ``L >= 3``, spanning at most :data:`MAX_SMOOTH_SECONDS` (and at
        least 3 samples whatever ``dt``).
    dt : float
        Sampling period in seconds.

    Returns
    -------
    control.TransferFunction
        Unit static gain, ``(L-1)/2`` samples of delay.

    Raises
    ------
    ValueError
        For a window that is not odd, shorter than 3 samples or longer than
        :data:`MAX_SMOOTH_SECONDS`.
    """
    if not (isinstance(samples, int | np.integer | float) and not isinstance(samples, bool)) \
            or int(samples) != samples or samples < 3 or samples % 2 == 0:
        raise ValueError(f"samples: expected an odd window length >= 3, got {samples!r}")
    if not (np.isfinite(dt) and dt > 0):
        raise ValueError(f"dt: expected a positive sampling period in seconds, got {dt!r}")
    whole = int(round(MAX_SMOOTH_SECONDS / dt))
    longest = max(3, whole if whole % 2 else whole - 1)
    if samples > longest:
        raise ValueError(f"samples: a window of {int(samples)} samples spans "
                         f"{samples * dt:.3g} s (expected at most {MAX_SMOOTH_SECONDS:g} s, "
                         f"{longest} samples at {1 / dt:g} Hz: a smoother longer than that "
                         "flattens the scan it smooths)")
    L = int(samples)
    h = np.hanning(L + 2)[1:-1]
    h /= h.sum()
    den = np.zeros(L)
    den[0] = 1.0
    return ct.tf(h, den, dt, inputs="y_ref", outputs="y_M", name="smoother")


def _pi_parts(model):
    """``(r, mu, r_inv, mu_inv)`` of the PI block the compensator inverts: the model's own, or,
    when a partial sum of its weights is not positive (a loading curve that falls somewhere:
    no exact inverse), the nearest weights that rise (:func:`invertible_weights`)."""
    from ..pi_operator import pi_inverse_parameters

    if not model.is_invertible() and len(model.poly):
        raise ValueError(
            "model: the PI block with polynomial terms has no inverse: a partial sum of "
            "the weights plus the polynomial terms' least slope over the envelope, "
            f"{model.branch_slope_min():.4g}, is not positive")
    mu = model.mu.copy() if len(model.poly) else invertible_weights(model)
    if len(model.poly):  # no inverse PI operator: the compensator solves per sample
        return model.thresholds.copy(), mu, np.zeros(0), np.zeros(0)
    r_inv, mu_inv = pi_inverse_parameters(model.thresholds, mu)
    return model.thresholds.copy(), mu, r_inv, mu_inv


def invertible_weights(model) -> np.ndarray:
    """The weights of a PI model's operator that the compensator inverts.

    The model's own when every partial sum ``mu_0 + .. + mu_i`` is positive (the exact
    inverse's condition); else the nearest that are
    (:func:`~hystid.pi_operator.admissible_weights`: the partial sums below 1e-3 of the largest
    raised to it, the others kept), and the compensation is approximate: the command is exact
    for that operator, and the model's output from it (:attr:`Compensation.y_pred`) says how
    far off the model's own. A batch fit leaves the weights free: on an independently
    simulated Bouc-Wen stage (exponent 2, 10 kHz) the default ``pi-stage`` model was 4.7 nm
    off a held-out record with a first partial sum of -0.22 of the largest, and ``compensate``
    refused it.

    Parameters
    ----------
    model : PISandwich
        An identified PI sandwich.

    Returns
    -------
    ndarray
        The weights ``mu``.

    Raises
    ------
    ValueError
        When the thresholds do not start at 0 and increase, or no partial sum is positive.
    """
    from ..pi_operator import admissible_weights

    r = np.asarray(model.thresholds, float)
    if not (r[0] == 0 and np.all(np.diff(r) > 0)):
        raise ValueError("model: the PI operator has no inverse: its thresholds must start at "
                         f"0 and increase, got {r.tolist()}")
    mu = np.asarray(model.mu, float)
    sums = np.cumsum(mu)
    if np.all(sums > 0):
        return mu.copy()
    if not np.max(sums) > 0:
        raise ValueError("model: the PI operator has no exact inverse (first weight or a partial "
                         "sum of the weights is not positive), and none of its partial sums is "
                         "positive: no branch rises, nothing to approximate it by")
    return admissible_weights(mu)


def _linear_parts(model):
    """``(a1, b1lead, b1tail, q1, a2, b2lead, b2tail, q2)`` of any sandwich class (the PI and
    multi-Duhem sandwiches carry their leading numerator coefficients in ``b1``, ``b2``)."""
    s = model.structure
    if isinstance(model, DuhemSandwich):
        return model.a1, 1.0, model.b1, s.q1, model.a2, 1.0, model.b2, s.q2
    b1, b2 = model.b1, model.b2
    return model.a1, float(b1[0]), b1[1:], s.q1, model.a2, float(b2[0]), b2[1:], s.q2


def hysteresis_gain(model: DuhemSandwich | MultiDuhemSandwich | PISandwich) -> float:
    """Slope of the hysteresis block's central (anhysteretic) line, ``dw2/dw1``.

    ``f1`` for the Duhem block (its ascending and descending branches are
    ``w2 = f1 w1 -+ (f1 - g0) / alpha``; for the generalised block the slope of its anhysteretic
    curve at the rest, ``F'(0) = f1``); for a PI block the secant of the loading curve over the
    largest threshold; for parallel Duhem operators the secant of their loading curve (a slow
    ramp from the rest, :meth:`~hystid.mduhem.MultiDuhemSandwich.rest_state`) over half the
    envelope's span: their slow operators stay far from their anhysteretic lines (slope
    ``sum_j f1_j``, taken without an envelope) over the inputs the model was identified on.

    Parameters
    ----------
    model : DuhemSandwich, MultiDuhemSandwich or PISandwich
        The identified stage.

    Returns
    -------
    float
        The slope ``dw2/dw1`` of the central line.
    """
    if isinstance(model, DuhemSandwich):
        return float(model.params["f1"])
    if getattr(type(model), "kind", None) == "mduhem":
        env = model.envelope
        if env is None or not env.u_max > env.u_min:
            return float(np.sum(model.f1))
        a = 0.5 * (env.u_max - env.u_min)  # L1 has unit DC gain: w1 = u - u_rest at rest
        return float(model.rest_state(model.u_rest + a).window("w2", 1)[0] / a)
    r, mu = model.thresholds, model.mu
    a = float(r[-1] + (r[1] - r[0] if len(r) > 1 else 1.0))
    return float(np.sum(mu * np.maximum(a - r, 0.0)) / a)


# =========================================================================== stable inverse
@njit(cache=True)
def lti_push(xl, yl, num, den, x):
    """One sample of ``num(z^-1) / den(z^-1)`` in direct form I (``den[0] = 1``), in place.

    The one recursion of the compensator's linear stages (the reference model, the causal part
    of L2's stable inverse); the exported C does the same operations in the same order.

    Parameters
    ----------
    xl : ndarray
        The last ``len(num)`` inputs, newest last (shifted in place).
    yl : ndarray
        The last ``len(den) - 1`` outputs, newest last (shifted in place).
    num, den : ndarray
        Coefficients of ``z^0, z^-1, ...``; ``den[0]`` is 1 and not used.
    x : float
        The new input.

    Returns
    -------
    float
        The new output.
    """
    nn = xl.shape[0]
    for i in range(nn - 1):
        xl[i] = xl[i + 1]
    xl[nn - 1] = x
    acc = 0.0
    for i in range(nn):
        acc += num[i] * xl[nn - 1 - i]
    nd = yl.shape[0]
    for j in range(1, nd + 1):
        acc -= den[j] * yl[nd - j]
    for i in range(nd - 1):
        yl[i] = yl[i + 1]
    if nd > 0:
        yl[nd - 1] = acc
    return acc


@njit(cache=True)
def lti_run(x, num, den, out):
    """:func:`lti_push` from rest over ``x``.

    Parameters
    ----------
    x : ndarray
        Input samples (at least ``len(out)``).
    num, den : ndarray
        As for :func:`lti_push`.
    out : ndarray
        Receives the first ``len(out)`` output samples.
    """
    xl = np.zeros(num.shape[0])
    yl = np.zeros(den.shape[0] - 1)
    for k in range(out.shape[0]):
        out[k] = lti_push(xl, yl, num, den, x[k])


@njit(cache=True)
def inverse_run(x, num, den, fir, delay, lag, A, B, gain, out):
    """The stable inverse of :class:`InverseFilter` from rest, as the exported C runs it.

    ``x`` holds the wanted output (deviations from the rest), at least ``len(out) + delay +
    lag + len(fir) - 1`` samples; ``out[k] = w(k)`` for ``k = 0 .. len(out) - 1``. Per input
    sample: the causal part ``v = num/den x(. + delay)``, the anti-causal part as the FIR
    ``w(k) = sum_j fir[j] v(k + lag + j)``; the first ``lag + len(fir) - 1`` values of ``w``
    fall before sample 0 (pre-actuation the resting block cannot have had): they drive the
    block's state ``A, B`` instead, and ``gain @ state`` is added to the first ``len(gain)``
    values of ``w`` (see :func:`inverse_filter`).

    Parameters
    ----------
    x : ndarray
        The wanted output, deviations from the rest.
    num, den, fir, delay, lag, A, B, gain
        The fields of :class:`InverseFilter`.
    out : ndarray
        Receives ``w(0) .. w(len(out) - 1)``.
    """
    xl = np.zeros(num.shape[0])
    vl = np.zeros(den.shape[0] - 1)
    nf = fir.shape[0]
    fl = np.zeros(2 * nf)  # each v twice: the last nf in order at fl[slot + 1 .. slot + nf]
    ns = A.shape[0]
    xs = np.zeros(ns)
    tmp = np.zeros(ns)
    nk = gain.shape[0]
    corr = np.zeros(nk)
    pre = lag + nf - 1
    slot = nf - 1
    for c in range(delay, out.shape[0] + delay + pre):
        v = lti_push(xl, vl, num, den, x[c])
        slot = slot + 1 if slot + 1 < nf else 0
        fl[slot] = v
        fl[slot + nf] = v
        w = 0.0
        for j in range(nf):
            w += fir[j] * fl[slot + 1 + j]
        k = c - delay - pre
        if k < 0:  # before sample 0: the block's state the cut pre-actuation would have left
            for i in range(ns):
                acc = 0.0
                for j in range(ns):
                    acc += A[i, j] * xs[j]
                acc += B[i] * w
                tmp[i] = acc
            for i in range(ns):
                xs[i] = tmp[i]
            if k == -1:
                for i in range(nk):
                    acc = 0.0
                    for j in range(ns):
                        acc += gain[i, j] * xs[j]
                    corr[i] = acc
        else:
            if k < nk:
                w += corr[k]
            out[k] = w


@dataclass(frozen=True)
class InverseFilter:
    """The stable inverse of a linear block as a causal filter with a fixed delay.

    Made by :func:`inverse_filter`; :func:`inverse_run` runs it (and the exported C step runs
    the same arithmetic). The block is ``z^-d b_in(z^-1) b_out(z^-1) / a(z^-1)`` with ``b_in``
    holding the zeros inside the unit circle and ``b_out`` those outside.

    Attributes
    ----------
    num, den : ndarray
        The causal part ``a / b_in`` (``den[0] = 1``), run on the wanted output read ``delay``
        samples ahead.
    fir : ndarray
        The anti-causal part ``1 / b_out``: its impulse response read forward, cut where it has
        decayed below :data:`ANTICAUSAL_DECAY` (one tap, 1, for a minimum-phase block).
    delay : int
        The block's delay ``d`` in samples.
    lag : int
        Number of zeros outside the unit circle (the FIR reads this many samples further).
    outside : ndarray
        The zeros outside the unit circle.
    A, B : ndarray
        A state-space realisation of the block (``x(k+1) = A x(k) + B w(k)``).
    gain : ndarray
        ``(settle, n)``: the correction of the first ``settle`` inputs for the block's state the
        cut pre-actuation would have left (empty for a minimum-phase block).
    static_gain : float
        The block's gain at DC.
    """

    num: np.ndarray
    den: np.ndarray
    fir: np.ndarray
    delay: int
    lag: int
    outside: np.ndarray
    A: np.ndarray
    B: np.ndarray
    gain: np.ndarray
    static_gain: float

    @property
    def pre(self) -> int:
        """Samples of pre-actuation: the anti-causal part's reach (0 for a minimum-phase block)."""
        return self.lag + self.fir.size - 1

    @property
    def preview(self) -> int:
        """Samples of the wanted output read ahead of each input sample: ``delay + pre``."""
        return self.delay + self.pre

    @property
    def settle(self) -> int:
        """Samples at the start over which the cut pre-actuation is made up (0: none needed)."""
        return int(self.gain.shape[0])

    def run(self, y: np.ndarray, n: int) -> np.ndarray:
        """The block's input for ``y`` (deviations from the rest, held at their end).

        Parameters
        ----------
        y : ndarray
            Wanted output, deviations from the rest; at least one sample.
        n : int
            Samples of input wanted (``y`` is held at its last value beyond its end).

        Returns
        -------
        ndarray
            ``n`` samples of the block's input (deviations from the rest).
        """
        y = np.asarray(y, float)
        need = n + self.preview
        x = np.concatenate([y[:need], np.full(max(need - y.size, 0), y[-1])])
        out = np.empty(n)
        inverse_run(np.ascontiguousarray(x), self.num, self.den, self.fir, self.delay,
                    self.lag, self.A, self.B, self.gain, out)
        return out


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


def _settle_gain(A: np.ndarray, B: np.ndarray, C: np.ndarray, D: float,
                 settle: int) -> np.ndarray:
    """``G`` with ``dw = G x``: the inputs over ``settle`` samples that bring the block from
    the state ``x`` missing at sample 0 to the path of the stable inverse.

    The output error over the first ``settle`` samples is least (in the sum of squares) subject
    to the state matching at sample ``settle``, after which the output is exact. ``x`` is the
    state the cut pre-actuation would have left; the error the block has without it is its
    free response from ``-x``.
    """
    ns = A.shape[0]
    powers = [np.eye(ns)]
    for _ in range(settle):
        powers.append(A @ powers[-1])
    phi = np.array([C @ powers[k] for k in range(settle)])  # free response from x0
    markov = np.r_[D, [float(C @ powers[k] @ B) for k in range(settle - 1)]]
    gam = np.zeros((settle, settle))
    for k in range(settle):
        gam[k, :k + 1] = markov[k::-1]
    psi = powers[settle]
    omega = np.column_stack([powers[settle - 1 - j] @ B for j in range(settle)])
    # the state matched exactly (a particular solution plus the null space of omega), the
    # output error least over what is left
    u, sv, vt = np.linalg.svd(omega)
    rank = int(np.sum(sv > sv[0] * 1e-13))
    particular = -(vt[:rank].T / sv[:rank]) @ (u[:, :rank].T @ psi)
    free = vt[rank:].T
    fit = np.linalg.lstsq(gam @ free, -(phi + gam @ particular), rcond=None)[0]
    return -(particular + free @ fit)  # applied to the state the cut pre-actuation leaves


def inverse_filter(block: ct.TransferFunction) -> InverseFilter:
    """The stable inverse of a discrete block as a causal filter with a fixed delay.

    The block is factored ``z^-d b_in(z^-1) b_out(z^-1) / a(z^-1)``; ``a / b_in`` runs forward
    in time from rest, ``1 / b_out`` (zeros outside the unit circle) backward, as a FIR of its
    impulse response cut at :data:`ANTICAUSAL_DECAY`, and the delay is read ahead. A block at
    rest before sample 0 cannot have had the pre-actuation the anti-causal part asks for there:
    the state it would have left is made up over the first ``settle`` samples (the output error
    least there, exact afterwards; ``settle`` is the pre-actuation's length, at least the
    block's order, at most :data:`MAX_SETTLE`).

    Parameters
    ----------
    block : control.TransferFunction
        A discrete SISO block with no zero on the unit circle.

    Returns
    -------
    InverseFilter
        The filter's coefficients.

    Raises
    ------
    ValueError
        For a zero on the unit circle, a block without a finite non-zero static gain or one
        that is not a discrete SISO transfer function.
    """
    b, a, d = _z_inverse(block)
    zeros = np.roots(b) if b.size > 1 else np.zeros(0)
    on = np.abs(np.abs(zeros) - 1.0) <= UNIT_CIRCLE_MARGIN
    if np.any(on):
        listed = ", ".join(f"{z:.6g}" for z in zeros[on])
        raise ValueError(f"block: zeros on the unit circle ({listed}) have no stable inverse; "
                         "give a reference model that keeps them")
    k = float(np.sum(b) / np.sum(a))
    if not (np.isfinite(k) and k != 0.0):
        raise ValueError(f"block: no finite non-zero static gain ({k!r})")
    inside, outside = zeros[np.abs(zeros) < 1.0], zeros[np.abs(zeros) > 1.0]
    b_in = np.real(b[0] * np.poly(inside)) if inside.size else np.array([b[0]])
    order = max(a.size - 1, d + b.size - 1)
    num_z = np.zeros(order + 1)
    num_z[d:d + b.size] = b
    den_z = np.zeros(order + 1)
    den_z[:a.size] = a
    A, B, C, D = signal.tf2ss(num_z[d:], den_z)  # the delay's leading zeros left out
    A, B, C, D = (np.ascontiguousarray(A, float), np.ascontiguousarray(B[:, 0], float),
                  np.asarray(C[0], float), float(np.asarray(D).ravel()[0]))
    if outside.size:
        slowest = float(np.max(1.0 / np.abs(outside)))
        runout = min(int(np.ceil(np.log(ANTICAUSAL_DECAY) / np.log(slowest))), MAX_RUNOUT)
        runout = max(runout, outside.size)
        c = np.real(np.poly(1.0 / outside))  # prod (1 - z / z_i) in powers of z
        impulse = np.zeros(runout + 1)
        impulse[0] = 1.0
        fir = signal.lfilter([1.0], c, impulse) / np.real(np.prod(-outside))
        settle = min(max(outside.size + runout, A.shape[0]), MAX_SETTLE)
        gain = _settle_gain(A, B, C, D, settle)
    else:
        fir, gain = np.ones(1), np.zeros((0, A.shape[0]))
    f = np.ascontiguousarray
    return InverseFilter(f(a / b_in[0]), f(b_in / b_in[0]), f(fir, float), int(d),
                         int(outside.size), outside, A, B, f(gain, float), k)


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
    settle : int
        Output samples at the start over which the pre-actuation the resting block could not
        have had before sample 0 is made up: the output is exact from there on (0 for a
        minimum-phase block).
    """

    signal: np.ndarray
    delay: int
    outside: np.ndarray
    preview: int
    settle: int = 0

    @property
    def minimum_phase(self) -> bool:
        """Whether the inverse is causal apart from the delay (no zero outside the circle)."""
        return self.outside.size == 0


def stable_inverse(block: ct.TransferFunction, y: np.ndarray, *, extra: int = 0,
                   y_rest: float = 0.0) -> StableInverse:
    """The input ``w`` for which ``block`` outputs ``y``, by the block's stable inverse.

    The block is factored ``z^-d b_in(z^-1) b_out(z^-1) / a(z^-1)``, with ``b_in`` holding the
    zeros inside the unit circle and ``b_out`` those outside. ``a / b_in`` runs forward in time
    from rest, ``1 / b_out`` backward in time from the held end (stable both ways), and the
    delay ``d`` is read ahead (see :func:`inverse_filter`). For a minimum-phase block, ``block``
    driven by ``w`` from rest gives ``y`` exactly (where ``y`` starts at rest). With zeros
    outside the unit circle the inverse acts before ``y`` moves (pre-actuation); what of it
    would fall before sample 0, where the block rests, is made up over the first
    :attr:`StableInverse.settle` samples: the output is exact from there on and as near ``y``
    as it can be before (least squares).

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
    filt = inverse_filter(block)
    y = np.asarray(y, float)
    if y.size == 0:
        raise ValueError("y: expected at least one sample")
    w = filt.run(y - y_rest, y.size + int(extra)) + y_rest / filt.static_gain
    return StableInverse(np.ascontiguousarray(w), filt.delay, filt.outside, filt.preview,
                         filt.settle)
