"""C99 text of the feed-forward compensator: the chain of
:mod:`hystid.compensate.compensator` (``_push_reference``, ``chain_step``) and the Duhem
reversal planner of :mod:`hystid.compensate.duhem_inverse` (``plan_step`` and its helpers),
written to do the same arithmetic in the same order.

The chain state is the flat vector of the Python compensator (``[x_M | y_M line | w2d line |
past u | past w1 | hysteresis state]``) at the offsets the generator defines (``HX_FF_*``
macros, ``hx_ff_*`` arrays, from the ``ispec``/``fpar`` arrays of the Python chain).
"""

from __future__ import annotations

__all__ = ["FF_CHAIN", "FF_PLANNER"]

#: The Duhem inverse and its preview planner (only compiled for a Duhem compensator).
FF_PLANNER = r"""
#define HX_ROUND_OFF 1e-13
#define HX_BIG 1e30
#define HX_K 32
#define HX_MARGIN 1e-11
#define HX_EXACT 0
#define HX_BOUND 1
#define HX_UNREACHABLE 2

static double hx_gap(double w1p, double w2p, double f0, double f1)
{
    return f0 * hx_sgn(w1p) + f1 * w1p - w2p;
}

static double hx_forward(double w1, double w1p, double w2p, double alpha, double f0,
                         double f1, double g0)
{
    double d = w1 - w1p;
    return w2p + alpha * hx_gap(w1p, w2p, f0, f1) * fabs(d) + g0 * d;
}

static int hx_solutions(double w2d, double w1p, double w2p, double alpha, double f0, double f1,
                        double g0, double *near, double *far)
{
    double G = hx_gap(w1p, w2p, f0, f1);
    double delta = w2d - w2p;
    double s_pos, s_neg, d;
    int n = 0;
    *near = 0.0;
    *far = 0.0;
    if (fabs(delta) <= HX_ROUND_OFF * (1.0 + fabs(w2d))) {
        return 1;
    }
    s_pos = g0 + alpha * G;
    s_neg = g0 - alpha * G;
    if (s_pos != 0.0) {
        d = delta / s_pos;
        if (d > 0.0) {
            *near = d;
            n = 1;
        }
    }
    if (s_neg != 0.0) {
        d = delta / s_neg;
        if (d < 0.0) {
            if (n == 0) {
                *near = d;
                n = 1;
            } else {
                n = 2;
                if (fabs(d) < fabs(*near)) {
                    *far = *near;
                    *near = d;
                } else {
                    *far = d;
                }
            }
        }
    }
    return n;
}

static double hx_towards_band(double w2d, double w1p, double w2p, double alpha, double f0,
                              double f1, double g0, double bound)
{
    double G = hx_gap(w1p, w2p, f0, f1);
    double direction = hx_sgn(w2d - w2p);
    double rate = f1 - g0 + alpha * fabs(G);
    double dmax = bound / alpha;
    if (rate > 0.0 && G != 0.0) {
        return direction * hx_min(fabs(G) / rate, dmax);
    }
    return direction * dmax;
}

static double hx_inverse_step(double w2d, double w1p, double w2p, double alpha, double f0,
                              double f1, double g0, double bound, int *status)
{
    double near, far;
    int n = hx_solutions(w2d, w1p, w2p, alpha, f0, f1, g0, &near, &far);
    if (n == 0) {
        *status = HX_UNREACHABLE;
        return hx_towards_band(w2d, w1p, w2p, alpha, f0, f1, g0, bound);
    }
    if (alpha * fabs(near) > bound) {
        *status = HX_BOUND;
        return hx_sgn(near) * bound / alpha;
    }
    *status = HX_EXACT;
    return near;
}

static double hx_gap_map(double x, double sigma, double delta, double alpha, double f1,
                         double g0)
{
    return sigma * (x - g0) / alpha - delta + f1 * delta / x;
}

static double hx_solve_piece(double c, double xa, double xb, double sigma, double delta,
                             double alpha, double f1, double g0)
{
    double a = sigma;
    double b = -(sigma * g0 + alpha * (delta + c));
    double cc = alpha * f1 * delta;
    double disc = b * b - 4.0 * a * cc;
    double sq, q, r1, r2, best, lo, hi, e1, e2;
    if (disc < 0.0) {
        disc = 0.0;
    }
    sq = sqrt(disc);
    q = b >= 0.0 ? -0.5 * (b + sq) : -0.5 * (b - sq);
    r1 = q / a;
    r2 = q != 0.0 ? cc / q : r1;
    best = r1;
    lo = hx_min(xa, xb);
    hi = hx_max(xa, xb);
    e1 = hx_max(hx_max(lo - r1, r1 - hi), 0.0);
    e2 = hx_max(hx_max(lo - r2, r2 - hi), 0.0);
    if (e2 < e1) {
        best = r2;
    }
    return hx_min(hx_max(best, lo), hi);
}

static int hx_add_interval(double *lo_out, double *hi_out, int n, double lo, double hi)
{
    int i, narrow = 0;
    if (hi < lo) {
        return n;
    }
    if (n < HX_K) {
        lo_out[n] = lo;
        hi_out[n] = hi;
        return n + 1;
    }
    for (i = 1; i < n; i++) {
        if (hi_out[i] - lo_out[i] < hi_out[narrow] - lo_out[narrow]) {
            narrow = i;
        }
    }
    if (hi - lo > hi_out[narrow] - lo_out[narrow]) {
        lo_out[narrow] = lo;
        hi_out[narrow] = hi;
    }
    return n;
}

static int hx_normalise(double *lo, double *hi, int n)
{
    int i, j, m = 0;
    double a, b;
    for (i = 1; i < n; i++) {
        a = lo[i];
        b = hi[i];
        j = i - 1;
        while (j >= 0 && lo[j] > a) {
            lo[j + 1] = lo[j];
            hi[j + 1] = hi[j];
            j -= 1;
        }
        lo[j + 1] = a;
        hi[j + 1] = b;
    }
    for (i = 0; i < n; i++) {
        if (m > 0 && lo[i] <= hi[m - 1] + 1e-15 * (1.0 + fabs(hi[m - 1]))) {
            hi[m - 1] = hx_max(hi[m - 1], hi[i]);
        } else {
            lo[m] = lo[i];
            hi[m] = hi[i];
            m += 1;
        }
    }
    return m;
}

static int hx_preimage(const double *lo, const double *hi, int n, double delta, double alpha,
                       double f1, double g0, double bound, double *lo_out, double *hi_out)
{
    int m = 0, sgm, p, i, npieces;
    double xmin, sigma, tau, xc, xa, xb, ga, gb, glo, ghi, l, h, x1, x2, G1, G2;
    double xs[3];
    if (delta == 0.0) {
        for (i = 0; i < n; i++) {
            lo_out[i] = lo[i];
            hi_out[i] = hi[i];
        }
        return n;
    }
    xmin = alpha * fabs(delta) / bound;
    for (sgm = 0; sgm < 2; sgm++) {
        sigma = sgm == 0 ? 1.0 : -1.0;
        tau = sigma * delta > 0.0 ? 1.0 : -1.0;
        npieces = 1;
        xs[0] = tau * xmin;
        if (tau > 0.0) {
            xc = f1 > 0.0 ? sqrt(alpha * f1 * fabs(delta)) : 0.0;
            if (xc > xmin) {
                xs[1] = xc;
                npieces = 2;
            }
        }
        xs[npieces] = tau * HX_BIG;
        for (p = 0; p < npieces; p++) {
            xa = xs[p];
            xb = xs[p + 1];
            ga = hx_gap_map(xa, sigma, delta, alpha, f1, g0);
            gb = hx_gap_map(xb, sigma, delta, alpha, f1, g0);
            glo = hx_min(ga, gb);
            ghi = hx_max(ga, gb);
            for (i = 0; i < n; i++) {
                l = hx_max(lo[i], glo);
                h = hx_min(hi[i], ghi);
                if (l > h) {
                    continue;
                }
                x1 = hx_solve_piece(l, xa, xb, sigma, delta, alpha, f1, g0);
                x2 = hx_solve_piece(h, xa, xb, sigma, delta, alpha, f1, g0);
                G1 = sigma * (x1 - g0) / alpha;
                G2 = sigma * (x2 - g0) / alpha;
                m = hx_add_interval(lo_out, hi_out, m, hx_min(G1, G2) + HX_MARGIN,
                                    hx_max(G1, G2) - HX_MARGIN);
            }
        }
    }
    return hx_normalise(lo_out, hi_out, m);
}

static int hx_inside(double G, const double *lo, const double *hi, int n)
{
    int i;
    for (i = 0; i < n; i++) {
        if (lo[i] <= G && G <= hi[i]) {
            return 1;
        }
    }
    return 0;
}

static int hx_target(double delta, double alpha, double g0, double bound, double *lo,
                     double *hi)
{
    if (delta < 0.0) {
        lo[0] = -HX_BIG;
        hi[0] = (g0 - alpha * fabs(delta) / bound) / alpha - HX_MARGIN;
    } else if (delta > 0.0) {
        lo[0] = (-g0 + alpha * fabs(delta) / bound) / alpha + HX_MARGIN;
        hi[0] = HX_BIG;
    } else {
        lo[0] = -HX_BIG;
        hi[0] = HX_BIG;
    }
    return hi[0] >= lo[0] ? 1 : 0;
}

static int hx_first_unreachable(const double *W, int n, int i0, double w1p, double w2p,
                                double alpha, double f0, double f1, double g0, double bound,
                                double *gaps)
{
    int i, st;
    double d, w1;
    for (i = i0; i < n; i++) {
        gaps[i] = hx_gap(w1p, w2p, f0, f1);
        d = hx_inverse_step(W[i], w1p, w2p, alpha, f0, f1, g0, bound, &st);
        if (st == HX_UNREACHABLE) {
            return i;
        }
        w1 = w1p + d;
        w2p = hx_forward(w1, w1p, w2p, alpha, f0, f1, g0);
        w1p = w1;
    }
    return -1;
}

/* plan_step of hystid.compensate.duhem_inverse: the increment of w1 for W[0], with W[1..n-1]
   as preview; *status as there, *far set when the far branch is taken. */
static double hx_plan_step(const double *W, int n, double w1p, double w2p, double alpha,
                           double f0, double f1, double g0, double bound, double *gaps,
                           int *status, int *far)
{
    double la[HX_K], ha[HX_K], lb[HX_K], hb[HX_K];
    double *lo = la, *hi = ha, *lo2 = lb, *hi2 = hb, *tmp;
    double d0, w1a, w2a, near, farv, w1f, w2f;
    int st0, j, m, i, n_sol;
    *far = 0;
    d0 = hx_inverse_step(W[0], w1p, w2p, alpha, f0, f1, g0, bound, &st0);
    *status = st0;
    if (st0 == HX_UNREACHABLE || n < 3) {
        return d0;
    }
    w1a = w1p + d0;
    w2a = hx_forward(w1a, w1p, w2p, alpha, f0, f1, g0);
    j = hx_first_unreachable(W, n, 1, w1a, w2a, alpha, f0, f1, g0, bound, gaps);
    if (j < 1) {
        return d0;
    }
    m = hx_target(W[j] - W[j - 1], alpha, g0, bound, lo, hi);
    for (i = j - 1; i > 0; i--) {
        if (m == 0) {
            break;
        }
        if (hx_inside(gaps[i + 1], lo, hi, m)) {
            return d0;
        }
        m = hx_preimage(lo, hi, m, W[i] - W[i - 1], alpha, f1, g0, bound, lo2, hi2);
        tmp = lo;
        lo = lo2;
        lo2 = tmp;
        tmp = hi;
        hi = hi2;
        hi2 = tmp;
    }
    if (m == 0) {
        return d0;
    }
    if (hx_inside(hx_gap(w1a, w2a, f0, f1), lo, hi, m)) {
        return d0;
    }
    n_sol = hx_solutions(W[0], w1p, w2p, alpha, f0, f1, g0, &near, &farv);
    if (n_sol == 2 && alpha * fabs(farv) <= bound) {
        w1f = w1p + farv;
        w2f = hx_forward(w1f, w1p, w2p, alpha, f0, f1, g0);
        if (hx_inside(hx_gap(w1f, w2f, f0, f1), lo, hi, m)) {
            *status = HX_EXACT;
            *far = 1;
            return farv;
        }
    }
    return d0;
}
"""

#: The compensator chain: reference path, hysteresis inverse, L1 inverse, internal model.
FF_CHAIN = r"""
static void hx_ff_push_reference(double *x, double r)
{
    double ym, w2;
    int i;
#if HX_FF_NM > 0
    double xm_new[HX_FF_NM], acc;
    int j;
    ym = HX_FF_DM * r;
    for (i = 0; i < HX_FF_NM; i++) {
        ym += hx_ff_cm[i] * x[HX_FF_OFF_M + i];
    }
    for (i = 0; i < HX_FF_NM; i++) {
        acc = hx_ff_bm[i] * r;
        for (j = 0; j < HX_FF_NM; j++) {
            acc += hx_ff_am[i * HX_FF_NM + j] * x[HX_FF_OFF_M + j];
        }
        xm_new[i] = acc;
    }
    for (i = 0; i < HX_FF_NM; i++) {
        x[HX_FF_OFF_M + i] = xm_new[i];
    }
#else
    ym = r;
#endif
    for (i = 0; i < HX_FF_LY - 1; i++) {
        x[HX_FF_OFF_Y + i] = x[HX_FF_OFF_Y + i + 1];
    }
    x[HX_FF_OFF_Y + HX_FF_LY - 1] = ym;
#if HX_FF_L2MODE == 0
    w2 = ym / HX_FF_K2;
#else
    {
        int j2;
        w2 = ym;
        for (i = 1; i <= HX_FF_N2A; i++) {
            w2 += hx_ff_a2[i - 1] * x[HX_FF_OFF_Y + HX_FF_LY - 1 - i];
        }
        for (j2 = 1; j2 <= HX_FF_N2B; j2++) {
            w2 -= hx_ff_b2t[j2 - 1] * x[HX_FF_OFF_W + HX_FF_LW - j2];
        }
        w2 /= HX_FF_B2LEAD;
    }
#endif
    for (i = 0; i < HX_FF_LW - 1; i++) {
        x[HX_FF_OFF_W + i] = x[HX_FF_OFF_W + i + 1];
    }
    x[HX_FF_OFF_W + HX_FF_LW - 1] = w2;
}

void hystid_ff_init(hystid_ff_state *s)
{
    int i;
    for (i = 0; i < HX_FF_NX; i++) {
        s->x[i] = 0.0;
    }
    s->n = 0;
    s->u = HYSTID_FF_REST_COMMAND;
    s->yd = 0.0;
    s->status = 0;
}

double hystid_ff_step(hystid_ff_state *s, double r)
{
    double *x = s->x;
    double w1p, w1c, u, w1;
    int i, j, status = 0;
#if HX_FF_KIND == 1
    double pinv[HX_FF_NPI], tail, cum;
#endif
    hx_ff_push_reference(x, r - HX_FF_R_SHIFT);
    if (s->n < HYSTID_FF_DELAY) {
        /* priming: the first HYSTID_FF_DELAY references are read in, the stage rests */
        s->n += 1;
        return s->u;
    }
    s->yd = x[HX_FF_OFF_Y + HX_FF_LY - 1 - (HX_FF_Q + HX_FF_P)] + HX_FF_R_SHIFT;
    w1p = x[HX_FF_OFF_W1 + HX_FF_H1 - 1];
    (void)w1p; /* the Duhem block's state only */
#if HX_FF_KIND == 0
    {
        int far = 0;
        double d = hx_plan_step(&x[HX_FF_OFF_W + HX_FF_LW - 1 - HX_FF_P], HX_FF_P + 1, w1p,
                                x[HX_FF_OFF_H], HX_FF_ALPHA, HX_FF_F0, HX_FF_F1, HX_FF_G0,
                                HX_FF_BOUND, s->gaps, &status, &far);
        if (far) {
            status |= 8;
        }
        w1c = w1p + d;
    }
#elif HX_FF_KIND == 1
    {
        double w2d = x[HX_FF_OFF_W + HX_FF_LW - 1 - HX_FF_P];
        tail = 0.0;
        for (i = HX_FF_NPI - 1; i >= 0; i--) {
            pinv[i] = tail;
            tail += hx_ff_mu_pi[i] * x[HX_FF_OFF_H + i];
        }
        cum = 0.0;
        for (i = 0; i < HX_FF_NPI; i++) {
            cum += hx_ff_mu_pi[i];
            pinv[i] += cum * x[HX_FF_OFF_H + i];
        }
        w1c = 0.0;
        for (i = 0; i < HX_FF_NPI; i++) {
            w1c += hx_ff_mu_inv[i] * hx_max(w2d - hx_ff_r_inv[i],
                                            hx_min(w2d + hx_ff_r_inv[i], pinv[i]));
        }
    }
#else
    w1c = x[HX_FF_OFF_W + HX_FF_LW - 1 - HX_FF_P] / HX_FF_KH;
#endif
    /* L1^-1 (eq. 1 solved for u(k)) */
    u = w1c;
    for (j = 1; j <= HX_FF_N1B; j++) {
        u -= hx_ff_b1t[j - 1] * x[HX_FF_OFF_U + HX_FF_N1B - j];
    }
    for (i = 1; i <= HX_FF_N1A; i++) {
        u += hx_ff_a1[i - 1] * x[HX_FF_OFF_W1 + HX_FF_H1 - i];
    }
    u /= HX_FF_B1LEAD;
    if (u > HX_FF_UMAX) {
        u = HX_FF_UMAX;
        status |= 4;
    } else if (u < HX_FF_UMIN) {
        u = HX_FF_UMIN;
        status |= 4;
    }
    /* the internal model follows the applied (saturated) command: no windup */
    w1 = HX_FF_B1LEAD * u;
    for (j = 1; j <= HX_FF_N1B; j++) {
        w1 += hx_ff_b1t[j - 1] * x[HX_FF_OFF_U + HX_FF_N1B - j];
    }
    for (i = 1; i <= HX_FF_N1A; i++) {
        w1 -= hx_ff_a1[i - 1] * x[HX_FF_OFF_W1 + HX_FF_H1 - i];
    }
#if HX_FF_KIND == 0
    x[HX_FF_OFF_H] = hx_forward(w1, w1p, x[HX_FF_OFF_H], HX_FF_ALPHA, HX_FF_F0, HX_FF_F1,
                                HX_FF_G0);
#elif HX_FF_KIND == 1
    for (i = 0; i < HX_FF_NPI; i++) {
        x[HX_FF_OFF_H + i] = hx_max(w1 - hx_ff_r_pi[i],
                                    hx_min(w1 + hx_ff_r_pi[i], x[HX_FF_OFF_H + i]));
    }
#endif
    for (i = 0; i < HX_FF_H1 - 1; i++) {
        x[HX_FF_OFF_W1 + i] = x[HX_FF_OFF_W1 + i + 1];
    }
    x[HX_FF_OFF_W1 + HX_FF_H1 - 1] = w1;
    for (i = 0; i < HX_FF_N1B - 1; i++) {
        x[HX_FF_OFF_U + i] = x[HX_FF_OFF_U + i + 1];
    }
    if (HX_FF_N1B > 0) {
        x[HX_FF_OFF_U + HX_FF_N1B - 1] = u;
    }
    s->u = u + HX_FF_U_SHIFT;
    s->status = status;
    return s->u;
}

double hystid_ff_desired(const hystid_ff_state *s)
{
    return s->yd;
}

int hystid_ff_status(const hystid_ff_state *s)
{
    return s->status;
}
"""
