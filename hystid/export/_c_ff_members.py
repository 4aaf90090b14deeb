"""C99 text of the members' per-sample inverses in the feed-forward compensator: the
``gduhem`` and ``mduhem`` steps of :mod:`hystid.compensate.member_inverse`, written to do the
same arithmetic in the same order, and :func:`ff_chain`, which puts them into the chain of
:mod:`hystid.export._c_ff`.
"""

from __future__ import annotations

from ._c_ff import FF_CHAIN

__all__ = ["FF_GDUHEM", "FF_MDUHEM", "FF_MEMBER", "FF_PI_POLY", "ff_chain"]

#: What the members' inverses share (:func:`hystid.compensate.member_inverse.affine_step` and
#: ``_towards``): the inverse step of a block whose step is ``Delta = S_s d`` on each direction.
FF_MEMBER = r"""
#define HX_ROUND_OFF 1e-13
#define HX_EXACT 0
#define HX_BOUND 1
#define HX_UNREACHABLE 2

/* affine_step of hystid.compensate.member_inverse: the number of exact solutions (0, 1, 2);
   *d the near one (clipped to the bound on the direction that comes closest when beyond it),
   *status HX_EXACT, HX_BOUND or (none) HX_UNREACHABLE */
static int hx_affine_step(double delta, double s_pos, double s_neg, double r_pos, double r_neg,
                          double bound, double *d, int *status)
{
    double d_pos = 0.0, d_neg = 0.0, near, rate, slope, other, o_rate, o_slope, miss, d2;
    int ok_pos = 0, ok_neg = 0, n;
    if (s_pos != 0.0) {
        d_pos = delta / s_pos;
        ok_pos = d_pos > 0.0;
    }
    if (s_neg != 0.0) {
        d_neg = delta / s_neg;
        ok_neg = d_neg < 0.0;
    }
    n = ok_pos + ok_neg;
    if (n == 0) {
        *d = 0.0;
        *status = HX_UNREACHABLE;
        return 0;
    }
    if (ok_pos && (!ok_neg || d_pos <= -d_neg)) {
        near = d_pos;
        rate = r_pos;
        slope = s_pos;
        other = d_neg;
        o_rate = r_neg;
        o_slope = s_neg;
    } else {
        near = d_neg;
        rate = r_neg;
        slope = s_neg;
        other = d_pos;
        o_rate = r_pos;
        o_slope = s_pos;
    }
    if (rate * fabs(near) <= bound) {
        *d = near;
        *status = HX_EXACT;
        return n;
    }
    /* beyond the bound: the clipped step that comes closest to the wanted w2 */
    *d = hx_sgn(near) * bound / rate;
    miss = fabs(delta - slope * *d);
    if (n == 2) {
        d2 = hx_sgn(other) * hx_min(fabs(other), bound / o_rate);
        if (fabs(delta - o_slope * d2) < miss) {
            if (o_rate * fabs(other) <= bound) {
                *d = other;
                *status = HX_EXACT;
                return n;
            }
            *d = d2;
        }
    }
    *status = HX_BOUND;
    return n;
}

/* _towards: the increment on direction that brings a rate term q (changing by rate_q per unit
   of d) to zero, at most dmax long; the whole dmax when it cannot */
static double hx_towards(double direction, double q, double rate_q, double dmax)
{
    double d;
    if (rate_q != 0.0) {
        d = -q / rate_q;
        if (d * direction > 0.0) {
            return direction * hx_min(fabs(d), dmax);
        }
    }
    return direction * dmax;
}
"""

#: The generalised Duhem block's inverse and forward step
#: (:func:`~hystid.compensate.member_inverse.gduhem_inverse_step`, ``gduhem_forward``): needs
#: the model part's ``hx_shape_terms`` and the chain's ``theta`` as ``hx_ff_theta``.
FF_GDUHEM = r"""
/* gduhem_inverse_step: the increment of w1 that brings w2(k-1) = w2p to w2d */
static double hx_gd_inverse_step(double w2d, double w1p, double w2p, double bound, int *status)
{
    double delta = w2d - w2p;
    double a_pos, F, g_pos, dF, dG, a_neg, F_neg, g_neg, dF_neg, dG_neg, E, s_pos, s_neg, d;
    if (fabs(delta) <= HX_ROUND_OFF * (1.0 + fabs(w2d))) {
        *status = HX_EXACT;
        return 0.0;
    }
    /* gduhem_slopes */
    hx_shape_terms(hx_ff_theta, w1p, 1.0, &a_pos, &F, &g_pos, &dF, &dG);
    hx_shape_terms(hx_ff_theta, w1p, -1.0, &a_neg, &F_neg, &g_neg, &dF_neg, &dG_neg);
    E = HX_FF_GD_F0 * hx_sgn(w1p) + F - w2p;
    s_pos = g_pos + a_pos * E;
    s_neg = g_neg - a_neg * E;
    if (hx_affine_step(delta, s_pos, s_neg, a_pos, a_neg, bound, &d, status) > 0) {
        return d;
    }
    /* unreachable: move w1 the way w2 is asked to go, until E = 0 (dE/dd = F' - S_s) */
    if (delta > 0.0) {
        return hx_towards(1.0, E, dF - s_pos, bound / a_pos);
    }
    return hx_towards(-1.0, E, dF - s_neg, bound / a_neg);
}

/* gduhem_forward: w2(k) of the generalised eq. (7) (as the model's step writes it) */
static double hx_gd_forward(double w1, double w1p, double w2p)
{
    double A, F, G, dF, dG;
    double dw1 = w1 - w1p;
    hx_shape_terms(hx_ff_theta, w1p, hx_sgn(dw1), &A, &F, &G, &dF, &dG);
    return w2p + A * (HX_FF_GD_F0 * hx_sgn(w1p) + F - w2p) * fabs(dw1) + G * dw1;
}
"""

#: The parallel Duhem operators' inverse and forward step
#: (:func:`~hystid.compensate.member_inverse.mduhem_inverse_step`, ``mduhem_forward``): the
#: chain's ``HX_FF_NPI`` rates, ``f1_j`` and ``g0_j`` as ``hx_ff_md_rates``, ``hx_ff_md_f1``,
#: ``hx_ff_md_g0``.
FF_MDUHEM = r"""
/* mduhem_inverse_step: the increment of w1 that brings sum_j p[j] to w2d */
static double hx_md_inverse_step(double w2d, double w1p, const double *p, double bound,
                                 int *status)
{
    double w2p = 0.0, rmax = 0.0, delta, g = 0.0, q = 0.0, c = 0.0, c2 = 0.0, e, d;
    int j;
    for (j = 0; j < HX_FF_NPI; j++) {
        w2p += p[j];
        rmax = hx_max(rmax, hx_ff_md_rates[j]);
    }
    delta = w2d - w2p;
    if (fabs(delta) <= HX_ROUND_OFF * (1.0 + fabs(w2d))) {
        *status = HX_EXACT;
        return 0.0;
    }
    /* mduhem_slopes: S_s = sum_j g0_j + s Q, Q = sum_j alpha_j E_j and how Q changes */
    for (j = 0; j < HX_FF_NPI; j++) {
        e = hx_ff_md_f1[j] * w1p - p[j];
        g += hx_ff_md_g0[j];
        q += hx_ff_md_rates[j] * e;
        c += hx_ff_md_rates[j] * (hx_ff_md_f1[j] - hx_ff_md_g0[j]);
        c2 += hx_ff_md_rates[j] * hx_ff_md_rates[j] * e;
    }
    if (hx_affine_step(delta, g + q, g - q, rmax, rmax, bound, &d, status) > 0) {
        return d;
    }
    if (delta > 0.0) {
        return hx_towards(1.0, q, c - c2, bound / rmax);
    }
    return hx_towards(-1.0, q, c + c2, bound / rmax);
}

/* mduhem_forward: the operators' states moved on to w1 (in place) */
static void hx_md_forward(double *p, double w1, double w1p)
{
    double d = w1 - w1p;
    double ad = fabs(d);
    int j;
    for (j = 0; j < HX_FF_NPI; j++) {
        p[j] = p[j] + hx_ff_md_rates[j] * (hx_ff_md_f1[j] * w1p - p[j]) * ad
               + hx_ff_md_g0[j] * d;
    }
}
"""

# where ff_chain puts the members' branches into FF_CHAIN (before these lines)
_AT_INIT = "#endif\n    for (i = 0; i < HYSTID_FF_M_NX; i++) {\n"
_AT_INVERSE = "#else\n    w1c = win[0] / HX_FF_KH;\n#endif\n"
_AT_FORWARD = "#endif\n    for (i = 0; i < HX_FF_H1 - 1; i++) {\n"

_MEMBER_BRANCHES = {
    4: (
        "#elif HX_FF_KIND == 4\n"
        "    s->x[HX_FF_OFF_H] = HX_FF_REST; /* the generalised block's state at rest */\n",
        "#elif HX_FF_KIND == 4\n"
        "    {\n"
        "        double d = hx_gd_inverse_step(win[0], w1p, x[HX_FF_OFF_H], HX_FF_BOUND,\n"
        "                                      &status);\n"
        "        w1c = w1p + d;\n"
        "    }\n",
        "#elif HX_FF_KIND == 4\n"
        "    x[HX_FF_OFF_H] = hx_gd_forward(w1, w1p, x[HX_FF_OFF_H]);\n",
    ),
    5: (
        "",
        "#elif HX_FF_KIND == 5\n"
        "    {\n"
        "        double d = hx_md_inverse_step(win[0], w1p, &x[HX_FF_OFF_H], HX_FF_BOUND,\n"
        "                                      &status);\n"
        "        w1c = w1p + d;\n"
        "    }\n",
        "#elif HX_FF_KIND == 5\n"
        "    hx_md_forward(&x[HX_FF_OFF_H], w1, w1p);\n",
    ),
}


#: :func:`hystid.compensate.member_inverse.pi_poly_inverse`: the wanted ``w2`` bracketed from
#: ``w1(k-1)`` and bisected, the same arithmetic in the same order (``hx_ff_poly`` holds the
#: polynomial terms' coefficients, ``HX_FF_NPOLY`` of them).
FF_PI_POLY = r"""
#define HX_ROUND_OFF 1e-13
#define HX_BRACKET_DOUBLINGS 80

/* the plays moved to w (their states p at k-1, not changed) and the polynomial terms, less
   the wanted w2 */
static double hx_pi_poly_gap(double w, double w2d, const double *p)
{
    double acc = 0.0, value = 0.0, power = w;
    int i, j;
    for (i = 0; i < HX_FF_NPI; i++) {
        acc += hx_ff_mu_pi[i] * hx_max(w - hx_ff_r_pi[i], hx_min(w + hx_ff_r_pi[i], p[i]));
    }
    for (j = 0; j < HX_FF_NPOLY; j++) {
        power *= w;
        value += hx_ff_poly[j] * power;
    }
    return acc + value - w2d;
}

/* w1(k); *status 2 (no exact step) when no bracket is found */
static double hx_pi_poly_inverse(double w2d, double w1p, const double *p, int *status)
{
    double g0 = hx_pi_poly_gap(w1p, w2d, p), way, slope, width, nearw, farw, lo, hi, mid;
    double power = w1p;
    int i, j, found = 0;
    if (fabs(g0) <= HX_ROUND_OFF * (1.0 + fabs(w2d))) {
        return w1p;
    }
    way = g0 > 0.0 ? -1.0 : 1.0;
    slope = 0.0;
    for (j = 0; j < HX_FF_NPOLY; j++) {
        slope += (j + 2) * hx_ff_poly[j] * power;
        power *= w1p;
    }
    slope = fabs(slope);
    for (i = 0; i < HX_FF_NPI; i++) {
        slope += fabs(hx_ff_mu_pi[i]);
    }
    width = slope > 0.0 ? fabs(g0) / slope : 1.0;
    nearw = w1p;
    farw = w1p + way * width;
    for (i = 0; i < HX_BRACKET_DOUBLINGS; i++) {
        if (hx_pi_poly_gap(farw, w2d, p) * way >= 0.0) {
            found = 1;
            break;
        }
        nearw = farw;
        width *= 2.0;
        farw = w1p + way * width;
    }
    if (!found) {
        *status = 2;
        return farw;
    }
    lo = nearw < farw ? nearw : farw;
    hi = nearw < farw ? farw : nearw;
    for (i = 0; i < 200; i++) {
        mid = 0.5 * (lo + hi);
        if (mid <= lo || mid >= hi) {
            break;
        }
        if (hx_pi_poly_gap(mid, w2d, p) < 0.0) {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    return 0.5 * (lo + hi);
}
"""


def ff_chain(kind: int) -> str:
    """The compensator's C text for a chain of ``kind`` (``compensator.KIND_*``).

    :data:`FF_CHAIN` itself for the plain Duhem, PI and central-line chains; for the
    generalised Duhem block (4) and the parallel Duhem operators (5) the same text with their
    branches added (the state at rest, the inverse step, the internal model's step), which
    call the functions of :data:`FF_GDUHEM` or :data:`FF_MDUHEM`.

    Parameters
    ----------
    kind : int
        The chain's kind, ``ispec[_KIND]`` of :mod:`hystid.compensate.compensator`.

    Returns
    -------
    str
        C99 text.
    """
    if kind not in _MEMBER_BRANCHES:
        return FF_CHAIN
    text = FF_CHAIN
    for anchor, branch in zip((_AT_INIT, _AT_INVERSE, _AT_FORWARD), _MEMBER_BRANCHES[kind],
                              strict=True):
        if text.count(anchor) != 1:  # pragma: no cover - the chain's text was changed
            raise RuntimeError(f"ff_chain: FF_CHAIN has {text.count(anchor)} places for "
                               f"{anchor!r}, expected one")
        text = text.replace(anchor, branch + anchor)
    return text
