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
    int i, k;
    blocks[0] = m->K_pos_A, blocks[1] = m->K_pos_B, blocks[2] = m->K_pos_C, blocks[3] = m->K_pos_D;
    blocks[4] = m->K_vel_A, blocks[5] = m->K_vel_B, blocks[6] = m->K_vel_C, blocks[7] = m->K_vel_D;
    blocks[8] = m->K_att_A, blocks[9] = m->K_att_B, blocks[10] = m->K_att_C,
    blocks[11] = m->K_att_D;
    blocks[12] = m->K_rate_A, blocks[13] = m->K_rate_B, blocks[14] = m->K_rate_C,
    blocks[15] = m->K_rate_D;
    for (k = 0; k < 16; k++) fp_need_finite(c, names[k], blocks[k], 3, 1);
    for (k = 0; k < 16; k += 4)
        for (i = 0; i < 3; i++)
            if (isfinite(blocks[k][i]) && fabs(blocks[k][i]) >= 1.0)
                fp_check_bad(c, names[k], i + 1, 0, blocks[k][i],
                             "the discrete block's pole must lie inside the unit circle (|A| < 1)");
    fp_need_positive(c, "gamma_opt", &m->gamma_opt, 1, 0);
    fp_need_positive(c, "W_u", m->W_u, 5, 1);
    fp_need_positive(c, "W_v", m->W_v, 3, 1);
    fp_need_positive(c, "W_nu", m->W_nu, 6, 1);
    fp_need_positive(c, "w_pref", &m->w_pref, 1, 0);
    fp_need_positive(c, "pref_omega_scale", &m->pref_omega_scale, 1, 0);
    fp_need_positive(c, "yaw_rate_max", &m->yaw_rate_max, 1, 0);
    fp_need_finite(c, "euler_min", m->euler_min, 2, 1);
    fp_need_finite(c, "euler_max", m->euler_max, 2, 1);
    for (i = 0; i < 2; i++) {
        int low = fabs(m->euler_min[i]) >= CTRL_PI / 2;
        if (m->euler_min[i] > m->euler_max[i])
            fp_check_bad(c, "euler_min", i + 1, 0, m->euler_min[i],
                         "exceeds euler_max (inverted bounds)");
        if (low || fabs(m->euler_max[i]) >= CTRL_PI / 2)
            fp_check_bad(c, low ? "euler_min" : "euler_max", i + 1, 0,
                         low ? m->euler_min[i] : m->euler_max[i], "must be inside (-pi/2, pi/2)");
    }
    if (m->qp_max_iter < 1 || m->qp_max_iter > 1000)
        fp_check_bad_int(c, "qp_max_iter", 0, (long)m->qp_max_iter, "must be in 1..1000");
}

/* Facet counts and the margin of the feasible-force polytopes. */
static void check_polytope_sizes(const ControllerModel *m, FpCheck *c) {
    char why[64];
    int i;
    if (m->poly_n < 4 || m->poly_n > FP_POLYTOPE_MAX_FACETS) {
        snprintf(why, sizeof why, "a bounded polytope in 3-D needs 4..%d facets",
                 FP_POLYTOPE_MAX_FACETS);
        fp_check_bad_int(c, "poly_n", 0, (long)m->poly_n, why);
        return;
    }
    if (!(m->poly_margin > 0.0 && m->poly_margin <= 1.0))
        fp_check_bad(c, "poly_margin", 0, 0, m->poly_margin, "must be in (0, 1]");
    snprintf(why, sizeof why, "must be 0 (none) or 4..%d", FP_FAIL_POLYTOPE_FACETS);
    for (i = 0; i < m->n_rotors; i++)
        if (m->fail_poly_n[i] != 0 &&
            (m->fail_poly_n[i] < 4 || m->fail_poly_n[i] > FP_FAIL_POLYTOPE_FACETS))
            fp_check_bad_int(c, "fail_poly_n", i + 1, (long)m->fail_poly_n[i], why);
}

int ctrl_check_parameters(const ControllerModel *m, const FpLogger *logger) {
    FpCheck c;
    FpRotorSet rs;
    fp_check_init(&c, logger);
    fp_need_positive(&c, "Ts", &m->Ts, 1, 0);
    FP_MODEL_TO_ROTOR_SET(m, &rs);
    if (fp_check_airframe(&c, m->mass, &m->inertia[0][0], m->g, &rs) != FP_OK) return c.errors;
    fp_need_positive(&c, "filt_wn", &m->filt_wn, 1, 0);
    fp_need_positive(&c, "filt_zeta", &m->filt_zeta, 1, 0);
    if (m->force_constraint != 0 && m->force_constraint != 1)
        fp_check_bad_int(&c, "force_constraint", 0, (long)m->force_constraint,
                         "must be 0 (joint polytope) or 1 (f_bz slice)");
    check_tunables(m, &c);
    if (c.errors == 0) check_polytope_sizes(m, &c);
    return c.errors;
}

int ctrl_check_tunables(const ControllerModel *m, const FpLogger *logger) {
    FpCheck c;
    fp_check_init(&c, logger);
    check_tunables(m, &c);
    return c.errors;
}
