"""The L1 - Duhem - L2 sandwich model (eqs. 1, 2, 7) and its python-control bridge."""

from __future__ import annotations

from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import control as ct
import numpy as np

from . import blocks
from .kernels import as_layout, simulate_into

if TYPE_CHECKING:  # pragma: no cover
    from matplotlib.axes import Axes

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
        return as_layout(self.n1a, self.n1b, self.n2a, self.n2b, self.q1, self.q2, self.f0)

    @property
    def history(self) -> int:
        """Number of past samples the difference equations reach back (at least 1)."""
        return max(1, self.n1a, self.q1 + self.n1b, self.n2a, self.q2 + self.n2b)


@dataclass
class InitialCondition:
    """Past values of the sandwich's signals, most recent last (``u(k-1), w1(k-1), ...``).

    Shorter arrays are padded with zeros at the old end; missing ones are zero (at rest).
    """

    u: np.ndarray = field(default_factory=lambda: np.zeros(0))
    w1: np.ndarray = field(default_factory=lambda: np.zeros(0))
    w2: np.ndarray = field(default_factory=lambda: np.zeros(0))
    y: np.ndarray = field(default_factory=lambda: np.zeros(0))

    def window(self, name: str, length: int) -> np.ndarray:
        """The last ``length`` values of signal ``name``, zero-padded at the old end."""
        v = np.asarray(getattr(self, name), dtype=float).ravel()
        if not np.all(np.isfinite(v)):
            raise ValueError(f"InitialCondition.{name} contains non-finite values")
        v = v[-length:] if length else v[:0]
        return np.concatenate([np.zeros(length - len(v)), v])


@dataclass
class SandwichResponse:
    """Simulated signals of the sandwich. Unpacks as ``t, y`` like python-control responses.

    Attributes
    ----------
    t, u, w1, w2, y : ndarray
        Time (s), input, internal signals and output.
    name : str
        Name of the simulated model.
    """

    t: np.ndarray
    u: np.ndarray
    w1: np.ndarray
    w2: np.ndarray
    y: np.ndarray
    name: str = "sandwich"

    def __iter__(self) -> Iterator[np.ndarray]:
        yield self.t
        yield self.y

    @property
    def duhem_margin(self) -> float:
        """max_k |dw1(k)|: condition (8) asks ``alpha * duhem_margin < 2``."""
        return float(np.max(np.abs(np.diff(self.w1)))) if len(self.w1) > 1 else 0.0

    def plot(self, ax: Sequence[Axes] | np.ndarray | None = None) -> Sequence[Axes] | np.ndarray:
        """Plot u, w1, w2 and y against time; returns the axes."""
        import matplotlib.pyplot as plt

        if ax is None:
            _, ax = plt.subplots(4, 1, sharex=True, figsize=(7, 6))
        for a, sig, label in zip(
            ax, (self.u, self.w1, self.w2, self.y), ("u", "w1", "w2", "y"), strict=False
        ):
            a.plot(self.t, sig, lw=0.8)
            a.set_ylabel(label)
        ax[-1].set_xlabel("time [s]")
        ax[0].set_title(self.name)
        return ax


class DuhemSandwich:
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

    Attributes
    ----------
    theta : ndarray
        Parameter vector in the paper's order (eq. 13).
    params : dict
        The same values by name.
    """

    def __init__(
        self,
        params: Mapping[str, float] | Sequence[float] | np.ndarray,
        structure: Structure | None = None,
        fs: float = 30_000.0,
        name: str = "sandwich",
    ) -> None:
        self.structure = structure or Structure()
        if not (np.isfinite(fs) and fs > 0):
            raise ValueError(f"fs must be a positive finite number of Hz, got {fs!r}")
        self.fs = float(fs)
        self.name = name
        self.theta = params_vector(params, self.structure.names)

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
        """True when L1 and L2 are stable and minimum phase (Assumption 1) and alpha > 0."""
        polys = [self.a1, self.b1, self.a2, self.b2]
        radius = max(
            (np.max(np.abs(np.roots(np.r_[1.0, p]))) if len(p) else 0.0) for p in polys
        )
        return bool(radius < 1.0 and self.params["alpha"] > 0)

    # ----------------------------------------------------------------- python-control bridge
    @property
    def dt(self) -> float:
        """Sampling period in seconds."""
        return 1.0 / self.fs

    @property
    def L1(self) -> ct.TransferFunction:
        """Amplifier + filter (eq. 1): discrete transfer function u -> w1."""
        s = self.structure
        return blocks.linear_block(
            self.a1, self.b1, s.q1, self.dt, inputs="u", outputs="w1", name="L1"
        )

    @property
    def L2(self) -> ct.TransferFunction:
        """Flexure hinge + load (eq. 2): discrete transfer function w2 -> y."""
        s = self.structure
        return blocks.linear_block(
            self.a2, self.b2, s.q2, self.dt, inputs="w2", outputs="y", name="L2"
        )

    @property
    def H(self) -> ct.NonlinearIOSystem:
        """Duhem hysteresis (eq. 7): discrete nonlinear system w1 -> w2."""
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
            :meth:`control_state` for the state matching an :class:`InitialCondition`.
        """
        l1 = ct.tf2ss(self.L1, method="scipy", inputs="u", outputs="w1", name="L1")
        l2 = ct.tf2ss(self.L2, method="scipy", inputs="w2", outputs="y", name="L2")
        return ct.interconnect(
            [l1, self.H, l2], inputs="u", outputs=["y", "w1", "w2"], name=self.name
        )

    def control_state(self, x0: InitialCondition | None = None) -> np.ndarray:
        """State vector of :meth:`to_control` that continues from the past ``x0``."""
        x0 = x0 or InitialCondition()
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
        """
        if isinstance(L1, ct.InterconnectedSystem) and H is None and L2 is None:
            sys = L1
            subs = {s.name: s for s in sys.syslist}
            if not {"L1", "H", "L2"} <= subs.keys():
                raise ValueError(f"expected subsystems L1, H, L2 in {sys.name!r}, got {list(subs)}")
            L1, H, L2 = (ct.ss2tf(subs["L1"]), subs["H"], ct.ss2tf(subs["L2"]))
            L1, L2 = _clean_tf(L1), _clean_tf(L2)
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
        return cls(values, structure, fs=1.0 / L1.dt, name=name)

    # ----------------------------------------------------------------- simulation
    def simulate(
        self, u: np.ndarray | Sequence[float], x0: InitialCondition | None = None
    ) -> SandwichResponse:
        """Simulate the sandwich with the compiled kernel.

        Parameters
        ----------
        u : array_like
            Input samples u(0) .. u(N-1).
        x0 : InitialCondition, optional
            Past signal values; at rest (all zero) by default.

        Returns
        -------
        SandwichResponse
            Time, input, ``w1``, ``w2`` and ``y``; unpacks as ``t, y``.
        """
        u = _as_signal(u, "u")
        x0 = x0 or InitialCondition()
        P = self.structure.history
        U, W1, W2, Y = (
            np.concatenate([x0.window(k, P), np.zeros(len(u))]) for k in ("u", "w1", "w2", "y")
        )
        U[P:] = u
        simulate_into(self.theta, self.structure.layout, U, W1, W2, Y, P)
        t = np.arange(len(u)) / self.fs
        return SandwichResponse(t, u, W1[P:], W2[P:], Y[P:], name=self.name)

    def __repr__(self) -> str:
        values = ", ".join(f"{k}={v:.6g}" for k, v in self.params.items())
        return f"DuhemSandwich({values}, fs={self.fs:g})"


def params_vector(
    params: Mapping[str, float] | Sequence[float] | np.ndarray, names: Sequence[str]
) -> np.ndarray:
    """Parameters as a vector in the order of ``names``, from a mapping or a sequence.

    Raises ``ValueError`` naming the missing, unknown or non-finite parameters.
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
    num = np.asarray(tf.num[0][0], float)
    den = np.asarray(tf.den[0][0], float)
    scale = max(np.max(np.abs(den)), 1.0)
    num = np.where(np.abs(num) < 1e-12 * scale, 0.0, num)
    return ct.tf(num, den, tf.dt, inputs=tf.input_labels, outputs=tf.output_labels)


def _as_signal(u, argname: str) -> np.ndarray:
    arr = np.asarray(u, dtype=float)
    if arr.ndim != 1:
        raise ValueError(f"{argname}: expected a 1-D array of samples, got shape {arr.shape}")
    if not np.all(np.isfinite(arr)):
        k = int(np.flatnonzero(~np.isfinite(arr))[0])
        raise ValueError(f"{argname}: non-finite value at sample {k}")
    return np.ascontiguousarray(arr)
