"""The sandwich's blocks as python-control objects, and the way back.

* :func:`linear_block` -- L1 or L2 of eqs. (1)-(2) as a discrete :class:`control.TransferFunction`.
* :func:`linear_coefficients` -- the inverse: (a, b, q) read back from a transfer function.
* :func:`read_linear` -- ``(a, num, q)`` of :func:`transfer_function` read back from a transfer
  function or a state-space realisation, its orders and delay read from the coefficients or
  checked against given ones; :func:`as_transfer_function` -- a realisation back as a transfer
  function (exactly when it is the controller form :meth:`Sandwich.to_control
  <hystid.sandwich.Sandwich.to_control>` makes).
* :func:`duhem_block` -- the discrete Duhem operator of eq. (7) as a
  :class:`control.NonlinearIOSystem` with states ``w1(k-1), w2(k-1)`` and pure
  update/output functions.
* :func:`state_from_past` -- the state of a state-space realisation that reproduces a given past.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import control as ct
import numpy as np

__all__ = [
    "DUHEM_PARAMS",
    "SHAPE_PARAMS",
    "as_transfer_function",
    "duhem_increment",
    "duhem_block",
    "duhem_output",
    "linear_block",
    "linear_coefficients",
    "placement_blocks",
    "read_linear",
    "state_from_past",
    "transfer_function",
]

DUHEM_PARAMS = ("alpha", "f0", "f1", "g0")
#: The generalised Duhem block's shape parameters (see :mod:`hystid.kernels`).
SHAPE_PARAMS = ("f2", "f3", "g1", "g2", "ad", "gd")


def linear_block(
    a: Sequence[float],
    b: Sequence[float],
    q: int,
    dt: float,
    *,
    inputs: str,
    outputs: str,
    name: str,
) -> ct.TransferFunction:
    """Discrete transfer function of ``x(k) = sum_j b_j v(k-q-j) + v(k-q) - sum_i a_i x(k-i)``.

    Parameters
    ----------
    a : sequence of float
        Denominator coefficients ``a_1 .. a_na`` (``a_0 = 1``).
    b : sequence of float
        Numerator coefficients ``b_1 .. b_nb`` (``b_0 = 1`` for uniqueness, Assumption 1).
    q : int
        Input delay in samples.
    dt : float
        Sampling period in seconds.
    inputs, outputs, name : str
        Signal and system names.

    Returns
    -------
    control.TransferFunction
        ``z^-q (1 + b_1 z^-1 + ...) / (1 + a_1 z^-1 + ...)`` written in powers of ``z``.
    """
    b = np.concatenate([[1.0], np.asarray(b, dtype=float)])
    return transfer_function(a, b, q, dt, inputs=inputs, outputs=outputs, name=name)


def transfer_function(
    a: Sequence[float],
    num: Sequence[float],
    q: int,
    dt: float,
    *,
    inputs: str,
    outputs: str,
    name: str,
) -> ct.TransferFunction:
    """Discrete transfer function of ``x(k) = sum_j num_j v(k-q-j) - sum_i a_i x(k-i)``.

    Parameters
    ----------
    a : sequence of float
        Denominator coefficients ``a_1 .. a_na`` (``a_0 = 1``).
    num : sequence of float
        The whole numerator from the delay on, ``num_0, num_1, ..``.
    q : int
        Input delay in samples.
    dt : float
        Sampling period in seconds.
    inputs, outputs, name : str
        Signal and system names.

    Returns
    -------
    control.TransferFunction
        ``z^-q (num_0 + num_1 z^-1 + ...) / (1 + a_1 z^-1 + ...)`` written in powers of ``z``.
    """
    a = np.asarray(a, dtype=float)
    b = np.asarray(num, dtype=float)
    m = max(len(a), q + len(b) - 1)
    full = np.zeros(m + 1)
    full[q : q + len(b)] = b
    den = np.zeros(m + 1)
    den[0] = 1.0
    den[1 : 1 + len(a)] = a
    return ct.tf(full, den, dt, inputs=inputs, outputs=outputs, name=name)


def linear_coefficients(
    tf: ct.TransferFunction, na: int | None = None, nb: int | None = None
) -> tuple[np.ndarray, np.ndarray, int]:
    """Read ``(a, b, q)`` of :func:`linear_block` back from a discrete SISO transfer function.

    Parameters
    ----------
    tf : control.TransferFunction
        Proper SISO transfer function in powers of ``z``.
    na, nb : int, optional
        Orders to return (padding with zeros); inferred from the coefficients when omitted.

    Returns
    -------
    a, b : ndarray
        Denominator ``a_1..a_na`` and numerator ``b_1..b_nb`` with ``a_0 = b_0 = 1``.
    q : int
        Input delay.

    Raises
    ------
    ValueError
        If ``tf`` is not SISO, not proper, or its first numerator coefficient is not 1.
    """
    if not isinstance(tf, ct.TransferFunction) or tf.ninputs != 1 or tf.noutputs != 1:
        raise ValueError(f"expected a SISO control.TransferFunction, got {tf!r}")
    num = np.atleast_1d(np.squeeze(np.asarray(tf.num[0][0], dtype=float)))
    den = np.atleast_1d(np.squeeze(np.asarray(tf.den[0][0], dtype=float)))
    if len(num) > len(den):
        raise ValueError(f"transfer function {tf.name!r} is not proper")
    num = np.concatenate([np.zeros(len(den) - len(num)), num]) / den[0]
    den = den / den[0]
    nonzero = np.flatnonzero(num)
    if nonzero.size == 0:
        raise ValueError(f"transfer function {tf.name!r} has a zero numerator")
    q = int(nonzero[0])
    if not np.isclose(num[q], 1.0, rtol=1e-12, atol=0.0):
        raise ValueError(
            f"transfer function {tf.name!r}: leading numerator coefficient is {num[q]:g}; "
            "the sandwich model fixes b_0 = 1 (scale it into the next block)"
        )
    b = num[q + 1 : nonzero[-1] + 1]
    a = np.trim_zeros(den[1:], "b")
    if na is not None:
        a = np.pad(a, (0, max(0, na - len(a))))[:na]
    if nb is not None:
        b = np.pad(b, (0, max(0, nb - len(b))))[:nb]
    return a, b, q


def as_transfer_function(
    sys: ct.TransferFunction | ct.StateSpace, label: str
) -> ct.TransferFunction:
    """A SISO linear block as a transfer function named ``label``.

    A state-space realisation in the controller form of ``control.tf2ss(method='scipy')`` (the
    one :meth:`hystid.sandwich.Sandwich.to_control` makes: ``A`` a companion matrix, ``B`` the
    first unit vector) is read exactly, its zero coefficients staying zero; any other one goes
    through :func:`control.ss2tf` and coefficients below 1e-12 of the largest are set to zero.

    Parameters
    ----------
    sys : control.TransferFunction or control.StateSpace
        The block.
    label : str
        Its name in the result and in errors (``"L1"``, ``"L2"``).

    Returns
    -------
    control.TransferFunction
        The same block, named ``label``.

    Raises
    ------
    ValueError
        If ``sys`` is not a SISO transfer function or state-space system.
    """
    if isinstance(sys, ct.TransferFunction) and sys.ninputs == sys.noutputs == 1:
        return sys
    if not isinstance(sys, ct.StateSpace) or sys.ninputs != 1 or sys.noutputs != 1:
        raise ValueError(f"{label}: expected a SISO control.TransferFunction or StateSpace, got "
                         f"{type(sys).__name__} {getattr(sys, 'name', '')!r}")
    A, B, C, D = (np.asarray(m, dtype=float) for m in (sys.A, sys.B, sys.C, sys.D))
    n = A.shape[0]
    d = float(D[0, 0])
    if n == 0:
        num, den = np.array([d]), np.array([1.0])
    elif np.array_equal(A[1:], np.eye(n - 1, n)) and np.array_equal(B[:, 0], np.eye(n)[0]):
        den = np.r_[1.0, -A[0]]
        num = np.r_[d, C[0] + d * den[1:]]
    else:
        tf = ct.ss2tf(sys)
        num = np.array(tf.num[0][0], dtype=float)
        den = np.array(tf.den[0][0], dtype=float)
        for c in (num, den[1:]):
            c[np.abs(c) < 1e-12 * max(np.max(np.abs(den)), 1.0)] = 0.0
    return ct.tf(num, den, sys.dt, inputs=sys.input_labels, outputs=sys.output_labels,
                 name=label)


def read_linear(
    sys: ct.TransferFunction | ct.StateSpace,
    label: str,
    *,
    q: int | None = None,
    na: int | None = None,
    nb: int | None = None,
) -> tuple[np.ndarray, np.ndarray, int]:
    """Read ``(a, num, q)`` of :func:`transfer_function` back from a discrete SISO block.

    Without ``q, na, nb`` they are read from the coefficients: the delay is the number of
    leading zero numerator coefficients (in powers of ``z^-1``), the orders the spans of the
    non-zero ones (a block whose last coefficient is exactly zero reads one order lower: the
    same system). With them, the coefficients outside must be zero.

    Parameters
    ----------
    sys : control.TransferFunction or control.StateSpace
        The block (see :func:`as_transfer_function`).
    label : str
        Its name in errors.
    q, na, nb : int, optional
        Delay, denominator order and number of numerator coefficients to read (all three or
        none).

    Returns
    -------
    a : ndarray
        Denominator coefficients ``a_1 .. a_na`` (``a_0 = 1``).
    num : ndarray
        Numerator coefficients from the delay on, ``num_0 .. num_{nb-1}``.
    q : int
        The delay.

    Raises
    ------
    ValueError
        If the block is not SISO, not proper, has a zero numerator, or does not fit the given
        orders (saying which).
    """
    tf = as_transfer_function(sys, label)
    num = np.atleast_1d(np.asarray(tf.num[0][0], dtype=float))
    den = np.atleast_1d(np.asarray(tf.den[0][0], dtype=float))
    if len(num) > len(den) or den[0] == 0:
        raise ValueError(f"{label}: transfer function is not proper")
    num = np.concatenate([np.zeros(len(den) - len(num)), num]) / den[0]
    den = den / den[0]
    given = [v is not None for v in (q, na, nb)]
    if any(given) and not all(given):
        raise ValueError(f"{label}: expected q, na and nb together, or none of them")
    if q is None or na is None or nb is None:
        nonzero = np.flatnonzero(num)
        if nonzero.size == 0:
            raise ValueError(f"{label}: transfer function has a zero numerator")
        q = int(nonzero[0])
        return np.trim_zeros(den[1:], "b"), num[q : nonzero[-1] + 1].copy(), q
    scale = max(1.0, np.max(np.abs(num)))
    m = max(len(den) - 1, na, q + nb - 1)  # coefficients of z^0, z^-1, .. cover the structure
    num = np.pad(num, (0, m + 1 - len(num)))
    den = np.pad(den, (0, m + 1 - len(den)))
    outside = np.r_[num[:q], num[q + nb :]]
    if np.any(np.abs(outside) > 1e-9 * scale) or np.any(np.abs(den[1 + na :]) > 1e-9):
        raise ValueError(
            f"{label}: does not fit the structure (delay {q}, {nb} numerator and {na} "
            "denominator coefficients)"
        )
    return den[1 : 1 + na].copy(), num[q : q + nb].copy(), q


def duhem_output(x: np.ndarray, w1: float, params: dict) -> float:
    """w2(k) of eq. (7) from the state ``x = [w1(k-1), w2(k-1)]`` and the input ``w1(k)``.

    Parameters
    ----------
    x : ndarray
        State ``[w1(k-1), w2(k-1)]``.
    w1 : float
        Input ``w1(k)``.
    params : dict
        ``alpha``, ``f1``, ``g0``, optionally ``f0`` and the generalised block's ``f2, f3,
        g1, g2, ad, gd`` (see :mod:`hystid.kernels`; missing ones are zero).

    Returns
    -------
    float
        ``w2(k)``.
    """
    return float(x[1]) + duhem_increment(params, float(x[0]), float(x[1]), w1 - float(x[0]))


def duhem_increment(params: Mapping[str, float], w1p: float, w2p: float, dw1: float) -> float:
    """``w2(k) - w2(k-1)`` of the (generalised) eq. (7), one sample, in plain Python.

    The compiled form is :func:`hystid.kernels.step`; this one serves the python-control block
    and the rest-state ramp, and is tested against the kernel.

    Parameters
    ----------
    params : mapping
        ``alpha, f1, g0`` and optionally ``f0, f2, f3, g1, g2, ad, gd`` (zero when missing).
    w1p, w2p : float
        ``w1(k-1)`` and ``w2(k-1)``.
    dw1 : float
        ``w1(k) - w1(k-1)``.

    Returns
    -------
    float
        The increment of ``w2``.
    """
    p = {k: 0.0 for k in SHAPE_PARAMS} | {"f0": 0.0} | dict(params)
    s = float(np.sign(dw1))
    rate = p["alpha"] * (1.0 + p["ad"] * s)
    f = p["f0"] * np.sign(w1p) + p["f1"] * w1p + p["f2"] * w1p**2 + p["f3"] * w1p**3
    g = p["g0"] + p["g1"] * w1p + p["g2"] * w1p**2 + p["gd"] * s
    return float(rate * (f - w2p) * abs(dw1) + g * dw1)


def _duhem_update(t, x, u, params):
    w1 = u[0]
    return np.array([w1, duhem_output(x, w1, params)])


def _duhem_outfcn(t, x, u, params):
    return np.array([duhem_output(x, u[0], params)])


def duhem_block(
    alpha: float,
    f1: float,
    g0: float,
    f0: float = 0.0,
    *,
    shape: Mapping[str, float] | None = None,
    dt: float,
    inputs: str = "w1",
    outputs: str = "w2",
    name: str = "H",
) -> ct.NonlinearIOSystem:
    """The discrete Duhem hysteresis operator (eq. 7) as a python-control system.

    Parameters
    ----------
    alpha, f1, g0, f0 : float
        Duhem coefficients: ``f(w1) = f0 sgn(w1) + f1 w1`` (eq. 5), ``g(w1) = g0`` (eq. 6).
    shape : mapping, optional
        The generalised block's ``f2, f3, g1, g2, ad, gd`` (see :mod:`hystid.kernels`); the
        ones given become system ``params`` too.
    dt : float
        Sampling period in seconds.
    inputs, outputs, name : str
        Signal and system names.

    Returns
    -------
    control.NonlinearIOSystem
        States ``w1_prev, w2_prev``; direct feed-through from ``w1(k)`` to ``w2(k)``. The
        parameters ``alpha, f0, f1, g0`` are system ``params`` and can be overridden in
        :func:`control.input_output_response`.
    """
    params = {"alpha": float(alpha), "f0": float(f0), "f1": float(f1), "g0": float(g0)}
    for key, value in (shape or {}).items():
        if key not in SHAPE_PARAMS:
            raise ValueError(f"shape: unknown parameter {key!r} (expected some of "
                             f"{', '.join(SHAPE_PARAMS)})")
        params[key] = float(value)
    return ct.nlsys(
        _duhem_update,
        _duhem_outfcn,
        inputs=[inputs],
        outputs=[outputs],
        states=[f"{inputs}_prev", f"{outputs}_prev"],
        params=params,
        dt=dt,
        name=name,
    )


def _shift_input(t, x, u, params):
    return np.array([u[0] - params["u_rest"]])


def _add_offset(t, x, u, params):
    return np.array([u[0] + params["offset"]])


def placement_blocks(u_rest: float, offset: float, dt: float) -> list[ct.NonlinearIOSystem]:
    """Static blocks placing a sandwich at its rest level and sensor offset.

    Parameters
    ----------
    u_rest : float
        Input rest level: block ``U0`` maps ``u`` to ``v = u - u_rest`` (L1's input).
    offset : float
        Sensor offset: block ``Y0`` maps ``x`` (L2's output) to ``y = x + offset``.
    dt : float
        Sampling period in seconds.

    Returns
    -------
    list of control.NonlinearIOSystem
        ``[U0, Y0]``, stateless, with ``u_rest`` and ``offset`` as system ``params``.
    """
    return [
        ct.nlsys(None, _shift_input, inputs=["u"], outputs=["v"], params={"u_rest": u_rest},
                 dt=dt, name="U0"),
        ct.nlsys(None, _add_offset, inputs=["x"], outputs=["y"], params={"offset": offset},
                 dt=dt, name="Y0"),
    ]


def state_from_past(ss: ct.StateSpace, u_past: np.ndarray, y_past: np.ndarray) -> np.ndarray:
    """State ``x(k)`` of a discrete realisation whose last ``n`` inputs and outputs were given.

    Solves ``y(k-n+i) = C A^i x(k-n) + sum_j C A^(i-1-j) B u(k-n+j) + D u(k-n+i)`` for
    ``x(k-n)`` (the realisation must be observable) and propagates it ``n`` steps.

    Parameters
    ----------
    ss : control.StateSpace
        SISO discrete realisation of order ``n``.
    u_past, y_past : ndarray
        Past inputs and outputs, most recent last, at least ``n`` long (zeros are prepended if
        shorter).

    Returns
    -------
    ndarray
        The state ``x(k)``, ``n`` values.
    """
    A, B, C, D = (np.asarray(m, dtype=float) for m in (ss.A, ss.B, ss.C, ss.D))
    n = A.shape[0]
    if n == 0:
        return np.zeros(0)
    u = np.pad(np.asarray(u_past, float), (max(0, n - len(u_past)), 0))[-n:]
    y = np.pad(np.asarray(y_past, float), (max(0, n - len(y_past)), 0))[-n:]
    obs = np.zeros((n, n))
    forced = np.zeros(n)
    Ai = np.eye(n)
    for i in range(n):
        obs[i] = (C @ Ai)[0]
        acc = D[0, 0] * u[i]
        for j in range(i):
            acc += (C @ np.linalg.matrix_power(A, i - 1 - j) @ B)[0, 0] * u[j]
        forced[i] = acc
        Ai = Ai @ A
    x = np.linalg.lstsq(obs, y - forced, rcond=None)[0]
    for j in range(n):
        x = A @ x + B[:, 0] * u[j]
    return x
