/*
 * FullPoseController: the paper's section III as a discrete-time system.
 *
 * One sample (every Ts):
 *   1. H(s) filters every measurement and the actuator feedback (exact ZOH
 *      discretization; the filter's derivative state of the body rates is the
 *      filtered angular acceleration).
 *   2. Guidance: first-order blocks K_xi, K_xidot with velocity/acceleration
 *      feed-forward give the commanded acceleration; outer INDI (eq. 14-15)
 *      and the WLS guidance QP (eq. 17-23) over [dfx, dfy, dfz, dphi, dtheta]
 *      give mu_c and df_b_c.  psi_c = psi_ref (outside the QP: see
 *      docs/architecture.md, "Design decisions").
 *   3. Stabilization: attitude and rate blocks, INDI on the rotational
 *      dynamics: dtau_c = I (dOmega_c - dOmega_m).
 *   4. Inner allocation: WLS on the analytic B''(u_a,m) (eq. 12-13) with
 *      actuator bounds, torque priority and a preferred configuration.
 */
#include "controller.h"

#include <math.h>
#include <stddef.h>
#include <stdio.h>
#include <string.h>

#include "controller_vars.h"
#include "default_gains.h"
#include "fp_clock.h"
#include "fp_math.h"

#define PI 3.14159265358979323846

#define ELEM_SIZE_REAL sizeof(double)
#define ELEM_SIZE_INTEGER sizeof(int32_t)
#define ELEM_SIZE_BOOLEAN sizeof(int32_t)
#define CTRL_CHECK(name, vr, type, kind, rows, cols, unit, desc)                                  \
    FP_STATIC_ASSERT(sizeof(((ControllerModel *)0)->name) == (rows) * (cols) * ELEM_SIZE_##type, \
                     name##_size);
CONTROLLER_VARIABLES(CTRL_CHECK)
FP_STATIC_ASSERT(FP_POLYTOPE_MAX_FACETS == 64, polytope_cap_matches_table);
FP_STATIC_ASSERT(FP_FAIL_POLYTOPE_FACETS * FP_MAX_ROTORS == 256, fail_polytope_cap_matches_table);
FP_STATIC_ASSERT(FP_POLYTOPE_MAX_FACETS <= FP_WLS_MAX_CONS, polytope_fits_qp);
FP_STATIC_ASSERT(3 * FP_MAX_ROTORS <= FP_WLS_MAX_VARS, allocation_fits_qp);
FP_STATIC_ASSERT(6 + 3 * FP_MAX_ROTORS <= FP_WLS_MAX_ROWS, allocation_rows_fit_qp);

#define CTRL_ROW(name, vr, type, kind, rows, cols, unit, desc) \
    {#name, vr, FP_##type, FP_##kind, rows, cols, offsetof(ControllerModel, name), unit, desc},
static const FpVar controller_vars[] = {CONTROLLER_VARIABLES(CTRL_ROW)};

/* Filtered-signal slots. */
enum { F_POS = 0, F_VEL = 3, F_ACC = 6, F_EULER = 9, F_RATE = 12, F_POS_REF = 15, F_VEL_REF = 18,
       F_EULER_REF = 21, F_OMEGA = 24 };
#define F_ALPHA (F_OMEGA + FP_MAX_ROTORS)
#define F_BETA (F_ALPHA + FP_MAX_ROTORS)

enum { BLK_POS = 0, BLK_VEL = 1, BLK_ATT = 2, BLK_RATE = 3 };

static double wrap_pi(double a) {
    a = fmod(a + PI, 2.0 * PI);
    if (a < 0.0) a += 2.0 * PI;
    return a - PI;
}

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
    FpAirframe af;
    double w[6] = {0.0, 0.0, 0.0, 0.0, 0.0, 0.0};
    int i;
    memset(m, 0, sizeof *m);
    fp_paper_hexacopter(&af);
    m->Ts = 0.002;
    FP_ROTOR_SET_TO_MODEL(&af.rotors, m);
    m->mass = af.mass;
    memcpy(m->inertia, af.inertia, sizeof m->inertia);
    m->g = af.g;
    m->filt_wn = 50.0;
    m->filt_zeta = 0.55;
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
    m->euler_min[0] = m->euler_min[1] = -60.0 * PI / 180.0;
    m->euler_max[0] = m->euler_max[1] = 60.0 * PI / 180.0;
    m->force_constraint = 0;
    m->poly_n = FP_DEFAULT_POLYTOPE_FACETS;
    for (i = 0; i < FP_DEFAULT_POLYTOPE_FACETS; i++) {
        m->poly_A[i][0] = fp_default_polytope_A[3 * i];
        m->poly_A[i][1] = fp_default_polytope_A[3 * i + 1];
        m->poly_A[i][2] = fp_default_polytope_A[3 * i + 2];
        m->poly_b[i] = fp_default_polytope_b[i];
    }
    for (i = 0; i < FP_MAX_ROTORS; i++) {
        int k, base = i * FP_FAIL_POLYTOPE_FACETS;
        m->fail_poly_n[i] = fp_default_fail_n[i];
        m->rotor_health[i] = 1.0;
        for (k = 0; k < fp_default_fail_n[i]; k++) {
            m->fail_poly_A[base + k][0] = fp_default_fail_A[3 * (base + k)];
            m->fail_poly_A[base + k][1] = fp_default_fail_A[3 * (base + k) + 1];
            m->fail_poly_A[base + k][2] = fp_default_fail_A[3 * (base + k) + 2];
            m->fail_poly_b[base + k] = fp_default_fail_b[base + k];
        }
    }
    m->poly_margin = 0.9;
    m->W_nu[0] = m->W_nu[1] = m->W_nu[2] = 1.0;
    /* Torque priority for roll and pitch; yaw, the weakest axis (drag torque and
     * tangential tilt only), ranks with the forces: with yaw at 100 a 0.3 rad heading
     * step saturated the servos for yaw and gave up the force, and the vehicle was lost. */
    m->W_nu[3] = m->W_nu[4] = 100.0;
    m->W_nu[5] = 1.0;
    m->yaw_rate_max = 0.5;
    m->w_pref = 0.1;
    m->pref_omega_scale = 1.0 / 50.0;
    m->qp_max_iter = 50;
    /* Measurements start at the hover trim of the default airframe. */
    w[2] = -af.mass * af.g;
    fp_preferred_config(&af.rotors, w, m->alpha, m->beta, m->omega, NULL, 0);
    memcpy(m->omega_cmd, m->omega, sizeof m->omega_cmd);
    memcpy(m->alpha_cmd, m->alpha, sizeof m->alpha_cmd);
    memcpy(m->beta_cmd, m->beta, sizeof m->beta_cmd);
}

/* ------------------------------------------------------------------------ */
/* H(s), discretized once: exact zero-order hold via a 3x3 matrix exponential */

static void expm3(double a[3][3], double out[3][3]) {
    double norm = 0.0, s[3][3], term[3][3], tmp[3][3];
    int i, j, k, squarings = 0, n;
    for (i = 0; i < 3; i++)
        for (j = 0; j < 3; j++) norm = fmax(norm, fabs(a[i][j]));
    while (norm > 0.5 && squarings < 60) {
        norm *= 0.5;
        squarings++;
    }
    for (i = 0; i < 3; i++)
        for (j = 0; j < 3; j++) {
            s[i][j] = ldexp(a[i][j], -squarings);
            out[i][j] = term[i][j] = (i == j) ? 1.0 : 0.0;
        }
    for (n = 1; n <= 16; n++) { /* Taylor series of exp(s), |s| <= 0.5 */
        for (i = 0; i < 3; i++)
            for (j = 0; j < 3; j++) {
                double v = 0.0;
                for (k = 0; k < 3; k++) v += term[i][k] * s[k][j];
                tmp[i][j] = v / n;
            }
        for (i = 0; i < 3; i++)
            for (j = 0; j < 3; j++) {
                term[i][j] = tmp[i][j];
                out[i][j] += tmp[i][j];
            }
    }
    for (; squarings > 0; squarings--) {
        m3_mul(&out[0][0], &out[0][0], &tmp[0][0]);
        memcpy(out, tmp, sizeof tmp);
    }
}

static void discretize_filter(ControllerModel *m) {
    /* states [y, y'], y'' = wn^2 (u - y) - 2 zeta wn y' ; augmented with the held input */
    double a[3][3] = {{0.0, 1.0, 0.0}, {0.0, 0.0, 0.0}, {0.0, 0.0, 0.0}}, e[3][3];
    double wn = m->filt_wn, z = m->filt_zeta;
    int i, j;
    a[1][0] = -wn * wn;
    a[1][1] = -2.0 * z * wn;
    a[1][2] = wn * wn;
    for (i = 0; i < 3; i++)
        for (j = 0; j < 3; j++) a[i][j] *= m->Ts;
    expm3(a, e);
    for (i = 0; i < 2; i++) {
        m->filt_phi[i][0] = e[i][0];
        m->filt_phi[i][1] = e[i][1];
        m->filt_gamma[i] = e[i][2];
    }
}

static void filter_update(const ControllerModel *m, double x[2], double u) {
    double y = m->filt_phi[0][0] * x[0] + m->filt_phi[0][1] * x[1] + m->filt_gamma[0] * u;
    double dy = m->filt_phi[1][0] * x[0] + m->filt_phi[1][1] * x[1] + m->filt_gamma[1] * u;
    x[0] = y;
    x[1] = dy;
}

/* First-order block x+ = A x + B e, y = C x + D e (discrete, one axis). */
static double block(double *x, double a, double b, double c, double d, double e) {
    double y = c * (*x) + d * e;
    *x = a * (*x) + b * e;
    return y;
}

/* ------------------------------------------------------------------------ */
/* Validation                                                               */

typedef struct {
    const FpLogger *logger;
    int errors;
} Check;

static void bad(Check *c, const char *name, int index, double value, const char *why) {
    char label[48], text[FP_REAL_TEXT];
    if (index > 0) snprintf(label, sizeof label, "%s[%d]", name, index);
    else snprintf(label, sizeof label, "%s", name);
    fp_log(c->logger, FP_ERROR, FP_LOG_ERROR, "parameter %s = %s: %s", label,
           fp_real_text(text, value), why);
    c->errors++;
}

/* n values must be finite and, with positive set, > 0. */
static void need(Check *c, const char *name, const double *v, int n, int positive) {
    int i;
    for (i = 0; i < n; i++) {
        if (!isfinite(v[i])) bad(c, name, n > 1 ? i + 1 : 0, v[i], "must be finite");
        else if (positive && !(v[i] > 0.0))
            bad(c, name, n > 1 ? i + 1 : 0, v[i], "must be positive");
    }
}

static void check_tunables(ControllerModel *m, Check *c) {
    const char *names[16] = {"K_pos_A", "K_pos_B", "K_pos_C", "K_pos_D", "K_vel_A", "K_vel_B",
                             "K_vel_C", "K_vel_D", "K_att_A", "K_att_B", "K_att_C", "K_att_D",
                             "K_rate_A", "K_rate_B", "K_rate_C", "K_rate_D"};
    const double *blocks[16];
    int i, k;
    blocks[0] = m->K_pos_A, blocks[1] = m->K_pos_B, blocks[2] = m->K_pos_C, blocks[3] = m->K_pos_D;
    blocks[4] = m->K_vel_A, blocks[5] = m->K_vel_B, blocks[6] = m->K_vel_C, blocks[7] = m->K_vel_D;
    blocks[8] = m->K_att_A, blocks[9] = m->K_att_B, blocks[10] = m->K_att_C,
    blocks[11] = m->K_att_D;
    blocks[12] = m->K_rate_A, blocks[13] = m->K_rate_B, blocks[14] = m->K_rate_C,
    blocks[15] = m->K_rate_D;
    for (k = 0; k < 16; k++) need(c, names[k], blocks[k], 3, 0);
    for (k = 0; k < 16; k += 4)
        for (i = 0; i < 3; i++)
            if (isfinite(blocks[k][i]) && fabs(blocks[k][i]) >= 1.0)
                bad(c, names[k], i + 1, blocks[k][i],
                    "the discrete block's pole must lie inside the unit circle (|A| < 1)");
    need(c, "gamma_opt", &m->gamma_opt, 1, 1);
    need(c, "W_u", m->W_u, 5, 1);
    need(c, "W_v", m->W_v, 3, 1);
    need(c, "W_nu", m->W_nu, 6, 1);
    need(c, "w_pref", &m->w_pref, 1, 1);
    need(c, "pref_omega_scale", &m->pref_omega_scale, 1, 1);
    need(c, "yaw_rate_max", &m->yaw_rate_max, 1, 1);
    need(c, "euler_min", m->euler_min, 2, 0);
    need(c, "euler_max", m->euler_max, 2, 0);
    for (i = 0; i < 2; i++) {
        if (m->euler_min[i] > m->euler_max[i])
            bad(c, "euler_min", i + 1, m->euler_min[i], "exceeds euler_max (inverted bounds)");
        if (fabs(m->euler_min[i]) >= PI / 2 || fabs(m->euler_max[i]) >= PI / 2)
            bad(c, fabs(m->euler_min[i]) >= PI / 2 ? "euler_min" : "euler_max", i + 1,
                fabs(m->euler_min[i]) >= PI / 2 ? m->euler_min[i] : m->euler_max[i],
                "must be inside (-pi/2, pi/2)");
    }
    if (m->qp_max_iter < 1 || m->qp_max_iter > 1000) {
        fp_log(c->logger, FP_ERROR, FP_LOG_ERROR, "parameter qp_max_iter = %d: must be in 1..1000",
               (int)m->qp_max_iter);
        c->errors++;
    }
}

/* Support of the polytope {A f <= d} along +-e_axis, found with the WLS solver as
 * min (e.f - target)^2 + eps |f|^2: infeasible -> empty; huge -> unbounded. */
static FpWlsStatus polytope_support(ControllerModel *m, const double (*A)[3], const double *d,
                                    int n, int axis, double sign, double *value) {
    FpWls *w = &m->guid; /* borrowed before the guidance QP is set up */
    FpWlsResult r;
    int i;
    const double far = 1e9;
    fp_wls_setup(w, 3, 4, n);
    for (i = 0; i < 3; i++) {
        w->A[i] = (i == axis) ? sign : 0.0;
        w->A[3 * (i + 1) + i] = 1e-6;
    }
    w->b[0] = far;
    for (i = 0; i < n; i++) {
        w->C[3 * i] = A[i][0];
        w->C[3 * i + 1] = A[i][1];
        w->C[3 * i + 2] = A[i][2];
        w->d[i] = d[i];
    }
    fp_wls_solve(w, 200, &r);
    *value = sign * w->x[axis];
    return r.status;
}

/* Facets finite with non-zero normals, the set non-empty and bounded; its f_bz range.
 * Returns 0 or logs an error naming the parameters and returns 1. */
static int check_facets(ControllerModel *m, Check *c, const char *name, const double (*A)[3],
                        const double *b, int n, double *fz_min, double *fz_max) {
    int i, axis;
    for (i = 0; i < n; i++) {
        double norm = sqrt(v3_dot(A[i], A[i]));
        if (!isfinite(norm) || !isfinite(b[i]) || !(norm > 1e-9)) {
            fp_log(c->logger, FP_ERROR, FP_LOG_ERROR,
                   "parameters %s: facet %d must be finite with a non-zero normal", name, i + 1);
            c->errors++;
            return 1;
        }
    }
    for (axis = 0; axis < 3; axis++) {
        double lo, hi;
        FpWlsStatus s1 = polytope_support(m, A, b, n, axis, -1.0, &lo);
        FpWlsStatus s2 = polytope_support(m, A, b, n, axis, 1.0, &hi);
        if (s1 == FP_WLS_INFEASIBLE || s2 == FP_WLS_INFEASIBLE) {
            fp_log(c->logger, FP_ERROR, FP_LOG_ERROR,
                   "parameters %s: the feasible-force polytope is empty", name);
            c->errors++;
            return 1;
        }
        lo = -lo;
        if (s1 != FP_WLS_OPTIMAL || s2 != FP_WLS_OPTIMAL || hi > 1e6 || lo < -1e6) {
            fp_log(c->logger, FP_ERROR, FP_LOG_ERROR,
                   "parameters %s: the feasible-force polytope is unbounded along body axis %d",
                   name, axis + 1);
            c->errors++;
            return 1;
        }
        if (axis == 2) {
            *fz_min = lo;
            *fz_max = hi;
        }
    }
    return 0;
}

/* Offsets d of {A f <= b} scaled by the margin about the hover force; 0 when the
 * hover force is outside the set (d = b then). */
static int scale_about_hover(const ControllerModel *m, const double (*A)[3], const double *b,
                             int n, double *d) {
    double hover[3] = {0.0, 0.0, 0.0};
    int i, inside = 1;
    hover[2] = -m->mass * m->g;
    for (i = 0; i < n; i++)
        if (!(v3_dot(A[i], hover) <= b[i] + 1e-9 * (1.0 + fabs(b[i])))) inside = 0;
    for (i = 0; i < n; i++) {
        double ah = v3_dot(A[i], hover);
        d[i] = inside ? ah + m->poly_margin * (b[i] - ah) : b[i];
    }
    return inside;
}

static void check_polytope(ControllerModel *m, Check *c) {
    int i;
    double fz_lo, fz_hi;
    if (m->poly_n < 4 || m->poly_n > FP_POLYTOPE_MAX_FACETS) {
        fp_log(c->logger, FP_ERROR, FP_LOG_ERROR,
               "parameter poly_n = %d: a bounded polytope in 3-D needs 4..%d facets",
               (int)m->poly_n, FP_POLYTOPE_MAX_FACETS);
        c->errors++;
        return;
    }
    if (!(m->poly_margin > 0.0 && m->poly_margin <= 1.0))
        bad(c, "poly_margin", 0, m->poly_margin, "must be in (0, 1]");
    for (i = 0; i < m->n_rotors; i++)
        if (m->fail_poly_n[i] != 0 &&
            (m->fail_poly_n[i] < 4 || m->fail_poly_n[i] > FP_FAIL_POLYTOPE_FACETS)) {
            fp_log(c->logger, FP_ERROR, FP_LOG_ERROR,
                   "parameter fail_poly_n[%d] = %d: must be 0 (none) or 4..%d", i + 1,
                   (int)m->fail_poly_n[i], FP_FAIL_POLYTOPE_FACETS);
            c->errors++;
        }
    if (c->errors) return;
    if (check_facets(m, c, "poly_A, poly_b", (const double(*)[3])m->poly_A, m->poly_b, m->poly_n,
                     &m->fz_min, &m->fz_max))
        return;
    /* The guidance works in S(0) scaled about the hover force: the margin keeps
     * actuator authority for attitude torques (S(0) assumes none) and absorbs the
     * outer approximation of the polytope. */
    m->hover_ok[0] = scale_about_hover(m, (const double(*)[3])m->poly_A, m->poly_b, m->poly_n,
                                       m->poly_d);
    if (!m->hover_ok[0]) {
        fp_log(c->logger, FP_ERROR, FP_LOG_ERROR,
               "parameters poly_A, poly_b: the hover force [0, 0, %.6g] N is outside the "
               "polytope: it does not describe this vehicle",
               -m->mass * m->g);
        c->errors++;
        return;
    }
    {
        /* scaling about the hover force maps the f_bz range the same way */
        double hz = -m->mass * m->g;
        m->fz_min = hz + m->poly_margin * (m->fz_min - hz);
        m->fz_max = hz + m->poly_margin * (m->fz_max - hz);
    }
    for (i = 0; i < FP_MAX_ROTORS; i++) {
        int base = i * FP_FAIL_POLYTOPE_FACETS;
        char name[48];
        m->hover_ok[i + 1] = 0;
        if (i >= m->n_rotors || m->fail_poly_n[i] == 0) continue;
        snprintf(name, sizeof name, "fail_poly_A, fail_poly_b (rotor %d)", i + 1);
        if (check_facets(m, c, name, (const double(*)[3])&m->fail_poly_A[base],
                         &m->fail_poly_b[base], m->fail_poly_n[i], &fz_lo, &fz_hi))
            return;
        m->hover_ok[i + 1] = scale_about_hover(m, (const double(*)[3])&m->fail_poly_A[base],
                                               &m->fail_poly_b[base], m->fail_poly_n[i],
                                               &m->fail_d[base]);
        if (m->hover_ok[i + 1]) { /* scaled about hover like the set itself */
            double hz = -m->mass * m->g;
            fz_lo = hz + m->poly_margin * (fz_lo - hz);
            fz_hi = hz + m->poly_margin * (fz_hi - hz);
        }
        m->fail_fz[i][0] = fz_lo;
        m->fail_fz[i][1] = fz_hi;
        if (!m->hover_ok[i + 1])
            fp_log(c->logger, FP_WARNING, FP_LOG_WARNING,
                   "losing rotor %d leaves no hover force in its feasible-force set", i + 1);
    }
}

static int validate(ControllerModel *m, const FpLogger *logger) {
    Check c;
    int i, n = m->n_rotors;
    c.logger = logger;
    c.errors = 0;
    need(&c, "Ts", &m->Ts, 1, 1);
    if (n < 1 || n > FP_MAX_ROTORS) {
        fp_log(logger, FP_ERROR, FP_LOG_ERROR, "parameter n_rotors = %d: must be in 1..%d",
               (int)n, FP_MAX_ROTORS);
        return 1;
    }
    need(&c, "mass", &m->mass, 1, 1);
    need(&c, "inertia", &m->inertia[0][0], 9, 0);
    need(&c, "g", &m->g, 1, 0);
    need(&c, "k_t", &m->k_t, 1, 1);
    need(&c, "k_d", &m->k_d, 1, 0);
    need(&c, "rotor_pos", &m->rotor_pos[0][0], 3 * n, 0);
    need(&c, "rotor_gamma", m->rotor_gamma, n, 0);
    need(&c, "alpha_min", m->alpha_min, n, 0);
    need(&c, "alpha_max", m->alpha_max, n, 0);
    need(&c, "beta_min", m->beta_min, n, 0);
    need(&c, "beta_max", m->beta_max, n, 0);
    need(&c, "omega_max", &m->omega_max, 1, 1);
    need(&c, "omega_min", &m->omega_min, 1, 0);
    need(&c, "filt_wn", &m->filt_wn, 1, 1);
    need(&c, "filt_zeta", &m->filt_zeta, 1, 1);
    for (i = 0; i < n; i++) {
        if (m->rotor_dir[i] != 1 && m->rotor_dir[i] != -1)
            bad(&c, "rotor_dir", i + 1, m->rotor_dir[i], "must be +1 or -1");
        if (m->alpha_min[i] > m->alpha_max[i])
            bad(&c, "alpha_min", i + 1, m->alpha_min[i], "exceeds alpha_max (inverted limits)");
        if (m->beta_min[i] > m->beta_max[i])
            bad(&c, "beta_min", i + 1, m->beta_min[i], "exceeds beta_max (inverted limits)");
    }
    if (m->omega_min < 0.0) bad(&c, "omega_min", 0, m->omega_min, "must not be negative");
    if (m->omega_min > m->omega_max)
        bad(&c, "omega_min", 0, m->omega_min, "exceeds omega_max (inverted limits)");
    if (m->force_constraint != 0 && m->force_constraint != 1) {
        fp_log(logger, FP_ERROR, FP_LOG_ERROR,
               "parameter force_constraint = %d: must be 0 (joint polytope) or 1 (f_bz slice)",
               (int)m->force_constraint);
        c.errors++;
    }
    {
        double l[3][3];
        int ok = 1;
        memcpy(l, m->inertia, sizeof l);
        for (i = 0; i < 3; i++)
            if (fabs(m->inertia[i][(i + 1) % 3] - m->inertia[(i + 1) % 3][i]) >
                1e-12 * fabs(m->inertia[i][i]))
                ok = 0;
        if (c.errors == 0 && (!ok || fp_cholesky_factor(&l[0][0], 3) != FP_OK)) {
            fp_log(logger, FP_ERROR, FP_LOG_ERROR,
                   "parameter inertia: must be symmetric positive definite");
            c.errors++;
        }
    }
    check_tunables(m, &c);
    if (c.errors == 0) check_polytope(m, &c);
    return c.errors;
}

/* ------------------------------------------------------------------------ */
/* Control law                                                              */


/* R = Rz(psi) Ry(theta) Rx(phi) and its partial derivatives in phi and theta. */
static void attitude_jacobian(const double e[3], double r[9], double dr_dphi[9],
                              double dr_dtheta[9]) {
    double rx[3][3], ry[3][3], rz[3][3], drx[3][3], dry[3][3], t[9];
    double cp = cos(e[0]), sp = sin(e[0]), ct = cos(e[1]), st = sin(e[1]);
    rot_x(e[0], rx);
    rot_y(e[1], ry);
    rot_z(e[2], rz);
    memset(drx, 0, sizeof drx);
    memset(dry, 0, sizeof dry);
    drx[1][1] = -sp, drx[1][2] = -cp, drx[2][1] = cp, drx[2][2] = -sp;
    dry[0][0] = -st, dry[0][2] = ct, dry[2][0] = -ct, dry[2][2] = -st;
    m3_mul(&rz[0][0], &ry[0][0], t);
    m3_mul(t, &rx[0][0], r);
    m3_mul(t, &drx[0][0], dr_dphi);
    m3_mul(&rz[0][0], &dry[0][0], t);
    m3_mul(t, &rx[0][0], dr_dtheta);
}

static void filtered_actuators(const ControllerModel *m, double a[], double b[], double w[]) {
    int i;
    for (i = 0; i < FP_MAX_ROTORS; i++) {
        a[i] = m->filt[F_ALPHA + i][0];
        b[i] = m->filt[F_BETA + i][0];
        w[i] = m->filt[F_OMEGA + i][0];
    }
}

typedef struct {
    double eff[FP_MAX_ROTORS]; /* known rotor efficiency, 0 for lost rotors */
    double mu_m[3], rate_m[3], ang_acc_m[3];
    double a_m[FP_MAX_ROTORS], b_m[FP_MAX_ROTORS], w_m[FP_MAX_ROTORS];
    double f_b_m[3], tau_b_m[3];
} Measured;

static void read_filters(const ControllerModel *m, Measured *s) {
    int i;
    for (i = 0; i < 3; i++) {
        s->mu_m[i] = m->filt[F_EULER + i][0];
        s->rate_m[i] = m->filt[F_RATE + i][0];
        s->ang_acc_m[i] = m->filt[F_RATE + i][1];
    }
    filtered_actuators(m, s->a_m, s->b_m, s->w_m);
    for (i = 0; i < FP_MAX_ROTORS; i++)
        s->eff[i] = (m->lost_mask >> i) & 1 ? 0.0 : fmin(fmax(m->rotor_health[i], 0.0), 1.0);
    fp_rotor_wrench(&m->rotors, s->a_m, s->b_m, s->w_m, s->eff, s->f_b_m, s->tau_b_m);
}

/* The feasible-force set in use: nominal, or the one after losing the single lost rotor. */
static int active_set(const ControllerModel *m, const double (**A)[3], const double **d,
                      double fz[2]) {
    int i = m->active_polytope;
    if (i >= 1) {
        *A = (const double(*)[3])&m->fail_poly_A[(i - 1) * FP_FAIL_POLYTOPE_FACETS];
        *d = &m->fail_d[(i - 1) * FP_FAIL_POLYTOPE_FACETS];
        fz[0] = m->fail_fz[i - 1][0];
        fz[1] = m->fail_fz[i - 1][1];
        return m->fail_poly_n[i - 1];
    }
    *A = (const double(*)[3])m->poly_A;
    *d = m->poly_d;
    fz[0] = m->fz_min;
    fz[1] = m->fz_max;
    return m->poly_n;
}

/* Guidance: blocks + feed-forward, outer INDI, WLS guidance QP. */
static void guidance(ControllerModel *m, const Measured *s, double df_c[3], double mu_c[3]) {
    FpWls *w = &m->guid;
    FpWlsResult res;
    double r[9], drp[9], drt[9], g_mat[3][5], v_c[3], dacc[3], f_w_ref[3], rf[3];
    double sg = sqrt(m->gamma_opt), t0;
    int i, j, k, n_cons = 0, flags = 0;
    const int nv = 5;
    const double(*pa)[3];
    const double *pd;
    double fz_range[2];
    int np = active_set(m, &pa, &pd, fz_range);
    /* Position and velocity references pass through the measurement filter H(s) before
     * they meet the filtered measurements: with the same delay on both sides the
     * feedback terms vanish when the vehicle tracks exactly, instead of pushing on the
     * filter's lag (~2 zeta / wn = 22 ms: 4 cm at 1.5 m/s).  acc_ref is the unfiltered
     * feed-forward: INDI compares it with the filtered acceleration, whose lag the
     * equally filtered actuator feedback cancels. */
    for (i = 0; i < 3; i++) {
        double e_pos = m->filt[F_POS_REF + i][0] - m->filt[F_POS + i][0];
        v_c[i] = block(&m->blk[BLK_POS][i], m->K_pos_A[i], m->K_pos_B[i], m->K_pos_C[i],
                       m->K_pos_D[i], e_pos) + m->filt[F_VEL_REF + i][0];
        m->acc_c[i] = block(&m->blk[BLK_VEL][i], m->K_vel_A[i], m->K_vel_B[i], m->K_vel_C[i],
                            m->K_vel_D[i], v_c[i] - m->filt[F_VEL + i][0]) + m->acc_ref[i];
        dacc[i] = m->acc_c[i] - m->filt[F_ACC + i][0];
    }
    attitude_jacobian(s->mu_m, r, drp, drt);
    /* eq. (20)-(21) */
    m3_mul_v(r, s->f_b_m, rf);
    for (i = 0; i < 3; i++) f_w_ref[i] = m->mass * dacc[i] + rf[i];
    for (i = 0; i < 3; i++) m->f_b_ref[i] = r[i] * f_w_ref[0] + r[3 + i] * f_w_ref[1] +
                                            r[6 + i] * f_w_ref[2];
    /* G = d(R f_b)/d[f_b, phi, theta] at the filtered measurement (eq. 14) */
    {
        double gp[3], gt[3];
        m3_mul_v(drp, s->f_b_m, gp);
        m3_mul_v(drt, s->f_b_m, gt);
        for (i = 0; i < 3; i++) {
            for (j = 0; j < 3; j++) g_mat[i][j] = r[3 * i + j];
            g_mat[i][3] = gp[i];
            g_mat[i][4] = gt[i];
        }
    }
    /* eq. (19): A = [sqrt(gamma) W_v G; W_u], b = [sqrt(gamma) W_v m dacc; W_u du_p] */
    w->n_rows = 8;
    for (i = 0; i < 3; i++) {
        for (j = 0; j < nv; j++) w->A[i * nv + j] = sg * m->W_v[i] * g_mat[i][j];
        w->b[i] = sg * m->W_v[i] * m->mass * dacc[i];
    }
    /* du_p: the increment to the reference pose, i.e. to mu_ref and to the body force
     * f_p = R_ref^T f_w_ref that mu_ref needs.  With du_p's force part at zero ("no force
     * increment") the force and attitude terms trade off and mu_c lags mu_ref by a
     * fraction of the tracking error even when mu_ref is feasible; with f_p both terms
     * vanish together, so mu_c = mu_ref up to second-order linearization error. */
    {
        double q[4], rr[3][3];
        quat_from_euler(m->euler_ref, q);
        rot_from_quat(q, rr);
        for (i = 0; i < 3; i++) {
            double f_p = rr[0][i] * f_w_ref[0] + rr[1][i] * f_w_ref[1] + rr[2][i] * f_w_ref[2];
            w->b[3 + i] = m->W_u[i] * (f_p - s->f_b_m[i]);
        }
    }
    for (i = 0; i < nv; i++)
        for (j = 0; j < nv; j++) w->A[(3 + i) * nv + j] = (i == j) ? m->W_u[i] : 0.0;
    w->b[6] = m->W_u[3] * wrap_pi(m->euler_ref[0] - s->mu_m[0]);
    w->b[7] = m->W_u[4] * (m->euler_ref[1] - s->mu_m[1]);
    for (i = 0; i < 3; i++) {
        w->lb[i] = -INFINITY;
        w->ub[i] = INFINITY;
    }
    for (i = 0; i < 2; i++) {
        w->lb[3 + i] = m->euler_min[i] - s->mu_m[i];
        w->ub[3 + i] = m->euler_max[i] - s->mu_m[i];
    }
    if (m->force_constraint == 0) {
        /* joint: A_poly (f_b_m + df) <= b_poly */
        for (k = 0; k < np; k++, n_cons++) {
            for (j = 0; j < nv; j++) w->C[n_cons * nv + j] = j < 3 ? pa[k][j] : 0.0;
            w->d[n_cons] = pd[k] - v3_dot(pa[k], s->f_b_m);
        }
    } else {
        /* paper eq. (22)-(23): slice at f_bz_ref (clamped into the polytope's z range) */
        double fz = fmin(fmax(m->f_b_ref[2], fz_range[0]), fz_range[1]);
        for (k = 0; k < np; k++) {
            double ax = pa[k][0], ay = pa[k][1];
            if (ax * ax + ay * ay < 1e-18) continue;
            for (j = 0; j < nv; j++) w->C[n_cons * nv + j] = 0.0;
            w->C[n_cons * nv] = ax;
            w->C[n_cons * nv + 1] = ay;
            w->d[n_cons] = pd[k] - pa[k][2] * fz - ax * s->f_b_m[0] -
                           ay * s->f_b_m[1];
            n_cons++;
        }
        w->lb[2] = fz_range[0] - s->f_b_m[2];
        w->ub[2] = fz_range[1] - s->f_b_m[2];
    }
    w->n_cons = n_cons;
    t0 = m->timing ? fp_clock_seconds() : 0.0;
    fp_wls_solve(w, m->qp_max_iter, &res);
    if (m->timing) m->t_guid = fp_clock_seconds() - t0;
    m->guid_status = (int32_t)res.status;
    m->guid_iter = res.iterations;
    for (i = 0; i < 3; i++) df_c[i] = w->x[i];
    mu_c[0] = s->mu_m[0] + w->x[3];
    mu_c[1] = s->mu_m[1] + w->x[4];
    mu_c[2] = m->euler_ref[2];
    for (k = 0; k < n_cons; k++) {
        double v = -w->d[k];
        for (j = 0; j < nv; j++) v += w->C[k * nv + j] * w->x[j];
        if (v > -1e-9 * (1.0 + fabs(w->d[k]))) flags |= 1;
    }
    if (w->x[3] <= w->lb[3] + 1e-12 || w->x[3] >= w->ub[3] - 1e-12) flags |= 2;
    if (w->x[4] <= w->lb[4] + 1e-12 || w->x[4] >= w->ub[4] - 1e-12) flags |= 4;
    m->guid_flags = flags;
    /* eq. (7): is the reference pose feasible?  R_ref^T f_w_ref in S(0) */
    {
        double q[4], rr[3][3], fb[3];
        int inside = 1;
        quat_from_euler(m->euler_ref, q);
        rot_from_quat(q, rr);
        for (i = 0; i < 3; i++) fb[i] = rr[0][i] * f_w_ref[0] + rr[1][i] * f_w_ref[1] +
                                        rr[2][i] * f_w_ref[2];
        for (k = 0; k < np; k++) /* 1 uN of slack: flat sets (quadrotor) have b = 0 facets */
            if (v3_dot(pa[k], fb) > pd[k] + 1e-6 * (1.0 + fabs(pd[k]))) inside = 0;
        m->feasible = inside;
    }
    for (i = 0; i < 3; i++) m->f_b_c[i] = s->f_b_m[i] + df_c[i];
}

/* Stabilization: blocks, then INDI on the rotational dynamics. */
static void stabilization(ControllerModel *m, const Measured *s, const double mu_c[3],
                          double dtau_c[3]) {
    double e[3], mu_dot_c[3], dw[3];
    double cp = cos(s->mu_m[0]), sp = sin(s->mu_m[0]);
    double ct = cos(s->mu_m[1]), st = sin(s->mu_m[1]);
    int i;
    /* As for position: the attitude error is taken against the reference delayed by
     * H(s) like the measurement, plus the guidance's departure mu_c - mu_ref. */
    for (i = 0; i < 3; i++)
        e[i] = wrap_pi(mu_c[i] - m->euler_ref[i]) +
               wrap_pi(m->filt[F_EULER_REF + i][0] - s->mu_m[i]);
    for (i = 0; i < 3; i++)
        mu_dot_c[i] = block(&m->blk[BLK_ATT][i], m->K_att_A[i], m->K_att_B[i], m->K_att_C[i],
                            m->K_att_D[i], e[i]) + m->euler_rate_ref[i];
    /* the heading rate is limited to what the yaw authority can follow */
    mu_dot_c[2] = fmin(fmax(mu_dot_c[2], -m->yaw_rate_max), m->yaw_rate_max);
    /* Euler rates to body rates at the measured attitude */
    m->rate_c[0] = mu_dot_c[0] - st * mu_dot_c[2];
    m->rate_c[1] = cp * mu_dot_c[1] + sp * ct * mu_dot_c[2];
    m->rate_c[2] = -sp * mu_dot_c[1] + cp * ct * mu_dot_c[2];
    for (i = 0; i < 3; i++)
        dw[i] = block(&m->blk[BLK_RATE][i], m->K_rate_A[i], m->K_rate_B[i], m->K_rate_C[i],
                      m->K_rate_D[i], m->rate_c[i] - s->rate_m[i]) - s->ang_acc_m[i];
    m3_mul_v(&m->inertia[0][0], dw, dtau_c);
}

/* Preferred configuration for the rotors still working: the minimum-norm split over
 * them; lost rotors get their current state (they are fixed in the QP anyway). */
static void preferred_without_lost(const ControllerModel *m, const double wrench[6],
                                   double a_pref[], double b_pref[], double w_pref[]) {
    FpRotorSet rs;
    double a[FP_MAX_ROTORS], b[FP_MAX_ROTORS], w[FP_MAX_ROTORS];
    int map[FP_MAX_ROTORS], i, n = 0;
    if (m->lost_mask == 0) {
        fp_preferred_config(&m->rotors, wrench, a_pref, b_pref, w_pref, NULL, 0);
        return;
    }
    rs = m->rotors;
    for (i = 0; i < m->n_rotors; i++) {
        a_pref[i] = m->filt[F_ALPHA + i][0];
        b_pref[i] = m->filt[F_BETA + i][0];
        w_pref[i] = m->omega_min;
        if ((m->lost_mask >> i) & 1) continue;
        map[n] = i;
        memcpy(rs.pos[n], m->rotors.pos[i], sizeof rs.pos[n]);
        rs.dir[n] = m->rotors.dir[i];
        rs.gamma[n] = m->rotors.gamma[i];
        rs.alpha_min[n] = m->rotors.alpha_min[i], rs.alpha_max[n] = m->rotors.alpha_max[i];
        rs.beta_min[n] = m->rotors.beta_min[i], rs.beta_max[n] = m->rotors.beta_max[i];
        n++;
    }
    if (n == 0) return;
    rs.n = n;
    fp_preferred_config(&rs, wrench, a, b, w, NULL, 0);
    for (i = 0; i < n; i++) {
        a_pref[map[i]] = a[i];
        b_pref[map[i]] = b[i];
        w_pref[map[i]] = w[i];
    }
}

/* Inner allocation: WLS on B''(u_a,m) with bounds, torque priority and a
 * preferred configuration (min-norm split of the commanded wrench). */
static void allocation(ControllerModel *m, const Measured *s, const double dnu[6],
                       double a_cmd[], double b_cmd[], double w_cmd[]) {
    FpWls *w = &m->alloc;
    FpWlsResult res;
    double b2p[6 * 3 * FP_MAX_ROTORS], nu_target[6];
    double a_pref[FP_MAX_ROTORS], b_pref[FP_MAX_ROTORS], w_pref[FP_MAX_ROTORS];
    double lo[3], hi[3], um[3], pref[3], scale[3], t0;
    int i, j, k, n = m->n_rotors, nv = 3 * n, flags = 0;
    fp_effectiveness_b2prime(&m->rotors, s->a_m, s->b_m, s->w_m, b2p);
    for (i = 0; i < 6; i++) /* a rotor's effectiveness scales with its known efficiency */
        for (j = 0; j < nv; j++) b2p[i * nv + j] *= s->eff[j / 3];
    for (i = 0; i < 3; i++) {
        nu_target[i] = s->f_b_m[i] + dnu[i];
        nu_target[3 + i] = s->tau_b_m[i] + dnu[3 + i];
    }
    /* an infeasible split still gives a usable preference once clamped below */
    preferred_without_lost(m, nu_target, a_pref, b_pref, w_pref);
    w->n_rows = 6 + nv;
    for (i = 0; i < 6; i++) {
        for (j = 0; j < nv; j++) w->A[i * nv + j] = m->W_nu[i] * b2p[i * nv + j];
        w->b[i] = m->W_nu[i] * dnu[i];
    }
    scale[0] = scale[1] = m->w_pref;
    scale[2] = m->w_pref * m->pref_omega_scale;
    for (i = 0; i < n; i++) {
        lo[0] = m->alpha_min[i], hi[0] = m->alpha_max[i], um[0] = s->a_m[i];
        lo[1] = m->beta_min[i], hi[1] = m->beta_max[i], um[1] = s->b_m[i];
        lo[2] = m->omega_min, hi[2] = m->omega_max, um[2] = s->w_m[i];
        pref[0] = a_pref[i], pref[1] = b_pref[i], pref[2] = w_pref[i];
        if ((m->lost_mask >> i) & 1) { /* a lost rotor: servos held, motor stopped */
            lo[0] = hi[0] = pref[0] = um[0];
            lo[1] = hi[1] = pref[1] = um[1];
            lo[2] = hi[2] = pref[2] = m->omega_min;
        }
        for (k = 0; k < 3; k++) {
            int col = 3 * i + k, row = 6 + col;
            for (j = 0; j < nv; j++) w->A[row * nv + j] = (j == col) ? scale[k] : 0.0;
            w->b[row] = scale[k] * (fmin(fmax(pref[k], lo[k]), hi[k]) - um[k]);
            w->lb[col] = lo[k] - um[k];
            w->ub[col] = hi[k] - um[k];
        }
    }
    t0 = m->timing ? fp_clock_seconds() : 0.0;
    fp_wls_solve(w, m->qp_max_iter, &res);
    if (m->timing) m->t_alloc = fp_clock_seconds() - t0;
    m->alloc_status = (int32_t)res.status;
    m->alloc_iter = res.iterations;
    for (i = 0; i < 6; i++) {
        double v = -dnu[i];
        for (j = 0; j < nv; j++) v += b2p[i * nv + j] * w->x[j];
        m->alloc_residual[i] = v;
    }
    for (i = 0; i < FP_MAX_ROTORS; i++) {
        if (i >= n) {
            a_cmd[i] = b_cmd[i] = w_cmd[i] = 0.0;
            continue;
        }
        a_cmd[i] = fmin(fmax(s->a_m[i] + w->x[3 * i], m->alpha_min[i]), m->alpha_max[i]);
        b_cmd[i] = fmin(fmax(s->b_m[i] + w->x[3 * i + 1], m->beta_min[i]), m->beta_max[i]);
        w_cmd[i] = fmin(fmax(s->w_m[i] + w->x[3 * i + 2], m->omega_min), m->omega_max);
        if ((m->lost_mask >> i) & 1) continue; /* a stopped dead rotor is not saturated */
        if (m->alpha_max[i] > m->alpha_min[i] &&
            (a_cmd[i] <= m->alpha_min[i] + 1e-9 || a_cmd[i] >= m->alpha_max[i] - 1e-9))
            flags |= 1 << (8 + i);
        if (m->beta_max[i] > m->beta_min[i] &&
            (b_cmd[i] <= m->beta_min[i] + 1e-9 || b_cmd[i] >= m->beta_max[i] - 1e-9))
            flags |= 1 << (16 + i);
        if (w_cmd[i] <= m->omega_min + 1e-9 || w_cmd[i] >= m->omega_max - 1e-9) flags |= 1 << i;
    }
    m->sat_flags = flags;
}

static int all_finite(const double *v, int n) {
    int i;
    for (i = 0; i < n; i++)
        if (!isfinite(v[i])) return 0;
    return 1;
}

/* Rotors below half efficiency are lost: pick the feasible-force set that goes with
 * the losses and say so once per change. */
static void update_rotor_losses(ControllerModel *m, const FpLogger *logger) {
    int32_t mask = 0;
    int i, count = 0, lost = -1;
    for (i = 0; i < m->n_rotors; i++)
        if (m->rotor_health[i] < 0.5) {
            mask |= (int32_t)1 << i;
            count++;
            lost = i;
        }
    if (mask == m->lost_mask) return;
    m->lost_mask = mask;
    m->rotors_lost = count;
    fp_wls_reset(&m->guid); /* the facets change: the old working set means nothing */
    if (count == 0) {
        m->active_polytope = 0;
        m->hover_possible = m->hover_ok[0];
        fp_log(logger, FP_WARNING, FP_LOG_WARNING, "all rotors healthy: nominal force set");
    } else if (count == 1 && m->fail_poly_n[lost] > 0) {
        m->active_polytope = lost + 1;
        m->hover_possible = m->hover_ok[lost + 1];
        fp_log(logger, FP_WARNING, FP_LOG_WARNING,
               "rotor %d lost: allocations exclude it, guidance uses its feasible force set%s",
               lost + 1, m->hover_possible ? "" : " (which cannot hold hover)");
    } else {
        m->active_polytope = -1;
        m->hover_possible = 0;
        fp_log(logger, FP_WARNING, FP_LOG_WARNING,
               "%d rotors lost (mask 0x%x): no feasible force set for this loss, hovering may "
               "be impossible; flying on with the remaining rotors",
               count, (unsigned)mask);
    }
}

/* One sample of the controller.  FP_WARNING: an input was not finite and the
 * last valid command is held (nothing else changes). */
static FpStatus control_sample(ControllerModel *m, const FpLogger *logger) {
    static const char *const names[] = {"pos_ref", "euler_ref", "vel_ref", "acc_ref",
                                        "euler_rate_ref", "pos", "vel", "acc", "euler", "rate",
                                        "omega", "alpha", "beta", "rotor_health"};
    const double *inputs[14];
    int counts[14] = {3, 3, 3, 3, 3, 3, 3, 3, 3, 3, 0, 0, 0, 0};
    Measured s;
    double df_c[3], mu_c[3], dtau[3], a_cmd[FP_MAX_ROTORS], b_cmd[FP_MAX_ROTORS];
    double w_cmd[FP_MAX_ROTORS], psi, t_start = m->timing ? fp_clock_seconds() : 0.0;
    int i, k, n = m->n_rotors;
    inputs[0] = m->pos_ref, inputs[1] = m->euler_ref, inputs[2] = m->vel_ref;
    inputs[3] = m->acc_ref, inputs[4] = m->euler_rate_ref, inputs[5] = m->pos;
    inputs[6] = m->vel, inputs[7] = m->acc, inputs[8] = m->euler, inputs[9] = m->rate;
    inputs[10] = m->omega, inputs[11] = m->alpha, inputs[12] = m->beta;
    inputs[13] = m->rotor_health;
    counts[10] = counts[11] = counts[12] = counts[13] = n;
    for (k = 0; k < 14; k++)
        for (i = 0; i < counts[k]; i++)
            if (!isfinite(inputs[k][i])) {
                fp_log(logger, FP_WARNING, FP_LOG_WARNING,
                       "input %s[%d] = %g is not finite: holding the last valid command",
                       names[k], i + 1, inputs[k][i]);
                return FP_WARNING;
            }
    for (i = 0; i < n; i++)
        if (m->rotor_health[i] < 0.0 || m->rotor_health[i] > 1.0) {
            fp_log(logger, FP_WARNING, FP_LOG_WARNING,
                   "input rotor_health[%d] = %g is outside [0, 1]: holding the last valid command",
                   i + 1, m->rotor_health[i]);
            return FP_WARNING;
        }
    update_rotor_losses(m, logger);
    /* 1. filters (heading unwrapped first so that +-pi crossings filter smoothly) */
    psi = m->psi_unwrapped + wrap_pi(m->euler[2] - m->psi_raw);
    m->psi_raw = m->euler[2];
    m->psi_unwrapped = psi;
    for (i = 0; i < 3; i++) {
        filter_update(m, m->filt[F_POS + i], m->pos[i]);
        filter_update(m, m->filt[F_VEL + i], m->vel[i]);
        filter_update(m, m->filt[F_ACC + i], m->acc[i]);
        filter_update(m, m->filt[F_EULER + i], i == 2 ? psi : m->euler[i]);
        filter_update(m, m->filt[F_RATE + i], m->rate[i]);
        filter_update(m, m->filt[F_POS_REF + i], m->pos_ref[i]);
        filter_update(m, m->filt[F_VEL_REF + i], m->vel_ref[i]);
    }
    {
        double psi_ref = m->psi_ref_unwrapped + wrap_pi(m->euler_ref[2] - m->psi_ref_raw);
        m->psi_ref_raw = m->euler_ref[2];
        m->psi_ref_unwrapped = psi_ref;
        filter_update(m, m->filt[F_EULER_REF], m->euler_ref[0]);
        filter_update(m, m->filt[F_EULER_REF + 1], m->euler_ref[1]);
        filter_update(m, m->filt[F_EULER_REF + 2], psi_ref);
    }
    for (i = 0; i < n; i++) {
        filter_update(m, m->filt[F_OMEGA + i], m->omega[i]);
        filter_update(m, m->filt[F_ALPHA + i], m->alpha[i]);
        filter_update(m, m->filt[F_BETA + i], m->beta[i]);
    }
    read_filters(m, &s);
    /* 2.-4. */
    guidance(m, &s, df_c, mu_c);
    stabilization(m, &s, mu_c, dtau);
    for (i = 0; i < 3; i++) {
        m->dnu_c[i] = df_c[i];
        m->dnu_c[3 + i] = dtau[i];
    }
    allocation(m, &s, m->dnu_c, a_cmd, b_cmd, w_cmd);
    if (!all_finite(a_cmd, n) || !all_finite(b_cmd, n) || !all_finite(w_cmd, n) ||
        !all_finite(mu_c, 3)) {
        fp_log(logger, FP_WARNING, FP_LOG_WARNING,
               "non-finite actuator command computed: holding the last valid command");
        return FP_WARNING;
    }
    for (i = 0; i < 3; i++) m->mu_c[i] = wrap_pi(mu_c[i]);
    memcpy(m->omega_cmd, w_cmd, sizeof w_cmd);
    memcpy(m->alpha_cmd, a_cmd, sizeof a_cmd);
    memcpy(m->beta_cmd, b_cmd, sizeof b_cmd);
    if (m->timing) m->t_step = fp_clock_seconds() - t_start;
    return FP_OK;
}

/* ------------------------------------------------------------------------ */
/* Model callbacks                                                          */

static FpStatus controller_initialize(void *model, double t0, const FpLogger *logger) {
    ControllerModel *m = (ControllerModel *)model;
    int i, n;
    (void)t0;
    if (validate(m, logger) != 0) return FP_ERROR;
    n = m->n_rotors;
    FP_MODEL_TO_ROTOR_SET(m, &m->rotors);
    discretize_filter(m);
    /* filters start in steady state at the initial measurements */
    memset(m->filt, 0, sizeof m->filt);
    memset(m->blk, 0, sizeof m->blk);
    m->psi_raw = m->psi_unwrapped = isfinite(m->euler[2]) ? m->euler[2] : 0.0;
    m->psi_ref_raw = m->psi_ref_unwrapped = isfinite(m->euler_ref[2]) ? m->euler_ref[2] : 0.0;
    for (i = 0; i < 3; i++) {
        m->filt[F_POS + i][0] = m->pos[i];
        m->filt[F_VEL + i][0] = m->vel[i];
        m->filt[F_ACC + i][0] = m->acc[i];
        m->filt[F_EULER + i][0] = m->euler[i];
        m->filt[F_RATE + i][0] = m->rate[i];
        m->filt[F_POS_REF + i][0] = m->pos_ref[i];
        m->filt[F_VEL_REF + i][0] = m->vel_ref[i];
        m->filt[F_EULER_REF + i][0] = m->euler_ref[i];
        m->mu_c[i] = m->euler_ref[i];
    }
    for (i = 0; i < n; i++) {
        m->filt[F_OMEGA + i][0] = m->omega[i];
        m->filt[F_ALPHA + i][0] = m->alpha[i];
        m->filt[F_BETA + i][0] = m->beta[i];
    }
    for (i = 0; i < CTRL_N_FILTERS; i++)
        if (!isfinite(m->filt[i][0])) {
            fp_log(logger, FP_ERROR, FP_LOG_ERROR,
                   "initial measurements must be finite (filter slot %d)", i + 1);
            return FP_ERROR;
        }
    if (fp_wls_setup(&m->guid, 5, 8, m->poly_n) != FP_OK ||
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
    for (i = 0; i < n; i++)
        if (!isfinite(m->rotor_health[i]) || m->rotor_health[i] < 0.0 ||
            m->rotor_health[i] > 1.0) {
            fp_log(logger, FP_ERROR, FP_LOG_ERROR,
                   "input rotor_health[%d] = %g: must be in [0, 1]", i + 1, m->rotor_health[i]);
            return FP_ERROR;
        }
    update_rotor_losses(m, logger);
    return FP_OK;
}

static FpStatus controller_tunables_changed(void *model, const FpLogger *logger) {
    ControllerModel *m = (ControllerModel *)model;
    Check c;
    c.logger = logger;
    c.errors = 0;
    check_tunables(m, &c);
    return c.errors ? FP_ERROR : FP_OK;
}

static FpStatus controller_step(void *model, double t, double h, const FpLogger *logger) {
    ControllerModel *m = (ControllerModel *)model;
    double ratio = h / m->Ts, samples = floor(ratio + 0.5);
    FpStatus status = FP_OK;
    long k, n;
    (void)t;
    if (samples < 1.0 || fabs(ratio - samples) > 1e-9 * samples) {
        fp_log(logger, FP_ERROR, FP_LOG_ERROR,
               "communication step %.12g s is not a whole multiple of the sample time Ts = "
               "%.12g s",
               h, m->Ts);
        return FP_ERROR;
    }
    if (samples > 1e7) {
        fp_log(logger, FP_ERROR, FP_LOG_ERROR,
               "communication step %.12g s would take %.0f samples (limit 1e7)", h, samples);
        return FP_ERROR;
    }
    n = (long)samples;
    for (k = 0; k < n; k++)
        if (control_sample(m, logger) != FP_OK) status = FP_WARNING;
    return status;
}

static int wls_valid(const FpWls *w) {
    return w->n_vars >= 0 && w->n_vars <= FP_WLS_MAX_VARS && w->n_rows >= 0 &&
           w->n_rows <= FP_WLS_MAX_ROWS && w->n_cons >= 0 && w->n_cons <= FP_WLS_MAX_CONS;
}

static int controller_state_valid(const void *model) {
    const ControllerModel *m = (const ControllerModel *)model;
    int i;
    if (m->n_rotors < 1 || m->n_rotors > FP_MAX_ROTORS || m->rotors.n < 0 ||
        m->rotors.n > FP_MAX_ROTORS || m->poly_n < 0 || m->poly_n > FP_POLYTOPE_MAX_FACETS ||
        m->active_polytope < -1 || m->active_polytope > FP_MAX_ROTORS ||
        !wls_valid(&m->guid) || !wls_valid(&m->alloc))
        return 0;
    for (i = 0; i < FP_MAX_ROTORS; i++)
        if (m->fail_poly_n[i] < 0 || m->fail_poly_n[i] > FP_FAIL_POLYTOPE_FACETS) return 0;
    return 1;
}

static const FpModelInfo controller_info = {
    "FullPoseController",
    "Full-pose controller for multirotors: robust INDI cascade with first-order blocks, WLS "
    "guidance allocation over the feasible-force polytope and WLS inner allocation "
    "(Hachem et al., section III)",
    sizeof(ControllerModel),
    controller_vars,
    sizeof controller_vars / sizeof controller_vars[0],
    0.002,
    10.0,
    controller_set_defaults,
    controller_initialize,
    controller_step,
    controller_tunables_changed,
    controller_state_valid,
};

const FpModelInfo *controller_model_info(void) { return &controller_info; }
