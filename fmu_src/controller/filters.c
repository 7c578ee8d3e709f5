/*
 * The measurement filter H(s) of the FullPoseController: its exact discretization and one
 * sample of every filtered signal (measurements, the position, velocity and attitude
 * references, the actuator feedback), and the filtered quantities a sample works with.
 */
#include <string.h>

#include "fp_math.h"
#include "stages.h"

/* exp(a) of a 3x3 matrix: scaling and squaring with a Taylor series. */
static void expm3(double a[3][3], double out[3][3]) {
    double norm = 0.0, s[3][3], term[3][3], tmp[3][3];
    int i, j, k, squarings = 0, n;
    for (i = 0; i < 3; i++)
        for (j = 0; j < 3; j++) norm = fmax(norm, fabs(a[i][j]));
    while (norm > 0.5 && squarings < 60) {
        norm *= 0.5;
        squarings++;
    }
    for (i = 0; i < 3; i++)
        for (j = 0; j < 3; j++) {
            s[i][j] = ldexp(a[i][j], -squarings);
            out[i][j] = term[i][j] = (i == j) ? 1.0 : 0.0;
        }
    for (n = 1; n <= 16; n++) { /* Taylor series of exp(s), |s| <= 0.5 */
        for (i = 0; i < 3; i++)
            for (j = 0; j < 3; j++) {
                double v = 0.0;
                for (k = 0; k < 3; k++) v += term[i][k] * s[k][j];
                tmp[i][j] = v / n;
            }
        for (i = 0; i < 3; i++)
            for (j = 0; j < 3; j++) {
                term[i][j] = tmp[i][j];
                out[i][j] += tmp[i][j];
            }
    }
    for (; squarings > 0; squarings--) {
        m3_mul(&out[0][0], &out[0][0], &tmp[0][0]);
        memcpy(out, tmp, sizeof tmp);
    }
}

void ctrl_filter_discretize(double wn, double zeta, double Ts, double phi[2][2],
                            double gamma[2]) {
    /* states [y, y'], y'' = wn^2 (u - y) - 2 zeta wn y' ; augmented with the held input */
    double a[3][3] = {{0.0, 1.0, 0.0}, {0.0, 0.0, 0.0}, {0.0, 0.0, 0.0}}, e[3][3];
    int i, j;
    a[1][0] = -wn * wn;
    a[1][1] = -2.0 * zeta * wn;
    a[1][2] = wn * wn;
    for (i = 0; i < 3; i++)
        for (j = 0; j < 3; j++) a[i][j] *= Ts;
    expm3(a, e);
    for (i = 0; i < 2; i++) {
        phi[i][0] = e[i][0];
        phi[i][1] = e[i][1];
        gamma[i] = e[i][2];
    }
}

double ctrl_unwrap(double angle, double *raw, double *unwrapped) {
    double psi = *unwrapped + ctrl_wrap_pi(angle - *raw);
    *raw = angle;
    *unwrapped = psi;
    return psi;
}

void ctrl_predict_pose(const double pos[3], const double vel[3], const double acc[3],
                       const double euler[3], const double rate[3], double age, double out[9]) {
    int i;
    if (!(age > 0.0)) {
        memcpy(out, pos, 3 * sizeof *out);
        memcpy(out + 3, vel, 3 * sizeof *out);
        memcpy(out + 6, euler, 3 * sizeof *out);
        return;
    }
    for (i = 0; i < 3; i++) {
        out[i] = pos[i] + age * (vel[i] + 0.5 * age * acc[i]);
        out[3 + i] = vel[i] + age * acc[i];
    }
    {
        double sp = sin(euler[0]), cp = cos(euler[0]), ct = cos(euler[1]);
        double tt = tan(euler[1]);
        double dphi = rate[0] + (sp * rate[1] + cp * rate[2]) * tt;
        double dtheta = cp * rate[1] - sp * rate[2];
        double dpsi = (sp * rate[1] + cp * rate[2]) / ct;
        out[6] = euler[0] + age * dphi;
        out[7] = euler[1] + age * dtheta;
        out[8] = euler[2] + age * dpsi;
    }
}

/* One sample of one filter: x+ = Phi x + Gamma u. */
static void filter_update(const double phi[2][2], const double gamma[2], double x[2], double u) {
    double y = phi[0][0] * x[0] + phi[0][1] * x[1] + gamma[0] * u;
    double dy = phi[1][0] * x[0] + phi[1][1] * x[1] + gamma[1] * u;
    x[0] = y;
    x[1] = dy;
}

void ctrl_filters_update(const double phi[2][2], const double gamma[2],
                         const CtrlFilterInputs *in, double x[CTRL_N_FILTERS][2]) {
    int i;
    for (i = 0; i < 3; i++) {
        filter_update(phi, gamma, x[F_POS + i], in->pos[i]);
        filter_update(phi, gamma, x[F_VEL + i], in->vel[i]);
        filter_update(phi, gamma, x[F_ACC + i], in->acc[i]);
        filter_update(phi, gamma, x[F_EULER + i], i == 2 ? in->psi : in->euler[i]);
        filter_update(phi, gamma, x[F_RATE + i], in->rate[i]);
        filter_update(phi, gamma, x[F_POS_REF + i], in->pos_ref[i]);
        filter_update(phi, gamma, x[F_VEL_REF + i], in->vel_ref[i]);
    }
    filter_update(phi, gamma, x[F_EULER_REF], in->mu_ref[0]);
    filter_update(phi, gamma, x[F_EULER_REF + 1], in->mu_ref[1]);
    filter_update(phi, gamma, x[F_EULER_REF + 2], in->psi_ref);
    for (i = 0; i < in->n_rotors; i++) {
        filter_update(phi, gamma, x[F_OMEGA + i], in->omega[i]);
        filter_update(phi, gamma, x[F_ALPHA + i], in->alpha[i]);
        filter_update(phi, gamma, x[F_BETA + i], in->beta[i]);
    }
}

void ctrl_filters_start(const CtrlFilterInputs *in, double x[CTRL_N_FILTERS][2]) {
    int i;
    memset(x, 0, CTRL_N_FILTERS * sizeof x[0]);
    for (i = 0; i < 3; i++) {
        x[F_POS + i][0] = in->pos[i];
        x[F_VEL + i][0] = in->vel[i];
        x[F_ACC + i][0] = in->acc[i];
        x[F_EULER + i][0] = in->euler[i];
        x[F_RATE + i][0] = in->rate[i];
        x[F_POS_REF + i][0] = in->pos_ref[i];
        x[F_VEL_REF + i][0] = in->vel_ref[i];
        x[F_EULER_REF + i][0] = in->mu_ref[i];
    }
    for (i = 0; i < in->n_rotors; i++) {
        x[F_OMEGA + i][0] = in->omega[i];
        x[F_ALPHA + i][0] = in->alpha[i];
        x[F_BETA + i][0] = in->beta[i];
    }
}

void ctrl_read_filters(const double x[CTRL_N_FILTERS][2], const FpRotorSet *rotors,
                       const FpRotorTrig *mounts, const double rotor_health[],
                       int32_t lost_mask, CtrlFiltered *s) {
    int i;
    for (i = 0; i < 3; i++) {
        s->pos_m[i] = x[F_POS + i][0];
        s->vel_m[i] = x[F_VEL + i][0];
        s->acc_m[i] = x[F_ACC + i][0];
        s->mu_m[i] = x[F_EULER + i][0];
        s->rate_m[i] = x[F_RATE + i][0];
        s->ang_acc_m[i] = x[F_RATE + i][1];
        s->pos_ref_f[i] = x[F_POS_REF + i][0];
        s->vel_ref_f[i] = x[F_VEL_REF + i][0];
        s->mu_ref_f[i] = x[F_EULER_REF + i][0];
    }
    for (i = 0; i < FP_MAX_ROTORS; i++) {
        s->a_m[i] = x[F_ALPHA + i][0];
        s->b_m[i] = x[F_BETA + i][0];
        s->w_m[i] = x[F_OMEGA + i][0];
        s->eff[i] = (lost_mask >> i) & 1 ? 0.0 : fmin(fmax(rotor_health[i], 0.0), 1.0);
    }
    /* the tilts' sin and cos once per sample: the wrench here, B'' in the allocation */
    memcpy(s->trig.sg, mounts->sg, sizeof s->trig.sg);
    memcpy(s->trig.cg, mounts->cg, sizeof s->trig.cg);
    fp_rotor_trig_tilts(rotors, s->a_m, s->b_m, &s->trig);
    /* nu_m as the sum of each rotor's wrench at full efficiency, which the detector fits */
    for (i = 0; i < 3; i++) s->f_b_m[i] = s->tau_b_m[i] = 0.0;
    for (i = 0; i < rotors->n && i < FP_MAX_ROTORS; i++) {
        const double *w = s->w_rotor[i];
        int j;
        fp_rotor_wrench_one(rotors, &s->trig, i, s->w_m[i], s->w_rotor[i]);
        for (j = 0; j < 3; j++) {
            s->f_b_m[j] += s->eff[i] * w[j];
            s->tau_b_m[j] += s->eff[i] * w[3 + j];
        }
    }
    rot_zyx_jacobian(s->mu_m, s->r_m, s->dr_dphi_m, s->dr_dtheta_m);
}
