/*
 * Active-set solver for  min ||A x - b||^2  s.t.  lb <= x <= ub,  C x <= d.
 * See wls.h for the contract.  This file: the driver; wls_active_set.c: the active-set loop
 * (ratio test, multipliers, anti-cycling); wls_qr.c: the factorisations; wls_phase1.c: the
 * feasible start; wls_internal.h: what the four share.  Outline:
 *
 * - Units: the iteration works on z, x_j = 2^e_j z_j (column_exponents below): A's and
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

/* The exponent field of |v| (0 for a zero, 0x7FF for inf or NaN). */
static int exp_field(double v) {
    uint64_t u;
    memcpy(&u, &v, sizeof u);
    return (int)((u >> 52) & 0x7FF);
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

/* The exponent of v > 0 (finite): v = f 2^ex with f in [0.5, 1), as frexp gives it, from
 * the bits of a normal v (frexp only for a subnormal one: a library call). */
static int expo(double v) {
    uint64_t u;
    int ex;
    memcpy(&u, &v, sizeof u);
    ex = (int)((u >> 52) & 0x7FF);
    if (ex != 0) return ex - 1022;
    (void)frexp(v, &ex);
    return ex;
}

/* 2^e for |e| <= 1022 (a normal double), built from its bits: exact, no library call. */
static double pow2(int e) {
    uint64_t u = (uint64_t)(e + 1023) << 52;
    double v;
    memcpy(&v, &u, sizeof v);
    return v;
}

/* A column exponent: within +-1000, so 2^e and 2^-e are normal doubles. */
static int16_t exponent_within(int e) { return (int16_t)(e > 1000 ? 1000 : e < -1000 ? -1000 : e); }

/* The Jacobi exponent of a column that is zero in A. */
#define ZERO_COLUMN INT16_MIN
/* The weight of a column zero in A's pull towards its range (see balance). */
#define ZERO_COLUMN_WEIGHT 1e-2
/* An entry of C below 2^-BALANCE_NEGLIGIBLE of its row's largest is left out of the balance. */
#define BALANCE_NEGLIGIBLE 30

/*
 * The balance of the columns (column_exponents): the real l minimising, with each row i of
 * C free to scale by 2^r_i and E_ij = expo(|C_ij|) over its non-zero entries,
 *     sum_j w_j (l_j - t_j)^2 + sum_i sum_{j: C_ij != 0} (E_ij + l_j + r_i)^2,
 * a column's own term pulling it to its Jacobi exponent (t_j = ej[j], w_j = 1) or, for a
 * column zero in A, weakly to its finite range (t_j = expo(ub - lb), else 0; w_j =
 * ZERO_COLUMN_WEIGHT).  Every term is unchanged when a column is scaled and l_j moves by
 * -log2 of the factor: the balance is as homogeneous as the Jacobi exponents (the logarithmic
 * scaling of Curtis and Reid, with A's column as one entry).  With the optimal r_i
 * eliminated, row i adds the projector I - 1 1' / n_i on its n_i non-zero columns to an
 * n x n positive definite system.  Rows with one entry say nothing, and an entry negligible
 * in its row (below 2^-BALANCE_NEGLIGIBLE of the largest, both at the Jacobi scaling) says
 * nothing either: a derived polytope's 1e-17 where a zero was meant would otherwise pull its
 * column by some 50 binary orders.  e = round(l); the Jacobi exponents on a failed
 * factorisation (cannot happen: the system is >= min w_j I).
 */
static void balance(const FpWls *w, const int16_t *ej, int16_t *e) {
    int n = w->n_vars, p = w->n_cons, i, j, q, r;
    double M[FP_WLS_MAX_VARS * FP_WLS_MAX_VARS], l[FP_WLS_MAX_VARS], ex[FP_WLS_MAX_VARS];
    int idx[FP_WLS_MAX_VARS];
    for (j = 0; j < n * n; j++) M[j] = 0.0;
    for (j = 0; j < n; j++) {
        double range = w->ub[j] - w->lb[j];
        if (ej[j] != ZERO_COLUMN) {
            M[j * n + j] = 1.0;
            l[j] = ej[j];
        } else {
            M[j * n + j] = ZERO_COLUMN_WEIGHT;
            l[j] = range > 0.0 && range < HUGE_VAL ? ZERO_COLUMN_WEIGHT * expo(range) : 0.0;
        }
    }
    for (i = 0; i < p; i++) {
        const double *row = w->C + i * n;
        double mean = 0.0, inv;
        int ni = 0, top = INT16_MIN, q0;
        /* the row's entries and the exponent of each at the Jacobi scaling (which is as
         * homogeneous as the balance); those below 2^-BALANCE_NEGLIGIBLE of the row's largest
         * there (rounding noise where a zero was meant, which would count as much as a real
         * entry) are left out */
        for (j = 0; j < n; j++) {
            if (row[j] == 0.0) continue;
            idx[ni] = j;
            ex[ni] = expo(fabs(row[j]));
            if (ej[j] != ZERO_COLUMN && ex[ni] + ej[j] > top) top = (int)ex[ni] + ej[j];
            ni++;
        }
        for (q = q0 = 0; q < ni; q++) {
            if (ej[idx[q]] != ZERO_COLUMN && ex[q] + ej[idx[q]] < top - BALANCE_NEGLIGIBLE)
                continue;
            idx[q0] = idx[q], ex[q0] = ex[q];
            mean += ex[q0++];
        }
        ni = q0;
        if (ni < 2) continue;
        inv = 1.0 / ni;
        mean *= inv;
        for (q = 0; q < ni; q++) {
            l[idx[q]] -= ex[q] - mean;
            for (r = 0; r <= q; r++) M[idx[q] * n + idx[r]] -= inv; /* lower triangle */
            M[idx[q] * n + idx[q]] += 1.0;
        }
    }
    if (!fp_chol_factor(M, n, 0.0)) {
        for (j = 0; j < n; j++) e[j] = ej[j] == ZERO_COLUMN ? 0 : ej[j];
        return;
    }
    fp_chol_backsolve(M, n, l);
    for (j = 0; j < n; j++) e[j] = exponent_within((int)lround(l[j]));
}

/*
 * The scaling of the variables, x_j = 2^e_j z_j, under which the iteration sees the same
 * problem whatever units the caller's variables are in.  Given the columns of A and C times
 * any s_j > 0 (and the bounds over s_j), every exponent below moves by -log2 s_j up to
 * rounding: the iteration sees the problem in the caller's base units up to a small power of
 * 2 per column, and the tolerances (relative to |z|, |c_i|, |A|) mean the same in every unit.
 * Powers of 2: scaling and unscaling are exact.
 * - Jacobi: ej_j with |A_j| 2^ej_j in [0.5, 1), the least-squares problem's own scaling
 *   (colsq: the squared column norms of A).  Without C these are the exponents.
 * - With C, the balance (balance): Jacobi alone would blow up a column small in A next to
 *   its entries in C (a variable that matters more to the constraints than to the
 *   objective, e.g. with fewer rows of A than variables) and distort the rows of C; the
 *   balance weighs A's column against the column's entries in the rows of C.  A function of
 *   C and the Jacobi exponents only (and the ranges of columns zero in A): kept in
 *   k->e_jac, k->e_bal and taken again while C is unchanged (c_same) and so are the Jacobi
 *   exponents, no column being zero in A: the guidance's constant force set pays for it
 *   only when a column's norm crosses a power of 2.
 * - Limits: no scaled entry of A or C and no finite scaled bound may exceed 2^SCALE_EXP_MAX
 *   (entries grow only for e_j > 0, bounds only for e_j < 0; the input's magnitudes are at
 *   most BIG): ctop is the largest |C_ij|, bfield the largest exponent field of a finite
 *   bound (so a bound of 2^bfield is the limit for every column: a coarser test than per
 *   column, which binds only for bounds within 2^|e_j| of 2^SCALE_EXP_MAX).
 * The exponents go to k->exps, 2^e_j and 2^-e_j to k->sc, k->sc_inv, whether they are
 * k->c_exp to *as_c_exp; returns 1 when some e_j != 0.
 */
static int column_exponents(const FpWls *w, FpWlsWork *k, const double *colsq, int c_same,
                            double ctop, int bfield, int *as_c_exp) {
    int n = w->n_vars, m = w->n_rows, i, j, any = 0, tiny = 0, zero = 0, same = c_same, eq = 1;
    int sum = 0, counted = 0, shift = 0, raw_top = INT16_MIN, bound_top = INT16_MIN;
    int hi = ctop > 0.0 ? SCALE_EXP_MAX - expo(ctop) : 1000;
    int lo = bfield > 0 ? bfield - 1022 - SCALE_EXP_MAX : -1000; /* (the largest, at most) */
    int16_t ej[FP_WLS_MAX_VARS], bal[FP_WLS_MAX_VARS], bf[FP_WLS_MAX_VARS];
    const int16_t *e = bal;
    /* |A_j|^2 = f 2^E, f in [0.5, 1), exponent field F = E + 1022: |A_j| has the exponent
     * ceil(E / 2) = (F + 1) / 2 - 511 (no square root); F = 0: zero or subnormal squares.
     * bf: the exponent field of the column's larger finite bound (0: none, or zero); without
     * C (e = ej) the sums for the common part below in the same pass. */
    for (j = 0; j < n; j++) {
        int f = exp_field(colsq[j]), fl = exp_field(w->lb[j]), fu = exp_field(w->ub[j]), v;
        v = 511 - (f + 1) / 2;
        ej[j] = (int16_t)v;
        tiny |= f == 0;
        same &= v == k->e_jac[j];
        fl = fl == 0x7FF ? 0 : fl, fu = fu == 0x7FF ? 0 : fu; /* no bound */
        bf[j] = (int16_t)(fl > fu ? fl : fu);
        sum += v;
        if (bf[j] > 0 && bf[j] - 1022 - v > raw_top) raw_top = bf[j] - 1022 - v;
    }
    counted = n;
    for (j = 0; tiny && j < n; j++) {
        double col[FP_WLS_MAX_ROWS], an;
        if (exp_field(colsq[j]) != 0) continue;
        for (i = 0; i < m; i++) col[i] = w->A[i * n + j];
        an = vnorm(col, m);
        ej[j] = an > 0.0 ? exponent_within(-expo(an)) : ZERO_COLUMN;
        zero |= ej[j] == ZERO_COLUMN;
        same = 0; /* (not kept: see below) */
    }
    if (w->n_cons == 0) {
        e = ej; /* Jacobi (a zero column: 0, below) */
    } else if (same && !zero) {
        e = k->e_bal;
    } else {
        balance(w, ej, bal);
        memcpy(k->e_jac, ej, (size_t)n * sizeof *ej);
        memcpy(k->e_bal, bal, (size_t)n * sizeof *bal);
    }
    /* the common part out: the exponents' mean, rounded, over the columns not zero in A
     * (the objective's weight is no unit of x); then, when every non-zero finite bound is
     * below 1/2 in the scaled units, all scaled up so that the largest is in [0.5, 1) (the
     * tolerances have a floor of 1 in those units: a problem far below it would pass as
     * feasible within it).  raw_top: the largest exponent of |bound| 2^-e_j. */
    if (e != ej || tiny) { /* (else summed above) */
        sum = counted = 0, raw_top = INT16_MIN;
        for (j = 0; j < n; j++) {
            int v = e[j] == ZERO_COLUMN ? 0 : e[j];
            if (e[j] != ZERO_COLUMN) sum += v, counted++;
            if (bf[j] > 0 && bf[j] - 1022 - v > raw_top) raw_top = bf[j] - 1022 - v;
        }
    }
    if (counted > 0) shift = (int)lround((double)sum / counted);
    /* (a column zero in A keeps v = 0: its bound's exponent moves not with the shift) */
    for (j = 0; zero && j < n; j++)
        if (e[j] == ZERO_COLUMN && bf[j] > 0 && bf[j] - 1022 > bound_top) bound_top = bf[j] - 1022;
    if (raw_top > INT16_MIN && raw_top + shift > bound_top) bound_top = raw_top + shift;
    if (bound_top < 0 && bound_top > INT16_MIN) shift -= bound_top;
    for (j = 0; j < n; j++) {
        /* the limits: A's entries stay below 2^(e_j - ej_j) (their column's norm does), C's
         * below ctop 2^e_j, the finite bounds below 2^bfield 2^-e_j */
        int v = e[j] == ZERO_COLUMN ? 0 : e[j] - shift;
        if (v > 0) {
            int top = hi;
            if (ej[j] != ZERO_COLUMN && ej[j] + SCALE_EXP_MAX < top) top = ej[j] + SCALE_EXP_MAX;
            if (v > top) v = top > 0 ? top : 0;
        } else if (v < lo) {
            v = lo < 0 ? lo : 0;
        }
        any |= v != 0;
        eq &= v == k->c_exp[j];
        if (v != k->exps[j]) { /* (k->sc, k->sc_inv hold 2^+-exps: 1 after setup) */
            k->exps[j] = (int16_t)v;
            k->sc[j] = pow2(v);
            k->sc_inv[j] = pow2(-v);
        }
    }
    *as_c_exp = eq;
    return any;
}

/* A and the bounds with the variables scaled (k->sc set): into k->as, k->lbs, k->ubs.  When
 * A ends in a diagonal block (rows m0 + j = d_j e_j', diag_tail) k->as holds its dense rows
 * only and k->ds the diagonal (Ctx.dg: the iteration reads no other entry of the tail). */
static void scale_a_bounds(const FpWls *w, FpWlsWork *k, int diag_tail, int m0) {
    int i, j, n = w->n_vars, dense = diag_tail ? m0 : w->n_rows;
    const double *restrict sc = k->sc, *restrict si = k->sc_inv;
    for (i = 0; i < dense; i++) {
        const double *restrict a = w->A + i * n;
        double *restrict as = k->as + i * n;
        for (j = 0; j < n; j++) as[j] = a[j] * sc[j];
    }
    for (j = 0; diag_tail && j < n; j++) k->ds[j] = w->A[(m0 + j) * n + j] * sc[j];
    for (j = 0; j < n; j++) {
        k->lbs[j] = w->lb[j] * si[j];
        k->ubs[j] = w->ub[j] * si[j];
    }
}

/* C with the variables scaled (k->sc set): into k->cs. */
static void scale_c(const FpWls *w, FpWlsWork *k) {
    int i, j, n = w->n_vars;
    const double *restrict sc = k->sc;
    for (i = 0; i < w->n_cons; i++) {
        const double *restrict c = w->C + i * n;
        double *restrict cs = k->cs + i * n;
        for (j = 0; j < n; j++) cs[j] = c[j] * sc[j];
    }
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
    /* the scaled problem (wls.c: column_exponents) and its exponents */
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

    /* The variables' scaling (column_exponents): the iteration sees A, C and the bounds
     * scaled, or the caller's own arrays when every exponent is 0. */
    memset(c, 0, sizeof *c);
    scaled = column_exponents(w, k, colsq, c_same, k->c_top, bfield, &same_exp);
    reuse &= same_exp; /* the kept norms are of C scaled by c_exp */
    c->A = w->A, c->C = w->C, c->lb = w->lb, c->ub = w->ub;
    if (scaled) {
        scale_a_bounds(w, k, diag_tail, m0);
        if (!reuse) scale_c(w, k);
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
