/* Small fixed-size vector, rotation and quaternion helpers (header-only). */
#ifndef FP_MATH_H
#define FP_MATH_H

#include <math.h>
#include <stddef.h>

/* 1 if all n values are finite. */
static inline int fp_all_finite(const double *v, size_t n) {
    size_t i;
    for (i = 0; i < n; i++)
        if (!isfinite(v[i])) return 0;
    return 1;
}

/* x limited to [lo, hi] (lo <= hi); NaN stays NaN, so a non-finite result is never hidden
 * behind a bound (fmin/fmax would return the bound) and the compiler needs no call. */
static inline double fp_clamp(double x, double lo, double hi) {
    return x < lo ? lo : (x > hi ? hi : x);
}

/* Cholesky factor L of the SPD n x n row-major matrix a in place (its lower triangle; the
 * upper one is not read).  0 when a pivot is not above min_pivot (or NaN), else 1. */
static inline int fp_chol_factor(double *a, int n, double min_pivot) {
    int i, j, k;
    for (j = 0; j < n; j++) {
        double d = a[j * n + j];
        for (k = 0; k < j; k++) d -= a[j * n + k] * a[j * n + k];
        if (!(d > min_pivot)) return 0;
        d = sqrt(d);
        a[j * n + j] = d;
        for (i = j + 1; i < n; i++) {
            double s = a[i * n + j];
            for (k = 0; k < j; k++) s -= a[i * n + k] * a[j * n + k];
            a[i * n + j] = s / d;
        }
    }
    return 1;
}

/* Solve L L' x = b in place with a factor from fp_chol_factor. */
static inline void fp_chol_backsolve(const double *l, int n, double *b) {
    int i, k;
    for (i = 0; i < n; i++) {
        double s = b[i];
        for (k = 0; k < i; k++) s -= l[i * n + k] * b[k];
        b[i] = s / l[i * n + i];
    }
    for (i = n - 1; i >= 0; i--) {
        double s = b[i];
        for (k = i + 1; k < n; k++) s -= l[k * n + i] * b[k];
        b[i] = s / l[i * n + i];
    }
}

static inline void v3_cross(const double a[3], const double b[3], double out[3]) {
    double x = a[1] * b[2] - a[2] * b[1];
    double y = a[2] * b[0] - a[0] * b[2];
    double z = a[0] * b[1] - a[1] * b[0];
    out[0] = x;
    out[1] = y;
    out[2] = z;
}

static inline double v3_dot(const double a[3], const double b[3]) {
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
}

/* Matrices are row-major double[9] (pass &m[0][0] for a double[3][3]). */
static inline void m3_mul_v(const double *m, const double v[3], double out[3]) {
    double x = m[0] * v[0] + m[1] * v[1] + m[2] * v[2];
    double y = m[3] * v[0] + m[4] * v[1] + m[5] * v[2];
    double z = m[6] * v[0] + m[7] * v[1] + m[8] * v[2];
    out[0] = x;
    out[1] = y;
    out[2] = z;
}

static inline void m3_mul(const double *a, const double *b, double *out) {
    double t[9];
    int i, j;
    for (i = 0; i < 3; i++)
        for (j = 0; j < 3; j++)
            t[3 * i + j] = a[3 * i] * b[j] + a[3 * i + 1] * b[3 + j] + a[3 * i + 2] * b[6 + j];
    for (i = 0; i < 9; i++) out[i] = t[i];
}

/* Elementary rotations (active, right-handed). */
static inline void rot_x(double a, double r[3][3]) {
    double c = cos(a), s = sin(a);
    r[0][0] = 1; r[0][1] = 0; r[0][2] = 0;
    r[1][0] = 0; r[1][1] = c; r[1][2] = -s;
    r[2][0] = 0; r[2][1] = s; r[2][2] = c;
}

static inline void rot_y(double a, double r[3][3]) {
    double c = cos(a), s = sin(a);
    r[0][0] = c; r[0][1] = 0; r[0][2] = s;
    r[1][0] = 0; r[1][1] = 1; r[1][2] = 0;
    r[2][0] = -s; r[2][1] = 0; r[2][2] = c;
}

static inline void rot_z(double a, double r[3][3]) {
    double c = cos(a), s = sin(a);
    r[0][0] = c; r[0][1] = -s; r[0][2] = 0;
    r[1][0] = s; r[1][1] = c; r[1][2] = 0;
    r[2][0] = 0; r[2][1] = 0; r[2][2] = 1;
}

/* R_B^W = Rz(psi) Ry(theta) Rx(phi) (row-major) and its partial derivatives in phi and
 * theta, from one sin and cos of each angle (the products of the elementary rotations
 * written out: d/dphi turns R's columns [c1 c2 c3] into [0 c3 -c2]).  Either derivative may
 * be NULL. */
static inline void rot_zyx_jacobian(const double e[3], double r[9], double dr_dphi[9],
                                    double dr_dtheta[9]) {
    double sp = sin(e[0]), cp = cos(e[0]), st = sin(e[1]), ct = cos(e[1]);
    double ss = sin(e[2]), cs = cos(e[2]);
    r[0] = ct * cs, r[1] = sp * st * cs - cp * ss, r[2] = cp * st * cs + sp * ss;
    r[3] = ct * ss, r[4] = sp * st * ss + cp * cs, r[5] = cp * st * ss - sp * cs;
    r[6] = -st, r[7] = sp * ct, r[8] = cp * ct;
    if (dr_dphi != NULL) {
        int i;
        for (i = 0; i < 3; i++) {
            dr_dphi[3 * i] = 0.0;
            dr_dphi[3 * i + 1] = r[3 * i + 2];
            dr_dphi[3 * i + 2] = -r[3 * i + 1];
        }
    }
    if (dr_dtheta != NULL) {
        dr_dtheta[0] = -st * cs, dr_dtheta[1] = sp * ct * cs, dr_dtheta[2] = cp * ct * cs;
        dr_dtheta[3] = -st * ss, dr_dtheta[4] = sp * ct * ss, dr_dtheta[5] = cp * ct * ss;
        dr_dtheta[6] = -ct, dr_dtheta[7] = -sp * st, dr_dtheta[8] = -cp * st;
    }
}

/* Quaternion [w, x, y, z] of R_B^W = Rz(psi) Ry(theta) Rx(phi). */
static inline void quat_from_euler(const double e[3], double q[4]) {
    double cr = cos(0.5 * e[0]), sr = sin(0.5 * e[0]);
    double cp = cos(0.5 * e[1]), sp = sin(0.5 * e[1]);
    double cy = cos(0.5 * e[2]), sy = sin(0.5 * e[2]);
    q[0] = cr * cp * cy + sr * sp * sy;
    q[1] = sr * cp * cy - cr * sp * sy;
    q[2] = cr * sp * cy + sr * cp * sy;
    q[3] = cr * cp * sy - sr * sp * cy;
}

static inline void euler_from_quat(const double q[4], double e[3]) {
    double w = q[0], x = q[1], y = q[2], z = q[3];
    double s = 2.0 * (w * y - z * x);
    if (s > 1.0) s = 1.0;
    if (s < -1.0) s = -1.0;
    e[0] = atan2(2.0 * (w * x + y * z), 1.0 - 2.0 * (x * x + y * y));
    e[1] = asin(s);
    e[2] = atan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z));
}

/* Rotation matrix R_B^W (body to world) of a unit quaternion. */
static inline void rot_from_quat(const double q[4], double r[3][3]) {
    double w = q[0], x = q[1], y = q[2], z = q[3];
    r[0][0] = 1 - 2 * (y * y + z * z); r[0][1] = 2 * (x * y - w * z); r[0][2] = 2 * (x * z + w * y);
    r[1][0] = 2 * (x * y + w * z); r[1][1] = 1 - 2 * (x * x + z * z); r[1][2] = 2 * (y * z - w * x);
    r[2][0] = 2 * (x * z - w * y); r[2][1] = 2 * (y * z + w * x); r[2][2] = 1 - 2 * (x * x + y * y);
}

static inline void quat_normalize(double q[4]) {
    double n = sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]);
    int i;
    if (!(n > 0.0)) {
        q[0] = 1.0; q[1] = q[2] = q[3] = 0.0;
        return;
    }
    if (q[0] < 0.0) n = -n; /* keep w >= 0: one sign for one attitude */
    for (i = 0; i < 4; i++) q[i] /= n;
}

#endif
