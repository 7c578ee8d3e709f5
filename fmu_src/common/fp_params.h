/*
 * Parameter checks shared by both models.
 *
 * An FpCheck collects the errors of one validation: every bad value is logged through the
 * model's FpLogger as "parameter NAME[INDEX] = VALUE: REASON" and counted, so one
 * initialization reports every bad parameter, not just the first.  The element checks
 * (finite, positive, within a range, ordered) name each element as the FMU variable table
 * does: NAME for a scalar, NAME[i] for a vector element, NAME[i,j] for a matrix element.
 *
 * fp_check_airframe holds the one set of rules for the airframe parameters that both FMUs
 * carry under the same names, so the plant and the controller accept and refuse the same
 * airframes.
 */
#ifndef FP_PARAMS_H
#define FP_PARAMS_H

#include <stdint.h>

#include "fp_model.h"
#include "multirotor.h"

typedef struct {
    const FpLogger *logger;
    int errors; /* errors logged so far */
} FpCheck;

void fp_check_init(FpCheck *c, const FpLogger *logger);

/* Log "parameter LABEL = VALUE: WHY" and count an error.  LABEL is name, name[i] (j = 0)
 * or name[i,j]; i = 0 for a scalar.  Indices are 1-based. */
void fp_check_bad(FpCheck *c, const char *name, int i, int j, double value, const char *why);

/* The same for an Integer parameter (the value printed as an integer). */
void fp_check_bad_int(FpCheck *c, const char *name, int i, long value, const char *why);

/* Log a free-form error about parameters (printf-style) and count it. */
void fp_check_error(FpCheck *c, const char *fmt, ...)
#if defined(__GNUC__)
    __attribute__((format(printf, 2, 3)))
#endif
    ;

/* Log a warning about parameters (usable but odd; not counted). */
void fp_check_warning(FpCheck *c, const char *fmt, ...)
#if defined(__GNUC__)
    __attribute__((format(printf, 2, 3)))
#endif
    ;

/*
 * Element checks on n values v of a parameter shaped by cols: 0 a scalar (n = 1), 1 a
 * vector, > 1 a row-major matrix with cols columns.  Each bad element is reported.
 *   fp_need_finite       finite ("must be finite")
 *   fp_need_positive     finite and > 0 ("must be positive")
 *   fp_need_nonnegative  finite and >= 0 ("must not be negative")
 *   fp_need_range        finite elements within [lo, hi] (reported with why; a non-finite
 *                        element is left to fp_need_finite)
 *   fp_need_ordered      lo[k] <= hi[k], reported on lo with why (NaN is not compared)
 */
void fp_need_finite(FpCheck *c, const char *name, const double *v, int n, int cols);
void fp_need_positive(FpCheck *c, const char *name, const double *v, int n, int cols);
void fp_need_nonnegative(FpCheck *c, const char *name, const double *v, int n, int cols);
void fp_need_range(FpCheck *c, const char *name, const double *v, int n, int cols, double lo,
                   double hi, const char *why);
void fp_need_ordered(FpCheck *c, const char *name, const double *lo, const double *hi, int n,
                     int cols, const char *why);

/*
 * The airframe rules of both FMUs, on their parameters of the same names (rs as
 * FP_MODEL_TO_ROTOR_SET fills it from the model, rs->n = n_rotors):
 *   n_rotors     in 1..FP_MAX_ROTORS (else nothing more is checked: FP_ERROR)
 *   mass         finite, > 0
 *   inertia      (9, row-major) finite, symmetric (|I_ij - I_ji| <= 1e-12 max|I|),
 *                positive definite; a warning when a principal moment exceeds the sum
 *                of the other two
 *   g            finite
 *   k_t          finite, > 0;   k_d  finite, >= 0
 *   rotor_pos, rotor_gamma       finite (rotors 1..n_rotors)
 *   rotor_dir                    +1 or -1
 *   alpha_min/max, beta_min/max  finite, within [-pi/2, pi/2], min <= max
 *   omega_min    finite, >= 0;  omega_max  finite, > 0;  omega_min <= omega_max
 * Errors are logged and counted in c.  Returns FP_ERROR only for a bad n_rotors.
 */
FpStatus fp_check_airframe(FpCheck *c, double mass, const double *inertia, double g,
                           const FpRotorSet *rs);

#endif
