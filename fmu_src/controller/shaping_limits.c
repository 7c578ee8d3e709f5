/*
 * The reference shaping's limits, from the airframe: a step is flown at the pace this
 * vehicle can keep, not at one vehicle's numbers.  Computed once at initialization from the
 * feasible-force set in use and the rotors; a limit the user gives (> 0) is taken as given.
 *
 *  Horizontal acceleration a_h = max(CTRL_LIM_FORCE_SHARE a_level, a_tilt):
 *    a_level = min over azimuths u of max{ t : [t u; -m g] in S(0) } / m, the level
 *      acceleration the (margin-scaled) force set leaves after the hover force: an
 *      over-actuated vehicle accelerates without tilting;
 *    a_tilt = 0.9 g tan(ref_tilt_max) within the thrust the set has (|f| <= -fz_min): what
 *      a vehicle whose force follows its attitude reaches at the tilt the user allows.
 *  Vertical acceleration a_z = 1/2 min(up cos(ref_tilt_max) - g, g - least), up and least
 *    the set's largest and smallest upward thrust per unit mass (climb and descent both
 *    leave half of the range to the feedback).
 *  Jerk j = a lambda (full acceleration within 1 / lambda, lambda = ref_bandwidth); where the
 *    tilt route sets a_h, the tilt must follow: j_h <= g ref_att_rate_max[roll].
 *  Speed v = a * CTRL_LIM_SPEED_TIME: the speed reached at the acceleration limit in that time.
 *  Heading: the yaw torque the rotors give at the hover trim beside the hover wrench,
 *    tau_z (linearised: the inner allocation's B'' at trim and the actuators' ranges, solved
 *    as a weighted least-squares that holds the other five wrench components), times
 *    CTRL_LIM_TORQUE_SHARE over I_zz: the heading acceleration; rate = acceleration *
 *    CTRL_LIM_SPEED_TIME; the stabilization's heading-rate command limit
 *    CTRL_LIM_YAW_RATE_ROOM times that rate (the rest is the feedback's).
 */
#include <math.h>
#include <string.h>

#include "fp_math.h"
#include "stages.h"

#define CTRL_LIM_FORCE_SHARE 0.85 /* of the level acceleration: the rest is the feedback's */
#define CTRL_LIM_TORQUE_SHARE 0.5 /* of the heading torque (linearised: optimistic) */
#define CTRL_LIM_SPEED_TIME 1.0   /* s */
#define CTRL_LIM_YAW_RATE_ROOM 1.25
#define CTRL_LIM_AZIMUTHS 24

/* max{ t >= 0 : A (h + t u) <= d } over the n facets (h inside): 0 when h is on a facet
 * that u leaves through (a set without extent along u). */
static double reach(const double (*A)[3], const double *d, int n, const double h[3],
                    const double u[3]) {
    double t = INFINITY;
    int j;
    for (j = 0; j < n; j++) {
        double au = v3_dot(A[j], u), slack = d[j] - v3_dot(A[j], h);
        if (au > 1e-12) t = fmin(t, fmax(slack, 0.0) / au);
    }
    return isfinite(t) ? t : 0.0;
}

double ctrl_level_acceleration(const CtrlForceSet *fs, double mass, double g) {
    double h[3] = {0.0, 0.0, -mass * g}, least = INFINITY;
    int k;
    for (k = 0; k < CTRL_LIM_AZIMUTHS; k++) {
        double az = 2.0 * CTRL_PI * k / CTRL_LIM_AZIMUTHS, u[3];
        u[0] = cos(az), u[1] = sin(az), u[2] = 0.0;
        least = fmin(least, reach(fs->A, fs->d, fs->n, h, u));
    }
    return least / mass;
}

FpStatus ctrl_torque_capability(const FpRotorSet *rs, double mass, double g, FpWls *w,
                                double tau_max[3]) {
    FpRotorTrig tr;
    FpWlsResult res;
    double wrench[6] = {0.0, 0.0, 0.0, 0.0, 0.0, 0.0};
    double a[FP_MAX_ROTORS], b[FP_MAX_ROTORS], om[FP_MAX_ROTORS];
    double b2[6 * 3 * FP_MAX_ROTORS], arm = 0.0;
    int i, j, axis, sign, n = rs->n, nv = 3 * n;
    wrench[2] = -mass * g;
    if (n < 1 || n > FP_MAX_ROTORS) return FP_ERROR;
    if (fp_preferred_config(rs, wrench, a, b, om, NULL, 0) != FP_OK) return FP_ERROR;
    memset(&tr, 0, sizeof tr);
    fp_rotor_trig_mounts(rs, &tr);
    fp_rotor_trig_tilts(rs, a, b, &tr);
    if (fp_effectiveness_b2prime_trig(rs, &tr, om, b2) != FP_OK) return FP_ERROR;
    for (i = 0; i < n; i++) arm += sqrt(v3_dot(rs->pos[i], rs->pos[i])) / n;
    if (fp_wls_setup(w, nv, 6 + nv, 0) != FP_OK) return FP_ERROR;
    for (axis = 0; axis < 3; axis++) {
        tau_max[axis] = INFINITY;
        for (sign = -1; sign <= 1; sign += 2) {
            /* ask for far more torque about `axis` than any rotor set gives, holding the
             * other five components at weight 1e3; a small pull toward the trim makes the
             * least-squares problem well posed */
            double target = sign * 100.0 * mass * fabs(g) * (arm > 0.0 ? arm : 1.0), got = 0.0;
            for (i = 0; i < 6; i++) {
                double wt = i == 3 + axis ? 1.0 : 1e3;
                for (j = 0; j < nv; j++) w->A[i * nv + j] = wt * b2[i * nv + j];
                w->b[i] = i == 3 + axis ? target : 0.0;
            }
            for (i = 0; i < nv; i++) {
                int r = i / 3, k = i % 3;
                double lo, hi, at, scale = k == 2 ? 1e-6 : 1e-4;
                for (j = 0; j < nv; j++) w->A[(6 + i) * nv + j] = i == j ? scale : 0.0;
                w->b[6 + i] = 0.0;
                lo = k == 0 ? rs->alpha_min[r] : k == 1 ? rs->beta_min[r] : rs->omega_min;
                hi = k == 0 ? rs->alpha_max[r] : k == 1 ? rs->beta_max[r] : rs->omega_max;
                at = k == 0 ? a[r] : k == 1 ? b[r] : om[r];
                w->lb[i] = fmin(lo - at, 0.0);
                w->ub[i] = fmax(hi - at, 0.0);
            }
            w->n_rows = 6 + nv;
            fp_wls_reset(w);
            if (fp_wls_solve(w, 200, &res) == FP_ERROR) return FP_ERROR;
            for (j = 0; j < nv; j++) got += b2[(3 + axis) * nv + j] * w->x[j];
            tau_max[axis] = fmin(tau_max[axis], fmax(sign * got, 0.0));
        }
    }
    fp_wls_reset(w);
    return FP_OK;
}

void ctrl_shaping_limits(const CtrlLimitInputs *in, CtrlShapingLimits *out) {
    double g = fabs(in->g), m = in->mass, tilt = in->tilt_max, lam = in->bandwidth;
    double up = -in->fs->fz[0] / m, least = -in->fs->fz[1] / m;
    double a_level = ctrl_level_acceleration(in->fs, m, in->g);
    double a_tilt = 0.9 * g * tan(tilt), a_h, a_z, j_h;
    int tilt_route, i;
    if (up > g) a_tilt = fmin(a_tilt, sqrt(up * up - g * g));
    tilt_route = a_tilt > CTRL_LIM_FORCE_SHARE * a_level;
    a_h = tilt_route ? a_tilt : CTRL_LIM_FORCE_SHARE * a_level;
    a_z = fmax(0.5 * fmin(up * cos(tilt) - g, g - least), 0.05 * g);
    out->a_level = a_level;
    out->acc[0] = in->acc_max[0] > 0.0 ? in->acc_max[0] : a_h;
    out->acc[1] = in->acc_max[1] > 0.0 ? in->acc_max[1] : a_z;
    j_h = out->acc[0] * lam;
    if (tilt_route) j_h = fmin(j_h, g * in->att_rate_max_given[0]);
    out->jerk[0] = in->jerk_max[0] > 0.0 ? in->jerk_max[0] : j_h;
    out->jerk[1] = in->jerk_max[1] > 0.0 ? in->jerk_max[1] : out->acc[1] * lam;
    for (i = 0; i < 2; i++)
        out->vel[i] = in->vel_max[i] > 0.0 ? in->vel_max[i] : out->acc[i] * CTRL_LIM_SPEED_TIME;
    for (i = 0; i < 3; i++) {
        double alpha = CTRL_LIM_TORQUE_SHARE * in->tau_max[i] / in->inertia[i][i];
        out->att_acc[i] = in->att_acc_max[i] > 0.0 ? in->att_acc_max[i] : alpha;
        out->att_rate[i] = in->att_rate_max_given[i] > 0.0 ? in->att_rate_max_given[i]
                                                           : out->att_acc[i] * CTRL_LIM_SPEED_TIME;
    }
    out->yaw_rate = CTRL_LIM_YAW_RATE_ROOM * out->att_rate[2];
}
