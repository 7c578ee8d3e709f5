#include "fp_params.h"

#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <string.h>

#include "fp_math.h"

#define PI 3.14159265358979323846

void fp_check_init(FpCheck *c, const FpLogger *logger, const FpVar *vars, size_t n_vars) {
    c->logger = logger;
    c->vars = vars;
    c->n_vars = n_vars;
    c->errors = 0;
}

const FpVar *fp_check_row(FpCheck *c, const char *name) {
    const FpVar *v = fp_var_find(c->vars, c->n_vars, name);
    if (v == NULL) fp_check_error(c, "internal error: no variable %s in the table", name);
    return v;
}

static void label_of(char *buf, size_t size, const char *name, int i, int j) {
    if (i <= 0) snprintf(buf, size, "%s", name);
    else if (j <= 0) snprintf(buf, size, "%s[%d]", name, i);
    else snprintf(buf, size, "%s[%d,%d]", name, i, j);
}

void fp_check_bad(FpCheck *c, const char *name, int i, int j, double value, const char *why) {
    char label[64], text[FP_REAL_TEXT];
    label_of(label, sizeof label, name, i, j);
    fp_log(c->logger, FP_ERROR, FP_LOG_ERROR, "parameter %s = %s: %s", label,
           fp_real_text(text, value), why);
    c->errors++;
}

void fp_check_bad_int(FpCheck *c, const char *name, int i, long value, const char *why) {
    char label[64];
    label_of(label, sizeof label, name, i, 0);
    fp_log(c->logger, FP_ERROR, FP_LOG_ERROR, "parameter %s = %ld: %s", label, value, why);
    c->errors++;
}

static void check_vlog(FpCheck *c, FpStatus status, FpLogCategory category, const char *fmt,
                       va_list args) {
    char message[512];
    vsnprintf(message, sizeof message, fmt, args);
    fp_log(c->logger, status, category, "%s", message);
}

void fp_check_error(FpCheck *c, const char *fmt, ...) {
    va_list args;
    va_start(args, fmt);
    check_vlog(c, FP_ERROR, FP_LOG_ERROR, fmt, args);
    va_end(args);
    c->errors++;
}

void fp_check_warning(FpCheck *c, const char *fmt, ...) {
    va_list args;
    va_start(args, fmt);
    check_vlog(c, FP_WARNING, FP_LOG_WARNING, fmt, args);
    va_end(args);
}

const char *fp_range_why(const FpRange *r, int integer, char *buf, size_t size) {
    char interval[2 * FP_REAL_TEXT + 8];
    const unsigned both = FP_RANGE_LO | FP_RANGE_HI, opens = FP_RANGE_LO_OPEN | FP_RANGE_HI_OPEN;
    fp_range_text(r, integer, interval, sizeof interval);
    if ((r->flags & both) == FP_RANGE_LO && r->lo == 0.0)
        snprintf(buf, size, "%s", (r->flags & FP_RANGE_LO_OPEN) ? "must be positive"
                                                                : "must not be negative");
    else if ((r->flags & both) == both && !integer && (r->flags & opens) == 0)
        snprintf(buf, size, "must be within %s", interval);
    else if ((r->flags & both) == both && !integer && (r->flags & opens) == opens)
        snprintf(buf, size, "must be inside %s", interval);
    else
        snprintf(buf, size, "must be in %s", interval);
    return buf;
}

/* Element k of row v, reported as name / name[i] / name[i,j]. */
static void bad_element(FpCheck *c, const FpVar *v, int k, double value, const char *why) {
    if (v->rows == 1 && v->cols == 1) fp_check_bad(c, v->name, 0, 0, value, why);
    else if (v->cols == 1) fp_check_bad(c, v->name, k + 1, 0, value, why);
    else fp_check_bad(c, v->name, k / v->cols + 1, k % v->cols + 1, value, why);
}

void fp_need_param(FpCheck *c, const char *name, const double *v, int n, const char *note) {
    const FpVar *row = fp_check_row(c, name);
    char why[160], range[96];
    int k;
    if (row == NULL) return;
    fp_range_why(&row->range, 0, range, sizeof range);
    snprintf(why, sizeof why, "%s%s%s", range, note != NULL ? ": " : "", note != NULL ? note : "");
    for (k = 0; k < n; k++) {
        if (!isfinite(v[k])) bad_element(c, row, k, v[k], "must be finite");
        else if (!fp_range_contains(&row->range, v[k])) bad_element(c, row, k, v[k], why);
    }
}

void fp_need_int_param(FpCheck *c, const char *name, const int32_t *v, int n) {
    const FpVar *row = fp_check_row(c, name);
    char why[96];
    int k;
    if (row == NULL) return;
    fp_range_why(&row->range, 1, why, sizeof why);
    for (k = 0; k < n; k++)
        if (!fp_range_contains(&row->range, (double)v[k]))
            fp_check_bad_int(c, name, row->rows * row->cols == 1 ? 0 : k + 1, (long)v[k], why);
}

void fp_need_ordered(FpCheck *c, const char *name, const double *lo, const double *hi, int n,
                     int cols, const char *why) {
    int k;
    for (k = 0; k < n; k++) {
        if (!(lo[k] > hi[k])) continue;
        if (cols <= 0) fp_check_bad(c, name, 0, 0, lo[k], why);
        else if (cols == 1) fp_check_bad(c, name, k + 1, 0, lo[k], why);
        else fp_check_bad(c, name, k / cols + 1, k % cols + 1, lo[k], why);
    }
}

/* ------------------------------------------------------------------------ */
/* Inertia                                                                  */

/* Eigenvalues of a symmetric 3x3 matrix (trigonometric closed form), e[0] >= e[1] >= e[2]. */
static void sym3_eigenvalues(double a[3][3], double e[3]) {
    double p1 = a[0][1] * a[0][1] + a[0][2] * a[0][2] + a[1][2] * a[1][2];
    double q = (a[0][0] + a[1][1] + a[2][2]) / 3.0, p2, p, b[3][3], r, phi;
    int i, j;
    if (p1 == 0.0) {
        for (i = 0; i < 3; i++) e[i] = a[i][i];
        return;
    }
    p2 = (a[0][0] - q) * (a[0][0] - q) + (a[1][1] - q) * (a[1][1] - q) +
         (a[2][2] - q) * (a[2][2] - q) + 2.0 * p1;
    p = sqrt(p2 / 6.0);
    for (i = 0; i < 3; i++)
        for (j = 0; j < 3; j++) b[i][j] = (a[i][j] - (i == j ? q : 0.0)) / p;
    r = 0.5 * (b[0][0] * (b[1][1] * b[2][2] - b[1][2] * b[2][1]) -
               b[0][1] * (b[1][0] * b[2][2] - b[1][2] * b[2][0]) +
               b[0][2] * (b[1][0] * b[2][1] - b[1][1] * b[2][0]));
    phi = r <= -1.0 ? PI / 3.0 : (r >= 1.0 ? 0.0 : acos(r) / 3.0);
    e[0] = q + 2.0 * p * cos(phi);
    e[2] = q + 2.0 * p * cos(phi + 2.0 * PI / 3.0);
    e[1] = 3.0 * q - e[0] - e[2];
}

/* Finite, symmetric, positive definite (leading minors, eigenvalues and a Cholesky factor
 * all agree), and a warning for moments no rigid body has. */
static void check_inertia(FpCheck *c, const double *inertia) {
    double a[3][3], e[3], l[9], scale = 0.0, m1, m2;
    int i, j;
    fp_need_param(c, "inertia", inertia, 9, NULL);
    for (i = 0; i < 9; i++)
        if (!isfinite(inertia[i])) return; /* reported as non-finite */
    for (i = 0; i < 9; i++) {
        a[i / 3][i % 3] = inertia[i];
        l[i] = inertia[i];
        scale = fmax(scale, fabs(inertia[i]));
    }
    for (i = 0; i < 3; i++)
        for (j = i + 1; j < 3; j++)
            if (fabs(a[i][j] - a[j][i]) > 1e-12 * scale)
                fp_check_bad(c, "inertia", i + 1, j + 1, a[i][j],
                             "the inertia matrix must be symmetric");
    /* Sylvester: leading principal minors positive <=> positive definite. */
    m1 = a[0][0];
    m2 = a[0][0] * a[1][1] - a[0][1] * a[1][0];
    sym3_eigenvalues(a, e);
    if (!(m1 > 0.0) || !(m2 > 0.0) || !(e[0] > 0.0 && e[1] > 0.0 && e[2] > 0.0) ||
        fp_cholesky_factor(l, 3) != FP_OK) {
        fp_check_error(c,
                       "parameter inertia is not positive definite (eigenvalues %.6g, %.6g, "
                       "%.6g kg.m2)",
                       e[0], e[1], e[2]);
        return;
    }
    for (i = 0; i < 3; i++)
        if (e[i] > e[(i + 1) % 3] + e[(i + 2) % 3] * (1.0 + 1e-12)) {
            fp_check_warning(c,
                             "parameter inertia: principal moment %.6g kg.m2 exceeds the sum of "
                             "the other two (%.6g + %.6g), which no rigid body has; using it as "
                             "given",
                             e[i], e[(i + 1) % 3], e[(i + 2) % 3]);
            break;
        }
}

/* ------------------------------------------------------------------------ */
/* Airframe                                                                 */

/* The eigenvalues of the Gram matrix of the columns cols[k] (k < n), largest first. */
static void gram_eigenvalues(const double (*cols)[3], int n, double e[3]) {
    double g[3][3] = {{0.0}};
    int i, j, k;
    for (k = 0; k < n; k++)
        for (i = 0; i < 3; i++)
            for (j = 0; j < 3; j++) g[i][j] += cols[k][i] * cols[k][j];
    sym3_eigenvalues(g, e);
    for (i = 0; i < 2; i++) /* (the diagonal case comes unsorted) */
        for (j = 0; j < 2 - i; j++)
            if (e[j] < e[j + 1]) {
                double t = e[j];
                e[j] = e[j + 1], e[j + 1] = t;
            }
}

/*
 * Control authority of a valid rotor set: no two rotors at one place, and torques about
 * every axis.  The torque directions a rotor offers are M_i t_i (thrust changes) and
 * M_i dt_i/dalpha, M_i dt_i/dbeta (tilts, where the servo moves), at the centre of its servo
 * box, with M_i = S(d_i) + c_i (k_d / k_t) I (eq. 3).  The moment arms alone (S(d_i)) must
 * span two axes, and with the drag torques all three: otherwise roll, pitch or yaw is out of
 * reach whatever the allocation does (all rotors at the centre, all on one line through it).
 */
static void check_authority(FpCheck *c, const FpRotorSet *rs) {
    double arm[3 * FP_MAX_ROTORS][3], all[3 * FP_MAX_ROTORS][3], e_arm[3], e_all[3];
    double size = 0.0, r = rs->k_d / rs->k_t;
    int i, j, k = 0;
    for (i = 0; i < rs->n; i++) size = fmax(size, sqrt(v3_dot(rs->pos[i], rs->pos[i])));
    for (i = 0; i < rs->n; i++)
        for (j = i + 1; j < rs->n; j++) {
            double d[3];
            d[0] = rs->pos[i][0] - rs->pos[j][0], d[1] = rs->pos[i][1] - rs->pos[j][1];
            d[2] = rs->pos[i][2] - rs->pos[j][2];
            if (sqrt(v3_dot(d, d)) <= 1e-9 * (1.0 + size)) {
                fp_check_error(c,
                               "parameter rotor_pos: rotors %d and %d are at the same position "
                               "(%.6g, %.6g, %.6g) m: no two rotors can occupy one place",
                               i + 1, j + 1, rs->pos[i][0], rs->pos[i][1], rs->pos[i][2]);
                return;
            }
        }
    for (i = 0; i < rs->n; i++) {
        double a0 = 0.5 * (rs->alpha_min[i] + rs->alpha_max[i]);
        double b0 = 0.5 * (rs->beta_min[i] + rs->beta_max[i]);
        double dirs[3][3];
        int n_dirs = 1, q;
        fp_thrust_direction(a0, b0, rs->gamma[i], dirs[0]);
        fp_thrust_direction_jacobian(a0, b0, rs->gamma[i], dirs[1], dirs[2]);
        if (rs->alpha_max[i] > rs->alpha_min[i]) n_dirs = 2;
        if (rs->beta_max[i] > rs->beta_min[i]) {
            if (n_dirs == 1) memcpy(dirs[1], dirs[2], sizeof dirs[1]);
            n_dirs++;
        }
        for (q = 0; q < n_dirs; q++, k++) {
            v3_cross(rs->pos[i], dirs[q], arm[k]);
            for (j = 0; j < 3; j++) all[k][j] = arm[k][j] + r * rs->dir[i] * dirs[q][j];
        }
    }
    gram_eigenvalues((const double(*)[3])arm, k, e_arm);
    gram_eigenvalues((const double(*)[3])all, k, e_all);
    if (!(e_arm[1] > 1e-9 * e_arm[0]) || !(e_arm[0] > 0.0))
        fp_check_error(c,
                       "parameter rotor_pos: the rotors' moment arms about the centre of gravity "
                       "give torque about %s axis (all rotors at the centre or on one line "
                       "through it): the vehicle cannot be controlled",
                       e_arm[0] > 0.0 ? "one" : "no");
    else if (!(e_all[2] > 1e-9 * e_all[0]))
        fp_check_error(c,
                       "parameters rotor_pos, rotor_dir, k_d: the rotors give no torque about one "
                       "axis (the moment arms span two, and the drag torques do not add the "
                       "third): the vehicle cannot be controlled");
}

/*
 * Physical plausibility of the propulsion (the FP_* bounds of multirotor.h; plant/airframe.py
 * applies the same ones, computed in the same order, to airframe files): a rotor speed
 * between 1 and 500000 rpm, a rotor's maximum thrust between 1 mN and 100 kN, at most 10 m
 * of drag torque per newton of thrust and, under gravity, a thrust-to-weight ratio between
 * 0.1 and 100.  Outside them no vehicle exists, and the numbers leave the range the force
 * sets and the allocation resolve (the controller's sets are bounded at 1e6 N).  A speed out
 * of range skips the thrust checks it would skew, a thrust out of range the ratio.  These
 * are not declared ranges (most bound a product of parameters): the messages read
 * "parameter NAME: ..." or "parameters A, B: ...", never "parameter NAME = VALUE: ...",
 * which reports a value outside its declared range.
 */
static void check_propulsion(FpCheck *c, const FpAirframe *af) {
    const double rpm = 2.0 * PI / 60.0;
    const double w_lo = FP_OMEGA_MAX_RPM_MIN * rpm, w_hi = FP_OMEGA_MAX_RPM_MAX * rpm;
    const double t_max = af->k_t * (af->omega_max * af->omega_max);
    const double ratio = af->k_d / af->k_t;
    if (!(af->omega_max >= w_lo && af->omega_max <= w_hi)) {
        fp_check_error(c,
                       "parameter omega_max: %.6g rad/s is outside [%.6g, %.6g] rad/s (%g to %g "
                       "rpm): %s than any rotor turns",
                       af->omega_max, w_lo, w_hi, FP_OMEGA_MAX_RPM_MIN, FP_OMEGA_MAX_RPM_MAX,
                       af->omega_max < w_lo ? "slower" : "faster");
        return;
    }
    if (!(t_max >= FP_ROTOR_THRUST_MIN && t_max <= FP_ROTOR_THRUST_MAX)) {
        fp_check_error(c,
                       "parameters k_t, omega_max: a rotor's maximum thrust k_t omega_max^2 = "
                       "%.6g N is outside [%g, %g] N: %s than any rotor's",
                       t_max, FP_ROTOR_THRUST_MIN, FP_ROTOR_THRUST_MAX,
                       t_max < FP_ROTOR_THRUST_MIN ? "less" : "more");
        return;
    }
    if (!(ratio <= FP_DRAG_RATIO_MAX))
        fp_check_error(c,
                       "parameters k_d, k_t: the drag torque per newton of thrust k_d / k_t = "
                       "%.6g m exceeds %g m: more than any rotor's",
                       ratio, FP_DRAG_RATIO_MAX);
    if (af->g > 0.0) {
        const double weight = af->mass * af->g;
        const double tw = (double)af->n_rotors * t_max / weight;
        if (!(tw >= FP_THRUST_TO_WEIGHT_MIN && tw <= FP_THRUST_TO_WEIGHT_MAX))
            fp_check_error(c,
                           "parameters mass, g, k_t, omega_max: the thrust-to-weight ratio "
                           "n_rotors k_t omega_max^2 / (mass g) = %d x %.6g N / %.6g N = %.6g "
                           "is outside [%g, %g]",
                           (int)af->n_rotors, t_max, weight, tw, FP_THRUST_TO_WEIGHT_MIN,
                           FP_THRUST_TO_WEIGHT_MAX);
    }
}

FpStatus fp_check_airframe(FpCheck *c, const FpAirframe *af) {
    FpRotorSet set;
    const FpRotorSet *rs = &set;
    int i, n = af->n_rotors, errors = c->errors, errors0 = c->errors;
    fp_rotor_set_of(af, &set);
    fp_need_int_param(c, "n_rotors", &af->n_rotors, 1);
    if (c->errors > errors) return FP_ERROR; /* the per-rotor checks need a valid n */
    if (n < 1 || n > FP_MAX_ROTORS) { /* a table whose range exceeds the arrays: a bug */
        fp_check_bad_int(c, "n_rotors", 0, (long)n, "exceeds the rotor slots");
        return FP_ERROR;
    }
    fp_need_param(c, "mass", &af->mass, 1, NULL);
    check_inertia(c, &af->inertia[0][0]);
    fp_need_param(c, "g", &af->g, 1, NULL);
    fp_need_param(c, "k_t", &rs->k_t, 1, NULL);
    fp_need_param(c, "k_d", &rs->k_d, 1, NULL);
    fp_need_param(c, "rotor_pos", &rs->pos[0][0], 3 * n, NULL);
    errors = c->errors;
    fp_need_int_param(c, "rotor_dir", rs->dir, n);
    if (c->errors == errors)
        for (i = 0; i < n; i++)
            if (rs->dir[i] != 1 && rs->dir[i] != -1)
                fp_check_bad_int(c, "rotor_dir", i + 1, (long)rs->dir[i], "must be +1 or -1");
    fp_need_param(c, "rotor_gamma", rs->gamma, n, NULL);
    fp_need_param(c, "alpha_min", rs->alpha_min, n, NULL);
    fp_need_param(c, "alpha_max", rs->alpha_max, n, NULL);
    fp_need_param(c, "beta_min", rs->beta_min, n, NULL);
    fp_need_param(c, "beta_max", rs->beta_max, n, NULL);
    fp_need_ordered(c, "alpha_min", rs->alpha_min, rs->alpha_max, n, 1,
                    "exceeds alpha_max (inverted limits)");
    fp_need_ordered(c, "beta_min", rs->beta_min, rs->beta_max, n, 1,
                    "exceeds beta_max (inverted limits)");
    fp_need_param(c, "omega_min", &rs->omega_min, 1, NULL);
    fp_need_param(c, "omega_max", &rs->omega_max, 1, NULL);
    fp_need_ordered(c, "omega_min", &rs->omega_min, &rs->omega_max, 1, 0,
                    "exceeds omega_max (inverted limits)");
    fp_need_param(c, "tau_motor", &af->tau_motor, 1, NULL);
    fp_need_param(c, "tau_servo", &af->tau_servo, 1, NULL);
    if (c->errors == errors0) check_propulsion(c, af);
    if (c->errors == errors0) check_authority(c, rs);
    return FP_OK;
}
