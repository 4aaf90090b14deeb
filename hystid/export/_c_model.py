"""C99 text of the placed model's step: the Duhem sandwich (eqs. 1, 7, 2) and the PI sandwich
(eqs. 29-31), written to do the arithmetic of :mod:`hystid.kernels` and
:func:`hystid.pi.pi_simulate_into` in the same order (so the results agree to the last bits).

The code reads constants the generator (:mod:`hystid.export.c`) defines before it: ``HX_*``
macros for the sizes and ``hx_*`` arrays for the coefficients.
"""

from __future__ import annotations

__all__ = ["DUHEM_STEP", "MODEL_COMMON", "PI_STEP"]

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

#: The Duhem sandwich, windows of ``HX_HIST + 1`` samples (the newest at ``HX_HIST``).
DUHEM_STEP = r"""
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
    int i, j;
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
    /* eq. (7) */
    w1p = W1[k - 1];
    w2p = W2[k - 1];
    dw1 = w1 - w1p;
    W2[k] = w2p + HX_ALPHA * (HX_F0 * hx_sgn(w1p) + HX_F1 * w1p - w2p) * fabs(dw1)
            + HX_G0 * dw1;
    /* eq. (2), b20 = 1 */
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

#: The PI sandwich (eqs. 29-31), play-operator states ``p``.
PI_STEP = r"""
void hystid_model_init(hystid_model_state *s)
{
    int i;
    for (i = 0; i <= HX_HIST; i++) {
        s->u[i] = 0.0;
        s->w1[i] = 0.0;
        s->w2[i] = 0.0;
        s->y[i] = 0.0;
    }
    for (i = 0; i < HX_NPI; i++) {
        s->p[i] = 0.0;
    }
}

double hystid_model_step(hystid_model_state *s, double u)
{
    double *U = s->u, *W1 = s->w1, *W2 = s->w2, *Y = s->y, *p = s->p;
    double w1, w2, y, v;
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
    W2[k] = w2;
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
