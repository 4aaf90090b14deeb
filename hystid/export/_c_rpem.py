"""C99 text of the on-line identifier's step: the recursive prediction-error recursion of
:mod:`hystid.identify.online` (``_rpem_sample`` with ``kernels.step_sens_row``,
``_recursive.admissible_into``, ``poly.schur_cohn_into``, ``_covariance_ok``, ``_resync``),
written to do the same arithmetic in the same order, and its supervisor
(:mod:`hystid.export._c_rpem_supervisor`) under ``HYSTID_RPEM_SUPERVISE``.

The signal windows hold ``HX_R_W`` samples (the newest at ``HX_R_W - 1``) and slide by one
sample per step; the Python recursion slides them in blocks, which moves values but computes
nothing, so the numbers are the same.
"""

from __future__ import annotations

from ._c_rpem_supervisor import SUPERVISOR, SUPERVISOR_INIT, SUPERVISOR_STEP

__all__ = ["GDUHEM_RPEM_STEP", "RPEM_STEP"]

RPEM_STEP = r"""
/* indices of scal (as _K, _LAM, ... of hystid.identify.online) */
#define HX_S_K 0
#define HX_S_LAM 1
#define HX_S_SIG 2
#define HX_S_SHORT 3
#define HX_S_LONG 4
#define HX_S_NPROJ 5
#define HX_S_NCLIP 6
#define HX_S_NREC 7
#define HX_S_FIRST 8
#define HX_S_HOLD 9
#define HX_S_GOODAGE 10
#define HX_S_NPRESET 11
#define HX_S_DW1MAX 12

static int hx_schur_cohn(const double *c, int n, double kmax, double *work)
{
    int i, m;
    double km, d, a, b;
    for (i = 0; i < n; i++) {
        work[i] = c[i];
    }
    for (m = n; m > 0; m--) {
        km = work[m - 1];
        if (!(fabs(km) < kmax)) {
            return 0;
        }
        d = 1.0 - km * km;
        for (i = 0; i < m / 2; i++) {
            a = work[i];
            b = work[m - 2 - i];
            work[i] = (a - km * b) / d;
            work[m - 2 - i] = (b - km * a) / d;
        }
    }
    return 1;
}

static int hx_admissible(const double *theta, double kmax, double *work)
{
    int i;
    for (i = 0; i < HX_R_NPAR; i++) {
        if (!isfinite(theta[i])) {
            return 0;
        }
    }
    if (theta[HX_R_I_ALPHA] <= 0.0) {
        return 0;
    }
    return hx_schur_cohn(theta + HX_R_I_A1, HX_R_N1A, kmax, work)
           && hx_schur_cohn(theta + HX_R_I_A2, HX_R_N2A, kmax, work)
           && hx_schur_cohn(theta + HX_R_I_B1, HX_R_N1B, kmax, work)
           && hx_schur_cohn(theta, HX_R_N2B, kmax, work);
}

static int hx_covariance_ok(double P[HX_R_NE][HX_R_NE], double trace_max)
{
    int i, j;
    double tr = 0.0;
    for (i = 0; i < HX_R_NE; i++) {
        if (!(P[i][i] >= 0.0) || !isfinite(P[i][i])) {
            return 0;
        }
        tr += P[i][i];
        for (j = 0; j < i; j++) {
            if (!(P[i][j] * P[i][j] <= P[i][i] * P[j][j])) {
                return 0;
            }
        }
    }
    return tr < trace_max && tr > 0.0;
}

/* kernels.step at index k of the windows, with theta: eqs. (1), (7), (2) (the recursion's
   model step and the supervisor's free runs) */
static void hx_step(const double *theta, const double *U, double *W1, double *W2, double *Y,
                    int k)
{
    const double alpha = theta[HX_R_I_ALPHA];
#if HX_R_I_F0 >= 0
    const double f0 = theta[HX_R_I_F0];
#else
    const double f0 = 0.0;
#endif
    const double f1 = theta[HX_R_I_F1];
    const double g0 = theta[HX_R_I_G0];
    double w1, y, w1p, w2p, dw1;
    int i, j;
    w1 = U[k - HX_R_Q1];
    for (j = 1; j <= HX_R_N1B; j++) {
        w1 += theta[HX_R_I_B1 + j - 1] * U[k - HX_R_Q1 - j];
    }
    for (i = 1; i <= HX_R_N1A; i++) {
        w1 -= theta[HX_R_I_A1 + i - 1] * W1[k - i];
    }
    W1[k] = w1;
    w1p = W1[k - 1];
    w2p = W2[k - 1];
    dw1 = w1 - w1p;
    W2[k] = w2p + alpha * (f0 * hx_sgn(w1p) + f1 * w1p - w2p) * fabs(dw1) + g0 * dw1;
    y = W2[k - HX_R_Q2];
    for (j = 1; j <= HX_R_N2B; j++) {
        y += theta[j - 1] * W2[k - HX_R_Q2 - j];
    }
    for (i = 1; i <= HX_R_N2A; i++) {
        y -= theta[HX_R_I_A2 + i - 1] * Y[k - i];
    }
    Y[k] = y;
}

/* kernels.step_sens_row at index k (= ks) of the windows, with theta */
static void hx_step_sens(hystid_rpem_state *s, const double *theta, int k)
{
    double *U = s->u, *W1 = s->w1, *W2 = s->w2, *Y = s->yh;
    double (*S1)[HX_R_NPAR] = s->s1, (*S2)[HX_R_NPAR] = s->s2, (*SY)[HX_R_NPAR] = s->sy;
    const double alpha = theta[HX_R_I_ALPHA];
#if HX_R_I_F0 >= 0
    const double f0 = theta[HX_R_I_F0];
#else
    const double f0 = 0.0;
#endif
    const double f1 = theta[HX_R_I_F1];
    const double g0 = theta[HX_R_I_G0];
    double w1p, w2p, dw1, G, s1, sd, absd, ddw1, dG, sy;
    int i, j, p;
    /* step: eqs. (1), (7), (2) */
    hx_step(theta, U, W1, W2, Y, k);
    w1p = W1[k - 1];
    w2p = W2[k - 1];
    /* sensitivities */
    dw1 = W1[k] - w1p;
    G = f0 * hx_sgn(w1p) + f1 * w1p - w2p;
    for (p = 0; p < HX_R_NPAR; p++) {
        s1 = 0.0;
        for (i = 1; i <= HX_R_N1A; i++) {
            s1 -= theta[HX_R_I_A1 + i - 1] * S1[k - i][p];
        }
        S1[k][p] = s1;
    }
    for (j = 1; j <= HX_R_N1B; j++) {
        S1[k][HX_R_I_B1 + j - 1] += U[k - HX_R_Q1 - j];
    }
    for (i = 1; i <= HX_R_N1A; i++) {
        S1[k][HX_R_I_A1 + i - 1] -= W1[k - i];
    }
    sd = hx_sgn(dw1);
    absd = fabs(dw1);
    for (p = 0; p < HX_R_NPAR; p++) {
        ddw1 = S1[k][p] - S1[k - 1][p];
        dG = f1 * S1[k - 1][p] - S2[k - 1][p];
        S2[k][p] = S2[k - 1][p] + alpha * (dG * absd + G * sd * ddw1) + g0 * ddw1;
    }
    S2[k][HX_R_I_ALPHA] += G * absd;
    S2[k][HX_R_I_F1] += alpha * w1p * absd;
#if HX_R_I_F0 >= 0
    S2[k][HX_R_I_F0] += alpha * hx_sgn(w1p) * absd;
#endif
    S2[k][HX_R_I_G0] += dw1;
    for (p = 0; p < HX_R_NPAR; p++) {
        sy = S2[k - HX_R_Q2][p];
        for (j = 1; j <= HX_R_N2B; j++) {
            sy += theta[j - 1] * S2[k - HX_R_Q2 - j][p];
        }
        for (i = 1; i <= HX_R_N2A; i++) {
            sy -= theta[HX_R_I_A2 + i - 1] * SY[k - i][p];
        }
        SY[k][p] = sy;
    }
    for (j = 1; j <= HX_R_N2B; j++) {
        SY[k][j - 1] += W2[k - HX_R_Q2 - j];
    }
    for (i = 1; i <= HX_R_N2A; i++) {
        SY[k][HX_R_I_A2 + i - 1] -= Y[k - i];
    }
}

/* _resync: the model output takes the measured one, w2 from L2 inverted on it */
static void hx_resync(hystid_rpem_state *s, const double *theta, int lo, int L)
{
    int i, j, p;
    double w2;
    for (i = lo; i <= L; i++) {
        s->yh[i] = s->ym[i];
        if (!isfinite(s->w1[i])) {
            s->w1[i] = 0.0;
        }
        for (p = 0; p < HX_R_NPAR; p++) {
            s->s1[i][p] = 0.0;
            s->s2[i][p] = 0.0;
            s->sy[i][p] = 0.0;
        }
    }
    for (i = lo + HX_R_RESYNC; i <= L; i++) {
        w2 = s->ym[i];
        for (j = 1; j <= HX_R_N2A; j++) {
            w2 += theta[HX_R_I_A2 + j - 1] * s->ym[i - j];
        }
        for (j = 1; j <= HX_R_N2B; j++) {
            w2 -= theta[j - 1] * s->w2[i - HX_R_Q2 - j];
        }
        s->w2[i - HX_R_Q2] = w2;
    }
}

@SUPERVISOR@
void hystid_rpem_init(hystid_rpem_state *s)
{
    int i, j, p;
    for (i = 0; i < HX_R_NE; i++) {
        s->est[i] = hx_r_est0[i];
        s->est_good[i] = hx_r_est0[i];
        for (j = 0; j < HX_R_NE; j++) {
            s->P[i][j] = hx_r_p0[i * HX_R_NE + j];
            s->P_good[i][j] = hx_r_p0[i * HX_R_NE + j];
        }
        s->PH[i] = 0.0;
        s->cand[i] = 0.0;
        s->work[i] = 0.0;
    }
    for (i = 0; i < 13; i++) {
        s->scal[i] = hx_r_scal0[i];
    }
    for (i = 0; i < HX_R_W; i++) {
        s->u[i] = hx_r_win0[i];
        s->w1[i] = hx_r_win0[HX_R_W + i];
        s->w2[i] = hx_r_win0[2 * HX_R_W + i];
        s->yh[i] = hx_r_win0[3 * HX_R_W + i];
        s->ym[i] = hx_r_win0[4 * HX_R_W + i];
        for (p = 0; p < HX_R_NPAR; p++) {
            s->s1[i][p] = 0.0;
            s->s2[i][p] = 0.0;
            s->sy[i][p] = 0.0;
        }
    }
    s->e = NAN;
@SUPERVISOR_INIT@}

void hystid_rpem_step(hystid_rpem_state *s, double u, double y)
{
    const int L = HX_R_W - 1;
    double *est = s->est, *scal = s->scal, *PH = s->PH, *cand = s->cand;
    double lam, e = NAN, sig, ec, hPh, sv, denom, dw1, v;
    int i, j, p, finite_y, restart, alarm;
    /* slide the windows by one sample */
    for (i = 0; i < L; i++) {
        s->u[i] = s->u[i + 1];
        s->w1[i] = s->w1[i + 1];
        s->w2[i] = s->w2[i + 1];
        s->yh[i] = s->yh[i + 1];
        s->ym[i] = s->ym[i + 1];
        for (p = 0; p < HX_R_NPAR; p++) {
            s->s1[i][p] = s->s1[i + 1][p];
            s->s2[i][p] = s->s2[i + 1][p];
            s->sy[i][p] = s->sy[i + 1][p];
        }
    }
    finite_y = isfinite(y);
    s->u[L] = u - HYSTID_U_REST;
    /* 1. model step with theta(k-1) and the exact sensitivities psi(k) */
    hx_step_sens(s, est, L);
    s->ym[L] = finite_y ? y - est[HX_R_NPAR] : s->yh[L - 1];
    scal[HX_S_LAM] = HX_R_LAM_INF - (HX_R_LAM_INF - scal[HX_S_LAM]) * HX_R_LAM_RATE;
    lam = scal[HX_S_LAM];
    restart = !isfinite(s->yh[L]);
    if (finite_y && !restart) {
        const double *psi = s->sy[L];
        e = y - s->yh[L] - est[HX_R_NPAR];
        /* 2. clipped residual, robust scale, short- and long-term residual levels */
        sig = scal[HX_S_SIG];
        ec = e;
        if (fabs(e) > HX_R_CLIP * sig) {
            ec = e > 0 ? HX_R_CLIP * sig : -HX_R_CLIP * sig;
            scal[HX_S_NCLIP] += 1.0;
        }
        scal[HX_S_SIG] = sqrt((1.0 - HX_R_A_SIG) * sig * sig + HX_R_A_SIG * ec * ec) + 1e-300;
        scal[HX_S_SHORT] = (1.0 - HX_R_A_SHORT) * scal[HX_S_SHORT] + HX_R_A_SHORT * e * e;
        alarm = scal[HX_S_SHORT] > HX_R_DIV_RATIO * HX_R_DIV_RATIO * scal[HX_S_LONG];
        if (!alarm) {
            scal[HX_S_LONG] = (1.0 - HX_R_A_LONG) * scal[HX_S_LONG]
                              + HX_R_A_LONG * scal[HX_S_SHORT];
        }
        /* 3. Gauss-Newton step with forgetting; the offset's sensitivity is 1 */
        hPh = 0.0;
        for (i = 0; i < HX_R_NE; i++) {
            sv = s->P[i][HX_R_NPAR];
            for (j = 0; j < HX_R_NPAR; j++) {
                sv += s->P[i][j] * psi[j];
            }
            PH[i] = sv;
            hPh += (i < HX_R_NPAR ? psi[i] : 1.0) * sv;
        }
        denom = lam + hPh;
        for (i = 0; i < HX_R_NE; i++) {
            cand[i] = est[i] + PH[i] * (ec / denom);
        }
        /* 4. projection onto the admissible set (Assumption 1; condition 8 over the largest
              |dw1| seen so far: alpha capped below 2 / max|dw1|) */
        dw1 = fabs(s->w1[L] - s->w1[L - 1]);
        if (dw1 > scal[HX_S_DW1MAX]) {
            scal[HX_S_DW1MAX] = dw1;
        }
        if (hx_admissible(cand, HX_R_KMAX, s->work)) {
            if (scal[HX_S_DW1MAX] > 0.0) {
                v = 2.0 * HX_R_ALPHA_MARGIN / scal[HX_S_DW1MAX];
                if (cand[HX_R_I_ALPHA] >= v) {
                    cand[HX_R_I_ALPHA] = v;
                    scal[HX_S_NPROJ] += 1.0;
                }
            }
            for (i = 0; i < HX_R_NE; i++) {
                est[i] = cand[i];
            }
        } else {
            scal[HX_S_NPROJ] += 1.0;
        }
        for (i = 0; i < HX_R_NE; i++) {
            for (j = 0; j <= i; j++) {
                v = (s->P[i][j] - PH[i] * PH[j] / denom) / lam;
                s->P[i][j] = v;
                s->P[j][i] = v;
            }
        }
        if (!hx_covariance_ok(s->P, HX_R_TRACE_MAX)) {
            scal[HX_S_NPRESET] += 1.0;
            for (i = 0; i < HX_R_NE; i++) {
                for (j = 0; j < HX_R_NE; j++) {
                    s->P[i][j] = 0.0;
                }
                s->P[i][i] = i < HX_R_NPAR ? HX_R_PRESET : HX_R_PRESET * HX_R_TRACK;
            }
        }
        /* divergence watch */
        if (alarm) {
            scal[HX_S_HOLD] += 1.0;
        } else {
            scal[HX_S_HOLD] = 0.0;
            if (scal[HX_S_SHORT] < 4.0 * scal[HX_S_LONG]) {
                scal[HX_S_GOODAGE] += 1.0;
                if (scal[HX_S_GOODAGE] > HX_R_DIV_HOLD) {
                    for (i = 0; i < HX_R_NE; i++) {
                        s->est_good[i] = est[i];
                        for (j = 0; j < HX_R_NE; j++) {
                            s->P_good[i][j] = s->P[i][j];
                        }
                    }
                    scal[HX_S_GOODAGE] = 0.0;
                }
            }
        }
        restart = scal[HX_S_HOLD] > HX_R_DIV_HOLD;
    }
    if (restart) {
        scal[HX_S_NREC] += 1.0;
        if (scal[HX_S_FIRST] < 0) {
            scal[HX_S_FIRST] = scal[HX_S_K] + 1.0;
        }
        for (i = 0; i < HX_R_NE; i++) {
            est[i] = s->est_good[i];
            for (j = 0; j < HX_R_NE; j++) {
                s->P[i][j] = s->P_good[i][j];
            }
        }
        hx_resync(s, est, 0, L);
        scal[HX_S_HOLD] = 0.0;
        scal[HX_S_GOODAGE] = 0.0;
        scal[HX_S_SHORT] = scal[HX_S_LONG];
        scal[HX_S_SIG] = sqrt(scal[HX_S_LONG]);
    }
    scal[HX_S_K] += 1.0;
    s->e = e;
@SUPERVISOR_STEP@}

const double *hystid_rpem_theta(const hystid_rpem_state *s)
{
    return s->est;
}

double hystid_rpem_offset(const hystid_rpem_state *s)
{
    return s->est[HX_R_NPAR];
}

double hystid_rpem_error(const hystid_rpem_state *s)
{
    return s->e;
}

long hystid_rpem_restarts(const hystid_rpem_state *s)
{
    return (long)s->scal[HX_S_NREC];
}

long hystid_rpem_rollbacks(const hystid_rpem_state *s)
{
#if HYSTID_RPEM_SUPERVISE
    return s->rollbacks;
#else
    (void)s;
    return 0;
#endif
}

long hystid_rpem_validated(const hystid_rpem_state *s)
{
#if HYSTID_RPEM_SUPERVISE
    return s->validated;
#else
    (void)s;
    return 0;
#endif
}
"""
RPEM_STEP = (RPEM_STEP.replace("@SUPERVISOR@\n", SUPERVISOR)
             .replace("@SUPERVISOR_INIT@", SUPERVISOR_INIT)
             .replace("@SUPERVISOR_STEP@", SUPERVISOR_STEP))

#: ``kernels.step_sens_row`` for the generalised Duhem block (its ``_shape_sens`` branch); needs
#: ``hx_shape_terms`` and the ``HX_I_*`` shape indices of the model's part
#: (:data:`hystid.export._c_model.SHAPE_TERMS`).
_SHAPE_STEP_SENS = r"""/* kernels.step at index k of the windows, with theta: eqs. (1), (7),
   (2) with the generalised eq. (7), w2(k) = w2(k-1) + A [f0 sgn(w1p) + F - w2(k-1)] |dw1|
   + G dw1 (hx_shape_terms) (the recursion's model step and the supervisor's free runs) */
static void hx_step(const double *theta, const double *U, double *W1, double *W2, double *Y,
                    int k)
{
#if HX_R_I_F0 >= 0
    const double f0 = theta[HX_R_I_F0];
#else
    const double f0 = 0.0;
#endif
    double w1, y, w1p, w2p, dw1, A, F, G, dF, dG;
    int i, j;
    w1 = U[k - HX_R_Q1];
    for (j = 1; j <= HX_R_N1B; j++) {
        w1 += theta[HX_R_I_B1 + j - 1] * U[k - HX_R_Q1 - j];
    }
    for (i = 1; i <= HX_R_N1A; i++) {
        w1 -= theta[HX_R_I_A1 + i - 1] * W1[k - i];
    }
    W1[k] = w1;
    w1p = W1[k - 1];
    w2p = W2[k - 1];
    dw1 = w1 - w1p;
    hx_shape_terms(theta, w1p, hx_sgn(dw1), &A, &F, &G, &dF, &dG);
    W2[k] = w2p + A * (f0 * hx_sgn(w1p) + F - w2p) * fabs(dw1) + G * dw1;
    y = W2[k - HX_R_Q2];
    for (j = 1; j <= HX_R_N2B; j++) {
        y += theta[j - 1] * W2[k - HX_R_Q2 - j];
    }
    for (i = 1; i <= HX_R_N2A; i++) {
        y -= theta[HX_R_I_A2 + i - 1] * Y[k - i];
    }
    Y[k] = y;
}

/* kernels.step_sens_row at index k (= ks) of the windows, with theta (hx_step, then the
   sensitivities of the generalised block) */
static void hx_step_sens(hystid_rpem_state *s, const double *theta, int k)
{
    double *U = s->u, *W1 = s->w1, *W2 = s->w2, *Y = s->yh;
    double (*S1)[HX_R_NPAR] = s->s1, (*S2)[HX_R_NPAR] = s->s2, (*SY)[HX_R_NPAR] = s->sy;
#if HX_R_I_F0 >= 0
    const double f0 = theta[HX_R_I_F0];
#else
    const double f0 = 0.0;
#endif
    double w1p, w2p, dw1, s1, sd, absd, ddw1, sy;
    double A, F, G, dF, dG, E, dE, rate, pw;
    int i, j, p;
    /* step: eqs. (1), (7), (2) */
    hx_step(theta, U, W1, W2, Y, k);
    w1p = W1[k - 1];
    w2p = W2[k - 1];
    /* sensitivities */
    dw1 = W1[k] - w1p;
    for (p = 0; p < HX_R_NPAR; p++) {
        s1 = 0.0;
        for (i = 1; i <= HX_R_N1A; i++) {
            s1 -= theta[HX_R_I_A1 + i - 1] * S1[k - i][p];
        }
        S1[k][p] = s1;
    }
    for (j = 1; j <= HX_R_N1B; j++) {
        S1[k][HX_R_I_B1 + j - 1] += U[k - HX_R_Q1 - j];
    }
    for (i = 1; i <= HX_R_N1A; i++) {
        S1[k][HX_R_I_A1 + i - 1] -= W1[k - i];
    }
    /* kernels._shape_sens: E = f0 sgn(w1p) + F - w2p, dE its derivative along p */
    sd = hx_sgn(dw1);
    absd = fabs(dw1);
    hx_shape_terms(theta, w1p, sd, &A, &F, &G, &dF, &dG);
    E = f0 * hx_sgn(w1p) + F - w2p;
    for (p = 0; p < HX_R_NPAR; p++) {
        ddw1 = S1[k][p] - S1[k - 1][p];
        dE = dF * S1[k - 1][p] - S2[k - 1][p];
        S2[k][p] = S2[k - 1][p] + A * (dE * absd + E * sd * ddw1) + G * ddw1
                   + dG * S1[k - 1][p] * dw1;
    }
#if HX_DIRECTIONAL
    rate = 1.0 + theta[HX_I_AD] * sd;
#else
    rate = 1.0;
#endif
    S2[k][HX_R_I_ALPHA] += rate * E * absd;
    S2[k][HX_R_I_F1] += A * w1p * absd;
#if HX_R_I_F0 >= 0
    S2[k][HX_R_I_F0] += A * hx_sgn(w1p) * absd;
#endif
    S2[k][HX_R_I_G0] += dw1;
    pw = w1p;
    for (j = 0; j < HX_NF; j++) { /* f2, f3 */
        pw *= w1p;
        S2[k][HX_I_F2 + j] += A * pw * absd;
    }
    pw = 1.0;
    for (j = 0; j < HX_NG; j++) { /* g1, g2 */
        pw *= w1p;
        S2[k][HX_I_G1 + j] += pw * dw1;
    }
#if HX_DIRECTIONAL
    S2[k][HX_I_AD] += theta[HX_R_I_ALPHA] * sd * E * absd;
    S2[k][HX_I_AD + 1] += sd * dw1;
#endif
    for (p = 0; p < HX_R_NPAR; p++) {
        sy = S2[k - HX_R_Q2][p];
        for (j = 1; j <= HX_R_N2B; j++) {
            sy += theta[j - 1] * S2[k - HX_R_Q2 - j][p];
        }
        for (i = 1; i <= HX_R_N2A; i++) {
            sy -= theta[HX_R_I_A2 + i - 1] * SY[k - i][p];
        }
        SY[k][p] = sy;
    }
    for (j = 1; j <= HX_R_N2B; j++) {
        SY[k][j - 1] += W2[k - HX_R_Q2 - j];
    }
    for (i = 1; i <= HX_R_N2A; i++) {
        SY[k][HX_R_I_A2 + i - 1] -= Y[k - i];
    }
}

"""

_ALPHA_CHECK = """    if (theta[HX_R_I_ALPHA] <= 0.0) {
        return 0;
    }
"""


def _generalised(text: str) -> str:
    """:data:`RPEM_STEP` for the generalised Duhem block: its step and sensitivities
    (:data:`_SHAPE_STEP_SENS`) and, with directions, the admissible set's ``|ad| < 1``."""
    start = text.index("/* kernels.step at index k")
    end = text.index("/* _resync")
    assert text.count(_ALPHA_CHECK) == 1
    text = text[:start] + _SHAPE_STEP_SENS + text[end:]
    return text.replace(_ALPHA_CHECK, _ALPHA_CHECK + """#if HX_DIRECTIONAL
    if (!(fabs(theta[HX_I_AD]) < 1.0)) {
        return 0; /* the rates alpha (1 +- ad) must stay positive */
    }
#endif
""")


#: The on-line identifier's step for the generalised Duhem block.
GDUHEM_RPEM_STEP = _generalised(RPEM_STEP)
