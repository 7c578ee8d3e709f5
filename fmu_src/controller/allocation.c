/*
 * Inner allocation (paper eq. 12-13): WLS on the analytic B2 = B''(u_a,m) at the filtered
 * actuator state, with the actuator bounds, the row weights W_nu (torque priority) and a
 * preferred configuration (the minimum-norm split of the commanded wrench nu_c).
 */
#include <string.h>

#include "fp_clock.h"
#include "fp_math.h"
#include "stages.h"

/* Preferred configuration for the rotors still working: the minimum-norm split over
 * them; lost rotors get their current state (they are fixed in the QP anyway). */
static void preferred_without_lost(const FpRotorSet *rotors, const FpPreferredSplit *split,
                                   int32_t lost_mask, const CtrlFiltered *s,
                                   const double nu_c[6], double a_pref[], double b_pref[],
                                   double w_pref[]) {
    FpRotorSet rs;
    double a[FP_MAX_ROTORS], b[FP_MAX_ROTORS], w[FP_MAX_ROTORS];
    int map[FP_MAX_ROTORS], i, n = 0;
    if (lost_mask == 0) { /* the geometry's part prepared once (fp_preferred_config) */
        fp_preferred_apply(rotors, split, nu_c, a_pref, b_pref, w_pref, NULL, 0);
        return;
    }
    rs = *rotors;
    for (i = 0; i < rotors->n; i++) {
        a_pref[i] = s->a_m[i];
        b_pref[i] = s->b_m[i];
        w_pref[i] = rotors->omega_min;
        if ((lost_mask >> i) & 1) continue;
        map[n] = i;
        memcpy(rs.pos[n], rotors->pos[i], sizeof rs.pos[n]);
        rs.dir[n] = rotors->dir[i];
        rs.gamma[n] = rotors->gamma[i];
        rs.alpha_min[n] = rotors->alpha_min[i], rs.alpha_max[n] = rotors->alpha_max[i];
        rs.beta_min[n] = rotors->beta_min[i], rs.beta_max[n] = rotors->beta_max[i];
        n++;
    }
    if (n == 0) return;
    rs.n = n;
    fp_preferred_config(&rs, nu_c, a, b, w, NULL, 0);
    for (i = 0; i < n; i++) {
        a_pref[map[i]] = a[i];
        b_pref[map[i]] = b[i];
        w_pref[map[i]] = w[i];
    }
}

void ctrl_allocation(const CtrlAllocationParams *p, const CtrlFiltered *s, const double dnu_c[6],
                     int32_t lost_mask, FpWls *qp, CtrlAllocationOut *out) {
    const FpRotorSet *rs = p->rotors;
    FpWls *w = qp;
    FpWlsResult res;
    double b2[6 * 3 * FP_MAX_ROTORS], nu_c[6];
    double a_pref[FP_MAX_ROTORS], b_pref[FP_MAX_ROTORS], w_pref[FP_MAX_ROTORS];
    double lo[3], hi[3], um[3], pref[3], scale[3], t0;
    int i, j, k, n = rs->n, nv = 3 * n;
    int32_t flags = 0;
    fp_effectiveness_b2prime_trig(rs, &s->trig, s->w_m, b2);
    for (i = 0; i < 6; i++) /* a rotor's effectiveness scales with its known efficiency */
        for (j = 0; j < n; j++) {
            double *bij = &b2[i * nv + 3 * j];
            bij[0] *= s->eff[j];
            bij[1] *= s->eff[j];
            bij[2] *= s->eff[j];
        }
    for (i = 0; i < 3; i++) {
        nu_c[i] = s->f_b_m[i] + dnu_c[i];
        nu_c[3 + i] = s->tau_b_m[i] + dnu_c[3 + i];
    }
    /* an infeasible split still gives a usable preference once clamped below */
    preferred_without_lost(rs, p->pref_split, lost_mask, s, nu_c, a_pref, b_pref, w_pref);
    w->n_rows = 6 + nv;
    for (i = 0; i < 6; i++) {
        for (j = 0; j < nv; j++) w->A[i * nv + j] = p->W_nu[i] * b2[i * nv + j];
        w->b[i] = p->W_nu[i] * dnu_c[i];
    }
    /* the preference rows: scale[k] on the diagonal, zero elsewhere (zeroed by fp_wls_setup
     * at initialization, never written off the diagonal since) */
    scale[0] = scale[1] = p->w_pref;
    scale[2] = p->w_pref * p->pref_omega_scale;
    for (i = 0; i < n; i++) {
        lo[0] = rs->alpha_min[i], hi[0] = rs->alpha_max[i], um[0] = s->a_m[i];
        lo[1] = rs->beta_min[i], hi[1] = rs->beta_max[i], um[1] = s->b_m[i];
        lo[2] = rs->omega_min, hi[2] = rs->omega_max, um[2] = s->w_m[i];
        pref[0] = a_pref[i], pref[1] = b_pref[i], pref[2] = w_pref[i];
        if ((lost_mask >> i) & 1) { /* a lost rotor: servos held, motor stopped */
            lo[0] = hi[0] = pref[0] = um[0];
            lo[1] = hi[1] = pref[1] = um[1];
            lo[2] = hi[2] = pref[2] = rs->omega_min;
        }
        for (k = 0; k < 3; k++) {
            int col = 3 * i + k, row = 6 + col;
            w->A[row * nv + col] = scale[k];
            w->b[row] = scale[k] * (fp_clamp(pref[k], lo[k], hi[k]) - um[k]);
            w->lb[col] = lo[k] - um[k];
            w->ub[col] = hi[k] - um[k];
        }
    }
    t0 = p->timing ? fp_clock_seconds() : 0.0;
    fp_wls_solve_brief(w, p->max_iter, &res);
    if (p->timing) out->t_solve = fp_clock_seconds() - t0;
    out->status = res.status;
    out->iterations = res.iterations;
    for (i = 0; i < 6; i++) {
        double v = -dnu_c[i];
        for (j = 0; j < nv; j++) v += b2[i * nv + j] * w->x[j];
        out->residual[i] = v;
    }
    for (i = 0; i < FP_MAX_ROTORS; i++) {
        double *a_cmd = out->alpha_cmd, *b_cmd = out->beta_cmd, *w_cmd = out->omega_cmd;
        if (i >= n) {
            a_cmd[i] = b_cmd[i] = w_cmd[i] = 0.0;
            continue;
        }
        a_cmd[i] = fp_clamp(s->a_m[i] + w->x[3 * i], rs->alpha_min[i], rs->alpha_max[i]);
        b_cmd[i] = fp_clamp(s->b_m[i] + w->x[3 * i + 1], rs->beta_min[i], rs->beta_max[i]);
        w_cmd[i] = fp_clamp(s->w_m[i] + w->x[3 * i + 2], rs->omega_min, rs->omega_max);
        if ((lost_mask >> i) & 1) continue; /* a stopped dead rotor is not saturated */
        if (rs->alpha_max[i] > rs->alpha_min[i] &&
            (a_cmd[i] <= rs->alpha_min[i] + 1e-9 || a_cmd[i] >= rs->alpha_max[i] - 1e-9))
            flags |= (int32_t)1 << (FP_SAT_ALPHA + i);
        if (rs->beta_max[i] > rs->beta_min[i] &&
            (b_cmd[i] <= rs->beta_min[i] + 1e-9 || b_cmd[i] >= rs->beta_max[i] - 1e-9))
            flags |= (int32_t)1 << (FP_SAT_BETA + i);
        if (w_cmd[i] <= rs->omega_min + 1e-9 || w_cmd[i] >= rs->omega_max - 1e-9)
            flags |= (int32_t)1 << (FP_SAT_MOTOR + i);
    }
    out->sat_flags = flags;
}
