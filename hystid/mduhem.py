"""The multi-Duhem sandwich: several Duhem operators of different rates in parallel.

::

    L1:  w1(k)   = sum_j b1j u(k-q1-j+1) - sum_i a1i w1(k-i)                  (unit DC gain)
    H:   w2_j(k) = w2_j(k-1) + alpha_j [f1_j w1(k-1) - w2_j(k-1)] |dw1(k)| + g0_j dw1(k)
         w2(k)   = sum_j w2_j(k)                                   (eq. 7 for each j = 0..m-1)
    L2:  y(k)    = sum_j b2j w2(k-q2-j+1) - sum_i a2i y(k-i)                  (unit DC gain)

One Duhem operator of eq. (7) makes one loop shape: after a reversal its branch bends towards
the anhysteretic line over a stretch of ``w1`` of about ``1 / alpha``, whatever the swing. A
sum of operators whose rates are spread over decades bends over several stretches at once: a
small reversal moves the fast operators along their whole loop while the slow ones hardly
leave their tangent, so minor loops get the shape a Preisach or Maxwell-slip stage gives them,
which one operator cannot make.

Parameterisation. The rates ``alpha_j`` are *not* parameters of the model vector: like the
PI sandwich's thresholds they are fixed attributes (:attr:`MultiDuhemSandwich.rates`), placed
by the batch fit on a log grid scaled to the training input's swing
(:func:`hystid.identify.mduhem_batch.rate_grid`). With the rates fixed the output is linear in
every ``f1_j`` and ``g0_j`` (each operator's recursion is linear in its state, driven by
``f1_j w1 |dw1|`` and ``g0_j dw1``), so the hysteresis block is identified like the PI
block's weights. As in the PI sandwich, scaling ``w1`` or ``w2`` by a constant moves into
``H`` exactly (``alpha_j -> alpha_j / |c|`` with ``w1 -> c w1``; ``f1_j, g0_j -> c f1_j,
c g0_j`` with ``w2 -> c w2``), so **L1 and L2 have unit DC gain**: their first numerator
coefficients are derived, ``b11 = 1 + sum a1 - sum_(j>1) b1j`` and likewise ``b21``. ``w1`` is
then in input units and ``w2`` in output units.

Condition (8) of the paper becomes ``max_j alpha_j |dw1(k)| < 2``: each operator's recursion
amplifies where it fails.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from .operating import Envelope
from .sandwich import InitialCondition, UnitGainSandwich

if TYPE_CHECKING:  # pragma: no cover
    import control as ct

    from .response import SandwichResponse

__all__ = ["MultiDuhemSandwich", "MultiDuhemStructure", "N_OPERATORS", "mduhem_block"]

#: Number of Duhem operators of the member by default.
N_OPERATORS = 4


@dataclass(frozen=True)
class MultiDuhemStructure:
    """Orders, delays and the number of operators of the multi-Duhem sandwich.

    The defaults are those of a 5-10 kHz piezo stage: L1 a first-order lag of unit DC gain
    (the amplifier, ``w1(k) = -a11 w1(k-1) + (1 + a11) u(k)``; the fit keeps its pole on
    ``[0, 1)``), L2 third order (a flexure mode and a slow real pole) with three numerator
    coefficients and one sample of delay, as the ``pi-stage`` member's.

    Parameters
    ----------
    n_operators : int
        Number of Duhem operators ``m``.
    n1a, n1b : int
        Denominator order and number of numerator coefficients of L1 (``b11 .. b1{n1b}``
        multiply ``u(k-q1) .. u(k-q1-n1b+1)``).
    n2a, n2b : int
        The same for L2.
    q1, q2 : int
        Input delays of L1 and L2.
    """

    n_operators: int = N_OPERATORS
    n1a: int = 1
    n1b: int = 1
    n2a: int = 3
    n2b: int = 3
    q1: int = 0
    q2: int = 1

    def __post_init__(self) -> None:
        for key in ("n1a", "n2a", "q1", "q2"):
            value = getattr(self, key)
            if isinstance(value, bool) or not isinstance(value, int | np.integer) or value < 0:
                raise ValueError(f"MultiDuhemStructure: {key} must be a non-negative integer, "
                                 f"got {value!r}")
        for key in ("n_operators", "n1b", "n2b"):
            value = getattr(self, key)
            if isinstance(value, bool) or not isinstance(value, int | np.integer) or value < 1:
                raise ValueError(f"MultiDuhemStructure: {key} must be a positive integer, got "
                                 f"{value!r}")
        from .validate import check_structure_size

        check_structure_size(self)

    @property
    def names(self) -> tuple[str, ...]:
        """Free parameter names, in the order of ``theta``: L1, H, L2 (signal flow).

        ``b11`` and ``b21`` are not free (unit DC gains); the rates are not parameters (see
        the module docstring).
        """
        m = self.n_operators
        return (
            tuple(f"a1{i}" for i in range(1, self.n1a + 1))
            + tuple(f"b1{j}" for j in range(2, self.n1b + 1))
            + tuple(f"f1_{j}" for j in range(m))
            + tuple(f"g0_{j}" for j in range(m))
            + tuple(f"a2{i}" for i in range(1, self.n2a + 1))
            + tuple(f"b2{j}" for j in range(2, self.n2b + 1))
        )

    @property
    def history(self) -> int:
        """Number of past samples the difference equations reach back (at least 1)."""
        return max(1, self.n1a, self.q1 + self.n1b - 1, self.n2a, self.q2 + self.n2b - 1)

    @property
    def layout(self) -> np.ndarray:
        """Integer layout of the compiled kernels (:mod:`hystid.mduhem_kernels`)."""
        return np.array([self.n1a, self.n1b, self.n_operators, self.n2a, self.n2b, self.q1,
                         self.q2], dtype=np.int64)

    def slices(self) -> dict[str, slice]:
        """Slices of ``theta`` by group: ``a1, b1, f1, g0, a2, b2`` (free coefficients only).

        Returns
        -------
        dict of str to slice
            Where each group sits in ``theta``.
        """
        m = self.n_operators
        sizes = (("a1", self.n1a), ("b1", self.n1b - 1), ("f1", m), ("g0", m),
                 ("a2", self.n2a), ("b2", self.n2b - 1))
        out, start = {}, 0
        for key, size in sizes:
            out[key] = slice(start, start + size)
            start += size
        return out


def _check_rates(rates: Any, m: int | None = None) -> np.ndarray:
    r = np.ascontiguousarray(np.asarray(rates, dtype=float).ravel())
    if r.size == 0 or not np.all(np.isfinite(r)) or np.any(r <= 0):
        raise ValueError(f"rates: expected finite positive Duhem rates alpha_j, got {r!r}")
    if m is not None and r.size != m:
        raise ValueError(f"rates: expected {m} values (one per operator of the structure), got "
                         f"{r.size}")
    return r


def _operator_arrays(params: Mapping[str, float], m: int) -> tuple[np.ndarray, ...]:
    return tuple(np.array([params[f"{key}{j}"] for j in range(m)])
                 for key in ("alpha", "f1_", "g0_"))


def _block_update(t: float, x: np.ndarray, u: np.ndarray, params: dict) -> np.ndarray:
    m = len(x) - 1
    alpha, f1, g0 = _operator_arrays(params, m)
    w1, v = float(u[0]), float(x[0])
    d = w1 - v
    return np.r_[w1, x[1:] + alpha * (f1 * v - x[1:]) * abs(d) + g0 * d]


def _block_output(t: float, x: np.ndarray, u: np.ndarray, params: dict) -> np.ndarray:
    return np.array([np.sum(_block_update(t, x, u, params)[1:])])


def mduhem_block(
    rates: np.ndarray | Sequence[float],
    f1: np.ndarray | Sequence[float],
    g0: np.ndarray | Sequence[float],
    *,
    dt: float,
    inputs: str = "w1",
    outputs: str = "w2",
    name: str = "H",
) -> ct.NonlinearIOSystem:
    """The parallel Duhem operators as a discrete python-control system ``w1 -> w2``.

    Parameters
    ----------
    rates, f1, g0 : array_like
        ``alpha_j``, ``f1_j`` and ``g0_j`` of eq. (7) for each operator, same length ``m``.
    dt : float
        Sampling period in seconds.
    inputs, outputs, name : str
        Signal and system names.

    Returns
    -------
    control.NonlinearIOSystem
        States ``w1_prev, w2_0 .. w2_{m-1}`` (the operators' ``w2_j(k-1)``); direct
        feed-through from ``w1(k)`` to ``w2(k)``; system ``params`` ``alpha0 ..``, ``f1_0 ..``,
        ``g0_0 ..`` (overridable in :func:`control.input_output_response`).
    """
    import control as ct

    alpha = _check_rates(rates)
    m = len(alpha)
    f1 = np.asarray(f1, dtype=float).ravel()
    g0 = np.asarray(g0, dtype=float).ravel()
    if f1.shape != (m,) or g0.shape != (m,):
        raise ValueError(f"f1, g0: expected {m} values each (one per rate), got {f1.size} and "
                         f"{g0.size}")
    params = {}
    for j in range(m):
        params.update({f"alpha{j}": float(alpha[j]), f"f1_{j}": float(f1[j]),
                       f"g0_{j}": float(g0[j])})
    return ct.nlsys(_block_update, _block_output, inputs=[inputs], outputs=[outputs],
                    states=[f"{inputs}_prev", *(f"{outputs}_{j}" for j in range(m))],
                    params=params, dt=dt, name=name)


class MultiDuhemSandwich(UnitGainSandwich):
    """Sandwich model L1 -> ``m`` parallel Duhem operators -> L2 (see the module docstring).

    Parameters
    ----------
    params : mapping or sequence of float
        Free parameters by name (:attr:`MultiDuhemStructure.names`), or a vector in that order.
    rates : array_like
        The operators' rates ``alpha_j`` (positive, one per operator; fixed, like a PI
        sandwich's thresholds).
    structure : MultiDuhemStructure, optional
        Orders, delays and ``m``; the default structure with ``m = len(rates)`` by default.
    fs : float
        Sampling rate in Hz.
    name : str
        Model name, used for the python-control systems.
    u_rest, offset : float
        Input rest level and sensor offset (see :mod:`hystid.operating`).
    envelope : Envelope, optional
        Inputs the model was identified on; simulating outside it warns.
    units : dict, optional
        Units of ``u`` and ``y`` (``{"u": "V", "y": "um"}`` by default).

    Attributes
    ----------
    theta : ndarray
        Free parameter vector.
    rates : ndarray
        The operators' rates.
    """

    #: The model file's ``kind`` (:mod:`hystid.modelfile`).
    kind = "mduhem"

    def __init__(
        self,
        params: Mapping[str, float] | Sequence[float] | np.ndarray,
        rates: np.ndarray | Sequence[float],
        structure: MultiDuhemStructure | None = None,
        fs: float = 10_000.0,
        name: str = "multi-Duhem sandwich",
        *,
        u_rest: float = 0.0,
        offset: float = 0.0,
        envelope: Envelope | None = None,
        units: Mapping[str, str] | None = None,
    ) -> None:
        self.rates = _check_rates(rates)
        structure = structure or MultiDuhemStructure(n_operators=len(self.rates))
        if not isinstance(structure, MultiDuhemStructure):
            raise TypeError(f"structure: expected a MultiDuhemStructure, got "
                            f"{type(structure).__name__}")
        _check_rates(self.rates, structure.n_operators)
        super().__init__(params, structure, fs, name, u_rest=u_rest, offset=offset,
                         envelope=envelope, units=units)

    # ----------------------------------------------------------------- parameters
    @property
    def f1(self) -> np.ndarray:
        """Slopes ``f1_j`` of the operators' anhysteretic lines."""
        return self._part("f1")

    @property
    def g0(self) -> np.ndarray:
        """Reversible slopes ``g0_j`` of the operators."""
        return self._part("g0")

    @property
    def coefficients(self) -> np.ndarray:
        """The full coefficient vector of the compiled kernels (:mod:`hystid.mduhem_kernels`):
        ``[a1 | b1 | rates | f1 | g0 | a2 | b2]``, the derived ``b11, b21`` included."""
        return np.ascontiguousarray(np.concatenate(
            [self.a1, self.b1, self.rates, self.f1, self.g0, self.a2, self.b2]))

    def is_stable(self) -> bool:
        """True when the poles of L1 and L2 lie inside the unit circle and every rate is > 0.

        Returns
        -------
        bool
            Whether both linear blocks are stable and the rates positive.
        """
        from .poly import is_stable

        return is_stable(self.a1, self.a2) and bool(np.all(self.rates > 0))

    @property
    def rate_bound(self) -> float:
        """The largest rate ``max_j alpha_j`` (the one condition 8 bounds)."""
        return float(np.max(self.rates))

    def envelope_bound(self, envelope: Envelope | None = None) -> float:
        """Largest ``max_j alpha_j |dw1|`` over every sine inside an input envelope (condition 8).

        As :meth:`hystid.model.DuhemSandwich.envelope_bound`: a sine of amplitude ``A`` and
        frequency ``w`` moves ``w1`` by at most ``|L1(e^jw)| min(2 A sin(w/2), slew)`` per
        sample. Condition (8) holds for every such input when the value is below 2.

        Parameters
        ----------
        envelope : Envelope, optional
            The model's own envelope by default.

        Returns
        -------
        float
            ``max_j alpha_j max_w |L1(e^jw)| min(2 A sin(w/2), slew)``; 0 without an envelope.
        """
        env = envelope or self.envelope
        if env is None:
            return 0.0
        w = np.linspace(1e-4, np.pi, 512)
        z = np.exp(-1j * w)
        num = sum(b * z ** (self.structure.q1 + j) for j, b in enumerate(self.b1))
        den = 1.0 + sum(a * z ** (i + 1) for i, a in enumerate(self.a1))
        move = np.minimum(2.0 * env.amplitude * np.sin(w / 2), env.slew)
        return float(self.rate_bound * np.max(np.abs(num / den) * move))

    # ----------------------------------------------------------------- python-control bridge
    @property
    def H(self) -> ct.NonlinearIOSystem:
        """The parallel Duhem operators: discrete system w1 -> w2 (:func:`mduhem_block`).

        Its ``params`` are the block's (``alpha0.., f1_0.., g0_0..``) and, where not zero, the
        model's ``u_rest`` and ``offset``, which the update ignores and :meth:`from_control`
        reads back.
        """
        return self._carry(mduhem_block(self.rates, self.f1, self.g0, dt=self.dt, name="H"))

    def operator_state(
        self, x0: InitialCondition | None = None, p0: np.ndarray | Sequence[float] | None = None
    ) -> np.ndarray:
        """The operators' states ``w2_j(-1)`` for a start from ``x0``.

        ``p0`` when given; otherwise the states eq. (7) reaches along a slow ramp of ``w1``
        from the rest (every state zero) to ``w1(-1)`` (zero at rest). ``x0.w2`` is L2's past
        only: it is not split between the operators.

        Parameters
        ----------
        x0 : InitialCondition, optional
            Past signal values (at rest by default).
        p0 : array_like, optional
            The operator states themselves.

        Returns
        -------
        ndarray
            One state per operator.
        """
        m = self.structure.n_operators
        if p0 is not None:
            p = np.asarray(p0, dtype=float).ravel()
            if p.shape != (m,) or not np.all(np.isfinite(p)):
                raise ValueError(f"p0: expected {m} finite operator states w2_j, got {p!r}")
            return p.copy()
        w1 = (x0 or InitialCondition()).window("w1", 1)[0]
        return self._ramp(w1)

    def _ramp(self, w1: float, steps: int = 400) -> np.ndarray:
        """Operator states after a slow ramp of ``w1`` from the rest (states zero) to ``w1``."""
        p = np.zeros(self.structure.n_operators)
        if w1 == 0.0:
            return p
        prev = 0.0
        for x in np.linspace(0.0, w1, steps + 1)[1:]:
            d = x - prev
            p = p + self.rates * (self.f1 * prev - p) * abs(d) + self.g0 * d
            prev = x
        return p

    def _h_state(self, x0: InitialCondition, **state: Any) -> np.ndarray:
        unknown = set(state) - {"p0"}
        if unknown:
            raise TypeError(f"the multi-Duhem block takes the state p0 (its operators' w2_j), "
                            f"got {sorted(unknown)}")
        return np.r_[x0.window("w1", 1)[0], self.operator_state(x0, state.get("p0"))]

    def rest_state(self, u0: float, steps: int = 400) -> InitialCondition:
        """The past of a stage brought slowly from its rest to input ``u0`` and held there.

        L1 and L2 sit at their steady state (unit DC gains: ``w1 = u0 - u_rest``); the
        operators at the states of a slow ramp of ``w1`` from the rest (:meth:`operator_state`
        reads them back from the returned ``w1``).

        Parameters
        ----------
        u0 : float
            Input level held before the record starts.
        steps : int
            Steps of the ramp.

        Returns
        -------
        InitialCondition
            Relative to the model's rest (see :meth:`simulate`).
        """
        P = self.structure.history + 1
        v = float(u0) - self.u_rest
        w2 = float(np.sum(self._ramp(v, steps)))
        return InitialCondition(*(np.full(P, x) for x in (v, v, w2, w2)))

    structure_type = MultiDuhemStructure

    @classmethod
    def _holds(cls, H: ct.NonlinearIOSystem) -> bool:
        """Whether ``H`` is a block of parallel Duhem operators (:func:`mduhem_block`)."""
        return {"alpha0", "f1_0", "g0_0"} <= H.params.keys()

    @classmethod
    def _describe(cls, H: ct.NonlinearIOSystem | None = None) -> str:
        """What a multi-Duhem block is, for messages."""
        if H is None:
            return "Duhem operators in parallel, params alpha0, f1_0, g0_0 .."
        return (f"{H.nstates - 1} Duhem operators in parallel (params alpha0.., f1_0.., "
                "g0_0..)")

    @classmethod
    def _from_blocks(
        cls,
        L1: ct.TransferFunction,
        H: ct.NonlinearIOSystem,
        L2: ct.TransferFunction,
        structure: MultiDuhemStructure | None = None,
        **model: Any,
    ) -> MultiDuhemSandwich:
        """The model from its three blocks (see :meth:`Sandwich.from_control`).

        DC gains of ``L1`` and ``L2`` move into ``H`` exactly: with ``L1 = g1 L1'`` and
        ``L2 = g2 L2'`` (unit-gain ``L1', L2'``) the rates become ``|g1| alpha_j`` and the
        slopes ``g1 g2 f1_j``, ``g1 g2 g0_j``. The orders and delays are read from ``L1`` and
        ``L2`` (``structure`` when given), the number of operators from ``H``.
        """
        m = H.nstates - 1
        if structure is not None and structure.n_operators != m:
            raise ValueError(f"H has {m} Duhem operators, the structure {structure.n_operators}")
        try:
            alpha, f1, g0 = _operator_arrays(H.params, m)
        except KeyError as err:
            raise ValueError(f"H: missing parameter {err} (expected alpha0.., f1_0.., g0_0.., "
                             "one per operator)") from None
        values, (g1, g2), orders = cls._linear_parts(L1, L2, structure)
        values.update({f"f1_{j}": g1 * g2 * v for j, v in enumerate(f1)})
        values.update({f"g0_{j}": g1 * g2 * v for j, v in enumerate(g0)})
        s = structure or MultiDuhemStructure(n_operators=m, **orders)
        return cls(values, abs(g1) * alpha, s, fs=1.0 / L1.dt, **model)

    # ----------------------------------------------------------------- simulation
    def _run(self, U: np.ndarray, W1: np.ndarray, W2: np.ndarray, Y: np.ndarray, P: int,
             x0: InitialCondition, **state: Any) -> None:
        from .mduhem_kernels import mduhem_simulate_into

        p = self._h_state(x0, **state)[1:]
        mduhem_simulate_into(self.coefficients, self.structure.layout, U, W1, W2, Y, p, P)

    def _block_admissibility(self, response: SandwichResponse) -> list[str]:
        """Condition (8) for every operator, ``max_j alpha_j |dw1(k)| < 2``, on the response."""
        ratio = self.rate_bound * np.abs(np.diff(response.w1))
        bad = int(np.count_nonzero(ratio >= 2.0))
        if not bad:
            return []
        return [f"condition (8) fails at {bad} samples (max_j alpha_j |dw1| up to "
                f"{np.max(ratio):.3g}, expected < 2): the fastest Duhem operator's recursion "
                "amplifies there"]

    def _repr_values(self) -> dict[str, float]:
        return {**self.params, **{f"alpha{j}": float(a) for j, a in enumerate(self.rates)}}
