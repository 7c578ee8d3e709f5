/*
 * Incremental 3-D convex hull of the force-set derivation (hull.h): the first tetrahedron
 * of four points spanning 3-D, then points added one by one (the faces they see replaced by
 * a fan from their horizon).  Used by derive_sets.c for the inner hull of the attainable
 * points and the dual hull of the outer polytope.
 */
#include <math.h>

#include "fp_math.h"
#include "hull.h"

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

double ctrl_dist_line(const double a[3], const double u[3], const double x[3]) {
    double v[3], t;
    int j;
    for (j = 0; j < 3; j++) v[j] = x[j] - a[j];
    t = v3_dot(v, u);
    for (j = 0; j < 3; j++) v[j] -= t * u[j];
    return sqrt(v3_dot(v, v));
}

/* 1 added, 0 inside (within eps), -1 face cap exceeded */
int ctrl_hull_add(CtrlHull *h, const double (*p)[3], int k, double eps) {
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
int ctrl_hull_build(CtrlHull *h, const double (*p)[3], int n, double eps) {
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
        d = ctrl_dist_line(p[i0], u, p[i]);
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
        if (ctrl_hull_add(h, p, i, eps) < 0) return -1;
    }
    return 1;
}
