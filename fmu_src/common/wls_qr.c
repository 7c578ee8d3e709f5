/*
 * The factorisations of the active-set solver (see wls.c for the method): Householder QR
 * of the working set's active rows, the null-space basis Z, the minimum-norm least-squares
 * step on the face (QR with column pivoting and a complete orthogonal decomposition for a
 * rank-deficient A_F Z), and the decomposition of a vector on the working set (multipliers).
 */
#include "wls_internal.h"

#define LDZ FP_WLS_NV1      /* leading dimension of qm and z (column-major) */
#define LDA FP_WLS_MAX_ROWS /* leading dimension of az (column-major) */

/* ------------------------------------------------------------------------ */
/* Householder helpers.  A reflector is H = I - tau v v' with v[0] = 1 implicit
 * and v[1..len-1] stored in the vector's tail. */

/* Turn x[0..len-1] into beta e1: x[0] = beta, x[1..] = v tail. */
static void house_make(double *x, int len, double *tau) {
    double xn = len > 1 ? vnorm(x + 1, len - 1) : 0.0;
    double alpha = x[0], beta, scale;
    int i;
    if (xn == 0.0) {
        *tau = 0.0;
        return;
    }
    beta = sqrt(alpha * alpha + xn * xn);
    if (alpha >= 0.0) beta = -beta;
    *tau = (beta - alpha) / beta;
    scale = 1.0 / (alpha - beta);
    for (i = 1; i < len; i++) x[i] *= scale;
    x[0] = beta;
}

/* y <- H y, with vt the stored tail of v (v[0] = 1). */
static void house_apply(const double *vt, int len, double tau, double *y) {
    double s;
    int i;
    if (tau == 0.0) return;
    s = y[0];
    for (i = 1; i < len; i++) s += vt[i - 1] * y[i];
    s *= tau;
    y[0] -= s;
    for (i = 1; i < len; i++) y[i] -= s * vt[i - 1];
}

#define QM(i, j) k->qm[(j) * LDZ + (i)]
#define ZM(i, j) k->z[(j) * LDZ + (i)]
#define AZ(i, j) k->az[(j) * LDA + (i)]

/* ------------------------------------------------------------------------ */
/* Working-set factorisation: QR of C_WF^T with dependent rows rejected.    */

void wls_factor_ws(Ctx *c) {
    FpWlsWork *k = c->k;
    int i, j, q, nf = 0, nw = 0;
    for (j = 0; j < c->nv; j++)
        if (k->state[j] == ST_FREE) k->free_idx[nf++] = j;
    for (i = 0; i < c->w->n_cons; i++) {
        double *col, cn, tail;
        if (!k->act[i]) continue;
        if (!k->use[i] || nw >= nf) {
            k->act[i] = 0;
            continue;
        }
        col = &QM(0, nw);
        for (q = 0; q < nf; q++) col[q] = cval(c, i, k->free_idx[q]);
        cn = vnorm(col, nf);
        for (q = 0; q < nw; q++) house_apply(&QM(q + 1, q), nf - q, k->tau_m[q], col + q);
        tail = vnorm(col + nw, nf - nw);
        if (!(tail > TOL_DEP * cn)) {
            k->act[i] = 0; /* dependent on the rows before it: not in the working set */
            continue;
        }
        house_make(col + nw, nf - nw, &k->tau_m[nw]);
        k->act_idx[nw++] = i;
    }
    c->nf = nf;
    c->nw = nw;
}

/* Null-space basis Z = Q[:, nw:nf] (only when nw > 0). */
static void build_z(Ctx *c) {
    FpWlsWork *k = c->k;
    int nf = c->nf, nw = c->nw, nz = nf - nw, col, q, i;
    for (col = 0; col < nz; col++) {
        double *zc = &ZM(0, col);
        for (i = 0; i < nf; i++) zc[i] = 0.0;
        zc[nw + col] = 1.0;
        for (q = nw - 1; q >= 0; q--) house_apply(&QM(q + 1, q), nf - q, k->tau_m[q], zc + q);
    }
}

/* ------------------------------------------------------------------------ */
/* Minimum-norm least squares  min ||AZ y - r||, AZ nr x nz (destroyed), r
 * destroyed.  Returns the rank. */

static int ls_minnorm(Ctx *c, int nr, int nz, double anorm, double *y) {
    FpWlsWork *k = c->k;
    int kmax = nr < nz ? nr : nz, kd = 0, kr, i, j, l;
    double *r = k->r, *u = k->u, r00;
    for (j = 0; j < nz; j++) k->perm[j] = j;
    for (i = 0; i < kmax; i++) {
        int piv = i;
        double best = -1.0;
        for (j = i; j < nz; j++) {
            double s = 0.0;
            for (l = i; l < nr; l++) s += AZ(l, j) * AZ(l, j);
            if (s > best) {
                best = s;
                piv = j;
            }
        }
        if (!(best > 0.0)) break;
        if (piv != i) {
            int t = k->perm[i];
            k->perm[i] = k->perm[piv];
            k->perm[piv] = t;
            for (l = 0; l < nr; l++) {
                double s = AZ(l, i);
                AZ(l, i) = AZ(l, piv);
                AZ(l, piv) = s;
            }
        }
        house_make(&AZ(i, i), nr - i, &k->tau_a[i]);
        for (j = i + 1; j < nz; j++) house_apply(&AZ(i + 1, i), nr - i, k->tau_a[i], &AZ(i, j));
        house_apply(&AZ(i + 1, i), nr - i, k->tau_a[i], r + i);
        kd = i + 1;
    }
    for (j = 0; j < nz; j++) y[j] = 0.0;
    if (kd == 0) return 0;
    /* rank cut-off relative to the largest column of A_F Z (which is
     * |R00| after pivoting) and to the norm of A (Z only rotates) */
    r00 = fabs(AZ(0, 0));
    if (anorm > r00) r00 = anorm;
    kr = 0;
    while (kr < kd && fabs(AZ(kr, kr)) > TOL_RANK * r00) kr++;
    if (kr == 0) return 0;
    /* Complete orthogonal decomposition: zero R12 with reflectors from the
     * right acting on columns {i, kr..nz-1}; R becomes [T 0]. */
    if (kr < nz) {
        int m2 = nz - kr;
        for (i = kr - 1; i >= 0; i--) {
            double tmp[NV1];
            tmp[0] = AZ(i, i);
            for (j = 0; j < m2; j++) tmp[1 + j] = AZ(i, kr + j);
            house_make(tmp, m2 + 1, &k->tau_c[i]);
            AZ(i, i) = tmp[0];
            for (j = 0; j < m2; j++) AZ(i, kr + j) = tmp[1 + j]; /* v tail kept in R12 */
            if (k->tau_c[i] != 0.0) {
                for (l = 0; l < i; l++) {
                    double s = AZ(l, i);
                    for (j = 0; j < m2; j++) s += tmp[1 + j] * AZ(l, kr + j);
                    s *= k->tau_c[i];
                    AZ(l, i) -= s;
                    for (j = 0; j < m2; j++) AZ(l, kr + j) -= s * tmp[1 + j];
                }
            }
        }
    }
    /* T w = (Q' r)[0:kr] */
    for (i = kr - 1; i >= 0; i--) {
        double s = r[i];
        for (j = i + 1; j < kr; j++) s -= AZ(i, j) * u[j];
        u[i] = s / AZ(i, i);
    }
    for (j = kr; j < nz; j++) u[j] = 0.0;
    if (kr < nz) {
        int m2 = nz - kr;
        for (i = 0; i < kr; i++) {
            double s;
            if (k->tau_c[i] == 0.0) continue;
            s = u[i];
            for (j = 0; j < m2; j++) s += AZ(i, kr + j) * u[kr + j];
            s *= k->tau_c[i];
            u[i] -= s;
            for (j = 0; j < m2; j++) u[kr + j] -= s * AZ(i, kr + j);
        }
    }
    for (j = 0; j < nz; j++) y[k->perm[j]] = u[j];
    return kr;
}

/* Step p (full length nv, zero on fixed variables) to the face minimiser.
 * Needs factor_ws (and uses the current x).  Returns 0 if not finite. */
int wls_compute_step(Ctx *c) {
    FpWlsWork *k = c->k;
    int nf = c->nf, nw = c->nw, nz = nf - nw, nr = nrows(c), i, j, q;
    double *y = k->v;
    for (j = 0; j < c->nv; j++) k->p[j] = 0.0;
    if (nz == 0) return 1;
    if (nw > 0) build_z(c);
    residual(c);
    /* AZ = A_F Z */
    for (j = 0; j < nz; j++) {
        for (i = 0; i < nr; i++) {
            double s = 0.0;
            if (c->ph1) {
                for (q = 0; q < nf; q++)
                    if (k->free_idx[q] == c->n) s = nw > 0 ? ZM(q, j) : (q == j ? 1.0 : 0.0);
            } else if (nw > 0) {
                const double *a = c->w->A + i * c->n;
                for (q = 0; q < nf; q++) s += a[k->free_idx[q]] * ZM(q, j);
            } else {
                s = c->w->A[i * c->n + k->free_idx[j]];
            }
            AZ(i, j) = s;
        }
    }
    ls_minnorm(c, nr, nz, c->ph1 ? 1.0 : c->anorm, y);
    if (nw > 0) {
        for (q = 0; q < nf; q++) {
            double s = 0.0;
            for (j = 0; j < nz; j++) s += ZM(q, j) * y[j];
            k->p[k->free_idx[q]] = s;
        }
    } else {
        for (q = 0; q < nf; q++) k->p[k->free_idx[q]] = y[q];
    }
    for (j = 0; j < c->nv; j++)
        if (!isfinite(k->p[j])) return 0;
    return 1;
}

/* Decompose v (length nv) on the working set (needs factor_ws):
 *     v = sum_q rr[q] c_{act_idx[q]} + sum_{j fixed} rb[j] n_j + z,
 * n_j = +e_j at an upper bound, -e_j at a lower one, z in the null space of
 * the working set (zero on fixed variables). */
void wls_decompose(Ctx *c, const double *v, double *z, double *rr, double *rb) {
    FpWlsWork *k = c->k;
    int nv = c->nv, nf = c->nf, nw = c->nw, i, j, q;
    double *qv = k->qv;
    for (q = 0; q < nf; q++) qv[q] = v[k->free_idx[q]];
    for (q = 0; q < nw; q++) house_apply(&QM(q + 1, q), nf - q, k->tau_m[q], qv + q);
    for (i = nw - 1; i >= 0; i--) {
        double s = qv[i];
        for (q = i + 1; q < nw; q++) s -= QM(i, q) * rr[q];
        rr[i] = s / QM(i, i);
    }
    for (j = 0; j < nv; j++) {
        double h;
        z[j] = 0.0;
        rb[j] = 0.0;
        if (k->state[j] != ST_LB && k->state[j] != ST_UB) continue;
        h = v[j];
        for (q = 0; q < nw; q++) h -= rr[q] * cval(c, k->act_idx[q], j);
        rb[j] = k->state[j] == ST_UB ? h : -h;
    }
    for (q = 0; q < nw; q++) qv[q] = 0.0;
    for (q = nw - 1; q >= 0; q--) house_apply(&QM(q + 1, q), nf - q, k->tau_m[q], qv + q);
    for (q = 0; q < nf; q++) z[k->free_idx[q]] = qv[q];
}

/* Move x (phase 2, warm start) onto the face of the working set: minimum-norm
 * correction so the active rows hold at equality.  Needs factor_ws. */
void wls_project_to_face(Ctx *c) {
    FpWlsWork *k = c->k;
    int nf = c->nf, nw = c->nw, i, q;
    double *e = k->u, *dl = k->v;
    if (nw == 0) return;
    for (q = 0; q < nw; q++) e[q] = dval(c, k->act_idx[q]) - crow_dot(c, k->act_idx[q], k->x);
    /* R' u = e (forward), then delta = Q [u; 0] */
    for (i = 0; i < nw; i++) {
        double s = e[i];
        for (q = 0; q < i; q++) s -= QM(q, i) * dl[q];
        dl[i] = s / QM(i, i);
    }
    for (i = nw; i < nf; i++) dl[i] = 0.0;
    for (q = nw - 1; q >= 0; q--) house_apply(&QM(q + 1, q), nf - q, k->tau_m[q], dl + q);
    for (q = 0; q < nf; q++) k->x[k->free_idx[q]] += dl[q];
}
