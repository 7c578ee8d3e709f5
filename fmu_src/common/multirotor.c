#include "multirotor.h"

#include <math.h>
#include <stdio.h>
#include <string.h>

#include "fp_math.h"

void fp_rotor_rotation(double alpha, double beta, double gamma, double r[3][3]) {
    double rz[3][3], rx[3][3], ry[3][3];
    rot_z(gamma, rz);
    rot_x(alpha, rx);
    rot_y(beta, ry);
    m3_mul(&rz[0][0], &rx[0][0], &r[0][0]);
    m3_mul(&r[0][0], &ry[0][0], &r[0][0]);
}

static void thrust_direction_sc(double sa, double ca, double sb, double cb, double sg,
                                double cg, double t[3]) {
    double lx = -sb, ly = sa * cb, lz = -ca * cb; /* -Rx(alpha) Ry(beta) e_z */
    t[0] = cg * lx - sg * ly;
    t[1] = sg * lx + cg * ly;
    t[2] = lz;
}

void fp_thrust_direction(double alpha, double beta, double gamma, double t[3]) {
    double sa = sin(alpha), ca = cos(alpha), sb = sin(beta), cb = cos(beta);
    double cg = cos(gamma), sg = sin(gamma);
    thrust_direction_sc(sa, ca, sb, cb, sg, cg, t);
}

void fp_rotor_trig_mounts(const FpRotorSet *rs, FpRotorTrig *tr) {
    int i;
    for (i = 0; i < rs->n && i < FP_MAX_ROTORS; i++) {
        tr->cg[i] = cos(rs->gamma[i]);
        tr->sg[i] = sin(rs->gamma[i]);
    }
}

void fp_rotor_trig_tilts(const FpRotorSet *rs, const double alpha[], const double beta[],
                         FpRotorTrig *tr) {
    int i;
    for (i = 0; i < rs->n && i < FP_MAX_ROTORS; i++) {
        /* read once: a store to tr could alias alpha or beta, and a reload would keep the
         * compiler from taking each sin and cos pair in one call */
        double a = alpha[i], b = beta[i];
        tr->sa[i] = sin(a);
        tr->ca[i] = cos(a);
        tr->sb[i] = sin(b);
        tr->cb[i] = cos(b);
    }
}

static void tilt_from_direction_sc(const double f[3], double sg, double cg, double *alpha,
                                   double *beta) {
    double n = sqrt(v3_dot(f, f));
    double lx, ly, lz, s;
    if (!(n > 0.0)) {
        *alpha = 0.0;
        *beta = 0.0;
        return;
    }
    /* undo the mounting rotation: l = Rz(-gamma) f / |f| */
    lx = (cg * f[0] + sg * f[1]) / n;
    ly = (-sg * f[0] + cg * f[1]) / n;
    lz = f[2] / n;
    s = -lx;
    if (s > 1.0) s = 1.0;
    if (s < -1.0) s = -1.0;
    *beta = asin(s);
    *alpha = atan2(ly, -lz);
}

void fp_tilt_from_direction(const double f[3], double gamma, double *alpha, double *beta) {
    double cg = cos(gamma), sg = sin(gamma);
    tilt_from_direction_sc(f, sg, cg, alpha, beta);
}

void fp_paper_hexacopter(FpAirframe *af) {
    const double pi = 3.14159265358979323846;
    int i;
    memset(af, 0, sizeof *af);
    af->mass = 0.6656;
    af->inertia[0][0] = 0.0041;
    af->inertia[1][1] = 0.0048;
    af->inertia[2][2] = 0.0599;
    af->g = 9.81;
    af->tau_motor = 1.0 / 53.94;
    af->tau_servo = 1.0 / 53.94;
    af->n_rotors = 6;
    af->k_t = 1.14e-4;
    af->k_d = 1.14e-6;
    for (i = 0; i < FP_MAX_ROTORS; i++) af->rotor_dir[i] = 1;
    for (i = 0; i < 6; i++) {
        double azimuth = (30.0 + 60.0 * i) * pi / 180.0; /* hexa "X", gamma = arm azimuth */
        af->rotor_pos[i][0] = 0.15 * cos(azimuth);
        af->rotor_pos[i][1] = 0.15 * sin(azimuth);
        af->rotor_dir[i] = (i % 2 == 0) ? 1 : -1;
        af->rotor_gamma[i] = azimuth;
        af->alpha_min[i] = af->beta_min[i] = -40.0 * pi / 180.0;
        af->alpha_max[i] = af->beta_max[i] = 40.0 * pi / 180.0;
    }
    af->omega_min = 0.0;
    af->omega_max = 2000.0 * 2.0 * pi / 60.0;
}

void fp_rotor_set_of(const FpAirframe *af, FpRotorSet *rs) {
    memset(rs, 0, sizeof *rs);
    rs->n = af->n_rotors;
    rs->k_t = af->k_t;
    rs->k_d = af->k_d;
    memcpy(rs->pos, af->rotor_pos, sizeof rs->pos);
    memcpy(rs->dir, af->rotor_dir, sizeof rs->dir);
    memcpy(rs->gamma, af->rotor_gamma, sizeof rs->gamma);
    memcpy(rs->alpha_min, af->alpha_min, sizeof rs->alpha_min);
    memcpy(rs->alpha_max, af->alpha_max, sizeof rs->alpha_max);
    memcpy(rs->beta_min, af->beta_min, sizeof rs->beta_min);
    memcpy(rs->beta_max, af->beta_max, sizeof rs->beta_max);
    rs->omega_min = af->omega_min;
    rs->omega_max = af->omega_max;
}

static void thrust_direction_jacobian_sc(double sa, double ca, double sb, double cb,
                                         double sg, double cg, double dt_dalpha[3],
                                         double dt_dbeta[3]) {
    /* t = Rz(gamma) [-sb, sa cb, -ca cb] */
    double ax = 0.0, ay = ca * cb, az = sa * cb;
    double bx = -cb, by = -sa * sb, bz = ca * sb;
    dt_dalpha[0] = cg * ax - sg * ay;
    dt_dalpha[1] = sg * ax + cg * ay;
    dt_dalpha[2] = az;
    dt_dbeta[0] = cg * bx - sg * by;
    dt_dbeta[1] = sg * bx + cg * by;
    dt_dbeta[2] = bz;
}

void fp_thrust_direction_jacobian(double alpha, double beta, double gamma, double dt_dalpha[3],
                                  double dt_dbeta[3]) {
    double sa = sin(alpha), ca = cos(alpha), sb = sin(beta), cb = cos(beta);
    double cg = cos(gamma), sg = sin(gamma);
    thrust_direction_jacobian_sc(sa, ca, sb, cb, sg, cg, dt_dalpha, dt_dbeta);
}

static void torque_arm(const FpRotorSet *rs, int i, double m[3][3]) {
    /* S(d_i) + r c_i I3 */
    const double *d = rs->pos[i];
    double rc = rs->k_d / rs->k_t * (double)rs->dir[i];
    m[0][0] = rc; m[0][1] = -d[2]; m[0][2] = d[1];
    m[1][0] = d[2]; m[1][1] = rc; m[1][2] = -d[0];
    m[2][0] = -d[1]; m[2][1] = d[0]; m[2][2] = rc;
}

static FpStatus check_set(const FpRotorSet *rs) {
    if (rs == NULL || rs->n < 1 || rs->n > FP_MAX_ROTORS || !(rs->k_t > 0.0)) return FP_ERROR;
    return FP_OK;
}

FpStatus fp_effectiveness_b(const FpRotorSet *rs, double *b) {
    int i, j, k, cols;
    if (check_set(rs) != FP_OK || b == NULL) return FP_ERROR;
    cols = 3 * rs->n;
    for (i = 0; i < rs->n; i++) {
        double m[3][3];
        torque_arm(rs, i, m);
        for (j = 0; j < 3; j++)
            for (k = 0; k < 3; k++) {
                b[j * cols + 3 * i + k] = j == k ? 1.0 : 0.0;
                b[(3 + j) * cols + 3 * i + k] = m[j][k];
            }
    }
    return FP_OK;
}

FpStatus fp_effectiveness_bprime(const FpRotorSet *rs, const double alpha[], const double beta[],
                                 double *bp) {
    int i, j, k, cols;
    if (check_set(rs) != FP_OK || bp == NULL || alpha == NULL || beta == NULL) return FP_ERROR;
    cols = 3 * rs->n;
    for (i = 0; i < rs->n; i++) {
        double m[3][3], r[3][3], mr[3][3];
        torque_arm(rs, i, m);
        fp_rotor_rotation(alpha[i], beta[i], rs->gamma[i], r);
        m3_mul(&m[0][0], &r[0][0], &mr[0][0]);
        for (j = 0; j < 3; j++)
            for (k = 0; k < 3; k++) {
                bp[j * cols + 3 * i + k] = r[j][k];
                bp[(3 + j) * cols + 3 * i + k] = mr[j][k];
            }
    }
    return FP_OK;
}

FpStatus fp_effectiveness_b2prime(const FpRotorSet *rs, const double alpha[], const double beta[],
                                  const double omega[], double *b2p) {
    FpRotorTrig tr;
    if (check_set(rs) != FP_OK || b2p == NULL) return FP_ERROR;
    fp_rotor_trig_mounts(rs, &tr);
    fp_rotor_trig_tilts(rs, alpha, beta, &tr);
    return fp_effectiveness_b2prime_trig(rs, &tr, omega, b2p);
}

FpStatus fp_effectiveness_b2prime_trig(const FpRotorSet *rs, const FpRotorTrig *tr,
                                       const double omega[], double *b2p) {
    int i, j, k, cols;
    if (check_set(rs) != FP_OK || b2p == NULL || tr == NULL) return FP_ERROR;
    cols = 3 * rs->n;
    for (i = 0; i < rs->n; i++) {
        double m[3][3], t[3], da[3], db[3], c[3][3];
        double thrust = rs->k_t * omega[i] * omega[i];
        torque_arm(rs, i, m);
        thrust_direction_sc(tr->sa[i], tr->ca[i], tr->sb[i], tr->cb[i], tr->sg[i], tr->cg[i], t);
        thrust_direction_jacobian_sc(tr->sa[i], tr->ca[i], tr->sb[i], tr->cb[i], tr->sg[i],
                                     tr->cg[i], da, db);
        for (j = 0; j < 3; j++) { /* d(force)/d(alpha, beta, omega) */
            c[j][0] = thrust * da[j];
            c[j][1] = thrust * db[j];
            c[j][2] = 2.0 * rs->k_t * omega[i] * t[j];
        }
        for (k = 0; k < 3; k++) {
            double col[3], torque[3];
            for (j = 0; j < 3; j++) col[j] = c[j][k];
            m3_mul_v(&m[0][0], col, torque);
            for (j = 0; j < 3; j++) {
                b2p[j * cols + 3 * i + k] = col[j];
                b2p[(3 + j) * cols + 3 * i + k] = torque[j];
            }
        }
    }
    return FP_OK;
}

void fp_rotor_wrench(const FpRotorSet *rs, const double alpha[], const double beta[],
                     const double omega[], const double efficiency[], double f_b[3],
                     double tau_b[3]) {
    FpRotorTrig tr;
    fp_rotor_trig_mounts(rs, &tr);
    fp_rotor_trig_tilts(rs, alpha, beta, &tr);
    fp_rotor_wrench_trig(rs, &tr, omega, efficiency, f_b, tau_b);
}

void fp_rotor_wrench_trig(const FpRotorSet *rs, const FpRotorTrig *tr, const double omega[],
                          const double efficiency[], double f_b[3], double tau_b[3]) {
    int i, j;
    for (j = 0; j < 3; j++) f_b[j] = tau_b[j] = 0.0;
    for (i = 0; i < rs->n && i < FP_MAX_ROTORS; i++) {
        double t[3], f[3], arm[3], thrust;
        thrust_direction_sc(tr->sa[i], tr->ca[i], tr->sb[i], tr->cb[i], tr->sg[i], tr->cg[i], t);
        thrust = rs->k_t * omega[i] * omega[i] * (efficiency ? efficiency[i] : 1.0);
        for (j = 0; j < 3; j++) f[j] = thrust * t[j];
        v3_cross(rs->pos[i], f, arm);
        for (j = 0; j < 3; j++) {
            f_b[j] += f[j];
            tau_b[j] += arm[j] + rs->k_d / rs->k_t * (double)rs->dir[i] * f[j];
        }
    }
}

void fp_rotor_wrench_one(const FpRotorSet *rs, const FpRotorTrig *tr, int i, double omega,
                         double w[6]) {
    double t[3], f[3], arm[3], thrust = rs->k_t * omega * omega;
    int j;
    thrust_direction_sc(tr->sa[i], tr->ca[i], tr->sb[i], tr->cb[i], tr->sg[i], tr->cg[i], t);
    for (j = 0; j < 3; j++) f[j] = thrust * t[j];
    v3_cross(rs->pos[i], f, arm);
    for (j = 0; j < 3; j++) {
        w[j] = f[j];
        w[3 + j] = arm[j] + rs->k_d / rs->k_t * (double)rs->dir[i] * f[j];
    }
}

int fp_rotor_tilts(const FpRotorSet *rs, int i) {
    return rs->alpha_max[i] > rs->alpha_min[i] || rs->beta_max[i] > rs->beta_min[i];
}

FpStatus fp_cholesky_factor(double *a, int n) {
    if (n < 1 || n > 32) return FP_ERROR;
    return fp_chol_factor(a, n, 0.0) ? FP_OK : FP_ERROR;
}

void fp_cholesky_backsolve(const double *l, int n, double *b) { fp_chol_backsolve(l, n, b); }

FpStatus fp_cholesky_solve(double *a, int n, double *b) {
    if (fp_cholesky_factor(a, n) != FP_OK) return FP_ERROR;
    fp_cholesky_backsolve(a, n, b);
    return FP_OK;
}

FpStatus fp_preferred_config(const FpRotorSet *rs, const double wrench[6], double alpha[],
                             double beta[], double omega[], char *why, int why_size) {
    FpPreferredSplit ps;
    if (fp_preferred_prepare(rs, &ps, why, why_size) != FP_OK) return FP_ERROR;
    return fp_preferred_apply(rs, &ps, wrench, alpha, beta, omega, why, why_size);
}

FpStatus fp_preferred_prepare(const FpRotorSet *rs, FpPreferredSplit *ps, char *why,
                              int why_size) {
    /* Columns of the reduced effectiveness matrix: 3 per tilting rotor (its
     * force vector), 1 per fixed rotor (its thrust along t_i). */
    double (*cols)[3 * FP_MAX_ROTORS] = ps->cols;
    double *gram = ps->gram;
    int32_t *first = ps->first;
    int i, j, k, m = 0;
    double trace = 0.0;
    if (why != NULL && why_size > 0) why[0] = '\0';
    ps->status = FP_ERROR;
    ps->m = 0;
    if (check_set(rs) != FP_OK) {
        if (why) snprintf(why, (size_t)why_size, "invalid rotor set");
        return FP_ERROR;
    }
    for (i = 0; i < rs->n; i++) {
        ps->cg[i] = cos(rs->gamma[i]);
        ps->sg[i] = sin(rs->gamma[i]);
    }
    for (i = 0; i < rs->n; i++) {
        double arm[3][3];
        torque_arm(rs, i, arm);
        first[i] = m;
        if (fp_rotor_tilts(rs, i)) {
            for (k = 0; k < 3; k++, m++)
                for (j = 0; j < 3; j++) {
                    cols[j][m] = j == k ? 1.0 : 0.0;
                    cols[3 + j][m] = arm[j][k];
                }
        } else {
            double t[3], at[3];
            fp_thrust_direction(rs->alpha_min[i], rs->beta_min[i], rs->gamma[i], t);
            m3_mul_v(&arm[0][0], t, at);
            for (j = 0; j < 3; j++) {
                cols[j][m] = t[j];
                cols[3 + j][m] = at[j];
            }
            m++;
        }
    }
    /* x = C^T (C C^T + eps I)^-1 w: the minimum-norm least-squares split; the
     * tiny regularization keeps rank-deficient sets (quadrotor) solvable. */
    for (i = 0; i < 6; i++)
        for (j = 0; j < 6; j++) {
            double s = 0.0;
            for (k = 0; k < m; k++) s += cols[i][k] * cols[j][k];
            gram[i * 6 + j] = s;
        }
    for (i = 0; i < 6; i++) trace += gram[i * 6 + i];
    for (i = 0; i < 6; i++) gram[i * 6 + i] += 1e-12 * trace;
    if (fp_cholesky_factor(gram, 6) != FP_OK) {
        if (why) snprintf(why, (size_t)why_size, "rotor geometry gives a singular allocation");
        return FP_ERROR;
    }
    ps->m = m;
    ps->status = FP_OK;
    return FP_OK;
}

FpStatus fp_preferred_apply(const FpRotorSet *rs, const FpPreferredSplit *ps,
                            const double wrench[6], double alpha[], double beta[],
                            double omega[], char *why, int why_size) {
    const double (*cols)[3 * FP_MAX_ROTORS] = ps->cols;
    const double *gram = ps->gram;
    const int32_t *first = ps->first;
    double y[6], x[3 * FP_MAX_ROTORS], back[6];
    int i, k, m = ps->m, pass;
    double scale = 0.0, err = 0.0;
    FpStatus status = FP_OK;
    if (why != NULL && why_size > 0) why[0] = '\0';
    if (ps->status != FP_OK || check_set(rs) != FP_OK || m < 1 || m > 3 * rs->n) {
        if (why) snprintf(why, (size_t)why_size, "invalid rotor set");
        return FP_ERROR;
    }
    for (k = 0; k < m; k++) x[k] = 0.0;
    for (i = 0; i < 6; i++) y[i] = wrench[i];
    /* two passes: the second (iterative refinement) removes the regularization's
     * and the normal equations' rounding error from the reproduced wrench */
    for (pass = 0; pass < 2; pass++) {
        fp_cholesky_backsolve(gram, 6, y);
        for (k = 0; k < m; k++)
            for (i = 0; i < 6; i++) x[k] += cols[i][k] * y[i];
        err = scale = 0.0;
        for (i = 0; i < 6; i++) {
            back[i] = 0.0;
            for (k = 0; k < m; k++) back[i] += cols[i][k] * x[k];
            y[i] = wrench[i] - back[i];
            err += y[i] * y[i];
            scale += wrench[i] * wrench[i];
        }
    }
    for (i = 0; i < rs->n; i++) {
        double thrust;
        if (fp_rotor_tilts(rs, i)) {
            const double *f = &x[first[i]];
            thrust = sqrt(v3_dot(f, f));
            tilt_from_direction_sc(f, ps->sg[i], ps->cg[i], &alpha[i], &beta[i]);
        } else {
            thrust = x[first[i]];
            alpha[i] = rs->alpha_min[i];
            beta[i] = rs->beta_min[i];
            if (thrust < 0.0 && status == FP_OK) {
                status = FP_ERROR;
                if (why)
                    snprintf(why, (size_t)why_size, "rotor %d would need negative thrust %.4g N",
                             i + 1, thrust);
            }
        }
        omega[i] = sqrt(fabs(thrust) / rs->k_t);
        if (status != FP_OK) continue;
        if (omega[i] > rs->omega_max || omega[i] < rs->omega_min) {
            status = FP_ERROR;
            if (why)
                snprintf(why, (size_t)why_size,
                         "rotor %d would need omega %.6g rad/s outside [%.6g, %.6g]", i + 1,
                         omega[i], rs->omega_min, rs->omega_max);
        } else if (alpha[i] < rs->alpha_min[i] - 1e-12 || alpha[i] > rs->alpha_max[i] + 1e-12 ||
                   beta[i] < rs->beta_min[i] - 1e-12 || beta[i] > rs->beta_max[i] + 1e-12) {
            status = FP_ERROR;
            if (why)
                snprintf(why, (size_t)why_size,
                         "rotor %d would need tilt alpha %.4g, beta %.4g rad outside its limits",
                         i + 1, alpha[i], beta[i]);
        }
    }
    if (status == FP_OK && err > 1e-12 * (scale > 1.0 ? scale : 1.0)) {
        status = FP_ERROR;
        if (why)
            snprintf(why, (size_t)why_size,
                     "the rotors cannot produce this wrench (residual %.3g)", sqrt(err));
    }
    return status;
}
