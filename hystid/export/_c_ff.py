"""C99 text of the feed-forward compensator of :func:`hystid.compensate.compensate`, one
sample at a time: the placement, the reference model and L2's stable inverse
(:func:`hystid.compensate.linear_parts.lti_push` and :func:`~hystid.compensate.linear_parts.
inverse_run`), the chain of :mod:`hystid.compensate.compensator` (``_push_reference``,
``chain_step``) and the Duhem reversal planner of :mod:`hystid.compensate.duhem_inverse`
(``plan_memo`` and its helpers), written to do the same arithmetic in the same order; for the
``gduhem`` and ``mduhem`` members the per-sample inverses are in
:mod:`hystid.export._c_ff_members`.

The chain state is the flat vector of the Python compensator (``[x_M | y_M line | w2d line |
past u | past w1 | hysteresis state]``) without its reference lines, at the offsets the
generator defines (``HX_FF_*`` macros, ``hx_ff_*`` arrays, from the ``ispec``/``fpar`` arrays
of the Python chain). With L2 inverted ahead of the chain (``x_M`` empty), the ``w2d`` line is a
ring of its own, written twice so that the planner's window is in order in memory, and the
``y_M`` line is not kept (the desired output comes from a ring of its own); the lines of the
preview's length cost O(1) a sample, not a shift over the preview.
"""

from __future__ import annotations

__all__ = ["FF_CHAIN", "FF_PLANNER"]

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

/* _push_reference of the chain (L2 inverted ahead, no reference model in the chain): w2d into
   its line, a ring written twice so that the last HYSTID_FF_W_LINE values are in order at
   wl[wpos + 1 .. wpos + HYSTID_FF_W_LINE], the oldest first (no shift over the preview). The
   chain's y_M line is not kept: the desired output comes from ydl. */
static void hx_ff_push_reference(hystid_ff_state *s, double r)
{
    double w2 = r / HX_FF_K2;
    s->wpos = s->wpos + 1 < HYSTID_FF_W_LINE ? s->wpos + 1 : 0;
    s->wl[s->wpos] = w2;
    s->wl[s->wpos + HYSTID_FF_W_LINE] = w2;
}

void hystid_ff_init(hystid_ff_state *s)
{
    int i;
    for (i = 0; i < HX_FF_NX; i++) {
        s->x[i] = 0.0;
    }
    for (i = 0; i < 2 * HYSTID_FF_W_LINE; i++) {
        s->wl[i] = HX_FF_REST; /* the reference line settled at the rest */
    }
    s->wpos = HYSTID_FF_W_LINE - 1;
#if HX_FF_KIND == 0
    s->x[HX_FF_OFF_H] = HX_FF_REST; /* the Duhem state remembered at rest */
    hx_planner_init(&s->plan);
#elif HX_FF_KIND == 1
    for (i = 0; i < HX_FF_NPI; i++) {
        s->x[HX_FF_OFF_H + i] = hx_ff_p_rest[i]; /* the plays where the swing left them */
    }
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
    s->ypos = HYSTID_FF_YD_LINE - 1;
    s->y_rest = HX_FF_Y_REST;
    s->n = 0;
    s->u = HYSTID_FF_REST_COMMAND;
    s->yd = HX_FF_Y_REST;
    s->status = 0;
}

double hystid_ff_step(hystid_ff_state *s, double r)
{
    double *x = s->x;
    const double *win;
    double dev, ym, v, w, w2d, w1p, w1c, u, w1;
    long k;
    int i, j, status = 0;
#if HX_FF_KIND == 1 && HX_FF_NPOLY == 0
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
    /* ydl: a ring, the newest at ypos, the oldest after it */
    s->ypos = s->ypos + 1 < HYSTID_FF_YD_LINE ? s->ypos + 1 : 0;
    s->ydl[s->ypos] = ym;
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
    hx_ff_push_reference(s, w2d);
    if (k < HX_FF_ADVANCE) {
        return s->u; /* priming: the chain reads w2d HX_FF_ADVANCE samples ahead */
    }
    s->yd = s->ydl[s->ypos + 1 < HYSTID_FF_YD_LINE ? s->ypos + 1 : 0] + s->y_rest;
    win = &s->wl[s->wpos + HYSTID_FF_W_LINE - HX_FF_P]; /* w2d(k+q1) .. w2d(k+q1+P) */
    w1p = x[HX_FF_OFF_W1 + HX_FF_H1 - 1];
    (void)w1p; /* the Duhem block's state only */
#if HX_FF_KIND == 0
    {
        int far = 0;
        double d = hx_plan_memo(win, HX_FF_P + 1, w1p, x[HX_FF_OFF_H], HX_FF_ALPHA, HX_FF_F0,
                                HX_FF_F1, HX_FF_G0, HX_FF_BOUND, &s->plan, &status, &far);
        if (far) {
            status |= 8;
        }
        w1c = w1p + d;
    }
#elif HX_FF_KIND == 1 && HX_FF_NPOLY > 0
    {
        int st = 0;
        w1c = hx_pi_poly_inverse(win[0], w1p, &x[HX_FF_OFF_H], &st);
        status |= st;
    }
#elif HX_FF_KIND == 1
    {
        double w2c = win[0];
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
    w1c = win[0] / HX_FF_KH;
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
