"""C99 text of the on-line identifier's supervisor (:mod:`hystid.identify.online_supervisor`),
written to do the same arithmetic in the same order, for the exported ``hystid_rpem_step``.

Python runs the two frozen estimates' free runs (``shadow_block``) over a block of
:data:`~hystid.identify.online_supervisor.BLOCK` samples at its end; the C step runs them one
sample at a time beside the recursion. The free runs do not depend on the recursion between
two block ends, so the numbers are the same and no sample carries the block's free runs: the
sample that ends a block adds only the checks (a sum of at most ``BLOCK`` squares) and, at
most, one rollback and the taking of a new candidate (copies of the estimate, its covariance
and the signal windows).

The block's residual sum of squares is
:func:`~hystid.identify.online_supervisor.finite_squares`: the squares of the finite residuals
added in order (``hx_block_sum``), the same on every CPU and numpy. ``max`` is Python's
(the first argument unless the second is larger: ``hx_pymax``). The accepted estimate's
block sums are differences of its running sums, as ``_Shadow.run`` takes them.

The text reads the recursion's ``hx_step`` (the model step with a parameter vector: the
export writes the Duhem step once for both) and the ``HX_R_*`` constants; the generator adds
``HX_R_BLOCK``, ``HX_R_HYSTERESIS``, ``HX_R_FORGET``, ``HX_R_FLOOR``, ``HX_R_SETTLE`` and
``HX_R_SUP_RATIO``.
"""

from __future__ import annotations

__all__ = ["SUPERVISOR", "SUPERVISOR_INIT", "SUPERVISOR_STEP"]

#: The supervisor's functions (after ``hx_step`` and ``hx_resync``, before the entry points).
SUPERVISOR = r"""
#if HYSTID_RPEM_SUPERVISE
/* hystid.identify.online_supervisor: the accepted estimate (the last validated one) and the
   candidate (the recursion's estimate at the start of the validation interval), each run
   freely on the samples (its shadow) */
static double hx_pymax(double a, double b)
{
    /* Python's max(a, b): a unless b is larger */
    return b > a ? b : a;
}

/* online_supervisor.finite_squares: the squares added in order */
static double hx_block_sum(const double *a, int n)
{
    double res = 0.0;
    int i;
    for (i = 0; i < n; i++) {
        res += a[i];
    }
    return res;
}

/* Supervisor._shadow: the recursion's estimate, covariance and signal windows, frozen */
static void hx_shadow_take(hystid_rpem_shadow *sh, const hystid_rpem_state *s)
{
    int i, j;
    for (i = 0; i < HX_R_NE; i++) {
        sh->est[i] = s->est[i];
        for (j = 0; j < HX_R_NE; j++) {
            sh->P[i][j] = s->P[i][j];
        }
    }
    for (i = 0; i < HX_R_W; i++) {
        sh->u[i] = s->u[i];
        sh->w1[i] = s->w1[i];
        sh->w2[i] = s->w2[i];
        sh->y[i] = s->yh[i];
    }
    for (i = 0; i < 3; i++) {
        sh->sums[i] = 0.0;
    }
}

/* shadow_block for one sample: the free run's step, sum e^2, n and sum |dw1| */
static void hx_shadow_step(hystid_rpem_shadow *sh, double u, double y)
{
    const int L = HX_R_W - 1;
    double e;
    int i;
    for (i = 0; i < L; i++) {
        sh->u[i] = sh->u[i + 1];
        sh->w1[i] = sh->w1[i + 1];
        sh->w2[i] = sh->w2[i + 1];
        sh->y[i] = sh->y[i + 1];
    }
    sh->u[L] = u;
    hx_step(sh->est, sh->u, sh->w1, sh->w2, sh->y, L);
    e = y - sh->y[L] - sh->est[HX_R_NPAR];
    if (isfinite(e)) {
        sh->sums[0] += e * e;
        sh->sums[1] += 1.0;
    }
    sh->sums[2] += fabs(sh->w1[L] - sh->w1[L - 1]);
}

static double hx_shadow_rms(const hystid_rpem_shadow *sh)
{
    return sqrt(sh->sums[0] / hx_pymax(sh->sums[1], 1.0));
}

/* Supervisor._new_candidate */
static void hx_new_candidate(hystid_rpem_state *s)
{
    hx_shadow_take(&s->shadow[1 - s->accepted], s);
    s->live[0] = s->live[1] = 0.0;
    s->versus[0] = s->versus[1] = 0.0;
}

/* Supervisor._rollback: the recursion restarts from the accepted estimate, its covariance
   and its free run */
static void hx_rollback(hystid_rpem_state *s, double k)
{
    const hystid_rpem_shadow *a = &s->shadow[s->accepted];
    double *scal = s->scal;
    double level;
    int i, j, p;
    for (i = 0; i < HX_R_NE; i++) {
        s->est[i] = a->est[i];
        s->est_good[i] = a->est[i];
        for (j = 0; j < HX_R_NE; j++) {
            s->P[i][j] = a->P[i][j];
            s->P_good[i][j] = a->P[i][j];
        }
    }
    for (i = 0; i < HX_R_W; i++) {
        s->u[i] = a->u[i];
        s->w1[i] = a->w1[i];
        s->w2[i] = a->w2[i];
        s->yh[i] = a->y[i];
        for (p = 0; p < HX_R_NPAR; p++) {
            s->s1[i][p] = 0.0;
            s->s2[i][p] = 0.0;
            s->sy[i][p] = 0.0;
        }
    }
    scal[HX_S_NREC] += 1.0;
    if (scal[HX_S_FIRST] < 0) {
        scal[HX_S_FIRST] = k;
    }
    level = hx_pymax(hx_pymax(hx_shadow_rms(a), HX_R_FLOOR), 1e-300);
    scal[HX_S_SIG] = level;
    scal[HX_S_SHORT] = level * level;
    scal[HX_S_HOLD] = scal[HX_S_GOODAGE] = 0.0;
    s->rollbacks += 1;
    hx_new_candidate(s);
}

/* Supervisor._step at the end of a block (k samples so far): divergence over the block,
   wander over the interval, validation of the candidate */
static void hx_block(hystid_rpem_state *s, double k)
{
    const hystid_rpem_shadow *a = &s->shadow[s->accepted];
    const hystid_rpem_shadow *c = &s->shadow[1 - s->accepted];
    double sq_a, n_a, sq_r, n_r, block_r, block_a, live, versus;
    sq_a = a->sums[0] - s->before[0];
    n_a = a->sums[1] - s->before[1];
    sq_r = hx_block_sum(s->sq, s->n_ok);
    n_r = (double)s->n_ok;
    s->live[0] += sq_r;
    s->live[1] += n_r;
    s->versus[0] += sq_a;
    s->versus[1] += n_a;
    if (n_r != 0.0 && n_a != 0.0) {
        block_r = sqrt(sq_r / n_r);
        block_a = hx_pymax(sqrt(sq_a / n_a), HX_R_FLOOR);
        if (block_r > HX_R_SUP_RATIO * block_a) {
            hx_rollback(s, k);
            return;
        }
    }
    if (k < s->settle) { /* the recursion settles from its start */
        return;
    }
    if (s->settle != 0.0) {
        s->settle = 0.0;
        hx_new_candidate(s);
        return;
    }
    if (s->live[1] >= 2 * HX_R_BLOCK && s->versus[1] != 0.0) {
        live = sqrt(s->live[0] / s->live[1]);
        versus = hx_pymax(sqrt(s->versus[0] / s->versus[1]), HX_R_FLOOR);
        if (live > (1.0 + HX_R_HYSTERESIS) * versus) {
            hx_rollback(s, k);
            return;
        }
    }
    if (c->est[HX_R_I_ALPHA] * c->sums[2] >= HX_R_FORGET && c->sums[1] >= 2 * HX_R_BLOCK) {
        versus = hx_pymax(sqrt(s->versus[0] / hx_pymax(s->versus[1], 1.0)), HX_R_FLOOR);
        if (hx_shadow_rms(c) > (1.0 + HX_R_HYSTERESIS) * versus) {
            hx_rollback(s, k);
            return;
        }
        s->accepted = 1 - s->accepted; /* the candidate validated */
        s->validated += 1;
        hx_new_candidate(s);
    }
}

/* Supervisor.feed_one: u less the rest level, y measured, e the recursion's residual */
static void hx_supervise(hystid_rpem_state *s, double u, double y, double e)
{
    hx_shadow_step(&s->shadow[0], u, y);
    hx_shadow_step(&s->shadow[1], u, y);
    if (isfinite(e)) {
        s->sq[s->n_ok] = e * e;
        s->n_ok += 1;
    }
    s->filled += 1;
    if (s->filled < HX_R_BLOCK) {
        return;
    }
    s->filled = 0;
    hx_block(s, s->scal[HX_S_K]);
    s->n_ok = 0;
    s->before[0] = s->shadow[s->accepted].sums[0];
    s->before[1] = s->shadow[s->accepted].sums[1];
}
#endif
"""

#: ``hystid_rpem_init``'s part (the warm start accepted, the recursion settling).
SUPERVISOR_INIT = r"""#if HYSTID_RPEM_SUPERVISE
    s->accepted = 0;
    hx_shadow_take(&s->shadow[0], s);
    hx_new_candidate(s);
    s->filled = 0;
    s->n_ok = 0;
    for (i = 0; i < HX_R_BLOCK; i++) {
        s->sq[i] = 0.0;
    }
    s->before[0] = s->before[1] = 0.0;
    s->settle = HX_R_SETTLE;
    s->rollbacks = 0;
    s->validated = 0;
#endif
"""

#: ``hystid_rpem_step``'s part, after the recursion's sample.
SUPERVISOR_STEP = r"""#if HYSTID_RPEM_SUPERVISE
    hx_supervise(s, s->u[L], y, e);
#endif
"""
