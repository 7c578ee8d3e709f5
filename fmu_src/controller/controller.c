/*
 * FullPoseController: the paper's section III as a discrete-time system.  This file holds
 * the model's variable table and callbacks: defaults, initialization (the input bounds, the
 * filters' and blocks' start; the force sets, the shaping's limits and the detector's
 * constants are derived by derive_params.c), tunable parameters,
 * the step over the sample grid with the check of the inputs before each sample, and the
 * check of a restored state.  One sample, the sequence of the stages, is
 * controller_sample.c; the stages themselves are in their own files (stages.h).
 */
#include "controller.h"

#include <float.h>
#include <math.h>
#include <stddef.h>
#include <stdio.h>
#include <string.h>

#include "controller_vars.h"
#include "default_gains.h"
#include "fp_math.h"
#include "stages.h"

#define ELEM_SIZE_REAL sizeof(double)
#define ELEM_SIZE_INTEGER sizeof(int32_t)
#define ELEM_SIZE_BOOLEAN sizeof(int32_t)
#define CTRL_CHECK(name, vr, type, kind, rows, cols, dtype, range, desc)                         \
    FP_STATIC_ASSERT(sizeof(((ControllerModel *)0)->name) == (rows) * (cols) * ELEM_SIZE_##type, \
                     name##_size);                                                               \
    FP_STATIC_ASSERT((FP_##type == FP_REAL) == (FP_T_##dtype != FP_T_NONE), name##_dtype);
#define CTRL_AF_CHECK(name, vr, type, kind, rows, cols, dtype, range, desc)                      \
    FP_STATIC_ASSERT(sizeof(((FpAirframe *)0)->name) == (rows) * (cols) * ELEM_SIZE_##type,     \
                     name##_size);                                                              \
    FP_STATIC_ASSERT((FP_##type == FP_REAL) == (FP_T_##dtype != FP_T_NONE), name##_dtype);
CONTROLLER_VARIABLES(CTRL_CHECK, CTRL_AF_CHECK)
FP_STATIC_ASSERT(FP_POLYTOPE_MAX_FACETS == 64, polytope_cap_matches_table);
FP_STATIC_ASSERT(FP_FAIL_POLYTOPE_FACETS * FP_MAX_ROTORS == 256, fail_polytope_cap_matches_table);
FP_STATIC_ASSERT(FP_POLYTOPE_MAX_FACETS <= FP_WLS_MAX_CONS, polytope_fits_qp);
FP_STATIC_ASSERT(3 * FP_MAX_ROTORS <= FP_WLS_MAX_VARS, allocation_fits_qp);
FP_STATIC_ASSERT(6 + 3 * FP_MAX_ROTORS <= FP_WLS_MAX_ROWS, allocation_rows_fit_qp);

#define CTRL_ROW(name, vr, type, kind, rows, cols, dtype, range, desc)                           \
    {#name, vr, FP_##type, FP_##kind, rows, cols, offsetof(ControllerModel, name), FP_T_##dtype,  \
     range, desc},
#define CTRL_AF_ROW(name, vr, type, kind, rows, cols, dtype, range, desc)                        \
    {#name, vr, FP_##type, FP_##kind, rows, cols,                                                 \
     offsetof(ControllerModel, af) + offsetof(FpAirframe, name), FP_T_##dtype, range, desc},
static const FpVar controller_vars[] = {CONTROLLER_VARIABLES(CTRL_ROW, CTRL_AF_ROW)};
#define N_CTRL_VARS (sizeof controller_vars / sizeof controller_vars[0])

/* Row indices (CV_pos, ...): the input checks read their plausible ranges from the rows. */
#define CTRL_INDEX(name, vr, type, kind, rows, cols, dtype, range, desc) CV_##name,
enum { CONTROLLER_VARIABLES(CTRL_INDEX, CTRL_INDEX) CV_COUNT };

/* ------------------------------------------------------------------------ */
/* Defaults                                                                 */

#define FP_COPY_BLOCK(m, loop)                                                     \
    do {                                                                           \
        memcpy((m)->K_##loop##_A, fp_default_K_##loop##_A, sizeof (m)->K_##loop##_A); \
        memcpy((m)->K_##loop##_B, fp_default_K_##loop##_B, sizeof (m)->K_##loop##_B); \
        memcpy((m)->K_##loop##_C, fp_default_K_##loop##_C, sizeof (m)->K_##loop##_C); \
        memcpy((m)->K_##loop##_D, fp_default_K_##loop##_D, sizeof (m)->K_##loop##_D); \
    } while (0)

static void controller_set_defaults(void *model) {
    ControllerModel *m = (ControllerModel *)model;
    FpRotorSet rs;
    double w[6] = {0.0, 0.0, 0.0, 0.0, 0.0, 0.0};
    int i;
    memset(m, 0, sizeof *m);
    fp_paper_hexacopter(&m->af);
    fp_rotor_set_of(&m->af, &rs);
    m->armed = 1;
    m->Ts = FP_DESIGN_TS;
    /* H(s) at 80 rad/s, a design variable of the robust synthesis: INDI rejects a torque
     * disturbance (a lost rotor) at the filter's bandwidth, and at 50 rad/s no certified
     * first-order attitude design reached the hand-tuned bandwidth (docs/robust_design.md) */
    m->filt_wn = FP_DESIGN_FILT_WN;
    m->filt_zeta = FP_DESIGN_FILT_ZETA;
    /* The structured H-infinity design (python -m controller.gains_defaults) */
    FP_COPY_BLOCK(m, pos);
    FP_COPY_BLOCK(m, vel);
    FP_COPY_BLOCK(m, att);
    FP_COPY_BLOCK(m, rate);
    m->gamma_opt = 1000.0;
    m->W_u[0] = m->W_u[1] = m->W_u[2] = 1.0;
    m->W_u[3] = m->W_u[4] = 10.0;
    m->W_v[0] = m->W_v[1] = 100.0;
    m->W_v[2] = 10.0;
    m->euler_min[0] = m->euler_min[1] = -60.0 * CTRL_PI / 180.0;
    m->euler_max[0] = m->euler_max[1] = 60.0 * CTRL_PI / 180.0;
    m->force_constraint = 0;
    /* poly_n = fail_poly_n[i] = 0: every force set derived from the airframe at
     * initialization (ctrl_force_sets_resolve) */
    for (i = 0; i < FP_MAX_ROTORS; i++) m->rotor_health[i] = 1.0;
    m->poly_margin = 0.9;
    m->W_nu[0] = m->W_nu[1] = m->W_nu[2] = 1.0;
    /* Torque priority for roll and pitch; yaw, the weakest axis (drag torque and
     * tangential tilt only), ranks with the forces: with yaw at 100 a 0.3 rad heading
     * step saturated the servos for yaw and gave up the force, and the vehicle was lost. */
    m->W_nu[3] = m->W_nu[4] = 100.0;
    m->W_nu[5] = 1.0;
    m->yaw_rate_max = 0.0; /* derived with the heading's shaping limits */
    m->w_pref = 0.1;
    m->pref_omega_scale = 1.0 / 50.0;
    m->qp_max_iter = 50;
    /* Reference shaping: a jump flown at the airframe's pace (shaping_limits.c derives
     * every limit left at 0), at most at ref_tilt_max of tilt (a 10 m step must not become a
     * 50-degree lunge); roll and pitch steps at 1 rad/s and 2 rad/s^2. */
    m->ref_shaping = 1;
    m->ref_bandwidth = 10.0;
    m->ref_tilt_max = 15.0 * CTRL_PI / 180.0;
    m->ref_vel_max[0] = m->ref_vel_max[1] = 0.0;
    m->ref_acc_max[0] = m->ref_acc_max[1] = 0.0;
    m->ref_jerk_max[0] = m->ref_jerk_max[1] = 0.0;
    m->ref_att_rate_max[0] = m->ref_att_rate_max[1] = 1.0;
    m->ref_att_rate_max[2] = 0.0;
    m->ref_att_acc_max[0] = m->ref_att_acc_max[1] = 2.0;
    m->ref_att_acc_max[2] = 0.0;
    /* Fault detection (detect.c): on, as on a vehicle that must notice a broken propeller
     * itself; thresholds from docs/controller.md's measurements (no false alarm over the
     * shipped scenarios with sensor noise on). */
    m->fault_detect = 1;
    m->fault_loss_min = 0.1;
    m->fault_fit_max = 0.3;
    m->fault_time = 0.02;
    /* Measurements start at the hover trim of the default airframe. */
    w[2] = -m->af.mass * m->af.g;
    fp_preferred_config(&rs, w, m->alpha, m->beta, m->omega, NULL, 0);
    memcpy(m->omega_cmd, m->omega, sizeof m->omega_cmd);
    memcpy(m->alpha_cmd, m->alpha, sizeof m->alpha_cmd);
    memcpy(m->beta_cmd, m->beta, sizeof m->beta_cmd);
}

/* ------------------------------------------------------------------------ */
/* The inputs of a sample                                                   */

/* The most control samples one doStep may run: 10^5 (200 s at Ts = 2 ms, about two seconds
 * of CPU): a call that cannot be cancelled must stay short enough for an importer to wait.
 * Tighter than the FMI layer's cap of 10^6 internal steps: a sample costs ~10x an RK4 step. */
#define CTRL_MAX_SAMPLES 1e5

/* 1 if every input is usable: finite and within its plausible range, the range of its table
 * row (a value beyond it is finite but absurd, a sensor glitch or a unit error, and would
 * poison the filters for seconds; the vehicle's own range matches the plant's,
 * docs/robustness.md).  The actuator measurements are also held to the airframe: omega to
 * [-omega_max, 2 omega_max], alpha and beta to the servo limits +- CTRL_SERVO_MARGIN.
 * Else the first unusable input is described in why. */
/* A vector's element by name and index, a scalar by its name (for messages only: this
 * runs in the sample's check of every input). */
static const char *element_name(const FpVar *row, int i, char *buf, size_t size) {
    if (row->rows * row->cols > 1)
        snprintf(buf, size, "%s[%d]", row->name, i + 1);
    else
        snprintf(buf, size, "%s", row->name);
    return buf;
}

/* The inputs checked every sample, in order, and each one's element count. */
static int checked_inputs(const ControllerModel *m, const double *inputs[CTRL_N_CHECKED_INPUTS],
                          int counts[CTRL_N_CHECKED_INPUTS]) {
    static const int c[CTRL_N_CHECKED_INPUTS] = {3, 3, 3, 3, 3, 3, 3, 3, 3, 3, 0, 0, 0, 0, 1};
    int n = m->af.n_rotors;
    memcpy(counts, c, sizeof c);
    inputs[0] = m->pos_ref, inputs[1] = m->euler_ref, inputs[2] = m->vel_ref;
    inputs[3] = m->acc_ref, inputs[4] = m->euler_rate_ref, inputs[5] = m->pos;
    inputs[6] = m->vel, inputs[7] = m->acc, inputs[8] = m->euler, inputs[9] = m->rate;
    inputs[10] = m->omega, inputs[11] = m->alpha, inputs[12] = m->beta;
    inputs[13] = m->rotor_health, inputs[14] = &m->pose_age;
    counts[10] = counts[11] = counts[12] = counts[13] = n;
    return CTRL_N_CHECKED_INPUTS;
}

static const int checked_rows[CTRL_N_CHECKED_INPUTS] = {
    CV_pos_ref, CV_euler_ref, CV_vel_ref, CV_acc_ref, CV_euler_rate_ref, CV_pos, CV_vel,
    CV_acc, CV_euler, CV_rate, CV_omega, CV_alpha, CV_beta, CV_rotor_health, CV_pose_age};

/* The plausible interval of input k's element i beyond its declared range. */
static void extra_bounds(const ControllerModel *m, int k, int i, double *a, double *b) {
    *a = -HUGE_VAL, *b = HUGE_VAL;
    if (checked_rows[k] == CV_omega) {
        *a = -m->af.omega_max, *b = 2.0 * m->af.omega_max;
    } else if (checked_rows[k] == CV_alpha || checked_rows[k] == CV_beta) {
        int al = checked_rows[k] == CV_alpha;
        *a = (al ? m->af.alpha_min[i] : m->af.beta_min[i]) - CTRL_SERVO_MARGIN;
        *b = (al ? m->af.alpha_max[i] : m->af.beta_max[i]) + CTRL_SERVO_MARGIN;
    }
}

/* in_lo/in_hi: each element's declared range and plausible interval as one closed,
 * finite interval (an open bound moved to the next double inside, infinities excluded), so
 * that v is usable exactly when in_lo <= v <= in_hi (NaN fails both). */
static void derive_input_bounds(ControllerModel *m) {
    int k, i;
    for (k = 0; k < CTRL_N_CHECKED_INPUTS; k++) {
        const FpRange *r = &controller_vars[checked_rows[k]].range;
        for (i = 0; i < FP_MAX_ROTORS; i++) {
            double a, b, lo = -DBL_MAX, hi = DBL_MAX;
            extra_bounds(m, k, i, &a, &b);
            if (r->flags & FP_RANGE_LO)
                lo = (r->flags & FP_RANGE_LO_OPEN) ? nextafter(r->lo, HUGE_VAL) : r->lo;
            if (r->flags & FP_RANGE_HI)
                hi = (r->flags & FP_RANGE_HI_OPEN) ? nextafter(r->hi, -HUGE_VAL) : r->hi;
            m->in_lo[k][i] = fmax(fmax(lo, a), -DBL_MAX);
            m->in_hi[k][i] = fmin(fmin(hi, b), DBL_MAX);
        }
    }
}

/* Why an input is unusable, in words (the slow path: only when the check failed). */
static int inputs_usable_why(const ControllerModel *m, char *why, size_t size) {
    const double *inputs[CTRL_N_CHECKED_INPUTS];
    int counts[CTRL_N_CHECKED_INPUTS];
    int i, k, n_in = checked_inputs(m, inputs, counts);
    for (k = 0; k < n_in; k++) {
        const FpVar *row = &controller_vars[checked_rows[k]];
        for (i = 0; i < counts[k]; i++) {
            double v = inputs[k][i], a, b;
            char range[96], name[48];
            extra_bounds(m, k, i, &a, &b);
            if (!isfinite(v)) {
                snprintf(why, size, "input %s = %g is not finite",
                         element_name(row, i, name, sizeof name), v);
                return 0;
            }
            if (!fp_range_contains(&row->range, v)) {
                snprintf(why, size, "input %s = %g is outside its plausible range %s",
                         element_name(row, i, name, sizeof name), v,
                         fp_range_text(&row->range, 0, range, sizeof range));
                return 0;
            }
            if (v < a || v > b) {
                snprintf(why, size, "input %s = %g is outside its plausible range [%g, %g]",
                         element_name(row, i, name, sizeof name), v, a, b);
                return 0;
            }
        }
    }
    return 1;
}

static int inputs_usable(const ControllerModel *m, char *why, size_t size) {
    const double *inputs[CTRL_N_CHECKED_INPUTS];
    int counts[CTRL_N_CHECKED_INPUTS];
    int i, k, n_in = checked_inputs(m, inputs, counts), ok = 1;
    for (k = 0; k < n_in; k++)
        for (i = 0; i < counts[k]; i++)
            ok &= inputs[k][i] >= m->in_lo[k][i] && inputs[k][i] <= m->in_hi[k][i];
    return ok ? 1 : inputs_usable_why(m, why, size);
}

/* Unusable inputs: hold the last command (the sample is skipped, filters and blocks keep
 * their state), say so once per episode, and recover at the first usable sample. */
static int inputs_valid(ControllerModel *m, const FpLogger *logger) {
    char why[160];
    if (inputs_usable(m, why, sizeof why)) {
        if (m->holding > 0)
            fp_log(logger, FP_WARNING, FP_LOG_WARNING,
                   "inputs usable again after %ld held sample(s): control resumed",
                   (long)m->holding);
        m->holding = 0;
        return 1;
    }
    /* every held sample says so (an fmi2Warning always comes with a message); the first in
     * full, the others briefly */
    if (m->holding == 0)
        fp_log(logger, FP_WARNING, FP_LOG_WARNING, "%s: holding the last valid command", why);
    else
        fp_log(logger, FP_WARNING, FP_LOG_WARNING, "still holding (sample %ld): %s",
               (long)m->holding + 1, why);
    if (m->holding < INT32_MAX) m->holding++;
    return 0;
}

/* ------------------------------------------------------------------------ */
/* Model callbacks                                                          */

/* The land detector's sample (ground.c) into the outputs landed, ground_support; a negative
 * ground.carried judges the measurements at once (at initialization). */
static void ground_sample(ControllerModel *m, CtrlGroundOut *out) {
    CtrlGroundParams p;
    CtrlGroundInputs in;
    int now = m->ground.carried < 0;
    p.mass = m->af.mass, p.g = m->af.g, p.Ts = now ? CTRL_LAND_TIME : m->Ts;
    in.support = m->ground_support, in.vel = m->vel;
    in.pos = m->pos, in.pos_ref = m->pos_ref, in.armed = m->armed;
    if (now) m->ground.carried = 0;
    ctrl_ground(&p, &in, &m->ground, out);
    m->landed = out->landed;
}

/* The ground's support from the raw measurements (ground.c): at initialization and while
 * the rotors idle; a flying sample computes it from its filtered signals. */
static void raw_ground_support(ControllerModel *m) {
    double f_b[3], tau_b[3], r[9];
    rot_zyx_jacobian(m->euler, r, NULL, NULL);
    fp_rotor_wrench(&m->rotors, m->alpha, m->beta, m->omega, m->health, f_b, tau_b);
    m->ground_support = ctrl_ground_support(m->af.mass, m->af.g, r, f_b, m->acc);
}

/* The controller's dynamic state started from the inputs as they are: the filters in steady
 * state at the measurements, the blocks at rest, the reference as given (no jump being
 * shaped), the twin at the reference pose, the detector fresh.  At initialization, and every
 * sample the rotors idle (ground.c), so that nothing winds up on the ground. */
static void restart_states(ControllerModel *m) {
    CtrlFilterInputs fin;
    int i;
    ctrl_predict_pose(m->pos, m->vel, m->acc, m->euler, m->rate, m->pose_age, m->pose_now);
    fin = ctrl_filter_inputs(m);
    ctrl_filters_start(&fin, m->roll.filt);
    memset(m->roll.blk, 0, sizeof m->roll.blk);
    m->roll.psi_raw = m->roll.psi_unwrapped = isfinite(m->pose_now[8]) ? m->pose_now[8] : 0.0;
    m->roll.psi_ref_raw = m->roll.psi_ref_unwrapped = isfinite(m->euler_ref[2]) ? m->euler_ref[2] : 0.0;
    memcpy(m->mu_c, m->euler_ref, sizeof m->mu_c);
    /* the reference as given, no jump being shaped; the twin at the reference pose */
    memset(&m->roll.shaping, 0, sizeof m->roll.shaping);
    ctrl_detect_start(&m->roll.detect);
    m->detect_p = ctrl_detect_params(m);
    for (i = 0; i < FP_MAX_ROTORS; i++) m->rotor_eff_est[i] = 1.0;
    memset(m->indi_residual, 0, sizeof m->indi_residual);
    m->rotors_detected = 0;
    memset(&m->roll.twin, 0, sizeof m->roll.twin);
    memcpy(m->roll.twin.mu, m->euler_ref, sizeof m->roll.twin.mu);
    m->roll.twin.mu[2] = m->roll.psi_ref_unwrapped;
    m->roll.twin.f[2] = -m->af.mass * m->af.g;
    memcpy(m->mu_ff, m->roll.twin.mu, sizeof m->mu_ff);
    memcpy(m->euler_ref_s, m->roll.twin.mu, sizeof m->euler_ref_s);
    memcpy(m->mu_rate_ff, m->euler_rate_ref, sizeof m->mu_rate_ff);
    memcpy(m->pos_ref_s, m->pos_ref, sizeof m->pos_ref_s);
    memcpy(m->vel_ref_s, m->vel_ref, sizeof m->vel_ref_s);
    memcpy(m->acc_ref_s, m->acc_ref, sizeof m->acc_ref_s);
}

static FpStatus controller_initialize(void *model, double t0, const FpLogger *logger) {
    ControllerModel *m = (ControllerModel *)model;
    CtrlGroundOut ground;
    int i, n;
    char why[160];
    if (ctrl_check_parameters(m, controller_vars, N_CTRL_VARS, logger) != 0) return FP_ERROR;
    fp_rotor_set_of(&m->af, &m->rotors); /* (validated: the force sets and samples use it) */
    if (ctrl_prepare_force_sets(m, controller_vars, N_CTRL_VARS, logger) != FP_OK) return FP_ERROR;
    if (ctrl_derive_shaping_limits(m, logger) != FP_OK) return FP_ERROR;
    derive_input_bounds(m);
    if (!inputs_usable(m, why, sizeof why)) { /* the initial state would be poisoned */
        fp_log(logger, FP_ERROR, FP_LOG_ERROR, "initialization: %s", why);
        return FP_ERROR;
    }
    m->holding = 0;
    m->grid_t0 = t0;
    m->inputs_age = 0.0;
    m->samples_run = 0;
    m->warned_coarse = 0;
    n = m->af.n_rotors;
    /* what the samples need of the geometry alone, once */
    memset(&m->rotor_trig, 0, sizeof m->rotor_trig);
    fp_rotor_trig_mounts(&m->rotors, &m->rotor_trig);
    fp_preferred_prepare(&m->rotors, &m->pref_split, NULL, 0); /* apply checks its status */
    ctrl_filter_discretize(m->filt_wn, m->filt_zeta, m->Ts, m->filt_phi, m->filt_gamma);
    restart_states(m);
    for (i = 0; i < CTRL_N_FILTERS; i++)
        if (!isfinite(m->roll.filt[i][0])) {
            fp_log(logger, FP_ERROR, FP_LOG_ERROR,
                   "initial measurements must be finite (filter slot %d)", i + 1);
            return FP_ERROR;
        }
    m->guid_c_rows = 0; /* (the twin's: its memset above) */
    if (fp_wls_setup(&m->guid, 5, 8, m->set_n) != FP_OK ||
        fp_wls_setup(&m->twin_qp, 5, 8, m->set_n) != FP_OK ||
        fp_wls_setup(&m->alloc, 3 * n, 6 + 3 * n, 0) != FP_OK) {
        fp_log(logger, FP_ERROR, FP_LOG_ERROR, "allocation problem sizes exceed the solver caps");
        return FP_ERROR;
    }
    /* initial commands hold the measured actuator state */
    for (i = 0; i < FP_MAX_ROTORS; i++) {
        m->omega_cmd[i] = i < n ? m->omega[i] : 0.0;
        m->alpha_cmd[i] = i < n ? m->alpha[i] : 0.0;
        m->beta_cmd[i] = i < n ? m->beta[i] : 0.0;
    }
    {
        double torque[3];
        fp_rotor_wrench(&m->rotors, m->alpha, m->beta, m->omega, NULL, m->f_b_c, torque);
        memcpy(m->f_b_ref, m->f_b_c, sizeof m->f_b_ref);
    }
    m->feasible = 1;
    m->guid_status = m->alloc_status = 0;
    m->guid_iter = m->alloc_iter = 0;
    m->sat_flags = m->guid_flags = 0;
    memset(m->acc_c, 0, sizeof m->acc_c);
    memset(m->rate_c, 0, sizeof m->rate_c);
    memset(m->dnu_c, 0, sizeof m->dnu_c);
    memset(m->alloc_residual, 0, sizeof m->alloc_residual);
    m->t_step = m->t_guid = m->t_alloc = 0.0;
    m->lost_mask = 0;
    m->rotors_lost = 0;
    m->active_polytope = 0;
    m->hover_possible = m->hover_ok[0];
    ctrl_update_rotor_losses(m, logger);
    /* a vehicle that starts resting on the ground has landed already (no time to wait):
     * its first sample shapes the reference from where it stands */
    memset(&m->ground, 0, sizeof m->ground);
    m->ground.carried = -1; /* (ground_sample: the start is judged at once) */
    raw_ground_support(m);
    ground_sample(m, &ground);
    m->idle = 0;
    m->shape_from_pose = m->landed;
    return FP_OK;
}

/* A sample with the rotors idle (ground.c): stopped when disarmed, at omega_min when armed,
 * the servos at their neutral position (0, within their limits); the dynamic state restarted
 * from the measurements, and the next flying sample shapes the reference from the pose. */
static void idle_sample(ControllerModel *m) {
    int i, n = m->af.n_rotors;
    double spin = m->armed ? m->af.omega_min : 0.0;
    restart_states(m);
    fp_wls_reset(&m->guid);
    fp_wls_reset(&m->alloc);
    fp_wls_reset(&m->twin_qp);
    for (i = 0; i < FP_MAX_ROTORS; i++) {
        m->omega_cmd[i] = i < n ? spin : 0.0;
        m->alpha_cmd[i] = i < n ? fp_clamp(0.0, m->af.alpha_min[i], m->af.alpha_max[i]) : 0.0;
        m->beta_cmd[i] = i < n ? fp_clamp(0.0, m->af.beta_min[i], m->af.beta_max[i]) : 0.0;
    }
    memset(m->acc_c, 0, sizeof m->acc_c);
    memset(m->rate_c, 0, sizeof m->rate_c);
    memset(m->dnu_c, 0, sizeof m->dnu_c);
    m->feasible = 1; /* (nothing is flown, nothing is infeasible) */
    m->shape_from_pose = 1;
    raw_ground_support(m);
}

/* One sample: the land detector, then the cascade or, on the ground, idle rotors. */
static FpStatus sample(ControllerModel *m, const FpLogger *logger) {
    CtrlGroundOut ground;
    ground_sample(m, &ground);
    m->idle = ground.idle;
    if (ground.idle) {
        idle_sample(m);
        return FP_OK;
    }
    return ctrl_sample(m, logger);
}

static FpStatus controller_tunables_changed(void *model, const FpLogger *logger) {
    ControllerModel *m = (ControllerModel *)model;
    if (ctrl_check_tunables(m, controller_vars, N_CTRL_VARS, logger)) return FP_ERROR;
    derive_input_bounds(m); /* (limits that bound the inputs may be among them) */
    return FP_OK;
}

/*
 * The sampling semantics (docs/controller.md, "Communication steps"): the controller samples
 * on its own grid t_k = t0 + k Ts (t0: the experiment's start time), whatever h is.  A doStep
 * from t to t + h runs, in order, the samples of the grid instants in [t, t + h): an FMU's
 * inputs hold from the communication point they were set at to the next, so the inputs set
 * before the call are the values at those instants.  Each sample advances the filters and
 * blocks by one Ts.  The outputs after the call are those of the last sample run, held
 * until the next one; an instant at t + h (within the tolerance of fp_steps_to_cover, which
 * covers importers that sum their steps) is the next call's, with the inputs set at t + h.
 * With h = Ts that is one sample per step, from the inputs at t_k, as it always was.  The
 * instants are counted (samples_run) against t0 + k Ts, never found by summing steps, so
 * the grid cannot drift.
 */
static FpStatus controller_step(void *model, double t, double h, const FpLogger *logger) {
    ControllerModel *m = (ControllerModel *)model;
    double tol = FP_STEP_TOL * h + FP_TIME_TOL * (fabs(t) + fabs(m->grid_t0));
    double due = fp_steps_to_cover(t + h - m->grid_t0, m->Ts, tol);
    double samples = due - (double)m->samples_run;
    FpStatus status = FP_OK;
    long k, n;
    if (!(samples > 0.0)) samples = 0.0; /* no grid instant in [t, t + h): outputs held */
    if (fp_check_step_work(h, samples, CTRL_MAX_SAMPLES, "control samples", logger) != FP_OK)
        return FP_ERROR;
    if (!m->warned_coarse && fp_steps_to_cover(h, m->Ts, FP_STEP_TOL * h) > 1.0) {
        /* once per run: every such step degrades control the same way */
        m->warned_coarse = 1;
        status = FP_WARNING;
        fp_log(logger, FP_WARNING, FP_LOG_WARNING,
               "communication step %.12g s is longer than the sample time Ts = %.12g s: the "
               "samples within one step all use the inputs of its start, held, so control "
               "degrades (docs/controller.md, \"Communication steps\"); use steps of at "
               "most Ts (said once)",
               h, m->Ts);
    }
    n = (long)samples;
    for (k = 0; k < n; k++) {
        /* the sample's instant is on the grid, its inputs are those set at t */
        double age = m->grid_t0 + (double)m->samples_run * m->Ts - t;
        m->inputs_age = age > tol ? age : 0.0;
        if (!inputs_valid(m, logger) || sample(m, logger) != FP_OK) status = FP_WARNING;
        m->samples_run++;
    }
    return status;
}

static int wls_valid(const FpWls *w) {
    return w->n_vars >= 0 && w->n_vars <= FP_WLS_MAX_VARS && w->n_rows >= 0 &&
           w->n_rows <= FP_WLS_MAX_ROWS && w->n_cons >= 0 && w->n_cons <= FP_WLS_MAX_CONS;
}

static int structure_valid(const ControllerModel *m) {
    int i;
    if (m->af.n_rotors < 1 || m->af.n_rotors > FP_MAX_ROTORS || m->rotors.n < 0 ||
        m->rotors.n > FP_MAX_ROTORS || m->poly_n < 0 || m->poly_n > FP_POLYTOPE_MAX_FACETS ||
        m->set_n < 0 || m->set_n > FP_POLYTOPE_MAX_FACETS ||
        m->active_polytope < -1 || m->active_polytope > FP_MAX_ROTORS ||
        !wls_valid(&m->guid) || !wls_valid(&m->alloc) || !wls_valid(&m->twin_qp))
        return 0;
    for (i = 0; i < FP_MAX_ROTORS; i++)
        if (m->fail_poly_n[i] < 0 || m->fail_poly_n[i] > FP_FAIL_POLYTOPE_FACETS ||
            m->set_fail_n[i] < 0 || m->set_fail_n[i] > FP_FAIL_POLYTOPE_FACETS)
            return 0;
    return 1;
}

/* The detector's constants of a restored model are those detect_params gives for its
 * parameters (all fixed after initialization), bit for bit. */
static int detect_params_agree(const ControllerModel *m) {
    CtrlDetectParams p = ctrl_detect_params(m);
    return memcmp(&p, &m->detect_p, sizeof p) == 0;
}

static FpStatus controller_check_restored(const void *model, int initialized,
                                          const FpLogger *logger) {
    const ControllerModel *m = (const ControllerModel *)model;
    if (!structure_valid(m)) {
        fp_log(logger, FP_ERROR, FP_LOG_ERROR,
               "restored state: a size or index is beyond its cap (rotors %ld, facets %ld)",
               (long)m->af.n_rotors, (long)m->poly_n);
        return FP_ERROR;
    }
    if (!initialized) return FP_OK; /* parameters are checked when initialization ends */
    if (ctrl_check_parameters(m, controller_vars, N_CTRL_VARS, logger) != 0) {
        fp_log(logger, FP_ERROR, FP_LOG_ERROR, "restored state: its parameters are invalid");
        return FP_ERROR;
    }
    /* what initialization derives from the (fixed) parameters, as it derives it: the rotor
     * set, and the detector's constants (detect.c divides by arm^2 and indexes by a count
     * that reaches persist >= 1) */
    if (m->rotors.n != m->af.n_rotors) {
        fp_log(logger, FP_ERROR, FP_LOG_ERROR,
               "restored state: rotor set of %ld rotors, the airframe has %ld",
               (long)m->rotors.n, (long)m->af.n_rotors);
        return FP_ERROR;
    }
    if (!detect_params_agree(m)) {
        fp_log(logger, FP_ERROR, FP_LOG_ERROR,
               "restored state: the fault detector's constants (mean arm %g m, %ld samples to "
               "persist) are not those its parameters give",
               m->detect_p.arm, (long)m->detect_p.persist);
        return FP_ERROR;
    }
    if (!fp_all_finite(&m->roll.filt[0][0], sizeof m->roll.filt / sizeof(double)) ||
        !fp_all_finite(&m->roll.blk[0][0], sizeof m->roll.blk / sizeof(double)) ||
        !fp_all_finite(m->roll.shaping.e_pos, 15) || !fp_all_finite(m->roll.shaping.pos_in, 15) ||
        !isfinite(m->inputs_age) ||
        !fp_all_finite(m->roll.twin.mu, 3) || !fp_all_finite(m->roll.twin.f, 3) ||
        !fp_all_finite(m->roll.detect.est, FP_MAX_ROTORS) ||
        !fp_all_finite(m->acc_limit, 2) || !fp_all_finite(m->vel_limit, 2) ||
        !fp_all_finite(m->jerk_limit, 2) || !fp_all_finite(m->att_rate_limit, 3) ||
        !fp_all_finite(m->att_acc_limit, 3) || !isfinite(m->yaw_rate_limit) ||
        !fp_all_finite(&m->set_A[0][0], sizeof m->set_A / sizeof(double)) ||
        !fp_all_finite(m->set_b, FP_POLYTOPE_MAX_FACETS) ||
        !fp_all_finite(&m->set_fail_A[0][0], sizeof m->set_fail_A / sizeof(double)) ||
        !fp_all_finite(m->set_fail_b, FP_MAX_ROTORS * FP_FAIL_POLYTOPE_FACETS) ||
        !fp_all_finite(m->poly_d, FP_POLYTOPE_MAX_FACETS) ||
        !fp_all_finite(m->fail_d, FP_MAX_ROTORS * FP_FAIL_POLYTOPE_FACETS) ||
        !fp_all_finite(&m->filt_phi[0][0], 4) || !fp_all_finite(m->filt_gamma, 2) ||
        !isfinite(m->grid_t0) || m->samples_run < 0) {
        fp_log(logger, FP_ERROR, FP_LOG_ERROR,
               "restored state: the filter or block states or the force sets are not "
               "finite, or the sample grid is invalid");
        return FP_ERROR;
    }
    return FP_OK;
}

static const FpModelInfo controller_info = {
    "FullPoseController",
    "Full-pose controller for multirotors: robust INDI cascade with first-order blocks, WLS "
    "guidance allocation over the feasible-force polytope and WLS inner allocation "
    "(Hachem et al., section III)",
    sizeof(ControllerModel),
    controller_vars,
    N_CTRL_VARS,
    0.002,
    10.0,
    controller_set_defaults,
    controller_initialize,
    controller_step,
    controller_tunables_changed,
    controller_check_restored,
    offsetof(ControllerModel, initialized),
    NULL,
    NULL, /* co-simulation only: sampled on its own grid, no continuous state */
};

const FpModelInfo *controller_model_info(void) { return &controller_info; }
