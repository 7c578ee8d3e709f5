/* FullPoseController: the robust INDI cascade of the paper's section III with
 * WLS guidance allocation and inner allocation, sampled at Ts. */
#ifndef CONTROLLER_H
#define CONTROLLER_H

#include <stdint.h>

#include "fp_model.h"
#include "multirotor.h"
#include "wls.h"

/* Capacities of the feasible-force sets (facets): S(0), and each single-failure set. */
#define FP_POLYTOPE_MAX_FACETS 64
#define FP_FAIL_POLYTOPE_FACETS 32

#define CTRL_N_CHECKED_INPUTS 15 /* the inputs checked every sample (controller.c) */
#define CTRL_N_FILTERS (24 + 3 * FP_MAX_ROTORS) /* measurements, pos/vel/euler refs, actuators */

/* The reference shaping's state (reference.c): the last input and the error state, the
 * shaped reference minus the input (zero: the input passes unchanged). */
typedef struct {
    int32_t started;
    double pos_in[3], vel_in[3], acc_in[3], mu_in[3], mu_rate_in[3];
    double e_pos[3], e_vel[3], e_acc[3], e_mu[3], e_rate[3];
} CtrlShaping;

/* The land detector's state (ground.c). */
typedef struct {
    int32_t carried; /* consecutive samples the ground has carried the vehicle */
    int32_t landed;
} CtrlGroundState;

/* The detector's constants (detect.c), derived from fixed parameters at initialization. */
typedef struct {
    double mass, inertia[3][3], g, Ts;
    double arm;        /* m: the rotors' mean distance from the centre (torque scale) */
    double acc_of_torque[3][3]; /* arm I^-1: a torque as the acceleration it causes */
    double loss_min;   /* smallest change of a rotor's efficiency an event may conclude */
    double fit_max;    /* share of an event's residual a rotor's model may leave unexplained */
    double wrench_min; /* m/s^2: a rotor whose full wrench stays below this is not fitted */
    double onset;      /* m/s^2: residual change (smoothed) that opens an event */
    double floor2;     /* (m/s^2)^2: per-sample noise floor the hypotheses' gap must exceed */
    double base_gain;  /* per sample: how fast the quiet residual level follows */
    double probe_omega; /* rad/s: a lost rotor's idle speed, 30 % of its share of the weight */
    int32_t persist;   /* samples an event lasts before it may conclude a fault */
    int32_t window;    /* samples after which an unexplained event is taken as a load */
} CtrlDetectParams;

/* Estimates below this: the rotor cannot produce thrust and is lost (motor idled at the
 * probe speed); a lost rotor's estimate back at or above CTRL_DETECT_RESTORE restores it. */
/* The land detector (ground.c): at rest below this speed, carried for this long; a reference
 * no higher than this above the vehicle keeps a landed vehicle's rotors idle. */
#define CTRL_LAND_SPEED 0.1  /* m/s */
#define CTRL_LAND_TIME 0.1   /* s */
#define CTRL_LAND_MARGIN 0.05 /* m */
#define CTRL_DETECT_LOST 0.15
#define CTRL_DETECT_RESTORE 0.3
#define CTRL_PROBE_HALF_PERIOD 0.05 /* s */

/* Samples the detector averages its raw signals over (detect.c). */
#define CTRL_DETECT_SPAN 4

/* Rotor-fault detection (detect.c): the last CTRL_DETECT_SPAN + 1 samples of the raw
 * signals, the residual's quiet level and noise, the event under test (its least-squares
 * sums), each rotor's efficiency estimate (1 until a detection), the rotors found faulty
 * and those the detector holds lost (bit i-1: rotor i). */
typedef struct {
    int32_t filled, head, active, n, found_mask, lost_mask;
    double est[FP_MAX_ROTORS];
    double rate[CTRL_DETECT_SPAN + 1][3], force[CTRL_DETECT_SPAN + 1][3]; /* accelerations */
    double wrench[CTRL_DETECT_SPAN + 1][FP_MAX_ROTORS][6]; /* each rotor's, as accelerations */
    double base[6];   /* the residual's level before the event */
    double onset[6];  /* smoothed residual change */
    double noise2;    /* the residual's mean square per sample about its level */
    double s_rr, s_r[6], s_ww[FP_MAX_ROTORS], s_wr[FP_MAX_ROTORS]; /* event sums */
} CtrlDetect;

/* The reference twin's pose (guidance.c, ctrl_guidance_twin): attitude and body force. */
typedef struct {
    double mu[3], f[3];
    int32_t active; /* its last sample solved the QP (the reference pose was infeasible) */
    int32_t c_rows; /* which force set's rows its QP's C holds (build_qp; 0: none yet) */
} CtrlTwin;

/* What one control sample advances, in one place: a sample that computed a non-finite
 * value is discarded by restoring a copy of this (controller_sample.c, ctrl_sample). */
typedef struct {
    double filt[CTRL_N_FILTERS][2];        /* [value, derivative] per filtered signal */
    double psi_raw, psi_unwrapped;         /* heading unwrapping before filtering */
    double psi_ref_raw, psi_ref_unwrapped; /* the same for the heading reference */
    double blk[4][3];                      /* states of the pos, vel, att, rate blocks */
    CtrlShaping shaping;
    CtrlDetect detect;
    CtrlTwin twin;
} CtrlRolled;

typedef struct {
    /* parameters */
    double Ts;
    FpAirframe af; /* the airframe model (common/airframe_vars.h) */
    double filt_wn, filt_zeta;
    double K_pos_A[3], K_pos_B[3], K_pos_C[3], K_pos_D[3];
    double K_vel_A[3], K_vel_B[3], K_vel_C[3], K_vel_D[3];
    double K_att_A[3], K_att_B[3], K_att_C[3], K_att_D[3];
    double K_rate_A[3], K_rate_B[3], K_rate_C[3], K_rate_D[3];
    double gamma_opt, W_u[5], W_v[3], euler_min[2], euler_max[2];
    int32_t force_constraint, poly_n;
    double poly_A[FP_POLYTOPE_MAX_FACETS][3], poly_b[FP_POLYTOPE_MAX_FACETS], poly_margin;
    int32_t fail_poly_n[FP_MAX_ROTORS];
    double fail_poly_A[FP_MAX_ROTORS * FP_FAIL_POLYTOPE_FACETS][3];
    double fail_poly_b[FP_MAX_ROTORS * FP_FAIL_POLYTOPE_FACETS];
    double W_nu[6], w_pref, pref_omega_scale, yaw_rate_max;
    int32_t ref_shaping;
    double ref_bandwidth, ref_tilt_max, ref_vel_max[2], ref_acc_max[2], ref_jerk_max[2];
    double ref_att_rate_max[3], ref_att_acc_max[3];
    int32_t fault_detect;
    double fault_loss_min, fault_fit_max, fault_time;
    int32_t qp_max_iter, timing;
    /* inputs */
    double pos_ref[3], euler_ref[3], vel_ref[3], acc_ref[3], euler_rate_ref[3];
    double pos[3], vel[3], acc[3], euler[3], rate[3];
    double omega[FP_MAX_ROTORS], alpha[FP_MAX_ROTORS], beta[FP_MAX_ROTORS];
    double rotor_health[FP_MAX_ROTORS];
    double pose_age;
    int32_t armed;
    /* outputs */
    double omega_cmd[FP_MAX_ROTORS], alpha_cmd[FP_MAX_ROTORS], beta_cmd[FP_MAX_ROTORS];
    double mu_c[3], f_b_ref[3], f_b_c[3];
    int32_t feasible, guid_status, guid_iter, alloc_status, alloc_iter, sat_flags, guid_flags;
    double acc_c[3], rate_c[3], dnu_c[6], alloc_residual[6];
    int32_t rotors_lost, hover_possible, active_polytope;
    double t_step, t_guid, t_alloc;
    double pos_ref_s[3], vel_ref_s[3], acc_ref_s[3], euler_ref_s[3], mu_ff[3], mu_rate_ff[3];
    double ref_acc_limit[2], ref_vel_limit[2], ref_jerk_limit[2];
    double ref_att_rate_limit[3], ref_att_acc_limit[3];
    double rotor_eff_est[FP_MAX_ROTORS], indi_residual[6];
    int32_t rotors_detected;
    int32_t landed, idle;
    double ground_support;
    /* internal state */
    FpRotorSet rotors;
    double filt_phi[2][2], filt_gamma[2]; /* discretized H(s): x+ = Phi x + Gamma u */
    CtrlRolled roll; /* what a sample advances: one copy rolls a discarded sample back */
    double pose_now[9]; /* pos, vel, euler predicted over pose_age to the sample (ctrl_predict_pose) */
    double inertia_inv[3][3];
    /* The force sets in use (prepare_force_sets): the parameters poly_* / fail_poly_* where
     * given (count > 0), else derived from the airframe at initialization (derive_sets.c). */
    int32_t set_n;                                        /* S(0): facets */
    double set_A[FP_POLYTOPE_MAX_FACETS][3], set_b[FP_POLYTOPE_MAX_FACETS];
    int32_t set_fail_n[FP_MAX_ROTORS];                    /* 0: that loss leaves no set */
    double set_fail_A[FP_MAX_ROTORS * FP_FAIL_POLYTOPE_FACETS][3];
    double set_fail_b[FP_MAX_ROTORS * FP_FAIL_POLYTOPE_FACETS];
    int32_t sets_derived;                  /* bit 0: S(0) derived; bit i: rotor i's set */
    double fz_min, fz_max;                 /* f_bz range of the polytope */
    double fail_fz[FP_MAX_ROTORS][2];      /* the same for each single-failure set */
    double poly_d[FP_POLYTOPE_MAX_FACETS]; /* offsets of the margin-scaled nominal polytope */
    double fail_d[FP_MAX_ROTORS * FP_FAIL_POLYTOPE_FACETS]; /* the same per failure set */
    int32_t hover_ok[FP_MAX_ROTORS + 1];   /* hover force inside: [0] nominal, [i] rotor i lost */
    int32_t lost_mask;                     /* rotors treated as lost (bit i-1: rotor i) */
    int32_t holding;                       /* samples held since an unusable input (0: none) */
    /* every input element's usable interval, closed and finite (derive_input_bounds): the
     * per-sample check is two comparisons each */
    double in_lo[CTRL_N_CHECKED_INPUTS][FP_MAX_ROTORS], in_hi[CTRL_N_CHECKED_INPUTS][FP_MAX_ROTORS];
    double grid_t0;                        /* the sample grid: instants grid_t0 + k Ts */
    int64_t samples_run;                   /* k of the next sample: the grid instants done */
    int32_t warned_coarse;                 /* the h > Ts warning was given */
    double inputs_age;                     /* this sample's instant minus the communication
                                            * point its inputs were set at (0 at h = Ts) */
    FpRotorTrig rotor_trig;     /* sin, cos of the rotors' mounting azimuths (gamma part) */
    FpPreferredSplit pref_split; /* the preferred configuration's geometry, all rotors */
    CtrlDetectParams detect_p;
    double health[FP_MAX_ROTORS]; /* efficiencies in use: rotor_health, or lower if detected */
    /* the shaping's limits in use (as given, or derived: shaping_limits.c) */
    double acc_limit[2], vel_limit[2], jerk_limit[2], att_rate_limit[3], att_acc_limit[3];
    double yaw_rate_limit; /* the heading-rate command limit when yaw_rate_max is 0 */
    FpWls guid, alloc, twin_qp;
    int32_t guid_c_rows; /* which force set's rows guid's C holds (build_qp; 0: none yet) */
    CtrlGroundState ground; /* the land detector (ground.c) */
    int32_t shape_from_pose; /* the next sample starts the shaping at the vehicle's pose */
    int32_t initialized; /* the glue's marker (FpModelInfo.initialized_offset); in padding */
} ControllerModel;

const FpModelInfo *controller_model_info(void);

#endif
