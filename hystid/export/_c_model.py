"""C99 text of the placed model's step: the Duhem sandwich (eqs. 1, 7, 2; the paper's block and
the generalised one), the PI sandwich (eqs. 29-31) and the multi-Duhem sandwich, written to do
the arithmetic of :mod:`hystid.kernels`, :func:`hystid.pi.pi_simulate_into` and
:mod:`hystid.mduhem_kernels` in the same order (so the results agree to the last bits).

The code reads constants the generator (:mod:`hystid.export.c`) defines before it: ``HX_*``
macros for the sizes and ``hx_*`` arrays for the coefficients.
"""

from __future__ import annotations

__all__ = ["DUHEM_STEP", "GDUHEM_STEP", "MDUHEM_STEP", "MODEL_COMMON", "PI_STEP",
           "SHAPE_TERMS"]

#: Helpers shared by the three parts (sign as eq. 6, minimum and maximum).
MODEL_COMMON = r"""
static double hx_sgn(double x)
{
    /* eq. (6): sgn(0) = 0 */
    if (x > 0.0) {
        return 1.0;
    }
    if (x < 0.0) {
        return -1.0;
    }
    return 0.0;
}

static double hx_max(double a, double b)
{
    return a >= b ? a : b;
}

static double hx_min(double a, double b)
{
    return a <= b ? a : b;
}
"""

#: The Duhem sandwich's step up to eq. (7): windows of ``HX_HIST + 1`` samples (the newest at
#: ``HX_HIST``), ``DECLARE`` standing for the generalised block's locals.
_DUHEM_HEAD = r"""
void hystid_model_init(hystid_model_state *s)
{
    int i;
    for (i = 0; i <= HX_HIST; i++) {
        s->u[i] = 0.0;
        s->w1[i] = 0.0;
        s->w2[i] = HX_W2_REST;
        s->y[i] = HX_Y_REST;
    }
}

double hystid_model_step(hystid_model_state *s, double u)
{
    double *U = s->u, *W1 = s->w1, *W2 = s->w2, *Y = s->y;
    double w1, w1p, w2p, dw1, y;
DECLARE    int i, j;
    const int k = HX_HIST;
    for (i = 0; i < HX_HIST; i++) {
        U[i] = U[i + 1];
        W1[i] = W1[i + 1];
        W2[i] = W2[i + 1];
        Y[i] = Y[i + 1];
    }
    U[k] = u - HYSTID_U_REST;
    /* eq. (1), b10 = 1 */
    w1 = U[k - HX_Q1];
    for (j = 1; j <= HX_N1B; j++) {
        w1 += hx_b1[j - 1] * U[k - HX_Q1 - j];
    }
    for (i = 1; i <= HX_N1A; i++) {
        w1 -= hx_a1[i - 1] * W1[k - i];
    }
    W1[k] = w1;
"""

#: The paper's eq. (7) (:func:`hystid.kernels.duhem_w2`).
_PLAIN_W2 = r"""    /* eq. (7) */
    w1p = W1[k - 1];
    w2p = W2[k - 1];
    dw1 = w1 - w1p;
    W2[k] = w2p + HX_ALPHA * (HX_F0 * hx_sgn(w1p) + HX_F1 * w1p - w2p) * fabs(dw1)
            + HX_G0 * dw1;
"""

#: Eq. (2), the output.
_DUHEM_TAIL = r"""    /* eq. (2), b20 = 1 */
    y = W2[k - HX_Q2];
    for (j = 1; j <= HX_N2B; j++) {
        y += hx_b2[j - 1] * W2[k - HX_Q2 - j];
    }
    for (i = 1; i <= HX_N2A; i++) {
        y -= hx_a2[i - 1] * Y[k - i];
    }
    Y[k] = y;
    return y + HYSTID_OFFSET;
}
"""

#: The Duhem sandwich with the paper's eq. (7), windows of ``HX_HIST + 1`` samples (the newest
#: at ``HX_HIST``).
DUHEM_STEP = _DUHEM_HEAD.replace("DECLARE", "") + _PLAIN_W2 + _DUHEM_TAIL

#: The PI sandwich (eqs. 29-31), play-operator states ``p``.
PI_STEP = r"""
void hystid_model_init(hystid_model_state *s)
{
    int i;
    for (i = 0; i <= HX_HIST; i++) {
        s->u[i] = 0.0;
        s->w1[i] = 0.0;
        s->w2[i] = HX_W2_REST;
        s->y[i] = HX_Y_REST;
    }
    for (i = 0; i < HX_NPI; i++) {
        s->p[i] = hx_p_rest[i];
    }
}

double hystid_model_step(hystid_model_state *s, double u)
{
    double *U = s->u, *W1 = s->w1, *W2 = s->w2, *Y = s->y, *p = s->p;
    double w1, w2, y, v, pw;
    int i, j;
    const int k = HX_HIST;
    for (i = 0; i < HX_HIST; i++) {
        U[i] = U[i + 1];
        W1[i] = W1[i + 1];
        W2[i] = W2[i + 1];
        Y[i] = Y[i + 1];
    }
    U[k] = u - HYSTID_U_REST;
    /* eq. (29) */
    w1 = 0.0;
    for (j = 0; j < HX_N1B; j++) {
        w1 += hx_b1[j] * U[k - HX_Q1 - j];
    }
    for (i = 0; i < HX_N1A; i++) {
        w1 -= hx_a1[i] * W1[k - 1 - i];
    }
    W1[k] = w1;
    /* eq. (30): p_i(k) = max{w1 - r_i, min[w1 + r_i, p_i(k-1)]} */
    w2 = 0.0;
    for (i = 0; i < HX_NPI; i++) {
        v = hx_max(w1 - hx_r[i], hx_min(w1 + hx_r[i], p[i]));
        p[i] = v;
        w2 += hx_mu[i] * v;
    }
    /* the polynomial terms beside the plays, c_j w1^j (hystid.pi_operator.poly_terms) */
    v = 0.0;
    pw = w1;
    for (j = 0; j < HX_NPOLY; j++) {
        pw *= w1;
        v += hx_c[j] * pw;
    }
    W2[k] = w2 + v;
    /* eq. (31) */
    y = 0.0;
    for (j = 0; j < HX_N2B; j++) {
        y += hx_b2[j] * W2[k - HX_Q2 - j];
    }
    for (i = 0; i < HX_N2A; i++) {
        y -= hx_a2[i] * Y[k - 1 - i];
    }
    Y[k] = y;
    return y + HYSTID_OFFSET;
}
"""

#: The generalised eq. (7)'s coefficients (:func:`hystid.kernels.shape_terms`), for the model's
#: step and the on-line identifier's: ``th`` is ``theta`` in the order of
#: :attr:`hystid.model.Structure.names`, its groups at the ``HX_I_*`` indices.
SHAPE_TERMS = r"""
/* hystid.kernels.shape_terms: at w1(k-1) = v and the direction sd = sgn(dw1(k)),
     A  = alpha (1 + ad sd)                 the rate
     F  = f1 v + f2 v^2 + f3 v^3           the anhysteretic curve (its f0 sgn(v) apart)
     G  = g0 + g1 v + g2 v^2 + gd sd       the reversible slope
   and dF = dF/dv, dG = dG/dv (the terms the structure has not are left out). */
static void hx_shape_terms(const double *th, double v, double sd, double *A, double *F,
                           double *G, double *dF, double *dG)
{
    double pw;
    int j;
    *A = th[HX_I_ALPHA];
    *F = th[HX_I_F1] * v;
    *dF = th[HX_I_F1];
    *G = th[HX_I_G0];
    *dG = 0.0;
    pw = v;
    for (j = 0; j < HX_NF; j++) { /* f2 v^2, f3 v^3 */
        *dF += (j + 2) * th[HX_I_F2 + j] * pw;
        pw *= v;
        *F += th[HX_I_F2 + j] * pw;
    }
    pw = 1.0;
    for (j = 0; j < HX_NG; j++) { /* g1 v, g2 v^2 */
        *dG += (j + 1) * th[HX_I_G1 + j] * pw;
        pw *= v;
        *G += th[HX_I_G1 + j] * pw;
    }
#if HX_DIRECTIONAL
    *A = *A * (1.0 + th[HX_I_AD] * sd);
    *G += th[HX_I_AD + 1] * sd;
#else
    (void)sd;
#endif
}
"""

#: The generalised eq. (7) (:func:`hystid.kernels.step`'s other branch):
#: ``w2(k) = w2(k-1) + A [f0 sgn(v) + F - w2(k-1)] |dw1| + G dw1``.
_SHAPE_W2 = r"""    /* eq. (7), generalised */
    w1p = W1[k - 1];
    w2p = W2[k - 1];
    dw1 = w1 - w1p;
    hx_shape_terms(hx_theta, w1p, hx_sgn(dw1), &A, &F, &G, &dF, &dG);
    W2[k] = w2p + A * (HX_F0 * hx_sgn(w1p) + F - w2p) * fabs(dw1) + G * dw1;
"""

#: The Duhem sandwich with the generalised block (``f_order``, ``g_order``, ``directional``);
#: needs :data:`SHAPE_TERMS` before it and ``hx_theta``, the model's ``theta``.
GDUHEM_STEP = (_DUHEM_HEAD.replace("DECLARE", "    double A, F, G, dF, dG;\n") + _SHAPE_W2
               + _DUHEM_TAIL)

#: The multi-Duhem sandwich (:mod:`hystid.mduhem_kernels`): L1 and L2 of unit DC gain around
#: ``HX_NOP`` Duhem operators of eq. (7) in parallel, their states ``p``.
MDUHEM_STEP = r"""
void hystid_model_init(hystid_model_state *s)
{
    int i;
    for (i = 0; i <= HX_HIST; i++) {
        s->u[i] = 0.0;
        s->w1[i] = 0.0;
        s->w2[i] = 0.0;
        s->y[i] = 0.0;
    }
    for (i = 0; i < HX_NOP; i++) {
        s->p[i] = 0.0;
    }
}

double hystid_model_step(hystid_model_state *s, double u)
{
    double *U = s->u, *W1 = s->w1, *W2 = s->w2, *Y = s->y, *p = s->p;
    double w1, v, d, ad, w2, y;
    int i, j;
    const int k = HX_HIST;
    for (i = 0; i < HX_HIST; i++) {
        U[i] = U[i + 1];
        W1[i] = W1[i + 1];
        W2[i] = W2[i + 1];
        Y[i] = Y[i + 1];
    }
    U[k] = u - HYSTID_U_REST;
    /* L1: w1(k) = sum_j b1j u(k-q1-j+1) - sum_i a1i w1(k-i) */
    w1 = 0.0;
    for (j = 0; j < HX_N1B; j++) {
        w1 += hx_b1[j] * U[k - HX_Q1 - j];
    }
    for (i = 0; i < HX_N1A; i++) {
        w1 -= hx_a1[i] * W1[k - 1 - i];
    }
    W1[k] = w1;
    /* eq. (7) for each operator: w2_j(k) = w2_j(k-1) + alpha_j [f1_j v - w2_j(k-1)] |d|
       + g0_j d, with v = w1(k-1) and d = w1(k) - v; w2(k) = sum_j w2_j(k) */
    v = W1[k - 1];
    d = w1 - v;
    ad = fabs(d);
    w2 = 0.0;
    for (j = 0; j < HX_NOP; j++) {
        p[j] = p[j] + hx_alpha[j] * (hx_f1[j] * v - p[j]) * ad + hx_g0[j] * d;
        w2 += p[j];
    }
    W2[k] = w2;
    /* L2: y(k) = sum_j b2j w2(k-q2-j+1) - sum_i a2i y(k-i) */
    y = 0.0;
    for (j = 0; j < HX_N2B; j++) {
        y += hx_b2[j] * W2[k - HX_Q2 - j];
    }
    for (i = 0; i < HX_N2A; i++) {
        y -= hx_a2[i] * Y[k - 1 - i];
    }
    Y[k] = y;
    return y + HYSTID_OFFSET;
}
"""
