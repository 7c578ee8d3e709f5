/*
 * Stabilization (paper section III): the attitude and rate blocks give the commanded body
 * rates and angular acceleration; inner INDI on the rotational dynamics turns the
 * acceleration increment into the torque increment dtau_c = I (dOmega_c - dOmega_m).
 */
#include "fp_math.h"
#include "stages.h"

void ctrl_stabilization(const CtrlStabilizationParams *p, const CtrlFiltered *s,
                        const double mu_c[3], const double mu_ref[3],
                        const double mu_dot_ref[3], const double mu_ddot_ref[3],
                        CtrlStabilizationState *st, double rate_c[3], double dtau_c[3]) {
    double e[3], mu_dot_c[3], dw[3], acc_ff[3];
    double cp = cos(s->mu_m[0]), sp = sin(s->mu_m[0]);
    double ct = cos(s->mu_m[1]), stt = sin(s->mu_m[1]);
    int i;
    /* As for position: the attitude error is taken against the reference delayed by
     * H(s) like the measurement, plus the guidance's departure mu_c - mu_ref. */
    for (i = 0; i < 3; i++)
        e[i] = ctrl_wrap_pi(mu_c[i] - mu_ref[i]) + ctrl_wrap_pi(s->mu_ref_f[i] - s->mu_m[i]);
    for (i = 0; i < 3; i++)
        mu_dot_c[i] = ctrl_block(&p->K_att, i, &st->x_att[i], e[i]) + mu_dot_ref[i];
    /* the heading rate is limited to what the yaw authority can follow */
    mu_dot_c[2] = fmin(fmax(mu_dot_c[2], -p->yaw_rate_max), p->yaw_rate_max);
    /* Euler rates to body rates at the measured attitude */
    rate_c[0] = mu_dot_c[0] - stt * mu_dot_c[2];
    rate_c[1] = cp * mu_dot_c[1] + sp * ct * mu_dot_c[2];
    rate_c[2] = -sp * mu_dot_c[1] + cp * ct * mu_dot_c[2];
    /* the feed-forward's angular acceleration, through the same kinematics */
    acc_ff[0] = mu_ddot_ref[0] - stt * mu_ddot_ref[2];
    acc_ff[1] = cp * mu_ddot_ref[1] + sp * ct * mu_ddot_ref[2];
    acc_ff[2] = -sp * mu_ddot_ref[1] + cp * ct * mu_ddot_ref[2];
    for (i = 0; i < 3; i++)
        dw[i] = ctrl_block(&p->K_rate, i, &st->x_rate[i], rate_c[i] - s->rate_m[i]) +
                acc_ff[i] - s->ang_acc_m[i];
    m3_mul_v(&p->inertia[0][0], dw, dtau_c);
}
