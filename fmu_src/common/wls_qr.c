/*
 * The factorisations of the active-set solver (see wls.c for the method): Householder QR
 * of the working set's active rows, the null-space basis Z, the minimum-norm least-squares
 * step on the face (QR with column pivoting and a complete orthogonal decomposition for a
 * rank-deficient A_F Z), and the decomposition of a vector on the working set (multipliers).
 */
#include "fp_math.h"
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

/* y_c <- H y_c for ncols columns y_c = y + c ld: house_apply on each, four columns at a time
 * with one accumulator each, so the four dot products run side by side instead of one
 * latency-bound chain after another (every column sums in the same order as house_apply:
 * the results are the same to the bit). */
static void house_apply_cols(const double *vt, int len, double tau, double *y, int ncols,
                             int ld) {
    int c = 0, i;
    if (tau == 0.0) return;
    for (; c + 4 <= ncols; c += 4) {
        double *y0 = y + c * ld, *y1 = y0 + ld, *y2 = y1 + ld, *y3 = y2 + ld;
        double s0 = y0[0], s1 = y1[0], s2 = y2[0], s3 = y3[0];
        for (i = 1; i < len; i++) {
            double v = vt[i - 1];
            s0 += v * y0[i];
            s1 += v * y1[i];
            s2 += v * y2[i];
            s3 += v * y3[i];
        }
        s0 *= tau, s1 *= tau, s2 *= tau, s3 *= tau;
        y0[0] -= s0, y1[0] -= s1, y2[0] -= s2, y3[0] -= s3;
        for (i = 1; i < len; i++) {
            double v = vt[i - 1];
            y0[i] -= s0 * v;
            y1[i] -= s1 * v;
            y2[i] -= s2 * v;
            y3[i] -= s3 * v;
        }
    }
    for (; c < ncols; c++) house_apply(vt, len, tau, y + c * ld);
}

/* Squared norms of rows [from, nr) of the columns [j0, j1) of a column-major matrix with
 * leading dimension ld, four columns at a time (each summed in row order). */
static void col_sq_norms(const double *a, int ld, int from, int nr, int j0, int j1,
                         double *out) {
    int j = j0, l;
    for (; j + 4 <= j1; j += 4) {
        const double *c0 = a + j * ld, *c1 = c0 + ld, *c2 = c1 + ld, *c3 = c2 + ld;
        double s0 = 0.0, s1 = 0.0, s2 = 0.0, s3 = 0.0;
        for (l = from; l < nr; l++) {
            s0 += c0[l] * c0[l];
            s1 += c1[l] * c1[l];
            s2 += c2[l] * c2[l];
            s3 += c3[l] * c3[l];
        }
        out[j] = s0, out[j + 1] = s1, out[j + 2] = s2, out[j + 3] = s3;
    }
    for (; j < j1; j++) {
        const double *c0 = a + j * ld;
        double s0 = 0.0;
        for (l = from; l < nr; l++) s0 += c0[l] * c0[l];
        out[j] = s0;
    }
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
        double best = -1.0, sq[NV1];
        col_sq_norms(k->az, LDA, i, nr, i, nz, sq);
        for (j = i; j < nz; j++) {
            if (sq[j] > best) {
                best = sq[j];
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
        house_apply_cols(&AZ(i + 1, i), nr - i, k->tau_a[i], &AZ(i, i + 1), nz - i - 1, LDA);
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

/* min ||AZ y - r|| for an AZ of full column rank (nr >= nz), as a face with active rows of C
 * has when A ends in a diagonal block: D_F Z has full rank (Z's columns orthonormal, every
 * d_j non-zero), so no column needs choosing or cutting and the QR goes without pivoting.
 * AZ and r destroyed.  Returns 0, y unset, when a diagonal of R is at the rank cut-off of
 * ls_minnorm anyway (rounding); the caller then rebuilds AZ and r and takes ls_minnorm. */
static int ls_full_rank(Ctx *c, int nr, int nz, double *y) {
    FpWlsWork *k = c->k;
    double *r = k->r, cut = c->anorm;
    int i, j;
    if (nz > nr) return 0;
    for (i = 0; i < nz; i++) {
        house_make(&AZ(i, i), nr - i, &k->tau_a[i]);
        house_apply_cols(&AZ(i + 1, i), nr - i, k->tau_a[i], &AZ(i, i + 1), nz - i - 1, LDA);
        house_apply(&AZ(i + 1, i), nr - i, k->tau_a[i], r + i);
        if (fabs(AZ(i, i)) > cut) cut = fabs(AZ(i, i));
    }
    cut *= TOL_RANK;
    for (i = nz - 1; i >= 0; i--) {
        double s = r[i];
        if (!(fabs(AZ(i, i)) > cut)) return 0;
        for (j = i + 1; j < nz; j++) s -= AZ(i, j) * y[j];
        y[i] = s / AZ(i, i);
    }
    return 1;
}

/* The primal form of the face step below (diag_tail_step), for an E too large for the dual
 * form: min ||A_F y - r|| with A_F = [M_F; D_F], M_F the m0 dense rows, D_F the free variables'
 * diagonal rows (the fixed variables' rows are constant over F).  Householder QR of
 * [D_F; M_F]: reflector q acts on D_F's row q and the m0 rows of M_F only (D_F's other rows
 * are zero in column q and stay so), so it costs O(nf^2 m0) instead of O(nf^2 nr), and
 * A_F has full rank (|R_qq| >= |d_q| > 0): no pivoting.  Returns 0 (the caller takes the
 * general path) when some |d_q| is at the general path's rank cut-off. */
static int diag_tail_primal(Ctx *c, double *y) {
    FpWlsWork *k = c->k;
    int nf = c->nf, n = c->n, m0 = c->m0, i, j, q;
    double *r = k->r, *rt = &AZ(0, nf), tmp[FP_WLS_MAX_ROWS + 1]; /* rt: column nf */
    for (q = 0; q < nf; q++) {
        int v = k->free_idx[q];
        double dq = tail_d(c, v);
        if (!(fabs(dq) > TOL_RANK * c->anorm)) return 0;
    }
    /* AZ rows 0..nf-1: D_F (R grows there), rows nf..nf+m0-1: M_F; rt likewise */
    for (j = 0; j < nf; j++) {
        int v = k->free_idx[j];
        double *col = &AZ(0, j);
        for (q = 0; q < nf; q++) col[q] = 0.0;
        col[j] = tail_d(c, v);
        for (i = 0; i < m0; i++) col[nf + i] = c->A[i * n + v];
        rt[j] = r[m0 + v];
    }
    for (i = 0; i < m0; i++) rt[nf + i] = r[i];
    for (q = 0; q < nf; q++) {
        double *cq = &AZ(0, q), *vt = cq + nf, tau;
        tmp[0] = cq[q];
        for (i = 0; i < m0; i++) tmp[1 + i] = vt[i];
        house_make(tmp, m0 + 1, &tau);
        cq[q] = tmp[0];
        for (i = 0; i < m0; i++) vt[i] = tmp[1 + i];
        if (tau == 0.0) continue;
        /* columns q+1..nf (nf: rt): y[q] and y[nf..] through H = I - tau v v', v = [1; vt] */
        j = q + 1;
        for (; j + 4 <= nf + 1; j += 4) {
            double *y0 = &AZ(0, j), *y1 = y0 + LDA, *y2 = y1 + LDA, *y3 = y2 + LDA;
            double s0 = y0[q], s1 = y1[q], s2 = y2[q], s3 = y3[q];
            for (i = 0; i < m0; i++) {
                double v = vt[i];
                s0 += v * y0[nf + i];
                s1 += v * y1[nf + i];
                s2 += v * y2[nf + i];
                s3 += v * y3[nf + i];
            }
            s0 *= tau, s1 *= tau, s2 *= tau, s3 *= tau;
            y0[q] -= s0, y1[q] -= s1, y2[q] -= s2, y3[q] -= s3;
            for (i = 0; i < m0; i++) {
                double v = vt[i];
                y0[nf + i] -= s0 * v;
                y1[nf + i] -= s1 * v;
                y2[nf + i] -= s2 * v;
                y3[nf + i] -= s3 * v;
            }
        }
        for (; j <= nf; j++) {
            double *yj = &AZ(0, j), s = yj[q];
            for (i = 0; i < m0; i++) s += vt[i] * yj[nf + i];
            s *= tau;
            yj[q] -= s;
            for (i = 0; i < m0; i++) yj[nf + i] -= s * vt[i];
        }
    }
    for (j = nf - 1; j >= 0; j--) { /* R y = (Q' r)[0:nf], by columns (no serial chain) */
        const double *rj = &AZ(0, j);
        double yj = rt[j] / rj[j];
        y[j] = yj;
        for (q = 0; q < j; q++) rt[q] -= rj[q] * yj;
    }
    return 1;
}

/* The face step when A ends in a diagonal block (Ctx.diag_tail) and no row of C is active:
 * min ||M_F y - r_M||^2 + ||D_F y - r_D||^2, M_F the m0 dense rows on the free variables,
 * D_F their diagonal rows (the fixed variables' rows are constant over F).  With z = D_F y
 * and E = M_F D_F^-1 the minimiser is z = r_D + E' lam, where lam = r_M - E z (the dense
 * rows' residual) solves
 *     (I + E E') lam = r_M - E r_D,
 * an m0 x m0 system (6 in the allocation, against up to 18 free variables) whose matrix is
 * >= I: positive definite whatever E is, every Cholesky pivot >= 1.  Its error: the
 * right-hand side is a difference of terms up to ||E|| ||r_D||, and z = r_D + E' lam
 * carries that rounding times ||E||, so z's relative error grows like eps ||E||^2 when the
 * dense rows are nearly met (the QR of [E'; I], used before, has the same order, the dual
 * problem's residual being z itself; its chain of reflectors made the control sample 2-6 %
 * slower in the closed loop).  The dual form is taken only for ||E||_F^2 <= DUAL_E2_MAX (the
 * allocation's ||E||_F^2 is ~2e5, the guidance's ~3e7), else diag_tail_primal.  Returns 1
 * (y set), 0 (the caller takes the general path) when some |d_q| is at the general path's
 * rank cut-off, -1 when E is too large (or rounding ate a pivot). */
static int diag_tail_dual(Ctx *c, double *y) {
    FpWlsWork *k = c->k;
    int nf = c->nf, n = c->n, m0 = c->m0, i, j, q;
    double *r = k->r, dinv[NV1], rd[NV1], lam[NV1], g[NV1 * NV1], e2 = 0.0;
    if (m0 + 1 > NV1) return -1; /* AZ holds NV1 columns */
    for (q = 0; q < nf; q++) {
        int v = k->free_idx[q];
        double dq = tail_d(c, v);
        if (!(fabs(dq) > TOL_RANK * c->anorm)) return 0;
        dinv[q] = 1.0 / dq;
        rd[q] = r[m0 + v];
    }
    /* AZ column i: row i of E (free variable q in row q) */
    for (i = 0; i < m0; i++) {
        const double *a = c->A + i * n;
        double *col = &AZ(0, i);
        for (q = 0; q < nf; q++) {
            col[q] = a[k->free_idx[q]] * dinv[q];
            e2 += col[q] * col[q];
        }
    }
    if (!(e2 <= DUAL_E2_MAX)) return -1;
    /* G = I + E E' (row-major, lower triangle) and lam's right-hand side r_M - E r_D, four
     * entries of a row side by side (independent sums, each element of row i read once) */
    for (i = 0; i < m0; i++) {
        const double *ei = &AZ(0, i);
        double s = r[i];
        for (j = 0; j + 4 <= i + 1; j += 4) {
            const double *e0 = &AZ(0, j), *e1 = e0 + LDA, *e2r = e1 + LDA, *e3 = e2r + LDA;
            double t0 = 0.0, t1 = 0.0, t2 = 0.0, t3 = 0.0;
            for (q = 0; q < nf; q++) {
                double x = ei[q];
                t0 += x * e0[q], t1 += x * e1[q], t2 += x * e2r[q], t3 += x * e3[q];
            }
            g[i * m0 + j] = t0, g[i * m0 + j + 1] = t1, g[i * m0 + j + 2] = t2;
            g[i * m0 + j + 3] = t3;
        }
        for (; j <= i; j++) {
            const double *ej = &AZ(0, j);
            double t = 0.0;
            for (q = 0; q < nf; q++) t += ei[q] * ej[q];
            g[i * m0 + j] = t;
        }
        g[i * m0 + i] += 1.0;
        for (q = 0; q < nf; q++) s -= ei[q] * rd[q];
        lam[i] = s;
    }
    /* Cholesky G = L L' (G >= I: every pivot >= 1 in exact arithmetic; one at or below 1/2
     * means rounding has eaten the identity: the primal form), then L L' lam = rhs */
    if (!fp_chol_factor(g, m0, 0.5)) return -1;
    fp_chol_backsolve(g, m0, lam);
    /* z = r_D + E' lam, y = D_F^-1 z */
    for (q = 0; q < nf; q++) {
        double s = rd[q];
        for (i = 0; i < m0; i++) s += AZ(q, i) * lam[i];
        y[q] = s * dinv[q];
    }
    return 1;
}

/* The face step when A ends in a diagonal block (Ctx.diag_tail) and no row of C is active,
 * in the dual form when E is small enough for it, else in the primal form.  Returns 0 (the
 * caller takes the general path) when some |d_q| is at the general path's rank cut-off. */
static int diag_tail_step(Ctx *c, double *y) {
    int rc = diag_tail_dual(c, y);
    return rc >= 0 ? rc : diag_tail_primal(c, y);
}

/* AZ = A_F Z when A ends in a diagonal block (Ctx.diag_tail): the dense rows as products,
 * the diagonal row of variable v only the one term d_v Z(q_v, :) where v is free (free
 * variable q_v), zero where it is fixed.  The same values as the general product, whose
 * other terms are zeros (0.0 + keeps its +0.0 for a zero term). */
static void az_diag_tail(Ctx *c, int nz) {
    FpWlsWork *k = c->k;
    int nf = c->nf, n = c->n, m0 = c->m0, i, j, q, pos[FP_WLS_MAX_VARS];
    for (i = 0; i < n; i++) pos[i] = -1;
    for (q = 0; q < nf; q++) pos[k->free_idx[q]] = q;
    for (j = 0; j < nz; j++) {
        for (i = 0; i < m0; i++) {
            const double *a = c->A + i * n;
            double s = 0.0;
            for (q = 0; q < nf; q++) s += a[k->free_idx[q]] * ZM(q, j);
            AZ(i, j) = s;
        }
        for (i = 0; i < n; i++)
            AZ(m0 + i, j) = pos[i] < 0 ? 0.0 : 0.0 + tail_d(c, i) * ZM(pos[i], j);
    }
}

/* Step p (full length nv, zero on fixed variables) to the face minimiser.
 * Needs factor_ws (and uses the current x).  Returns 0 if not finite. */
int wls_compute_step(Ctx *c) {
    FpWlsWork *k = c->k;
    int nf = c->nf, nw = c->nw, nz = nf - nw, nr = nrows(c), i, j, q;
    double *y = k->v;
    for (j = 0; j < c->nv; j++) k->p[j] = 0.0;
    if (nz == 0) return 1;
    if (!c->ph1 && nw == 0 && c->diag_tail) {
        residual(c);
        if (diag_tail_step(c, y)) {
            for (q = 0; q < nf; q++) k->p[k->free_idx[q]] = y[q];
            for (j = 0; j < c->nv; j++)
                if (!isfinite(k->p[j])) return 0;
            return 1;
        }
    }
    if (nw > 0) build_z(c);
    residual(c);
    /* AZ = A_F Z */
    if (!c->ph1 && nw > 0 && c->diag_tail) {
        az_diag_tail(c, nz);
        if (!ls_full_rank(c, nr, nz, y)) {
            residual(c); /* both destroyed by the attempt */
            az_diag_tail(c, nz);
            ls_minnorm(c, nr, nz, c->anorm, y);
        }
    } else {
        for (j = 0; j < nz; j++) {
            for (i = 0; i < nr; i++) {
                double s = 0.0;
                if (c->ph1) {
                    for (q = 0; q < nf; q++)
                        if (k->free_idx[q] == c->n) s = nw > 0 ? ZM(q, j) : (q == j ? 1.0 : 0.0);
                } else if (nw > 0) {
                    const double *a = c->A + i * c->n;
                    for (q = 0; q < nf; q++) s += a[k->free_idx[q]] * ZM(q, j);
                } else {
                    s = aval(c, i, k->free_idx[j]);
                }
                AZ(i, j) = s;
            }
        }
        ls_minnorm(c, nr, nz, c->ph1 ? 1.0 : c->anorm, y);
    }
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
