/*
 * Active-set solver for  min ||A x - b||^2  s.t.  lb <= x <= ub,  C x <= d.
 * See wls.h for the contract.  This file: the driver and the input checks; wls_active_set.c:
 * the active-set loop (ratio test, multipliers, anti-cycling); wls_qr.c: the factorisations;
 * wls_phase1.c: the feasible start; wls_scale.c: the variables' units (the exponents and the
 * scaled copies); wls_internal.h: what the five share.  Outline:
 *
 * - Units: the iteration works on z, x_j = 2^e_j z_j (wls_scale.c): A's and
 *   C's columns times 2^e_j, the bounds over it, in copies in the workspace (a constant C's
 *   copy kept while its exponents are).  e_j makes A's column of about unit norm (Jacobi),
 *   balanced against the column's entries in C where there are rows of C, with the common
 *   part of the e_j removed (an objective's weight is no unit of x); so variables in any
 *   units are solved alike, the tolerances below meaning the same in all of them.  Powers
 *   of 2: x = 2^e z and the bounds are exact, and the products of a scaled entry with a
 *   scaled z are the unscaled products bit for bit.
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
 *   least largest (row-normalised) violation, which is what x is then (the rows normalised
 *   as the caller gave them: t weighted per row, wls_phase1.c).
 * - Cold start: iteration 1 is the unconstrained least-squares minimiser
 *   (minimum-norm step from the previous x), projected as above.
 * - Warm start: the stored working set is factorised, x moved onto its face
 *   (minimum-norm correction of the active rows) and to the face minimiser;
 *   if that point is feasible and its multipliers are non-negative the solve
 *   ends after this one iteration, otherwise it continues from there (or from
 *   its projection if the point is infeasible).
 */
#include <stdint.h>
#include <string.h>

#include "fp_math.h"
#include "wls_internal.h"

/* ------------------------------------------------------------------------ */
/* Driver.                                                                  */

static int big(double v) { return !(fabs(v) <= BIG); } /* also NaN */

/* No entry big (or NaN), without a branch per entry: the largest magnitude compared as the
 * bits of |v| (IEEE doubles of one sign order as their bit patterns; inf and NaN lie above
 * every finite value). */
static double top_abs(const double *v, int len) { /* max |v_i| (NaN if one is), by bits */
    uint64_t top = 0;
    double t;
    int i;
    for (i = 0; i < len; i++) {
        uint64_t u;
        memcpy(&u, v + i, sizeof u);
        u &= UINT64_C(0x7FFFFFFFFFFFFFFF);
        top = u > top ? u : top;
    }
    memcpy(&t, &top, sizeof t);
    return t;
}

static int none_big(const double *v, int len) { return top_abs(v, len) <= BIG; }

/* 1 if the n x n block t (row-major, contiguous) is diagonal with a non-zero diagonal, by
 * the bits of its entries (|bits| != 0 exactly when the entry != 0.0, NaN included): the
 * off-diagonal entries are the n - 1 runs of n between consecutive diagonal entries. */
static int diagonal_block(const double *t, int n) {
    uint64_t off = 0, u;
    int r, q, nonzero = 1;
    for (r = 0; r + 1 < n; r++) {
        const double *run = t + r * (n + 1) + 1;
        for (q = 0; q < n; q++) {
            memcpy(&u, run + q, sizeof u);
            off |= u;
        }
    }
    for (r = 0; r < n; r++) {
        memcpy(&u, t + r * (n + 1), sizeof u);
        nonzero &= (u & UINT64_C(0x7FFFFFFFFFFFFFFF)) != 0;
    }
    return (off & UINT64_C(0x7FFFFFFFFFFFFFFF)) == 0 && nonzero;
}

/* One pass over A: the squared column norms into colsq (each column summed in row order),
 * whether A ends in a diagonal tail with non-zero diagonal (rows m0 + j = d_j e_j', m0 >= 0)
 * into *diag_tail, and the bad-input check: no entry big (or NaN).  A column whose sum of
 * squares is below BIG^2 / 2 has no entry of magnitude BIG or more; otherwise (also inf and
 * NaN sums) every entry is checked (none_big).  Returns 0 on a big entry.  On a diagonal
 * tail a column's sum gets only its diagonal entry's square from the tail (the zeros add
 * nothing). */
static int a_pass(const FpWls *w, int m0, double *colsq, int *diag_tail) {
    int i, j, n = w->n_vars, ok, dense = m0 >= 0 ? m0 : w->n_rows, small = 1;
    for (j = 0; j < n; j++) colsq[j] = 0.0;
    for (i = 0; i < dense; i++) {
        const double *a = w->A + i * n;
        for (j = 0; j < n; j++) colsq[j] += a[j] * a[j];
    }
    ok = m0 >= 0 && diagonal_block(w->A + m0 * n, n);
    if (ok) {
        const double *t = w->A + m0 * n;
        for (j = 0; j < n; j++) colsq[j] += t[j * (n + 1)] * t[j * (n + 1)];
    } else {
        for (; i < w->n_rows; i++) {
            const double *a = w->A + i * n;
            for (j = 0; j < n; j++) colsq[j] += a[j] * a[j];
        }
    }
    *diag_tail = ok;
    for (j = 0; j < n; j++) small &= colsq[j] < 0.5 * BIG * BIG;
    return small || none_big(w->A, w->n_rows * n);
}

/* The checks of b and of the bounds (A: a_pass; C and d: in the row loop of solve), and the
 * largest exponent field of a finite bound into *field (0 if none).  A bound is bad when
 * big or NaN, except lb = -inf and ub = +inf (no bound): by the bits of |bound| (which order
 * as the magnitudes; inf and NaN above every finite value), those two counted as 0. */
static int b_bounds_ok(const FpWls *w, int *field) {
    const double big_value = BIG;
    const uint64_t abs_mask = UINT64_C(0x7FFFFFFFFFFFFFFF), neg_inf = UINT64_C(0xFFF0000000000000),
                   pos_inf = UINT64_C(0x7FF0000000000000);
    uint64_t limit, top = 0;
    int i, n = w->n_vars;
    if (!none_big(w->b, w->n_rows)) return 0;
    memcpy(&limit, &big_value, sizeof limit);
    for (i = 0; i < n; i++) {
        uint64_t l, u;
        memcpy(&l, w->lb + i, sizeof l);
        memcpy(&u, w->ub + i, sizeof u);
        l = l == neg_inf ? 0 : l & abs_mask;
        u = u == pos_inf ? 0 : u & abs_mask;
        top = l > top ? l : top;
        top = u > top ? u : top;
    }
    *field = (int)(top >> 52);
    return top <= limit;
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

static void write_back(FpWls *w, const FpWlsWork *k) {
    int j, i;
    for (j = 0; j < w->n_vars; j++) {
        int8_t s = k->state[j];
        w->bound_ws[j] = (int8_t)(s == ST_UB ? 1 : (s == ST_FREE ? 0 : -1));
    }
    for (i = 0; i < w->n_cons; i++) w->cons_ws[i] = k->act[i];
}

/* The result; objective and max_violation only with stats (else -1: not computed). */
static FpStatus finish_stats(FpWls *w, FpWlsStatus st, int iter, int it1, int warm,
                             FpWlsResult *out, int stats) {
    if (out != NULL) {
        out->status = st;
        out->iterations = iter;
        out->phase1_iterations = it1;
        out->warm_start = warm;
        if (!stats) {
            out->objective = out->max_violation = -1.0;
        } else {
            out->objective = st == FP_WLS_BAD_INPUT ? 0.0 : objective(w, w->x);
            out->max_violation = st == FP_WLS_BAD_INPUT ? 0.0 : max_violation(w, w->x);
            if (!isfinite(out->objective)) out->objective = DBL_MAX;
            if (!isfinite(out->max_violation)) out->max_violation = DBL_MAX;
        }
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
        w->work.sc[j] = w->work.sc_inv[j] = 1.0; /* 2^exps, exps = 0 */
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
    w->c_unchanged = 0;
    return FP_OK;
}

void fp_wls_reset(FpWls *w) {
    if (w == NULL) return;
    memset(w->bound_ws, 0, sizeof w->bound_ws);
    memset(w->cons_ws, 0, sizeof w->cons_ws);
}

#if defined(__GNUC__) || defined(__clang__)
#define FP_PREFETCH(p) __builtin_prefetch((const void *)(p), 1, 3)
#else
#define FP_PREFETCH(p) ((void)(p))
#endif

/* Every 64-byte line of [p, p + bytes). */
static void prefetch_range(const void *p, size_t bytes) {
    const char *c = (const char *)p;
    size_t off;
    for (off = 0; off < bytes; off += 64) FP_PREFETCH(c + off);
    if (bytes > 0) FP_PREFETCH(c + bytes - 1);
}

void fp_wls_prefetch(const FpWls *w) {
    const FpWlsWork *k;
    size_t n, m, p, cols;
    if (w == NULL || w->n_vars < 1 || w->n_vars > FP_WLS_MAX_VARS || w->n_rows < 0 ||
        w->n_rows > FP_WLS_MAX_ROWS || w->n_cons < 0 || w->n_cons > FP_WLS_MAX_CONS)
        return;
    n = (size_t)w->n_vars, m = (size_t)w->n_rows, p = (size_t)w->n_cons;
    k = &w->work;
    prefetch_range(w->A, m * n * sizeof(double));
    prefetch_range(w->b, m * sizeof(double));
    prefetch_range(w->lb, n * sizeof(double));
    prefetch_range(w->ub, n * sizeof(double));
    prefetch_range(w->C, p * n * sizeof(double));
    prefetch_range(w->d, p * sizeof(double));
    prefetch_range(w->x, n * sizeof(double));
    prefetch_range(w->bound_ws, n);
    prefetch_range(w->cons_ws, p);
    /* the workspace: the vectors (one per row of names in FpWlsWork), the factors' columns */
    {
        const double *vecs[] = {k->x, k->p, k->g, k->u, k->v, k->qv, k->nvec, k->zvec,
                                k->rr, k->rb, k->tau_m, k->tau_a};
        size_t i;
        for (i = 0; i < sizeof vecs / sizeof vecs[0]; i++)
            prefetch_range(vecs[i], (n + 1) * sizeof(double));
    }
    prefetch_range(k->r, m * sizeof(double));
    /* the scaled problem (wls_scale.c: wls_column_exponents) and its exponents */
    prefetch_range(k->as, (m > n ? m - n : m) * n * sizeof(double)); /* (a diagonal tail: in ds) */
    prefetch_range(k->ds, n * sizeof(double));
    prefetch_range(k->cs, p * n * sizeof(double));
    prefetch_range(k->lbs, n * sizeof(double));
    prefetch_range(k->ubs, n * sizeof(double));
    prefetch_range(k->sc, n * sizeof(double));
    prefetch_range(k->sc_inv, n * sizeof(double));
    prefetch_range(k->exps, n * sizeof(int16_t));
    prefetch_range(k->c_exp, n * sizeof(int16_t));
    prefetch_range(k->e_jac, n * sizeof(int16_t));
    prefetch_range(k->e_bal, n * sizeof(int16_t));
    prefetch_range(k->cinv, p * sizeof(double));
    prefetch_range(k->csq, p * sizeof(double));
    prefetch_range(k->cnorm, p * sizeof(double));
    prefetch_range(k->mur, p * sizeof(double));
    prefetch_range(k->act, p);
    prefetch_range(k->use, p);
    prefetch_range(k->state, n + 1);
    prefetch_range(k->free_idx, (n + 1) * sizeof(int));
    prefetch_range(k->act_idx, (n + 1) * sizeof(int));
    prefetch_range(k->perm, (n + 1) * sizeof(int));
    cols = n + 1 < FP_WLS_NV1 ? n + 1 : FP_WLS_NV1;
    {
        size_t j;
        for (j = 0; j < cols; j++) prefetch_range(k->az + j * FP_WLS_MAX_ROWS, m * sizeof(double));
    }
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

static FpStatus solve(FpWls *w, int max_iter, FpWlsResult *out, int stats);

FpStatus fp_wls_solve(FpWls *w, int max_iter, FpWlsResult *out) {
    return solve(w, max_iter, out, 1);
}

FpStatus fp_wls_solve_brief(FpWls *w, int max_iter, FpWlsResult *out) {
    return solve(w, max_iter, out, 0);
}

static FpStatus solve(FpWls *w, int max_iter, FpWlsResult *out, int stats) {
    FpWlsWork *k;
    Ctx ctx, *c = &ctx;
    int n, i, j, iter = 0, it1 = 0, warm = 0, crossed = 0, zero_row_infeasible = 0, rc;
    double fscale = 1.0, colsq[FP_WLS_MAX_VARS], sq4[4], xs[FP_WLS_MAX_VARS], amax = 0.0;
    int bfield;
    int diag_tail = 0, m0, reuse, c_same, all_used, scaled, same_exp;

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
    m0 = w->n_rows - n;
    if (max_iter < 1 || !a_pass(w, m0, colsq, &diag_tail) || !b_bounds_ok(w, &bfield))
        return finish_stats(w, FP_WLS_BAD_INPUT, 0, 0, 0, out, stats);
    /* C as the last solve had it (the caller says so, and that solve kept every row's
     * norm): its entries were checked then, and their largest magnitude kept (c_top).
     * Else the check of C's entries (d: in the rows' pass below). */
    reuse = c_same = w->c_unchanged && k->c_rows_ok == w->n_cons && k->c_cols_ok == n;
    w->c_unchanged = 0;
    if (!reuse) {
        k->c_rows_ok = k->c_cols_ok = -1; /* valid again once this C's rows are */
        k->c_top = top_abs(w->C, w->n_cons * n);
        if (!(k->c_top <= BIG)) return finish_stats(w, FP_WLS_BAD_INPUT, 0, 0, 0, out, stats);
    }

    /* The variables' scaling (wls_scale.c): the iteration sees A, C and the bounds
     * scaled, or the caller's own arrays when every exponent is 0. */
    memset(c, 0, sizeof *c);
    scaled = wls_column_exponents(w, k, colsq, c_same, k->c_top, bfield, &same_exp);
    reuse &= same_exp; /* the kept norms are of C scaled by c_exp */
    c->A = w->A, c->C = w->C, c->lb = w->lb, c->ub = w->ub;
    if (scaled) {
        wls_scale_a_bounds(w, k, diag_tail, m0);
        if (!reuse) wls_scale_c(w, k);
        c->A = k->as, c->C = k->cs, c->lb = k->lbs, c->ub = k->ubs;
    }

    /* The rows of C as the iteration sees them: their norms and scales.  The norm, its
     * square root and 1 / norm are taken from the last solve when the row's sum of squares
     * is the same (a constant force set), as vnorm would give them.  Kept rows (reuse):
     * only d is read; a d that is not a plain finite number takes the full pass. */
    for (i = 0; reuse && i < w->n_cons; i++) {
        double ad = fabs(w->d[i]);
        if (!(ad <= BIG)) break;
        k->use[i] = 1;
        if (ad * k->cinv[i] > fscale) fscale = ad * k->cinv[i];
    }
    if (reuse && i < w->n_cons) reuse = 0, fscale = 1.0;
    k->c_rows_ok = k->c_cols_ok = -1;
    all_used = 1;
    for (i = 0; !reuse && i < w->n_cons; i++) {
        const double *row = c->C + i * n;
        double sq, cn;
        if (w->d[i] != INFINITY && big(w->d[i]))
            return finish_stats(w, FP_WLS_BAD_INPUT, 0, 0, 0, out, stats);
        if (i % 4 == 0) sumsq4(row, n, w->n_cons - i < 4 ? w->n_cons - i : 4, n, sq4);
        sq = sq4[i % 4];
        k->use[i] = 0;
        if (sq >= DBL_MIN && sq < HUGE_VAL && sq == k->csq[i] && k->cnorm[i] > 0.0) {
            cn = k->cnorm[i];
        } else {
            cn = vnorm(row, n);
            k->csq[i] = sq;
            k->cnorm[i] = cn;
            k->cinv[i] = 1.0 / cn;
        }
        if (w->d[i] == INFINITY) {
            k->csq[i] = -1.0; /* cinv is 0 for a disabled row: no cache */
            k->cinv[i] = 0.0;
            continue;
        }
        if (cn == 0.0 || !(k->cinv[i] < INFINITY)) {
            k->csq[i] = -1.0;
            k->cinv[i] = 0.0;
            if (w->d[i] < 0.0) zero_row_infeasible = 1;
            continue;
        }
        k->use[i] = 1;
        /* the offset in row-norm units; times 1 / norm: no division per row */
        if (fabs(w->d[i]) * k->cinv[i] > fscale) fscale = fabs(w->d[i]) * k->cinv[i];
    }
    for (i = 0; !reuse && i < w->n_cons; i++) all_used &= k->use[i];
    if (all_used) { /* (kept rows: their exponents are c_exp already) */
        k->c_rows_ok = w->n_cons, k->c_cols_ok = n;
        if (!reuse) memcpy(k->c_exp, k->exps, (size_t)n * sizeof *k->c_exp);
    }

    for (j = 0; j < n; j++)
        if (w->lb[j] > w->ub[j]) crossed = 1;
    if (crossed) {
        for (j = 0; j < n; j++) {
            double lo = fmin(w->lb[j], w->ub[j]), hi = fmax(w->lb[j], w->ub[j]);
            w->x[j] = fmin(fmax(w->x[j], lo), hi);
        }
        return finish_stats(w, FP_WLS_INFEASIBLE, 0, 0, 0, out, stats);
    }

    c->w = w;
    c->k = k;
    c->n = n;
    c->nv = n;
    for (j = 0; j < n; j++) { /* the largest column norm of the scaled A */
        double sq = scaled ? colsq[j] * k->sc[j] * k->sc[j] : colsq[j];
        if (sq > amax) amax = sq;
    }
    c->anorm = sqrt(amax);
    c->m0 = m0;
    c->diag_tail = diag_tail;
    c->dg = scaled ? k->ds : w->A + (m0 > 0 ? m0 : 0) * n;
    c->dgs = scaled ? 1 : n + 1;

    /* A start point far outside the problem's own scale (the constraint offsets and finite
     * bounds) is a stale or corrupt warm start; it would also set the feasibility
     * tolerance, so the solve starts cold instead. */
    {
        double scale = fscale;
        for (j = 0; j < n; j++) {
            if (isfinite(c->lb[j]) && fabs(c->lb[j]) > scale) scale = fabs(c->lb[j]);
            if (isfinite(c->ub[j]) && fabs(c->ub[j]) > scale) scale = fabs(c->ub[j]);
            xs[j] = scaled ? w->x[j] * k->sc_inv[j] : w->x[j];
        }
        if (!(inf_norm(xs, n) <= START_RANGE * scale)) {
            for (j = 0; j < n; j++) w->x[j] = xs[j] = 0.0;
            fp_wls_reset(w);
        }
    }

    /* Working set from the caller (sanitised) and start point. */
    for (j = 0; j < n; j++) {
        int8_t s = ST_FREE;
        k->x[j] = xs[j];
        if (c->lb[j] == c->ub[j])
            s = ST_EQ;
        else if (w->bound_ws[j] < 0 && isfinite(c->lb[j]))
            s = ST_LB;
        else if (w->bound_ws[j] > 0 && isfinite(c->ub[j]))
            s = ST_UB;
        if (s == ST_LB || s == ST_UB) warm = 1;
        if (s == ST_EQ || s == ST_LB) k->x[j] = c->lb[j];
        if (s == ST_UB) k->x[j] = c->ub[j];
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
    wls_factor_ws(c);
    wls_project_to_face(c);
    if (!wls_compute_step(c)) {
        rc = RUN_NUMERIC;
    } else {
        int feasible = 1;
        for (j = 0; j < n; j++) k->x[j] += k->p[j];
        for (j = 0; j < n && feasible; j++) {
            if (k->state[j] != ST_FREE) continue;
            if (k->x[j] < c->lb[j] - c->tol_feas || k->x[j] > c->ub[j] + c->tol_feas) feasible = 0;
        }
        for (i = 0; i + 4 <= w->n_cons && feasible; i += 4) { /* four rows side by side */
            double s4[4];
            int q;
            crow_dot4(c, i, k->x, s4);
            for (q = 0; q < 4; q++)
                if (k->use[i + q] && !k->act[i + q] && s4[q] - dval(c, i + q) > c->tol_feas)
                    feasible = 0;
        }
        for (; i < w->n_cons && feasible; i++)
            if (k->use[i] && !k->act[i] && crow_dot(c, i, k->x) - dval(c, i) > c->tol_feas)
                feasible = 0;
        if (feasible) {
            /* early exit if the multipliers say so, else continue from here */
            int drop;
            wls_clamp_free(c);
            drop = wls_pick_drop(c);
            if (drop < 0) {
                rc = RUN_OPTIMAL;
            } else {
                wls_drop_constraint(c, drop);
                rc = wls_run(c, max_iter, &iter);
            }
        } else {
            /* phase 1 from this point, then phase 2 */
            rc = wls_find_feasible(c, max_iter, &iter);
            it1 = iter - 1;
            if (rc == RUN_FEASIBLE) rc = wls_run(c, max_iter, &iter);
        }
    }

    /* Result. */
    for (j = 0; j < n; j++)
        if (!isfinite(k->x[j])) rc = RUN_NUMERIC;
    if (rc == RUN_NUMERIC) return finish_stats(w, FP_WLS_BAD_INPUT, iter, it1, warm, out, stats);
    for (j = 0; j < n; j++) { /* in the caller's units (exact: a power of 2) */
        double v = scaled ? k->x[j] * k->sc[j] : k->x[j];
        if (v < w->lb[j]) v = w->lb[j];
        if (v > w->ub[j]) v = w->ub[j];
        w->x[j] = v;
    }
    write_back(w, k);
    if (rc == RUN_INFEASIBLE || zero_row_infeasible)
        return finish_stats(w, FP_WLS_INFEASIBLE, iter, it1, warm, out, stats);
    if (rc == RUN_CAP) return finish_stats(w, FP_WLS_MAX_ITER, iter, it1, warm, out, stats);
    return finish_stats(w, FP_WLS_OPTIMAL, iter, it1, warm, out, stats);
}
