/* Ground contact of the landing gear (contact.h). */
#include "contact.h"

#include <math.h>
#include <string.h>

#include "fp_math.h"

/* 1 / the apparent mass at lever arm r_b (body) along the world direction e_w. */
static double apparent_inverse_mass(const ContactParams *p, const double *r_w,
                                    const double r_b[3], const double e_w[3]) {
    double e_b[3], rxe[3], irxe[3];
    int i;
    for (i = 0; i < 3; i++) /* e in the body frame: R^T e */
        e_b[i] = r_w[i] * e_w[0] + r_w[3 + i] * e_w[1] + r_w[6 + i] * e_w[2];
    v3_cross(r_b, e_b, rxe);
    m3_mul_v(p->inertia_inv, rxe, irxe);
    return 1.0 / p->mass + v3_dot(rxe, irxe);
}

/* Point i's world position into at; its penetration (> 0: below the ground). */
static double point_at(const ContactParams *p, int i, const double pos[3], const double *r,
                       double at[3]) {
    double arm[3];
    int j;
    m3_mul_v(r, p->pos + 3 * i, arm);
    for (j = 0; j < 3; j++) at[j] = pos[j] + arm[j];
    return at[2] - p->ground_z;
}

/* The friction force along the ground (x, y) of a point at `at` moving at v with normal force
 * fn, and whether it slips (k s + c v_t beyond mu fn). */
static int friction(const ContactParams *p, int i, const double at[3], const double v[3],
                    double fn, double ft[2]) {
    double s[2] = {0.0, 0.0}, mag, cap = p->friction * fn;
    int j;
    if (p->anchored & ((int32_t)1 << i))
        for (j = 0; j < 2; j++) s[j] = at[j] - p->anchor[2 * i + j];
    for (j = 0; j < 2; j++) ft[j] = -(p->stiffness * s[j] + p->damping * v[j]);
    mag = sqrt(ft[0] * ft[0] + ft[1] * ft[1]);
    if (!(mag > cap)) return 0;
    for (j = 0; j < 2; j++) ft[j] = mag > 0.0 ? ft[j] * (cap / mag) : 0.0;
    return 1;
}

void contact_wrench(const ContactParams *p, const double pos[3], const double vel[3],
                    const double *r, const double rate[3], ContactWrench *out) {
    int i, j;
    memset(out, 0, sizeof *out);
    for (i = 0; i < p->n; i++) {
        double at[3], wxr[3], wxr_w[3], v[3], f_w[3], f_b[3], t_b[3], ft[2], fn;
        double d = point_at(p, i, pos, r, at);
        if (!(d > 0.0)) continue;
        out->flags |= (int32_t)1 << i;
        v3_cross(rate, p->pos + 3 * i, wxr);
        m3_mul_v(r, wxr, wxr_w);
        for (j = 0; j < 3; j++) v[j] = vel[j] + wxr_w[j];
        fn = fmax(0.0, p->stiffness * d + p->damping * v[2]);
        out->normal[i] = fn;
        friction(p, i, at, v, fn, ft);
        f_w[0] = ft[0];
        f_w[1] = ft[1];
        f_w[2] = -fn;
        for (j = 0; j < 3; j++) {
            out->force_w[j] += f_w[j];
            f_b[j] = r[j] * f_w[0] + r[3 + j] * f_w[1] + r[6 + j] * f_w[2]; /* R^T f */
        }
        v3_cross(p->pos + 3 * i, f_b, t_b);
        for (j = 0; j < 3; j++) out->torque_b[j] += t_b[j];
    }
}

int contact_deepest(const ContactParams *p, const double pos[3], const double *r,
                    double *depth) {
    int i, deepest = -1;
    *depth = 0.0;
    for (i = 0; i < p->n; i++) {
        double at[3], d = point_at(p, i, pos, r, at);
        if (d > *depth) {
            *depth = d;
            deepest = i;
        }
    }
    return deepest;
}

void contact_depths(const ContactParams *p, const double pos[3], const double *r, double *depth) {
    int i;
    for (i = 0; i < p->n; i++) {
        double at[3];
        depth[i] = point_at(p, i, pos, r, at);
    }
}

int32_t contact_update_anchors(const ContactParams *p, const double pos[3], const double *r,
                               double *anchor) {
    int32_t anchored = 0;
    int i, j;
    for (i = 0; i < p->n; i++) {
        double at[3], s[2], len, reach;
        double d = point_at(p, i, pos, r, at);
        if (!(d > 0.0)) continue; /* lifted off: no anchor */
        anchored |= (int32_t)1 << i;
        if (!(p->anchored & ((int32_t)1 << i))) { /* touched down here */
            anchor[2 * i] = at[0];
            anchor[2 * i + 1] = at[1];
            continue;
        }
        /* the elastic reach: k |s| at most mu F_n (F_n of the penetration alone) */
        reach = p->friction * d;
        for (j = 0; j < 2; j++) s[j] = at[j] - anchor[2 * i + j];
        len = sqrt(s[0] * s[0] + s[1] * s[1]);
        if (len > reach) /* slipping: the anchor follows, the spring at its limit */
            for (j = 0; j < 2; j++) anchor[2 * i + j] = at[j] - s[j] * (reach / len);
    }
    return anchored;
}

double contact_fastest_rate(const ContactParams *p) {
    static const double upright[9] = {1, 0, 0, 0, 1, 0, 0, 0, 1};
    static const double axes[3][3] = {{1, 0, 0}, {0, 1, 0}, {0, 0, 1}};
    double worst = 0.0;
    int a, i;
    for (a = 0; a < 3; a++) {
        double cw = 0.0, kw = 0.0;
        for (i = 0; i < p->n; i++) {
            double w = apparent_inverse_mass(p, upright, p->pos + 3 * i, axes[a]);
            cw += p->damping * w;
            kw += p->stiffness * w;
        }
        worst = fmax(worst, cw + sqrt(kw));
    }
    return worst;
}
