/*
 * The variables' units of the active-set solver (see wls.c): the iteration works on z,
 * x_j = 2^e_j z_j, and this file finds the exponents e_j (Jacobi, balanced against C in the
 * style of Curtis and Reid, the common part removed) and makes the scaled copies of A, C
 * and the bounds in the workspace.  Called from the driver (wls.c) only; calls no other
 * file of the solver.
 */
#include <stdint.h>
#include <string.h>

#include "fp_math.h"
#include "wls_internal.h"

/* The exponent field of |v| (0 for a zero, 0x7FF for inf or NaN). */
static int exp_field(double v) {
    uint64_t u;
    memcpy(&u, &v, sizeof u);
    return (int)((u >> 52) & 0x7FF);
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
 * The balance of the columns (wls_column_exponents): the real l minimising, with each row
 * i of C free to scale by 2^r_i and E_ij = expo(|C_ij|) over its non-zero entries,
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
int wls_column_exponents(const FpWls *w, FpWlsWork *k, const double *colsq, int c_same,
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
void wls_scale_a_bounds(const FpWls *w, FpWlsWork *k, int diag_tail, int m0) {
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
void wls_scale_c(const FpWls *w, FpWlsWork *k) {
    int i, j, n = w->n_vars;
    const double *restrict sc = k->sc;
    for (i = 0; i < w->n_cons; i++) {
        const double *restrict c = w->C + i * n;
        double *restrict cs = k->cs + i * n;
        for (j = 0; j < n; j++) cs[j] = c[j] * sc[j];
    }
}
