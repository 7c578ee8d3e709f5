/*
 * libfp_multirotor (installed in plant/lib/, used by plant/effectiveness.py): the rotor
 * geometry of common/multirotor.c, the very code both FMUs run.  A rotor set crosses the
 * API as an opaque buffer of fp_rotor_set_size() bytes made from an airframe buffer
 * (fp_rotor_set_from_airframe), itself filled row by row from the airframe table.
 * Matrices are row-major.  Every function returns 0 on success, else a non-zero FpStatus.
 */
#ifndef FP_MULTIROTOR_API_H
#define FP_MULTIROTOR_API_H

#include <stdint.h>

#include "fp_api.h"

/* Version of this API (1). */
FP_API int fp_api_version(void);

/* FP_MAX_ROTORS, the largest rotor count. */
FP_API int fp_max_rotors(void);

/* The airframe variable table both FMUs share (common/airframe_vars.h): its row count, and
 * row i's name (into name[name_size]), shape (rows x cols), type (integer: 1 for an Integer
 * row, stored as int32, 0 for a Real one, stored as double) and byte offset in the airframe
 * buffer.  FP_ERROR for i out of range or a name that does not fit. */
FP_API int fp_airframe_variable_count(void);
FP_API int fp_airframe_variable(int i, char *name, int name_size, int32_t *rows, int32_t *cols,
                                int32_t *integer, int32_t *offset);

/* Size in bytes of an airframe buffer (the FpAirframe both models embed), filled row by row
 * at the offsets above. */
FP_API int fp_airframe_size(void);

/* The rotor-set buffer (fp_rotor_set_size() bytes) of an airframe buffer: what the rotor
 * functions below take.  FP_ERROR when n_rotors or k_t is invalid. */
FP_API int fp_rotor_set_from_airframe(const void *airframe, void *rotor_set);

/* Size in bytes of the opaque rotor-set buffer the functions below take. */
FP_API int fp_rotor_set_size(void);

/* R_Mi^B(alpha, beta, gamma) = Rz(gamma) Rx(alpha) Ry(beta) into r9[9]. */
FP_API int fp_rotor_rotation_api(double alpha, double beta, double gamma, double *r9);

/* Unit thrust direction t_i in the body frame into t3[3]. */
FP_API int fp_thrust_direction_api(double alpha, double beta, double gamma, double *t3);

/* Tilt angles that point the thrust along f3[3]. */
FP_API int fp_tilt_from_direction_api(const double *f3, double gamma, double *alpha,
                                      double *beta);

/* Paper eq. (3): B, 6 x 3n. */
FP_API int fp_effectiveness_b_api(const void *rotor_set, double *b);

/* Paper eq. (9)-(10): B'(lambda), 6 x 3n. */
FP_API int fp_effectiveness_bprime_api(const void *rotor_set, const double *alpha,
                                       const double *beta, double *bp);

/* Paper eq. (12)-(13): B''(u_a), 6 x 3n, columns [alpha_1, beta_1, omega_1, ...]. */
FP_API int fp_effectiveness_b2prime_api(const void *rotor_set, const double *alpha,
                                        const double *beta, const double *omega, double *b2p);

/* Body force f_b[3] and torque tau_b[3] of the rotors (efficiency may be NULL: all 1). */
FP_API int fp_rotor_wrench_api(const void *rotor_set, const double *alpha, const double *beta,
                               const double *omega, const double *efficiency, double *f_b,
                               double *tau_b);

/* Minimum-norm split of wrench[6] into alpha, beta, omega [n]; non-zero with the reason in
 * why[why_size] when it is not feasible. */
FP_API int fp_preferred_config_api(const void *rotor_set, const double *wrench, double *alpha,
                                   double *beta, double *omega, char *why, int why_size);

#endif
