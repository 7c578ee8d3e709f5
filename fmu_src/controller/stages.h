/*
 * The stages of one FullPoseController sample, as controller_sample.c sequences them:
 *
 *   reference.c      reference shaping: jumps of the input flown within limits
 *   guidance.c       (first) the reference twin: the feed-forward attitude mu_ff
 *   filters.c        H(s) on every measurement, reference and actuator feedback
 *   guidance.c       K_xi, K_xidot, outer INDI and the WLS guidance QP: mu_c, df_b_c
 *   stabilization.c  attitude and rate blocks, inner INDI: rate_c, dtau_c
 *   allocation.c     the WLS inner allocation on B''(u_a,m): actuator commands
 *   force_sets.c     the feasible-force sets S(0): prepared at initialization, the one in
 *                    use picked after rotor losses
 *   validate.c       parameter validation (the airframe rules are common/fp_params.c)
 *
 * Each stage is a function of explicit inputs, parameters and state: parameters and inputs
 * come in through const pointers (views of the ControllerModel members, built by
 * controller_sample.c), what a stage carries from sample to sample through a small state struct
 * of pointers, and it writes its results only to its output struct or arrays.  Symbols are
 * the paper's: mu (Euler attitude), nu = [f_b; tau_b] (virtual control), B2 = B''(u_a).
 */
#ifndef CTRL_STAGES_H
#define CTRL_STAGES_H

#include <math.h>
#include <stdint.h>

#include "controller.h"
#include "fp_params.h"
#include "multirotor.h"
#include "wls.h"

#define CTRL_PI 3.14159265358979323846

/* Slots of ControllerModel.filt, the filter states [value, derivative] per signal. */
enum { F_POS = 0, F_VEL = 3, F_ACC = 6, F_EULER = 9, F_RATE = 12, F_POS_REF = 15, F_VEL_REF = 18,
       F_EULER_REF = 21, F_OMEGA = 24 };
#define F_ALPHA (F_OMEGA + FP_MAX_ROTORS)
#define F_BETA (F_ALPHA + FP_MAX_ROTORS)

/* Rows of ControllerModel.blk, the states of the first-order blocks. */
enum { BLK_POS = 0, BLK_VEL = 1, BLK_ATT = 2, BLK_RATE = 3 };

static inline double ctrl_wrap_pi(double a) {
    double b = a + CTRL_PI;
    if (b >= 0.0 && b < 2.0 * CTRL_PI) return b - CTRL_PI; /* fmod(b, 2 pi) is b: no call */
    a = fmod(b, 2.0 * CTRL_PI);
    if (a < 0.0) a += 2.0 * CTRL_PI;
    return a - CTRL_PI;
}

/* The first-order blocks x+ = A x + B e, y = C x + D e (discrete) of one cascade level:
 * A, B, C, D hold one value per axis. */
typedef struct {
    const double *A, *B, *C, *D;
} CtrlBlock;

/* One axis of a block: returns y and advances its state x. */
static inline double ctrl_block(const CtrlBlock *k, int axis, double *x, double e) {
    double y = k->C[axis] * (*x) + k->D[axis] * e;
    *x = k->A[axis] * (*x) + k->B[axis] * e;
    return y;
}

/* ------------------------------------------------------------------------ */
/* reference.c                                                              */

typedef struct {
    int enabled;
    double Ts;
    double lambda;                       /* rad/s: the cascade's poles in its linear region */
    double vel_max[2], acc_max[2], jerk_max[2]; /* [horizontal (norm), vertical] */
    double att_rate_max[3], att_acc_max[3];     /* per Euler angle */
} CtrlShapingParams;

typedef struct {
    const double *pos, *vel, *acc; /* xi_ref and its derivatives as given */
    const double *mu, *mu_rate;    /* mu_ref (heading unwrapped) and its rate as given */
} CtrlShapingInputs;

typedef struct {
    double pos[3], vel[3], acc[3], mu[3], mu_rate[3];
    double jerk[3]; /* the correction's jerk from this sample to the next (0 at zero error) */
} CtrlShapedRef;

/* One sample of the shaped reference; x carries the error state. */
void ctrl_shape_reference(const CtrlShapingParams *p, const CtrlShapingInputs *in,
                          CtrlShaping *x, CtrlShapedRef *out);

/* The shaping started at the vehicle's pose: the reference the inputs give, with the error
 * state set so that the shaped reference begins at pos, vel (at rest in acceleration) and
 * the attitude mu; a jump from there to the reference is then shaped as any step (a takeoff
 * from the ground at the vehicle's pace). */
void ctrl_shaping_start_at(const CtrlShapingInputs *in, const double pos[3],
                           const double vel[3], const double mu[3], CtrlShaping *x);

/* ------------------------------------------------------------------------ */
/* ground.c                                                                 */

typedef struct {
    double mass, g, Ts;
} CtrlGroundParams;

typedef struct {
    double support;              /* ctrl_ground_support of the last sample's signals, N */
    const double *vel;           /* measured, world NED */
    const double *pos, *pos_ref; /* measured position, the reference as given */
    int armed;
} CtrlGroundInputs;

typedef struct {
    int landed;     /* on the ground: it carries half the weight or more, at rest, for
                     * CTRL_LAND_TIME; off it when it carries under a quarter */
    int idle;       /* the rotors idle: disarmed, or landed with the reference not above */
} CtrlGroundOut;

/* The upward force the ground exerts, N: m g + (R f_b)_z - m a_z, from the attitude R
 * (body to world, row-major), the rotors' force f_b (body) and the acceleration a (world
 * NED) of one instant. */
double ctrl_ground_support(double mass, double g, const double r[9], const double f_b[3],
                           const double acc[3]);

/* One sample of the land detector and the idle decision. */
void ctrl_ground(const CtrlGroundParams *p, const CtrlGroundInputs *in, CtrlGroundState *x,
                 CtrlGroundOut *out);

/* ------------------------------------------------------------------------ */
/* filters.c                                                                */

/* H(s) = wn^2 / (s^2 + 2 zeta wn s + wn^2) discretized exactly (zero-order hold) at Ts:
 * x+ = Phi x + Gamma u with x = [y, y']. */
void ctrl_filter_discretize(double wn, double zeta, double Ts, double phi[2][2],
                            double gamma[2]);

/* The heading psi made continuous before filtering: the angle nearest *unwrapped that
 * differs from angle by a multiple of 2 pi.  Updates both states and returns it. */
double ctrl_unwrap(double angle, double *raw, double *unwrapped);

/* The pose measurements carried forward over their age to the sample instant: position and
 * velocity with the measured acceleration (constant over the age), the Euler angles with the
 * Euler-angle rates of the measured body rates (ZYX kinematics).  out = [pos, vel, euler];
 * age 0 copies the measurements unchanged. */
void ctrl_predict_pose(const double pos[3], const double vel[3], const double acc[3],
                       const double euler[3], const double rate[3], double age, double out[9]);

/* What the filters take in one sample. */
typedef struct {
    const double *pos, *vel, *acc, *euler, *rate; /* measurements, 3 each */
    const double *pos_ref, *vel_ref, *mu_ref;     /* references xi_ref, xi_ref', mu_ref */
    double psi, psi_ref;                          /* unwrapped euler[2], mu_ref[2] */
    const double *omega, *alpha, *beta;           /* measured actuators, n_rotors each */
    int n_rotors;
} CtrlFilterInputs;

/* One sample of every filter; x is ControllerModel.filt. */
void ctrl_filters_update(const double phi[2][2], const double gamma[2],
                         const CtrlFilterInputs *in, double x[CTRL_N_FILTERS][2]);

/* Every filter in steady state at its input (the raw headings: at the start the unwrapped
 * heading is the raw one). */
void ctrl_filters_start(const CtrlFilterInputs *in, double x[CTRL_N_FILTERS][2]);

/* One sample's signals after H(s) (subscript m: measured). */
typedef struct {
    double pos_m[3], vel_m[3], acc_m[3];     /* world NED */
    double mu_m[3], rate_m[3], ang_acc_m[3]; /* ang_acc_m: the rate filter's derivative */
    double a_m[FP_MAX_ROTORS], b_m[FP_MAX_ROTORS], w_m[FP_MAX_ROTORS]; /* alpha, beta, omega */
    double eff[FP_MAX_ROTORS];               /* known rotor efficiency, 0 for lost rotors */
    double f_b_m[3], tau_b_m[3];             /* nu_m: the rotor wrench at a_m, b_m, w_m */
    double w_rotor[FP_MAX_ROTORS][6]; /* each rotor's own wrench at full efficiency */
    FpRotorTrig trig;                        /* sin, cos of a_m, b_m and the azimuths */
    /* R(mu_m) (body to world, row-major) and its derivatives in phi and theta, once per
     * sample for the guidance and the detector */
    double r_m[9], dr_dphi_m[9], dr_dtheta_m[9];
    /* the references delayed by H(s) like the measurements */
    double pos_ref_f[3], vel_ref_f[3], mu_ref_f[3];
} CtrlFiltered;

void ctrl_read_filters(const double x[CTRL_N_FILTERS][2], const FpRotorSet *rotors,
                       const FpRotorTrig *mounts, const double rotor_health[],
                       int32_t lost_mask, CtrlFiltered *s);

/* ------------------------------------------------------------------------ */
/* force_sets.c                                                             */

/* A feasible-force set {f_b : A f_b <= d} (unit normals, d scaled about the hover force). */
typedef struct {
    const double (*A)[3];
    const double *d;
    int n;        /* facets */
    double fz[2]; /* its f_bz range [min, max] */
    int32_t id;   /* which set: 0 nominal, i after losing rotor i (its rows never change) */
} CtrlForceSet;

/*
 * Validate the polytope {A f_b <= b} of n facets (finite, non-zero normals, non-empty,
 * bounded; errors name it as `name`) and derive what the guidance uses: the offsets d of
 * the set scaled by margin about the hover force [0, 0, hover_fz], its f_bz range fz (scaled
 * the same way), and *hover_ok, whether the hover force lies inside (if not: d = b, fz
 * unscaled).  scratch is a solver the support functions borrow.  FP_ERROR when invalid.
 */
FpStatus ctrl_force_set_prepare(FpCheck *c, const char *name, const double (*A)[3],
                                const double *b, int n, double hover_fz, double margin,
                                FpWls *scratch, double d[], double *fz_min, double *fz_max,
                                int32_t *hover_ok);

/*
 * The force sets the controller flies with (ControllerModel.set_*): for S(0) and for the set
 * after losing each rotor, the given polytope where its count is > 0, else the one derived
 * from the airframe (derive_sets.h).  A given set is checked against the derived one: it
 * may be smaller (a design margin), but reaching more than CTRL_SET_MISMATCH of the rotors'
 * total thrust beyond what the airframe can produce means it belongs to another vehicle,
 * and it is refused.  An empty derived S(0), or one without the hover force, is refused
 * with its cause.  *derived: bit 0 S(0) derived, bit i rotor i's set.  Uses about 53 kB of
 * stack (the derivation's working memory) and nothing after it returns.
 */
#define CTRL_SET_MISMATCH 0.1
typedef struct {
    int32_t n;                   /* given facets (0: derive) */
    const double (*A)[3];
    const double *b;
} CtrlGivenSet;

FpStatus ctrl_force_sets_resolve(FpCheck *c, const FpRotorSet *rs, const CtrlGivenSet *s0, const CtrlGivenSet fail[],
                                 FpWls *scratch, int32_t *n_out, double A_out[][3],
                                 double b_out[], int32_t fail_n_out[], double fail_A_out[][3],
                                 double fail_b_out[], int32_t *derived);

/* Which rotors are lost (told efficiency below one half, or lost to the detector) and which
 * force set goes with it. */
typedef struct {
    int32_t lost_mask;       /* bit i-1: rotor i */
    int32_t rotors_lost;     /* how many */
    int32_t active_polytope; /* 0 nominal, i: after losing rotor i, -1: several (nominal) */
    int32_t hover_possible;  /* the hover force lies in that set */
} CtrlLosses;

/* rotor_health: as told; detected_lost: the detector's lost rotors (bit i-1: rotor i);
 * hover_ok[0]: nominal set, [i]: set after losing rotor i (ControllerModel.hover_ok). */
void ctrl_rotor_losses(int n_rotors, const double rotor_health[], int32_t detected_lost,
                       const int32_t fail_poly_n[], const int32_t hover_ok[], CtrlLosses *out);

/* Say which force set a change of losses leaves the guidance with. */
void ctrl_log_losses(const CtrlLosses *l, const FpLogger *logger);

/* ------------------------------------------------------------------------ */
/* shaping_limits.c: the shaping's limits from the airframe (initialization)  */

/* The level acceleration the force set fs leaves after the hover force [0, 0, -m g]: the
 * least over azimuths of the horizontal force reachable at that f_z, over m. */
double ctrl_level_acceleration(const CtrlForceSet *fs, double mass, double g);

/* The torque the rotors give about each body axis at the hover trim while holding the
 * other five wrench components (linearised: B'' at trim, the actuators' ranges), the
 * smaller of the two directions; w is a solver borrowed for it (set up and reset here). */
FpStatus ctrl_torque_capability(const FpRotorSet *rs, double mass, double g, FpWls *w,
                                double tau_max[3]);

typedef struct {
    const CtrlForceSet *fs; /* the nominal force set (margin-scaled offsets) */
    double mass, g, inertia[3][3], tau_max[3];
    double tilt_max, bandwidth;       /* ref_tilt_max, ref_bandwidth */
    const double *vel_max, *acc_max, *jerk_max;       /* [h, v] as given (0: derive) */
    const double *att_rate_max_given, *att_acc_max;   /* per Euler angle (0: derive) */
} CtrlLimitInputs;

typedef struct {
    double vel[2], acc[2], jerk[2], att_rate[3], att_acc[3];
    double yaw_rate; /* the stabilization's heading-rate command limit that goes with it */
    double a_level;  /* m/s^2: the level acceleration of the force set (diagnostic) */
} CtrlShapingLimits;

void ctrl_shaping_limits(const CtrlLimitInputs *in, CtrlShapingLimits *out);

/* ------------------------------------------------------------------------ */
/* detect.c                                                                 */


/* What the detector takes in one sample: raw measurements, not H(s)-filtered. */
typedef struct {
    const double *acc, *euler, *rate;   /* world acceleration, attitude now, body rates */
    const double *omega, *alpha, *beta; /* actuator measurements, n_rotors each */
    const double *eff;                  /* efficiencies in use, 0 for lost rotors */
} CtrlDetectInputs;

typedef struct {
    int detected; /* the rotor (0-based) whose estimate this sample concluded, else -1 */
} CtrlDetectOut;

void ctrl_detect_start(CtrlDetect *x);

/* The INDI residual of the filtered signals (output indi_residual): the rotor wrench the
 * filtered measurements say minus the one the filtered actuators give with s->eff,
 * [force (N); torque (N m)], body. */
void ctrl_detect_residual(const CtrlDetectParams *p, const CtrlFiltered *s, double res[6]);

/* One sample of the detector (mounts: the rotors' azimuth sin and cos). */
void ctrl_detect(const CtrlDetectParams *p, const FpRotorSet *rs, const FpRotorTrig *mounts,
                 const CtrlDetectInputs *in, CtrlDetect *x, CtrlDetectOut *out);

/* ------------------------------------------------------------------------ */
/* guidance.c                                                               */

typedef struct {
    double mass;
    CtrlBlock K_pos, K_vel;              /* K_xi, K_xidot */
    double gamma_opt;                    /* weight of the acceleration-tracking term */
    const double *W_u, *W_v;             /* 5 and 3 diagonal weights */
    const double *euler_min, *euler_max; /* bounds of [phi_c, theta_c] */
    int force_constraint;                /* 0: joint S(0), 1: slice P_xy at f_bz_ref */
    int max_iter, timing;
} CtrlGuidanceParams;

typedef struct {
    const double *acc_ref; /* acceleration feed-forward (unfiltered) */
    const double *mu_ref;  /* reference attitude */
    const double *r_ref;   /* R(mu_ref), row-major (computed once for the twin and this) */
} CtrlGuidanceInputs;

typedef struct {
    double *x_pos, *x_vel; /* states of the K_xi and K_xidot blocks, 3 each */
    FpWls *qp;             /* the guidance QP; its working set warm-starts the next sample */
    int32_t *c_rows;       /* which force set's rows qp's C holds (0: none yet) */
} CtrlGuidanceState;

typedef struct {
    double acc_c[3];   /* commanded acceleration (blocks plus feed-forward) */
    double f_b_ref[3]; /* body force that follows xi_ref at the measured attitude, eq. (21) */
    double df_c[3];    /* commanded body-force increment df_b_c */
    double mu_c[3];    /* commanded attitude (not wrapped) */
    double f_b_c[3];   /* f_b_m + df_b_c */
    FpWlsStatus status;
    int iterations;
    int32_t flags;    /* active constraints: bit 0 force set, bit 1 phi, bit 2 theta bound */
    int32_t feasible; /* eq. (7): R(mu_ref)^T f_w_ref lies in the force set */
    double t_solve;   /* s, only written with timing */
} CtrlGuidanceOut;

void ctrl_guidance(const CtrlGuidanceParams *p, const CtrlForceSet *fs,
                   const CtrlGuidanceInputs *in, const CtrlFiltered *s, CtrlGuidanceState *st,
                   CtrlGuidanceOut *out);

/* The feed-forward attitude mu_ff: the guidance's answer for a vehicle on the reference
 * (acc_ref, mu_ref; r_ref = R(mu_ref)) exactly; tw carries its pose, w its QP
 * (warm-started). */
void ctrl_guidance_twin(const CtrlGuidanceParams *p, const CtrlForceSet *fs,
                        const double acc_ref[3], const double mu_ref[3],
                        const double r_ref[9], double g, CtrlTwin *tw, FpWls *w,
                        double mu_ff[3]);

/* ------------------------------------------------------------------------ */
/* stabilization.c                                                          */

typedef struct {
    CtrlBlock K_att, K_rate;
    double yaw_rate_max;
    const double (*inertia)[3]; /* nominal I */
} CtrlStabilizationParams;

typedef struct {
    double *x_att, *x_rate; /* states of the attitude and rate blocks, 3 each */
} CtrlStabilizationState;

/* From mu_c (guidance), mu_ref and its rate feed-forward mu_dot_ref: the commanded body
 * rates rate_c and the torque increment dtau_c = I (dOmega_c - dOmega_m). */
void ctrl_stabilization(const CtrlStabilizationParams *p, const CtrlFiltered *s,
                        const double mu_c[3], const double mu_ref[3],
                        const double mu_dot_ref[3], const double mu_ddot_ref[3],
                        CtrlStabilizationState *st, double rate_c[3], double dtau_c[3]);

/* ------------------------------------------------------------------------ */
/* allocation.c                                                             */

typedef struct {
    const FpRotorSet *rotors; /* geometry and actuator limits */
    const FpPreferredSplit *pref_split; /* fp_preferred_prepare of rotors */
    const double *W_nu;       /* 6 row weights of dnu */
    double w_pref;            /* weight of the preferred configuration */
    double pref_omega_scale;  /* scale of rotor speeds in that term */
    int max_iter, timing;
} CtrlAllocationParams;

typedef struct {
    double alpha_cmd[FP_MAX_ROTORS], beta_cmd[FP_MAX_ROTORS], omega_cmd[FP_MAX_ROTORS];
    double residual[6]; /* B2 du - dnu_c */
    int32_t sat_flags;  /* bit i-1 motor i, bit 7+i alpha i, bit 15+i beta i */
    FpWlsStatus status;
    int iterations;
    double t_solve; /* s, only written with timing */
} CtrlAllocationOut;

/* The actuator commands that realise dnu_c = [df_b_c; dtau_c] at the filtered actuator
 * state; rotors in lost_mask stay where they are, their motors stopped. */
void ctrl_allocation(const CtrlAllocationParams *p, const CtrlFiltered *s, const double dnu_c[6],
                     int32_t lost_mask, FpWls *qp, CtrlAllocationOut *out);

/* ------------------------------------------------------------------------ */
/* validate.c                                                               */

/* Every parameter but the polytopes' facets (ctrl_force_set_prepare checks those); the
 * number of errors, each logged.  vars, n_vars: the model's variable table (controller.c
 * passes it), where the messages find each parameter's name and range. */
int ctrl_check_parameters(const ControllerModel *m, const FpVar *vars, size_t n_vars,
                          const FpLogger *logger);

/* The tunable parameters only (after a change while stepping); vars, n_vars as above. */
int ctrl_check_tunables(const ControllerModel *m, const FpVar *vars, size_t n_vars,
                        const FpLogger *logger);

/* ------------------------------------------------------------------------ */
/* derive_params.c: what initialization derives from the fixed parameters    */

/* The detector's constants (a pure function of the parameters: a restored state's are
 * compared with it bit for bit). */
CtrlDetectParams ctrl_detect_params(const ControllerModel *m);

/* The force sets in use (given or derived from the airframe), validated, with their
 * margin-scaled offsets, f_bz ranges and hover flags; vars, n_vars: the model's variable
 * table, for the messages.  FP_ERROR (logged) when a set is invalid or holds no hover. */
FpStatus ctrl_prepare_force_sets(ControllerModel *m, const FpVar *vars, size_t n_vars,
                                 const FpLogger *logger);

/* The shaping's limits in use (as given, or derived: shaping_limits.c) into the model and
 * its ref_*_limit outputs.  FP_ERROR (logged) when the torque capability is needed and
 * cannot be computed. */
FpStatus ctrl_derive_shaping_limits(ControllerModel *m, const FpLogger *logger);

/* ------------------------------------------------------------------------ */
/* controller_sample.c: the sequence of one sample (controller.c runs it)   */

/* The filters' view of the model: the pose as predicted to now (pose_now), the references
 * and the actuator feedback. */
CtrlFilterInputs ctrl_filter_inputs(const ControllerModel *m);

/* Rotors below half efficiency are lost: pick the feasible-force set that goes with
 * the losses and say so once per change. */
void ctrl_update_rotor_losses(ControllerModel *m, const FpLogger *logger);

/* One sample from usable inputs (controller.c checks them first): FP_OK, or FP_WARNING when
 * it computed a non-finite value and was discarded. */
FpStatus ctrl_sample(ControllerModel *m, const FpLogger *logger);

#endif
