#include "plant.h"

#include <math.h>
#include <stddef.h>
#include <string.h>

#include "fp_clock.h"
#include "fp_math.h"
#include "fp_params.h"
#include "plant_vars.h"

#define PI 3.14159265358979323846

/* The variable table: each row must name a PlantModel member of matching size. */
#define ELEM_SIZE_REAL sizeof(double)
#define ELEM_SIZE_INTEGER sizeof(int32_t)
#define ELEM_SIZE_BOOLEAN sizeof(int32_t)
/* ... and a declared type exactly when it is a Real. */
#define PLANT_CHECK(name, vr, type, kind, rows, cols, dtype, range, desc)                        \
    FP_STATIC_ASSERT(sizeof(((PlantModel *)0)->name) == (rows) * (cols) * ELEM_SIZE_##type,     \
                     name##_size);                                                              \
    FP_STATIC_ASSERT((FP_##type == FP_REAL) == (FP_T_##dtype != FP_T_NONE), name##_dtype);
#define PLANT_AF_CHECK(name, vr, type, kind, rows, cols, dtype, range, desc)                     \
    FP_STATIC_ASSERT(sizeof(((FpAirframe *)0)->name) == (rows) * (cols) * ELEM_SIZE_##type,     \
                     name##_size);                                                              \
    FP_STATIC_ASSERT((FP_##type == FP_REAL) == (FP_T_##dtype != FP_T_NONE), name##_dtype);
/* ... and a Model Exchange row is a Real part of its vector member. */
#define PLANT_XS_CHECK(name, vr, type, kind, rows, cols, dtype, range, desc, member, first)      \
    FP_STATIC_ASSERT(FP_##type == FP_REAL && FP_T_##dtype != FP_T_NONE, name##_real);           \
    FP_STATIC_ASSERT(((first) + (rows) * (cols)) * sizeof(double) <=                              \
                         sizeof(((PlantModel *)0)->member),                                      \
                     name##_within);
PLANT_VARIABLES(PLANT_CHECK, PLANT_AF_CHECK, PLANT_XS_CHECK)
/* The state rows cover x (their order is checked by tools/mdgen.c). */
#define PLANT_NO_ROW(...)
#define PLANT_XS_COUNT_STATE(rows, cols) +(rows) * (cols)
#define PLANT_XS_COUNT_DERIVATIVE(rows, cols)
#define PLANT_XS_COUNT(name, vr, type, kind, rows, cols, dtype, range, desc, member, first)      \
    PLANT_XS_COUNT_##kind(rows, cols)
FP_STATIC_ASSERT(0 PLANT_VARIABLES(PLANT_NO_ROW, PLANT_NO_ROW, PLANT_XS_COUNT) == PLANT_NX,
                 state_rows_cover_x);

#define PLANT_ROW(name, vr, type, kind, rows, cols, dtype, range, desc)                          \
    {#name, vr, FP_##type, FP_##kind, rows, cols, offsetof(PlantModel, name), FP_T_##dtype, range, \
     desc},
#define PLANT_AF_ROW(name, vr, type, kind, rows, cols, dtype, range, desc)                       \
    {#name, vr, FP_##type, FP_##kind, rows, cols,                                                 \
     offsetof(PlantModel, af) + offsetof(FpAirframe, name), FP_T_##dtype, range, desc},
#define PLANT_XS_ROW(name, vr, type, kind, rows, cols, dtype, range, desc, member, first)        \
    {#name, vr, FP_##type, FP_##kind, rows, cols,                                                 \
     offsetof(PlantModel, member) + (size_t)(first) * sizeof(double), FP_T_##dtype, range, desc},
static const FpVar plant_vars[] = {PLANT_VARIABLES(PLANT_ROW, PLANT_AF_ROW, PLANT_XS_ROW)};
#define N_PLANT_VARS (sizeof plant_vars / sizeof plant_vars[0])

/* Row indices (PV_mass, ...): the input checks read their ranges from the rows. */
#define PLANT_INDEX(name, vr, type, kind, rows, cols, dtype, range, desc) PV_##name,
#define PLANT_XS_INDEX(name, vr, type, kind, rows, cols, dtype, range, desc, member, first)      \
    PV_##name,
enum { PLANT_VARIABLES(PLANT_INDEX, PLANT_INDEX, PLANT_XS_INDEX) PV_COUNT };

/* State vector layout (plant.h). */
#define X_POS PLANT_X_POS
#define X_VEL PLANT_X_VEL
#define X_QUAT PLANT_X_QUAT
#define X_RATE PLANT_X_RATE
#define X_OMEGA PLANT_X_OMEGA
#define X_ALPHA PLANT_X_ALPHA
#define X_BETA PLANT_X_BETA

/* ------------------------------------------------------------------------ */
/* Defaults: the paper's tilting hexacopter (Table I).                      */


static void hover_wrench(const PlantModel *m, const double euler[3], double w[6]) {
    double q[4], r[3][3];
    int j;
    quat_from_euler(euler, q);
    rot_from_quat(q, r);
    /* f_b = -R^T (m g e_z): cancel gravity, no torque */
    for (j = 0; j < 3; j++) {
        w[j] = -m->af.mass * m->af.g * r[2][j];
        w[3 + j] = 0.0;
    }
}

void plant_set_defaults(void *model) {
    PlantModel *m = (PlantModel *)model;
    double w[6], zero[3] = {0.0, 0.0, 0.0};
    int i;
    FpRotorSet rs;
    memset(m, 0, sizeof *m);
    fp_paper_hexacopter(&m->af);
    fp_rotor_set_of(&m->af, &rs);
    for (i = 0; i < FP_MAX_ROTORS; i++) m->efficiency[i] = 1.0;
    m->h_internal = 5e-4;
    m->init_trim = 1;
    m->noise_seed = 1;
    /* no landing gear (n_contacts 0): the airframe file gives it (docs/plant.md) */
    m->contact_stiffness = 1e4;
    m->contact_damping = 100.0;
    m->contact_friction = 0.5;
    /* Inputs start at hover trim so the FMU hovers when simulated alone. */
    hover_wrench(m, zero, w);
    if (fp_preferred_config(&rs, w, m->alpha_cmd, m->beta_cmd, m->omega_cmd, NULL, 0) != FP_OK) {
        memset(m->omega_cmd, 0, sizeof m->omega_cmd);
    }
}

/* ------------------------------------------------------------------------ */
/* Noise: xoshiro256** seeded by splitmix64, normal deviates by Box-Muller. */

static uint64_t splitmix64(uint64_t *s) {
    uint64_t z = (*s += 0x9e3779b97f4a7c15ULL);
    z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ULL;
    z = (z ^ (z >> 27)) * 0x94d049bb133111ebULL;
    return z ^ (z >> 31);
}

static uint64_t rotl(uint64_t x, int k) { return (x << k) | (x >> (64 - k)); }

static uint64_t rng_next(uint64_t s[4]) {
    uint64_t result = rotl(s[1] * 5, 7) * 9, t = s[1] << 17;
    s[2] ^= s[0];
    s[3] ^= s[1];
    s[1] ^= s[2];
    s[0] ^= s[3];
    s[2] ^= t;
    s[3] = rotl(s[3], 45);
    return result;
}

static double rng_uniform(uint64_t s[4]) { /* in (0, 1) */
    return ((double)(rng_next(s) >> 11) + 0.5) * (1.0 / 9007199254740992.0);
}

static double rng_normal(uint64_t s[4]) {
    double u1 = rng_uniform(s), u2 = rng_uniform(s);
    return sqrt(-2.0 * log(u1)) * cos(2.0 * PI * u2);
}

static void add_noise(uint64_t s[4], double *v, int n, double sigma) {
    int i;
    if (!(sigma > 0.0)) return;
    for (i = 0; i < n; i++) v[i] += sigma * rng_normal(s);
}

/* ------------------------------------------------------------------------ */
/* Dynamics                                                                 */

typedef struct {
    double omega[FP_MAX_ROTORS], alpha[FP_MAX_ROTORS], beta[FP_MAX_ROTORS];
} Commands;

/* dx = f(x); also returns the rotor wrench and accelerations when asked. */
/* The ground contact's parameters as contact.c takes them. */
static ContactParams contact_params(const PlantModel *m) {
    ContactParams p;
    p.n = m->n_contacts;
    p.pos = &m->contact_pos[0][0];
    p.ground_z = m->ground_z;
    p.stiffness = m->contact_stiffness;
    p.damping = m->contact_damping;
    p.friction = m->contact_friction;
    p.mass = m->af.mass;
    p.inertia_inv = &m->inertia_inv[0][0];
    p.anchor = &m->contact_anchor[0][0];
    p.anchored = m->contact_anchored;
    return p;
}

/* The farthest contact point's distance from the centre of gravity. */
static double contact_reach(const PlantModel *m) {
    double reach = 0.0;
    int i;
    for (i = 0; i < m->n_contacts; i++)
        reach = fmax(reach, sqrt(m->contact_pos[i][0] * m->contact_pos[i][0] +
                                 m->contact_pos[i][1] * m->contact_pos[i][1] +
                                 m->contact_pos[i][2] * m->contact_pos[i][2]));
    return reach;
}

/* A start with a contact point deeper under the ground than one point's spring carries the
 * whole weight at (m g / k) is no pose to start from: the ground would throw the vehicle. */
static int check_start_above_ground(const PlantModel *m, const FpLogger *logger) {
    ContactParams cp = contact_params(m);
    double r[3][3], depth, limit = m->af.mass * fabs(m->af.g) / m->contact_stiffness;
    int i;
    rot_from_quat(m->x + X_QUAT, r);
    i = contact_deepest(&cp, m->x + X_POS, &r[0][0], &depth);
    if (i < 0 || depth <= limit) return 0;
    fp_log(logger, FP_ERROR, FP_LOG_ERROR,
           "parameter pos0 = [%g, %g, %g] m: contact point %d of the landing gear starts %.4g m "
           "below the ground (ground_z = %g m), deeper than the %.4g m at which it alone would "
           "carry the weight; start higher (pos0[3] <= %.4g m puts the gear on the ground) or "
           "set ground_z",
           m->pos0[0], m->pos0[1], m->pos0[2], i + 1, depth, m->ground_z, limit,
           m->pos0[2] - depth);
    return 1;
}

/* Each contact point's depth below the ground at the state (contact_depth, the event
 * indicators of Model Exchange): -1 for the points beyond n_contacts (never crossing). */
static void contact_depth_of(const PlantModel *m, double z[PLANT_MAX_CONTACTS]) {
    int i;
    for (i = 0; i < PLANT_MAX_CONTACTS; i++) z[i] = -1.0;
    if (m->n_contacts > 0) {
        ContactParams cp = contact_params(m);
        double r[3][3];
        rot_from_quat(m->x + X_QUAT, r);
        contact_depths(&cp, m->x + X_POS, &r[0][0], z);
    }
}

/* After an internal step: the contact points' anchors at the new state (contact.h). */
static void update_anchors(PlantModel *m) {
    ContactParams cp;
    double r[3][3];
    if (m->x[X_POS + 2] + m->contact_reach <= m->ground_z) { /* out of reach: none touches */
        m->contact_anchored = 0;
        return;
    }
    cp = contact_params(m);
    rot_from_quat(m->x + X_QUAT, r);
    m->contact_anchored =
        contact_update_anchors(&cp, m->x + X_POS, &r[0][0], &m->contact_anchor[0][0]);
}

/* dx = f(x, u); the rotor wrench (body) into f_b, tau_b and the contact into contact when
 * not NULL. */
static void derivative(const PlantModel *m, const Commands *u, const double *x, double *dx,
                       double f_b[3], double tau_b[3], ContactWrench *contact) {
    const double *q = x + X_QUAT, *w = x + X_RATE;
    double r[3][3], fw[3], iw[3], gyro[3], tau[3], fb[3], tb[3];
    int i, n = m->af.n_rotors;
    ContactWrench cw;
    fp_rotor_wrench(&m->rotors, x + X_ALPHA, x + X_BETA, x + X_OMEGA, m->efficiency, fb, tb);
    rot_from_quat(q, r);
    m3_mul_v(&r[0][0], fb, fw);
    for (i = 0; i < 3; i++) {
        dx[X_POS + i] = x[X_VEL + i];
        dx[X_VEL + i] = (fw[i] + m->f_d[i]) / m->af.mass + m->a_d[i];
    }
    /* (no point can touch while the centre of gravity is higher above the ground than the
     * farthest point reaches: the contact is then not evaluated, as without a ground, and
     * every sum stays as it was, to the bit) */
    if (m->n_contacts > 0 && x[X_POS + 2] + m->contact_reach > m->ground_z) {
        ContactParams cp = contact_params(m);
        contact_wrench(&cp, x + X_POS, x + X_VEL, &r[0][0], w, &cw);
        for (i = 0; i < 3; i++) dx[X_VEL + i] += cw.force_w[i] / m->af.mass;
    } else {
        memset(&cw, 0, sizeof cw);
    }
    dx[X_VEL + 2] += m->af.g;
    dx[X_QUAT + 0] = -0.5 * (q[1] * w[0] + q[2] * w[1] + q[3] * w[2]);
    dx[X_QUAT + 1] = 0.5 * (q[0] * w[0] + q[2] * w[2] - q[3] * w[1]);
    dx[X_QUAT + 2] = 0.5 * (q[0] * w[1] - q[1] * w[2] + q[3] * w[0]);
    dx[X_QUAT + 3] = 0.5 * (q[0] * w[2] + q[1] * w[1] - q[2] * w[0]);
    m3_mul_v(&m->af.inertia[0][0], w, iw);
    v3_cross(w, iw, gyro);
    for (i = 0; i < 3; i++) tau[i] = tb[i] + m->tau_d[i] - gyro[i];
    if (cw.flags != 0)
        for (i = 0; i < 3; i++) tau[i] += cw.torque_b[i];
    m3_mul_v(&m->inertia_inv[0][0], tau, dx + X_RATE);
    for (i = 0; i < FP_MAX_ROTORS; i++) {
        if (i < n) {
            dx[X_OMEGA + i] = (u->omega[i] - x[X_OMEGA + i]) / m->af.tau_motor;
            dx[X_ALPHA + i] = (u->alpha[i] - x[X_ALPHA + i]) / m->af.tau_servo;
            dx[X_BETA + i] = (u->beta[i] - x[X_BETA + i]) / m->af.tau_servo;
        } else {
            dx[X_OMEGA + i] = dx[X_ALPHA + i] = dx[X_BETA + i] = 0.0;
        }
    }
    if (f_b != NULL)
        for (i = 0; i < 3; i++) {
            f_b[i] = fb[i];
            tau_b[i] = tb[i];
        }
    if (contact != NULL) *contact = cw;
}

static void rk4_step(const PlantModel *m, const Commands *u, double *x, double h) {
    double k1[PLANT_NX], k2[PLANT_NX], k3[PLANT_NX], k4[PLANT_NX], xt[PLANT_NX];
    int i;
    derivative(m, u, x, k1, NULL, NULL, NULL);
    for (i = 0; i < PLANT_NX; i++) xt[i] = x[i] + 0.5 * h * k1[i];
    derivative(m, u, xt, k2, NULL, NULL, NULL);
    for (i = 0; i < PLANT_NX; i++) xt[i] = x[i] + 0.5 * h * k2[i];
    derivative(m, u, xt, k3, NULL, NULL, NULL);
    for (i = 0; i < PLANT_NX; i++) xt[i] = x[i] + h * k3[i];
    derivative(m, u, xt, k4, NULL, NULL, NULL);
    for (i = 0; i < PLANT_NX; i++) x[i] += h / 6.0 * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i]);
    quat_normalize(x + X_QUAT);
}

static double clamp(double v, double lo, double hi, int32_t *flags, int bit) {
    if (v < lo) {
        *flags |= (int32_t)1 << bit;
        return lo;
    }
    if (v > hi) {
        *flags |= (int32_t)1 << bit;
        return hi;
    }
    return v;
}

static void saturate(const PlantModel *m, Commands *u, int32_t *flags) {
    int i;
    *flags = 0;
    memset(u, 0, sizeof *u);
    for (i = 0; i < m->af.n_rotors; i++) {
        u->omega[i] = clamp(m->omega_cmd[i], m->af.omega_min, m->af.omega_max, flags,
                            FP_SAT_MOTOR + i);
        u->alpha[i] = clamp(m->alpha_cmd[i], m->af.alpha_min[i], m->af.alpha_max[i], flags,
                            FP_SAT_ALPHA + i);
        u->beta[i] = clamp(m->beta_cmd[i], m->af.beta_min[i], m->af.beta_max[i], flags,
                           FP_SAT_BETA + i);
    }
}

/* ------------------------------------------------------------------------ */
/* Sensor timing                                                            */

static double wrap_angle(double a) { /* to [-pi, pi) */
    return a - 2.0 * PI * floor((a + PI) / (2.0 * PI));
}

/* Keeps the true pose of communication point t (a ring of PLANT_HISTORY points). */
static void history_push(PlantModel *m, double t) {
    int k = m->hist_count == 0 ? 0 : (m->hist_head + 1) % PLANT_HISTORY;
    m->hist_t[k] = t;
    memcpy(m->hist[k], m->pos_true, sizeof m->pos_true);
    memcpy(m->hist[k] + 3, m->vel_true, sizeof m->vel_true);
    memcpy(m->hist[k] + 6, m->euler_true, sizeof m->euler_true);
    m->hist_head = k;
    if (m->hist_count < PLANT_HISTORY) m->hist_count++;
}

/* The true pose at time s into out (linear between kept points, Euler angles the short way;
 * before the first point of the run, the initial pose).  Fails (1) when s lies before the
 * points kept. */
static int pose_at(const PlantModel *m, double s, double out[9]) {
    int k = m->hist_head, j, i;
    if (s >= m->hist_t[k]) {
        memcpy(out, m->hist[k], sizeof m->hist[k]);
        return 0;
    }
    for (j = 1; j < m->hist_count; j++) {
        int prev = (k + PLANT_HISTORY - 1) % PLANT_HISTORY;
        if (s >= m->hist_t[prev]) {
            double w = (s - m->hist_t[prev]) / (m->hist_t[k] - m->hist_t[prev]);
            for (i = 0; i < 9; i++) {
                double d = m->hist[k][i] - m->hist[prev][i];
                out[i] = m->hist[prev][i] + w * (i >= 6 ? wrap_angle(d) : d);
            }
            out[6] = wrap_angle(out[6]);
            out[8] = wrap_angle(out[8]);
            return 0;
        }
        k = prev;
    }
    if (m->hist_count < PLANT_HISTORY) { /* k is the run's first point */
        memcpy(out, m->hist[k], sizeof m->hist[k]);
        return 0;
    }
    return 1;
}

/* The latest instant t0 + k p at or before t (t itself for p = 0: every point). */
static double sample_instant(double t0, double p, double t) {
    if (!(p > 0.0)) return t;
    return t0 + floor((t - t0) / p + 1e-9) * p;
}

/* The outputs of the true state: the derivative at the state and the commands u (der_x), the
 * rotor wrench, the contact, the state as the *_true outputs and the actuators. */
static void true_outputs(PlantModel *m, const Commands *u) {
    int i;
    ContactWrench cw;
    derivative(m, u, m->x, m->der_x, m->f_b, m->tau_b, &cw);
    memcpy(m->contact_force, cw.normal, sizeof m->contact_force);
    m->contact_flags = cw.flags;
    m->landed = m->n_contacts > 0 && cw.flags == (int32_t)((1u << m->n_contacts) - 1u);
    contact_depth_of(m, m->contact_depth);
    for (i = 0; i < 3; i++) {
        m->pos_true[i] = m->x[X_POS + i];
        m->vel_true[i] = m->x[X_VEL + i];
        m->rate_true[i] = m->x[X_RATE + i];
    }
    euler_from_quat(m->x + X_QUAT, m->euler_true);
    memcpy(m->quat_true, m->x + X_QUAT, sizeof m->quat_true);
    if (m->quat_true[0] < 0.0)
        for (i = 0; i < 4; i++) m->quat_true[i] = -m->quat_true[i];
    for (i = 0; i < FP_MAX_ROTORS; i++) {
        int used = i < m->af.n_rotors;
        m->omega[i] = used ? m->x[X_OMEGA + i] : 0.0;
        m->alpha[i] = used ? m->x[X_ALPHA + i] : 0.0;
        m->beta[i] = used ? m->x[X_BETA + i] : 0.0;
    }
}

/* Outputs at communication point t: the true state, and the measurements taken from it.
 * Pose measurements (pos, vel, euler, quat) are sampled every mocap_period and show the state
 * mocap_delay before their sample instant; inertial ones (acc, rate, ang_acc) are sampled at
 * the first communication point at or after each imu_period; both are held in between and
 * their noise is drawn once per sample.  With all three parameters 0 every measurement is the
 * current state plus fresh noise. */
static FpStatus compute_outputs(PlantModel *m, const Commands *u, double t,
                                const FpLogger *logger) {
    const double *dx = m->der_x;
    double s_pose = sample_instant(m->t0, m->mocap_period, t);
    double s_imu = sample_instant(m->t0, m->imu_period, t);
    int pose_due = s_pose > m->mocap_last, imu_due = s_imu > m->imu_last;
    /* (a sample instant on this point up to the round-off of summed steps is this point) */
    int delayed = m->mocap_delay > 0.0 || fabs(s_pose - t) > 1e-9 * m->mocap_period;
    int i;
    true_outputs(m, u);
    history_push(m, t);
    if (pose_due) {
        double p[9];
        if (!delayed) {
            memcpy(p, m->hist[m->hist_head], sizeof p);
        } else if (pose_at(m, s_pose - m->mocap_delay, p)) {
            fp_log(logger, FP_ERROR, FP_LOG_ERROR,
                   "parameter mocap_delay = %g s: at t = %.6g s it reaches back beyond the %d "
                   "communication points the plant keeps (to t = %.6g s); use a longer "
                   "communication step or a shorter delay",
                   m->mocap_delay, t, PLANT_HISTORY,
                   m->hist_t[(m->hist_head + 1) % PLANT_HISTORY]);
            return FP_ERROR;
        }
        memcpy(m->pos, p, sizeof m->pos);
        memcpy(m->vel, p + 3, sizeof m->vel);
        memcpy(m->euler, p + 6, sizeof m->euler);
        m->mocap_last = delayed ? s_pose : t;
    }
    /* (never below 0: a sample instant after t by round-off is t's own) */
    m->pose_age = fmax(0.0, t - m->mocap_last) + m->mocap_delay;
    if (imu_due) {
        for (i = 0; i < 3; i++) {
            m->acc[i] = dx[X_VEL + i];
            m->rate[i] = m->x[X_RATE + i];
            m->ang_acc[i] = dx[X_RATE + i];
        }
        m->imu_last = s_imu;
    }
    /* (one draw order for every setting: the default's, bit for bit) */
    if (pose_due) add_noise(m->rng, m->pos, 3, m->noise_pos);
    if (pose_due) add_noise(m->rng, m->vel, 3, m->noise_vel);
    if (imu_due) add_noise(m->rng, m->acc, 3, m->noise_acc);
    if (pose_due) add_noise(m->rng, m->euler, 3, m->noise_att);
    if (imu_due) add_noise(m->rng, m->rate, 3, m->noise_rate);
    if (imu_due) add_noise(m->rng, m->ang_acc, 3, m->noise_ang_acc);
    if (pose_due) {
        if (m->noise_att > 0.0 || delayed) {
            quat_from_euler(m->euler, m->quat);
            if (m->quat[0] < 0.0)
                for (i = 0; i < 4; i++) m->quat[i] = -m->quat[i];
        } else {
            memcpy(m->quat, m->quat_true, sizeof m->quat);
        }
    }
    return FP_OK;
}

/* ------------------------------------------------------------------------ */
/* Parameter validation (the airframe rules are shared with the controller) */

static int invert3(double a[3][3], double inv[3][3]) {
    double det = a[0][0] * (a[1][1] * a[2][2] - a[1][2] * a[2][1]) -
                 a[0][1] * (a[1][0] * a[2][2] - a[1][2] * a[2][0]) +
                 a[0][2] * (a[1][0] * a[2][1] - a[1][1] * a[2][0]);
    int i, j;
    if (!(fabs(det) > 0.0)) return -1;
    for (i = 0; i < 3; i++)
        for (j = 0; j < 3; j++) {
            int r0 = (j + 1) % 3, r1 = (j + 2) % 3, c0 = (i + 1) % 3, c1 = (i + 2) % 3;
            inv[i][j] = (a[r0][c0] * a[r1][c1] - a[r0][c1] * a[r1][c0]) / det;
        }
    return 0;
}

/* Each initial actuator state within its own range and, when the range is met, within the
 * airframe's limits (which no static range can state). */
static void check_initial_actuator(FpCheck *c, const char *name, const double *v, int n,
                                   const double *lo, const double *hi, int per_rotor,
                                   const char *why) {
    const FpVar *row = fp_check_row(c, name);
    int i;
    fp_need_param(c, name, v, n, NULL);
    for (i = 0; i < n && row != NULL; i++) {
        double a = per_rotor ? lo[i] : lo[0], b = per_rotor ? hi[i] : hi[0];
        if (!isfinite(v[i]) || !fp_range_contains(&row->range, v[i])) continue; /* reported */
        if (v[i] < a || v[i] > b) fp_check_bad(c, name, i + 1, 0, v[i], why);
    }
}

/* The contact's fastest mode within RK4's stability at h_internal (contact.h); needs the
 * inertia's inverse, so it runs with valid airframe numbers only. */
static int check_contact_rate(const PlantModel *m, const FpLogger *logger) {
    ContactParams cp = contact_params(m);
    double inertia[3][3], inertia_inv[3][3], rate;
    memcpy(inertia, m->af.inertia, sizeof inertia);
    if (invert3(inertia, inertia_inv) != 0) return 0; /* (reported by initialization) */
    cp.inertia_inv = &inertia_inv[0][0];
    rate = contact_fastest_rate(&cp);
    if (rate * m->h_internal <= PLANT_CONTACT_RATE_STEP) return 0;
    fp_log(logger, FP_ERROR, FP_LOG_ERROR,
           "parameters contact_stiffness = %g N/m and contact_damping = %g N.s/m: the stiffest "
           "contact mode of the %ld points (rate up to %.4g 1/s) is too fast "
           "for RK4 at h_internal = %g s (rate x h_internal = %.3g, at most %g); lower them or "
           "h_internal",
           m->contact_stiffness, m->contact_damping, (long)m->n_contacts, rate, m->h_internal,
           rate * m->h_internal, PLANT_CONTACT_RATE_STEP);
    return 1;
}

static int validate(const PlantModel *m, const FpLogger *logger) {
    FpCheck c;
    int n = m->af.n_rotors;
    fp_check_init(&c, logger, plant_vars, N_PLANT_VARS);
    if (fp_check_airframe(&c, &m->af) != FP_OK) return c.errors;
    fp_need_param(&c, "h_internal", &m->h_internal, 1, NULL);
    fp_need_param(&c, "pos0", m->pos0, 3, NULL);
    fp_need_param(&c, "vel0", m->vel0, 3, NULL);
    fp_need_param(&c, "euler0", m->euler0, 3, NULL);
    fp_need_param(&c, "rate0", m->rate0, 3, NULL);
    if (!m->init_trim) { /* ignored with init_trim, so not checked then */
        check_initial_actuator(&c, "omega0", m->omega0, n, &m->af.omega_min, &m->af.omega_max, 0,
                               "outside [omega_min, omega_max]");
        check_initial_actuator(&c, "alpha0", m->alpha0, n, m->af.alpha_min, m->af.alpha_max, 1,
                               "outside [alpha_min, alpha_max]");
        check_initial_actuator(&c, "beta0", m->beta0, n, m->af.beta_min, m->af.beta_max, 1,
                               "outside [beta_min, beta_max]");
    }
    fp_need_param(&c, "noise_pos", &m->noise_pos, 1, NULL);
    fp_need_param(&c, "noise_vel", &m->noise_vel, 1, NULL);
    fp_need_param(&c, "noise_acc", &m->noise_acc, 1, NULL);
    fp_need_param(&c, "noise_att", &m->noise_att, 1, NULL);
    fp_need_param(&c, "noise_rate", &m->noise_rate, 1, NULL);
    fp_need_param(&c, "noise_ang_acc", &m->noise_ang_acc, 1, NULL);
    fp_need_param(&c, "mocap_period", &m->mocap_period, 1, NULL);
    fp_need_param(&c, "mocap_delay", &m->mocap_delay, 1, NULL);
    fp_need_param(&c, "imu_period", &m->imu_period, 1, NULL);
    fp_need_int_param(&c, "n_contacts", &m->n_contacts, 1);
    if (c.errors != 0) return c.errors; /* (contact_pos is read to n_contacts) */
    fp_need_param(&c, "ground_z", &m->ground_z, 1, NULL);
    fp_need_param(&c, "contact_stiffness", &m->contact_stiffness, 1, NULL);
    fp_need_param(&c, "contact_damping", &m->contact_damping, 1, NULL);
    fp_need_param(&c, "contact_friction", &m->contact_friction, 1, NULL);
    fp_need_param(&c, "contact_pos", &m->contact_pos[0][0], 3 * m->n_contacts, NULL);
    if (c.errors == 0 && m->n_contacts > 0 && check_contact_rate(m, logger) != 0) c.errors++;
    if (c.errors == 0 && m->h_internal > 0.2 * fmin(m->af.tau_motor, m->af.tau_servo))
        fp_check_warning(&c,
                         "parameter h_internal = %g s is coarse against the actuator time "
                         "constants (%g s, %g s); RK4 will be inaccurate",
                         m->h_internal, m->af.tau_motor, m->af.tau_servo);
    return c.errors;
}

/* ------------------------------------------------------------------------ */
/* Model callbacks                                                          */

/* Every input finite and within its table range; else an error naming the first bad one. */
static int check_inputs(const PlantModel *m, const FpLogger *logger) {
    static const int rows[] = {PV_omega_cmd, PV_alpha_cmd, PV_beta_cmd, PV_efficiency,
                               PV_f_d,       PV_tau_d,     PV_a_d};
    const double *values[7];
    int counts[7] = {0, 0, 0, 0, 3, 3, 3};
    int i, k;
    values[0] = m->omega_cmd, values[1] = m->alpha_cmd, values[2] = m->beta_cmd;
    values[3] = m->efficiency, values[4] = m->f_d, values[5] = m->tau_d, values[6] = m->a_d;
    counts[0] = counts[1] = counts[2] = counts[3] = m->af.n_rotors; /* the others are ignored */
    for (k = 0; k < 7; k++) {
        const FpVar *v = &plant_vars[rows[k]];
        for (i = 0; i < counts[k]; i++) {
            double x = values[k][i];
            char range[96];
            if (!isfinite(x)) {
                fp_log(logger, FP_ERROR, FP_LOG_ERROR, "input %s[%d] = %g is not finite",
                       v->name, i + 1, x);
                return 1;
            }
            if (!fp_range_contains(&v->range, x)) {
                fp_log(logger, FP_ERROR, FP_LOG_ERROR, "input %s[%d] = %g is outside %s",
                       v->name, i + 1, x, fp_range_text(&v->range, 0, range, sizeof range));
                return 1;
            }
        }
    }
    return 0;
}

static FpStatus plant_initialize(void *model, double t0, const FpLogger *logger) {
    PlantModel *m = (PlantModel *)model;
    Commands u;
    uint64_t seed;
    int i;
    if (validate(m, logger) != 0) return FP_ERROR;
    fp_rotor_set_of(&m->af, &m->rotors);
    if (invert3(m->af.inertia, m->inertia_inv) != 0) {
        fp_log(logger, FP_ERROR, FP_LOG_ERROR, "parameter inertia is singular");
        return FP_ERROR;
    }
    memset(m->x, 0, sizeof m->x);
    for (i = 0; i < 3; i++) {
        m->x[X_POS + i] = m->pos0[i];
        m->x[X_VEL + i] = m->vel0[i];
        m->x[X_RATE + i] = m->rate0[i];
    }
    quat_from_euler(m->euler0, m->x + X_QUAT);
    quat_normalize(m->x + X_QUAT);
    if (m->init_trim) {
        double w[6];
        char why[160];
        hover_wrench(m, m->euler0, w);
        if (fp_preferred_config(&m->rotors, w, m->x + X_ALPHA, m->x + X_BETA, m->x + X_OMEGA, why,
                                (int)sizeof why) != FP_OK) {
            fp_log(logger, FP_ERROR, FP_LOG_ERROR,
                   "parameter init_trim: no hover trim at euler0 = [%g, %g, %g] rad: %s",
                   m->euler0[0], m->euler0[1], m->euler0[2], why);
            return FP_ERROR;
        }
    } else {
        for (i = 0; i < m->af.n_rotors; i++) {
            m->x[X_OMEGA + i] = m->omega0[i];
            m->x[X_ALPHA + i] = m->alpha0[i];
            m->x[X_BETA + i] = m->beta0[i];
        }
    }
    if (check_inputs(m, logger) != 0) return FP_ERROR; /* inputs set before initialization */
    seed = (uint64_t)(uint32_t)m->noise_seed;
    for (i = 0; i < 4; i++) m->rng[i] = splitmix64(&seed);
    saturate(m, &u, &m->sat_flags);
    m->sat_flags = 0;
    m->t_step = 0.0;
    m->t0 = t0;
    m->hist_count = m->hist_head = 0;
    m->mocap_last = m->imu_last = t0 - 1.0; /* every sensor samples at t0 */
    m->contact_reach = contact_reach(m);
    m->contact_anchored = 0; /* the points touching at t0 stick where they are */
    memset(m->contact_anchor, 0, sizeof m->contact_anchor);
    if (m->n_contacts > 0) {
        if (check_start_above_ground(m, logger) != 0) return FP_ERROR;
        update_anchors(m);
    }
    if (compute_outputs(m, &u, t0, logger) != FP_OK) return FP_ERROR;
    fp_log(logger, FP_OK, FP_LOG_MODEL, "initial state: %d rotors, omega_1 = %g rad/s",
           (int)m->af.n_rotors, m->x[X_OMEGA]);
    return FP_OK;
}


/* The physically meaningful range of the vehicle state: beyond it the rigid-body and rotor
 * model mean nothing and RK4 soon overflows to NaN, so a step that leaves it is refused with
 * the state kept from before the step (docs/robustness.md). */
#define PLANT_MAX_DISTANCE 1e7 /* m from the origin */
#define PLANT_MAX_SPEED 1e3    /* m/s */
#define PLANT_MAX_RATE 1e3     /* rad/s body rate */

/* 0 if x is finite and inside the physical range; else logs the first quantity outside it (at
 * the end of a co-simulation step from t, or at time t of a Model Exchange instance: me). */
static int state_outside(const double *x, double t, int me, const FpLogger *logger) {
    static const char *const names[] = {"pos", "vel", "quat", "rate"};
    static const int first[] = {X_POS, X_VEL, X_QUAT, X_RATE}, size[] = {3, 3, 4, 3};
    static const double limit[] = {PLANT_MAX_DISTANCE, PLANT_MAX_SPEED, 2.0, PLANT_MAX_RATE};
    int g, i;
    for (g = 0; g < 4; g++)
        for (i = 0; i < size[g]; i++) {
            double v = x[first[g] + i];
            if (!(fabs(v) <= limit[g])) {
                if (me) {
                    fp_log(logger, FP_ERROR, FP_LOG_ERROR,
                           "the vehicle state left its physical range at t = %.6g s: %s[%d] = "
                           "%g (limit %g) (are the inputs f_d, tau_d, a_d plausible?)",
                           t, names[g], i + 1, v, limit[g]);
                    return 1;
                }
                fp_log(logger, FP_ERROR, FP_LOG_ERROR,
                       "the vehicle state left its physical range in the step from t = %.6g s: "
                       "%s[%d] = %g (limit %g); the step is refused and the state kept from "
                       "before it (are the inputs f_d, tau_d, a_d plausible?)",
                       t, names[g], i + 1, v, limit[g]);
                return 1;
            }
        }
    for (i = X_OMEGA; i < PLANT_NX; i++)
        if (!isfinite(x[i])) {
            if (me)
                fp_log(logger, FP_ERROR, FP_LOG_ERROR,
                       "the actuator state is not finite at t = %.6g s", t);
            else
                fp_log(logger, FP_ERROR, FP_LOG_ERROR,
                       "the actuator state is not finite after the step from t = %.6g s; the "
                       "step is refused and the state kept from before it", t);
            return 1;
        }
    return 0;
}

/* Any h > 0: ceil(h / h_internal) equal RK4 steps (fp_steps_to_cover), so a step that is a
 * multiple of h_internal takes exactly the steps of h_internal it always did, and any other
 * step the fewest equal steps no longer than h_internal.  At most FP_MAX_INTERNAL_STEPS
 * (10^6, 500 s at the default 0.5 ms, about a second of CPU): a call that cannot be cancelled
 * must stay short enough for an importer to wait. */
static FpStatus plant_step(void *model, double t, double h, const FpLogger *logger) {
    PlantModel *m = (PlantModel *)model;
    Commands u;
    double substeps = fp_steps_to_cover(h, m->h_internal, FP_STEP_TOL * h), hi;
    double t_start = m->timing ? fp_clock_seconds() : 0.0;
    double x_before[PLANT_NX], anchor_before[PLANT_MAX_CONTACTS][2];
    int32_t flags_before = m->sat_flags, anchored_before = m->contact_anchored;
    long k, n;
    if (fp_check_step_work(h, substeps, FP_MAX_INTERNAL_STEPS, "RK4 steps of h_internal",
                           logger) != FP_OK)
        return FP_ERROR;
    if (check_inputs(m, logger) != 0) return FP_ERROR;
    memcpy(x_before, m->x, sizeof x_before);
    memcpy(anchor_before, m->contact_anchor, sizeof anchor_before);
    saturate(m, &u, &m->sat_flags);
    n = (long)substeps;
    hi = h / substeps;
    for (k = 0; k < n; k++) {
        rk4_step(m, &u, m->x, hi);
        if (m->n_contacts > 0) update_anchors(m);
    }
    if (state_outside(m->x, t, 0, logger)) {
        memcpy(m->x, x_before, sizeof x_before);
        memcpy(m->contact_anchor, anchor_before, sizeof anchor_before);
        m->contact_anchored = anchored_before;
        m->sat_flags = flags_before;
        return FP_ERROR;
    }
    if (compute_outputs(m, &u, t + h, logger) != FP_OK) return FP_ERROR;
    if (m->timing) m->t_step = fp_clock_seconds() - t_start;
    return FP_OK;
}

static FpStatus plant_check_restored(const void *model, int initialized,
                                     const FpLogger *logger) {
    const PlantModel *m = (const PlantModel *)model;
    if (m->af.n_rotors < 1 || m->af.n_rotors > FP_MAX_ROTORS || m->rotors.n < 0 ||
        m->rotors.n > FP_MAX_ROTORS || (initialized && m->rotors.n != m->af.n_rotors)) {
        fp_log(logger, FP_ERROR, FP_LOG_ERROR,
               "restored state: rotor count %ld (rotor set %ld) outside 1..%d",
               (long)m->af.n_rotors, (long)m->rotors.n, FP_MAX_ROTORS);
        return FP_ERROR;
    }
    /* the measurement-delay ring: the step writes hist[(hist_head + 1) % PLANT_HISTORY] and walks
     * hist_count points back from hist_head (any lifecycle: a model's own values are in range) */
    if (m->hist_head < 0 || m->hist_head >= PLANT_HISTORY) {
        fp_log(logger, FP_ERROR, FP_LOG_ERROR,
               "restored state: hist_head = %ld is outside 0..%d (the index of the latest "
               "point of the measurement-delay history)",
               (long)m->hist_head, PLANT_HISTORY - 1);
        return FP_ERROR;
    }
    if (m->hist_count < 0 || m->hist_count > PLANT_HISTORY) {
        fp_log(logger, FP_ERROR, FP_LOG_ERROR,
               "restored state: hist_count = %ld is outside 0..%d (the points kept in the "
               "measurement-delay history)",
               (long)m->hist_count, PLANT_HISTORY);
        return FP_ERROR;
    }
    if (!initialized) return FP_OK; /* parameters are checked when initialization ends */
    if (validate(m, logger) != 0) {
        fp_log(logger, FP_ERROR, FP_LOG_ERROR, "restored state: its parameters are invalid");
        return FP_ERROR;
    }
    if (m->contact_reach != contact_reach(m)) { /* (skipping the contact relies on it) */
        fp_log(logger, FP_ERROR, FP_LOG_ERROR,
               "restored state: contact_reach %g m is not the landing gear's %g m",
               m->contact_reach, contact_reach(m));
        return FP_ERROR;
    }
    if (!fp_all_finite(m->x, PLANT_NX) || !fp_all_finite(&m->inertia_inv[0][0], 9) ||
        !fp_all_finite(&m->contact_anchor[0][0], 2 * PLANT_MAX_CONTACTS) ||
        !fp_all_finite(m->pos, 3) || !fp_all_finite(m->vel, 3) || !fp_all_finite(m->euler, 3) ||
        !fp_all_finite(m->rate, 3)) {
        fp_log(logger, FP_ERROR, FP_LOG_ERROR, "restored state: the vehicle state is not finite");
        return FP_ERROR;
    }
    return FP_OK;
}

/* ------------------------------------------------------------------------ */
/* Model Exchange (fp_model.h FpModelExchange, docs/fmus.md "Model Exchange")  */

/* What only the co-simulation step does is refused: sensor noise is drawn once per
 * communication step and sample, sampling and latency act on communication points and the
 * step's timing times fmi2DoStep; Model Exchange has none of them.  Each parameter that asks
 * for one is named. */
static FpStatus plant_me_check(const void *model, const FpLogger *logger) {
    const PlantModel *m = (const PlantModel *)model;
    static const char *const names[] = {"noise_pos",  "noise_vel",    "noise_acc",
                                        "noise_att",  "noise_rate",   "noise_ang_acc",
                                        "mocap_period", "mocap_delay", "imu_period"};
    const double values[] = {m->noise_pos,  m->noise_vel,    m->noise_acc,
                             m->noise_att,  m->noise_rate,   m->noise_ang_acc,
                             m->mocap_period, m->mocap_delay, m->imu_period};
    size_t i;
    int bad = 0;
    for (i = 0; i < sizeof names / sizeof names[0]; i++) {
        char v[FP_REAL_TEXT];
        if (values[i] == 0.0) continue;
        fp_log(logger, FP_ERROR, FP_LOG_ERROR,
               "parameter %s = %s must be 0 in Model Exchange: %s acts per communication step "
               "of co-simulation, which a Model Exchange instance has not (its outputs are the "
               "true state); use the co-simulation interface for %s",
               names[i], fp_real_text(v, values[i]),
               i < 6 ? "sensor noise" : i < 8 ? "the motion-capture sampling" : "the IMU sampling",
               i < 6 ? "sensor noise" : "sensor timing");
        bad++;
    }
    if (m->timing) {
        fp_log(logger, FP_ERROR, FP_LOG_ERROR,
               "parameter timing = true must be false in Model Exchange: t_step times "
               "fmi2DoStep, which a Model Exchange instance has not");
        bad++;
    }
    return bad ? FP_ERROR : FP_OK;
}

static void plant_me_get_states(const void *model, double *x) {
    memcpy(x, ((const PlantModel *)model)->x, sizeof ((const PlantModel *)model)->x);
}

/* The solver's state as it is: the quaternion is not renormalized (the co-simulation step
 * renormalizes after every RK4 step; a solver keeps its norm to its tolerance, and the
 * right-hand side takes it as it comes, as RK4's inner stages do). */
static void plant_me_set_states(void *model, const double *x) {
    memcpy(((PlantModel *)model)->x, x, sizeof ((PlantModel *)model)->x);
}

static void plant_me_get_derivatives(const void *model, double *dx) {
    memcpy(dx, ((const PlantModel *)model)->der_x, sizeof ((const PlantModel *)model)->der_x);
}

/* The state rows' declared nominals (RotorSpeed 100 rad/s), 1 where none. */
static void plant_me_nominals(const void *model, double *nominal) {
    size_t i, k = 0;
    (void)model;
    for (i = 0; i < N_PLANT_VARS; i++) {
        const FpVar *v = &plant_vars[i];
        double n = fp_declared_type(v->dtype)->nominal;
        uint32_t j;
        if (v->kind != FP_STATE) continue;
        for (j = 0; j < fp_var_count(v) && k < PLANT_NX; j++) nominal[k++] = n > 0.0 ? n : 1.0;
    }
}

/* The right-hand side the RK4 step integrates, at the commands saturated as the step
 * saturates them (sat_flags: the commands set now), and the outputs of the state: the true
 * state, which the measured outputs equal (ideal sensors: plant_me_check). */
static FpStatus plant_me_evaluate(void *model, double t, const FpLogger *logger) {
    PlantModel *m = (PlantModel *)model;
    Commands u;
    int i;
    (void)t; /* (autonomous: time enters through the inputs only) */
    if (check_inputs(m, logger) != 0) return FP_ERROR;
    saturate(m, &u, &m->sat_flags);
    true_outputs(m, &u);
    for (i = 0; i < 3; i++) {
        m->pos[i] = m->pos_true[i];
        m->vel[i] = m->vel_true[i];
        m->euler[i] = m->euler_true[i];
        m->rate[i] = m->rate_true[i];
        m->acc[i] = m->der_x[X_VEL + i];
        m->ang_acc[i] = m->der_x[X_RATE + i];
    }
    memcpy(m->quat, m->quat_true, sizeof m->quat);
    m->pose_age = 0.0;
    return FP_OK;
}

/* Each contact point's depth below the ground (contact_depth): the contact force switches
 * on where one changes sign (its damping term jumps there), so the solver locates touchdown
 * and lift-off. */
static void plant_me_event_indicators(const void *model, double *z) {
    contact_depth_of((const PlantModel *)model, z);
}

/* After a completed integrator step and in an event: the contact anchors at the state (as
 * after every RK4 step in co-simulation), the state checked against its physical range. */
static FpStatus plant_me_update_discrete(void *model, double t, const FpLogger *logger) {
    PlantModel *m = (PlantModel *)model;
    if (state_outside(m->x, t, 1, logger)) return FP_ERROR;
    if (m->n_contacts > 0) update_anchors(m);
    return FP_OK;
}

static const FpModelExchange plant_me = {
    PLANT_NX,
    PLANT_NZ,
    "contact_depth",
    plant_me_check,
    plant_me_get_states,
    plant_me_set_states,
    plant_me_nominals,
    plant_me_evaluate,
    plant_me_get_derivatives,
    plant_me_event_indicators,
    plant_me_update_discrete,
};

static const FpModelInfo plant_info = {
    "MultirotorPlant",
    "6-DoF multirotor with up to 8 tilting rotors (paper eq. 1-3), first-order motor and servo "
    "dynamics, hard limits, disturbances and optional sensor noise; fixed-step RK4",
    sizeof(PlantModel),
    plant_vars,
    N_PLANT_VARS,
    0.002,
    10.0,
    plant_set_defaults,
    plant_initialize,
    plant_step,
    NULL,
    plant_check_restored,
    offsetof(PlantModel, initialized),
    NULL,
    &plant_me,
};

const FpModelInfo *plant_model_info(void) { return &plant_info; }
