/*
 * Internal to the solver (wls.c, wls_active_set.c, wls_qr.c, wls_phase1.c, wls_scale.c): the
 * iteration context, the working-set states, the tolerances and the accessors shared by the
 * five files.  Not part of the API (wls.h).  The files call each other in layers only:
 * wls_qr.c <- wls_active_set.c <- wls_phase1.c <- wls.c, and wls_scale.c <- wls.c (the
 * scaling calls none of the others).
 */
#ifndef FP_WLS_INTERNAL_H
#define FP_WLS_INTERNAL_H

#include <float.h>
#include <math.h>

#include "wls.h"

#define NV1 FP_WLS_NV1

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
#define START_RANGE 1e6    /* a start point beyond START_RANGE x the data's scale is dropped */
#define TOL_GI 1e-10       /* projection phase: a normal this close to the span is dependent */
#ifndef DUAL_E2_MAX
#define DUAL_E2_MAX 1e6    /* the diagonal tail's dual step only for ||M_F D_F^-1||_F^2 <= this */
#endif

/* Magnitudes above this are bad input (their squares would overflow). */
#define BIG 1e150
/* The column scaling keeps every scaled entry of A and C and every finite scaled bound at
 * or below 2^SCALE_EXP_MAX (about 3e150: just above BIG, so their squares still fit). */
#define SCALE_EXP_MAX 500

/* Outcomes of the iteration loop. */
enum { RUN_OPTIMAL, RUN_CAP, RUN_FEASIBLE, RUN_INFEASIBLE, RUN_NUMERIC };

typedef struct {
    FpWls *w;
    FpWlsWork *k;
    /* The problem the iteration sees: the variables scaled, x = 2^e z per variable (wls_scale.c:
     * wls_column_exponents), so A and C are the caller's with column j times 2^e_j and the
     * bounds times 2^-e_j.  Each points to the caller's array when every e_j is 0, else to
     * the scaled copy in the workspace.  b and d are the caller's (no row is scaled). */
    const double *A, *C, *lb, *ub;
    int n;        /* variables of the problem */
    int nv;       /* variables iterated: n, or n + 1 in phase 1 (t last) */
    int ph1;      /* phase 1: objective t^2, rows of C get a -t term */
    int nf, nw;   /* free variables, accepted active rows */
    int stall;    /* consecutive iterations that did not move x */
    int bland;    /* stalled long enough: use smallest-index choices */
    double anorm; /* largest column norm of A (rank cut-off scale) */
    double tol_feas;
    /* A ends in a diagonal block: rows m0 + j (j < n) are d_j e_j', every d_j != 0 (the
     * regularisation rows of an allocation, the W_u rows of the guidance).  Then a face
     * without active rows of C has a full-rank A_F and its step comes from a QR of m0
     * columns (dual form) or of one reflector per free variable on 1 + m0 rows (primal
     * form, for a large M_F D_F^-1) (wls_qr.c).  m0 = n_rows - n; diag_tail 0: not so. */
    int diag_tail, m0;
    /* The diagonal d_j of such a tail: dg[j * dgs], in A (dgs = n + 1) or, scaled, in a
     * packed copy (dgs = 1; the scaled A then holds only the dense rows). */
    const double *dg;
    int dgs;
} Ctx;

/* ------------------------------------------------------------------------ */
/* Problem accessors (phase 1 and phase 2 share the loop).                  */

static inline double lbv(const Ctx *c, int j) { return j < c->n ? c->lb[j] : 0.0; }

static inline double ubv(const Ctx *c, int j) { return j < c->n ? c->ub[j] : INFINITY; }

/* Row i of the scaled C (with the -t column in phase 1: -tw[i], see wls_phase1.c). */
static inline double cval(const Ctx *c, int i, int j) {
    return j < c->n ? c->C[i * c->n + j] * c->k->cinv[i] : -c->k->tw[i];
}

static inline double dval(const Ctx *c, int i) { return c->w->d[i] * c->k->cinv[i]; }

/* d_j of a diagonal tail (Ctx.diag_tail). */
static inline double tail_d(const Ctx *c, int j) { return c->dg[j * c->dgs]; }

/* Element (i, j) of A as the iteration sees it (a diagonal tail's zeros included). */
static inline double aval(const Ctx *c, int i, int j) {
    if (c->diag_tail && i >= c->m0) return i - c->m0 == j ? tail_d(c, j) : 0.0;
    return c->A[i * c->n + j];
}

/* sum_j cval(c, i, j) x[j]: the row's product before normalising times the row's 1 / norm
 * (one multiplication per row, not per element), then the phase-1 -t term. */
static inline double crow_dot(const Ctx *c, int i, const double *x) {
    const double *row = c->C + i * c->n;
    double s = 0.0;
    int j;
    for (j = 0; j < c->n; j++) s += row[j] * x[j];
    s *= c->k->cinv[i];
    for (; j < c->nv; j++) s -= c->k->tw[i] * x[j];
    return s;
}

/* crow_dot of the four rows i..i+3 side by side (each the same arithmetic as crow_dot). */
static inline void crow_dot4(const Ctx *c, int i, const double *x, double s[4]) {
    const double *r0 = c->C + i * c->n, *r1 = r0 + c->n, *r2 = r1 + c->n, *r3 = r2 + c->n;
    const double *ci = c->k->cinv + i, *tw = c->k->tw + i;
    double s0 = 0.0, s1 = 0.0, s2 = 0.0, s3 = 0.0;
    int j;
    for (j = 0; j < c->n; j++) {
        s0 += r0[j] * x[j];
        s1 += r1[j] * x[j];
        s2 += r2[j] * x[j];
        s3 += r3[j] * x[j];
    }
    s0 *= ci[0], s1 *= ci[1], s2 *= ci[2], s3 *= ci[3];
    for (; j < c->nv; j++) {
        s0 -= tw[0] * x[j];
        s1 -= tw[1] * x[j];
        s2 -= tw[2] * x[j];
        s3 -= tw[3] * x[j];
    }
    s[0] = s0, s[1] = s1, s[2] = s2, s[3] = s3;
}

/* crow_dot of the rows i..i+3 that exist (fewer at the end of C) into s. */
static inline void crow_dots(const Ctx *c, int i, const double *x, double s[4]) {
    int r;
    if (i + 4 <= c->w->n_cons) {
        crow_dot4(c, i, x, s);
        return;
    }
    for (r = 0; i + r < c->w->n_cons; r++) s[r] = crow_dot(c, i + r, x);
}

static inline int nrows(const Ctx *c) { return c->ph1 ? 1 : c->w->n_rows; }

/* r = b - A x over the rows of the current objective. */
static inline void residual(Ctx *c) {
    FpWlsWork *k = c->k;
    int i, j, n = c->n;
    if (c->ph1) {
        k->r[0] = -k->x[n];
        return;
    }
    /* a diagonal tail (rows m0 + j = d_j e_j'): its rows' one non-zero term each (the zero
     * terms change no non-zero sum) */
    int dense = c->diag_tail ? c->m0 : c->w->n_rows;
    for (i = dense; i < c->w->n_rows; i++)
        k->r[i] = c->w->b[i] - tail_d(c, i - dense) * k->x[i - dense];
    for (i = 0; i + 4 <= dense; i += 4) { /* four rows side by side */
        const double *a0 = c->A + i * n, *a1 = a0 + n, *a2 = a1 + n, *a3 = a2 + n;
        double s0 = c->w->b[i], s1 = c->w->b[i + 1], s2 = c->w->b[i + 2], s3 = c->w->b[i + 3];
        for (j = 0; j < n; j++) {
            double xj = k->x[j];
            s0 -= a0[j] * xj;
            s1 -= a1[j] * xj;
            s2 -= a2[j] * xj;
            s3 -= a3[j] * xj;
        }
        k->r[i] = s0, k->r[i + 1] = s1, k->r[i + 2] = s2, k->r[i + 3] = s3;
    }
    for (; i < dense; i++) {
        const double *a = c->A + i * n;
        double s = c->w->b[i];
        for (j = 0; j < n; j++) s -= a[j] * k->x[j];
        k->r[i] = s;
    }
}

static inline double inf_norm(const double *x, int len);

static inline double vnorm(const double *x, int len) {
    double s = 0.0, m;
    int i;
    for (i = 0; i < len; i++) s += x[i] * x[i];
    if (s >= DBL_MIN && s < HUGE_VAL) return sqrt(s);
    /* the squares underflowed (entries below ~1e-154) or overflowed: the norm of x scaled
     * by its largest entry, scaled back, so a tiny but nonzero row is not a zero row */
    m = inf_norm(x, len);
    if (!(m > 0.0) || !(m < HUGE_VAL)) return sqrt(s);
    s = 0.0;
    for (i = 0; i < len; i++) s += (x[i] / m) * (x[i] / m);
    return m * sqrt(s);
}

/* The sums of squares of rows rows (<= 4) of length len, ld apart, side by side (each summed
 * in index order, as vnorm sums). */
static inline void sumsq4(const double *x, int ld, int rows, int len, double out[4]) {
    const double *x0 = x, *x1 = x + ld, *x2 = x + 2 * ld, *x3 = x + 3 * ld;
    double s0 = 0.0, s1 = 0.0, s2 = 0.0, s3 = 0.0;
    int i, r;
    if (rows < 4) {
        for (r = 0; r < rows; r++) {
            double s = 0.0;
            for (i = 0; i < len; i++) s += x[r * ld + i] * x[r * ld + i];
            out[r] = s;
        }
        return;
    }
    for (i = 0; i < len; i++) {
        s0 += x0[i] * x0[i];
        s1 += x1[i] * x1[i];
        s2 += x2[i] * x2[i];
        s3 += x3[i] * x3[i];
    }
    out[0] = s0, out[1] = s1, out[2] = s2, out[3] = s3;
}

/* vnorm of rows rows (<= 4) of length len, ld apart, side by side: each sums in the same
 * order as vnorm and takes its square root, or is vnorm itself when the sum under- or
 * overflowed. */
static inline void vnorm4(const double *x, int ld, int rows, int len, double out[4]) {
    double s[4];
    int i;
    if (rows < 4) {
        for (i = 0; i < rows; i++) out[i] = vnorm(x + i * ld, len);
        return;
    }
    sumsq4(x, ld, 4, len, s);
    for (i = 0; i < 4; i++)
        out[i] = s[i] >= DBL_MIN && s[i] < HUGE_VAL ? sqrt(s[i]) : vnorm(x + i * ld, len);
}

static inline double inf_norm(const double *x, int len) {
    double m = 0.0;
    int i;
    for (i = 0; i < len; i++)
        if (fabs(x[i]) > m) m = fabs(x[i]);
    return m;
}

/* ------------------------------------------------------------------------ */
/* wls_qr.c: factorisations of the working set and the steps they give.    */

/* Householder QR of C_WF^T (active rows on the free variables); dependent rows leave the
 * working set.  Sets c->nf, c->nw and the free and active index lists. */
void wls_factor_ws(Ctx *c);

/* Step p (full length nv, zero on fixed variables) to the face minimiser.
 * Needs wls_factor_ws (and uses the current x).  Returns 0 if not finite. */
int wls_compute_step(Ctx *c);

/* Decompose v (length nv) on the working set (needs wls_factor_ws):
 *     v = sum_q rr[q] c_{act_idx[q]} + sum_{j fixed} rb[j] n_j + z,
 * n_j = +e_j at an upper bound, -e_j at a lower one, z in the null space of
 * the working set (zero on fixed variables). */
void wls_decompose(Ctx *c, const double *v, double *z, double *rr, double *rb);

/* Move x (phase 2, warm start) onto the face of the working set: minimum-norm
 * correction so the active rows hold at equality.  Needs wls_factor_ws. */
void wls_project_to_face(Ctx *c);

/* ------------------------------------------------------------------------ */
/* wls_active_set.c: the active-set loop.                                   */

/* The active-set loop from a feasible point with a consistent working set: RUN_OPTIMAL,
 * RUN_CAP, RUN_NUMERIC, or in phase 1 RUN_FEASIBLE. */
int wls_run(Ctx *c, int max_iter, int *iter);

/* Clamp the free variables into their bounds (removes rounding overshoot). */
void wls_clamp_free(Ctx *c);

/* Multipliers at the face minimiser (needs wls_factor_ws for the current set): the global
 * index of the constraint to drop (j < nv a bound, nv + i row i of C), or -1 if none. */
int wls_pick_drop(Ctx *c);

/* Drop constraint idx (a global index as wls_pick_drop returns) from the working set. */
void wls_drop_constraint(Ctx *c, int idx);

/* ------------------------------------------------------------------------ */
/* wls_phase1.c: a feasible start.                                          */

/* From any k->x: a feasible point with a consistent working set
 * (RUN_FEASIBLE), RUN_INFEASIBLE (x: minimax point, or the best found within
 * the cap), RUN_CAP (x: phase-1 iterate clamped into the bounds) or
 * RUN_NUMERIC. */
int wls_find_feasible(Ctx *c, int max_iter, int *iter);

/* ------------------------------------------------------------------------ */
/* wls_scale.c: the variables' units (powers of 2).                         */

/* The exponents of the variables' scaling x_j = 2^e_j z_j: A's column of about unit norm
 * (Jacobi, from colsq, A's squared column norms), balanced against the column's entries in
 * the rows of C (Curtis-Reid style; kept in k->e_jac, k->e_bal and taken again while C is
 * unchanged, c_same, and so are the Jacobi exponents), the common part removed, all scaled
 * up when every finite bound is below 1/2, and limited so that no scaled entry of A or C
 * (ctop: the largest |C_ij|) and no finite scaled bound (bfield: the largest exponent field
 * of a finite bound) exceeds 2^SCALE_EXP_MAX.  The exponents go to k->exps, 2^e_j and 2^-e_j
 * to k->sc, k->sc_inv; *as_c_exp says whether they are k->c_exp.  Returns 1 when some
 * e_j != 0. */
int wls_column_exponents(const FpWls *w, FpWlsWork *k, const double *colsq, int c_same,
                         double ctop, int bfield, int *as_c_exp);

/* A and the bounds with the variables scaled (k->sc set): into k->as, k->lbs, k->ubs; when
 * A ends in a diagonal block (diag_tail, rows m0 + j = d_j e_j') k->as holds its dense rows
 * only and k->ds the diagonal. */
void wls_scale_a_bounds(const FpWls *w, FpWlsWork *k, int diag_tail, int m0);

/* C with the variables scaled (k->sc set): into k->cs. */
void wls_scale_c(const FpWls *w, FpWlsWork *k);

#endif
