"""The Prandtl-Ishlinskii (PI) sandwich of the paper's comparison (eqs. 29-31).

::

    L1:  w1(k) = -a11 w1(k-1) - a12 w1(k-2) + b11 u(k-1) + b12 u(k-2)                  (29)
    H:   w2(k) = sum_i mu_i p_i(k),
         p_i(k) = max{w1(k) - r_i, min[w1(k) + r_i, p_i(k-1)]}                           (30)
    L2:  y(k)  = -a21 y(k-1) - a22 y(k-2) + b21 w2(k-1) + b22 w2(k-2)                    (31)

Each ``p_i`` is a backlash (play) operator of threshold ``r_i``; the hysteresis block is their
weighted sum, and with ``PIStructure(n_poly=k)`` memoryless terms beside them,
``w2 = sum_i mu_i p_i + c_2 w1^2 + .. + c_{k+1} w1^{k+1}`` (:func:`poly_terms`): a sum of plays
draws point-symmetric loops only, and the terms bend them (the ``pi-poly`` member). This module
holds

* :func:`pi_thresholds` -- the paper's threshold placement rule, ``r_i = i/N (max - min)/2``
  (with :func:`hystid.thresholds.swing_thresholds`, the fits' default, in
  :mod:`hystid.thresholds`);
* :func:`play_operator` and :func:`pi_operator` -- compiled eq. (30) on a whole signal;
* :func:`pi_inverse_parameters` -- the exact inverse PI operator (thresholds and weights);
* :func:`pi_block` / :func:`pi_inverse_block` -- both as discrete ``control.NonlinearIOSystem``
  with the play-operator states as system states (these four live in
  :mod:`hystid.pi_operator`, the operator alone, and are handed on here);
* :class:`PIStructure` and :class:`PISandwich` -- the model, with the same API as
  :class:`hystid.model.DuhemSandwich`.

Uniqueness. Scaling ``w2`` by ``c`` and ``L2`` by ``1/c`` leaves ``y`` unchanged, and because a
play operator is positively homogeneous (``P_r[c v] = c P_{r/|c|}[v]``), scaling ``w1`` only
rescales the thresholds. The model therefore fixes **unit DC gain for L1 and for L2**: the first
numerator coefficient of each is derived, ``b11 = 1 + a11 + a12 - b12`` and
``b21 = 1 + a21 + a22 - b22``, and the weights ``mu_i`` are free. Then ``w1`` is in input units
(the thresholds come from the input's range) and ``H`` is the quasi-static input-output loop
(weights in output units per input unit).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import control as ct
import numpy as np

from .operating import Envelope
from .pi_operator import (  # the operator; re-exported here, where the sandwich is
    _check_thresholds,
    _initial_states,
    _unpack,
    pi_block,
    pi_inverse_block,
    pi_inverse_parameters,
    pi_inverse_state,
    pi_operator,
    pi_simulate_into,
    play_operator,
    poly_keys,
    poly_terms,
    rest_plays,
)
from .poly import is_stable
from .sandwich import InitialCondition, UnitGainSandwich, unit_gain_numerator
from .signals import finite_number
from .thresholds import pi_thresholds

__all__ = [
    "PISandwich",
    "PIStructure",
    "pi_block",
    "pi_inverse_block",
    "pi_inverse_parameters",
    "pi_inverse_state",
    "pi_operator",
    "pi_thresholds",
    "play_operator",
    "pi_simulate_into",
    "poly_terms",
    "rest_plays",
    "unit_gain_numerator",
    "N_OPERATORS",
]

#: The paper's number of backlash operators (Section 4).
N_OPERATORS = 40


# =========================================================================== the sandwich
@dataclass(frozen=True)
class PIStructure:
    """Orders and delays of the PI sandwich (eqs. 29-31); the defaults are the paper's.

    Parameters
    ----------
    n_operators : int
        Number of play operators ``N``.
    n1a, n1b : int
        Denominator order and number of numerator coefficients of L1
        (``b11 .. b1{n1b}`` multiply ``u(k-q1) .. u(k-q1-n1b+1)``).
    n2a, n2b : int
        The same for L2.
    q1, q2 : int
        Input delays of L1 and L2 (1 in eqs. 29 and 31).
    n_poly : int
        Memoryless polynomial terms beside the plays, ``c_2 w1^2 .. c_{n_poly+1}
        w1^{n_poly+1}`` (``w1`` from the rest): the loop's asymmetry, which a sum of plays
        cannot make (its loops are point-symmetric). 0 (the paper's operator) by default.
    """

    n_operators: int = N_OPERATORS
    n1a: int = 2
    n1b: int = 2
    n2a: int = 2
    n2b: int = 2
    q1: int = 1
    q2: int = 1
    n_poly: int = 0

    def __post_init__(self) -> None:
        for key in ("n1a", "n2a", "q1", "q2", "n_poly"):
            value = getattr(self, key)
            if not isinstance(value, int | np.integer) or value < 0:
                raise ValueError(f"PIStructure: {key} must be a non-negative integer, got "
                                 f"{value!r}")
        for key in ("n_operators", "n1b", "n2b"):
            value = getattr(self, key)
            if not isinstance(value, int | np.integer) or value < 1:
                raise ValueError(f"PIStructure: {key} must be a positive integer, got {value!r}")
        from .validate import check_structure_size

        check_structure_size(self)  # a delay of 1e9 samples would allocate for minutes

    @property
    def names(self) -> tuple[str, ...]:
        """Free parameter names, in the order of ``theta``: L1, H, L2 (signal flow).

        ``b11`` and ``b21`` are not free: they fix unit DC gains (see the module docstring).
        """
        return (
            tuple(f"a1{i}" for i in range(1, self.n1a + 1))
            + tuple(f"b1{j}" for j in range(2, self.n1b + 1))
            + tuple(f"mu{i}" for i in range(self.n_operators))
            + tuple(f"c{j}" for j in range(2, self.n_poly + 2))
            + tuple(f"a2{i}" for i in range(1, self.n2a + 1))
            + tuple(f"b2{j}" for j in range(2, self.n2b + 1))
        )

    @property
    def history(self) -> int:
        """Number of past samples the difference equations reach back (at least 1)."""
        return max(1, self.n1a, self.q1 + self.n1b - 1, self.n2a, self.q2 + self.n2b - 1)

    def slices(self) -> dict[str, slice]:
        """Slices of ``theta`` by group: ``a1, b1, mu, c, a2, b2`` (free coefficients only;
        ``c`` the polynomial terms' coefficients, empty without them).

        Returns
        -------
        dict of str to slice
            Where each group sits in ``theta``.
        """
        sizes = (("a1", self.n1a), ("b1", self.n1b - 1), ("mu", self.n_operators),
                 ("c", self.n_poly), ("a2", self.n2a), ("b2", self.n2b - 1))
        out, start = {}, 0
        for key, size in sizes:
            out[key] = slice(start, start + size)
            start += size
        return out


class PISandwich(UnitGainSandwich):
    """Sandwich model L1 -> Prandtl-Ishlinskii H -> L2 (eqs. 29-31).

    Parameters
    ----------
    params : mapping or sequence of float
        Free parameters by name (see :attr:`PIStructure.names`: ``a11, a12, b12, mu0 ..
        mu{N-1}, a21, a22, b22``), or a vector in that order.
    thresholds : array_like
        Thresholds ``r_i`` of the play operators (see :func:`pi_thresholds`); their number sets
        ``N``.
    structure : PIStructure, optional
        Orders and delays; the paper's (eqs. 29, 31) with ``N = len(thresholds)`` by default.
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
    rest_swing : float
        The stage's last excursion before its rest, in input units from the rest (0 by
        default: the plays start virgin). A stage brought back to its rest from
        ``u_rest + rest_swing`` rests on one branch of its loop: each play sits at
        ``sign(s) min(max(|s| - r_i, 0), r_i)`` (:attr:`rest_plays`), the block's output at rest
        is their weighted sum and L2 has settled on it. The PI analogue of the Duhem sandwich's
        ``rest_memory``; the batch fit estimates it when the record starts at rest.

    Attributes
    ----------
    theta : ndarray
        Free parameter vector.
    thresholds : ndarray
        Play-operator thresholds (fixed, not identified).
    rest_swing : float
        See above.
    """

    #: The model file's ``kind`` (:mod:`hystid.modelfile`).
    kind = "pi"

    def __init__(
        self,
        params: Mapping[str, float] | Sequence[float] | np.ndarray,
        thresholds: np.ndarray | Sequence[float],
        structure: PIStructure | None = None,
        fs: float = 30_000.0,
        name: str = "PI sandwich",
        *,
        u_rest: float = 0.0,
        offset: float = 0.0,
        envelope: Envelope | None = None,
        units: Mapping[str, str] | None = None,
        rest_swing: float = 0.0,
    ) -> None:
        self.thresholds = _check_thresholds(thresholds)
        self.rest_swing = finite_number(rest_swing, "rest_swing")
        structure = structure or PIStructure(n_operators=len(self.thresholds))
        if structure.n_operators != len(self.thresholds):
            raise ValueError(
                f"thresholds: expected {structure.n_operators} values for the structure, "
                f"got {len(self.thresholds)}"
            )
        super().__init__(params, structure, fs, name, u_rest=u_rest, offset=offset,
                         envelope=envelope, units=units)

    # ----------------------------------------------------------------- parameters
    @property
    def mu(self) -> np.ndarray:
        """Weights ``mu_i`` of the play operators."""
        return self._part("mu")

    @property
    def poly(self) -> np.ndarray:
        """Coefficients ``c_2, c_3, ..`` of the memoryless terms beside the plays (empty for
        the paper's operator; see :attr:`PIStructure.n_poly`)."""
        return self._part("c")

    def hysteresis_output(self, w1: float, p: np.ndarray) -> float:
        """``w2`` for input ``w1`` (from the rest) and play states ``p`` already at ``w1``:
        the weighted plays and the polynomial terms.

        Parameters
        ----------
        w1 : float
            The block's input.
        p : ndarray
            The plays' states at that input.

        Returns
        -------
        float
        """
        return float(self.mu @ p) + poly_terms(float(w1), self.poly)[0]

    def w1_span(self) -> tuple[float, float]:
        """The block input's range the model is trusted on, from the rest: the envelope's input
        range (L1 has unit DC gain), else twice the largest threshold either side.

        Returns
        -------
        tuple of float
        """
        if self.envelope is not None:
            return (self.envelope.u_min - self.u_rest, self.envelope.u_max - self.u_rest)
        reach = 2.0 * float(np.max(self.thresholds))
        return (-reach, reach)

    def poly_slope_min(self) -> float:
        """The polynomial terms' least slope over :meth:`w1_span` (0 without them): at the
        span's ends or where the slope turns inside it.

        Returns
        -------
        float
        """
        if not len(self.poly):
            return 0.0
        lo, hi = self.w1_span()
        slope = np.polynomial.Polynomial(np.r_[0.0, 0.0, self.poly]).deriv()
        turns = slope.deriv().roots()
        turns = turns[np.isreal(turns)].real
        at = np.r_[lo, hi, turns[(turns > lo) & (turns < hi)]]
        return float(np.min(slope(at)))

    def branch_slope_min(self) -> float:
        """The least slope of any branch of the hysteresis block over :meth:`w1_span`: the
        least partial sum of the weights (a branch after a reversal, plays moving in order of
        their thresholds) plus the polynomial terms' least slope. Positive: every branch rises.

        Returns
        -------
        float
        """
        return float(np.min(np.cumsum(self.mu))) + self.poly_slope_min()

    @property
    def coefficients(self) -> dict[str, float]:
        """Every coefficient of eqs. (29) and (31) by name, the derived ``b11, b21`` included."""
        out = {}
        for prefix, vec in (("a1", self.a1), ("b1", self.b1), ("a2", self.a2), ("b2", self.b2)):
            out.update({f"{prefix}{i + 1}": float(v) for i, v in enumerate(vec)})
        return out

    def is_stable(self) -> bool:
        """True when the poles of L1 and L2 lie inside the unit circle.

        Returns
        -------
        bool
            Whether both linear blocks are stable.
        """
        return is_stable(self.a1, self.a2)

    def is_invertible(self) -> bool:
        """Whether the hysteresis block has an inverse (see :func:`pi_inverse_parameters`).

        Returns
        -------
        bool
            True when the thresholds start at 0 and increase and every branch rises
            (:meth:`branch_slope_min` positive; without polynomial terms: ``mu_0 > 0`` and
            every partial sum positive, the exact inverse's condition).
        """
        r = self.thresholds
        return bool(r[0] == 0 and np.all(np.diff(r) > 0) and self.branch_slope_min() > 0)

    # ----------------------------------------------------------------- python-control bridge
    @property
    def H(self) -> ct.NonlinearIOSystem:
        """PI hysteresis (eq. 30): discrete nonlinear system w1 -> w2 (see :func:`pi_block`).

        Its ``params`` are the block's (``pi_mu*``, ``pi_r*``) and, where not zero, the model's
        ``u_rest`` and ``offset``, which the update ignores and :meth:`from_control` reads back.
        """
        return self._carry(pi_block(self.thresholds, self.mu, dt=self.dt, name="H",
                                    poly=self.poly))

    @property
    def H_inverse(self) -> ct.NonlinearIOSystem:
        """The exact inverse of :attr:`H` (w2 -> w1), for hysteresis compensation.

        Raises
        ------
        ValueError
            With polynomial terms, which have no inverse PI operator (their per-sample inverse
            is the compensator's: :func:`hystid.compensate.compensator`).
        """
        if len(self.poly):
            raise ValueError("H_inverse: a PI block with polynomial terms has no inverse PI "
                             "operator; hystid.compensate inverts it sample by sample")
        return pi_inverse_block(self.thresholds, self.mu, dt=self.dt, name="H_inv")

    @property
    def rest_plays(self) -> np.ndarray:
        """The plays' states at rest after the swing :attr:`rest_swing` (zero without one)."""
        return rest_plays(self.rest_swing, self.thresholds)

    def at_rest(self) -> InitialCondition:
        """The past of the stage at rest: ``w1 = 0``, the plays at :attr:`rest_plays`, ``w2``
        their weighted sum and L2 (unit DC gain) settled on it.

        Returns
        -------
        InitialCondition
            Relative to the model's rest.
        """
        if not self.rest_swing:
            return InitialCondition()
        P = self.structure.history + 1
        w2 = self.hysteresis_output(0.0, self.rest_plays)
        return InitialCondition(w2=np.full(P, w2), y=np.full(P, w2))

    def operator_state(
        self, x0: InitialCondition | None = None, p0: np.ndarray | Sequence[float] | None = None
    ) -> np.ndarray:
        """Play-operator states ``p_i(-1)`` for a start from ``x0``.

        ``p0`` when given; otherwise the state reached from the state at rest
        (:attr:`rest_plays`) by a monotone move to ``w1(-1)``:
        ``p_i = max(w1 - r_i, min(w1 + r_i, p_rest_i))`` (``p_rest`` at rest).

        Parameters
        ----------
        x0 : InitialCondition, optional
            Past signal values (at rest by default).
        p0 : array_like, optional
            The operator states themselves.

        Returns
        -------
        ndarray
            One state per play operator.
        """
        if p0 is not None:
            return _initial_states(p0, len(self.thresholds))
        w1 = (x0 or InitialCondition()).window("w1", 1)[0]
        return np.maximum(w1 - self.thresholds, np.minimum(w1 + self.thresholds,
                                                           self.rest_plays))

    def settled_state(self, u0: float) -> InitialCondition:
        """The past of a stage that moved monotonically from its rest to input ``u0`` and is
        held there: L1 and L2 (unit DC gains) at their steady state, the plays where that move
        leaves them (:meth:`operator_state`).

        :func:`hystid.baselines.simulate_from_rest` starts a record that begins in motion
        from it at the record's mean input level (then a ramp to the first input); a record
        that begins at rest at another level starts from the model's own rest instead (its
        slow dynamics then follow the move as the stage's did).

        Parameters
        ----------
        u0 : float
            Input level.

        Returns
        -------
        InitialCondition
            Relative to the model's rest (see :meth:`simulate`).
        """
        P = self.structure.history + 1
        v = float(u0) - self.u_rest
        p = np.maximum(v - self.thresholds, np.minimum(v + self.thresholds, self.rest_plays))
        w2 = self.hysteresis_output(v, p)
        return InitialCondition(*(np.full(P, x) for x in (v, v, w2, w2)))

    def _h_state(self, x0: InitialCondition, **state: Any) -> np.ndarray:
        unknown = set(state) - {"p0"}
        if unknown:
            raise TypeError(f"the PI block takes the state p0, got {sorted(unknown)}")
        return self.operator_state(x0, state.get("p0"))

    structure_type = PIStructure
    _reading_options = ("prefix",)
    _carried = ("rest_swing",)

    @staticmethod
    def _prefixes(H: ct.NonlinearIOSystem) -> list[str]:
        """Prefixes ``p`` of the PI blocks whose ``p_mu0``, ``p_r0`` are in ``H.params``."""
        return [k[:-4] for k in H.params if k.endswith("_mu0") and f"{k[:-4]}_r0" in H.params]

    @classmethod
    def _holds(cls, H: ct.NonlinearIOSystem) -> bool:
        """Whether ``H`` is a PI block (:func:`pi_block`)."""
        return bool(cls._prefixes(H))

    @classmethod
    def _describe(cls, H: ct.NonlinearIOSystem | None = None) -> str:
        """What a PI block is, for messages."""
        if H is None:
            return "a Prandtl-Ishlinskii block, one state per play, params <prefix>_mu0, _r0 .."
        p = cls._prefixes(H)[0]
        return f"a Prandtl-Ishlinskii block of {H.nstates} plays (params {p}_mu*, {p}_r*)"

    @classmethod
    def _from_blocks(
        cls,
        L1: ct.TransferFunction,
        H: ct.NonlinearIOSystem,
        L2: ct.TransferFunction,
        structure: PIStructure | None = None,
        *,
        prefix: str | None = None,
        **model: Any,
    ) -> PISandwich:
        """The model from its three blocks (see :meth:`Sandwich.from_control`).

        Any DC gains of ``L1`` and ``L2`` are moved into ``H`` exactly: with ``L1 = g1 L1'``
        and ``L2 = g2 L2'`` (unit-gain ``L1', L2'``) the weights become ``g1 g2 mu_i`` and the
        thresholds ``r_i / |g1|`` (a play operator is positively homogeneous). The orders and
        delays are read from ``L1`` and ``L2`` (``structure`` when given), the number of plays
        from ``H``; ``prefix`` names ``H``'s parameters (the one ``H`` has by default).
        """
        n = H.nstates
        if structure is not None and structure.n_operators != n:
            raise ValueError(f"H has {n} play operators, the structure {structure.n_operators}")
        if prefix is None:
            found = cls._prefixes(H)
            if len(found) != 1:
                raise ValueError(f"H: params of {len(found)} PI blocks (prefixes {found}); pass "
                                 "prefix= to say which")
            prefix = found[0]
        try:
            mu, r = _unpack(H.params, prefix, n)
        except KeyError as err:
            raise ValueError(f"H: missing parameter {err} (expected {prefix}_mu0.., "
                             f"{prefix}_r0.., one per state)") from None
        values, (g1, g2), orders = cls._linear_parts(L1, L2, structure)
        values.update({f"mu{i}": g1 * g2 * m for i, m in enumerate(mu)})
        # c_j w1^j with w1 = g1 w1': the coefficient on w1'^j is g1^j g2 c_j
        keys = poly_keys(prefix, H.params)
        values.update({f"c{j}": g1 ** j * g2 * float(H.params[k])
                       for j, k in enumerate(keys, start=2)})
        if structure is not None and structure.n_poly != len(keys):
            raise ValueError(f"H has {len(keys)} polynomial terms, the structure "
                             f"{structure.n_poly}")
        s = structure or PIStructure(n_operators=n, n_poly=len(keys), **orders)
        return cls(values, r / abs(g1), s, fs=1.0 / L1.dt, **model)

    # ----------------------------------------------------------------- simulation
    def _run(self, U: np.ndarray, W1: np.ndarray, W2: np.ndarray, Y: np.ndarray, P: int,
             x0: InitialCondition, **state: Any) -> None:
        p = self._h_state(x0, **state)
        s = self.structure
        pi_simulate_into(self.a1, self.b1, s.q1, self.mu, self.poly, self.thresholds, self.a2,
                         self.b2, s.q2, U, W1, W2, Y, p, P)

    def __repr__(self) -> str:
        lin = ", ".join(f"{k}={v:.6g}" for k, v in self.coefficients.items())
        poly = "".join(f", c{j}={v:.6g}" for j, v in enumerate(self.poly, start=2))
        return f"PISandwich({lin}, N={len(self.thresholds)}{poly}, fs={self.fs:g})"
