/*
 * FullPoseController: one sample of the paper's section III as a discrete-time system, the
 * sequence of the stages (stages.h; each in its own file) and the views of the model they
 * are given.  The model's callbacks, its variable table and the check of the inputs that
 * precedes every sample are controller.c.
 *
 * One sample (every Ts):
 *   1. H(s) filters every measurement and the actuator feedback (exact ZOH
 *      discretization; the filter's derivative state of the body rates is the
 *      filtered angular acceleration): filters.c.
 *   2. Guidance: first-order blocks K_xi, K_xidot with velocity/acceleration
 *      feed-forward give the commanded acceleration; outer INDI (eq. 14-15)
 *      and the WLS guidance QP (eq. 17-23) over [dfx, dfy, dfz, dphi, dtheta]
 *      give mu_c and df_b_c.  psi_c = psi_ref (outside the QP: see
 *      docs/architecture.md, "Design decisions"): guidance.c.
 *   3. Stabilization: attitude and rate blocks, INDI on the rotational
 *      dynamics: dtau_c = I (dOmega_c - dOmega_m): stabilization.c.
 *   4. Inner allocation: WLS on the analytic B''(u_a,m) (eq. 12-13) with
 *      actuator bounds, torque priority and a preferred configuration: allocation.c.
 */
#include <math.h>
#include <stddef.h>
#include <string.h>

#include "controller.h"
#include "fp_clock.h"
#include "fp_math.h"
#include "stages.h"

/* ------------------------------------------------------------------------ */
/* Views of the model for the stages                                        */

#define CTRL_BLOCK(m, loop) \
    ((CtrlBlock){(m)->K_##loop##_A, (m)->K_##loop##_B, (m)->K_##loop##_C, (m)->K_##loop##_D})

CtrlFilterInputs ctrl_filter_inputs(const ControllerModel *m) {
    CtrlFilterInputs in;
    /* the pose as predicted to now (ctrl_predict_pose, before this view is taken) */
    in.pos = m->pose_now, in.vel = m->pose_now + 3, in.acc = m->acc;
    in.euler = m->pose_now + 6, in.rate = m->rate;
    in.pos_ref = m->pos_ref, in.vel_ref = m->vel_ref, in.mu_ref = m->euler_ref;
    in.psi = m->pose_now[8], in.psi_ref = m->euler_ref[2];
    in.omega = m->omega, in.alpha = m->alpha, in.beta = m->beta;
    in.n_rotors = m->af.n_rotors;
    return in;
}

/* The feasible-force set in use: nominal, or the one after losing the single lost rotor. */
static CtrlForceSet force_set_in_use(const ControllerModel *m) {
    CtrlForceSet fs;
    int i = m->active_polytope;
    if (i >= 1) {
        fs.A = (const double(*)[3])&m->set_fail_A[(i - 1) * FP_FAIL_POLYTOPE_FACETS];
        fs.d = &m->fail_d[(i - 1) * FP_FAIL_POLYTOPE_FACETS];
        fs.n = m->set_fail_n[i - 1];
        fs.fz[0] = m->fail_fz[i - 1][0];
        fs.fz[1] = m->fail_fz[i - 1][1];
        fs.id = i;
        return fs;
    }
    fs.A = (const double(*)[3])m->set_A;
    fs.d = m->poly_d;
    fs.n = m->set_n;
    fs.fz[0] = m->fz_min;
    fs.fz[1] = m->fz_max;
    fs.id = 0;
    return fs;
}

static CtrlGuidanceParams guidance_params(const ControllerModel *m) {
    CtrlGuidanceParams p;
    p.mass = m->af.mass;
    p.K_pos = CTRL_BLOCK(m, pos);
    p.K_vel = CTRL_BLOCK(m, vel);
    p.gamma_opt = m->gamma_opt;
    p.W_u = m->W_u, p.W_v = m->W_v;
    p.euler_min = m->euler_min, p.euler_max = m->euler_max;
    p.force_constraint = m->force_constraint;
    p.max_iter = m->qp_max_iter, p.timing = m->timing;
    return p;
}

static CtrlShapingParams shaping_params(const ControllerModel *m) {
    CtrlShapingParams p;
    p.enabled = m->ref_shaping != 0;
    p.Ts = m->Ts;
    p.lambda = m->ref_bandwidth;
    memcpy(p.vel_max, m->vel_limit, sizeof p.vel_max);
    memcpy(p.acc_max, m->acc_limit, sizeof p.acc_max);
    memcpy(p.jerk_max, m->jerk_limit, sizeof p.jerk_max);
    memcpy(p.att_rate_max, m->att_rate_limit, sizeof p.att_rate_max);
    memcpy(p.att_acc_max, m->att_acc_limit, sizeof p.att_acc_max);
    return p;
}

static CtrlStabilizationParams stabilization_params(const ControllerModel *m) {
    CtrlStabilizationParams p;
    p.K_att = CTRL_BLOCK(m, att);
    p.K_rate = CTRL_BLOCK(m, rate);
    p.yaw_rate_max = m->yaw_rate_max > 0.0 ? m->yaw_rate_max : m->yaw_rate_limit;
    p.inertia = (const double(*)[3])m->af.inertia;
    return p;
}

static CtrlAllocationParams allocation_params(const ControllerModel *m) {
    CtrlAllocationParams p;
    p.rotors = &m->rotors;
    p.pref_split = &m->pref_split;
    p.W_nu = m->W_nu;
    p.w_pref = m->w_pref, p.pref_omega_scale = m->pref_omega_scale;
    p.max_iter = m->qp_max_iter, p.timing = m->timing;
    return p;
}


/* ------------------------------------------------------------------------ */
/* One sample                                                               */

/* Rotors told below half efficiency, or lost to the detector, are lost: pick the
 * feasible-force set that goes with the losses and say so once per change. */
void ctrl_update_rotor_losses(ControllerModel *m, const FpLogger *logger) {
    CtrlLosses l;
    int i;
    /* what is known of each rotor: what the importer says, or less where detected */
    for (i = 0; i < FP_MAX_ROTORS; i++)
        m->health[i] = m->fault_detect ? fmin(m->rotor_health[i], m->roll.detect.est[i])
                                       : m->rotor_health[i];
    ctrl_rotor_losses(m->af.n_rotors, m->rotor_health,
                      m->fault_detect ? m->roll.detect.lost_mask : 0, m->set_fail_n, m->hover_ok,
                      &l);
    if (l.lost_mask == m->lost_mask) return;
    m->lost_mask = l.lost_mask;
    m->rotors_lost = l.rotors_lost;
    m->active_polytope = l.active_polytope;
    m->hover_possible = l.hover_possible;
    fp_wls_reset(&m->guid); /* the facets change: the old working set means nothing */
    fp_wls_reset(&m->twin_qp);
    ctrl_log_losses(&l, logger);
}


/* One sample from usable inputs (controller.c checks them first): FP_OK, or FP_WARNING when
 * it computed a non-finite value and was discarded. */
FpStatus ctrl_sample(ControllerModel *m, const FpLogger *logger) {
    CtrlFilterInputs fin;
    CtrlFiltered s;
    CtrlForceSet fs;
    CtrlGuidanceParams gp;
    CtrlGuidanceInputs gin;
    CtrlGuidanceState gst;
    CtrlGuidanceOut g;
    CtrlStabilizationParams sp;
    CtrlStabilizationState sst;
    CtrlAllocationParams ap;
    CtrlAllocationOut a;
    CtrlShapingParams shp;
    CtrlShapingInputs shin;
    CtrlShapedRef r;
    double mu_in[3], mu_ff[3], mu_rate_ff[3], mu_acc_ff[3], pos_in[3], vel_in[3], r_ref[9];
    double age = m->inputs_age;
    double dtau_c[3], rate_c[3], dnu_c[6], t_start = m->timing ? fp_clock_seconds() : 0.0;
    /* what a sample changes besides its outputs: restored when the sample is discarded */
    CtrlRolled before;
    CtrlDetectOut dout;
    double residual[6], acc_lead[3];
    int i, n = m->af.n_rotors;
    /* the QPs' memory arrives while the filters, the guidance set-up and B'' compute */
    fp_wls_prefetch(&m->guid);
    fp_wls_prefetch(&m->alloc);
    ctrl_update_rotor_losses(m, logger);
    before = m->roll;
    /* 0. the reference: shaped (headings unwrapped first so that +-pi crossings are no
     * jumps), then the twin's feed-forward attitude and its rate */
    mu_in[0] = m->euler_ref[0], mu_in[1] = m->euler_ref[1];
    mu_in[2] = ctrl_unwrap(m->euler_ref[2], &m->roll.psi_ref_raw, &m->roll.psi_ref_unwrapped);
    memcpy(pos_in, m->pos_ref, sizeof pos_in);
    memcpy(vel_in, m->vel_ref, sizeof vel_in);
    if (age > 0.0)
        /* inputs set before this instant (a step h that is no multiple of Ts): the
         * reference carried forward by its own derivatives, as the pose is by its age, so
         * that a smooth reference is seen smooth and not as a staircase of jumps */
        for (i = 0; i < 3; i++) {
            pos_in[i] += age * (m->vel_ref[i] + 0.5 * age * m->acc_ref[i]);
            vel_in[i] += age * m->acc_ref[i];
            mu_in[i] += age * m->euler_rate_ref[i];
        }
    shp = shaping_params(m);
    shin.pos = pos_in, shin.vel = vel_in, shin.acc = m->acc_ref;
    shin.mu = mu_in, shin.mu_rate = m->euler_rate_ref;
    if (m->shape_from_pose && shp.enabled) /* leaving the ground: from where it stands */
        ctrl_shaping_start_at(&shin, m->pos, m->vel, m->euler, &m->roll.shaping);
    ctrl_shape_reference(&shp, &shin, &m->roll.shaping, &r);
    fs = force_set_in_use(m);
    gp = guidance_params(m);
    rot_zyx_jacobian(r.mu, r_ref, NULL, NULL); /* the twin's and the guidance's R(mu_ref) */
    ctrl_guidance_twin(&gp, &fs, r.acc, r.mu, r_ref, m->af.g, &m->roll.twin, &m->twin_qp, mu_ff);
    for (i = 0; i < 3; i++) /* the twin's rate wherever it departs from the reference */
        mu_rate_ff[i] = m->roll.twin.active || before.twin.active
                            ? ctrl_wrap_pi(mu_ff[i] - m->mu_ff[i]) / m->Ts
                            : r.mu_rate[i];
    /* and its angular acceleration: without it the rate loop lags every change of rate
     * (a quadrotor's attitude rate follows the jerk of its path) */
    for (i = 0; i < 3; i++) mu_acc_ff[i] = (mu_rate_ff[i] - m->mu_rate_ff[i]) / m->Ts;
    /* 1. filters (the measured heading unwrapped like the reference's; the pose predicted
     * over its age and the inputs' own) */
    ctrl_predict_pose(m->pos, m->vel, m->acc, m->euler, m->rate, m->pose_age + age,
                      m->pose_now);
    fin = ctrl_filter_inputs(m);
    fin.psi = ctrl_unwrap(m->pose_now[8], &m->roll.psi_raw, &m->roll.psi_unwrapped);
    fin.pos_ref = r.pos, fin.vel_ref = r.vel;
    fin.mu_ref = mu_ff, fin.psi_ref = mu_ff[2];
    if (m->shape_from_pose) /* leaving the ground: every filter at rest where it stands */
        ctrl_filters_start(&fin, m->roll.filt);
    ctrl_filters_update((const double(*)[2])m->filt_phi, m->filt_gamma, &fin, m->roll.filt);
    ctrl_read_filters((const double(*)[2])m->roll.filt, &m->rotors, &m->rotor_trig, m->health,
                      m->lost_mask, &s);
    /* what the ground carries, for the next sample's land detector (ground.c) */
    m->ground_support = ctrl_ground_support(m->af.mass, m->af.g, s.r_m, s.f_b_m, s.acc_m);
    if (m->fault_detect) {
        /* a detection counts from the next sample on (ctrl_update_rotor_losses) */
        CtrlDetectInputs din;
        din.acc = m->acc, din.euler = s.mu_m, din.rate = m->rate;
        din.omega = m->omega, din.alpha = m->alpha, din.beta = m->beta;
        din.eff = s.eff;
        ctrl_detect(&m->detect_p, &m->rotors, &m->rotor_trig, &din, &m->roll.detect, &dout);
        ctrl_detect_residual(&m->detect_p, &s, residual);
        if (dout.detected >= 0) {
            double e = m->roll.detect.est[dout.detected];
            fp_log(logger, FP_WARNING, FP_LOG_WARNING,
                   "rotor %d: efficiency %.2f estimated from the residual (was %.2f)%s",
                   dout.detected + 1, e, s.eff[dout.detected],
                   e < CTRL_DETECT_LOST ? ": lost" : "");
        }
    }
    /* 2. guidance */
    /* the shaping's acceleration led by the actuators' lag (first order: a force commanded
     * now arrives tau later), so that a shaped step's jerk does not leave the vehicle behind
     * its reference; zero at zero shaping error, so a given trajectory is flown as given */
    for (i = 0; i < 3; i++)
        acc_lead[i] = r.acc[i] + fmax(m->af.tau_motor, m->af.tau_servo) * r.jerk[i];
    gin.acc_ref = acc_lead;
    gin.mu_ref = r.mu;
    gin.r_ref = r_ref;
    gst.x_pos = m->roll.blk[BLK_POS];
    gst.x_vel = m->roll.blk[BLK_VEL];
    gst.qp = &m->guid;
    gst.c_rows = &m->guid_c_rows;
    ctrl_guidance(&gp, &fs, &gin, &s, &gst, &g);
    /* 3. stabilization */
    sp = stabilization_params(m);
    sst.x_att = m->roll.blk[BLK_ATT];
    sst.x_rate = m->roll.blk[BLK_RATE];
    ctrl_stabilization(&sp, &s, g.mu_c, mu_ff, mu_rate_ff, mu_acc_ff, &sst, rate_c, dtau_c);
    /* 4. inner allocation of dnu_c = [df_b_c; dtau_c] */
    for (i = 0; i < 3; i++) {
        dnu_c[i] = g.df_c[i];
        dnu_c[3 + i] = dtau_c[i];
    }
    ap = allocation_params(m);
    ctrl_allocation(&ap, &s, dnu_c, m->lost_mask, &m->alloc, &a);
    if (m->fault_detect) {
        /* rotors lost to the detector idle at the probe speed, switched between two levels
         * every CTRL_PROBE_HALF_PERIOD: a rotor that produces thrust after all shows it
         * moving with its speed (a load would not), and is restored */
        int64_t half = (int64_t)ceil(CTRL_PROBE_HALF_PERIOD / m->Ts - 1e-9);
        double level = (m->samples_run / (half > 0 ? half : 1)) % 2 ? 1.0 : 0.6;
        for (i = 0; i < n; i++)
            if (((m->roll.detect.lost_mask & m->lost_mask) >> i) & 1 &&
                !(m->rotor_health[i] < 0.5))
                a.omega_cmd[i] = level * m->detect_p.probe_omega;
    }
    /* never a non-finite output: a sample that computed one is discarded whole (states
     * restored, the QPs' warm starts dropped) and the last valid outputs held */
    if (!fp_all_finite(a.alpha_cmd, (size_t)n) || !fp_all_finite(a.beta_cmd, (size_t)n) ||
        !fp_all_finite(a.omega_cmd, (size_t)n) ||
        !fp_all_finite(g.mu_c, 3) || !fp_all_finite(g.acc_c, 3) || !fp_all_finite(g.f_b_ref, 3) ||
        !fp_all_finite(g.f_b_c, 3) || !fp_all_finite(rate_c, 3) || !fp_all_finite(dnu_c, 6) ||
        !fp_all_finite(a.residual, 6) || !fp_all_finite(mu_acc_ff, 3)) {
        m->roll = before;
        fp_wls_reset(&m->twin_qp);
        fp_wls_reset(&m->guid);
        fp_wls_reset(&m->alloc);
        fp_log(logger, FP_WARNING, FP_LOG_WARNING,
               "non-finite value computed from the inputs: sample discarded, holding the last "
               "valid command");
        return FP_WARNING;
    }
    m->shape_from_pose = 0;
    memcpy(m->pos_ref_s, r.pos, sizeof m->pos_ref_s);
    memcpy(m->vel_ref_s, r.vel, sizeof m->vel_ref_s);
    memcpy(m->acc_ref_s, r.acc, sizeof m->acc_ref_s);
    memcpy(m->euler_ref_s, r.mu, sizeof m->euler_ref_s);
    memcpy(m->mu_ff, mu_ff, sizeof m->mu_ff);
    memcpy(m->mu_rate_ff, mu_rate_ff, sizeof m->mu_rate_ff);
    if (m->fault_detect) {
        memcpy(m->indi_residual, residual, sizeof m->indi_residual);
        memcpy(m->rotor_eff_est, m->roll.detect.est, sizeof m->rotor_eff_est);
        m->rotors_detected = m->roll.detect.found_mask;
    }
    memcpy(m->acc_c, g.acc_c, sizeof m->acc_c);
    memcpy(m->f_b_ref, g.f_b_ref, sizeof m->f_b_ref);
    memcpy(m->f_b_c, g.f_b_c, sizeof m->f_b_c);
    m->guid_status = (int32_t)g.status;
    m->guid_iter = g.iterations;
    m->guid_flags = g.flags;
    m->feasible = g.feasible;
    if (m->timing) m->t_guid = g.t_solve;
    memcpy(m->rate_c, rate_c, sizeof m->rate_c);
    memcpy(m->dnu_c, dnu_c, sizeof m->dnu_c);
    m->alloc_status = (int32_t)a.status;
    m->alloc_iter = a.iterations;
    memcpy(m->alloc_residual, a.residual, sizeof m->alloc_residual);
    m->sat_flags = a.sat_flags;
    if (m->timing) m->t_alloc = a.t_solve;
    for (i = 0; i < 3; i++) m->mu_c[i] = ctrl_wrap_pi(g.mu_c[i]);
    memcpy(m->omega_cmd, a.omega_cmd, sizeof m->omega_cmd);
    memcpy(m->alpha_cmd, a.alpha_cmd, sizeof m->alpha_cmd);
    memcpy(m->beta_cmd, a.beta_cmd, sizeof m->beta_cmd);
    if (m->timing) m->t_step = fp_clock_seconds() - t_start;
    return FP_OK;
}
