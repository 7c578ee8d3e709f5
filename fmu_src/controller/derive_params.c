/*
 * What the controller's initialization derives from its fixed parameters (controller.c
 * calls these once, after the parameters are checked): the feasible-force sets in use with
 * their margin-scaled offsets, the reference shaping's limits, the fault detector's
 * constants.  A restored state is held to the same derivations (controller.c compares the
 * detector's constants bit for bit).
 */
#include <math.h>
#include <stdio.h>
#include <string.h>

#include "controller.h"
#include "fp_math.h"
#include "stages.h"

/* ------------------------------------------------------------------------ */
/* Initialization: the detector's constants                                 */

/* Window of an event: an explanation not found in this time is a load. */
#define DETECT_WINDOW 0.2 /* s */

CtrlDetectParams ctrl_detect_params(const ControllerModel *m) {
    CtrlDetectParams p;
    const double(*in)[3] = (const double(*)[3])m->af.inertia;
    double arm = 0.0, det, share;
    int i, j;
    memset(&p, 0, sizeof p); /* bit-for-bit comparable (detect_params_agree) */
    p.mass = m->af.mass, p.g = m->af.g, p.Ts = m->Ts;
    memcpy(p.inertia, m->af.inertia, sizeof p.inertia);
    for (i = 0; i < m->af.n_rotors; i++)
        arm += sqrt(v3_dot(m->af.rotor_pos[i], m->af.rotor_pos[i])) / m->af.n_rotors;
    p.arm = arm * arm > 0.0 ? arm : 1.0;
    /* arm I^-1 (adjugate over determinant; the airframe rules make I positive definite) */
    det = in[0][0] * (in[1][1] * in[2][2] - in[1][2] * in[2][1]) -
          in[0][1] * (in[1][0] * in[2][2] - in[1][2] * in[2][0]) +
          in[0][2] * (in[1][0] * in[2][1] - in[1][1] * in[2][0]);
    for (i = 0; i < 3; i++)
        for (j = 0; j < 3; j++) {
            int r0 = (j + 1) % 3, r1 = (j + 2) % 3, c0 = (i + 1) % 3, c1 = (i + 2) % 3;
            p.acc_of_torque[i][j] =
                det > 0.0 ? p.arm * (in[r0][c0] * in[r1][c1] - in[r0][c1] * in[r1][c0]) / det
                          : 0.0;
        }
    p.loss_min = m->fault_loss_min, p.fit_max = m->fault_fit_max;
    /* a rotor's share of the weight, as the acceleration it gives */
    share = fabs(m->af.g) / (m->af.n_rotors > 0 ? m->af.n_rotors : 1);
    /* a rotor below a twentieth of its share has no signature to speak of */
    p.wrench_min = 0.05 * share;
    /* an event opens at a change of half the smallest loss concluded, and a rotor's fit
     * must beat the load's by more than 5 % of its share per sample (sensor noise) */
    p.onset = 0.5 * m->fault_loss_min * share;
    p.floor2 = (0.05 * share) * (0.05 * share);
    p.base_gain = fmin(m->Ts / 0.5, 1.0); /* the quiet level follows within 0.5 s */
    p.probe_omega = fp_clamp(sqrt(0.3 * m->af.mass * fabs(m->af.g) /
                                  ((m->af.n_rotors > 0 ? m->af.n_rotors : 1) * m->af.k_t)),
                             m->rotors.omega_min, m->rotors.omega_max);
    p.persist = (int32_t)ceil(m->fault_time / m->Ts - 1e-9);
    if (p.persist < 1) p.persist = 1;
    p.window = (int32_t)ceil(DETECT_WINDOW / m->Ts - 1e-9);
    if (p.window < p.persist) p.window = p.persist;
    return p;
}

/* ------------------------------------------------------------------------ */
/* Initialization: the force sets                                           */

/* The force sets in use (given or derived from the airframe), validated, with their
 * margin-scaled offsets, f_bz ranges and hover flags (the guidance QP's solver is borrowed
 * before it is set up). */
FpStatus ctrl_prepare_force_sets(ControllerModel *m, const FpVar *vars, size_t n_vars,
                                 const FpLogger *logger) {
    FpCheck c;
    CtrlGivenSet s0, fail[FP_MAX_ROTORS];
    double hover_fz = -m->af.mass * m->af.g;
    char lost[48] = "";
    int i, n_lost = 0;
    fp_check_init(&c, logger, vars, n_vars);
    s0.n = m->poly_n, s0.A = (const double(*)[3])m->poly_A, s0.b = m->poly_b;
    for (i = 0; i < FP_MAX_ROTORS; i++) {
        int base = i * FP_FAIL_POLYTOPE_FACETS;
        fail[i].n = m->fail_poly_n[i];
        fail[i].A = (const double(*)[3])&m->fail_poly_A[base];
        fail[i].b = &m->fail_poly_b[base];
    }
    if (ctrl_force_sets_resolve(&c, &m->rotors, &s0, fail, &m->guid, &m->set_n, m->set_A,
                                m->set_b,
                                m->set_fail_n, m->set_fail_A, m->set_fail_b,
                                &m->sets_derived) != FP_OK)
        return FP_ERROR;
    if (ctrl_force_set_prepare(&c, "poly_A, poly_b", (const double(*)[3])m->set_A, m->set_b,
                               m->set_n, hover_fz, m->poly_margin, &m->guid, m->poly_d,
                               &m->fz_min, &m->fz_max, &m->hover_ok[0]) != FP_OK)
        return FP_ERROR;
    if (!m->hover_ok[0]) {
        if (m->sets_derived & 1)
            fp_check_error(&c,
                           "parameters mass, k_t, omega_max, rotor tilts: the hover force [0, "
                           "0, %.6g] N is outside the feasible-force set S(0) derived from the "
                           "airframe (its most upward force is %.6g N): the rotors cannot hold "
                           "this vehicle",
                           hover_fz, m->fz_min);
        else
            fp_check_error(&c,
                           "parameters poly_A, poly_b: the hover force [0, 0, %.6g] N is "
                           "outside the polytope: it does not describe this vehicle",
                           hover_fz);
        return FP_ERROR;
    }
    for (i = 0; i < FP_MAX_ROTORS; i++) {
        int base = i * FP_FAIL_POLYTOPE_FACETS;
        char name[48];
        m->hover_ok[i + 1] = 0;
        if (i >= m->af.n_rotors || m->set_fail_n[i] == 0) continue;
        snprintf(name, sizeof name, "fail_poly_A, fail_poly_b (rotor %d)", i + 1);
        if (ctrl_force_set_prepare(&c, name, (const double(*)[3])&m->set_fail_A[base],
                                   &m->set_fail_b[base], m->set_fail_n[i], hover_fz,
                                   m->poly_margin, &m->guid, &m->fail_d[base], &m->fail_fz[i][0],
                                   &m->fail_fz[i][1], &m->hover_ok[i + 1]) != FP_OK)
            return FP_ERROR;
        if (!m->hover_ok[i + 1] && strlen(lost) + 4 < sizeof lost)
            snprintf(lost + strlen(lost), sizeof lost - strlen(lost), "%s%d",
                     n_lost++ ? ", " : "", i + 1);
    }
    if (n_lost) /* one warning for all of them: each loss is a fact of the airframe */
        fp_check_warning(&c,
                         "losing rotor %s leaves no hover force in the feasible-force set "
                         "(each of them alone)",
                         lost);
    return FP_OK;
}

/* The shaping's limits in use: as given, or derived from the airframe (shaping_limits.c) -
 * the rotors' torque capability computed with the inner allocation's solver, borrowed
 * before it is set up. */
FpStatus ctrl_derive_shaping_limits(ControllerModel *m, const FpLogger *logger) {
    CtrlLimitInputs in;
    CtrlShapingLimits out;
    CtrlForceSet fs;
    double tau[3] = {0.0, 0.0, 0.0};
    int i, need_torque = 0;
    for (i = 0; i < 3; i++) need_torque |= !(m->ref_att_acc_max[i] > 0.0);
    if (need_torque &&
        ctrl_torque_capability(&m->rotors, m->af.mass, m->af.g, &m->alloc, tau) != FP_OK) {
        fp_log(logger, FP_ERROR, FP_LOG_ERROR,
               "parameters ref_att_acc_max: the rotors' torque capability at the hover trim "
               "cannot be computed for this airframe; give every element (> 0)");
        return FP_ERROR;
    }
    fs.A = (const double(*)[3])m->set_A, fs.d = m->poly_d, fs.n = m->set_n;
    fs.fz[0] = m->fz_min, fs.fz[1] = m->fz_max, fs.id = 0;
    in.fs = &fs;
    in.mass = m->af.mass, in.g = m->af.g;
    memcpy(in.inertia, m->af.inertia, sizeof in.inertia);
    memcpy(in.tau_max, tau, sizeof in.tau_max);
    in.tilt_max = m->ref_tilt_max, in.bandwidth = m->ref_bandwidth;
    in.vel_max = m->ref_vel_max, in.acc_max = m->ref_acc_max, in.jerk_max = m->ref_jerk_max;
    in.att_rate_max_given = m->ref_att_rate_max, in.att_acc_max = m->ref_att_acc_max;
    ctrl_shaping_limits(&in, &out);
    memcpy(m->acc_limit, out.acc, sizeof m->acc_limit);
    memcpy(m->vel_limit, out.vel, sizeof m->vel_limit);
    memcpy(m->jerk_limit, out.jerk, sizeof m->jerk_limit);
    memcpy(m->att_rate_limit, out.att_rate, sizeof m->att_rate_limit);
    memcpy(m->att_acc_limit, out.att_acc, sizeof m->att_acc_limit);
    m->yaw_rate_limit = out.yaw_rate;
    memcpy(m->ref_acc_limit, m->acc_limit, sizeof m->ref_acc_limit);
    memcpy(m->ref_vel_limit, m->vel_limit, sizeof m->ref_vel_limit);
    memcpy(m->ref_jerk_limit, m->jerk_limit, sizeof m->ref_jerk_limit);
    memcpy(m->ref_att_rate_limit, m->att_rate_limit, sizeof m->ref_att_rate_limit);
    memcpy(m->ref_att_acc_limit, m->att_acc_limit, sizeof m->ref_att_acc_limit);
    return FP_OK;
}
