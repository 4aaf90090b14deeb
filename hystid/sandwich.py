"""The one sandwich base: what every member of the model family shares.

A sandwich is ``L1 -> H -> L2`` (eqs. 1, 7, 2 for the Duhem block, 29-31 for the PI block),
placed in the record's units (:mod:`hystid.operating`). :class:`Sandwich` owns everything but
the hysteresis block:

* the parameters (``theta`` in the structure's order, :attr:`params` by name) and ``fs``;
* placement, envelope and units (:class:`~hystid.operating.Placed`), :meth:`save`;
* the linear blocks :attr:`L1`, :attr:`L2` as ``control.TransferFunction``;
* :meth:`to_control` (the interconnection, with the ``U0``/``Y0`` placement blocks) and
  :meth:`control_state`, :meth:`from_control` (its inverse, and that of ``(L1, H, L2)``: on
  :class:`Sandwich` itself it chooses the member by the ``H`` block);
* :meth:`simulate`, returning a :class:`~hystid.response.SandwichResponse`, and
  :meth:`admissibility` (the model's soundness, the envelope, a finite output).

A member supplies only its own parts: its ``structure`` (with ``names``, ``history``, ``q1``,
``q2``), the coefficient vectors ``a1, a2`` and full numerators ``num1, num2`` of its linear
blocks, the hysteresis block :attr:`H` (its ``params`` carrying the placement, :meth:`_carry`)
and its state (:meth:`_h_state`), the compiled kernel (:meth:`_run`), optionally its own
admissibility test (:meth:`_block_admissibility`), and how it reads its blocks back: which
``H`` is its (:meth:`_holds`, :meth:`_describe`), its ``structure_type`` and
:meth:`_from_blocks`.
"""

from __future__ import annotations

import re
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


#: The members of the family by ``kind``, each reading its own H block: a class that sets its
#: own ``kind`` registers itself when it is defined (the base knows no member by name).
_MEMBERS: dict[str, type[Sandwich]] = {}


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

    def __init_subclass__(cls, **kwargs: Any) -> None:
        super().__init_subclass__(**kwargs)
        if cls.__dict__.get("kind"):  # a member: it names its own kind
            _MEMBERS.setdefault(cls.__dict__["kind"], cls)

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
        L1: ct.TransferFunction | ct.StateSpace | ct.InterconnectedSystem,
        H: ct.NonlinearIOSystem | None = None,
        L2: ct.TransferFunction | ct.StateSpace | None = None,
        *,
        structure: Any = None,
        like: Sandwich | None = None,
        name: str | None = None,
        **options: Any,
    ) -> Sandwich:
        """Build a model from python-control objects: the inverse of :meth:`to_control` and of
        ``(L1, H, L2)``.

        What the blocks hold is read back: the parameters, the structure (orders and delays
        from the coefficients, the number of plays or operators and the Duhem block's shape
        from ``H``), the rest level and offset (the ``U0`` / ``Y0`` blocks of an
        interconnected system; ``H`` carries them too, as ``params`` its update ignores, and
        the Duhem block its ``rest_memory``). Called on :class:`Sandwich` itself, the member is
        chosen by the ``H`` block; called on a member whose block ``H`` is not, it says which
        class reads it.

        The blocks do not hold the envelope nor the units (``None`` and ``{"u": "V", "y":
        "um"}`` unless given), nor an order whose last coefficient is exactly zero (it reads
        one order lower: the same system); pass ``like=model`` to take them from a model.

        Parameters
        ----------
        L1, H, L2 : control systems
            The three blocks (transfer functions or state-space realisations for L1 and L2,
            the member's hysteresis system for H), or a single
            :class:`control.InterconnectedSystem` made by :meth:`to_control` (its ``U0`` /
            ``Y0`` blocks give the rest level and offset; their absence means none).
        structure : object, optional
            The member's structure to read the blocks into (they must fit it); read from the
            blocks by default.
        like : Sandwich, optional
            A model of the same member whose structure (unless ``structure`` is given),
            envelope, units and name the result takes.
        name : str, optional
            Name of the returned model: the interconnected system's, ``like``'s or the
            member's default otherwise.
        **options
            ``u_rest``, ``offset``, ``envelope``, ``units`` (and ``rest_memory`` of the Duhem
            sandwich) override what the blocks and ``like`` give; the member's own reading
            options (``f0`` of :class:`~hystid.model.DuhemSandwich`, ``prefix`` of
            :class:`~hystid.pi.PISandwich`).

        Returns
        -------
        Sandwich
            The model; it simulates as the one the blocks came from.

        Raises
        ------
        ValueError
            If the system is not the sandwich's (its blocks named, the dt not shared, an ``H``
            block of no member or of another member than ``cls``'s, blocks that do not fit
            ``structure``).
        TypeError
            For an unknown option, naming the ones there are.
        """
        import control as ct

        placed: dict[str, Any] = {}
        if isinstance(L1, ct.InterconnectedSystem) and H is None and L2 is None:
            sys = L1
            subs = {s.name: s for s in sys.syslist}
            if not {"L1", "H", "L2"} <= subs.keys():
                raise ValueError(f"from_control: expected subsystems L1, H, L2 in {sys.name!r} "
                                 f"(a system made by to_control), got {list(subs)}")
            L1, H, L2 = subs["L1"], subs["H"], subs["L2"]
            for block, key in (("U0", "u_rest"), ("Y0", "offset")):  # the system's placement
                placed[key] = float(sys.params.get(key, subs[block].params[key])) \
                    if block in subs else 0.0
            if name is None and not re.fullmatch(r"sys\[\d+\]", str(sys.name)):
                name = sys.name
        elif H is None or L2 is None:
            raise ValueError("from_control: expected the blocks L1, H and L2, or one "
                             "control.InterconnectedSystem made by to_control; got "
                             f"{type(L1).__name__} and H={H!r}, L2={L2!r}")
        target = cls._reader(H)
        dts = [getattr(b, "dt", None) for b in (L1, H, L2)]
        if not (dts[0] and dts[0] is not True and dts[0] == dts[1] == dts[2]):
            raise ValueError(f"from_control: L1, H and L2 must share one discrete dt in "
                             f"seconds; got {dts}")
        carried = ("u_rest", "offset", *target._carried)
        settable = (*carried, "envelope", "units")
        unknown = sorted(set(options) - set(settable) - set(target._reading_options))
        if unknown:
            raise TypeError(f"{cls.__name__}.from_control: unknown options {unknown}; expected "
                            f"structure, like, name, {', '.join(settable)}"
                            + "".join(f", {o}" for o in target._reading_options))
        model: dict[str, Any] = {k: float(H.params[k]) for k in carried if k in H.params}
        model.update(placed)
        if like is not None:
            if not isinstance(like, target):
                raise ValueError(f"like: expected a {target.__name__} (the class that reads "
                                 f"this H block), got {type(like).__name__}")
            model.update(envelope=like.envelope, units=like.units)
            structure = like.structure if structure is None else structure
            name = like.name if name is None else name
        model.update({k: v for k, v in options.items() if k in settable})
        if name is not None:
            model["name"] = name
        if structure is not None and not isinstance(structure, target.structure_type):
            raise TypeError(f"structure: expected a {target.structure_type.__name__} for "
                            f"{target.__name__}, got {type(structure).__name__}")
        reading = {k: v for k, v in options.items() if k in target._reading_options}
        return target._from_blocks(L1, H, L2, structure, **reading, **model)

    # ----------------------------------------------------------------- reading blocks back
    #: The structure class of the member (set by each member).
    structure_type: ClassVar[type] = object
    #: Constructor keywords beyond ``u_rest`` and ``offset`` that :attr:`H` carries in its
    #: ``params`` (the Duhem sandwich's ``rest_memory``).
    _carried: ClassVar[tuple[str, ...]] = ()
    #: The member's own options of :meth:`from_control`.
    _reading_options: ClassVar[tuple[str, ...]] = ()

    @classmethod
    def _holds(cls, H: ct.NonlinearIOSystem) -> bool:
        """Whether ``H`` is this member's hysteresis block (none for the base)."""
        return False

    @classmethod
    def _describe(cls, H: ct.NonlinearIOSystem | None = None) -> str:
        """What ``H`` (or the member's block in general) is, for messages."""
        return "a hysteresis block"

    @classmethod
    def _reader(cls, H: Any) -> type[Sandwich]:
        """The class that reads ``H``: ``cls`` when it holds the block, the member that does
        when ``cls`` is not a member (:class:`Sandwich` itself); otherwise a clear error."""
        import control as ct

        if not isinstance(H, ct.NonlinearIOSystem):
            raise ValueError(f"H: expected the model's hysteresis block, a discrete "
                             f"control.NonlinearIOSystem, got {type(H).__name__} "
                             f"{getattr(H, 'name', '')!r}")
        if cls._holds(H):
            return cls
        members = _member_classes()
        owner = next((m for m in members if m._holds(H)), None)
        if owner is None:
            raise ValueError(
                "H: expected the hysteresis block of a hystid member ("
                + "; ".join(f"{m.__name__}: {m._describe(None)}" for m in members)
                + f"), got {H.name!r} with {H.nstates} states and params {sorted(H.params)}")
        if not cls.kind:
            return owner
        raise ValueError(
            f"{cls.__name__}.from_control: the H block is {owner._describe(H)}, which "
            f"{owner.__module__}.{owner.__name__} reads: call {owner.__name__}.from_control, or "
            "hystid.sandwich.Sandwich.from_control, which chooses the class by the H block")

    @classmethod
    def _from_blocks(cls, L1: ct.TransferFunction, H: ct.NonlinearIOSystem,
                     L2: ct.TransferFunction, structure: Any = None, **model: Any) -> Sandwich:
        """The member's model from its blocks; ``model`` holds the constructor's keywords."""
        raise NotImplementedError(f"{cls.__name__} does not read python-control blocks; use "
                                  "hystid.sandwich.Sandwich.from_control")

    def _carry(self, block: ct.NonlinearIOSystem) -> ct.NonlinearIOSystem:
        """``block`` with the model's non-zero placement (``u_rest``, ``offset`` and the
        member's :attr:`_carried`) added to its ``params``: the update ignores them, and
        :meth:`from_control` reads them back."""
        block.params.update({k: float(getattr(self, k)) for k in ("u_rest", "offset",
                                                                  *self._carried)
                             if getattr(self, k)})
        return block

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

        u = finite_signal(u, "u", min_size=1)
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

    @classmethod
    def _linear_parts(
        cls, L1: Any, L2: Any, structure: Any = None
    ) -> tuple[dict[str, float], tuple[float, float], dict[str, int]]:
        """The free coefficients of L1 and L2 read as unit-gain blocks, the DC gains ``g1, g2``
        moved out of them (the member moves them into H) and the orders and delays read
        (``n1a, n1b, q1, n2a, n2b, q2``; those of ``structure`` when given)."""
        from .blocks import read_linear

        values: dict[str, float] = {}
        gains: list[float] = []
        orders: dict[str, int] = {}
        for j, tf in ((1, L1), (2, L2)):
            given = {} if structure is None else {
                "q": getattr(structure, f"q{j}"), "na": getattr(structure, f"n{j}a"),
                "nb": getattr(structure, f"n{j}b")}
            a, b, q = read_linear(tf, f"L{j}", **given)
            g = float(np.sum(b) / (1.0 + np.sum(a)))
            if not np.isfinite(g) or g == 0:
                raise ValueError(f"L{j}: expected a finite non-zero DC gain (moved into H), got "
                                 f"{g:g}")
            values.update({f"a{j}{i + 1}": float(v) for i, v in enumerate(a)})
            values.update({f"b{j}{i + 1}": float(v) / g for i, v in enumerate(b) if i > 0})
            gains.append(g)
            orders.update({f"n{j}a": len(a), f"n{j}b": len(b), f"q{j}": q})
        return values, (gains[0], gains[1]), orders

    @property
    def num1(self) -> np.ndarray:
        """Full numerator of L1 from its delay on: ``[b11, b12, ..]``."""
        return self.b1

    @property
    def num2(self) -> np.ndarray:
        """Full numerator of L2 from its delay on: ``[b21, b22, ..]``."""
        return self.b2


def _member_classes() -> tuple[type[Sandwich], ...]:
    """The members of the family defined so far (a member's H block exists only once its
    module is loaded), each reading its own H block."""
    return tuple(_MEMBERS.values())
