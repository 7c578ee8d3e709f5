/*
 * Parameter checks shared by both models.
 *
 * An FpCheck collects the errors of one validation: every bad value is logged through the
 * model's FpLogger as "parameter NAME[INDEX] = VALUE: REASON" and counted, so one
 * initialization reports every bad parameter, not just the first.  The element checks read
 * the static bound of each parameter from its row in the model's variable table (the range
 * that modelDescription.xml declares as min/max), so the check and the declaration cannot
 * differ, and name each element as the table does: NAME for a scalar, NAME[i] for a vector
 * element, NAME[i,j] for a matrix element.
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
    const FpVar *vars; /* the model's variable table: the ranges the checks read */
    size_t n_vars;
    int errors;        /* errors logged so far */
} FpCheck;

void fp_check_init(FpCheck *c, const FpLogger *logger, const FpVar *vars, size_t n_vars);

/* The table row of `name` (NULL, counted as an error, when the model has none: a bug). */
const FpVar *fp_check_row(FpCheck *c, const char *name);

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
 * The first n elements of a parameter against its table row (fp_model.h FpRange), each bad
 * element reported under the row's structured name (name, name[i], name[i,j]):
 *   fp_need_param      Real: finite ("must be finite") and within the range ("must be
 *                      positive", "must not be negative", "must be within [-pi/2, pi/2]",
 *                      "must be inside (-1, 1)", "must be in (0, 1]"; note, when not
 *                      NULL, is appended: "...: the block's pole ...")
 *   fp_need_int_param  Integer: within the range ("must be in 1..8")
 *   fp_need_ordered    lo[k] <= hi[k] (a bound that depends on another parameter), reported
 *                      on lo with why (NaN is not compared); cols as the row's shape
 * fp_range_why writes the reason a value outside r is given ("must be positive", ...).
 */
void fp_need_param(FpCheck *c, const char *name, const double *v, int n, const char *note);
void fp_need_int_param(FpCheck *c, const char *name, const int32_t *v, int n);
void fp_need_ordered(FpCheck *c, const char *name, const double *lo, const double *hi, int n,
                     int cols, const char *why);
const char *fp_range_why(const FpRange *r, int integer, char *buf, size_t size);

/*
 * The airframe rules of both FMUs, on the rows of the airframe table they share
 * (common/airframe_vars.h, members of af); the ranges are those rows':
 *   n_rotors     within its range (1..FP_MAX_ROTORS; else nothing more is checked: FP_ERROR)
 *   mass, g, k_t, k_d, omega_min, omega_max     finite, within their ranges
 *   inertia      (9, row-major) finite, symmetric (|I_ij - I_ji| <= 1e-12 max|I|),
 *                positive definite; a warning when a principal moment exceeds the sum
 *                of the other two
 *   rotor_pos, rotor_gamma       finite (rotors 1..n_rotors)
 *   rotor_dir                    within its range, and +1 or -1
 *   alpha_min/max, beta_min/max  finite, within their ranges, min <= max
 *   omega_min <= omega_max; tau_motor, tau_servo positive
 *   physical plausibility (the FP_* bounds of multirotor.h): omega_max within [1, 500000]
 *                rpm, k_t omega_max^2 within [1e-3, 1e5] N, k_d / k_t <= 10 m, with g > 0
 *                n_rotors k_t omega_max^2 / (mass g) within [0.1, 100]
 *   control authority: no two rotors at one place; the moment arms give torque about two
 *                axes and, with the drag torques, about all three
 * Errors are logged and counted in c.  Returns FP_ERROR only for a bad n_rotors.
 */
FpStatus fp_check_airframe(FpCheck *c, const FpAirframe *af);

#endif
