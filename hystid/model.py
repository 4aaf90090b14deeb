"""The L1 - Duhem - L2 sandwich model (eqs. 1, 2, 7) and its python-control bridge."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from .operating import Envelope, Placed, warn_admissibility
from .signals import finite_number, finite_signal

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
    """

    n1a: int = 1
    n1b: int = 0
    n2a: int = 2
    n2b: int = 0
    q1: int = 1
    q2: int = 0
    f0: bool = False

    def __post_init__(self) -> None:
        for key in ("n1a", "n1b", "n2a", "n2b", "q1", "q2"):
            value = getattr(self, key)
            if not isinstance(value, int | np.integer) or value < 0:
                raise ValueError(f"Structure: {key} must be a non-negative integer, got {value!r}")
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
        )

    @property
    def layout(self) -> np.ndarray:
        """Integer layout passed to the compiled kernels."""
        from .kernels import as_layout  # numba loads on first use, not on import hystid

        return as_layout(self.n1a, self.n1b, self.n2a, self.n2b, self.q1, self.q2, self.f0)

    @property
    def history(self) -> int:
        """Number of past samples the difference equations reach back (at least 1)."""
        return max(1, self.n1a, self.q1 + self.n1b, self.n2a, self.q2 + self.n2b)


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


class DuhemSandwich(Placed):
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
        self.structure = structure or Structure()
        if not (np.isfinite(fs) and fs > 0):
            raise ValueError(f"fs must be a positive finite number of Hz, got {fs!r}")
        self.fs = float(fs)
        self.name = name
        self.theta = params_vector(params, self.structure.names)
        self._place(u_rest, offset, envelope, units)
        self.rest_memory = finite_number(rest_memory, "rest_memory")

    # ----------------------------------------------------------------- parameters
    @property
    def params(self) -> dict[str, float]:
        """Parameter values by name."""
        return dict(zip(self.structure.names, map(float, self.theta), strict=True))

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
        return float(self.params["alpha"] * np.max(np.abs(num / den) * move))

    # ----------------------------------------------------------------- python-control bridge
    @property
    def dt(self) -> float:
        """Sampling period in seconds."""
        return 1.0 / self.fs

    @property
    def L1(self) -> ct.TransferFunction:
        """Amplifier + filter (eq. 1): discrete transfer function u -> w1."""
        from . import blocks

        s = self.structure
        return blocks.linear_block(
            self.a1, self.b1, s.q1, self.dt, inputs="u", outputs="w1", name="L1"
        )

    @property
    def L2(self) -> ct.TransferFunction:
        """Flexure hinge + load (eq. 2): discrete transfer function w2 -> y."""
        from . import blocks

        s = self.structure
        return blocks.linear_block(
            self.a2, self.b2, s.q2, self.dt, inputs="w2", outputs="y", name="L2"
        )

    @property
    def H(self) -> ct.NonlinearIOSystem:
        """Duhem hysteresis (eq. 7): discrete nonlinear system w1 -> w2."""
        from . import blocks

        p = self.params
        return blocks.duhem_block(
            p["alpha"], p["f1"], p["g0"], p.get("f0", 0.0), dt=self.dt, name="H"
        )

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

        from . import blocks

        placed = bool(self.u_rest or self.offset)
        l1 = ct.tf2ss(self.L1, method="scipy", inputs="v" if placed else "u", outputs="w1",
                      name="L1")
        l2 = ct.tf2ss(self.L2, method="scipy", inputs="w2", outputs="x" if placed else "y",
                      name="L2")
        systems = [l1, self.H, l2]
        if placed:
            systems += blocks.placement_blocks(self.u_rest, self.offset, self.dt)
        return ct.interconnect(
            systems, inputs="u", outputs=["y", "w1", "w2"], name=self.name
        )

    def control_state(self, x0: InitialCondition | None = None) -> np.ndarray:
        """State vector of :meth:`to_control` that continues from the past ``x0``.

        Parameters
        ----------
        x0 : InitialCondition, optional
            Past signal values; at rest by default.

        Returns
        -------
        ndarray
            The states of ``L1``, ``H`` and ``L2`` in the order of :meth:`to_control`.
        """
        import control as ct

        from . import blocks

        x0 = x0 or self.at_rest()
        n = self.structure.history + 1
        l1 = ct.tf2ss(self.L1, method="scipy")
        l2 = ct.tf2ss(self.L2, method="scipy")
        x1 = blocks.state_from_past(l1, x0.window("u", n), x0.window("w1", n))
        x2 = blocks.state_from_past(l2, x0.window("w2", n), x0.window("y", n))
        xh = [x0.window("w1", 1)[0], x0.window("w2", 1)[0]]
        return np.concatenate([x1, xh, x2])

    @classmethod
    def from_control(
        cls,
        L1: ct.TransferFunction | ct.InterconnectedSystem,
        H: ct.NonlinearIOSystem | None = None,
        L2: ct.TransferFunction | None = None,
        *,
        f0: bool | None = None,
        name: str = "sandwich",
    ) -> DuhemSandwich:
        """Build a model from python-control objects.

        Parameters
        ----------
        L1, H, L2 : control systems
            The three blocks (transfer functions for L1 and L2, the Duhem system for H), or a
            single :class:`control.InterconnectedSystem` made by :meth:`to_control`.
        f0 : bool, optional
            Keep the ``f0 sgn`` term; by default only when ``H.params['f0']`` is non-zero.
        name : str
            Name of the returned model.

        Returns
        -------
        DuhemSandwich
            The model, with the rest level and offset of ``U0`` / ``Y0`` blocks if present.
        """
        import control as ct

        from . import blocks

        placement = {}
        if isinstance(L1, ct.InterconnectedSystem) and H is None and L2 is None:
            sys = L1
            subs = {s.name: s for s in sys.syslist}
            if not {"L1", "H", "L2"} <= subs.keys():
                raise ValueError(f"expected subsystems L1, H, L2 in {sys.name!r}, got {list(subs)}")
            L1, H, L2 = (ct.ss2tf(subs["L1"]), subs["H"], ct.ss2tf(subs["L2"]))
            L1, L2 = _clean_tf(L1), _clean_tf(L2)
            placement = {k: float(subs[b].params[k]) for b, k in (("U0", "u_rest"),
                                                                  ("Y0", "offset")) if b in subs}
        if H is None or L2 is None:
            raise ValueError("from_control needs L1, H and L2, or one InterconnectedSystem")
        if L1.dt != L2.dt or L1.dt != H.dt or not L1.dt:
            raise ValueError(f"blocks must share one discrete dt; got {L1.dt}, {H.dt}, {L2.dt}")
        a1, b1, q1 = blocks.linear_coefficients(L1)
        a2, b2, q2 = blocks.linear_coefficients(L2)
        hp = H.params
        f0_value = float(hp.get("f0", 0.0))
        use_f0 = bool(f0_value != 0.0) if f0 is None else f0
        structure = Structure(len(a1), len(b1), len(a2), len(b2), q1, q2, use_f0)
        values = {"alpha": hp["alpha"], "f1": hp["f1"], "g0": hp["g0"]}
        if use_f0:
            values["f0"] = f0_value
        for prefix, vec in (("a1", a1), ("b1", b1), ("a2", a2), ("b2", b2)):
            values.update({f"{prefix}{i + 1}": v for i, v in enumerate(vec)})
        return cls(values, structure, fs=1.0 / L1.dt, name=name, **placement)

    # ----------------------------------------------------------------- simulation
    def simulate(
        self,
        u: np.ndarray | Sequence[float],
        x0: InitialCondition | None = None,
        *,
        check: bool = True,
    ) -> SandwichResponse:
        """Simulate the sandwich with the compiled kernel.

        Parameters
        ----------
        u : array_like
            Input samples u(0) .. u(N-1), in the record's units.
        x0 : InitialCondition, optional
            Past signal values relative to the rest (``u - u_rest``, ``y - offset``); at rest
            with the model's :attr:`rest_memory` by default (:meth:`at_rest`).
        check : bool
            Warn (:class:`~hystid.operating.AdmissibilityWarning`) when the input leaves the
            model's envelope or condition (8) fails; the reasons are also in
            ``response.warnings``.

        Returns
        -------
        SandwichResponse
            A :class:`control.TimeResponseData`: input ``u``, output ``y``, states ``w1``,
            ``w2`` (each also an attribute); unpacks as ``t, y``.
        """
        from .kernels import simulate_into
        from .response import SandwichResponse

        u = finite_signal(u, "u")
        x0 = x0 or self.at_rest()
        P = self.structure.history
        U, W1, W2, Y = (
            np.concatenate([x0.window(k, P), np.zeros(len(u))]) for k in ("u", "w1", "w2", "y")
        )
        U[P:] = u - self.u_rest
        with np.errstate(over="ignore", invalid="ignore"):
            simulate_into(self.theta, self.structure.layout, U, W1, W2, Y, P)
        t = np.arange(len(u)) / self.fs
        resp = SandwichResponse(t, u, W1[P:], W2[P:], Y[P:] + self.offset, name=self.name,
                                units=self.units)
        if check:
            resp.warnings = self.admissibility(u, resp)
            warn_admissibility(resp.warnings, self.name)
        return resp

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

    def _l2_gain(self) -> float:
        return float((1.0 + np.sum(self.b2)) / (1.0 + np.sum(self.a2)))

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
        p = self.params
        f0 = p.get("f0", 0.0)
        w2, prev = self.rest_memory, 0.0
        for x in np.linspace(0.0, w1, steps + 1)[1:]:
            d = x - prev
            w2 += p["alpha"] * (f0 * np.sign(prev) + p["f1"] * prev - w2) * abs(d) + p["g0"] * d
            prev = x
        y = w2 * self._l2_gain()
        return InitialCondition(*(np.full(P, x) for x in (v, w1, w2, y)))

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
            unstable L1 or L2, ``alpha <= 0``, a huge number), the envelope violations
            (:meth:`Envelope.violations`) and, when condition (8)
            ``alpha |dw1(k)| < 2`` fails at some sample, how often and how far.
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
        ratio = self.params["alpha"] * np.abs(np.diff(response.w1))
        bad = int(np.count_nonzero(ratio >= 2.0))
        if bad:
            out.append(f"condition (8) fails at {bad} samples (alpha |dw1| up to "
                       f"{np.max(ratio):.3g}, expected < 2): the Duhem recursion amplifies "
                       "there")
        return out


    def __repr__(self) -> str:
        values = ", ".join(f"{k}={v:.6g}" for k, v in self.params.items())
        placed = "".join(f", {k}={getattr(self, k):.6g}" for k in ("u_rest", "offset")
                         if getattr(self, k))
        return f"DuhemSandwich({values}, fs={self.fs:g}{placed})"


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



def _clean_tf(tf: ct.TransferFunction) -> ct.TransferFunction:
    """Round-off clean-up of a transfer function obtained from a state-space realisation."""
    import control as ct

    num = np.asarray(tf.num[0][0], float)
    den = np.asarray(tf.den[0][0], float)
    scale = max(np.max(np.abs(den)), 1.0)
    num = np.where(np.abs(num) < 1e-12 * scale, 0.0, num)
    return ct.tf(num, den, tf.dt, inputs=tf.input_labels, outputs=tf.output_labels)


def __getattr__(name: str):
    # SandwichResponse subclasses control.TimeResponseData: python-control loads on first use
    if name == "SandwichResponse":
        from .response import SandwichResponse

        return SandwichResponse
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
