/*
 * Rotor geometry shared by the plant, the controller and the Python core
 * library.  Conventions (pinned here, tested in tests/):
 *
 *  - Body frame FRD.  Rotor i sits at d_i, spins with c_i = +-1 and is tilted
 *    by lambda_i = [alpha_i, beta_i, gamma_i].
 *  - R_Mi^B(lambda_i) = Rz(gamma_i) * Rx(alpha_i) * Ry(beta_i): gamma_i is a
 *    fixed mounting rotation about the body z axis (we set it to the arm's
 *    azimuth, so alpha tilts about the arm), alpha_i is the outer servo about
 *    the mounted x axis, beta_i the inner servo about the once-rotated y axis.
 *  - Thrust f_mi = k_t * omega_i^2 acts along the rotor's -z axis, so at zero
 *    tilt it points to body -z (up).  Its direction in the body frame is
 *    t_i = -R_Mi^B e_z = -Rz(gamma)[sin(beta), -sin(alpha)cos(beta), cos(alpha)cos(beta)].
 *  - The rotor's reaction (drag) torque is c_i * k_d * omega_i^2 along t_i,
 *    so paper eq. (3) holds literally: tau_i = (S(d_i) + r c_i I3) f_bi with
 *    r = k_d / k_t.
 */
#ifndef FP_MULTIROTOR_H
#define FP_MULTIROTOR_H

#include <stdint.h>
#include <string.h>

#include "fp_model.h"

#define FP_MAX_ROTORS 8

/* The servo limits alpha_min/max, beta_min/max of every airframe lie within +-pi/2: the
 * range both FMUs' tables give those rows (and so the bound fp_check_airframe applies). */
#define FP_SERVO_LIMIT 1.57079632679489661923

/* Physical plausibility of an airframe's propulsion, checked by fp_check_airframe in both
 * FMUs and by plant/airframe.py alike (tests/test_plant/test_airframes.py compares the
 * numbers; docs/airframes.md, "Plausible numbers", gives the physics):
 *   omega_max                   within [1, 500000] rpm (x 2 pi / 60 rad/s)
 *   k_t omega_max^2             (a rotor's maximum thrust) within [1e-3, 1e5] N
 *   k_d / k_t                   (drag torque per newton of thrust) at most 10 m
 *   n k_t omega_max^2 / (m g)   (thrust-to-weight ratio, when g > 0) within [0.1, 100] */
#define FP_OMEGA_MAX_RPM_MIN 1.0
#define FP_OMEGA_MAX_RPM_MAX 500000.0
#define FP_ROTOR_THRUST_MIN 1e-3
#define FP_ROTOR_THRUST_MAX 1e5
#define FP_DRAG_RATIO_MAX 10.0
#define FP_THRUST_TO_WEIGHT_MIN 0.1
#define FP_THRUST_TO_WEIGHT_MAX 100.0

/* Bit of rotor i (0-based) in both FMUs' sat_flags output: FP_SAT_<kind> + i.
 * (Python: controller.fmu_parameters.SAT_FLAG_SHIFT; a test compares them.) */
enum { FP_SAT_MOTOR = 0, FP_SAT_ALPHA = 8, FP_SAT_BETA = 16 };

/* Geometry and actuator limits of a rotor set (SI units, radians). */
typedef struct {
    int32_t n;
    double k_t, k_d;
    double pos[FP_MAX_ROTORS][3];
    int32_t dir[FP_MAX_ROTORS];
    double gamma[FP_MAX_ROTORS];
    double alpha_min[FP_MAX_ROTORS], alpha_max[FP_MAX_ROTORS];
    double beta_min[FP_MAX_ROTORS], beta_max[FP_MAX_ROTORS];
    double omega_min, omega_max;
} FpRotorSet;

/* An airframe as both FMUs hold it: one struct, the members of the airframe variable table
 * (common/airframe_vars.h), embedded as `af` in both models. */
typedef struct {
    int32_t n_rotors;
    double mass, inertia[3][3], g, k_t, k_d;
    double rotor_pos[FP_MAX_ROTORS][3];
    int32_t rotor_dir[FP_MAX_ROTORS];
    double rotor_gamma[FP_MAX_ROTORS];
    double alpha_min[FP_MAX_ROTORS], alpha_max[FP_MAX_ROTORS];
    double beta_min[FP_MAX_ROTORS], beta_max[FP_MAX_ROTORS];
    double omega_min, omega_max;
    double tau_motor, tau_servo;
} FpAirframe;

/* The paper's hexacopter (Table I), the default airframe of both FMUs. */
void fp_paper_hexacopter(FpAirframe *af);

/* The rotor set of an airframe (what the rotor math needs of it). */
void fp_rotor_set_of(const FpAirframe *af, FpRotorSet *rs);

/* sin and cos of every rotor's tilt angles (alpha, beta) and mounting azimuth (gamma), so
 * that a sample that needs the thrust directions, their derivatives and the wrench at one
 * actuator state evaluates each once.  The *_trig functions below give exactly (to the
 * bit) what their angle-taking counterparts give. */
typedef struct {
    double sa[FP_MAX_ROTORS], ca[FP_MAX_ROTORS]; /* alpha */
    double sb[FP_MAX_ROTORS], cb[FP_MAX_ROTORS]; /* beta */
    double sg[FP_MAX_ROTORS], cg[FP_MAX_ROTORS]; /* gamma */
} FpRotorTrig;

/* The gamma part of tr (constant for a rotor set). */
void fp_rotor_trig_mounts(const FpRotorSet *rs, FpRotorTrig *tr);

/* The alpha and beta part of tr at the tilts alpha[], beta[] (rs->n each). */
void fp_rotor_trig_tilts(const FpRotorSet *rs, const double alpha[], const double beta[],
                         FpRotorTrig *tr);

/* fp_rotor_wrench and fp_effectiveness_b2prime from tr (both parts filled). */
void fp_rotor_wrench_trig(const FpRotorSet *rs, const FpRotorTrig *tr, const double omega[],
                          const double efficiency[], double f_b[3], double tau_b[3]);
FpStatus fp_effectiveness_b2prime_trig(const FpRotorSet *rs, const FpRotorTrig *tr,
                                       const double omega[], double *b2p);

/* Partial derivatives of the thrust direction t_i with respect to alpha and beta. */
void fp_thrust_direction_jacobian(double alpha, double beta, double gamma, double dt_dalpha[3],
                                  double dt_dbeta[3]);

/* Paper eq. (12)-(13): B''(u_a) = d(B'(lambda) F(omega))/du_a, 6 x 3n row-major,
 * columns ordered [alpha_1, beta_1, omega_1, ..., alpha_n, beta_n, omega_n]. */
FpStatus fp_effectiveness_b2prime(const FpRotorSet *rs, const double alpha[], const double beta[],
                                  const double omega[], double *b2p);

/* R_Mi^B(alpha, beta, gamma), row-major. */
void fp_rotor_rotation(double alpha, double beta, double gamma, double r[3][3]);

/* Unit thrust direction t_i in the body frame. */
void fp_thrust_direction(double alpha, double beta, double gamma, double t[3]);

/* Tilt angles that point the thrust along the body-frame vector f (|f| > 0). */
void fp_tilt_from_direction(const double f[3], double gamma, double *alpha, double *beta);

/* Paper eq. (3): B (6 x 3n, row-major) mapping per-rotor body forces to [f_b; tau_b]. */
FpStatus fp_effectiveness_b(const FpRotorSet *rs, double *b);

/*
 * Paper eq. (9)-(10): B'(lambda) (6 x 3n, row-major), so that
 * [f_b; tau_b] = B'(lambda) F(omega) with F_i = [0, 0, -k_t omega_i^2].
 */
FpStatus fp_effectiveness_bprime(const FpRotorSet *rs, const double alpha[], const double beta[],
                                 double *bp);

/* Body force and torque produced by the rotors (efficiency may be NULL = all 1). */
void fp_rotor_wrench(const FpRotorSet *rs, const double alpha[], const double beta[],
                     const double omega[], const double efficiency[], double f_b[3],
                     double tau_b[3]);

/* Rotor i's own wrench [f_b; tau_b] at speed omega and full efficiency (tr filled). */
void fp_rotor_wrench_one(const FpRotorSet *rs, const FpRotorTrig *tr, int i, double omega,
                         double w[6]);

/* A rotor can tilt when either servo has a non-empty range. */
int fp_rotor_tilts(const FpRotorSet *rs, int i);

/*
 * Preferred actuator configuration for a body wrench [f_b; tau_b]: the
 * minimum-norm split into per-rotor forces (a full 3-D force for a tilting
 * rotor, a thrust along the fixed direction otherwise), converted to
 * alpha, beta, omega.  Returns FP_OK when the split reproduces the wrench
 * within 1e-6 relative and every actuator is inside its limits; otherwise
 * FP_ERROR with the reason in why (and the unclamped split in the outputs).
 */
/* What fp_preferred_config needs of the geometry alone: the reduced effectiveness
 * columns, the Cholesky factor of their regularised Gram matrix, the mounting azimuths'
 * sin and cos.  fp_preferred_prepare + fp_preferred_apply = fp_preferred_config, to the
 * bit; a controller prepares once per rotor set and applies every sample. */
typedef struct {
    double cols[6][3 * FP_MAX_ROTORS];
    double gram[36]; /* Cholesky factor */
    double sg[FP_MAX_ROTORS], cg[FP_MAX_ROTORS];
    int32_t first[FP_MAX_ROTORS]; /* first column of each rotor */
    int32_t m;                    /* columns */
    int32_t status;               /* FP_OK, or FP_ERROR: invalid set or singular geometry */
} FpPreferredSplit;

FpStatus fp_preferred_prepare(const FpRotorSet *rs, FpPreferredSplit *ps, char *why,
                              int why_size);
FpStatus fp_preferred_apply(const FpRotorSet *rs, const FpPreferredSplit *ps,
                            const double wrench[6], double alpha[], double beta[],
                            double omega[], char *why, int why_size);

FpStatus fp_preferred_config(const FpRotorSet *rs, const double wrench[6], double alpha[],
                             double beta[], double omega[], char *why, int why_size);

/* Cholesky of an SPD n x n matrix in place (lower factor; n <= 32). */
FpStatus fp_cholesky_factor(double *a, int n);

/* Solve L L^T x = b in place with a factor from fp_cholesky_factor. */
void fp_cholesky_backsolve(const double *l, int n, double *b);

/* Cholesky solve of the SPD n x n system a x = b in place (n <= 32). */
FpStatus fp_cholesky_solve(double *a, int n, double *b);

#endif
