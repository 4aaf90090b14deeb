"""The L1 - Duhem - L2 sandwich model (eqs. 1, 2, 7) and its python-control bridge."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from .operating import Envelope
from .sandwich import InitialCondition, Sandwich, params_vector
from .signals import finite_number

if TYPE_CHECKING:  # pragma: no cover
    import control as ct

    from .response import SandwichResponse

__all__ = ["DuhemSandwich", "InitialCondition", "SandwichResponse", "Structure", "params_vector"]


@dataclass(frozen=True)
class Structure:
    """Orders, delays and options of the sandwich (eqs. 1, 2, 7).

    The defaults are the paper's experimental structure (eqs. 24-25)::

        w1(k) = -a11 w1(k-1) + u(k-1)
        w2(k) = w2(k-1) + alpha [f1 w1(k-1) - w2(k-1)] |dw1(k)| + g0 dw1(k)
        y(k)  = -a21 y(k-1) - a22 y(k-2) + w2(k)

    Parameters
    ----------
    n1a, n1b : int
        Denominator and numerator orders of L1 (``b10 = 1``).
    n2a, n2b : int
        Denominator and numerator orders of L2 (``b20 = 1``).
    q1, q2 : int
        Delays of L1 and L2 in samples.
    f0 : bool
        Whether the ``f0 sgn(w1)`` term of eq. (5) is in the model.
    f_order : int
        Order of the anhysteretic curve ``F(w1) = f1 w1 + f2 w1^2 + f3 w1^3`` of the
        generalised Duhem block (1, the paper's, to 3).
    g_order : int
        Order of the reversible slope ``G(w1) = g0 + g1 w1 + g2 w1^2`` (0, the paper's, to 2).
    directional : bool
        Direction-dependent rate and slope: ``alpha (1 + ad sgn(dw1))`` and ``G + gd sgn(dw1)``
        (the loop's ascending and descending branches differ).
    """

    n1a: int = 1
    n1b: int = 0
    n2a: int = 2
    n2b: int = 0
    q1: int = 1
    q2: int = 0
    f0: bool = False
    f_order: int = 1
    g_order: int = 0
    directional: bool = False

    def __post_init__(self) -> None:
        for key in ("n1a", "n1b", "n2a", "n2b", "q1", "q2"):
            value = getattr(self, key)
            if not isinstance(value, int | np.integer) or value < 0:
                raise ValueError(f"Structure: {key} must be a non-negative integer, got {value!r}")
        for key, low, high in (("f_order", 1, 3), ("g_order", 0, 2)):
            value = getattr(self, key)
            if not isinstance(value, int | np.integer) or not low <= value <= high:
                raise ValueError(f"Structure: {key} must be an integer from {low} to {high}, "
                                 f"got {value!r}")
        from .validate import check_structure_size

        check_structure_size(self)  # a delay of 1e9 samples would allocate for minutes

    @property
    def names(self) -> tuple[str, ...]:
        """Parameter names in the paper's order of theta (eq. 13)."""
        return (
            tuple(f"b2{j}" for j in range(1, self.n2b + 1))
            + ("alpha",)
            + (("f0",) if self.f0 else ())
            + ("f1",)
            + tuple(f"b1{j}" for j in range(1, self.n1b + 1))
            + ("g0",)
            + tuple(f"a1{i}" for i in range(1, self.n1a + 1))
            + tuple(f"a2{i}" for i in range(1, self.n2a + 1))
            + tuple(f"f{j}" for j in range(2, self.f_order + 1))
            + tuple(f"g{j}" for j in range(1, self.g_order + 1))
            + (("ad", "gd") if self.directional else ())
        )

    @property
    def is_plain(self) -> bool:
        """Whether the hysteresis block is the paper's eq. (7) (no generalised shape terms)."""
        return self.f_order == 1 and self.g_order == 0 and not self.directional

    @property
    def layout(self) -> np.ndarray:
        """Integer layout passed to the compiled kernels."""
        from .kernels import as_layout  # numba loads on first use, not on import hystid

        return as_layout(self.n1a, self.n1b, self.n2a, self.n2b, self.q1, self.q2, self.f0,
                         self.f_order - 1, self.g_order, self.directional)

    @property
    def history(self) -> int:
        """Number of past samples the difference equations reach back (at least 1)."""
        return max(1, self.n1a, self.q1 + self.n1b, self.n2a, self.q2 + self.n2b)


class DuhemSandwich(Sandwich):
    """Sandwich model L1 -> Duhem H -> L2 of a piezo-driven positioning stage.

    Parameters
    ----------
    params : mapping or sequence of float
        Parameter values by name (see :attr:`Structure.names`), or a vector in that order.
    structure : Structure, optional
        Orders, delays and the ``f0`` option; the paper's experimental structure by default.
    fs : float
        Sampling rate in Hz (the paper's stage runs at 30 kHz).
    name : str
        Model name, used for the python-control systems.
    u_rest : float
        Input level at which the stage rests; the sandwich sees ``u - u_rest``
        (see :mod:`hystid.operating`).
    offset : float
        Sensor reading at rest (the sensor's zero offset); added to the sandwich's output.
    envelope : Envelope, optional
        Inputs the model was identified on; simulating outside it warns.
    units : dict, optional
        Units of ``u`` and ``y`` (``{"u": "V", "y": "um"}`` by default).
    rest_memory : float
        Duhem state ``w2`` of the stage at rest (output units before L2): a stage at rest still
        remembers how it got there, and eq. (7) keeps that value until the input moves. The
        batch identification fits it on records that start at rest; simulations start from it
        by default (:meth:`at_rest`).

    Attributes
    ----------
    theta : ndarray
        Parameter vector in the paper's order (eq. 13).
    params : dict
        The same values by name.
    """

    #: The model file's ``kind`` (:mod:`hystid.modelfile`).
    kind = "duhem"

    def __init__(
        self,
        params: Mapping[str, float] | Sequence[float] | np.ndarray,
        structure: Structure | None = None,
        fs: float = 30_000.0,
        name: str = "sandwich",
        *,
        u_rest: float = 0.0,
        offset: float = 0.0,
        envelope: Envelope | None = None,
        units: Mapping[str, str] | None = None,
        rest_memory: float = 0.0,
    ) -> None:
        super().__init__(params, structure or Structure(), fs, name, u_rest=u_rest,
                         offset=offset, envelope=envelope, units=units)
        self.rest_memory = finite_number(rest_memory, "rest_memory")

    # ----------------------------------------------------------------- parameters
    def _group(self, prefix: str, n: int) -> np.ndarray:
        p = self.params
        return np.array([p[f"{prefix}{i}"] for i in range(1, n + 1)])

    @property
    def a1(self) -> np.ndarray:
        """L1 denominator coefficients a11..a1n1a."""
        return self._group("a1", self.structure.n1a)

    @property
    def b1(self) -> np.ndarray:
        """L1 numerator coefficients b11..b1n1b (b10 = 1)."""
        return self._group("b1", self.structure.n1b)

    @property
    def a2(self) -> np.ndarray:
        """L2 denominator coefficients a21..a2n2a."""
        return self._group("a2", self.structure.n2a)

    @property
    def b2(self) -> np.ndarray:
        """L2 numerator coefficients b21..b2n2b (b20 = 1)."""
        return self._group("b2", self.structure.n2b)

    @property
    def num1(self) -> np.ndarray:
        """Full numerator of L1 from its delay on: ``[1, b11, ..]`` (eq. 1, ``b10 = 1``)."""
        return np.concatenate([[1.0], self.b1])

    @property
    def num2(self) -> np.ndarray:
        """Full numerator of L2 from its delay on: ``[1, b21, ..]`` (eq. 2, ``b20 = 1``)."""
        return np.concatenate([[1.0], self.b2])

    def is_stable(self) -> bool:
        """True when L1 and L2 are stable and minimum phase (Assumption 1) and alpha > 0.

        Returns
        -------
        bool
            Whether Assumption 1 holds and ``alpha > 0``.
        """
        from .poly import is_stable  # numba loads on first use, not on import hystid

        return is_stable(self.a1, self.b1, self.a2, self.b2) and self.params["alpha"] > 0

    def envelope_bound(self, envelope: Envelope | None = None) -> float:
        """Largest ``alpha |dw1|`` over every sine inside an input envelope (condition 8).

        A sine of amplitude ``A`` and frequency ``w`` (rad/sample) moves ``w1`` by at most
        ``|L1(e^jw)| 2 A sin(w/2)`` per sample; inside the envelope ``2 A sin(w/2)`` is also
        bounded by the slew. Condition (8) holds for every such input when the returned value
        is below 2.

        Parameters
        ----------
        envelope : Envelope, optional
            The model's own envelope by default.

        Returns
        -------
        float
            ``alpha max_w |L1(e^jw)| min(2 A sin(w/2), slew)``; 0 without an envelope.
        """
        env = envelope or self.envelope
        if env is None:
            return 0.0
        w = np.linspace(1e-4, np.pi, 512)
        z = np.exp(-1j * w)
        num = 1.0 + sum(b * z ** (j + 1) for j, b in enumerate(self.b1))
        den = 1.0 + sum(a * z ** (i + 1) for i, a in enumerate(self.a1))
        move = np.minimum(2.0 * env.amplitude * np.sin(w / 2), env.slew)
        return float(self.rate_bound * np.max(np.abs(num / den) * move))

    @property
    def rate_bound(self) -> float:
        """The largest rate of eq. (7): ``alpha``, or ``alpha (1 + |ad|)`` with directions."""
        p = self.params
        return p["alpha"] * (1.0 + abs(p.get("ad", 0.0)))

    @property
    def shape(self) -> dict[str, float]:
        """The generalised Duhem block's shape parameters (empty for the paper's eq. 7)."""
        from .blocks import SHAPE_PARAMS

        return {k: v for k, v in self.params.items() if k in SHAPE_PARAMS}

    # ----------------------------------------------------------------- python-control bridge
    @property
    def H(self) -> ct.NonlinearIOSystem:
        """Duhem hysteresis (eq. 7): discrete nonlinear system w1 -> w2.

        Its ``params`` are the block's (``alpha, f0, f1, g0`` and the shape's) and, where not
        zero, the model's ``u_rest``, ``offset`` and ``rest_memory``, which the update ignores
        and :meth:`from_control` reads back.
        """
        from . import blocks

        p = self.params
        return self._carry(blocks.duhem_block(
            p["alpha"], p["f1"], p["g0"], p.get("f0", 0.0), shape=self.shape, dt=self.dt,
            name="H"
        ))

    def _h_state(self, x0: InitialCondition, **state: Any) -> np.ndarray:
        if state:
            raise TypeError(f"the Duhem block takes no state beyond x0, got {sorted(state)}")
        return np.array([x0.window("w1", 1)[0], x0.window("w2", 1)[0]])

    structure_type = Structure
    _carried = ("rest_memory",)
    _reading_options = ("f0",)

    @classmethod
    def _holds(cls, H: ct.NonlinearIOSystem) -> bool:
        """Whether ``H`` is a Duhem block (:func:`hystid.blocks.duhem_block`)."""
        return {"alpha", "f1", "g0"} <= H.params.keys() and H.nstates == 2

    @classmethod
    def _describe(cls, H: ct.NonlinearIOSystem | None = None) -> str:
        """What a Duhem block is, for messages."""
        from .blocks import SHAPE_PARAMS

        if H is None:
            return "a Duhem block of eq. (7), 2 states, params alpha, f1, g0 (and f0, f2, ..)"
        shape = [k for k in SHAPE_PARAMS if k in H.params]
        if shape:
            return f"a generalised Duhem block (params alpha, f1, g0, {', '.join(shape)})"
        return "a Duhem block of eq. (7) (params alpha, f1, g0)"

    @classmethod
    def _from_blocks(
        cls,
        L1: ct.TransferFunction,
        H: ct.NonlinearIOSystem,
        L2: ct.TransferFunction,
        structure: Structure | None = None,
        *,
        f0: bool | None = None,
        **model: Any,
    ) -> DuhemSandwich:
        """The model from its three blocks (see :meth:`Sandwich.from_control`).

        The orders and delays are read from L1 and L2, the shape (``f_order``, ``g_order``,
        ``directional``) from the parameters ``H`` has; ``f0`` keeps the ``f0 sgn`` term, by
        default only when ``H.params['f0']`` is non-zero. With ``structure`` the blocks must
        fit it (a shape parameter it lacks must be zero, one it has and ``H`` lacks is zero).
        """
        from . import blocks

        hp = H.params
        shape = {k: float(hp[k]) for k in blocks.SHAPE_PARAMS if k in hp}
        f0_value = float(hp.get("f0", 0.0))
        if structure is None:
            a1, num1, q1 = blocks.read_linear(L1, "L1")
            a2, num2, q2 = blocks.read_linear(L2, "L2")
            structure = Structure(
                len(a1), len(num1) - 1, len(a2), len(num2) - 1, q1, q2,
                bool(f0_value != 0.0) if f0 is None else bool(f0),
                3 if "f3" in shape else 2 if "f2" in shape else 1,
                2 if "g2" in shape else 1 if "g1" in shape else 0,
                "ad" in shape or "gd" in shape)
        else:
            if f0 is not None and bool(f0) != structure.f0:
                raise ValueError(f"f0={f0!r} contradicts the structure (f0={structure.f0})")
            s = structure
            a1, num1, _ = blocks.read_linear(L1, "L1", q=s.q1, na=s.n1a, nb=s.n1b + 1)
            a2, num2, _ = blocks.read_linear(L2, "L2", q=s.q2, na=s.n2a, nb=s.n2b + 1)
            outside = {k: v for k, v in {**shape, "f0": f0_value}.items()
                       if v != 0.0 and k not in s.names}
            if outside:
                raise ValueError(f"H: {', '.join(f'{k} = {v:g}' for k, v in outside.items())} "
                                 f"not in the structure given ({s})")
        for label, num in (("L1", num1), ("L2", num2)):
            if not np.isclose(num[0], 1.0, rtol=1e-12, atol=0.0):
                raise ValueError(
                    f"{label}: leading numerator coefficient is {num[0]:g}; the Duhem sandwich "
                    "fixes b_0 = 1 (scale it into the next block)")
        values = {"alpha": hp["alpha"], "f1": hp["f1"], "g0": hp["g0"], "f0": f0_value}
        values.update({k: shape.get(k, 0.0) for k in structure.names if k in blocks.SHAPE_PARAMS})
        for prefix, vec in (("a1", a1), ("b1", num1[1:]), ("a2", a2), ("b2", num2[1:])):
            values.update({f"{prefix}{i + 1}": v for i, v in enumerate(vec)})
        values = {k: float(values[k]) for k in structure.names}
        return cls(values, structure, fs=1.0 / L1.dt, **model)

    # ----------------------------------------------------------------- simulation
    def _run(self, U: np.ndarray, W1: np.ndarray, W2: np.ndarray, Y: np.ndarray, P: int,
             x0: InitialCondition, **state: Any) -> None:
        from .kernels import simulate_into

        if state:
            raise TypeError(f"the Duhem block takes no state beyond x0, got {sorted(state)}")
        simulate_into(self.theta, self.structure.layout, U, W1, W2, Y, P)

    def at_rest(self) -> InitialCondition:
        """The past of the stage at rest: ``w1 = 0``, the Duhem state at :attr:`rest_memory`.

        Returns
        -------
        InitialCondition
            L2 settled on the remembered ``w2`` (relative to the model's rest).
        """
        P = self.structure.history + 1
        if not self.rest_memory:
            return InitialCondition()
        y = self.rest_memory * self._l2_gain()
        return InitialCondition(w2=np.full(P, self.rest_memory), y=np.full(P, y))

    def rest_state(self, u0: float, steps: int = 400) -> InitialCondition:
        """The past of a stage brought slowly from its rest to input ``u0`` and held there.

        L1 and L2 sit at their steady state; the Duhem state is the one eq. (7) reaches along a
        slow ramp of ``w1`` from the rest to its steady value (a stage is brought to its working
        point before a record starts; the direction of the last move is not known, the ramp
        takes the direct one).

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
        w1 = v * (1.0 + np.sum(self.b1)) / (1.0 + np.sum(self.a1))
        from .blocks import duhem_increment

        p = self.params
        w2, prev = self.rest_memory, 0.0
        for x in np.linspace(0.0, w1, steps + 1)[1:]:
            w2 += duhem_increment(p, prev, w2, x - prev)
            prev = x
        y = w2 * self._l2_gain()
        if not np.isfinite(y):
            env = getattr(self, "envelope", None)
            unit = (self.units or {}).get("u", "")
            seen = (f"; the model was identified on inputs {env.u_min:g}..{env.u_max:g} {unit}"
                    if env is not None else "")
            raise ValueError(
                f"u0 = {u0:g} {unit}: the model's rest state at that input is not finite (the "
                f"Duhem state diverges on the way there{seen}); expected an input in the "
                "model's units and range")
        return InitialCondition(*(np.full(P, x) for x in (v, w1, w2, y)))

    def _block_admissibility(self, response: SandwichResponse) -> list[str]:
        """Condition (8), ``alpha |dw1(k)| < 2``, on the simulated response (with the
        generalised block's rate ``alpha (1 + ad sgn(dw1))``)."""
        dw1 = np.diff(response.w1)
        ratio = self.params["alpha"] * (1.0 + self.params.get("ad", 0.0) * np.sign(dw1)) \
            * np.abs(dw1)
        bad = int(np.count_nonzero(ratio >= 2.0))
        if not bad:
            return []
        return [f"condition (8) fails at {bad} samples (alpha |dw1| up to {np.max(ratio):.3g}, "
                "expected < 2): the Duhem recursion amplifies there"]


def __getattr__(name: str):
    # SandwichResponse subclasses control.TimeResponseData: python-control loads on first use
    if name == "SandwichResponse":
        from .response import SandwichResponse

        return SandwichResponse
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
