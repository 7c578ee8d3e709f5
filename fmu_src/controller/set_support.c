/*
 * The support function of a feasible-force set (derive_sets.h has the method): the revised
 * simplex on the inner model of the rotors with zero torque, whose maximiser is an inner
 * point, and its dual bound, the outer offset valid for the continuous servo box (each
 * rotor's term in closed form).  Used by derive_sets.c through set_support.h.
 */
#include <math.h>

#include "fp_math.h"
#include "set_support.h"

#define LP_MAX_ITER 4000   /* pivots per support solve */
#define LP_REFACTOR 40     /* pivots between refactorisations of the basis inverse */
#define LP_BLAND_AFTER 25  /* degenerate pivots in a row before Bland's rule */
#define LP_PIVOT_TOL 1e-9
#define COLS_PER_ROTOR (2 * (CTRL_SET_DIRS + 1))
#define ORIGIN_DIR CTRL_SET_DIRS

/* ------------------------------------------------------------------------ */
/* One rotor's forces                                                       */

/* max over the servo box of g . t(alpha, beta, gamma), in closed form: with g' = Rz(gamma)^T g,
 * g . t = -g'1 sin(beta) + cos(beta) (g'2 sin(alpha) - g'3 cos(alpha)); cos(beta) >= 0 on the
 * box (|beta| <= pi/2), so the best alpha does not depend on beta, and each factor is a
 * cosine whose maximum over an interval is its peak or an end. */
static double cosine_max(double a, double b, double lo, double hi) {
    /* max of a sin(x) + b cos(x) over [lo, hi] within [-pi/2, pi/2] */
    double peak = atan2(a, b);
    double v_lo, v_hi;
    if (peak >= lo && peak <= hi) return hypot(a, b);
    v_lo = a * sin(lo) + b * cos(lo);
    v_hi = a * sin(hi) + b * cos(hi);
    return v_lo > v_hi ? v_lo : v_hi;
}

static double best_alignment(const double g[3], double gamma, const double box[4]) {
    double cg = cos(gamma), sg = sin(gamma);
    double g1 = cg * g[0] + sg * g[1], g2 = -sg * g[0] + cg * g[1], g3 = g[2];
    double m = cosine_max(g2, -g3, box[0], box[1]);
    return cosine_max(-g1, m, box[2], box[3]);
}

/* max over conv U_r of g . f */
static double rotor_support(const CtrlSetWork *w, int r, const double g[3]) {
    double s = best_alignment(g, w->gamma[r], w->box[r]);
    return s >= 0.0 ? w->t_max * s : w->t_min * s;
}

/* g = c - M_r^T y */
static void reduced_direction(const CtrlSetWork *w, int r, const double c[3], const double y[3],
                              double g[3]) {
    int j;
    for (j = 0; j < 3; j++)
        g[j] = c[j] - (w->M[r][0][j] * y[0] + w->M[r][1][j] * y[1] + w->M[r][2][j] * y[2]);
}

/* ------------------------------------------------------------------------ */
/* The LP: maximise c . sum f over the inner model with zero torque          */

/* Column ids: rotor r, thrust direction k (ORIGIN_DIR: the zero force), level 0 (T_max) or 1
 * (T_min); artificial of row i: -1 - i. */
static int32_t col_id(int r, int k, int level) { return r * COLS_PER_ROTOR + 2 * k + level; }

static void col_force(const CtrlSetWork *w, int32_t id, double f[3]) {
    int r = id / COLS_PER_ROTOR, k = (id % COLS_PER_ROTOR) / 2, level = id % 2;
    double t = level ? w->t_min : w->t_max;
    if (k == ORIGIN_DIR) {
        f[0] = f[1] = f[2] = 0.0;
        return;
    }
    f[0] = t * w->dir[r][k][0], f[1] = t * w->dir[r][k][1], f[2] = t * w->dir[r][k][2];
}

static void col_vector(const CtrlSetWork *w, int32_t id, double a[CTRL_LP_MAX_ROWS]) {
    double f[3];
    int i, r;
    for (i = 0; i < w->m; i++) a[i] = 0.0;
    if (id < 0) {
        a[-1 - id] = 1.0;
        return;
    }
    r = id / COLS_PER_ROTOR;
    col_force(w, id, f);
    for (i = 0; i < 3; i++) a[i] = v3_dot(w->M[r][i], f);
    a[3 + r] = 1.0;
}

static double rhs(int row) { return row < 3 ? 0.0 : 1.0; }

/* binv = B^-1 from the basis columns, xb = B^-1 rhs (Gauss-Jordan, partial pivoting). */
static int lp_refactor(CtrlSetWork *w) {
    double t[CTRL_LP_MAX_ROWS][2 * CTRL_LP_MAX_ROWS], col[CTRL_LP_MAX_ROWS];
    int m = w->m, i, j, k;
    for (j = 0; j < m; j++) {
        col_vector(w, w->basis[j], col);
        for (i = 0; i < m; i++) t[i][j] = col[i];
    }
    for (i = 0; i < m; i++)
        for (j = 0; j < m; j++) t[i][m + j] = i == j ? 1.0 : 0.0;
    for (k = 0; k < m; k++) {
        int p = k;
        double piv;
        for (i = k + 1; i < m; i++)
            if (fabs(t[i][k]) > fabs(t[p][k])) p = i;
        if (!(fabs(t[p][k]) > 1e-12)) return 0;
        if (p != k)
            for (j = 0; j < 2 * m; j++) {
                double s = t[k][j];
                t[k][j] = t[p][j], t[p][j] = s;
            }
        piv = t[k][k];
        for (j = 0; j < 2 * m; j++) t[k][j] /= piv;
        for (i = 0; i < m; i++)
            if (i != k && t[i][k] != 0.0) {
                double f = t[i][k];
                for (j = 0; j < 2 * m; j++) t[i][j] -= f * t[k][j];
            }
    }
    for (i = 0; i < m; i++) {
        w->xb[i] = 0.0;
        for (j = 0; j < m; j++) {
            w->binv[i][j] = t[i][m + j];
            w->xb[i] += t[i][m + j] * rhs(j);
        }
        if (w->xb[i] < 0.0 && w->xb[i] > -1e-9) w->xb[i] = 0.0;
    }
    w->pivots = 0;
    return 1;
}

/* Cost of a basic column: phase 1 maximises minus the artificials' sum. */
static double col_cost(const CtrlSetWork *w, int32_t id, const double *c) {
    double f[3];
    if (id < 0) return c ? 0.0 : -1.0;
    if (!c) return 0.0;
    col_force(w, id, f);
    return v3_dot(c, f);
}

/* Simplex iterations from the current (feasible) basis; c NULL: phase 1.  On return pi
 * holds the duals [y; z].  0: optimal, 1: iteration limit or singular basis. */
static int lp_iterate(CtrlSetWork *w, const double *c, double pi[CTRL_LP_MAX_ROWS]) {
    const double tol = SET_REL_TOL * w->scale;
    int iter, degenerate = 0, m = w->m;
    for (iter = 0; iter < LP_MAX_ITER; iter++) {
        double cb[CTRL_LP_MAX_ROWS], a[CTRL_LP_MAX_ROWS], dv[CTRL_LP_MAX_ROWS];
        double best = tol, theta = INFINITY, zero[3] = {0.0, 0.0, 0.0};
        int32_t enter = -1;
        int i, j, r, leave = -1, bland = degenerate >= LP_BLAND_AFTER;
        if (w->pivots >= LP_REFACTOR && !lp_refactor(w)) return 1;
        for (i = 0; i < m; i++) cb[i] = col_cost(w, w->basis[i], c);
        for (j = 0; j < m; j++) {
            pi[j] = 0.0;
            for (i = 0; i < m; i++) pi[j] += cb[i] * w->binv[i][j];
        }
        /* pricing: the reduced cost of column (r, k, level) is T (c - M_r^T y).t_k - z_r */
        for (r = 0; r < w->n && !(bland && enter >= 0); r++) {
            double g[3], z = pi[3 + r];
            int k;
            reduced_direction(w, r, c ? c : zero, pi, g);
            for (k = 0; k < w->n_dirs[r]; k++) {
                double s = v3_dot(g, w->dir[r][k]);
                double d_max = w->t_max * s - z;
                if (d_max > best) {
                    best = bland ? tol : d_max, enter = col_id(r, k, 0);
                    if (bland) break;
                }
                if (w->t_min > 0.0) {
                    double d_min = w->t_min * s - z;
                    if (d_min > best) {
                        best = bland ? tol : d_min, enter = col_id(r, k, 1);
                        if (bland) break;
                    }
                }
            }
            if (w->t_min == 0.0 && -z > best && !(bland && enter >= 0))
                best = bland ? tol : -z, enter = col_id(r, ORIGIN_DIR, 0);
        }
        if (enter < 0) return 0;
        col_vector(w, enter, a);
        for (i = 0; i < m; i++) {
            dv[i] = 0.0;
            for (j = 0; j < m; j++) dv[i] += w->binv[i][j] * a[j];
        }
        /* ratio test; in phase 2 a basic artificial is fixed at zero */
        for (i = 0; i < m; i++) {
            double ratio;
            if (c && w->basis[i] < 0) {
                if (fabs(dv[i]) <= LP_PIVOT_TOL) continue;
                ratio = 0.0;
            } else {
                if (dv[i] <= LP_PIVOT_TOL) continue;
                ratio = w->xb[i] / dv[i];
                if (ratio < 0.0) ratio = 0.0;
            }
            if (ratio < theta - 1e-15 ||
                (ratio <= theta + 1e-15 && leave >= 0 &&
                 (bland ? w->basis[i] < w->basis[leave] : fabs(dv[i]) > fabs(dv[leave])))) {
                theta = ratio, leave = i;
            }
        }
        if (leave < 0) return 1; /* unbounded: cannot happen for a bounded inner model */
        degenerate = theta <= 0.0 ? degenerate + 1 : 0;
        for (i = 0; i < m; i++) {
            w->xb[i] -= theta * dv[i];
            if (w->xb[i] < 0.0 && w->xb[i] > -1e-9) w->xb[i] = 0.0;
        }
        w->xb[leave] = theta;
        {
            double p = dv[leave];
            for (j = 0; j < m; j++) w->binv[leave][j] /= p;
            for (i = 0; i < m; i++)
                if (i != leave && dv[i] != 0.0)
                    for (j = 0; j < m; j++) w->binv[i][j] -= dv[i] * w->binv[leave][j];
        }
        w->basis[leave] = enter;
        w->pivots++;
        w->lp_pivots++;
    }
    return 1;
}

/* The LP of the rotors in w, started feasible: CTRL_SET_EMPTY when zero torque is out of
 * reach. */
CtrlSetStatus ctrl_set_lp_start(CtrlSetWork *w, char *why, int why_size) {
    double pi[CTRL_LP_MAX_ROWS];
    int i, r;
    w->m = 3 + w->n;
    for (i = 0; i < 3; i++) w->basis[i] = -1 - i;
    for (r = 0; r < w->n; r++)
        w->basis[3 + r] = w->t_min == 0.0 ? col_id(r, ORIGIN_DIR, 0) : -1 - (3 + r);
    if (!lp_refactor(w)) {
        set_why(why, why_size, "singular starting basis");
        return CTRL_SET_FAILED;
    }
    if (w->t_min > 0.0) {
        double infeas = 0.0;
        if (lp_iterate(w, NULL, pi) != 0) {
            set_why(why, why_size, "the feasibility LP hit its iteration limit");
            return CTRL_SET_FAILED;
        }
        for (i = 0; i < w->m; i++)
            if (w->basis[i] < 0) infeas += w->xb[i];
        if (infeas > 1e-7) return CTRL_SET_EMPTY;
    }
    return CTRL_SET_OK;
}

/* Support along unit c: the inner point p (an attainable force) and the outer offset h. */
CtrlSetStatus ctrl_set_support(CtrlSetWork *w, const double c[3], double p[3], double *h,
                               char *why, int why_size) {
    double pi[CTRL_LP_MAX_ROWS], inner, outer = 0.0;
    int i, r;
    w->lp_solves++;
    if (lp_iterate(w, c, pi) != 0) {
        set_why(why, why_size, "a support LP hit its iteration limit");
        return CTRL_SET_FAILED;
    }
    p[0] = p[1] = p[2] = 0.0;
    for (i = 0; i < w->m; i++)
        if (w->basis[i] >= 0) {
            double f[3];
            col_force(w, w->basis[i], f);
            p[0] += w->xb[i] * f[0], p[1] += w->xb[i] * f[1], p[2] += w->xb[i] * f[2];
        }
    for (r = 0; r < w->n; r++) {
        double g[3];
        reduced_direction(w, r, c, pi, g);
        outer += rotor_support(w, r, g);
    }
    inner = v3_dot(c, p);
    *h = outer > inner ? outer : inner; /* weak duality: outer >= inner up to rounding */
    return CTRL_SET_OK;
}
