/*
 * Phase 1 of the active-set solver (see wls.c): a feasible start by projecting onto the
 * constraints with the dual method of Goldfarb and Idnani, and when the set is infeasible
 * the point of least largest (row-normalised) violation by a minimax phase 1.
 */
#include "wls_internal.h"

/* Largest scaled violation of the usable rows at k->x (phase-2 view); *arg = row. */
static double row_violation(Ctx *c, int *arg) {
    FpWlsWork *k = c->k;
    double v = -INFINITY;
    int i;
    *arg = -1;
    double cx4[4];
    for (i = 0; i < c->w->n_cons; i++) {
        double s;
        if (i % 4 == 0) crow_dots(c, i, k->x, cx4);
        if (!k->use[i]) continue;
        s = cx4[i % 4] - dval(c, i);
        if (s > v) {
            v = s;
            *arg = i;
        }
    }
    return v;
}

/* The weights of t in the minimax rows, so that t measures each row's violation in the
 * caller's units: row i of the iteration (unit norm in the scaled variables) is
 * (C_i x - d_i) / |C_i S|, S the column scaling, and its violation over |C_i| (the caller's
 * row normalised, as wls.h documents x) is that over rho_i = |C_i| / |C_i S|.  The rows
 * C_i x - rho_i t <= d_i hold for t >= every such violation; tw = rho / max rho keeps the
 * column of t at most 1 (a constant factor on t changes no minimiser), so that t <= tol_feas
 * still means every row holds within tol_feas.  Without scaling every tw is 1. */
static void minimax_weights(Ctx *c) {
    FpWlsWork *k = c->k;
    double top = 0.0;
    int i;
    for (i = 0; i < c->w->n_cons; i++) {
        k->tw[i] = 1.0;
        if (c->C == c->w->C || !k->use[i]) continue;
        k->tw[i] = vnorm(c->w->C + i * c->n, c->n) * k->cinv[i];
        if (k->tw[i] > top) top = k->tw[i];
    }
    for (i = 0; top > 0.0 && i < c->w->n_cons; i++)
        if (k->use[i]) k->tw[i] /= top;
}

/* Minimax phase 1 from k->x (within the bounds, k->state consistent with it), whose largest
 * scaled violation is above tol_feas: the start t is the largest weighted violation. */
static int phase1_minimax(Ctx *c, int max_iter, int *iter) {
    FpWlsWork *k = c->k;
    int rc, i, n = c->n, arg = -1;
    double t0 = 0.0, cx4[4];
    minimax_weights(c);
    for (i = 0; i < c->w->n_cons; i++) {
        double v;
        if (i % 4 == 0) crow_dots(c, i, k->x, cx4); /* phase-2 view: nv == n */
        if (!k->use[i]) continue;
        v = (cx4[i % 4] - dval(c, i)) / k->tw[i];
        if (arg < 0 || v > t0) {
            t0 = v;
            arg = i;
        }
    }
    c->ph1 = 1;
    c->nv = n + 1;
    c->bland = 0;
    c->stall = 0;
    k->x[n] = t0;
    k->state[n] = ST_FREE;
    for (i = 0; i < c->w->n_cons; i++) k->act[i] = 0;
    if (arg >= 0) k->act[arg] = 1;
    rc = wls_run(c, max_iter, iter);
    c->ph1 = 0;
    c->nv = n;
    c->bland = 0;
    c->stall = 0;
    if (rc == RUN_OPTIMAL) rc = k->x[n] <= c->tol_feas ? RUN_FEASIBLE : RUN_INFEASIBLE;
    return rc;
}

/* Phase 1 proper: project the start x0 = k->x (within the bounds, every
 * variable free except lb == ub) onto the feasible set, min ||x - x0||^2, by
 * the dual method of Goldfarb and Idnani (identity Hessian, so J = Q).  It
 * needs no feasible start, adds the most violated constraint at a time and
 * ends at a feasible point whose working set is tight and independent, or
 * with a proof of infeasibility (a violated constraint whose normal is a
 * non-positive combination of the active ones).  first >= 0: the first constraint to add
 * is row first of C (the caller found it by the same scan at this point). */
static int phase1_project(Ctx *c, int first, int max_iter, int *iter) {
    FpWlsWork *k = c->k;
    FpWls *w = c->w;
    int n = c->n, i, j, q;
    double cx4[4];
    for (j = 0; j < NV1; j++) k->mub[j] = 0.0;
    for (i = 0; i < w->n_cons; i++) k->mur[i] = 0.0;
    for (;;) {
        int pidx = -1, psign = 0;
        double pv = c->tol_feas, up = 0.0;
        if (first >= 0) { /* the caller's scan of this very point found it */
            pidx = n + first;
            first = -1;
        } else {
            for (j = 0; j < n; j++) {
                if (k->state[j] != ST_FREE) continue;
                if (c->lb[j] - k->x[j] > pv) {
                    pv = c->lb[j] - k->x[j];
                    pidx = j;
                    psign = -1;
                } else if (k->x[j] - c->ub[j] > pv) {
                    pv = k->x[j] - c->ub[j];
                    pidx = j;
                    psign = 1;
                }
            }
            for (i = 0; i < w->n_cons; i++) {
                double v;
                if (i % 4 == 0) crow_dots(c, i, k->x, cx4);
                if (!k->use[i] || k->act[i]) continue;
                v = cx4[i % 4] - dval(c, i);
                if (v > pv) {
                    pv = v;
                    pidx = n + i;
                }
            }
        }
        if (pidx < 0) return RUN_FEASIBLE;
        for (;;) {
            double *nv = k->nvec, *z = k->zvec, *rr = k->rr, *rb = k->rb;
            double viol, zz = 0.0, nn = 0.0, tau1, tau2 = INFINITY, tau;
            int l = -1;
            if (*iter >= max_iter) return RUN_CAP;
            ++*iter;
            wls_factor_ws(c);
            for (j = 0; j < n; j++) nv[j] = 0.0;
            if (pidx < n) {
                nv[pidx] = (double)psign;
                viol = psign > 0 ? k->x[pidx] - c->ub[pidx] : c->lb[pidx] - k->x[pidx];
            } else {
                for (j = 0; j < n; j++) nv[j] = cval(c, pidx - n, j);
                viol = crow_dot(c, pidx - n, k->x) - dval(c, pidx - n);
            }
            if (viol <= c->tol_feas) break; /* satisfied on the way */
            wls_decompose(c, nv, z, rr, rb);
            for (q = 0; q < c->nf; q++) {
                j = k->free_idx[q];
                zz += nv[j] * z[j];
                nn += nv[j] * nv[j];
            }
            tau1 = sqrt(fabs(zz)) > TOL_GI * sqrt(nn) ? viol / zz : INFINITY;
            for (j = 0; j < n; j++) {
                double ratio;
                if ((k->state[j] != ST_LB && k->state[j] != ST_UB) || !(rb[j] > TOL_GI)) continue;
                ratio = k->mub[j] / rb[j];
                if (ratio < tau2) {
                    tau2 = ratio;
                    l = j;
                }
            }
            for (q = 0; q < c->nw; q++) {
                double ratio;
                if (!(rr[q] > TOL_GI)) continue;
                ratio = k->mur[k->act_idx[q]] / rr[q];
                if (ratio < tau2) {
                    tau2 = ratio;
                    l = n + k->act_idx[q];
                }
            }
            if (tau1 == INFINITY && tau2 == INFINITY) return RUN_INFEASIBLE;
            tau = tau1 <= tau2 ? tau1 : tau2;
            for (q = 0; q < c->nf; q++) {
                j = k->free_idx[q];
                k->x[j] -= tau * z[j];
            }
            for (j = 0; j < n; j++) {
                if (k->state[j] != ST_LB && k->state[j] != ST_UB) continue;
                k->mub[j] -= tau * rb[j];
                if (k->mub[j] < 0.0) k->mub[j] = 0.0;
            }
            for (q = 0; q < c->nw; q++) {
                double *m = &k->mur[k->act_idx[q]];
                *m -= tau * rr[q];
                if (*m < 0.0) *m = 0.0;
            }
            up += tau;
            if (tau1 <= tau2) {
                if (pidx < n) {
                    k->state[pidx] = (int8_t)(psign > 0 ? ST_UB : ST_LB);
                    k->x[pidx] = psign > 0 ? c->ub[pidx] : c->lb[pidx];
                    k->mub[pidx] = up;
                } else {
                    k->act[pidx - n] = 1;
                    k->mur[pidx - n] = up;
                }
                break;
            }
            if (l < n) {
                k->state[l] = ST_FREE;
                k->mub[l] = 0.0;
            } else {
                k->act[l - n] = 0;
                k->mur[l - n] = 0.0;
            }
        }
    }
}

/* Clamp the non-fixed variables of k->x into the bounds; with fix != 0 the
 * variables on a bound join the working set, otherwise all are freed. */
static void clamp_start(Ctx *c, int fix) {
    FpWlsWork *k = c->k;
    int j;
    for (j = 0; j < c->n; j++) {
        if (k->state[j] == ST_EQ) continue;
        k->state[j] = ST_FREE;
        if (k->x[j] <= c->lb[j]) {
            k->x[j] = c->lb[j];
            if (fix) k->state[j] = ST_LB;
        } else if (k->x[j] >= c->ub[j]) {
            k->x[j] = c->ub[j];
            if (fix) k->state[j] = ST_UB;
        }
    }
}

/* From any k->x: a feasible point with a consistent working set
 * (RUN_FEASIBLE), RUN_INFEASIBLE (x: minimax point, or the best found within
 * the cap), RUN_CAP (x: phase-1 iterate clamped into the bounds) or
 * RUN_NUMERIC. */
int wls_find_feasible(Ctx *c, int max_iter, int *iter) {
    FpWlsWork *k = c->k;
    int i, rc, arg;
    double viol;
    for (i = 0; i < c->w->n_cons; i++) k->act[i] = 0;
    clamp_start(c, 1);
    viol = row_violation(c, &arg);
    if (viol <= c->tol_feas) return RUN_FEASIBLE;
    /* x is within the bounds and every row inactive: the projection's first scan would find
     * row arg (the first of the largest violations, above tol_feas) */
    clamp_start(c, 0);
    rc = phase1_project(c, arg, max_iter, iter);
    if (rc == RUN_CAP) clamp_start(c, 0);
    if (rc != RUN_INFEASIBLE) return rc;
    /* Infeasible: the point of least largest violation, within the bounds. */
    for (i = 0; i < c->w->n_cons; i++) k->act[i] = 0;
    clamp_start(c, 1);
    viol = row_violation(c, &arg);
    if (viol <= c->tol_feas) return RUN_FEASIBLE;
    rc = phase1_minimax(c, max_iter, iter);
    if (rc == RUN_FEASIBLE || rc == RUN_NUMERIC) return rc;
    return RUN_INFEASIBLE;
}
