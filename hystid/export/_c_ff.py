"""C99 text of the feed-forward compensator of :func:`hystid.compensate.compensate`, one
sample at a time: the placement, the reference model and L2's stable inverse
(:func:`hystid.compensate.linear_parts.lti_push` and :func:`~hystid.compensate.linear_parts.
inverse_run`), the chain of :mod:`hystid.compensate.compensator` (``_push_reference``,
``chain_step``) and the Duhem reversal planner of :mod:`hystid.compensate.duhem_inverse`
(``plan_memo`` and its helpers), written to do the same arithmetic in the same order; for the
``gduhem`` and ``mduhem`` members the per-sample inverses of
:mod:`hystid.compensate.member_inverse` (:func:`ff_chain` puts them into the chain).

The chain state is the flat vector of the Python compensator (``[x_M | y_M line | w2d line |
past u | past w1 | hysteresis state]``) at the offsets the generator defines (``HX_FF_*``
macros, ``hx_ff_*`` arrays, from the ``ispec``/``fpar`` arrays of the Python chain); with L2
inverted ahead of the chain its reference lines hold ``w2d``.
"""

from __future__ import annotations

__all__ = ["FF_CHAIN", "FF_GDUHEM", "FF_MDUHEM", "FF_MEMBER", "FF_PLANNER", "ff_chain"]

#: The Duhem inverse and its preview planner (only compiled for a Duhem compensator).
FF_PLANNER = r"""
#define HX_ROUND_OFF 1e-13
#define HX_BIG 1e30
#define HX_K HYSTID_FF_PLAN_K
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

/* plan_memo of hystid.compensate.duhem_inverse: the increment of w1 for W[0], with W[1..n-1]
   as preview; *status as there, *far set when the far branch is taken. The memo p keeps the
   previous sample's near-branch path and backward sets (the window moves on by one sample a
   call); it changes the work done, not the result (plan_step's). */
static double hx_plan_memo(const double *W, int n, double w1p, double w2p, double alpha,
                           double f0, double f1, double g0, double bound, hystid_ff_planner *p,
                           int *status, int *far)
{
    double *gaps = p->gaps, *room = p->room;
    const double *lo, *hi;
    double *out_lo, *out_hi;
    double d0, w1a, w2a, a1, a2, d, w1, near, farv, w1f, w2f;
    int base, stop, same, st0, st, j, i, k, slot, kept, fill, m, r, scratch, n_sol;
    *far = 0;
    base = p->base;
    p->base = base + 1 < n ? base + 1 : 0;
    if (p->target >= 0) {
        p->target -= 1;
    }
    stop = p->exit;
    p->exit = -1;
    d0 = hx_inverse_step(W[0], w1p, w2p, alpha, f0, f1, g0, bound, &st0);
    *status = st0;
    if (st0 == HX_UNREACHABLE || n < 3) {
        p->key = 0;
        return d0;
    }
    w1a = w1p + d0;
    w2a = hx_forward(w1a, w1p, w2p, alpha, f0, f1, g0);
    same = p->key == 1 && w1p == p->key_w1 && w2p == p->key_w2;
    if (same) {
        /* the state is where the kept path went after its first step: it goes on alike */
        j = p->j;
        if (j >= 0) {
            j -= 1;
        }
        i = p->end - 1;
        a1 = p->end_w1;
        a2 = p->end_w2;
    } else {
        j = -1;
        i = 0;
        a1 = w1a;
        a2 = w2a;
    }
    if (j < 0) {
        while (i < n - 1) {
            i += 1;
            slot = base + i;
            if (slot >= n) {
                slot -= n;
            }
            gaps[slot] = hx_gap(a1, a2, f0, f1);
            d = hx_inverse_step(W[i], a1, a2, alpha, f0, f1, g0, bound, &st);
            if (st == HX_UNREACHABLE) {
                j = i;
                break;
            }
            w1 = a1 + d;
            a2 = hx_forward(w1, a1, a2, alpha, f0, f1, g0);
            a1 = w1;
        }
    }
    p->key = 1;
    p->key_w1 = w1a;
    p->key_w2 = w2a;
    p->end = i;
    p->j = j;
    p->end_w1 = a1;
    p->end_w2 = a2;
    if (j < 0) {
        return d0;
    }
    if (same && stop >= 2) {
        /* the same path, target and sets: the backward pass would stop there again */
        if (stop > 2) {
            p->exit = stop - 1;
        }
        return d0;
    }
    if (p->target != j) {
        p->target = j;
        p->kept = 0;
        p->fill = 0;
    }
    kept = p->kept;
    fill = p->fill;
    scratch = 0;
    if (kept == 0) {
        m = hx_target(W[j] - W[j - 1], alpha, g0, bound, p->scratch[0], p->scratch[1]);
        lo = p->scratch[0];
        hi = p->scratch[1];
        scratch = 1;
        if (2 * m <= HYSTID_FF_PLAN_ROOM) {
            for (k = 0; k < m; k++) {
                room[k] = lo[k];
                room[m + k] = hi[k];
            }
            p->count[0] = m;
            p->place[0] = 0;
            lo = room;
            hi = room + m;
            fill = 2 * m;
            kept = 1;
        }
    } else {
        m = p->count[0];
        lo = room + p->place[0];
        hi = room + p->place[0] + m;
    }
    i = j;
    r = 0;
    for (;;) {
        if (m == 0) {
            break;
        }
        if (i > 1) {
            slot = base + i;
            if (slot >= n) {
                slot -= n;
            }
            if (hx_inside(gaps[slot], lo, hi, m)) {
                break;
            }
        } else {
            p->kept = kept;
            p->fill = fill;
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
        i -= 1;
        r += 1;
        if (r < kept) {
            m = p->count[r];
            lo = room + p->place[r];
            hi = room + p->place[r] + m;
            continue;
        }
        out_lo = p->scratch[2 * scratch];
        out_hi = p->scratch[2 * scratch + 1];
        scratch = 1 - scratch;
        m = hx_preimage(lo, hi, m, W[i] - W[i - 1], alpha, f1, g0, bound, out_lo, out_hi);
        if (r == kept && fill + 2 * m <= HYSTID_FF_PLAN_ROOM) {
            for (k = 0; k < m; k++) {
                room[fill + k] = out_lo[k];
                room[fill + m + k] = out_hi[k];
            }
            p->count[r] = m;
            p->place[r] = fill;
            lo = room + fill;
            hi = room + fill + m;
            fill += 2 * m;
            kept = r + 1;
        } else {
            lo = out_lo;
            hi = out_hi;
        }
    }
    if (i >= 2) {
        p->exit = i;
    }
    p->kept = kept;
    p->fill = fill;
    return d0;
}

static void hx_planner_init(hystid_ff_planner *p)
{
    int i, k;
    p->base = 0;
    p->key = 0;
    p->end = 0;
    p->j = -1;
    p->target = -1;
    p->kept = 0;
    p->exit = -1;
    p->fill = 0;
    p->key_w1 = p->key_w2 = p->end_w1 = p->end_w2 = 0.0;
    for (i = 0; i < HYSTID_FF_PREVIEW + 1; i++) {
        p->count[i] = 0;
        p->place[i] = 0;
        p->gaps[i] = 0.0;
    }
    for (i = 0; i < 4; i++) {
        for (k = 0; k < HX_K; k++) {
            p->scratch[i][k] = 0.0;
        }
    }
    for (i = 0; i < HYSTID_FF_PLAN_ROOM; i++) {
        p->room[i] = 0.0;
    }
}
"""

#: The compensator: placement, reference model, L2's stable inverse, then the chain (hysteresis
#: inverse, L1 inverse, internal model).
FF_CHAIN = r"""
static double hx_lti_push(double *xl, int nn, double *yl, int nd, const double *num,
                          const double *den, double x)
{
    double acc = 0.0;
    int i, j;
    for (i = 0; i < nn - 1; i++) {
        xl[i] = xl[i + 1];
    }
    xl[nn - 1] = x;
    for (i = 0; i < nn; i++) {
        acc += num[i] * xl[nn - 1 - i];
    }
    for (j = 1; j <= nd; j++) {
        acc -= den[j] * yl[nd - j];
    }
    for (i = 0; i < nd - 1; i++) {
        yl[i] = yl[i + 1];
    }
    if (nd > 0) {
        yl[nd - 1] = acc;
    }
    return acc;
}

static void hx_ff_push_reference(double *x, double r)
{
    double w2;
    int i;
    for (i = 0; i < HX_FF_LY - 1; i++) {
        x[HX_FF_OFF_Y + i] = x[HX_FF_OFF_Y + i + 1];
    }
    x[HX_FF_OFF_Y + HX_FF_LY - 1] = r;
    w2 = r / HX_FF_K2;
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
    for (i = HX_FF_OFF_Y; i < HX_FF_OFF_U; i++) {
        s->x[i] = HX_FF_REST; /* the reference lines settled at the rest */
    }
#if HX_FF_KIND == 0
    s->x[HX_FF_OFF_H] = HX_FF_REST; /* the Duhem state remembered at rest */
    hx_planner_init(&s->plan);
#endif
    for (i = 0; i < HYSTID_FF_M_NX; i++) {
        s->mx[i] = 0.0;
    }
    for (i = 0; i < HYSTID_FF_M_NY; i++) {
        s->my[i] = 0.0;
    }
    for (i = 0; i < HYSTID_FF_L2_NX; i++) {
        s->lx[i] = 0.0;
    }
    for (i = 0; i < HYSTID_FF_L2_NY; i++) {
        s->lv[i] = 0.0;
    }
    for (i = 0; i < 2 * HYSTID_FF_L2_NF; i++) {
        s->fl[i] = 0.0;
    }
    s->slot = HYSTID_FF_L2_NF - 1;
    for (i = 0; i < HYSTID_FF_L2_NS; i++) {
        s->xs[i] = 0.0;
    }
    for (i = 0; i < HYSTID_FF_SETTLE; i++) {
        s->corr[i] = 0.0;
    }
    for (i = 0; i < HYSTID_FF_YD_LINE; i++) {
        s->ydl[i] = 0.0;
    }
    s->y_rest = HX_FF_Y_REST;
    s->n = 0;
    s->u = HYSTID_FF_REST_COMMAND;
    s->yd = HX_FF_Y_REST;
    s->status = 0;
}

double hystid_ff_step(hystid_ff_state *s, double r)
{
    double *x = s->x;
    double dev, ym, v, w, w2d, w1p, w1c, u, w1;
    long k;
    int i, j, status = 0;
#if HX_FF_KIND == 1
    double pinv[HX_FF_NPI], tail, cum;
#endif
    k = s->n;
    s->n += 1;
#if HX_FF_ANCHOR_REFERENCE
    if (k == 0) {
        s->y_rest = r; /* the stage rests at the reference's first sample */
    }
#endif
    dev = r - s->y_rest;
    /* the reference model M, read HX_FF_LEAD samples late */
#if HX_FF_M
    ym = hx_lti_push(s->mx, HYSTID_FF_M_NX, s->my, HX_FF_M_ND, hx_ff_m_num, hx_ff_m_den, dev);
    k -= HX_FF_LEAD;
    if (k < 0) {
        return s->u;
    }
#else
    ym = dev;
#endif
    for (i = 0; i < HYSTID_FF_YD_LINE - 1; i++) {
        s->ydl[i] = s->ydl[i + 1];
    }
    s->ydl[HYSTID_FF_YD_LINE - 1] = ym;
    /* L2's stable inverse: its delay read ahead, the causal part, the anti-causal FIR */
    k -= HX_FF_L2_DELAY;
    if (k < 0) {
        return s->u;
    }
    v = hx_lti_push(s->lx, HYSTID_FF_L2_NX, s->lv, HX_FF_L2_ND, hx_ff_l2_num, hx_ff_l2_den, ym);
    /* each v twice: the last HYSTID_FF_L2_NF in order at fl[slot + 1 .. slot + NF] */
    s->slot = s->slot + 1 < HYSTID_FF_L2_NF ? s->slot + 1 : 0;
    s->fl[s->slot] = v;
    s->fl[s->slot + HYSTID_FF_L2_NF] = v;
    w = 0.0;
    for (j = 0; j < HYSTID_FF_L2_NF; j++) {
        w += hx_ff_l2_fir[j] * s->fl[s->slot + 1 + j];
    }
    k -= HX_FF_L2_PRE;
#if HX_FF_L2_PRE > 0
    if (k < 0) {
        /* pre-actuation before the first sample: the state it would have left L2 in */
        double tmp[HYSTID_FF_L2_NS], acc;
        for (i = 0; i < HYSTID_FF_L2_NS; i++) {
            acc = 0.0;
            for (j = 0; j < HYSTID_FF_L2_NS; j++) {
                acc += hx_ff_l2_a[i * HYSTID_FF_L2_NS + j] * s->xs[j];
            }
            acc += hx_ff_l2_b[i] * w;
            tmp[i] = acc;
        }
        for (i = 0; i < HYSTID_FF_L2_NS; i++) {
            s->xs[i] = tmp[i];
        }
        if (k == -1) {
            for (i = 0; i < HYSTID_FF_SETTLE; i++) {
                acc = 0.0;
                for (j = 0; j < HYSTID_FF_L2_NS; j++) {
                    acc += hx_ff_l2_gain[i * HYSTID_FF_L2_NS + j] * s->xs[j];
                }
                s->corr[i] = acc;
            }
        }
        return s->u;
    }
    if (k < HYSTID_FF_SETTLE) {
        w += s->corr[k];
    }
#endif
    w2d = w + HX_FF_REST;
    /* the chain: hysteresis inverse, L1 inverse, internal model */
    hx_ff_push_reference(x, w2d);
    if (k < HX_FF_ADVANCE) {
        return s->u; /* priming: the chain reads w2d HX_FF_ADVANCE samples ahead */
    }
    s->yd = s->ydl[0] + s->y_rest;
    w1p = x[HX_FF_OFF_W1 + HX_FF_H1 - 1];
    (void)w1p; /* the Duhem block's state only */
#if HX_FF_KIND == 0
    {
        int far = 0;
        double d = hx_plan_memo(&x[HX_FF_OFF_W + HX_FF_LW - 1 - HX_FF_P], HX_FF_P + 1, w1p,
                                x[HX_FF_OFF_H], HX_FF_ALPHA, HX_FF_F0, HX_FF_F1, HX_FF_G0,
                                HX_FF_BOUND, &s->plan, &status, &far);
        if (far) {
            status |= 8;
        }
        w1c = w1p + d;
    }
#elif HX_FF_KIND == 1
    {
        double w2c = x[HX_FF_OFF_W + HX_FF_LW - 1 - HX_FF_P];
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
            w1c += hx_ff_mu_inv[i] * hx_max(w2c - hx_ff_r_inv[i],
                                            hx_min(w2c + hx_ff_r_inv[i], pinv[i]));
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
_AT_INVERSE = "#else\n    w1c = x[HX_FF_OFF_W + HX_FF_LW - 1 - HX_FF_P] / HX_FF_KH;\n#endif\n"
_AT_FORWARD = "#endif\n    for (i = 0; i < HX_FF_H1 - 1; i++) {\n"

_MEMBER_BRANCHES = {
    4: (
        "#elif HX_FF_KIND == 4\n"
        "    s->x[HX_FF_OFF_H] = HX_FF_REST; /* the generalised block's state at rest */\n",
        "#elif HX_FF_KIND == 4\n"
        "    {\n"
        "        double d = hx_gd_inverse_step(x[HX_FF_OFF_W + HX_FF_LW - 1 - HX_FF_P], w1p,\n"
        "                                      x[HX_FF_OFF_H], HX_FF_BOUND, &status);\n"
        "        w1c = w1p + d;\n"
        "    }\n",
        "#elif HX_FF_KIND == 4\n"
        "    x[HX_FF_OFF_H] = hx_gd_forward(w1, w1p, x[HX_FF_OFF_H]);\n",
    ),
    5: (
        "",
        "#elif HX_FF_KIND == 5\n"
        "    {\n"
        "        double d = hx_md_inverse_step(x[HX_FF_OFF_W + HX_FF_LW - 1 - HX_FF_P], w1p,\n"
        "                                      &x[HX_FF_OFF_H], HX_FF_BOUND, &status);\n"
        "        w1c = w1p + d;\n"
        "    }\n",
        "#elif HX_FF_KIND == 5\n"
        "    hx_md_forward(&x[HX_FF_OFF_H], w1, w1p);\n",
    ),
}


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
