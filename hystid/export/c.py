"""C99 export of a saved model: the placed model, the feed-forward compensator and the on-line
identifier's step, as ``hystid_model.h`` and ``hystid_model.c``.

The generated code allocates nothing and includes nothing beyond ``math.h``. Every number it
holds comes from the same Python objects the Python functions run on (the model's coefficients,
the compensator's chain arrays, the on-line identifier's packed state), written with 17
significant digits, and the C code does the same floating-point operations in the same order,
so it agrees with Python sample by sample to the last bit when the compiler does not contract
``a*b+c`` into fused multiply-adds (``-ffp-contract=off``, GCC's default with ``-std=c99``;
clang contracts by default) and is not given ``-ffast-math``; otherwise to round-off.

What each function is:

* ``hystid_model_step`` -- ``model.simulate(u).y`` one sample at a time: the recorded input in
  (record units), the displacement out (record units, the sensor offset included), from rest
  (the Duhem state at the model's ``rest_memory``, a PI model's plays where its
  ``rest_swing`` left them).
* ``hystid_ff_step`` -- :func:`hystid.compensate.compensate` one sample at a time, in the
  record's units (the reference as the sensor reads it in, the command as the amplifier takes
  it out; the rest level and the model's output at rest, or the reference's first sample with
  ``anchor="reference"``; limits from the model's envelope by default; L2 inverted by its
  stable inverse, the pre-actuation cut at the start made up; see :func:`ff_options`).
  ``compensate`` reads the reference ``preview`` samples ahead (the reference model's lead, L2's
  delay and pre-actuation, L1's delay and the reversal planner's preview); a causal step
  cannot, so the C step returns the command for the reference ``HYSTID_FF_DELAY = preview``
  samples earlier (during the first ``HYSTID_FF_DELAY`` calls, the rest command). Fed the
  reference followed by ``HYSTID_FF_DELAY`` copies of its last value, it returns
  ``compensate(model, r).u`` after those first calls.
* ``hystid_rpem_step`` -- one sample of the on-line identifier's recursion
  (:func:`hystid.identify.online.rpem_run`) and its supervisor
  (:mod:`hystid.identify.online_supervisor`; ``HYSTID_RPEM_SUPERVISE 0`` leaves it out),
  warm-started from the saved model (see :func:`hystid.export.rpem.rpem_start`; its Python
  counterpart is :func:`hystid.export.rpem.rpem_reference`); Duhem models only (the paper's
  block and the generalised one). The start-up solve of
  :class:`~hystid.identify.online.OnlineIdentifier` (a batch fit) is not part of the export.

The placed model and the compensator are written for the Duhem sandwich (the paper's block and
the generalised one: ``f_order``, ``g_order``, ``directional``), the Prandtl-Ishlinskii
sandwiches and the multi-Duhem sandwich: the plain Duhem block's inverse with its reversal
planner, the PI operator's exact inverse, the generalised block's and the parallel Duhem
operators' per-sample inverses without look-ahead (:mod:`hystid.compensate.member_inverse`) and
the central line; the on-line identifier for the Duhem sandwiches.
"""

from __future__ import annotations

import inspect
import os
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from ..kernels import offsets
from ..model import DuhemSandwich
from ._c_ff import FF_PLANNER
from ._c_ff_members import FF_GDUHEM, FF_MDUHEM, FF_MEMBER, FF_PI_POLY, ff_chain
from ._c_model import DUHEM_STEP, GDUHEM_STEP, MDUHEM_STEP, MODEL_COMMON, PI_STEP, SHAPE_TERMS
from ._c_rpem import GDUHEM_RPEM_STEP, RPEM_STEP
from .rpem import rpem_start

if TYPE_CHECKING:  # pragma: no cover
    from ..compensate.placed import _Plan
    from ..identify.online import OnlineIdentifier
    from ..mduhem import MultiDuhemSandwich
    from ..pi import PISandwich
    from ..records import Record

__all__ = ["C_FILES", "FF_KEYS", "c_sources", "export_c", "ff_options", "ff_plan",
           "rpem_start"]

#: The files :func:`export_c` writes.
C_FILES = ("hystid_model.h", "hystid_model.c")


# =========================================================================== numbers as C
def _num(x: float) -> str:
    """A double as C text that reads back to the same bits (Python's shortest repr)."""
    x = float(x)
    if not np.isfinite(x):
        raise ValueError(f"cannot export a non-finite number ({x!r})")
    text = repr(x)
    return f"({text})" if text.startswith("-") else text


def _array(name: str, values: Sequence[float] | np.ndarray) -> str:
    """``static const double name[n] = {...};`` (one placeholder 0.0 when empty: C has no
    empty arrays; the code never reads it then)."""
    vals = [float(v) for v in np.ravel(np.asarray(values, dtype=float))] or [0.0]
    body = ",\n    ".join(", ".join(_num(v) for v in vals[i:i + 4]) for i in range(0, len(vals), 4))
    return f"static const double {name}[{len(vals)}] = {{\n    {body}\n}};\n"


def _define(name: str, value: float | int) -> str:
    if isinstance(value, int | np.integer) and not isinstance(value, bool):
        return f"#define {name} {int(value)}\n"
    return f"#define {name} {_num(value)}\n"


# =========================================================================== the parts
def _model_part(model: DuhemSandwich | PISandwich | MultiDuhemSandwich) -> tuple[str, str]:
    """(header text, source text) of the placed model."""
    s = model.structure
    duhem = isinstance(model, DuhemSandwich)
    multi = _is_mduhem(model)
    hist = s.history
    head = (_define("HYSTID_FS", model.fs) + _define("HYSTID_U_REST", model.u_rest)
            + _define("HYSTID_OFFSET", model.offset) + _define("HYSTID_MODEL_WINDOW", hist + 1))
    fields = "    double u[HYSTID_MODEL_WINDOW], w1[HYSTID_MODEL_WINDOW];\n" \
             "    double w2[HYSTID_MODEL_WINDOW], y[HYSTID_MODEL_WINDOW];\n"
    if duhem:
        head += "#define HYSTID_KIND_DUHEM 1\n"
        if not s.is_plain:
            head += ("/* the generalised Duhem block: f_order, g_order, directional */\n"
                     "#define HYSTID_DUHEM_GENERALISED 1\n")
    elif multi:
        head += "#define HYSTID_KIND_MDUHEM 1\n" + _define("HYSTID_MODEL_OPERATORS",
                                                           len(model.rates))
        fields += "    double p[HYSTID_MODEL_OPERATORS]; /* the Duhem operators' states */\n"
    else:
        head += "#define HYSTID_KIND_PI 1\n" + _define("HYSTID_MODEL_OPERATORS",
                                                       len(model.thresholds))
        fields += "    double p[HYSTID_MODEL_OPERATORS]; /* play-operator states */\n"
    head += ("\n/* The placed model's state: past samples of u - u_rest, w1, w2 and y - offset "
             "(newest last). */\ntypedef struct hystid_model_state {\n" + fields
             + "} hystid_model_state;\n\n"
             "/* Start at rest (the state model.simulate starts from). */\n"
             "void hystid_model_init(hystid_model_state *s);\n"
             "/* One sample: the recorded input u in, the displacement out (record units). */\n"
             "double hystid_model_step(hystid_model_state *s, double u);\n")
    src = (_define("HX_HIST", hist) + _define("HX_Q1", s.q1) + _define("HX_Q2", s.q2)
           + _define("HX_N1A", len(model.a1)) + _define("HX_N1B", len(model.b1))
           + _define("HX_N2A", len(model.a2)) + _define("HX_N2B", len(model.b2))
           + _array("hx_a1", model.a1) + _array("hx_b1", model.b1)
           + _array("hx_a2", model.a2) + _array("hx_b2", model.b2))
    if duhem:
        p = model.params
        rest = model.at_rest()
        src += (_define("HX_ALPHA", p["alpha"]) + _define("HX_F0", p.get("f0", 0.0))
                + _define("HX_F1", p["f1"]) + _define("HX_G0", p["g0"])
                + _define("HX_W2_REST", rest.window("w2", 1)[0])
                + _define("HX_Y_REST", rest.window("y", 1)[0]))
        if s.is_plain:
            src += DUHEM_STEP
        else:
            src += (_shape_indices(s) + _array("hx_theta", model.theta) + SHAPE_TERMS
                    + GDUHEM_STEP)
    elif multi:
        src += (_define("HX_NOP", len(model.rates)) + _array("hx_alpha", model.rates)
                + _array("hx_f1", model.f1) + _array("hx_g0", model.g0) + MDUHEM_STEP)
    else:
        rest = model.at_rest()  # the plays where the swing before the rest left them
        src += (_define("HX_NPI", len(model.thresholds)) + _array("hx_r", model.thresholds)
                + _array("hx_p_rest", model.rest_plays)
                + _define("HX_W2_REST", rest.window("w2", 1)[0])
                + _define("HX_Y_REST", rest.window("y", 1)[0])
                + _array("hx_mu", model.mu) + _define("HX_NPOLY", len(model.poly))
                + _array("hx_c", model.poly) + PI_STEP)
    return head, src


def _is_mduhem(model: Any) -> bool:
    return getattr(type(model), "kind", None) == "mduhem"


def _shape_indices(structure: Any) -> str:
    """``HX_I_*``: where :func:`hystid.kernels.shape_terms` reads each group in ``theta`` (0 for
    a group the structure has not: the loops over it are empty then), and the group sizes."""
    from ..kernels import offsets, shape_offsets

    layout = structure.layout
    _, i_alpha, _, i_f1, _, i_g0, _, _ = (int(v) for v in offsets(layout))
    i_f2, i_g1, i_ad = (max(int(v), 0) for v in shape_offsets(layout))
    return "".join(_define(f"HX_{k}", int(v)) for k, v in (
        ("I_ALPHA", i_alpha), ("I_F1", i_f1), ("I_G0", i_g0), ("I_F2", i_f2), ("I_G1", i_g1),
        ("I_AD", i_ad), ("NF", layout[7]), ("NG", layout[8]), ("DIRECTIONAL", layout[9])))


#: The keyword arguments of :func:`hystid.compensate.compensate` the exported compensator takes.
FF_KEYS = ("u_limits", "margin", "reference_model", "reference_lead", "preview", "duhem_bound",
           "compensation", "anchor")


def ff_options(
    model: DuhemSandwich | PISandwich | MultiDuhemSandwich, **options: Any
) -> dict[str, Any]:
    """The keyword arguments of :func:`hystid.compensate.compensate` the export runs with.

    The exported step is ``compensate(model, r, **ff_options(model, ...))`` one sample at a
    time, in the record's units (the reference as the sensor reads it in, the command as the
    amplifier takes it out). The options not given take ``compensate``'s defaults; the limits
    are resolved: ``u_limits`` when given, else the model's envelope widened by ``margin``
    (:func:`~hystid.compensate.envelope_limits`).

    Parameters
    ----------
    model : DuhemSandwich, PISandwich or MultiDuhemSandwich
        The model.
    **options
        Any of :data:`FF_KEYS`.

    Returns
    -------
    dict
        Every key of :data:`FF_KEYS`, ``u_limits`` in the record's units.

    Raises
    ------
    ValueError
        For an unknown option, or no ``u_limits`` for a model without an envelope.
    """
    from ..compensate import placed

    unknown = sorted(set(options) - set(FF_KEYS))
    if unknown:
        raise ValueError(f"compensator options: unknown {unknown} (expected {list(FF_KEYS)})")
    params = inspect.signature(placed.compensate).parameters
    kw = {k: options.get(k, params[k].default) for k in FF_KEYS}
    if kw["u_limits"] is None:
        kw["u_limits"] = placed.envelope_limits(model, kw["margin"])
    return kw


def ff_plan(model: DuhemSandwich | PISandwich | MultiDuhemSandwich, **options: Any) -> _Plan:
    """The stages the exported ``hystid_ff_step`` runs (see :func:`ff_options`).

    Parameters
    ----------
    model : DuhemSandwich, PISandwich or MultiDuhemSandwich
        The model.
    **options
        As for :func:`ff_options`.

    Returns
    -------
    hystid.compensate.placed._Plan
        What :func:`hystid.compensate.compensate` runs; its ``preview`` is the step's delay
        ``HYSTID_FF_DELAY``.
    """
    from ..compensate import placed

    return placed._plan(model, **ff_options(model, **options))


def _ff_part(
    plan: _Plan, model: DuhemSandwich | PISandwich | MultiDuhemSandwich
) -> tuple[str, str]:
    """(header text, source text) of the compensator."""
    from ..compensate import compensator as comp
    from ..compensate import duhem_inverse as di

    chain, l2 = plan.chain, plan.l2
    ispec, fpar = chain.ispec, chain.fpar
    kind = int(ispec[comp._KIND])
    # the PI block's polynomial terms (their count after ispec[_NI]; none without them)
    npoly = int(ispec[comp._NI]) if kind == comp.KIND_PI and len(ispec) > comp._NI else 0
    names = {comp.KIND_DUHEM: "Duhem",
             comp.KIND_PI: ("PI block with polynomial terms' per-sample" if npoly else
                            "Prandtl-Ishlinskii"),
             comp.KIND_LINEAR: "central-line",
             comp.KIND_GDUHEM: "generalised Duhem block's per-sample",
             comp.KIND_MDUHEM: "multi-Duhem sandwich's per-sample"}
    if kind not in names:
        raise ValueError(f"compensator kind {kind} is not exported to C (the C step has the "
                         "Duhem (plain and generalised), multi-Duhem, Prandtl-Ishlinskii and "
                         "central-line inverses)")
    rest = min(max(0.0, float(fpar[comp._UMIN])), float(fpar[comp._UMAX])) + model.u_rest
    P = int(ispec[comp._P])
    if int(ispec[comp._NM]) or int(ispec[comp._L2MODE]) or int(ispec[comp._Q2]):
        raise ValueError("the compensator chain must have L2 left out (it is inverted ahead)")
    lines = int(ispec[comp._OFF_U])  # x_M (empty), the y_M and w2d lines
    M = bool(plan.m_num.size)
    ns = int(l2.A.shape[0])
    where = "the first reference sample" if plan.anchor == "reference" else \
        "the model's output at rest"
    planner = (
        "/* the reversal planner's memo (hystid.compensate.duhem_inverse.planner_memo): the "
        "previous\n   sample's near-branch path (a ring of gaps) and the backward sets it "
        "keeps */\n"
        + _define("HYSTID_FF_PLAN_K", di._K)
        + _define("HYSTID_FF_PLAN_ROOM", 2 * di.MEMO_INTERVALS * (P + 1))
        + "typedef struct hystid_ff_planner {\n"
        "    int base, key, end, j, target, kept, exit, fill;\n"
        "    int count[HYSTID_FF_PREVIEW + 1], place[HYSTID_FF_PREVIEW + 1];\n"
        "    double key_w1, key_w2, end_w1, end_w2;\n"
        "    double gaps[HYSTID_FF_PREVIEW + 1];\n"
        "    double scratch[4][HYSTID_FF_PLAN_K];\n"
        "    double room[HYSTID_FF_PLAN_ROOM];\n"
        "} hystid_ff_planner;\n")
    head = (f"\n/* Feed-forward compensator: hystid.compensate.compensate(model, r) one sample "
            f"at a time ({names[kind]}\n   inverse), in the record's units: the reference as the "
            f"sensor reads it in, the command as the\n   amplifier takes it out (limits "
            f"{plan.u_limits[0]!r} .. {plan.u_limits[1]!r}; the stage rests at {where}).\n"
            f"   compensate() reads the reference {plan.preview} samples ahead (reference "
            f"model lead {plan.lead}, L2's delay\n   {l2.delay} and pre-actuation {l2.pre}, L1's "
            f"delay {chain.delay}, reversal planner {P}): the step takes r(n) and\n   returns "
            f"the command for r(n - HYSTID_FF_DELAY). */\n"
            + _define("HYSTID_FF_DELAY", plan.preview) + _define("HYSTID_FF_PREVIEW", P)
            + _define("HYSTID_FF_SETTLE", max(l2.settle, 1))
            + _define("HYSTID_FF_NX", int(ispec[comp._NX]) - lines)
            + _define("HYSTID_FF_W_LINE", P + 1)
            + _define("HYSTID_FF_M_NX", max(plan.m_num.size, 1))
            + _define("HYSTID_FF_M_NY", max(plan.m_den.size - 1, 1))
            + _define("HYSTID_FF_L2_NX", l2.num.size)
            + _define("HYSTID_FF_L2_NY", max(l2.den.size - 1, 1))
            + _define("HYSTID_FF_L2_NF", l2.fir.size) + _define("HYSTID_FF_L2_NS", max(ns, 1))
            + _define("HYSTID_FF_YD_LINE", l2.preview + chain.advance + 1)
            + _define("HYSTID_FF_U_MIN", plan.u_limits[0])
            + _define("HYSTID_FF_U_MAX", plan.u_limits[1])
            + "/* the command returned while the first HYSTID_FF_DELAY references are read in */\n"
            + _define("HYSTID_FF_REST_COMMAND", rest)
            + (planner if kind == comp.KIND_DUHEM else "")
            + "typedef struct hystid_ff_state {\n"
            "    double x[HYSTID_FF_NX]; /* the Python chain's state after its reference "
            "lines */\n"
            "    double wl[2 * HYSTID_FF_W_LINE]; /* its w2d line: a ring written twice */\n"
            "    int wpos;\n"
            + ("    hystid_ff_planner plan; /* the reversal planner's memo */\n"
               if kind == comp.KIND_DUHEM else "")
            + (
            "    double mx[HYSTID_FF_M_NX], my[HYSTID_FF_M_NY]; /* reference model */\n"
            "    double lx[HYSTID_FF_L2_NX], lv[HYSTID_FF_L2_NY]; /* L2^-1, causal part */\n"
            "    double fl[2 * HYSTID_FF_L2_NF]; /* L2^-1, anti-causal part */\n"
            "    int slot;\n"
            "    double xs[HYSTID_FF_L2_NS], corr[HYSTID_FF_SETTLE]; /* pre-actuation made up */\n"
            "    double ydl[HYSTID_FF_YD_LINE]; /* desired output, aligned with the command (a "
            "ring) */\n"
            "    int ypos;\n"
            "    double y_rest;\n    long n;\n    double u, yd;\n    int status;\n"
            "} hystid_ff_state;\n\n"
            "void hystid_ff_init(hystid_ff_state *s);\n"
            "/* r: the reference now (record units); returns the command for the reference "
            "HYSTID_FF_DELAY\n   samples ago (record units). */\n"
            "double hystid_ff_step(hystid_ff_state *s, double r);\n"
            "/* the output asked for at that command's sample (compensate().y_des) and the "
            "status bits (1 step\n   clipped to the bound of condition 8, 2 no exact step, 4 "
            "saturated, 8 turning the hysteresis round) */\n"
            "double hystid_ff_desired(const hystid_ff_state *s);\n"
            "int hystid_ff_status(const hystid_ff_state *s);\n"))
    # the C state x is the chain's vector without its leading part ([x_M | y_M line | w2d
    # line], x_M empty): w2d's line is a ring of its own, the y_M line is not read in C
    names_i = ("KIND", "N1A", "N1B", "Q1", "N2A", "N2B", "Q2", "NM", "L2MODE", "P", "NPI",
               "OFF_U", "OFF_W1", "OFF_H", "NX", "H1", "Q")
    shifted = ("OFF_U", "OFF_W1", "OFF_H", "NX")
    src = "".join(_define(f"HX_FF_{n}", int(ispec[getattr(comp, f"_{n}")])
                          - (lines if n in shifted else 0)) for n in names_i)
    fnames = ("ALPHA", "F0", "F1", "G0", "BOUND", "UMIN", "UMAX", "B1LEAD", "B2LEAD", "K2", "KH")
    src += "".join(_define(f"HX_FF_{n}", float(fpar[getattr(comp, f"_{n}")])) for n in fnames)
    src += "".join(_define(f"HX_FF_{k}", v) for k, v in (
        ("ADVANCE", chain.advance), ("Y_REST", plan.y_rest), ("REST", plan.rest),
        ("U_SHIFT", plan.u_rest), ("ANCHOR_REFERENCE", int(plan.anchor == "reference")),
        ("M", int(M)), ("M_ND", plan.m_den.size - 1), ("LEAD", plan.lead),
        ("L2_DELAY", l2.delay), ("L2_PRE", l2.pre), ("L2_ND", l2.den.size - 1)))
    arrays: dict[str, np.ndarray] = {"a1": chain.a1, "b1t": chain.b1t, "l2_num": l2.num,
                                     "l2_den": l2.den, "l2_fir": l2.fir}
    if l2.pre:
        arrays.update(l2_a=l2.A, l2_b=l2.B, l2_gain=l2.gain)
    if M:
        arrays.update(m_num=plan.m_num, m_den=plan.m_den)
    member = ""
    if kind == comp.KIND_PI:
        arrays.update(r_pi=chain.r_pi, mu_pi=chain.mu_pi,
                      p_rest=plan.plays if len(plan.plays) else np.zeros(len(chain.r_pi)))
        src += _define("HX_FF_NPOLY", npoly)
        if npoly:  # the polynomial terms: the per-sample inverse (pi_poly_inverse)
            arrays.update(poly=fpar[comp._NF:comp._NF + npoly])
            member = FF_PI_POLY
        else:  # the exact inverse PI operator
            arrays.update(r_inv=chain.r_inv, mu_inv=chain.mu_inv)
    if kind == comp.KIND_GDUHEM:  # the chain's theta, read by the model part's hx_shape_terms
        theta, layout = fpar[comp._NF:], ispec[comp._NI:]
        # hx_shape_terms reads theta at the HX_I_* indices of the model's layout
        if not np.array_equal(layout, model.structure.layout):  # pragma: no cover
            raise ValueError("the compensator's generalised Duhem block is not the model's")
        i_f0 = int(offsets(layout)[2])
        src += _define("HX_FF_GD_F0", float(theta[i_f0]) if i_f0 >= 0 else 0.0)
        arrays.update(theta=theta)
        member = FF_MEMBER + FF_GDUHEM
    elif kind == comp.KIND_MDUHEM:  # the operators' rates, f1_j and g0_j, HX_FF_NPI of each
        m = int(ispec[comp._NPI])
        h = fpar[comp._NF:]
        arrays.update(md_rates=h[:m], md_f1=h[m:2 * m], md_g0=h[2 * m:3 * m])
        member = FF_MEMBER + FF_MDUHEM
    src += "".join(_array(f"hx_ff_{k}", v) for k, v in arrays.items())
    if kind == comp.KIND_DUHEM:
        src += FF_PLANNER
    return head, src + member + ff_chain(kind)


def _rpem_part(ident: OnlineIdentifier, supervise: bool = True) -> tuple[str, str]:
    """(header text, source text) of the on-line identifier's step; ``ident`` has its
    supervisor (its constants are written whether it is on by default or not)."""
    from ..identify import online_kernels as on
    from ..identify import online_supervisor as osup
    from ..kernels import offsets

    s = ident.structure
    npar = len(ident.theta)
    w = ident.window
    sett = ident._sett
    sup = ident._supervisor
    if sup is None or osup.BLOCK > 128:  # hx_block_sum is numpy's sum of at most 128 terms
        raise ValueError("the exported on-line identifier needs the supervisor's state and "
                         "blocks of at most 128 samples")
    head = ("\n/* On-line identifier (hystid.identify.online: recursive prediction error), "
            "warm-started from\n   the model. Parameters in the order of "
            f"theta: {', '.join(s.names)}; then the offset.\n"
            "   HYSTID_RPEM_SUPERVISE 1: with the supervisor of "
            "hystid.identify.online_supervisor (as\n   OnlineIdentifier(supervise=True) after "
            "its start-up; the warm start is the validated estimate):\n   the last validated "
            "estimate and a candidate run freely beside the recursion, and every\n"
            "   HYSTID_RPEM_BLOCK samples the recursion is rolled back to the validated one "
            "when it diverges\n   or wanders, or the candidate validates. 0: the bare "
            "recursion (OnlineIdentifier(supervise=False)).\n"
            "   Define it alike for every file that includes this header. Cost: every sample "
            "is the recursion's\n   step (with its HYSTID_RPEM_NPAR sensitivities) and two "
            "model steps (the free runs); the\n   sample that ends a block (the worst) adds a "
            "sum of at most HYSTID_RPEM_BLOCK squares and at\n   most one rollback and one "
            "new candidate: copies of (HYSTID_RPEM_NPAR + 1)^2 covariances and\n   of the "
            "signal windows, O(HYSTID_RPEM_BLOCK + HYSTID_RPEM_NPAR^2 + HYSTID_RPEM_WINDOW "
            "HYSTID_RPEM_NPAR). */\n"
            + f"#ifndef HYSTID_RPEM_SUPERVISE\n#define HYSTID_RPEM_SUPERVISE {int(supervise)}\n"
            "#endif\n"
            + _define("HYSTID_RPEM_NPAR", npar) + _define("HYSTID_RPEM_WINDOW", w)
            + _define("HYSTID_RPEM_BLOCK", osup.BLOCK)
            + "#if HYSTID_RPEM_SUPERVISE\n"
            "/* a frozen estimate (with its covariance) and its free run: past samples of u - "
            "u_rest, w1, w2\n   and y - offset, and since it was taken sum e^2, samples, "
            "sum |dw1| */\n"
            "typedef struct hystid_rpem_shadow {\n"
            "    double est[HYSTID_RPEM_NPAR + 1];\n"
            "    double P[HYSTID_RPEM_NPAR + 1][HYSTID_RPEM_NPAR + 1];\n"
            "    double u[HYSTID_RPEM_WINDOW], w1[HYSTID_RPEM_WINDOW], w2[HYSTID_RPEM_WINDOW];\n"
            "    double y[HYSTID_RPEM_WINDOW], sums[3];\n"
            "} hystid_rpem_shadow;\n#endif\n"
            + "typedef struct hystid_rpem_state {\n"
            "    double est[HYSTID_RPEM_NPAR + 1], est_good[HYSTID_RPEM_NPAR + 1];\n"
            "    double P[HYSTID_RPEM_NPAR + 1][HYSTID_RPEM_NPAR + 1];\n"
            "    double P_good[HYSTID_RPEM_NPAR + 1][HYSTID_RPEM_NPAR + 1];\n"
            "    double scal[13], PH[HYSTID_RPEM_NPAR + 1], cand[HYSTID_RPEM_NPAR + 1];\n"
            "    double work[HYSTID_RPEM_NPAR + 1];\n"
            "    double u[HYSTID_RPEM_WINDOW], w1[HYSTID_RPEM_WINDOW], w2[HYSTID_RPEM_WINDOW];\n"
            "    double yh[HYSTID_RPEM_WINDOW], ym[HYSTID_RPEM_WINDOW];\n"
            "    double s1[HYSTID_RPEM_WINDOW][HYSTID_RPEM_NPAR];\n"
            "    double s2[HYSTID_RPEM_WINDOW][HYSTID_RPEM_NPAR];\n"
            "    double sy[HYSTID_RPEM_WINDOW][HYSTID_RPEM_NPAR];\n"
            "    double e;\n"
            "#if HYSTID_RPEM_SUPERVISE\n"
            "    hystid_rpem_shadow shadow[2]; /* the validated estimate and the candidate */\n"
            "    int accepted, filled, n_ok;\n"
            "    double sq[HYSTID_RPEM_BLOCK]; /* the block's squared residuals */\n"
            "    double before[2], live[2], versus[2], settle;\n"
            "    long rollbacks, validated;\n"
            "#endif\n} hystid_rpem_state;\n\n"
            "void hystid_rpem_init(hystid_rpem_state *s);\n"
            "/* One sample: the recorded input u and the measured output y (record units; a "
            "non-finite y\n   is skipped). */\n"
            "void hystid_rpem_step(hystid_rpem_state *s, double u, double y);\n"
            "/* The current estimate: HYSTID_RPEM_NPAR parameters, then the sensor offset. */\n"
            "const double *hystid_rpem_theta(const hystid_rpem_state *s);\n"
            "double hystid_rpem_offset(const hystid_rpem_state *s);\n"
            "/* The last residual y - yhat - offset (NaN for a skipped sample). */\n"
            "double hystid_rpem_error(const hystid_rpem_state *s);\n"
            "/* Restarts after a diverging residual so far (the supervisor's rollbacks "
            "included). */\n"
            "long hystid_rpem_restarts(const hystid_rpem_state *s);\n"
            "/* The supervisor's rollbacks and validated candidates so far (0 without it). */\n"
            "long hystid_rpem_rollbacks(const hystid_rpem_state *s);\n"
            "long hystid_rpem_validated(const hystid_rpem_state *s);\n")
    i_b2, i_alpha, i_f0, i_f1, i_b1, i_g0, i_a1, i_a2 = (int(v) for v in offsets(s.layout))
    src = "".join(_define(f"HX_R_{k}", v) for k, v in (
        ("NPAR", npar), ("NE", npar + 1), ("W", w), ("N1A", s.n1a), ("N1B", s.n1b),
        ("N2A", s.n2a), ("N2B", s.n2b), ("Q1", s.q1), ("Q2", s.q2), ("I_ALPHA", i_alpha),
        ("I_F0", i_f0), ("I_F1", i_f1), ("I_B1", i_b1), ("I_G0", i_g0), ("I_A1", i_a1),
        ("I_A2", i_a2), ("RESYNC", max(s.n2a, s.q2 + s.n2b)), ("ALPHA_MARGIN", on.ALPHA_MARGIN),
        ("BLOCK", osup.BLOCK), ("HYSTERESIS", osup.HYSTERESIS), ("FORGET", osup.FORGET),
        ("FLOOR", sup.floor), ("SETTLE", float(sup._settle_until)),
        ("SUP_RATIO", sup.diverge_ratio)))
    if i_b2 != 0:  # the C code reads b2j at theta[j - 1]
        raise ValueError("unexpected parameter layout: b2 does not lead theta")
    settings = {"LAM_INF": "LAM_INF", "LAM_RATE": "LAM_RATE", "CLIP": "CLIP",
                "TRACE_MAX": "TRACE", "DIV_RATIO": "DIV_RATIO", "DIV_HOLD": "DIV_HOLD",
                "PRESET": "PRESET", "KMAX": "KMAX", "A_SHORT": "SHORT", "A_LONG": "LONG",
                "A_SIG": "SIG", "TRACK": "TRACK"}
    src += "".join(_define(f"HX_R_{c}", float(sett[getattr(on, f"_S_{k}")]))
                   for c, k in settings.items())
    pos = int(ident._ints[on._I_POS])
    windows = np.concatenate([a[pos - w:pos] for a in ident._windows[:5]])
    src += (_array("hx_r_est0", ident._est) + _array("hx_r_p0", ident.P)
            + _array("hx_r_scal0", ident._scal) + _array("hx_r_win0", windows))
    return head, src + (RPEM_STEP if s.is_plain else GDUHEM_RPEM_STEP)


# =========================================================================== assembling
def c_sources(
    model: DuhemSandwich | PISandwich | MultiDuhemSandwich,
    *,
    source: str = "",
    compensator: Mapping[str, Any] | None = None,
    rpem_sigma: float | None = None,
    rpem_record: Record | None = None,
    rpem_supervise: bool = True,
    notes: list[str] | None = None,
) -> dict[str, str]:
    """The text of ``hystid_model.h`` and ``hystid_model.c`` for a model.

    Parameters
    ----------
    model : DuhemSandwich, PISandwich or MultiDuhemSandwich
        The model (placed or not; the Duhem sandwich with the paper's block or the generalised
        one).
    source : str
        Where the model came from (a file name), for the header's comment.
    compensator : mapping, optional
        Options of :func:`hystid.compensate.compensate` for the exported compensator (see
        :func:`ff_options`).
    rpem_sigma : float, optional
        Initial residual scale of the on-line identifier (see :func:`rpem_start`).
    rpem_record : Record, optional
        A record of the stage for the on-line identifier's starting information.
    rpem_supervise : bool
        The default of ``HYSTID_RPEM_SUPERVISE`` in the header: the on-line identifier's step
        with its supervisor (as :class:`~hystid.identify.online.OnlineIdentifier`) or the
        bare recursion; a ``-DHYSTID_RPEM_SUPERVISE=0`` (or ``1``) when compiling overrides it.
    notes : list of str, optional
        Receives what the export leaves out and why (a model whose compensator cannot be
        built is exported without it, ``HYSTID_NO_FF`` defined; a multi-Duhem model without
        the on-line identifier, ``HYSTID_NO_RPEM`` defined).

    Returns
    -------
    dict of str to str
        File name to content, for the names in :data:`C_FILES`.

    Raises
    ------
    ValueError
        For a model kind the export has no C for (it names the kind), when the compensator
        cannot be built with the ``compensator`` options given, or a number is not finite.
    """
    from .. import __version__
    from ..mduhem import MultiDuhemSandwich
    from ..pi import PISandwich

    if not isinstance(model, DuhemSandwich | PISandwich | MultiDuhemSandwich):
        raise ValueError(f"model: a {type(model).__name__} cannot be exported to C (the export "
                         "has the Duhem, the Prandtl-Ishlinskii and the multi-Duhem "
                         "sandwiches)")
    duhem = isinstance(model, DuhemSandwich)
    plain = duhem and model.structure.is_plain
    mhead, msrc = _model_part(model)
    try:
        fhead, fsrc = _ff_part(ff_plan(model, **dict(compensator or {})), model)
        if isinstance(model, PISandwich) and not len(model.poly) and not model.is_invertible():
            approx = ("the model's PI operator has no exact inverse (a partial sum of its "
                      "weights is not positive): the compensator inverts the nearest operator "
                      "whose partial sums are (hystid.compensate.linear_parts."
                      "invertible_weights); hystid compensate gives the model's output from "
                      "its command")
            fhead = f"\n/* Approximate feed-forward: {approx}. */\n" + fhead
            if notes is not None:
                notes.append(f"approximate feed-forward compensator: {approx}")
    except ValueError as err:
        if compensator:  # options asked for explicitly: their error is the answer
            raise
        reason = str(err).replace("*/", "* /")
        fhead = (f"\n/* No feed-forward compensator: {reason}. */\n"
                 "#define HYSTID_NO_FF 1\n")
        fsrc = ""
        if notes is not None:
            notes.append(f"no feed-forward compensator in the export: {reason}")
    rhead = rsrc = ""
    if duhem:
        rhead, rsrc = _rpem_part(rpem_start(model, rpem_record, rpem_sigma), rpem_supervise)
    elif isinstance(model, MultiDuhemSandwich):
        reason = "the multi-Duhem sandwich has no on-line identifier (it is identified in " \
                 "batch only)"
        rhead = f"\n/* No on-line identifier: {reason}. */\n#define HYSTID_NO_RPEM 1\n"
        if notes is not None:
            notes.append(f"no on-line identifier in the export: {reason}")
    else:
        rhead = "\n#define HYSTID_NO_RPEM 1 /* Duhem models only */\n"
    kind = ("Duhem" if plain else "generalised Duhem" if duhem else
            "Prandtl-Ishlinskii" if isinstance(model, PISandwich) else "multi-Duhem")
    units = f"u in {model.units.get('u', '?')}, y in {model.units.get('y', '?')}"
    banner = (f"/* Generated by hystid {__version__} (hystid export --c) from "
              f"{source or 'a model'}:\n   the {kind} sandwich {model.name!r} at "
              f"{model.fs:g} Hz, {units}. C99, no allocation, only math.h.\n"
              "   Python's numbers to the last bit need no -ffast-math and no fused multiply-adds "
              "(-ffp-contract=off:\n   GCC's default with -std=c99; clang contracts by "
              "default). */\n")
    header = (banner + "#ifndef HYSTID_MODEL_H\n#define HYSTID_MODEL_H\n\n" + mhead + fhead
              + rhead
              + "\n#endif /* HYSTID_MODEL_H */\n")
    # an unused static function is an error: sgn for the Duhem parts and the members'
    # inverses, min and max for the PI parts and the Duhem reversal planner, min for the
    # members' inverses and max for the multi-Duhem one (the multi-Duhem step needs none)
    cut, cut2 = (MODEL_COMMON.index(f"static double hx_{f}") for f in ("max", "min"))
    pi = isinstance(model, PISandwich)
    planner = "static double hx_plan_memo" in fsrc
    member = "static int hx_affine_step" in fsrc
    helpers = (MODEL_COMMON[:cut] if duhem or member else "") \
        + (MODEL_COMMON[cut:cut2] if pi or planner or "hx_md_inverse_step" in fsrc else "") \
        + (MODEL_COMMON[cut2:] if pi or planner or member else "")
    source_text = (banner + '#include <math.h>\n\n#include "hystid_model.h"\n' + helpers
                   + "\n/* ---- the placed model */\n" + msrc
                   + ("\n/* ---- the feed-forward compensator */\n" + fsrc if fsrc else "")
                   + ("\n/* ---- the on-line identifier */\n" + rsrc if rsrc else ""))
    return {"hystid_model.h": header, "hystid_model.c": source_text}


def export_c(
    model: DuhemSandwich | PISandwich | MultiDuhemSandwich,
    folder: str | os.PathLike[str],
    *,
    force: bool = False,
    source: str = "",
    compensator: Mapping[str, Any] | None = None,
    rpem_sigma: float | None = None,
    rpem_record: Record | None = None,
    rpem_supervise: bool = True,
    notes: list[str] | None = None,
) -> list[Path]:
    """Write ``hystid_model.h`` and ``hystid_model.c`` into a folder.

    Parameters
    ----------
    model : DuhemSandwich, PISandwich or MultiDuhemSandwich
        The model.
    folder : str or os.PathLike
        The folder (created with its parents when missing).
    force : bool
        Replace the two files when they exist.
    source : str
        Where the model came from, for the header's comment.
    compensator : mapping, optional
        Options of :func:`hystid.compensate.compensate` (see :func:`ff_options`).
    rpem_sigma : float, optional
        Initial residual scale of the on-line identifier (see :func:`rpem_start`).
    rpem_record : Record, optional
        A record of the stage for the on-line identifier's starting information.
    rpem_supervise : bool
        The on-line identifier's step with its supervisor by default (see
        :func:`c_sources`).
    notes : list of str, optional
        Receives what the export leaves out and why (see :func:`c_sources`).

    Returns
    -------
    list of pathlib.Path
        The written files.

    Raises
    ------
    hystid.safeio.OutputError
        When a file exists (without ``force``), is a link or a folder, or the folder cannot be
        written; nothing is written then.
    ValueError
        See :func:`c_sources`.
    """
    from ..safeio import check_output_dir, write_text

    out = check_output_dir(folder, C_FILES, option="--c", force=force)
    texts = c_sources(model, source=source, compensator=compensator, rpem_sigma=rpem_sigma,
                      rpem_record=rpem_record, rpem_supervise=rpem_supervise, notes=notes)
    out.mkdir(parents=True, exist_ok=True)
    paths = []
    for name in C_FILES:
        write_text(out / name, texts[name])
        paths.append(out / name)
    return paths
