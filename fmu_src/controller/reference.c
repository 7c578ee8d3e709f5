/*
 * Reference shaping: what the user asks for (a waypoint jump, a 10 m step, a 3 rad heading
 * step) made into a reference the vehicle can follow inside its limits.
 *
 * The shaped reference is the input plus an error state e (position, velocity and
 * acceleration; per Euler angle: angle and rate).  A discontinuity of the input is absorbed
 * into e, so the shaped reference stays continuous; e is then driven back to zero by a
 * cascade of saturated laws (velocity from the position error through a square-root braking
 * law, acceleration from the velocity error, jerk from the acceleration error), each within
 * its limit.  The smooth part of the input passes unchanged: while e is zero the output is
 * the input bit for bit, so a trajectory with consistent derivatives (sines, chirps, the
 * minimum-jerk waypoints) flies exactly as without shaping.  Limits bound the correction
 * added to the input, within what the input's own motion leaves of them.
 *
 * In the linear region the cascade's poles lie together at -lambda (a triple pole for
 * translation, a double pole for the angles): the fastest choice without overshoot.
 */
#include <string.h>

#include "stages.h"

/* Discontinuities an input of consistent derivatives never shows: its increment beyond
 * what its own derivative explains (trapezoidal rule, error ~ Ts^3 jerk / 12 ~ 1e-9 m). */
#define JUMP_POS 1e-6   /* m, rad */
#define JUMP_VEL 1e-6   /* m/s, rad/s: beyond the rule, as for positions */
#define JUMP_ACC_RATE 50.0 /* m/s^3: acceleration changes faster than this are jumps */
#define JUMP_ATT_ACC 5.0   /* rad/s^2: angular-rate changes faster than this are jumps */
#define SNAP 1e-9          /* an error state below this is zero: the output is the input */
#define BUDGET_FLOOR 0.25  /* share of a limit the correction keeps when the input uses it */
#define BRAKE_SHARE 0.75   /* of the acceleration limit: braking (the rest absorbs the jerk-limited turn) */

/* The velocity that stops from distance d within deceleration decel: linear (gain k) near
 * zero, the square-root braking law beyond, continuous with its slope at the junction. */
static double braking_speed(double d, double k, double decel) {
    double d_lin = decel / (k * k);
    if (d <= d_lin) return k * d;
    return sqrt(2.0 * decel * (d - 0.5 * d_lin));
}

static double norm_n(const double *v, int n) {
    double s = 0.0;
    int i;
    for (i = 0; i < n; i++) s += v[i] * v[i];
    return sqrt(s);
}

/* v scaled to norm at most limit (n elements). */
static void limit_n(double *v, int n, double limit) {
    double r = norm_n(v, n);
    int i;
    if (r > limit && r > 0.0)
        for (i = 0; i < n; i++) v[i] *= limit / r;
}

/* What a limit leaves for the correction once the input uses `used` of it. */
static double budget(double limit, double used) {
    return fmax(limit - used, BUDGET_FLOOR * limit);
}

/* One group of translation axes (x and y together, so a jump is flown in a straight line,
 * or z alone): n elements of the error state, driven toward zero for one sample. */
static void shape_translation(const CtrlShapingParams *p, int group, int n, double *ep,
                              double *ev, double *ea, const double *v_in, const double *a_in,
                              double *jerk_out) {
    /* poles no faster than the jerk limit lets the acceleration follow: a cascade whose
     * jerk saturates overshoots (a quadrotor's tilt rate bounds its jerk) */
    double lam = fmin(p->lambda, p->jerk_max[group] / p->acc_max[group]);
    double vt[2], at[2], jerk[2], d = norm_n(ep, n);
    double v_lim = budget(p->vel_max[group], norm_n(v_in, n));
    double a_lim = budget(p->acc_max[group], norm_n(a_in, n));
    double speed = d > 0.0 ? fmin(braking_speed(d, lam / 3.0, BRAKE_SHARE * a_lim), v_lim) : 0.0;
    double ts = p->Ts;
    int i;
    for (i = 0; i < n; i++) vt[i] = d > 0.0 ? -ep[i] / d * speed : 0.0;
    for (i = 0; i < n; i++) at[i] = lam * (vt[i] - ev[i]);
    limit_n(at, n, a_lim);
    {
        /* the speed the velocity reaches while the acceleration returns to zero: at the
         * speed limit, no more acceleration outward */
        double vp[2], an = norm_n(ea, n), vn, along = 0.0, k = 3.0 * lam;
        double j = p->jerk_max[group], a_sat = j / k;
        /* the jerk law's own decay: at the jerk limit above a_sat, exponential below */
        double dv = an <= a_sat ? an / k : (an * an - a_sat * a_sat) / (2.0 * j) + a_sat / k;
        for (i = 0; i < n; i++) vp[i] = ev[i] + (an > 0.0 ? ea[i] / an * dv : 0.0);
        vn = norm_n(vp, n);
        if (vn >= v_lim) {
            for (i = 0; i < n; i++) along += at[i] * vp[i] / vn;
            if (along > 0.0)
                for (i = 0; i < n; i++) at[i] -= along * vp[i] / vn;
        }
    }
    for (i = 0; i < n; i++) jerk[i] = 3.0 * lam * (at[i] - ea[i]);
    limit_n(jerk, n, p->jerk_max[group]);
    for (i = 0; i < n; i++) {
        jerk_out[i] = jerk[i];
        ep[i] += ts * (ev[i] + ts * (0.5 * ea[i] + ts * jerk[i] / 6.0));
        ev[i] += ts * (ea[i] + 0.5 * ts * jerk[i]);
        ea[i] += ts * jerk[i];
    }
}

/* One Euler angle: the angle and rate errors toward zero for one sample. */
static void shape_angle(const CtrlShapingParams *p, int axis, double *e, double *er,
                        double rate_in) {
    double lam = p->lambda, ts = p->Ts;
    double r_lim = budget(p->att_rate_max[axis], fabs(rate_in));
    double a_lim = p->att_acc_max[axis];
    double d = fabs(*e);
    double rt = d > 0.0 ? -copysign(fmin(braking_speed(d, 0.5 * lam, 0.5 * a_lim), r_lim), *e)
                        : 0.0;
    double acc = fmin(fmax(2.0 * lam * (rt - *er), -a_lim), a_lim);
    *e += ts * (*er + 0.5 * ts * acc);
    *er += ts * acc;
}

static int all_below(const double *v, int n, double tol) {
    int i;
    for (i = 0; i < n; i++)
        if (fabs(v[i]) >= tol) return 0;
    return 1;
}

void ctrl_shape_reference(const CtrlShapingParams *p, const CtrlShapingInputs *in,
                          CtrlShaping *x, CtrlShapedRef *out) {
    double ts = p->Ts;
    int i;
    if (!p->enabled) {
        memcpy(out->pos, in->pos, sizeof out->pos);
        memcpy(out->vel, in->vel, sizeof out->vel);
        memcpy(out->acc, in->acc, sizeof out->acc);
        memcpy(out->mu, in->mu, sizeof out->mu);
        memcpy(out->mu_rate, in->mu_rate, sizeof out->mu_rate);
        memset(out->jerk, 0, sizeof out->jerk);
        return;
    }
    if (x->started) {
        /* discontinuities of the input move into the error state */
        for (i = 0; i < 3; i++) {
            double jp = in->pos[i] - x->pos_in[i] - 0.5 * ts * (in->vel[i] + x->vel_in[i]);
            double jv = in->vel[i] - x->vel_in[i] - 0.5 * ts * (in->acc[i] + x->acc_in[i]);
            double ja = in->acc[i] - x->acc_in[i];
            double jm = ctrl_wrap_pi(in->mu[i] - x->mu_in[i]) -
                        0.5 * ts * (in->mu_rate[i] + x->mu_rate_in[i]);
            double jr = in->mu_rate[i] - x->mu_rate_in[i];
            if (fabs(jp) > JUMP_POS) x->e_pos[i] -= jp;
            if (fabs(jv) > JUMP_VEL) x->e_vel[i] -= jv;
            if (fabs(ja) > JUMP_ACC_RATE * ts) x->e_acc[i] -= ja;
            if (fabs(jm) > JUMP_POS) x->e_mu[i] -= jm;
            if (fabs(jr) > JUMP_ATT_ACC * ts) x->e_rate[i] -= jr;
        }
    }
    x->started = 1;
    memcpy(x->pos_in, in->pos, sizeof x->pos_in);
    memcpy(x->vel_in, in->vel, sizeof x->vel_in);
    memcpy(x->acc_in, in->acc, sizeof x->acc_in);
    memcpy(x->mu_in, in->mu, sizeof x->mu_in);
    memcpy(x->mu_rate_in, in->mu_rate, sizeof x->mu_rate_in);
    if (all_below(x->e_pos, 3, SNAP) && all_below(x->e_vel, 3, SNAP) &&
        all_below(x->e_acc, 3, SNAP)) {
        memset(x->e_pos, 0, sizeof x->e_pos);
        memset(x->e_vel, 0, sizeof x->e_vel);
        memset(x->e_acc, 0, sizeof x->e_acc);
    }
    for (i = 0; i < 3; i++)
        if (fabs(x->e_mu[i]) < SNAP && fabs(x->e_rate[i]) < SNAP) x->e_mu[i] = x->e_rate[i] = 0.0;
    /* this sample's reference: the input plus the error (exactly the input at zero error) */
    for (i = 0; i < 3; i++) {
        out->pos[i] = in->pos[i] + x->e_pos[i];
        out->vel[i] = in->vel[i] + x->e_vel[i];
        out->acc[i] = in->acc[i] + x->e_acc[i];
        out->mu[i] = in->mu[i] + x->e_mu[i];
        out->mu_rate[i] = in->mu_rate[i] + x->e_rate[i];
    }
    /* the error state at the next sample */
    shape_translation(p, 0, 2, &x->e_pos[0], &x->e_vel[0], &x->e_acc[0], &in->vel[0],
                      &in->acc[0], &out->jerk[0]);
    shape_translation(p, 1, 1, &x->e_pos[2], &x->e_vel[2], &x->e_acc[2], &in->vel[2],
                      &in->acc[2], &out->jerk[2]);
    for (i = 0; i < 3; i++) shape_angle(p, i, &x->e_mu[i], &x->e_rate[i], in->mu_rate[i]);
}

void ctrl_shaping_start_at(const CtrlShapingInputs *in, const double pos[3],
                           const double vel[3], const double mu[3], CtrlShaping *x) {
    int i;
    memset(x, 0, sizeof *x);
    x->started = 1;
    for (i = 0; i < 3; i++) {
        x->pos_in[i] = in->pos[i];
        x->vel_in[i] = in->vel[i];
        x->acc_in[i] = in->acc[i];
        x->mu_in[i] = in->mu[i];
        x->mu_rate_in[i] = in->mu_rate[i];
        x->e_pos[i] = pos[i] - in->pos[i];
        x->e_vel[i] = vel[i] - in->vel[i];
        x->e_acc[i] = -in->acc[i];
        x->e_mu[i] = ctrl_wrap_pi(mu[i] - in->mu[i]);
        x->e_rate[i] = -in->mu_rate[i];
    }
}
