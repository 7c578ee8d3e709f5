/*
 * Parameter validation of the FullPoseController.  The airframe parameters it shares with
 * the plant go through the plant's very rules (fp_check_airframe); the polytopes' facets
 * are checked where they are prepared (force_sets.c).
 */
#include <stdio.h>

#include "stages.h"

/* The first-order blocks, the weights, the attitude bounds and the iteration cap. */
static void check_tunables(const ControllerModel *m, FpCheck *c) {
    static const char *const names[16] = {
        "K_pos_A", "K_pos_B", "K_pos_C", "K_pos_D", "K_vel_A", "K_vel_B", "K_vel_C", "K_vel_D",
        "K_att_A", "K_att_B", "K_att_C", "K_att_D", "K_rate_A", "K_rate_B", "K_rate_C",
        "K_rate_D"};
    const double *blocks[16];
    int k;
    blocks[0] = m->K_pos_A, blocks[1] = m->K_pos_B, blocks[2] = m->K_pos_C, blocks[3] = m->K_pos_D;
    blocks[4] = m->K_vel_A, blocks[5] = m->K_vel_B, blocks[6] = m->K_vel_C, blocks[7] = m->K_vel_D;
    blocks[8] = m->K_att_A, blocks[9] = m->K_att_B, blocks[10] = m->K_att_C,
    blocks[11] = m->K_att_D;
    blocks[12] = m->K_rate_A, blocks[13] = m->K_rate_B, blocks[14] = m->K_rate_C,
    blocks[15] = m->K_rate_D;
    for (k = 0; k < 16; k++)
        fp_need_param(c, names[k], blocks[k], 3,
                      k % 4 == 0 ? "the discrete block's pole must lie inside the unit circle"
                                 : NULL);
    fp_need_param(c, "gamma_opt", &m->gamma_opt, 1, NULL);
    fp_need_param(c, "W_u", m->W_u, 5, NULL);
    fp_need_param(c, "W_v", m->W_v, 3, NULL);
    fp_need_param(c, "W_nu", m->W_nu, 6, NULL);
    fp_need_param(c, "w_pref", &m->w_pref, 1, NULL);
    fp_need_param(c, "pref_omega_scale", &m->pref_omega_scale, 1, NULL);
    fp_need_param(c, "yaw_rate_max", &m->yaw_rate_max, 1, NULL);
    fp_need_param(c, "euler_min", m->euler_min, 2, NULL);
    fp_need_param(c, "euler_max", m->euler_max, 2, NULL);
    fp_need_ordered(c, "euler_min", m->euler_min, m->euler_max, 2, 1,
                    "exceeds euler_max (inverted bounds)");
    fp_need_int_param(c, "qp_max_iter", &m->qp_max_iter, 1);
}

/* The reference shaping's limits (fixed: the acceleration limits derive from them at
 * initialization). */
static void check_shaping(const ControllerModel *m, FpCheck *c) {
    fp_need_param(c, "ref_bandwidth", &m->ref_bandwidth, 1, NULL);
    fp_need_param(c, "ref_tilt_max", &m->ref_tilt_max, 1, NULL);
    fp_need_param(c, "ref_vel_max", m->ref_vel_max, 2, NULL);
    fp_need_param(c, "ref_acc_max", m->ref_acc_max, 2, NULL);
    fp_need_param(c, "ref_jerk_max", m->ref_jerk_max, 2, NULL);
    fp_need_param(c, "ref_att_rate_max", m->ref_att_rate_max, 3, NULL);
    fp_need_param(c, "ref_att_acc_max", m->ref_att_acc_max, 3, NULL);
    fp_need_param(c, "fault_loss_min", &m->fault_loss_min, 1, NULL);
    fp_need_param(c, "fault_fit_max", &m->fault_fit_max, 1, NULL);
    fp_need_param(c, "fault_time", &m->fault_time, 1, NULL);
}

/* Facet counts and the margin of the feasible-force polytopes: 0 (derive from the airframe)
 * or a bounded polytope's 4 facets and more. */
static void check_polytope_sizes(const ControllerModel *m, FpCheck *c) {
    char why[64];
    int i, errors = c->errors;
    fp_need_int_param(c, "poly_n", &m->poly_n, 1);
    if (c->errors > errors) return;
    if (m->poly_n != 0 && m->poly_n < 4) {
        snprintf(why, sizeof why, "must be 0 (derived) or 4..%d", FP_POLYTOPE_MAX_FACETS);
        fp_check_bad_int(c, "poly_n", 0, (long)m->poly_n, why);
    }
    fp_need_param(c, "poly_margin", &m->poly_margin, 1, NULL);
    errors = c->errors;
    fp_need_int_param(c, "fail_poly_n", m->fail_poly_n, m->af.n_rotors);
    if (c->errors > errors) return;
    snprintf(why, sizeof why, "must be 0 (derived) or 4..%d", FP_FAIL_POLYTOPE_FACETS);
    for (i = 0; i < m->af.n_rotors; i++) /* a bounded polytope in 3-D needs 4 facets */
        if (m->fail_poly_n[i] != 0 && m->fail_poly_n[i] < 4)
            fp_check_bad_int(c, "fail_poly_n", i + 1, (long)m->fail_poly_n[i], why);
}

int ctrl_check_parameters(const ControllerModel *m, const FpVar *vars, size_t n_vars,
                          const FpLogger *logger) {
    FpCheck c;
    fp_check_init(&c, logger, vars, n_vars);
    fp_need_param(&c, "Ts", &m->Ts, 1, NULL);
    if (fp_check_airframe(&c, &m->af) != FP_OK) return c.errors;
    fp_need_param(&c, "filt_wn", &m->filt_wn, 1, NULL);
    fp_need_param(&c, "filt_zeta", &m->filt_zeta, 1, NULL);
    fp_need_int_param(&c, "force_constraint", &m->force_constraint, 1);
    check_tunables(m, &c);
    check_shaping(m, &c);
    if (c.errors == 0) check_polytope_sizes(m, &c);
    return c.errors;
}

int ctrl_check_tunables(const ControllerModel *m, const FpVar *vars, size_t n_vars,
                        const FpLogger *logger) {
    FpCheck c;
    fp_check_init(&c, logger, vars, n_vars);
    check_tunables(m, &c);
    return c.errors;
}
