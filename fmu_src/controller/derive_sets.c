/*
 * Feasible-force sets from the airframe (derive_sets.h has the method): the rotors loaded
 * into the inner model, the seed directions and the affine hull, and the sandwich
 * refinement that picks the directions, in 3-D and within a plane.  The support function
 * (revised simplex and its dual bound) is set_support.c, the incremental 3-D convex hull
 * hull.c; both are called from here only.
 */
#include "derive_sets.h"

#include <math.h>
#include <string.h>

#include "fp_math.h"
#include "hull.h"
#include "set_support.h"

#define SET_FLOOR 0.05     /* floor of the relative excess measure, times the force scale */

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
    s = ctrl_set_support(w, c, p, &h, why, why_size);
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
        d = ctrl_dist_line(w->p[0], u[0], w->p[i]);
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
    r = ctrl_hull_build(&w->outer, (const double(*)[3])w->q, n_c, SET_REL_TOL * qmax);
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
    if (ctrl_hull_build(&w->inner, (const double(*)[3])w->p, w->n_p, eps_in) <= 0 ||
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
        if (newp >= 0 &&
            ctrl_hull_add(&w->inner, (const double(*)[3])w->p, newp, eps_in) < 0)
            break;
        {
            int k = w->n_c - 1, added;
            double sl = w->b[k] - v3_dot(w->c[k], o);
            for (j = 0; j < 3; j++) w->q[k][j] = w->c[k][j] / sl;
            for (j = 0; j < w->n_c; j++) qmax = fmax(qmax, sqrt(v3_dot(w->q[j], w->q[j])));
            added = ctrl_hull_add(&w->outer, (const double(*)[3])w->q, k, SET_REL_TOL * qmax);
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
    s = ctrl_set_lp_start(w, why, why_size);
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
    if (ctrl_hull_build(&w->outer, (const double(*)[3])w->q, n, 1e-12 * qmax) <= 0) return FP_ERROR;
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
