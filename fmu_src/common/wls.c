/*
 * Active-set solver for  min ||A x - b||^2  s.t.  lb <= x <= ub,  C x <= d.
 * See wls.h for the contract.  Outline:
 *
 * - Working set: fixed variables (at lb or ub) and active rows of C (held at
 *   equality).  Rows of C are scaled to unit norm internally, so multipliers
 *   of bounds and of rows are comparable.
 * - Each iteration factorises the working set from scratch (sizes are tiny):
 *   Householder QR of C_WF^T (active rows restricted to the free variables F)
 *   gives a null-space basis Z; the step p = Z y with y the minimum-norm
 *   minimiser of ||A_F Z y - r||, r = b - A x (QR with column pivoting plus a
 *   complete orthogonal decomposition when A_F Z is rank-deficient).
 * - Ratio test: a blocking bound or row is added to the working set; a full
 *   step reaches the minimiser on the current face, where the multipliers are
 *   computed from the same QR.  A negative one is dropped (the most
 *   negative; ties in the ratio test go to the fastest-approached
 *   constraint).  Against cycling at degenerate vertices: after STALL_BLAND
 *   iterations in a row that did not move x, Bland's smallest-index rule on
 *   both choices until x moves (terminates; used only then, as it is slow).
 *   Rows dependent on the working set are never added (blocking needs
 *   c'p > TOL_BLOCK ||p||) and are dropped when factorising.
 * - Phase 1 (when the start is not feasible): the projection of the start
 *   onto the feasible set, min ||x - x0||^2, by the dual method of Goldfarb
 *   and Idnani (no feasible start needed; identity Hessian).  It ends at a
 *   feasible point with a tight, independent working set, or proves the set
 *   infeasible; then a second phase 1, the primal iteration above on
 *   min t^2  s.t.  lb <= x <= ub,  C x - t <= d,  t >= 0, finds the point of
 *   least largest (row-normalised) violation, which is what x is then.
 * - Cold start: iteration 1 is the unconstrained least-squares minimiser
 *   (minimum-norm step from the previous x), projected as above.
 * - Warm start: the stored working set is factorised, x moved onto its face
 *   (minimum-norm correction of the active rows) and to the face minimiser;
 *   if that point is feasible and its multipliers are non-negative the solve
 *   ends after this one iteration, otherwise it continues from there (or from
 *   its projection if the point is infeasible).
 */
#include "wls.h"

#include <float.h>
#include <math.h>
#include <string.h>

#define NV1 FP_WLS_NV1
#define LDZ FP_WLS_NV1      /* leading dimension of qm and z (column-major) */
#define LDA FP_WLS_MAX_ROWS /* leading dimension of az (column-major) */

/* Variable states in the working set. */
#define ST_FREE 0
#define ST_LB (-1)
#define ST_UB 1
#define ST_EQ 2 /* lb == ub: fixed for good */

/* Tolerances (relative; see where they are used). */
#define TOL_DEP 1e-12      /* a row this close to the span of the others is dependent */
#define TOL_BLOCK 1e-11    /* a row blocks only if c'p > TOL_BLOCK ||p|| (c unit norm) */
#define TOL_BLOCK_B 1e-14  /* a bound blocks only if |p_j| > TOL_BLOCK_B ||p|| */
#define TOL_RANK 1e-12     /* rank cut-off of the pivoted QR of A_F Z */
#define TOL_TIE 1e-12      /* step lengths this close are ties */
#define TOL_STEP 1e-14     /* ||p|| below this (relative to ||x||) is no step */
#define TOL_MULT 1e-13     /* multipliers above -TOL_MULT * (gradient scale) are >= 0 */
#define TOL_FEAS 1e-11     /* feasibility, relative to max(1, |d|, |x|) */
#define TOL_GI 1e-10       /* projection phase: a normal this close to the span is dependent */

/* Magnitudes above this are bad input (their squares would overflow). */
#define BIG 1e150

/* Outcomes of the iteration loop. */
enum { RUN_OPTIMAL, RUN_CAP, RUN_FEASIBLE, RUN_INFEASIBLE, RUN_NUMERIC };

typedef struct {
    FpWls *w;
    FpWlsWork *k;
    int n;        /* variables of the problem */
    int nv;       /* variables iterated: n, or n + 1 in phase 1 (t last) */
    int ph1;      /* phase 1: objective t^2, rows of C get a -t term */
    int nf, nw;   /* free variables, accepted active rows */
    int stall;    /* consecutive iterations that did not move x */
    int bland;    /* stalled long enough: use smallest-index choices */
    double anorm; /* largest column norm of A (rank cut-off scale) */
    double tol_feas;
} Ctx;

/* ------------------------------------------------------------------------ */
/* Problem accessors (phase 1 and phase 2 share the loop).                  */

static double lbv(const Ctx *c, int j) { return j < c->n ? c->w->lb[j] : 0.0; }

static double ubv(const Ctx *c, int j) { return j < c->n ? c->w->ub[j] : INFINITY; }

/* Row i of the scaled C (with the -t column in phase 1). */
static double cval(const Ctx *c, int i, int j) {
    return j < c->n ? c->w->C[i * c->n + j] * c->k->cinv[i] : -1.0;
}

static double dval(const Ctx *c, int i) { return c->w->d[i] * c->k->cinv[i]; }

static double crow_dot(const Ctx *c, int i, const double *x) {
    double s = 0.0;
    int j;
    for (j = 0; j < c->nv; j++) s += cval(c, i, j) * x[j];
    return s;
}

static int nrows(const Ctx *c) { return c->ph1 ? 1 : c->w->n_rows; }

/* r = b - A x over the rows of the current objective. */
static void residual(Ctx *c) {
    FpWlsWork *k = c->k;
    int i, j, n = c->n;
    if (c->ph1) {
        k->r[0] = -k->x[n];
        return;
    }
    for (i = 0; i < c->w->n_rows; i++) {
        const double *a = c->w->A + i * n;
        double s = c->w->b[i];
        for (j = 0; j < n; j++) s -= a[j] * k->x[j];
        k->r[i] = s;
    }
}

/* ------------------------------------------------------------------------ */
/* Householder helpers.  A reflector is H = I - tau v v' with v[0] = 1 implicit
 * and v[1..len-1] stored in the vector's tail. */

static double vnorm(const double *x, int len) {
    double s = 0.0;
    int i;
    for (i = 0; i < len; i++) s += x[i] * x[i];
    return sqrt(s);
}

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

static void factor_ws(Ctx *c) {
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
static int compute_step(Ctx *c) {
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

static double inf_norm(const double *x, int len) {
    double m = 0.0;
    int i;
    for (i = 0; i < len; i++)
        if (fabs(x[i]) > m) m = fabs(x[i]);
    return m;
}

/* Clamp free variables into their bounds (removes rounding overshoot). */
static void clamp_free(Ctx *c) {
    FpWlsWork *k = c->k;
    int q;
    for (q = 0; q < c->nf; q++) {
        int j = k->free_idx[q];
        if (k->x[j] < lbv(c, j)) k->x[j] = lbv(c, j);
        if (k->x[j] > ubv(c, j)) k->x[j] = ubv(c, j);
    }
}

/* Ratio test along p and the step; adds the blocking bound or row.
 * Returns 1 if a constraint was added, 0 for a full step.  *moved tells
 * whether x changed noticeably. */
static int ratio_step(Ctx *c, int *moved) {
    FpWlsWork *k = c->k;
    int q, i, blk = -1, nv = c->nv;
    double pn = vnorm(k->p, nv), amin = 1.0, alpha_blk = 2.0, rate_blk = 0.0;
    double xinf = inf_norm(k->x, nv), pinf = inf_norm(k->p, nv);
    /* ties are judged as distances along the step: with a huge face step (an
     * ill-conditioned face) a fixed 1e-12 in step fraction is O(1) in x, and snapping
     * x onto the tied constraint's bound would leave another one violated */
    double tie = (pinf > 0.0 && c->tol_feas / pinf < TOL_TIE) ? c->tol_feas / pinf : TOL_TIE;
    /* candidates: global index j < nv for bounds, nv + i for rows */
    for (q = 0; q < c->nf; q++) {
        int j = k->free_idx[q];
        double pj = k->p[j], s, ratio, rate;
        if (pj > TOL_BLOCK_B * pn && isfinite(ubv(c, j))) {
            s = ubv(c, j) - k->x[j];
            rate = pj / pn;
            ratio = (s > 0.0 ? s : 0.0) / pj;
        } else if (pj < -TOL_BLOCK_B * pn && isfinite(lbv(c, j))) {
            s = k->x[j] - lbv(c, j);
            rate = -pj / pn;
            ratio = (s > 0.0 ? s : 0.0) / -pj;
        } else {
            continue;
        }
        if (ratio < amin) amin = ratio;
        if (ratio < alpha_blk - tie ||
            (ratio <= alpha_blk + tie && !c->bland && rate > rate_blk)) {
            if (ratio < 1.0 || (blk >= 0 && ratio <= 1.0)) {
                blk = j;
                alpha_blk = ratio;
                rate_blk = rate;
            }
        }
    }
    for (i = 0; i < c->w->n_cons; i++) {
        double cp = 0.0, s, ratio, rate;
        if (!k->use[i] || k->act[i]) continue;
        for (q = 0; q < c->nf; q++) cp += cval(c, i, k->free_idx[q]) * k->p[k->free_idx[q]];
        if (!(cp > TOL_BLOCK * pn)) continue;
        s = dval(c, i) - crow_dot(c, i, k->x);
        rate = cp / pn;
        ratio = (s > 0.0 ? s : 0.0) / cp;
        if (ratio < amin) amin = ratio;
        if (ratio < alpha_blk - tie ||
            (ratio <= alpha_blk + tie && !c->bland && rate > rate_blk)) {
            if (ratio < 1.0 || (blk >= 0 && ratio <= 1.0)) {
                blk = nv + i;
                alpha_blk = ratio;
                rate_blk = rate;
            }
        }
    }
    if (blk < 0) amin = 1.0;
    for (q = 0; q < c->nf; q++) {
        int j = k->free_idx[q];
        k->x[j] += amin * k->p[j];
    }
    *moved = amin * inf_norm(k->p, nv) > TOL_STEP * (xinf > 1.0 ? xinf : 1.0);
    if (blk < 0) {
        clamp_free(c);
        return 0;
    }
    if (blk < nv) {
        int up = k->p[blk] > 0.0;
        k->x[blk] = up ? ubv(c, blk) : lbv(c, blk);
        k->state[blk] = (int8_t)(up ? ST_UB : ST_LB);
    } else {
        k->act[blk - nv] = 1;
    }
    clamp_free(c);
    return 1;
}

/* Decompose v (length nv) on the working set (needs factor_ws):
 *     v = sum_q rr[q] c_{act_idx[q]} + sum_{j fixed} rb[j] n_j + z,
 * n_j = +e_j at an upper bound, -e_j at a lower one, z in the null space of
 * the working set (zero on fixed variables). */
static void decompose(Ctx *c, const double *v, double *z, double *rr, double *rb) {
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

/* Multipliers at the face minimiser (needs factor_ws for the current set).
 * Returns the global index of the constraint to drop, or -1 if none. */
static int pick_drop(Ctx *c) {
    FpWlsWork *k = c->k;
    int nv = c->nv, nw = c->nw, nr = nrows(c), i, j, q, drop = -1;
    double *lam = k->rr, *mu = k->rb, worst, tol, xn = vnorm(k->x, nv), gs = 0.0;
    /* gradient g = -2 A' r, and the scale of its rounding error:
     * 2 sum_i ||a_i|| (|r_i| + |b_i| + ||a_i|| ||x||) */
    residual(c);
    if (c->ph1) {
        for (j = 0; j < nv; j++) k->g[j] = j == c->n ? -2.0 * k->r[0] : 0.0;
        gs = 2.0 * (fabs(k->r[0]) + xn);
    } else {
        for (j = 0; j < nv; j++) k->g[j] = 0.0;
        for (i = 0; i < nr; i++) {
            const double *a = c->w->A + i * c->n;
            double ri = -2.0 * k->r[i], an = vnorm(a, nv);
            for (j = 0; j < nv; j++) k->g[j] += a[j] * ri;
            gs += 2.0 * an * (fabs(k->r[i]) + fabs(c->w->b[i]) + an * xn);
        }
    }
    tol = TOL_MULT * gs;
    if (!(tol > DBL_MIN)) tol = DBL_MIN;
    /* stationarity: -g = sum lam c + sum mu n (+ z = 0 at the face minimiser) */
    for (j = 0; j < nv; j++) k->nvec[j] = -k->g[j];
    decompose(c, k->nvec, k->zvec, lam, mu);
    worst = -tol;
    for (j = 0; j < nv; j++) {
        if (k->state[j] != ST_LB && k->state[j] != ST_UB) continue;
        if (c->bland) {
            if (mu[j] < -tol) return j;
        } else if (mu[j] < worst) {
            worst = mu[j];
            drop = j;
        }
    }
    for (q = 0; q < nw; q++) {
        if (c->bland) {
            if (lam[q] < -tol) return nv + k->act_idx[q];
        } else if (lam[q] < worst) {
            worst = lam[q];
            drop = nv + k->act_idx[q];
        }
    }
    return drop;
}

static void drop_constraint(Ctx *c, int idx) {
    if (idx < c->nv)
        c->k->state[idx] = ST_FREE;
    else
        c->k->act[idx - c->nv] = 0;
}

/* Anti-cycling: after STALL_BLAND iterations in a row that did not move x
 * (a degenerate vertex), choose by smallest index (Bland) until x moves. */
#define STALL_BLAND 50
static void stalled(Ctx *c, int moved) {
    c->stall = moved ? 0 : c->stall + 1;
    c->bland = c->stall >= STALL_BLAND;
}

/* The active-set loop from a feasible point with a consistent working set. */
static int run(Ctx *c, int max_iter, int *iter) {
    FpWlsWork *k = c->k;
    for (;;) {
        int moved = 0, drop;
        if (c->ph1 && k->x[c->n] <= c->tol_feas) return RUN_FEASIBLE;
        if (*iter >= max_iter) return RUN_CAP;
        ++*iter;
        factor_ws(c);
        if (!compute_step(c)) return RUN_NUMERIC;
        if (inf_norm(k->p, c->nv) > TOL_STEP * (inf_norm(k->x, c->nv) + DBL_MIN)) {
            if (ratio_step(c, &moved)) {
                stalled(c, moved);
                continue;
            }
            if (c->ph1 && k->x[c->n] <= c->tol_feas) return RUN_FEASIBLE;
        }
        drop = pick_drop(c);
        if (drop < 0) return RUN_OPTIMAL;
        drop_constraint(c, drop);
        stalled(c, moved);
    }
}

/* ------------------------------------------------------------------------ */
/* Driver.                                                                  */

static int big(double v) { return !(fabs(v) <= BIG); } /* also NaN */

static int data_ok(const FpWls *w) {
    int i, n = w->n_vars;
    for (i = 0; i < w->n_rows * n; i++)
        if (big(w->A[i])) return 0;
    for (i = 0; i < w->n_rows; i++)
        if (big(w->b[i])) return 0;
    for (i = 0; i < n; i++) {
        if (w->lb[i] != -INFINITY && big(w->lb[i])) return 0;
        if (w->ub[i] != INFINITY && big(w->ub[i])) return 0;
    }
    for (i = 0; i < w->n_cons * n; i++)
        if (big(w->C[i])) return 0;
    for (i = 0; i < w->n_cons; i++)
        if (w->d[i] != INFINITY && big(w->d[i])) return 0;
    return 1;
}

static double max_violation(const FpWls *w, const double *x) {
    double v = 0.0;
    int i, j, n = w->n_vars;
    for (j = 0; j < n; j++) {
        if (w->lb[j] - x[j] > v) v = w->lb[j] - x[j];
        if (x[j] - w->ub[j] > v) v = x[j] - w->ub[j];
    }
    for (i = 0; i < w->n_cons; i++) {
        double s = -w->d[i];
        if (!isfinite(w->d[i])) continue;
        for (j = 0; j < n; j++) s += w->C[i * n + j] * x[j];
        if (s > v) v = s;
    }
    return v;
}

static double objective(const FpWls *w, const double *x) {
    double f = 0.0;
    int i, j, n = w->n_vars;
    for (i = 0; i < w->n_rows; i++) {
        double s = -w->b[i];
        for (j = 0; j < n; j++) s += w->A[i * n + j] * x[j];
        f += s * s;
    }
    return f;
}

/* Largest scaled violation of the usable rows at k->x (phase-2 view); *arg = row. */
static double row_violation(Ctx *c, int *arg) {
    FpWlsWork *k = c->k;
    double v = -INFINITY;
    int i;
    *arg = -1;
    for (i = 0; i < c->w->n_cons; i++) {
        double s;
        if (!k->use[i]) continue;
        s = crow_dot(c, i, k->x) - dval(c, i);
        if (s > v) {
            v = s;
            *arg = i;
        }
    }
    return v;
}

/* Move x (phase 2, warm start) onto the face of the working set: minimum-norm
 * correction so the active rows hold at equality.  Needs factor_ws. */
static void project_to_face(Ctx *c) {
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

static void write_back(FpWls *w, const FpWlsWork *k) {
    int j, i;
    for (j = 0; j < w->n_vars; j++) {
        int8_t s = k->state[j];
        w->bound_ws[j] = (int8_t)(s == ST_UB ? 1 : (s == ST_FREE ? 0 : -1));
    }
    for (i = 0; i < w->n_cons; i++) w->cons_ws[i] = k->act[i];
}

static FpStatus finish(FpWls *w, FpWlsStatus st, int iter, int it1, int warm, FpWlsResult *out) {
    if (out != NULL) {
        out->status = st;
        out->iterations = iter;
        out->phase1_iterations = it1;
        out->warm_start = warm;
        out->objective = st == FP_WLS_BAD_INPUT ? 0.0 : objective(w, w->x);
        out->max_violation = st == FP_WLS_BAD_INPUT ? 0.0 : max_violation(w, w->x);
        if (!isfinite(out->objective)) out->objective = DBL_MAX;
        if (!isfinite(out->max_violation)) out->max_violation = DBL_MAX;
    }
    if (st == FP_WLS_OPTIMAL) return FP_OK;
    if (st == FP_WLS_BAD_INPUT) return FP_ERROR;
    return FP_WARNING;
}

FpStatus fp_wls_setup(FpWls *w, int n_vars, int n_rows, int n_cons) {
    int j;
    if (w == NULL || n_vars < 1 || n_vars > FP_WLS_MAX_VARS || n_rows < 0 ||
        n_rows > FP_WLS_MAX_ROWS || n_cons < 0 || n_cons > FP_WLS_MAX_CONS)
        return FP_ERROR;
    memset(w, 0, sizeof *w);
    w->n_vars = n_vars;
    w->n_rows = n_rows;
    w->n_cons = n_cons;
    for (j = 0; j < FP_WLS_MAX_VARS; j++) {
        w->lb[j] = -INFINITY;
        w->ub[j] = INFINITY;
    }
    return FP_OK;
}

FpStatus fp_wls_set_data(FpWls *w, const double *A, const double *b, const double *lb,
                         const double *ub, const double *C, const double *d) {
    size_t n, m, p;
    if (w == NULL || w->n_vars < 1 || w->n_vars > FP_WLS_MAX_VARS || w->n_rows < 0 ||
        w->n_rows > FP_WLS_MAX_ROWS || w->n_cons < 0 || w->n_cons > FP_WLS_MAX_CONS)
        return FP_ERROR;
    n = (size_t)w->n_vars;
    m = (size_t)w->n_rows;
    p = (size_t)w->n_cons;
    if (A != NULL && m > 0) memcpy(w->A, A, m * n * sizeof(double));
    if (b != NULL && m > 0) memcpy(w->b, b, m * sizeof(double));
    if (lb != NULL) memcpy(w->lb, lb, n * sizeof(double));
    if (ub != NULL) memcpy(w->ub, ub, n * sizeof(double));
    if (C != NULL && p > 0) memcpy(w->C, C, p * n * sizeof(double));
    if (d != NULL && p > 0) memcpy(w->d, d, p * sizeof(double));
    return FP_OK;
}

void fp_wls_reset(FpWls *w) {
    if (w == NULL) return;
    memset(w->bound_ws, 0, sizeof w->bound_ws);
    memset(w->cons_ws, 0, sizeof w->cons_ws);
}

const char *fp_wls_status_name(int status) {
    switch (status) {
    case FP_WLS_OPTIMAL: return "optimal";
    case FP_WLS_MAX_ITER: return "max_iter";
    case FP_WLS_INFEASIBLE: return "infeasible";
    case FP_WLS_BAD_INPUT: return "bad_input";
    default: return "unknown";
    }
}

/* Minimax phase 1 from k->x (within the bounds, k->state consistent with it)
 * with largest scaled violation t0 > tol_feas at row arg. */
static int phase1_minimax(Ctx *c, double t0, int arg, int max_iter, int *iter) {
    FpWlsWork *k = c->k;
    int rc, i, n = c->n;
    c->ph1 = 1;
    c->nv = n + 1;
    c->bland = 0;
    c->stall = 0;
    k->x[n] = t0;
    k->state[n] = ST_FREE;
    for (i = 0; i < c->w->n_cons; i++) k->act[i] = 0;
    if (arg >= 0) k->act[arg] = 1;
    rc = run(c, max_iter, iter);
    c->ph1 = 0;
    c->nv = n;
    c->bland = 0;
    c->stall = 0;
    if (rc == RUN_OPTIMAL) rc = k->x[n] <= c->tol_feas ? RUN_FEASIBLE : RUN_INFEASIBLE;
    return rc;
}

/* Phase 1 proper: project the start x0 = k->x (within the bounds, every
 * variable free except lb == ub) onto the feasible set, min ||x - x0||^2, by
 * the dual method of Goldfarb and Idnani (identity Hessian, so J = Q).  It
 * needs no feasible start, adds the most violated constraint at a time and
 * ends at a feasible point whose working set is tight and independent, or
 * with a proof of infeasibility (a violated constraint whose normal is a
 * non-positive combination of the active ones). */
static int phase1_project(Ctx *c, int max_iter, int *iter) {
    FpWlsWork *k = c->k;
    FpWls *w = c->w;
    int n = c->n, i, j, q;
    for (j = 0; j < NV1; j++) k->mub[j] = 0.0;
    for (i = 0; i < w->n_cons; i++) k->mur[i] = 0.0;
    for (;;) {
        int pidx = -1, psign = 0;
        double pv = c->tol_feas, up = 0.0;
        for (j = 0; j < n; j++) {
            if (k->state[j] != ST_FREE) continue;
            if (w->lb[j] - k->x[j] > pv) {
                pv = w->lb[j] - k->x[j];
                pidx = j;
                psign = -1;
            } else if (k->x[j] - w->ub[j] > pv) {
                pv = k->x[j] - w->ub[j];
                pidx = j;
                psign = 1;
            }
        }
        for (i = 0; i < w->n_cons; i++) {
            double v;
            if (!k->use[i] || k->act[i]) continue;
            v = crow_dot(c, i, k->x) - dval(c, i);
            if (v > pv) {
                pv = v;
                pidx = n + i;
            }
        }
        if (pidx < 0) return RUN_FEASIBLE;
        for (;;) {
            double *nv = k->nvec, *z = k->zvec, *rr = k->rr, *rb = k->rb;
            double viol, zz = 0.0, nn = 0.0, tau1, tau2 = INFINITY, tau;
            int l = -1;
            if (*iter >= max_iter) return RUN_CAP;
            ++*iter;
            factor_ws(c);
            for (j = 0; j < n; j++) nv[j] = 0.0;
            if (pidx < n) {
                nv[pidx] = (double)psign;
                viol = psign > 0 ? k->x[pidx] - w->ub[pidx] : w->lb[pidx] - k->x[pidx];
            } else {
                for (j = 0; j < n; j++) nv[j] = cval(c, pidx - n, j);
                viol = crow_dot(c, pidx - n, k->x) - dval(c, pidx - n);
            }
            if (viol <= c->tol_feas) break; /* satisfied on the way */
            decompose(c, nv, z, rr, rb);
            for (q = 0; q < c->nf; q++) {
                j = k->free_idx[q];
                zz += nv[j] * z[j];
                nn += nv[j] * nv[j];
            }
            tau1 = sqrt(fabs(zz)) > TOL_GI * sqrt(nn) ? viol / zz : INFINITY;
            for (j = 0; j < n; j++) {
                double ratio;
                if ((k->state[j] != ST_LB && k->state[j] != ST_UB) || !(rb[j] > TOL_GI)) continue;
                ratio = k->mub[j] / rb[j];
                if (ratio < tau2) {
                    tau2 = ratio;
                    l = j;
                }
            }
            for (q = 0; q < c->nw; q++) {
                double ratio;
                if (!(rr[q] > TOL_GI)) continue;
                ratio = k->mur[k->act_idx[q]] / rr[q];
                if (ratio < tau2) {
                    tau2 = ratio;
                    l = n + k->act_idx[q];
                }
            }
            if (tau1 == INFINITY && tau2 == INFINITY) return RUN_INFEASIBLE;
            tau = tau1 <= tau2 ? tau1 : tau2;
            for (q = 0; q < c->nf; q++) {
                j = k->free_idx[q];
                k->x[j] -= tau * z[j];
            }
            for (j = 0; j < n; j++) {
                if (k->state[j] != ST_LB && k->state[j] != ST_UB) continue;
                k->mub[j] -= tau * rb[j];
                if (k->mub[j] < 0.0) k->mub[j] = 0.0;
            }
            for (q = 0; q < c->nw; q++) {
                double *m = &k->mur[k->act_idx[q]];
                *m -= tau * rr[q];
                if (*m < 0.0) *m = 0.0;
            }
            up += tau;
            if (tau1 <= tau2) {
                if (pidx < n) {
                    k->state[pidx] = (int8_t)(psign > 0 ? ST_UB : ST_LB);
                    k->x[pidx] = psign > 0 ? w->ub[pidx] : w->lb[pidx];
                    k->mub[pidx] = up;
                } else {
                    k->act[pidx - n] = 1;
                    k->mur[pidx - n] = up;
                }
                break;
            }
            if (l < n) {
                k->state[l] = ST_FREE;
                k->mub[l] = 0.0;
            } else {
                k->act[l - n] = 0;
                k->mur[l - n] = 0.0;
            }
        }
    }
}

/* Clamp the non-fixed variables of k->x into the bounds; with fix != 0 the
 * variables on a bound join the working set, otherwise all are freed. */
static void clamp_start(Ctx *c, int fix) {
    FpWlsWork *k = c->k;
    FpWls *w = c->w;
    int j;
    for (j = 0; j < c->n; j++) {
        if (k->state[j] == ST_EQ) continue;
        k->state[j] = ST_FREE;
        if (k->x[j] <= w->lb[j]) {
            k->x[j] = w->lb[j];
            if (fix) k->state[j] = ST_LB;
        } else if (k->x[j] >= w->ub[j]) {
            k->x[j] = w->ub[j];
            if (fix) k->state[j] = ST_UB;
        }
    }
}

/* From any k->x: a feasible point with a consistent working set
 * (RUN_FEASIBLE), RUN_INFEASIBLE (x: minimax point, or the best found within
 * the cap), RUN_CAP (x: phase-1 iterate clamped into the bounds) or
 * RUN_NUMERIC. */
static int find_feasible(Ctx *c, int max_iter, int *iter) {
    FpWlsWork *k = c->k;
    int i, rc, arg;
    double viol;
    for (i = 0; i < c->w->n_cons; i++) k->act[i] = 0;
    clamp_start(c, 1);
    viol = row_violation(c, &arg);
    if (viol <= c->tol_feas) return RUN_FEASIBLE;
    clamp_start(c, 0);
    rc = phase1_project(c, max_iter, iter);
    if (rc == RUN_CAP) clamp_start(c, 0);
    if (rc != RUN_INFEASIBLE) return rc;
    /* Infeasible: the point of least largest violation, within the bounds. */
    for (i = 0; i < c->w->n_cons; i++) k->act[i] = 0;
    clamp_start(c, 1);
    viol = row_violation(c, &arg);
    if (viol <= c->tol_feas) return RUN_FEASIBLE;
    rc = phase1_minimax(c, viol, arg, max_iter, iter);
    if (rc == RUN_FEASIBLE || rc == RUN_NUMERIC) return rc;
    return RUN_INFEASIBLE;
}

FpStatus fp_wls_solve(FpWls *w, int max_iter, FpWlsResult *out) {
    FpWlsWork *k;
    Ctx ctx, *c = &ctx;
    int n, i, j, iter = 0, it1 = 0, warm = 0, crossed = 0, zero_row_infeasible = 0, rc;
    double fscale;

    if (w == NULL) return FP_ERROR;
    if (w->n_vars < 1 || w->n_vars > FP_WLS_MAX_VARS || w->n_rows < 0 ||
        w->n_rows > FP_WLS_MAX_ROWS || w->n_cons < 0 || w->n_cons > FP_WLS_MAX_CONS) {
        if (out != NULL) memset(out, 0, sizeof *out);
        if (out != NULL) out->status = FP_WLS_BAD_INPUT;
        return FP_ERROR;
    }
    n = w->n_vars;
    k = &w->work;
    for (j = 0; j < n; j++)
        if (!isfinite(w->x[j])) w->x[j] = 0.0;
    if (max_iter < 1 || !data_ok(w)) return finish(w, FP_WLS_BAD_INPUT, 0, 0, 0, out);

    for (j = 0; j < n; j++)
        if (w->lb[j] > w->ub[j]) crossed = 1;
    if (crossed) {
        for (j = 0; j < n; j++) {
            double lo = fmin(w->lb[j], w->ub[j]), hi = fmax(w->lb[j], w->ub[j]);
            w->x[j] = fmin(fmax(w->x[j], lo), hi);
        }
        return finish(w, FP_WLS_INFEASIBLE, 0, 0, 0, out);
    }

    memset(c, 0, sizeof *c);
    c->w = w;
    c->k = k;
    c->n = n;
    c->nv = n;
    for (j = 0; j < n; j++) {
        double s = 0.0;
        for (i = 0; i < w->n_rows; i++) s += w->A[i * n + j] * w->A[i * n + j];
        if (s > c->anorm) c->anorm = s;
    }
    c->anorm = sqrt(c->anorm);
    fscale = 1.0;
    for (i = 0; i < w->n_cons; i++) {
        double cn = vnorm(w->C + i * n, n);
        k->use[i] = 0;
        k->cinv[i] = 0.0;
        if (w->d[i] == INFINITY) continue;
        if (cn == 0.0 || !(1.0 / cn < INFINITY)) {
            if (w->d[i] < 0.0) zero_row_infeasible = 1;
            continue;
        }
        k->use[i] = 1;
        k->cinv[i] = 1.0 / cn;
        if (fabs(w->d[i]) / cn > fscale) fscale = fabs(w->d[i]) / cn;
    }

    /* Working set from the caller (sanitised) and start point. */
    for (j = 0; j < n; j++) {
        int8_t s = ST_FREE;
        k->x[j] = w->x[j];
        if (w->lb[j] == w->ub[j])
            s = ST_EQ;
        else if (w->bound_ws[j] < 0 && isfinite(w->lb[j]))
            s = ST_LB;
        else if (w->bound_ws[j] > 0 && isfinite(w->ub[j]))
            s = ST_UB;
        if (s == ST_LB || s == ST_UB) warm = 1;
        if (s == ST_EQ || s == ST_LB) k->x[j] = w->lb[j];
        if (s == ST_UB) k->x[j] = w->ub[j];
        k->state[j] = s;
    }
    for (i = 0; i < w->n_cons; i++) {
        k->act[i] = (int8_t)(w->cons_ws[i] && k->use[i]);
        if (k->act[i]) warm = 1;
    }
    {
        double xi = inf_norm(k->x, n);
        if (xi > fscale) fscale = xi;
    }
    c->tol_feas = TOL_FEAS * fscale;

    /* Iteration 1: the minimiser on the face of the stored working set (for
     * an empty one, i.e. a cold start: the unconstrained least-squares
     * minimiser, minimum-norm step from the previous x). */
    iter = 1;
    factor_ws(c);
    project_to_face(c);
    if (!compute_step(c)) {
        rc = RUN_NUMERIC;
    } else {
        int feasible = 1;
        for (j = 0; j < n; j++) k->x[j] += k->p[j];
        for (j = 0; j < n && feasible; j++) {
            if (k->state[j] != ST_FREE) continue;
            if (k->x[j] < w->lb[j] - c->tol_feas || k->x[j] > w->ub[j] + c->tol_feas) feasible = 0;
        }
        for (i = 0; i < w->n_cons && feasible; i++)
            if (k->use[i] && !k->act[i] && crow_dot(c, i, k->x) - dval(c, i) > c->tol_feas)
                feasible = 0;
        if (feasible) {
            /* early exit if the multipliers say so, else continue from here */
            int drop;
            clamp_free(c);
            drop = pick_drop(c);
            if (drop < 0) {
                rc = RUN_OPTIMAL;
            } else {
                drop_constraint(c, drop);
                rc = run(c, max_iter, &iter);
            }
        } else {
            /* phase 1 from this point, then phase 2 */
            rc = find_feasible(c, max_iter, &iter);
            it1 = iter - 1;
            if (rc == RUN_FEASIBLE) rc = run(c, max_iter, &iter);
        }
    }

    /* Result. */
    for (j = 0; j < n; j++)
        if (!isfinite(k->x[j])) rc = RUN_NUMERIC;
    if (rc == RUN_NUMERIC) return finish(w, FP_WLS_BAD_INPUT, iter, it1, warm, out);
    for (j = 0; j < n; j++) {
        double v = k->x[j];
        if (v < w->lb[j]) v = w->lb[j];
        if (v > w->ub[j]) v = w->ub[j];
        w->x[j] = v;
    }
    write_back(w, k);
    if (rc == RUN_INFEASIBLE || zero_row_infeasible)
        return finish(w, FP_WLS_INFEASIBLE, iter, it1, warm, out);
    if (rc == RUN_CAP) return finish(w, FP_WLS_MAX_ITER, iter, it1, warm, out);
    return finish(w, FP_WLS_OPTIMAL, iter, it1, warm, out);
}
