"""The one sandwich base: what every member of the model family shares.

A sandwich is ``L1 -> H -> L2`` (eqs. 1, 7, 2 for the Duhem block, 29-31 for the PI block),
placed in the record's units (:mod:`hystid.operating`). :class:`Sandwich` owns everything but
the hysteresis block:

* the parameters (``theta`` in the structure's order, :attr:`params` by name) and ``fs``;
* placement, envelope and units (:class:`~hystid.operating.Placed`), :meth:`save`;
* the linear blocks :attr:`L1`, :attr:`L2` as ``control.TransferFunction``;
* :meth:`to_control` (the interconnection, with the ``U0``/``Y0`` placement blocks) and
  :meth:`control_state`, :meth:`from_control` (its inverse);
* :meth:`simulate`, returning a :class:`~hystid.response.SandwichResponse`, and
  :meth:`admissibility` (the model's soundness, the envelope, a finite output).

A member supplies only its own parts: its ``structure`` (with ``names``, ``history``, ``q1``,
``q2``), the coefficient vectors ``a1, a2`` and full numerators ``num1, num2`` of its linear
blocks, the hysteresis block :attr:`H` and its state (:meth:`_h_state`), the compiled kernel
(:meth:`_run`), and optionally its own admissibility test (:meth:`_block_admissibility`) and
how it reads its blocks back (:meth:`_from_blocks`).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, ClassVar

import numpy as np

from .operating import Envelope, Placed, warn_admissibility
from .signals import finite_signal

if TYPE_CHECKING:
    import control as ct

    from .response import SandwichResponse

__all__ = ["InitialCondition", "Sandwich", "UnitGainSandwich", "params_vector",
           "unit_gain_numerator"]


@dataclass
class InitialCondition:
    """Past values of the sandwich's signals, most recent last (``u(k-1), w1(k-1), ...``).

    Shorter arrays are padded with zeros at the old end; missing ones are zero (at rest).

    Parameters
    ----------
    u, w1, w2, y : ndarray
        Past input, internal signals and output, oldest first.
    """

    u: np.ndarray = field(default_factory=lambda: np.zeros(0))
    w1: np.ndarray = field(default_factory=lambda: np.zeros(0))
    w2: np.ndarray = field(default_factory=lambda: np.zeros(0))
    y: np.ndarray = field(default_factory=lambda: np.zeros(0))

    def window(self, name: str, length: int) -> np.ndarray:
        """The last ``length`` values of signal ``name``, zero-padded at the old end.

        Parameters
        ----------
        name : {"u", "w1", "w2", "y"}
            The signal.
        length : int
            Number of past samples wanted.

        Returns
        -------
        ndarray
            ``length`` values, oldest first.
        """
        v = np.asarray(getattr(self, name), dtype=float).ravel()
        if not np.all(np.isfinite(v)):
            raise ValueError(f"InitialCondition.{name} contains non-finite values")
        v = v[-length:] if length else v[:0]
        return np.concatenate([np.zeros(length - len(v)), v])


def params_vector(
    params: Mapping[str, float] | Sequence[float] | np.ndarray, names: Sequence[str]
) -> np.ndarray:
    """Parameters as a vector in the order of ``names``, from a mapping or a sequence.

    Parameters
    ----------
    params : mapping or sequence of float
        Values by name, or a vector already in the order of ``names``.
    names : sequence of str
        Parameter names in the wanted order.

    Returns
    -------
    ndarray
        The values in the order of ``names``.

    Raises
    ------
    ValueError
        Naming the missing, unknown or non-finite parameters.
    """
    if isinstance(params, Mapping):
        missing = [n for n in names if n not in params]
        extra = [n for n in params if n not in names]
        if missing or extra:
            raise ValueError(
                f"params: expected the names {list(names)}; missing {missing}, unknown {extra}"
            )
        theta = np.array([params[n] for n in names], dtype=float)
    else:
        theta = np.asarray(params, dtype=float).ravel()
        if theta.shape != (len(names),):
            raise ValueError(
                f"params: expected {len(names)} values {list(names)}, got shape {theta.shape}"
            )
    if not np.all(np.isfinite(theta)):
        bad = [n for n, v in zip(names, theta, strict=True) if not np.isfinite(v)]
        raise ValueError(f"params: non-finite values for {bad}")
    return theta


class Sandwich(Placed):
    """Base of every sandwich model ``L1 -> H -> L2``; members add their hysteresis block.

    Parameters
    ----------
    params : mapping or sequence of float
        Parameter values by name (see the structure's ``names``), or a vector in that order.
    structure : object
        The member's structure (orders, delays, block options), already validated.
    fs : float
        Sampling rate in Hz.
    name : str
        Model name, used for the python-control systems and responses.
    u_rest, offset : float
        Input rest level and sensor offset (see :mod:`hystid.operating`).
    envelope : Envelope, optional
        Inputs the model was identified on; simulating outside it warns.
    units : dict, optional
        Units of ``u`` and ``y`` (``{"u": "V", "y": "um"}`` by default).

    Attributes
    ----------
    theta : ndarray
        Parameter vector in the structure's order.
    structure : object
        Orders, delays and options.
    fs : float
        Sampling rate in Hz.
    """

    #: The model file's ``kind`` (:mod:`hystid.modelfile`); set by each member.
    kind: ClassVar[str] = ""

    structure: Any

    def __init__(
        self,
        params: Mapping[str, float] | Sequence[float] | np.ndarray,
        structure: Any,
        fs: float,
        name: str,
        *,
        u_rest: float = 0.0,
        offset: float = 0.0,
        envelope: Envelope | None = None,
        units: Mapping[str, str] | None = None,
    ) -> None:
        self.structure = structure
        if not (np.isfinite(fs) and fs > 0):
            raise ValueError(f"fs must be a positive finite number of Hz, got {fs!r}")
        self.fs = float(fs)
        self.name = name
        self.theta = params_vector(params, self.structure.names)
        self._place(u_rest, offset, envelope, units)

    # ----------------------------------------------------------------- what a member supplies
    a1: np.ndarray
    a2: np.ndarray

    @property
    def num1(self) -> np.ndarray:
        """Full numerator of L1 from its delay on: ``w1(k) = sum_j num1[j] u(k-q1-j) - ..``."""
        raise NotImplementedError

    @property
    def num2(self) -> np.ndarray:
        """Full numerator of L2 from its delay on: ``y(k) = sum_j num2[j] w2(k-q2-j) - ..``."""
        raise NotImplementedError

    @property
    def H(self) -> ct.NonlinearIOSystem:
        """The hysteresis block as a discrete ``control.NonlinearIOSystem`` ``w1 -> w2``."""
        raise NotImplementedError

    def is_stable(self) -> bool:
        """Whether the model's linear blocks are stable (each member adds its own conditions).

        Returns
        -------
        bool
        """
        raise NotImplementedError

    def at_rest(self) -> InitialCondition:
        """The past of the stage at rest (members with a remembered rest state override it).

        Returns
        -------
        InitialCondition
            All signals zero relative to the rest.
        """
        return InitialCondition()

    def _h_state(self, x0: InitialCondition, **state: Any) -> np.ndarray:
        """The hysteresis block's state in :meth:`to_control` continuing from ``x0``."""
        raise NotImplementedError

    def _run(self, U: np.ndarray, W1: np.ndarray, W2: np.ndarray, Y: np.ndarray, P: int,
             x0: InitialCondition, **state: Any) -> None:
        """Run the member's compiled kernel on the extended arrays from index ``P`` on."""
        raise NotImplementedError

    def _block_admissibility(self, response: SandwichResponse) -> list[str]:
        """The member's own admissibility test on a simulated response (none by default)."""
        return []

    # ----------------------------------------------------------------- parameters
    @property
    def params(self) -> dict[str, float]:
        """Parameter values by name."""
        return dict(zip(self.structure.names, map(float, self.theta), strict=True))

    @property
    def dt(self) -> float:
        """Sampling period in seconds."""
        return 1.0 / self.fs

    def _l2_gain(self) -> float:
        return float(np.sum(self.num2) / (1.0 + np.sum(self.a2)))

    # ----------------------------------------------------------------- python-control bridge
    @property
    def L1(self) -> ct.TransferFunction:
        """Amplifier + filter: discrete transfer function ``u -> w1``."""
        from .blocks import transfer_function

        return transfer_function(self.a1, self.num1, self.structure.q1, self.dt,
                                 inputs="u", outputs="w1", name="L1")

    @property
    def L2(self) -> ct.TransferFunction:
        """Flexure hinge + load: discrete transfer function ``w2 -> y``."""
        from .blocks import transfer_function

        return transfer_function(self.a2, self.num2, self.structure.q2, self.dt,
                                 inputs="w2", outputs="y", name="L2")

    def to_control(self) -> ct.InterconnectedSystem:
        """The whole sandwich as a python-control interconnected system.

        Returns
        -------
        control.InterconnectedSystem
            Input ``u``; outputs ``y, w1, w2``; states those of ``L1`` (realised with
            ``tf2ss(method='scipy')``), ``H`` and ``L2`` in that order. Use
            :meth:`control_state` for the state matching an :class:`InitialCondition`. A model
            with a rest level or an offset also holds the static blocks ``U0`` (``u - u_rest``)
            and ``Y0`` (``+ offset``).
        """
        import control as ct

        from .blocks import placement_blocks

        placed = bool(self.u_rest or self.offset)
        l1 = ct.tf2ss(self.L1, method="scipy", inputs="v" if placed else "u", outputs="w1",
                      name="L1")
        l2 = ct.tf2ss(self.L2, method="scipy", inputs="w2", outputs="x" if placed else "y",
                      name="L2")
        systems = [l1, self.H, l2]
        if placed:
            systems += placement_blocks(self.u_rest, self.offset, self.dt)
        return ct.interconnect(systems, inputs="u", outputs=["y", "w1", "w2"], name=self.name)

    def control_state(self, x0: InitialCondition | None = None, **state: Any) -> np.ndarray:
        """State vector of :meth:`to_control` that continues from the past ``x0``.

        Parameters
        ----------
        x0 : InitialCondition, optional
            Past signal values relative to the rest; :meth:`at_rest` by default.
        **state
            The hysteresis block's own state where the member takes one (``p0`` of the PI
            sandwich).

        Returns
        -------
        ndarray
            The states of ``L1``, ``H`` and ``L2`` in the order of :meth:`to_control`.
        """
        import control as ct

        from .blocks import state_from_past

        x0 = x0 or self.at_rest()
        n = self.structure.history + 1
        l1 = ct.tf2ss(self.L1, method="scipy")
        l2 = ct.tf2ss(self.L2, method="scipy")
        x1 = state_from_past(l1, x0.window("u", n), x0.window("w1", n))
        x2 = state_from_past(l2, x0.window("w2", n), x0.window("y", n))
        return np.concatenate([x1, self._h_state(x0, **state), x2])

    @classmethod
    def from_control(
        cls,
        L1: ct.TransferFunction | ct.InterconnectedSystem,
        H: ct.NonlinearIOSystem | None = None,
        L2: ct.TransferFunction | None = None,
        *,
        name: str | None = None,
        **options: Any,
    ) -> Sandwich:
        """Build a model from python-control objects.

        Parameters
        ----------
        L1, H, L2 : control systems
            The three blocks (transfer functions for L1 and L2, the member's hysteresis system
            for H), or a single :class:`control.InterconnectedSystem` made by
            :meth:`to_control` (its ``U0`` / ``Y0`` blocks give the rest level and offset).
        name : str, optional
            Name of the returned model (the member's default name otherwise).
        **options
            The member's own reading options (see its ``_from_blocks``).

        Returns
        -------
        Sandwich
            The model, placed as the interconnected system was.
        """
        import control as ct

        placement: dict[str, float] = {}
        if isinstance(L1, ct.InterconnectedSystem) and H is None and L2 is None:
            sys = L1
            subs = {s.name: s for s in sys.syslist}
            if not {"L1", "H", "L2"} <= subs.keys():
                raise ValueError(f"expected subsystems L1, H, L2 in {sys.name!r}, got {list(subs)}")
            L1, H, L2 = (_clean_tf(ct.ss2tf(subs["L1"])), subs["H"],
                         _clean_tf(ct.ss2tf(subs["L2"])))
            placement = {k: float(subs[b].params[k]) for b, k in (("U0", "u_rest"),
                                                                  ("Y0", "offset")) if b in subs}
        if H is None or L2 is None:
            raise ValueError("from_control needs L1, H and L2, or one InterconnectedSystem")
        if not (L1.dt and L1.dt == L2.dt == H.dt):
            raise ValueError(f"blocks must share one discrete dt; got {L1.dt}, {H.dt}, {L2.dt}")
        extra = {"name": name} if name is not None else {}
        return cls._from_blocks(L1, H, L2, **extra, **options, **placement)

    @classmethod
    def _from_blocks(cls, L1: ct.TransferFunction, H: ct.NonlinearIOSystem,
                     L2: ct.TransferFunction, **options: Any) -> Sandwich:
        raise NotImplementedError

    # ----------------------------------------------------------------- simulation
    def simulate(
        self,
        u: np.ndarray | Sequence[float],
        x0: InitialCondition | None = None,
        *,
        check: bool = True,
        **state: Any,
    ) -> SandwichResponse:
        """Simulate the sandwich with the member's compiled kernel.

        Parameters
        ----------
        u : array_like
            Input samples u(0) .. u(N-1), in the record's units.
        x0 : InitialCondition, optional
            Past signal values relative to the rest (``u - u_rest``, ``y - offset``);
            :meth:`at_rest` by default.
        check : bool
            Warn (:class:`~hystid.operating.AdmissibilityWarning`) when the model may not be
            trusted on ``u`` (:meth:`admissibility`); the reasons are also in
            ``response.warnings``.
        **state
            The hysteresis block's own state where the member takes one (``p0`` of the PI
            sandwich).

        Returns
        -------
        SandwichResponse
            A :class:`control.TimeResponseData`: input ``u``, output ``y``, states ``w1``,
            ``w2`` (each also an attribute); unpacks as ``t, y``.
        """
        from .response import SandwichResponse

        u = finite_signal(u, "u")
        if x0 is not None and not isinstance(x0, InitialCondition):
            raise TypeError(f"x0: expected a hystid.InitialCondition (past signal values) or "
                            f"None (at rest), got {type(x0).__name__}")
        x0 = x0 or self.at_rest()
        P = self.structure.history
        U, W1, W2, Y = (
            np.concatenate([x0.window(k, P), np.zeros(len(u))]) for k in ("u", "w1", "w2", "y")
        )
        U[P:] = u - self.u_rest
        with np.errstate(over="ignore", invalid="ignore"):
            self._run(U, W1, W2, Y, P, x0, **state)
        t = np.arange(len(u)) / self.fs
        resp = SandwichResponse(t, u, W1[P:], W2[P:], Y[P:] + self.offset, name=self.name,
                                units=self.units)
        if check:
            resp.warnings = self.admissibility(u, resp)
            warn_admissibility(resp.warnings, self.name)
        return resp

    def admissibility(
        self, u: np.ndarray, response: SandwichResponse | None = None
    ) -> list[str]:
        """Why the model may not be trusted on input ``u`` (empty when it may).

        Parameters
        ----------
        u : ndarray
            Input samples in the record's units.
        response : SandwichResponse, optional
            The simulated response to ``u`` when already at hand.

        Returns
        -------
        list of str
            Why the model itself is not sound (:func:`hystid.validate.check_model`: an
            unstable L1 or L2, a huge number, the member's own conditions), the envelope
            violations (:meth:`Envelope.violations`), a diverged simulation and the member's
            own test on the response (condition 8 for the Duhem block).
        """
        from .validate import check_model

        out = self.envelope.violations(u) if self.envelope is not None else []
        try:
            check_model(self)
        except ValueError as err:
            out.append(f"the model is not sound: {err}")
        if response is None:
            response = self.simulate(u, check=False)
        if not np.all(np.isfinite(response.y)):
            out.append("the simulation diverged (non-finite output)")
            return out
        return out + self._block_admissibility(response)

    def _repr_values(self) -> dict[str, float]:
        return self.params

    def __repr__(self) -> str:
        values = ", ".join(f"{k}={v:.6g}" for k, v in self._repr_values().items())
        placed = "".join(f", {k}={getattr(self, k):.6g}" for k in ("u_rest", "offset")
                         if getattr(self, k))
        return f"{type(self).__name__}({values}, fs={self.fs:g}{placed})"


def unit_gain_numerator(a: np.ndarray, b_rest: np.ndarray) -> np.ndarray:
    """Full numerator ``[b_1, b_2, ...]`` with ``b_1`` set for unit DC gain: sum b = 1 + sum a.

    Parameters
    ----------
    a : ndarray
        Denominator coefficients ``a_1 ..``.
    b_rest : ndarray
        Numerator coefficients after the first, ``b_2 ..``.

    Returns
    -------
    ndarray
        ``[b_1, b_2, ...]``.
    """
    return np.concatenate([[1.0 + np.sum(a) - np.sum(b_rest)], b_rest])


class UnitGainSandwich(Sandwich):
    """A sandwich whose L1 and L2 have unit DC gain: ``w1`` is in input units and the
    hysteresis block carries the quasi-static loop (the PI and multi-Duhem members).

    The first numerator coefficient of each linear block is derived
    (:func:`unit_gain_numerator`); the structure gives the slices of ``theta`` by group
    (``structure.slices()``: ``a1``, ``b1``, ``a2``, ``b2`` and the block's own).

    Parameters
    ----------
    *args, **kwargs
        Those of :class:`Sandwich`.
    """

    def _part(self, key: str) -> np.ndarray:
        return np.array(self.theta[self.structure.slices()[key]])

    @property
    def a1(self) -> np.ndarray:  # type: ignore[override]
        """L1 denominator coefficients ``a11 ..``."""
        return self._part("a1")

    @property
    def b1(self) -> np.ndarray:
        """L1 numerator coefficients ``b11, b12 ..`` (``b11`` derived: unit DC gain)."""
        return unit_gain_numerator(self.a1, self._part("b1"))

    @property
    def a2(self) -> np.ndarray:  # type: ignore[override]
        """L2 denominator coefficients ``a21 ..``."""
        return self._part("a2")

    @property
    def b2(self) -> np.ndarray:
        """L2 numerator coefficients ``b21, b22 ..`` (``b21`` derived: unit DC gain)."""
        return unit_gain_numerator(self.a2, self._part("b2"))

    @property
    def num1(self) -> np.ndarray:
        """Full numerator of L1 from its delay on: ``[b11, b12, ..]``."""
        return self.b1

    @property
    def num2(self) -> np.ndarray:
        """Full numerator of L2 from its delay on: ``[b21, b22, ..]``."""
        return self.b2


def _clean_tf(tf: ct.TransferFunction) -> ct.TransferFunction:
    """Round-off clean-up of a transfer function obtained from a state-space realisation."""
    import control as ct

    num = np.asarray(tf.num[0][0], float)
    den = np.asarray(tf.den[0][0], float)
    scale = max(np.max(np.abs(den)), 1.0)
    num = np.where(np.abs(num) < 1e-12 * scale, 0.0, num)
    return ct.tf(num, den, tf.dt, inputs=tf.input_labels, outputs=tf.output_labels)
