/*
 * The active-set loop of the solver (see wls.c for the method): from a feasible point with
 * a consistent working set, the ratio test and the step, the multipliers at the face
 * minimiser and the constraint to drop, and the anti-cycling rule.  Phase 2 and the minimax
 * phase 1 (wls_phase1.c) run it; the driver (wls.c) also uses its clamp, multipliers and
 * drop after the first iteration.
 */
#include "wls_internal.h"

/* Clamp free variables into their bounds (removes rounding overshoot). */
void wls_clamp_free(Ctx *c) {
    FpWlsWork *k = c->k;
    int q;
    for (q = 0; q < c->nf; q++) {
        int j = k->free_idx[q];
        if (k->x[j] < lbv(c, j)) k->x[j] = lbv(c, j);
        if (k->x[j] > ubv(c, j)) k->x[j] = ubv(c, j);
    }
}

/* Ratio test along p and the step; adds the blocking bound or row.
 * Returns 1 if a constraint was added, 0 for a full step.  *moved tells
 * whether x changed noticeably. */
static int ratio_step(Ctx *c, int *moved) {
    FpWlsWork *k = c->k;
    int q, i, blk = -1, nv = c->nv;
    double pn = vnorm(k->p, nv), amin = 1.0, alpha_blk = 2.0, rate_blk = 0.0;
    double xinf = inf_norm(k->x, nv), pinf = inf_norm(k->p, nv), cp4[4], cx4[4];
    /* ties are judged as distances along the step: with a huge face step (an
     * ill-conditioned face) a fixed 1e-12 in step fraction is O(1) in x, and snapping
     * x onto the tied constraint's bound would leave another one violated */
    double tie = (pinf > 0.0 && c->tol_feas / pinf < TOL_TIE) ? c->tol_feas / pinf : TOL_TIE;
    /* candidates: global index j < nv for bounds, nv + i for rows */
    for (q = 0; q < c->nf; q++) {
        int j = k->free_idx[q];
        double pj = k->p[j], s, ratio, rate;
        if (pj > TOL_BLOCK_B * pn && isfinite(ubv(c, j))) {
            s = ubv(c, j) - k->x[j];
            rate = pj / pn;
            ratio = (s > 0.0 ? s : 0.0) / pj;
        } else if (pj < -TOL_BLOCK_B * pn && isfinite(lbv(c, j))) {
            s = k->x[j] - lbv(c, j);
            rate = -pj / pn;
            ratio = (s > 0.0 ? s : 0.0) / -pj;
        } else {
            continue;
        }
        if (ratio < amin) amin = ratio;
        if (ratio < alpha_blk - tie ||
            (ratio <= alpha_blk + tie && !c->bland && rate > rate_blk)) {
            if (ratio < 1.0 || (blk >= 0 && ratio <= 1.0)) {
                blk = j;
                alpha_blk = ratio;
                rate_blk = rate;
            }
        }
    }
    for (i = 0; i < c->w->n_cons; i++) {
        /* c'p over the free variables in index order: crow_dot(p), p being zero on the
         * fixed ones (their zero terms change no non-zero sum); four rows at a time */
        double cp, s, ratio, rate;
        if (i % 4 == 0) {
            crow_dots(c, i, k->p, cp4);
            crow_dots(c, i, k->x, cx4);
        }
        if (!k->use[i] || k->act[i]) continue;
        cp = cp4[i % 4];
        if (!(cp > TOL_BLOCK * pn)) continue;
        s = dval(c, i) - cx4[i % 4];
        rate = cp / pn;
        ratio = (s > 0.0 ? s : 0.0) / cp;
        if (ratio < amin) amin = ratio;
        if (ratio < alpha_blk - tie ||
            (ratio <= alpha_blk + tie && !c->bland && rate > rate_blk)) {
            if (ratio < 1.0 || (blk >= 0 && ratio <= 1.0)) {
                blk = nv + i;
                alpha_blk = ratio;
                rate_blk = rate;
            }
        }
    }
    if (blk < 0) amin = 1.0;
    for (q = 0; q < c->nf; q++) {
        int j = k->free_idx[q];
        k->x[j] += amin * k->p[j];
    }
    *moved = amin * inf_norm(k->p, nv) > TOL_STEP * (xinf > 1.0 ? xinf : 1.0);
    if (blk < 0) {
        wls_clamp_free(c);
        return 0;
    }
    if (blk < nv) {
        int up = k->p[blk] > 0.0;
        k->x[blk] = up ? ubv(c, blk) : lbv(c, blk);
        k->state[blk] = (int8_t)(up ? ST_UB : ST_LB);
    } else {
        k->act[blk - nv] = 1;
    }
    wls_clamp_free(c);
    return 1;
}

/* Multipliers at the face minimiser (needs factor_ws for the current set).
 * Returns the global index of the constraint to drop, or -1 if none. */
int wls_pick_drop(Ctx *c) {
    FpWlsWork *k = c->k;
    int nv = c->nv, nw = c->nw, nr = nrows(c), i, j, q, drop = -1;
    double *lam = k->rr, *mu = k->rb, worst, tol, xn = vnorm(k->x, nv), gs = 0.0;
    /* per variable: the rounding scale of its own gradient entry, so that a badly scaled
     * column's bound multiplier is judged on its own scale, not on the largest column's */
    double gsj[FP_WLS_MAX_VARS + 1], tolj[FP_WLS_MAX_VARS + 1];
    /* no multiplier to judge (no active row, no variable at a bound): nothing to drop */
    if (nw == 0) {
        int fixed = 0;
        for (j = 0; j < nv; j++) fixed |= k->state[j] == ST_LB || k->state[j] == ST_UB;
        if (!fixed) return -1;
    }
    /* gradient g = -2 A' r, and the scale of its rounding error:
     * 2 sum_i ||a_i|| (|r_i| + |b_i| + ||a_i|| ||x||), per variable with |a_ij| for the
     * first ||a_i|| */
    residual(c);
    for (j = 0; j < nv; j++) gsj[j] = 0.0;
    if (c->ph1) {
        for (j = 0; j < nv; j++) k->g[j] = j == c->n ? -2.0 * k->r[0] : 0.0;
        gs = 2.0 * (fabs(k->r[0]) + xn);
        for (j = 0; j < nv; j++) gsj[j] = gs;
    } else {
        /* without an active row only the variables at a bound have multipliers (mu_j =
         * -+g_j): their columns alone, each entry the same sum as with every column (the
         * allocation's face: a few of 18); gs, which only the rows' multipliers use, then
         * not at all */
        int cols[FP_WLS_MAX_VARS + 1], ncol = 0;
        double an4[4];
        /* a diagonal tail's rows have one non-zero each: only its terms (the zero terms
         * change no sum; each entry still sums over the rows in order) */
        int dense = c->diag_tail ? c->m0 : nr;
        for (j = 0; j < nv; j++) {
            k->g[j] = 0.0;
            if (nw > 0 || k->state[j] == ST_LB || k->state[j] == ST_UB) cols[ncol++] = j;
        }
        for (i = 0; i < dense; i++) {
            const double *a = c->A + i * c->n;
            double ri = -2.0 * k->r[i], an;
            if (i % 4 == 0) vnorm4(a, c->n, dense - i < 4 ? dense - i : 4, nv, an4);
            an = an4[i % 4];
            double ei = fabs(k->r[i]) + fabs(c->w->b[i]) + an * xn;
            for (q = 0; q < ncol; q++) {
                j = cols[q];
                k->g[j] += a[j] * ri;
                gsj[j] += 2.0 * fabs(a[j]) * ei;
            }
            gs += 2.0 * an * ei;
        }
        for (q = 0; dense < nr && q < ncol; q++) { /* the diagonal row of each column */
            double dj, an, ei;
            j = cols[q];
            i = dense + j;
            dj = tail_d(c, j);
            an = vnorm(&dj, 1); /* = vnorm of the row */
            ei = fabs(k->r[i]) + fabs(c->w->b[i]) + an * xn;
            k->g[j] += dj * (-2.0 * k->r[i]);
            gsj[j] += 2.0 * fabs(dj) * ei;
            gs += 2.0 * an * ei;
        }
    }
    tol = TOL_MULT * gs;
    if (!(tol > DBL_MIN)) tol = DBL_MIN;
    for (j = 0; j < nv; j++) {
        /* a bound's multiplier also carries the active rows' (mu_j = -g_j - sum lam c_j):
         * their rounding scale times the rows' entries in column j (a column zero in A has
         * no gradient of its own, and its multiplier is that share alone) */
        double share = 0.0;
        if (!c->ph1 && nw > 0 && (k->state[j] == ST_LB || k->state[j] == ST_UB))
            for (q = 0; q < nw; q++) share += fabs(cval(c, k->act_idx[q], j));
        tolj[j] = TOL_MULT * (gsj[j] + gs * share);
        if (!(tolj[j] > DBL_MIN)) tolj[j] = DBL_MIN;
    }
    /* stationarity: -g = sum lam c + sum mu n (+ z = 0 at the face minimiser); with no
     * active row that is mu_j = -g_j at an upper bound, g_j at a lower one */
    if (nw > 0) {
        for (j = 0; j < nv; j++) k->nvec[j] = -k->g[j];
        wls_decompose(c, k->nvec, k->zvec, lam, mu);
    } else {
        for (j = 0; j < nv; j++) mu[j] = k->state[j] == ST_UB ? -k->g[j] : k->g[j];
    }
    /* the most negative multiplier relative to its own tolerance */
    worst = -1.0;
    for (j = 0; j < nv; j++) {
        if (k->state[j] != ST_LB && k->state[j] != ST_UB) continue;
        if (c->bland) {
            if (mu[j] < -tolj[j]) return j;
        } else if (mu[j] / tolj[j] < worst) {
            worst = mu[j] / tolj[j];
            drop = j;
        }
    }
    for (q = 0; q < nw; q++) {
        if (c->bland) {
            if (lam[q] < -tol) return nv + k->act_idx[q];
        } else if (lam[q] / tol < worst) {
            worst = lam[q] / tol;
            drop = nv + k->act_idx[q];
        }
    }
    return drop;
}

void wls_drop_constraint(Ctx *c, int idx) {
    if (idx < c->nv)
        c->k->state[idx] = ST_FREE;
    else
        c->k->act[idx - c->nv] = 0;
}

/* Anti-cycling: after STALL_BLAND iterations in a row that did not move x
 * (a degenerate vertex), choose by smallest index (Bland) until x moves. */
#define STALL_BLAND 50
static void stalled(Ctx *c, int moved) {
    c->stall = moved ? 0 : c->stall + 1;
    c->bland = c->stall >= STALL_BLAND;
}

/* The active-set loop from a feasible point with a consistent working set. */
int wls_run(Ctx *c, int max_iter, int *iter) {
    FpWlsWork *k = c->k;
    for (;;) {
        int moved = 0, drop;
        if (c->ph1 && k->x[c->n] <= c->tol_feas) return RUN_FEASIBLE;
        if (*iter >= max_iter) return RUN_CAP;
        ++*iter;
        wls_factor_ws(c);
        if (!wls_compute_step(c)) return RUN_NUMERIC;
        if (inf_norm(k->p, c->nv) > TOL_STEP * (inf_norm(k->x, c->nv) + DBL_MIN)) {
            if (ratio_step(c, &moved)) {
                stalled(c, moved);
                continue;
            }
            if (c->ph1 && k->x[c->n] <= c->tol_feas) return RUN_FEASIBLE;
        }
        drop = wls_pick_drop(c);
        if (drop < 0) return RUN_OPTIMAL;
        wls_drop_constraint(c, drop);
        stalled(c, moved);
    }
}
