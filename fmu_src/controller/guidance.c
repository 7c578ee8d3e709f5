/*
 * Guidance (paper eq. 14-23).  The blocks K_xi and K_xidot with velocity and acceleration
 * feed-forward give the commanded acceleration; outer INDI turns it into the force the
 * reference needs; the WLS guidance QP over du = [df_b (3), dphi, dtheta] finds the pose
 * nearest the reference whose force lies in the feasible-force set: the commanded attitude
 * mu_c (psi_c = psi_ref, outside the QP: docs/architecture.md, "Design decisions") and the
 * body-force increment df_b_c.
 */
#include <string.h>

#include "fp_clock.h"
#include "fp_math.h"
#include "stages.h"

enum { NV = 5 }; /* QP variables [dfx, dfy, dfz, dphi, dtheta] */

/* Outer INDI at the filtered measurement. */
typedef struct {
    const double *r, *dr_dphi, *dr_dtheta; /* R(mu_m) and its partial derivatives (9 each) */
    double dacc[3];                        /* acc_c - acc_m */
    double f_w_ref[3];                     /* world force the reference needs, eq. (20) */
    double f_p[3];                         /* R(mu_ref)^T f_w_ref: body force at mu_ref */
} OuterIndi;

/* K_xi and K_xidot with feed-forward: acc_c, and dacc = acc_c - acc_m.
 * Position and velocity references pass through the measurement filter H(s) before they
 * meet the filtered measurements: with the same delay on both sides the feedback terms
 * vanish when the vehicle tracks exactly, instead of pushing on the filter's lag
 * (~2 zeta / wn = 22 ms: 4 cm at 1.5 m/s).  acc_ref is the unfiltered feed-forward: INDI
 * compares it with the filtered acceleration, whose lag the equally filtered actuator
 * feedback cancels. */
static void outer_loop(const CtrlGuidanceParams *p, const CtrlGuidanceInputs *in,
                       const CtrlFiltered *s, CtrlGuidanceState *st, double acc_c[3],
                       double dacc[3]) {
    int i;
    for (i = 0; i < 3; i++) {
        double e_pos = s->pos_ref_f[i] - s->pos_m[i];
        double v_c = ctrl_block(&p->K_pos, i, &st->x_pos[i], e_pos) + s->vel_ref_f[i];
        acc_c[i] = ctrl_block(&p->K_vel, i, &st->x_vel[i], v_c - s->vel_m[i]) + in->acc_ref[i];
        dacc[i] = acc_c[i] - s->acc_m[i];
    }
}

/* The QP of eq. (17)-(23) into w: objective rows, bounds and the force-set rows. */
/* Linearized at the attitude mu0 and body force f0: the filtered measurement for the
 * vehicle, the reference twin's last pose for the feed-forward (ctrl_guidance_twin). */
static void build_qp(const CtrlGuidanceParams *p, const CtrlForceSet *fs,
                     const double mu_ref[3], const double mu0[3], const double f0[3],
                     const OuterIndi *o, double f_bz_ref, int32_t *c_rows, FpWls *w) {
    double g_mat[3][NV], sg = sqrt(p->gamma_opt);
    int i, j, k, n_cons = 0;
    /* C's rows depend on the force set and the constraint's form alone: written when
     * those change, only the offsets d every sample */
    int32_t key = 2 * (fs->id + 1) + (p->force_constraint != 0);
    int rows_known = *c_rows == key;
    /* G = d(R f_b)/d[f_b, phi, theta] at the filtered measurement (eq. 14) */
    {
        double gp[3], gt[3];
        m3_mul_v(o->dr_dphi, f0, gp);
        m3_mul_v(o->dr_dtheta, f0, gt);
        for (i = 0; i < 3; i++) {
            for (j = 0; j < 3; j++) g_mat[i][j] = o->r[3 * i + j];
            g_mat[i][3] = gp[i];
            g_mat[i][4] = gt[i];
        }
    }
    /* eq. (19): A = [sqrt(gamma) W_v G; W_u], b = [sqrt(gamma) W_v m dacc; W_u du_p] */
    w->n_rows = 8;
    for (i = 0; i < 3; i++) {
        for (j = 0; j < NV; j++) w->A[i * NV + j] = sg * p->W_v[i] * g_mat[i][j];
        w->b[i] = sg * p->W_v[i] * p->mass * o->dacc[i];
    }
    /* du_p: the increment to the reference pose, i.e. to mu_ref and to the body force
     * f_p = R_ref^T f_w_ref that mu_ref needs.  With du_p's force part at zero ("no force
     * increment") the force and attitude terms trade off and mu_c lags mu_ref by a
     * fraction of the tracking error even when mu_ref is feasible; with f_p both terms
     * vanish together, so mu_c = mu_ref up to second-order linearization error. */
    for (i = 0; i < 3; i++) w->b[3 + i] = p->W_u[i] * (o->f_p[i] - f0[i]);
    memset(&w->A[3 * NV], 0, NV * NV * sizeof(double));
    for (i = 0; i < NV; i++) w->A[(3 + i) * NV + i] = p->W_u[i];
    w->b[6] = p->W_u[3] * ctrl_wrap_pi(mu_ref[0] - mu0[0]);
    w->b[7] = p->W_u[4] * (mu_ref[1] - mu0[1]);
    for (i = 0; i < 3; i++) {
        w->lb[i] = -INFINITY;
        w->ub[i] = INFINITY;
    }
    for (i = 0; i < 2; i++) {
        w->lb[3 + i] = p->euler_min[i] - mu0[i];
        w->ub[3 + i] = p->euler_max[i] - mu0[i];
    }
    if (p->force_constraint == 0) {
        /* joint: A_poly (f_b_m + df) <= b_poly */
        for (k = 0; k < fs->n; k++, n_cons++) {
            double *row = &w->C[n_cons * NV];
            if (!rows_known) {
                row[0] = fs->A[k][0], row[1] = fs->A[k][1], row[2] = fs->A[k][2];
                row[3] = row[4] = 0.0;
            }
            w->d[n_cons] = fs->d[k] - v3_dot(fs->A[k], f0);
        }
    } else {
        /* paper eq. (22)-(23): slice at f_bz_ref (clamped into the polytope's z range) */
        double fz = fmin(fmax(f_bz_ref, fs->fz[0]), fs->fz[1]);
        for (k = 0; k < fs->n; k++) {
            double ax = fs->A[k][0], ay = fs->A[k][1];
            if (ax * ax + ay * ay < 1e-18) continue;
            if (!rows_known) {
                for (j = 0; j < NV; j++) w->C[n_cons * NV + j] = 0.0;
                w->C[n_cons * NV] = ax;
                w->C[n_cons * NV + 1] = ay;
            }
            w->d[n_cons] = fs->d[k] - fs->A[k][2] * fz - ax * f0[0] - ay * f0[1];
            n_cons++;
        }
        w->lb[2] = fs->fz[0] - f0[2];
        w->ub[2] = fs->fz[1] - f0[2];
    }
    w->n_cons = n_cons;
    w->c_unchanged = rows_known; /* the solver keeps the rows' norms */
    *c_rows = key;
}

/* The constraints active at the QP's solution (guid_flags): the solver's final working set,
 * whose constraints hold with equality at x (no second pass over the polytope's rows). */
static int32_t active_constraints(const FpWls *w) {
    int32_t flags = 0;
    int k;
    for (k = 0; k < w->n_cons; k++)
        if (w->cons_ws[k]) {
            flags |= 1;
            break; /* one is enough */
        }
    if (w->bound_ws[3] != 0) flags |= 2;
    if (w->bound_ws[4] != 0) flags |= 4;
    return flags;
}

/* eq. (7): is the reference pose feasible?  f_p = R_ref^T f_w_ref in the force set. */
static int32_t reference_feasible(const CtrlForceSet *fs, const double f_p[3]) {
    int k;
    for (k = 0; k < fs->n; k++) /* 1 uN of slack: flat sets (quadrotor) have b = 0 facets */
        if (v3_dot(fs->A[k], f_p) > fs->d[k] + 1e-6 * (1.0 + fabs(fs->d[k]))) return 0;
    return 1;
}

void ctrl_guidance(const CtrlGuidanceParams *p, const CtrlForceSet *fs,
                   const CtrlGuidanceInputs *in, const CtrlFiltered *s, CtrlGuidanceState *st,
                   CtrlGuidanceOut *out) {
    FpWls *w = st->qp;
    FpWlsResult res;
    OuterIndi o;
    double rf[3], t0;
    int i;
    outer_loop(p, in, s, st, out->acc_c, o.dacc);
    o.r = s->r_m, o.dr_dphi = s->dr_dphi_m, o.dr_dtheta = s->dr_dtheta_m;
    /* eq. (20)-(21) */
    m3_mul_v(o.r, s->f_b_m, rf);
    for (i = 0; i < 3; i++) o.f_w_ref[i] = p->mass * o.dacc[i] + rf[i];
    for (i = 0; i < 3; i++)
        out->f_b_ref[i] = o.r[i] * o.f_w_ref[0] + o.r[3 + i] * o.f_w_ref[1] +
                          o.r[6 + i] * o.f_w_ref[2];
    for (i = 0; i < 3; i++)
        o.f_p[i] = in->r_ref[i] * o.f_w_ref[0] + in->r_ref[3 + i] * o.f_w_ref[1] +
                   in->r_ref[6 + i] * o.f_w_ref[2];
    build_qp(p, fs, in->mu_ref, s->mu_m, s->f_b_m, &o, out->f_b_ref[2], st->c_rows, w);
    t0 = p->timing ? fp_clock_seconds() : 0.0;
    fp_wls_solve_brief(w, p->max_iter, &res);
    if (p->timing) out->t_solve = fp_clock_seconds() - t0;
    out->status = res.status;
    out->iterations = res.iterations;
    for (i = 0; i < 3; i++) out->df_c[i] = w->x[i];
    out->mu_c[0] = s->mu_m[0] + w->x[3];
    out->mu_c[1] = s->mu_m[1] + w->x[4];
    out->mu_c[2] = in->mu_ref[2];
    out->flags = active_constraints(w);
    out->feasible = reference_feasible(fs, o.f_p);
    for (i = 0; i < 3; i++) out->f_b_c[i] = s->f_b_m[i] + out->df_c[i];
}

/*
 * The reference twin: a virtual vehicle that flies the reference exactly (no disturbance,
 * no tracking error) and realizes every force and attitude it commands.  Its guidance QP
 * is the vehicle's own (eq. 17-23), linearized at the twin's last pose instead of the
 * measurement, so its attitude mu_ff is the mu_c the guidance commands when tracking is
 * exact.  Its rate is the feed-forward consistent with mu_c; it depends on the reference
 * alone, so it never feeds the measured rate back (differentiating mu_c itself would:
 * mu_c = mu_m + dmu).  Where the reference pose is feasible mu_ff = mu_ref exactly and no
 * QP is solved.
 */
void ctrl_guidance_twin(const CtrlGuidanceParams *p, const CtrlForceSet *fs,
                        const double acc_ref[3], const double mu_ref[3],
                        const double r_ref[9], double g, CtrlTwin *tw, FpWls *w,
                        double mu_ff[3]) {
    OuterIndi o;
    FpWlsResult res;
    double r[9], dr_dphi[9], dr_dtheta[9], mu0[3], f0[3], rf[3], f_bz;
    int i;
    for (i = 0; i < 3; i++) o.f_w_ref[i] = p->mass * (acc_ref[i] - (i == 2 ? g : 0.0));
    for (i = 0; i < 3; i++)
        o.f_p[i] = r_ref[i] * o.f_w_ref[0] + r_ref[3 + i] * o.f_w_ref[1] +
                   r_ref[6 + i] * o.f_w_ref[2];
    if (reference_feasible(fs, o.f_p)) {
        memcpy(mu_ff, mu_ref, 3 * sizeof(double));
        memcpy(tw->mu, mu_ref, sizeof tw->mu);
        memcpy(tw->f, o.f_p, sizeof tw->f);
        tw->active = 0;
        return;
    }
    mu0[0] = tw->mu[0], mu0[1] = tw->mu[1], mu0[2] = mu_ref[2];
    memcpy(f0, tw->f, sizeof f0);
    rot_zyx_jacobian(mu0, r, dr_dphi, dr_dtheta);
    o.r = r, o.dr_dphi = dr_dphi, o.dr_dtheta = dr_dtheta;
    m3_mul_v(o.r, f0, rf);
    for (i = 0; i < 3; i++) o.dacc[i] = (o.f_w_ref[i] - rf[i]) / p->mass;
    f_bz = o.r[2] * o.f_w_ref[0] + o.r[5] * o.f_w_ref[1] + o.r[8] * o.f_w_ref[2];
    build_qp(p, fs, mu_ref, mu0, f0, &o, f_bz, &tw->c_rows, w);
    fp_wls_solve_brief(w, p->max_iter, &res);
    for (i = 0; i < 3; i++) tw->f[i] = f0[i] + w->x[i];
    tw->mu[0] = mu0[0] + w->x[3];
    tw->mu[1] = mu0[1] + w->x[4];
    tw->mu[2] = mu_ref[2];
    if (!fp_all_finite(tw->mu, 3) || !fp_all_finite(tw->f, 3)) {
        /* never a non-finite feed-forward: start again from the reference pose */
        fp_wls_reset(w);
        memcpy(tw->mu, mu_ref, sizeof tw->mu);
        memcpy(tw->f, o.f_p, sizeof tw->f);
    }
    memcpy(mu_ff, tw->mu, 3 * sizeof(double));
    tw->active = 1;
}
