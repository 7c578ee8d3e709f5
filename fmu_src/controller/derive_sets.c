/*
 * Feasible-force sets from the airframe (derive_sets.h has the method).  Three parts: the
 * revised simplex of the support function with its dual bound, an incremental 3-D convex
 * hull (inner points, and the outer polytope's vertices through the dual hull), and the
 * sandwich refinement that picks the directions.
 */
#include "derive_sets.h"

#include <math.h>
#include <stdio.h>
#include <string.h>

#include "fp_math.h"

#define LP_MAX_ITER 4000   /* pivots per support solve */
#define LP_REFACTOR 40     /* pivots between refactorisations of the basis inverse */
#define LP_BLAND_AFTER 25  /* degenerate pivots in a row before Bland's rule */
#define LP_PIVOT_TOL 1e-9
#define SET_REL_TOL 1e-9   /* geometric tolerances, times the force scale */
#define SET_FLOOR 0.05     /* floor of the relative excess measure, times the force scale */
#define COLS_PER_ROTOR (2 * (CTRL_SET_DIRS + 1))
#define ORIGIN_DIR CTRL_SET_DIRS

static void set_why(char *why, int size, const char *text) {
    if (why && size > 0) snprintf(why, (size_t)size, "%s", text);
}

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
static CtrlSetStatus lp_start(CtrlSetWork *w, char *why, int why_size) {
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
static CtrlSetStatus support(CtrlSetWork *w, const double c[3], double p[3], double *h,
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

/* ------------------------------------------------------------------------ */
/* Incremental 3-D convex hull                                              */

static void face_plane(const double (*p)[3], CtrlHullFace *f) {
    double e1[3], e2[3], n[3], len;
    int j;
    for (j = 0; j < 3; j++) {
        e1[j] = p[f->v[1]][j] - p[f->v[0]][j];
        e2[j] = p[f->v[2]][j] - p[f->v[0]][j];
    }
    v3_cross(e1, e2, n);
    len = sqrt(v3_dot(n, n));
    for (j = 0; j < 3; j++) f->n[j] = len > 0.0 ? n[j] / len : 0.0;
    f->off = v3_dot(f->n, p[f->v[0]]);
}

static double dist_line(const double a[3], const double u[3], const double x[3]) {
    double v[3], t;
    int j;
    for (j = 0; j < 3; j++) v[j] = x[j] - a[j];
    t = v3_dot(v, u);
    for (j = 0; j < 3; j++) v[j] -= t * u[j];
    return sqrt(v3_dot(v, v));
}

/* 1 added, 0 inside (within eps), -1 face cap exceeded */
static int hull_add(CtrlHull *h, const double (*p)[3], int k, double eps) {
    int32_t visible[CTRL_SET_MAX_FACES];
    int32_t horizon[3 * CTRL_SET_MAX_FACES][2];
    int f, g, e, n_vis = 0, n_hz = 0, kept = 0;
    for (f = 0; f < h->n_faces; f++) {
        visible[f] = v3_dot(h->f[f].n, p[k]) - h->f[f].off > eps;
        n_vis += visible[f];
    }
    if (n_vis == 0) return 0;
    for (f = 0; f < h->n_faces; f++) {
        if (!visible[f]) continue;
        for (e = 0; e < 3; e++) {
            int32_t a = h->f[f].v[e], b = h->f[f].v[(e + 1) % 3];
            int other = -1;
            for (g = 0; g < h->n_faces && other < 0; g++) {
                int q;
                if (g == f) continue;
                for (q = 0; q < 3; q++)
                    if (h->f[g].v[q] == b && h->f[g].v[(q + 1) % 3] == a) other = g;
            }
            if (other < 0 || !visible[other]) {
                horizon[n_hz][0] = a, horizon[n_hz][1] = b;
                n_hz++;
            }
        }
    }
    if (h->n_faces - n_vis + n_hz > CTRL_SET_MAX_FACES) return -1;
    for (f = 0; f < h->n_faces; f++)
        if (!visible[f]) h->f[kept++] = h->f[f];
    for (e = 0; e < n_hz; e++) {
        CtrlHullFace *nf = &h->f[kept++];
        nf->v[0] = horizon[e][0], nf->v[1] = horizon[e][1], nf->v[2] = k;
        face_plane(p, nf);
    }
    h->n_faces = kept;
    return 1;
}

/* The hull of points 0..n-1: 1, or 0 when they span less than 3-D (within eps), -1 caps. */
static int hull_build(CtrlHull *h, const double (*p)[3], int n, double eps) {
    int i0 = 0, i1 = -1, i2 = -1, i3 = -1, i, j, f;
    double best = eps, u[3], nrm[3], e2[3], d;
    static const int faces[4][3] = {{0, 1, 2}, {0, 3, 1}, {0, 2, 3}, {1, 3, 2}};
    int32_t pick[4];
    h->n_faces = 0;
    for (i = 0; i < n; i++) {
        double v[3] = {p[i][0] - p[i0][0], p[i][1] - p[i0][1], p[i][2] - p[i0][2]};
        d = sqrt(v3_dot(v, v));
        if (d > best) best = d, i1 = i;
    }
    if (i1 < 0) return 0;
    for (j = 0; j < 3; j++) u[j] = (p[i1][j] - p[i0][j]) / best;
    best = eps;
    for (i = 0; i < n; i++) {
        d = dist_line(p[i0], u, p[i]);
        if (d > best) best = d, i2 = i;
    }
    if (i2 < 0) return 0;
    for (j = 0; j < 3; j++) e2[j] = p[i2][j] - p[i0][j];
    v3_cross(u, e2, nrm);
    d = sqrt(v3_dot(nrm, nrm));
    for (j = 0; j < 3; j++) nrm[j] /= d;
    best = eps;
    for (i = 0; i < n; i++) {
        double v[3] = {p[i][0] - p[i0][0], p[i][1] - p[i0][1], p[i][2] - p[i0][2]};
        d = fabs(v3_dot(v, nrm));
        if (d > best) best = d, i3 = i;
    }
    if (i3 < 0) return 0;
    pick[0] = i0, pick[1] = i1, pick[2] = i2, pick[3] = i3;
    for (j = 0; j < 3; j++)
        h->interior[j] = 0.25 * (p[i0][j] + p[i1][j] + p[i2][j] + p[i3][j]);
    for (f = 0; f < 4; f++) {
        CtrlHullFace *hf = &h->f[f];
        hf->v[0] = pick[faces[f][0]], hf->v[1] = pick[faces[f][1]], hf->v[2] = pick[faces[f][2]];
        face_plane(p, hf);
        if (v3_dot(hf->n, h->interior) - hf->off > 0.0) {
            int32_t s = hf->v[1];
            hf->v[1] = hf->v[2], hf->v[2] = s;
            face_plane(p, hf);
        }
    }
    h->n_faces = 4;
    for (i = 0; i < n; i++) {
        if (i == i0 || i == i1 || i == i2 || i == i3) continue;
        if (hull_add(h, p, i, eps) < 0) return -1;
    }
    return 1;
}

/* ------------------------------------------------------------------------ */
/* The set                                                                  */

static void load_rotors(CtrlSetWork *w, const FpRotorSet *rs, int32_t lost_mask) {
    double B[6 * 3 * FP_MAX_ROTORS];
    int i, r = 0;
    fp_effectiveness_b(rs, B);
    w->t_min = rs->k_t * rs->omega_min * rs->omega_min;
    w->t_max = rs->k_t * rs->omega_max * rs->omega_max;
    for (i = 0; i < rs->n; i++) {
        int ga, gb, ia, ib, row, col, k = 0;
        if (lost_mask & ((int32_t)1 << i)) continue;
        w->slot[r] = i;
        w->gamma[r] = rs->gamma[i];
        w->box[r][0] = rs->alpha_min[i], w->box[r][1] = rs->alpha_max[i];
        w->box[r][2] = rs->beta_min[i], w->box[r][3] = rs->beta_max[i];
        for (row = 0; row < 3; row++)
            for (col = 0; col < 3; col++)
                w->M[r][row][col] = B[(3 + row) * 3 * rs->n + 3 * i + col];
        ga = rs->alpha_max[i] > rs->alpha_min[i] ? CTRL_SET_GRID : 1;
        gb = rs->beta_max[i] > rs->beta_min[i] ? CTRL_SET_GRID : 1;
        for (ia = 0; ia < ga; ia++)
            for (ib = 0; ib < gb; ib++) {
                double a = ga > 1 ? rs->alpha_min[i] + (rs->alpha_max[i] - rs->alpha_min[i]) *
                                                           ia / (ga - 1)
                                  : rs->alpha_min[i];
                double b = gb > 1 ? rs->beta_min[i] +
                                        (rs->beta_max[i] - rs->beta_min[i]) * ib / (gb - 1)
                                  : rs->beta_min[i];
                fp_thrust_direction(a, b, rs->gamma[i], w->dir[r][k++]);
            }
        w->n_dirs[r] = k;
        r++;
    }
    w->n = r;
    w->scale = rs->n * w->t_max;
}

/* Evaluate a new direction: its outer facet and (when new) its inner point. */
static CtrlSetStatus add_direction(CtrlSetWork *w, const double c_in[3], int *new_point,
                                   char *why, int why_size) {
    double c[3], p[3], h, len = sqrt(v3_dot(c_in, c_in));
    int j, i;
    CtrlSetStatus s;
    *new_point = -1;
    if (w->n_c >= CTRL_SET_MAX_DIRS) {
        set_why(why, why_size, "too many support directions");
        return CTRL_SET_FAILED;
    }
    for (j = 0; j < 3; j++) c[j] = c_in[j] / len;
    s = support(w, c, p, &h, why, why_size);
    if (s != CTRL_SET_OK) return s;
    for (j = 0; j < 3; j++) w->c[w->n_c][j] = c[j];
    w->b[w->n_c] = h;
    w->n_c++;
    for (i = 0; i < w->n_p; i++) {
        double d[3] = {p[0] - w->p[i][0], p[1] - w->p[i][1], p[2] - w->p[i][2]};
        if (sqrt(v3_dot(d, d)) <= SET_REL_TOL * w->scale) return CTRL_SET_OK;
    }
    for (j = 0; j < 3; j++) w->p[w->n_p][j] = p[j];
    *new_point = w->n_p++;
    return CTRL_SET_OK;
}

/* Dimension of the inner points' affine hull and an orthonormal frame: u[0..dim-1] span it,
 * u[dim..2] its complement. */
static int affine_frame(const CtrlSetWork *w, double u[3][3]) {
    const double tol = 1e-7 * w->scale;
    double best = tol, v[3], d;
    int i, j, i1 = -1, i2 = -1, dim;
    static const double axes[3][3] = {{1, 0, 0}, {0, 1, 0}, {0, 0, 1}};
    for (i = 0; i < w->n_p; i++) {
        for (j = 0; j < 3; j++) v[j] = w->p[i][j] - w->p[0][j];
        d = sqrt(v3_dot(v, v));
        if (d > best) best = d, i1 = i;
    }
    if (i1 < 0) {
        memcpy(u, axes, sizeof axes);
        return 0;
    }
    for (j = 0; j < 3; j++) u[0][j] = (w->p[i1][j] - w->p[0][j]) / best;
    best = tol;
    for (i = 0; i < w->n_p; i++) {
        d = dist_line(w->p[0], u[0], w->p[i]);
        if (d > best) best = d, i2 = i;
    }
    if (i2 < 0) {
        /* complement of a line: the axis least aligned with it, made orthogonal */
        int a = 0;
        for (j = 1; j < 3; j++)
            if (fabs(u[0][j]) < fabs(u[0][a])) a = j;
        v3_cross(u[0], axes[a], u[1]);
        d = sqrt(v3_dot(u[1], u[1]));
        for (j = 0; j < 3; j++) u[1][j] /= d;
        v3_cross(u[0], u[1], u[2]);
        return 1;
    }
    {
        double e[3], t;
        for (j = 0; j < 3; j++) e[j] = w->p[i2][j] - w->p[0][j];
        t = v3_dot(e, u[0]);
        for (j = 0; j < 3; j++) e[j] -= t * u[0][j];
        d = sqrt(v3_dot(e, e));
        for (j = 0; j < 3; j++) u[1][j] = e[j] / d;
        v3_cross(u[0], u[1], u[2]);
    }
    dim = 2;
    for (i = 0; i < w->n_p; i++) {
        for (j = 0; j < 3; j++) v[j] = w->p[i][j] - w->p[0][j];
        if (fabs(v3_dot(v, u[2])) > tol) dim = 3;
    }
    return dim;
}

static void write_facet(double A[][3], double b[], int *n, const double c[3], double h) {
    A[*n][0] = c[0], A[*n][1] = c[1], A[*n][2] = c[2];
    b[*n] = h;
    (*n)++;
}

/* The outer polytope's dual points about o and their hull; marks the non-redundant facets. */
static int outer_hull(CtrlSetWork *w, const double o[3], int n_c, int *count) {
    double qmax = 0.0;
    int j, f, r;
    for (j = 0; j < n_c; j++) {
        double s = w->b[j] - v3_dot(w->c[j], o);
        int k;
        if (!(s > 0.0)) return -1;
        for (k = 0; k < 3; k++) w->q[j][k] = w->c[j][k] / s;
        qmax = fmax(qmax, sqrt(v3_dot(w->q[j], w->q[j])));
    }
    r = hull_build(&w->outer, (const double(*)[3])w->q, n_c, SET_REL_TOL * qmax);
    if (r <= 0) return -1;
    memset(w->used, 0, sizeof w->used);
    for (f = 0; f < w->outer.n_faces; f++)
        for (j = 0; j < 3; j++) w->used[w->outer.f[f].v[j]] = 1;
    *count = 0;
    for (j = 0; j < n_c; j++) *count += w->used[j];
    return 0;
}

/* Sandwich refinement of a full-dimensional set (directions and points seeded). */
static CtrlSetStatus refine(CtrlSetWork *w, int cap, double A[][3], double b[], int32_t *n_out,
                            char *why, int why_size) {
    double o[3] = {0.0, 0.0, 0.0};
    const double eps_in = SET_REL_TOL * w->scale;
    int i, j, f, count = 0, n_out_i = 0;
    for (i = 0; i < w->n_p; i++)
        for (j = 0; j < 3; j++) o[j] += w->p[i][j] / w->n_p;
    if (hull_build(&w->inner, (const double(*)[3])w->p, w->n_p, eps_in) <= 0 ||
        outer_hull(w, o, w->n_c, &count) != 0) {
        set_why(why, why_size, "degenerate hull of the seed directions");
        return CTRL_SET_FAILED;
    }
    while (count < cap && w->n_c < CTRL_SET_MAX_DIRS) {
        double best = -1.0, best_abs = 0.0, qmax = 0.0;
        int best_f = -1, newp, g;
        CtrlSetStatus s;
        for (f = 0; f < w->inner.n_faces; f++) {
            const CtrlHullFace *F = &w->inner.f[f];
            double ex = -INFINITY, at = 0.0;
            int dup = 0;
            for (j = 0; j < w->n_c && !dup; j++) dup = v3_dot(F->n, w->c[j]) > 1.0 - 1e-12;
            if (dup) continue;
            for (g = 0; g < w->outer.n_faces; g++) {
                const CtrlHullFace *G = &w->outer.f[g];
                double v[3], e;
                if (!(G->off > 0.0)) continue;
                for (j = 0; j < 3; j++) v[j] = o[j] + G->n[j] / G->off;
                e = v3_dot(F->n, v) - F->off;
                if (e > ex) ex = e, at = sqrt(v3_dot(v, v));
            }
            if (ex / (at + SET_FLOOR * w->scale) > best) {
                best = ex / (at + SET_FLOOR * w->scale), best_abs = ex, best_f = f;
            }
        }
        if (best_f < 0 || best_abs <= 1e-7 * w->scale) break; /* inner and outer agree */
        s = add_direction(w, w->inner.f[best_f].n, &newp, why, why_size);
        if (s != CTRL_SET_OK) return s;
        if (newp >= 0 && hull_add(&w->inner, (const double(*)[3])w->p, newp, eps_in) < 0) break;
        {
            int k = w->n_c - 1, added;
            double sl = w->b[k] - v3_dot(w->c[k], o);
            for (j = 0; j < 3; j++) w->q[k][j] = w->c[k][j] / sl;
            for (j = 0; j < w->n_c; j++) qmax = fmax(qmax, sqrt(v3_dot(w->q[j], w->q[j])));
            added = hull_add(&w->outer, (const double(*)[3])w->q, k, SET_REL_TOL * qmax);
            if (added < 0) break;
            memset(w->used, 0, sizeof w->used);
            for (f = 0; f < w->outer.n_faces; f++)
                for (j = 0; j < 3; j++) w->used[w->outer.f[f].v[j]] = 1;
            count = 0;
            for (j = 0; j < w->n_c; j++) count += w->used[j];
        }
        if (count > cap) { /* the last facet pushed it over: without it */
            w->n_c--;
            if (outer_hull(w, o, w->n_c, &count) != 0) {
                set_why(why, why_size, "degenerate outer hull");
                return CTRL_SET_FAILED;
            }
            break;
        }
    }
    for (j = 0; j < w->n_c; j++)
        if (w->used[j] && n_out_i < cap) write_facet(A, b, &n_out_i, w->c[j], w->b[j]);
    *n_out = n_out_i;
    return CTRL_SET_OK;
}

/* ------------------------------------------------------------------------ */
/* A planar set: the sandwich refinement within its plane                   */

#define PLANE_MAX CTRL_SET_MAX_DIRS

typedef struct {
    int n_d, n_p;
    double d[PLANE_MAX][2], h[PLANE_MAX]; /* in-plane directions and their support */
    double p[PLANE_MAX][2];               /* inner points, in-plane coordinates */
    double v[PLANE_MAX * 2][2];           /* vertices of the outer polygon */
    int n_v;
    int hull[PLANE_MAX], n_hull;          /* the inner points' hull, counter-clockwise */
    int used[PLANE_MAX];                  /* direction j carries an outer edge */
} CtrlPlane;

static double cross2(const double o[2], const double a[2], const double b[2]) {
    return (a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0]);
}

/* Convex hull of the inner points (monotone chain on an index order sorted by x, y). */
static void plane_inner_hull(CtrlPlane *pl, double eps) {
    int order[PLANE_MAX], i, j, k = 0, lower;
    for (i = 0; i < pl->n_p; i++) order[i] = i;
    for (i = 1; i < pl->n_p; i++) /* insertion sort: at most PLANE_MAX points */
        for (j = i; j > 0; j--) {
            const double *a = pl->p[order[j - 1]], *b = pl->p[order[j]];
            if (a[0] < b[0] || (a[0] == b[0] && a[1] <= b[1])) break;
            k = order[j], order[j] = order[j - 1], order[j - 1] = k;
        }
    k = 0;
    for (i = 0; i < pl->n_p; i++) {
        while (k >= 2 && cross2(pl->p[pl->hull[k - 2]], pl->p[pl->hull[k - 1]],
                                pl->p[order[i]]) <= eps)
            k--;
        pl->hull[k++] = order[i];
    }
    lower = k + 1;
    for (i = pl->n_p - 2; i >= 0; i--) {
        while (k >= lower && cross2(pl->p[pl->hull[k - 2]], pl->p[pl->hull[k - 1]],
                                    pl->p[order[i]]) <= eps)
            k--;
        pl->hull[k++] = order[i];
    }
    pl->n_hull = k > 1 ? k - 1 : k;
}

/* Vertices of the outer polygon {x : d_j . x <= h_j}: the pairwise intersections that
 * satisfy every constraint; marks the directions that carry an edge. */
static int plane_outer(CtrlPlane *pl, double tol) {
    int i, j, k, count = 0;
    pl->n_v = 0;
    memset(pl->used, 0, sizeof pl->used);
    for (i = 0; i < pl->n_d; i++)
        for (j = i + 1; j < pl->n_d; j++) {
            double det = pl->d[i][0] * pl->d[j][1] - pl->d[i][1] * pl->d[j][0], x[2];
            int ok = 1;
            if (fabs(det) < 1e-12) continue;
            x[0] = (pl->h[i] * pl->d[j][1] - pl->h[j] * pl->d[i][1]) / det;
            x[1] = (pl->d[i][0] * pl->h[j] - pl->d[j][0] * pl->h[i]) / det;
            for (k = 0; k < pl->n_d && ok; k++)
                ok = pl->d[k][0] * x[0] + pl->d[k][1] * x[1] <= pl->h[k] + tol;
            if (!ok || pl->n_v >= PLANE_MAX * 2) continue;
            pl->v[pl->n_v][0] = x[0], pl->v[pl->n_v][1] = x[1];
            pl->n_v++;
            pl->used[i] = pl->used[j] = 1;
        }
    for (i = 0; i < pl->n_d; i++) count += pl->used[i];
    return count;
}

/* Support along the in-plane direction dir2: its offset and inner point, kept. */
static CtrlSetStatus plane_add(CtrlSetWork *w, CtrlPlane *pl, const double u[3][3],
                               const double o[3], const double dir2[2], char *why,
                               int why_size) {
    double c[3], rel[3];
    int j, newp;
    CtrlSetStatus s;
    if (pl->n_d >= PLANE_MAX) {
        set_why(why, why_size, "too many support directions in the plane");
        return CTRL_SET_FAILED;
    }
    for (j = 0; j < 3; j++) c[j] = dir2[0] * u[0][j] + dir2[1] * u[1][j];
    s = add_direction(w, c, &newp, why, why_size);
    if (s != CTRL_SET_OK) return s;
    pl->d[pl->n_d][0] = dir2[0], pl->d[pl->n_d][1] = dir2[1];
    pl->h[pl->n_d] = w->b[w->n_c - 1] - v3_dot(w->c[w->n_c - 1], o);
    pl->n_d++;
    if (newp >= 0 && pl->n_p < PLANE_MAX) {
        for (j = 0; j < 3; j++) rel[j] = w->p[newp][j] - o[j];
        pl->p[pl->n_p][0] = v3_dot(rel, u[0]);
        pl->p[pl->n_p][1] = v3_dot(rel, u[1]);
        pl->n_p++;
    }
    return CTRL_SET_OK;
}

/* The planar set's in-plane facets: seeded with 8 directions, then the inner polygon's
 * edge beyond which the outer polygon sticks out most (relative to the force magnitude,
 * as in 3-D) gives the next, until `cap` facets carry an edge or the two agree. */
static CtrlSetStatus refine_plane(CtrlSetWork *w, const double u[3][3], int cap, double A[][3],
                                  double b[], int *n, char *why, int why_size) {
    CtrlPlane pl;
    double o[3];
    const double tol = SET_REL_TOL * w->scale;
    int k, j, count;
    CtrlSetStatus s;
    memset(&pl, 0, sizeof pl);
    for (j = 0; j < 3; j++) o[j] = w->p[0][j];
    for (k = 0; k < w->n_p && pl.n_p < PLANE_MAX; k++) { /* the points found so far */
        double rel[3] = {w->p[k][0] - o[0], w->p[k][1] - o[1], w->p[k][2] - o[2]};
        pl.p[pl.n_p][0] = v3_dot(rel, u[0]);
        pl.p[pl.n_p][1] = v3_dot(rel, u[1]);
        pl.n_p++;
    }
    for (k = 0; k < 8; k++) {
        double t = 2.0 * 3.14159265358979323846 * k / 8.0, d2[2];
        d2[0] = cos(t), d2[1] = sin(t);
        if ((s = plane_add(w, &pl, u, o, d2, why, why_size)) != CTRL_SET_OK) return s;
    }
    count = plane_outer(&pl, tol);
    while (count < cap && pl.n_d < PLANE_MAX) {
        double best = -1.0, best_abs = 0.0, best_n[2] = {0.0, 0.0};
        int e;
        plane_inner_hull(&pl, tol * tol);
        for (e = 0; e < pl.n_hull; e++) {
            const double *a = pl.p[pl.hull[e]], *c = pl.p[pl.hull[(e + 1) % pl.n_hull]];
            double nn[2] = {c[1] - a[1], a[0] - c[0]}, len = hypot(nn[0], nn[1]), ex = -1.0;
            double at = 0.0;
            int dup = 0, q;
            if (!(len > tol)) continue;
            nn[0] /= len, nn[1] /= len;
            for (q = 0; q < pl.n_d && !dup; q++)
                dup = nn[0] * pl.d[q][0] + nn[1] * pl.d[q][1] > 1.0 - 1e-12;
            if (dup) continue;
            for (q = 0; q < pl.n_v; q++) {
                double ev = nn[0] * (pl.v[q][0] - a[0]) + nn[1] * (pl.v[q][1] - a[1]);
                if (ev > ex) {
                    double v3[3];
                    for (j = 0; j < 3; j++)
                        v3[j] = o[j] + pl.v[q][0] * u[0][j] + pl.v[q][1] * u[1][j];
                    ex = ev, at = sqrt(v3_dot(v3, v3));
                }
            }
            if (ex / (at + SET_FLOOR * w->scale) > best)
                best = ex / (at + SET_FLOOR * w->scale), best_abs = ex, best_n[0] = nn[0],
                best_n[1] = nn[1];
        }
        if (best < 0.0 || best_abs <= 1e-7 * w->scale) break; /* inner and outer agree */
        if ((s = plane_add(w, &pl, u, o, best_n, why, why_size)) != CTRL_SET_OK) return s;
        count = plane_outer(&pl, tol);
        if (count > cap) { /* the last direction pushed it over: without it */
            pl.n_d--;
            count = plane_outer(&pl, tol);
            break;
        }
    }
    for (k = 0; k < pl.n_d && count > 0; k++) {
        double c[3];
        if (!pl.used[k]) continue;
        for (j = 0; j < 3; j++) c[j] = pl.d[k][0] * u[0][j] + pl.d[k][1] * u[1][j];
        write_facet(A, b, n, c, pl.h[k] + v3_dot(c, o));
    }
    return CTRL_SET_OK;
}

CtrlSetStatus ctrl_derive_force_set(const FpRotorSet *rs, int32_t lost_mask, int cap,
                                    CtrlSetWork *w, double A[][3], double b[], int32_t *n_out,
                                    int32_t *dim, char *why, int why_size) {
    static const double seeds[14][3] = {{1, 0, 0},  {-1, 0, 0},  {0, 1, 0},   {0, -1, 0},
                                        {0, 0, 1},  {0, 0, -1},  {1, 1, 1},   {1, 1, -1},
                                        {1, -1, 1}, {1, -1, -1}, {-1, 1, 1},  {-1, 1, -1},
                                        {-1, -1, 1}, {-1, -1, -1}};
    double u[3][3];
    int i, k, newp, d, round, n = 0;
    CtrlSetStatus s;
    *n_out = 0;
    *dim = -1;
    set_why(why, why_size, "");
    if (cap < 8 || rs->n < 1 || rs->n > FP_MAX_ROTORS) {
        set_why(why, why_size, "invalid size");
        return CTRL_SET_FAILED;
    }
    load_rotors(w, rs, lost_mask);
    w->n_c = w->n_p = 0;
    if (w->n == 0) return CTRL_SET_EMPTY;
    s = lp_start(w, why, why_size);
    if (s != CTRL_SET_OK) return s;
    for (i = 0; i < 14; i++)
        if ((s = add_direction(w, seeds[i], &newp, why, why_size)) != CTRL_SET_OK) return s;
    /* the affine hull: probe across it until the probes find nothing new */
    d = affine_frame(w, u);
    for (round = 0; round < 3 && d < 3; round++) {
        int before = d;
        for (k = d; k < 3; k++) {
            double neg[3] = {-u[k][0], -u[k][1], -u[k][2]};
            if ((s = add_direction(w, u[k], &newp, why, why_size)) != CTRL_SET_OK ||
                (s = add_direction(w, neg, &newp, why, why_size)) != CTRL_SET_OK)
                return s;
        }
        d = affine_frame(w, u);
        if (d == before) break;
    }
    *dim = d;
    if (d == 3) return refine(w, cap, A, b, n_out, why, why_size);
    /* flat: opposite pairs across the affine hull, and a fan within a plane */
    for (k = 0; k < 3; k++) {
        int sign;
        if (k < d && d != 1) continue;
        for (sign = 1; sign >= -1; sign -= 2) {
            double c[3] = {sign * u[k][0], sign * u[k][1], sign * u[k][2]};
            if ((s = add_direction(w, c, &newp, why, why_size)) != CTRL_SET_OK) return s;
            write_facet(A, b, &n, w->c[w->n_c - 1], w->b[w->n_c - 1]);
        }
    }
    if (d == 2) {
        s = refine_plane(w, (const double(*)[3])u, cap - n, A, b, &n, why, why_size);
        if (s != CTRL_SET_OK) return s;
    }
    *n_out = n;
    return CTRL_SET_OK;
}

FpStatus ctrl_polytope_max(const double A[][3], const double b[], int n, const double o[3],
                           const double c[][3], int n_c, CtrlSetWork *w, double h[]) {
    double qmax = 0.0;
    int j, f, k;
    if (n < 4 || n > CTRL_SET_MAX_DIRS) return FP_ERROR;
    for (j = 0; j < n; j++) {
        double s = b[j] - v3_dot(A[j], o);
        if (!(s > 0.0)) return FP_ERROR;
        for (k = 0; k < 3; k++) w->q[j][k] = A[j][k] / s;
        qmax = fmax(qmax, sqrt(v3_dot(w->q[j], w->q[j])));
    }
    if (hull_build(&w->outer, (const double(*)[3])w->q, n, 1e-12 * qmax) <= 0) return FP_ERROR;
    for (k = 0; k < n_c; k++) h[k] = -INFINITY;
    for (f = 0; f < w->outer.n_faces; f++) {
        const CtrlHullFace *G = &w->outer.f[f];
        double v[3];
        if (!(G->off > 1e-300)) return FP_ERROR; /* the origin on the dual hull: unbounded */
        for (j = 0; j < 3; j++) v[j] = o[j] + G->n[j] / G->off;
        for (k = 0; k < n_c; k++) h[k] = fmax(h[k], v3_dot(c[k], v));
    }
    return FP_OK;
}
