/*
 * Bounded, linearly constrained least squares for control allocation:
 *
 *     minimise ||A x - b||^2   subject to   lb <= x <= ub,   C x <= d
 *
 * A primal active-set method on the least-squares form (Haerkegaard's WLS
 * allocation generalised to general inequalities), with a working set of
 * fixed variables (active bounds) and active rows of C.  No heap allocation,
 * no globals, no static mutable state: everything lives in one FpWls struct
 * per problem instance, which holds no pointers (it may be copied with
 * memcpy, e.g. in an FMU state snapshot).
 *
 * Usage:
 *     FpWls w;                               (or a member of a model struct)
 *     fp_wls_setup(&w, n_vars, n_rows, n_cons);
 *     then every sample: write w.A, w.b, w.lb, w.ub, w.C, w.d (or call
 *     fp_wls_set_data) and call fp_wls_solve(&w, max_iter, &result);
 *     the solution is w.x.
 *
 * Data layout: A is n_rows x n_vars and C is n_cons x n_vars, both packed
 * row-major with row length n_vars (element (i, j) at [i * n_vars + j]).
 * Bounds may be -INFINITY / +INFINITY (no bound) and lb[j] == ub[j] (a fixed
 * variable).  d[i] == +INFINITY disables row i of C.
 *
 * Warm start: the working set of the last solve is kept in bound_ws and
 * cons_ws and is the starting guess of the next solve (a caller may also
 * write them).  When that working set is still optimal for the new data the
 * solve ends after one iteration (one factorisation).  fp_wls_reset() forgets
 * it (cold start).
 *
 * Result (never NaN or inf in x):
 *   FP_WLS_OPTIMAL     x is optimal: feasible, and the KKT multipliers are
 *                      non-negative within a tolerance relative to the
 *                      rounding error of the gradient.
 *   FP_WLS_MAX_ITER    the iteration cap was hit.  If a feasible point had been
 *                      found, x is the last (and best: the objective never
 *                      increases in phase 2) feasible iterate; otherwise x is
 *                      the last phase-1 iterate clamped into the bounds.
 *                      result.max_violation tells which.
 *   FP_WLS_INFEASIBLE  no x satisfies the constraints.  x is within the bounds
 *                      and minimises the largest violation of the rows of
 *                      C x <= d, each row scaled to unit norm as given (if the
 *                      cap cut that search short: the best point found).  If a
 *                      zero row of C has d < 0, x is the solution without it.  If
 *                      the bounds cross (lb > ub), x is the previous solution
 *                      clamped into [min(lb,ub), max(lb,ub)].
 *   FP_WLS_BAD_INPUT   NaN anywhere in the data, inf in A, b or C, lb = +inf,
 *                      ub = -inf, d = -inf, any finite magnitude above 1e150,
 *                      max_iter < 1 or sizes not set up.  x is left at the
 *                      previous solution (zero after setup) and the working
 *                      set is unchanged.
 *
 * Units: the solver works on the variables scaled by powers of 2, x_j = 2^e_j z_j, chosen
 * from A's column norms and the rows of C (wls_scale.c, wls_column_exponents), so that a problem
 * given with its variables in other units (columns of A and C times s_j, bounds over s_j)
 * is solved as the same problem: the answer moves only by rounding.  The scaling is exact
 * (powers of 2) and invisible to the caller: x, the working set, the result's objective
 * and max_violation are in the caller's units; the tolerances below act on the scaled
 * problem.  Neither the objective's weight (A and b times a factor) nor the rows' scales of
 * C change the scaling.
 *
 * Numerics: the equality-constrained subproblems are solved by a null-space
 * method with Householder QR (no normal equations), rank-revealing QR with
 * column pivoting and a complete orthogonal decomposition for a rank-deficient
 * A (minimum-norm step), so weight ratios of 1e7 and more are fine.  When A ends
 * in a diagonal block with non-zero diagonal (rows n_rows - n_vars + j = d_j e_j',
 * e.g. regularisation or preference rows) and no row of C is active, the face
 * has full rank and its step comes from a QR that exploits the block: in dual form (one
 * reflector per other row of A) while ||M_F D_F^-1|| is small enough for it, else in
 * primal form (one reflector per free variable, on the other rows plus one) (wls_qr.c).
 * A feasible start comes from projecting onto the constraints with the
 * Goldfarb-Idnani dual method; degenerate vertices are handled with Bland's rule.  See wls.c.
 * An iteration is one factorisation of the working set: O(n^2 (n + rows)) flops.
 *
 * Known limit: a problem whose reduced least-squares problem lies near the rank cut-off
 * (an objective 1e12 times more sensitive in one direction than in another, e.g. the
 * controller's support problem min (c'f - 1e9)^2 + 1e-12 |f|^2 in force_sets.c) can end
 * OPTIMAL with a constraint violated by some 1e-7 of the data's size: its iterates pass
 * through magnitudes 1e8 times the answer's.
 */
#ifndef FP_WLS_H
#define FP_WLS_H

#include "fp_model.h"

#define FP_WLS_MAX_VARS 32 /* variables */
#define FP_WLS_MAX_ROWS 48 /* rows of A */
#define FP_WLS_MAX_CONS 96 /* rows of C (bounds are separate) */

/* Internal: phase 1 adds one variable. */
#define FP_WLS_NV1 (FP_WLS_MAX_VARS + 1)

typedef enum {
    FP_WLS_OPTIMAL = 0,
    FP_WLS_MAX_ITER = 1,
    FP_WLS_INFEASIBLE = 2,
    FP_WLS_BAD_INPUT = 3
} FpWlsStatus;

typedef struct {
    FpWlsStatus status;
    int iterations;        /* factorisations in all (phase 1 included), <= max_iter */
    int phase1_iterations; /* of which spent finding a feasible point */
    int warm_start;        /* 1 if the solve started from a non-empty working set */
    double objective;      /* ||A x - b||^2 at the returned x */
    double max_violation;  /* max(0, lb - x, x - ub, C x - d) at x, in input units */
} FpWlsResult;

/* Private workspace: do not touch (it is here only so FpWls has a known size). */
typedef struct {
    double x[FP_WLS_NV1];
    double p[FP_WLS_NV1];
    double g[FP_WLS_NV1];
    double u[FP_WLS_NV1];
    double v[FP_WLS_NV1];
    double qv[FP_WLS_NV1];
    double nvec[FP_WLS_NV1];
    double zvec[FP_WLS_NV1];
    double rr[FP_WLS_NV1];
    double rb[FP_WLS_NV1];
    double mub[FP_WLS_NV1];
    double mur[FP_WLS_MAX_CONS];
    double r[FP_WLS_MAX_ROWS];
    double cinv[FP_WLS_MAX_CONS];
    double csq[FP_WLS_MAX_CONS], cnorm[FP_WLS_MAX_CONS]; /* row norms of the last solve's C */
    double tw[FP_WLS_MAX_CONS];                          /* minimax phase 1: weights of t */
    /* the variables' scaling x_j = 2^e_j z_j: the scaled A, C and bounds, and the factors */
    double as[FP_WLS_MAX_ROWS * FP_WLS_MAX_VARS];
    double ds[FP_WLS_MAX_VARS]; /* a diagonal tail's diagonal, scaled (as: the dense rows) */
    double cs[FP_WLS_MAX_CONS * FP_WLS_MAX_VARS];
    double lbs[FP_WLS_MAX_VARS], ubs[FP_WLS_MAX_VARS];
    double sc[FP_WLS_MAX_VARS], sc_inv[FP_WLS_MAX_VARS]; /* 2^e_j and 2^-e_j */
    double qm[FP_WLS_NV1 * FP_WLS_NV1];
    double z[FP_WLS_NV1 * FP_WLS_NV1];
    double az[FP_WLS_MAX_ROWS * FP_WLS_NV1];
    double tau_m[FP_WLS_NV1];
    double tau_a[FP_WLS_NV1];
    double tau_c[FP_WLS_NV1];
    int free_idx[FP_WLS_NV1];
    int act_idx[FP_WLS_NV1];
    int perm[FP_WLS_NV1];
    int8_t state[FP_WLS_NV1];
    int8_t act[FP_WLS_MAX_CONS];
    int8_t use[FP_WLS_MAX_CONS];
    /* the last solve found every row of its n_cons x n_vars C usable and kept its norm in
     * csq, cnorm, cinv: c_rows_ok = n_cons, c_cols_ok = n_vars (else -1); the norms are of
     * C scaled by the exponents c_exp (its copy in cs unless every one is 0) */
    int32_t c_rows_ok, c_cols_ok;
    double c_top; /* the largest |C_ij| of the C of c_rows_ok */
    /* exps: the last solve's e_j (sc, sc_inv hold 2^+-exps; all 0 after setup) */
    int16_t exps[FP_WLS_MAX_VARS], c_exp[FP_WLS_MAX_VARS];
    /* the balance of the last solve that computed one: from the Jacobi exponents e_jac to
     * e_bal (before the common part and the limits), a function of C and e_jac (wls.c) */
    int16_t e_jac[FP_WLS_MAX_VARS], e_bal[FP_WLS_MAX_VARS];
} FpWlsWork;

typedef struct {
    /* Sizes, set by fp_wls_setup. */
    int n_vars, n_rows, n_cons;
    /* Problem data, written by the caller (layout: see top of this file). */
    double A[FP_WLS_MAX_ROWS * FP_WLS_MAX_VARS];
    double b[FP_WLS_MAX_ROWS];
    double lb[FP_WLS_MAX_VARS];
    double ub[FP_WLS_MAX_VARS];
    double C[FP_WLS_MAX_CONS * FP_WLS_MAX_VARS];
    double d[FP_WLS_MAX_CONS];
    /* 1 when C (and the sizes) are exactly the last solve's: a constant set's rows, rewritten
     * only when the set changes.  The solve then keeps the last solve's checks and norms of
     * the rows instead of reading C again (d is checked every time).  Set by the caller
     * before each solve that it applies to; every solve and fp_wls_set_data clear it. */
    int32_t c_unchanged;
    /* Solution of the last solve (always finite). */
    double x[FP_WLS_MAX_VARS];
    /* Working set: bound_ws[j] = -1 at lb, +1 at ub, 0 free; cons_ws[i] = 1 active. */
    int8_t bound_ws[FP_WLS_MAX_VARS];
    int8_t cons_ws[FP_WLS_MAX_CONS];
    FpWlsWork work;
} FpWls;

/*
 * Check the sizes against the caps (1 <= n_vars <= FP_WLS_MAX_VARS,
 * 0 <= n_rows <= FP_WLS_MAX_ROWS, 0 <= n_cons <= FP_WLS_MAX_CONS) and clear
 * everything: A, b, C, d = 0, lb = -inf, ub = +inf, x = 0, empty working set.
 * FP_ERROR (and w untouched) on bad sizes or w == NULL.
 */
FpStatus fp_wls_setup(FpWls *w, int n_vars, int n_rows, int n_cons);

/*
 * Copy problem data into w (packed row-major as above).  Any pointer may be
 * NULL to keep the stored values; C and d are ignored when n_cons == 0.
 */
FpStatus fp_wls_set_data(FpWls *w, const double *A, const double *b, const double *lb,
                         const double *ub, const double *C, const double *d);

/* Forget the working set (the next solve starts cold from the previous x). */
void fp_wls_reset(FpWls *w);

/*
 * Solve with at most max_iter iterations (factorisations).  Fills *out when
 * out != NULL.  Returns FP_OK when optimal, FP_WARNING for FP_WLS_MAX_ITER or
 * FP_WLS_INFEASIBLE (x is defined and usable), FP_ERROR for FP_WLS_BAD_INPUT.
 */
FpStatus fp_wls_solve(FpWls *w, int max_iter, FpWlsResult *out);

/*
 * fp_wls_solve without the two figures of the result that cost a pass over the data:
 * out->objective and out->max_violation are -1 (not computed).  Everything else, x and the
 * working set included, is exactly what fp_wls_solve gives.  For control loops that use
 * only the status and the iterations.
 */
FpStatus fp_wls_solve_brief(FpWls *w, int max_iter, FpWlsResult *out);

/*
 * Ask the memory system for the parts of w that the next solve reads and writes (its data
 * as sized by fp_wls_setup and the workspace it uses), so that they arrive together while
 * the caller builds the problem instead of one cache miss at a time during the solve.
 * A hint only (a no-op on compilers without __builtin_prefetch): changes no value.
 */
void fp_wls_prefetch(const FpWls *w);

/* "optimal", "max_iter", "infeasible", "bad_input" (or "unknown"). */
const char *fp_wls_status_name(int status);

#endif
