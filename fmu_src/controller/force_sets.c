/*
 * The feasible-force sets of the guidance: S(0) of the vehicle (paper eq. 6) and, for each
 * rotor, S(0) after losing it, given as polytopes {f_b : A f_b <= b}.  At initialization each
 * is validated and scaled about the hover force by poly_margin (the reserve for attitude
 * torques, which S(0) assumes zero, that also absorbs the outer approximation); while
 * flying the rotor losses pick the set in use.
 */
#include <stdio.h>

#include "derive_sets.h"
#include "fp_math.h"
#include "stages.h"

/* Support h(c) = max c.f of the polytope {A f <= d}, found with the WLS solver as
 * min (c.f - far)^2 + eps |f|^2: infeasible -> empty; huge -> unbounded. */
static FpWlsStatus polytope_support(FpWls *w, const double (*A)[3], const double *d, int n,
                                    const double c[3], double *value) {
    FpWlsResult r;
    int i;
    const double far = 1e9;
    fp_wls_setup(w, 3, 4, n);
    for (i = 0; i < 3; i++) {
        w->A[i] = c[i];
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
    *value = v3_dot(c, w->x);
    return r.status;
}

/* Facets finite with non-zero normals, the set non-empty and bounded; its f_bz range.
 * FP_ERROR (logged, naming the parameters) otherwise. */
static FpStatus check_facets(FpCheck *c, const char *name, const double (*A)[3],
                             const double *b, int n, FpWls *scratch, double *fz_min,
                             double *fz_max) {
    int i, axis;
    for (i = 0; i < n; i++) {
        double norm = sqrt(v3_dot(A[i], A[i]));
        if (!isfinite(norm) || !isfinite(b[i]) || !(norm > 1e-9)) {
            fp_check_error(c, "parameters %s: facet %d must be finite with a non-zero normal",
                           name, i + 1);
            return FP_ERROR;
        }
    }
    for (axis = 0; axis < 3; axis++) {
        double lo, hi, down[3] = {0.0, 0.0, 0.0}, up[3] = {0.0, 0.0, 0.0};
        FpWlsStatus s1, s2;
        down[axis] = -1.0, up[axis] = 1.0;
        s1 = polytope_support(scratch, A, b, n, down, &lo);
        s2 = polytope_support(scratch, A, b, n, up, &hi);
        if (s1 == FP_WLS_INFEASIBLE || s2 == FP_WLS_INFEASIBLE) {
            fp_check_error(c, "parameters %s: the feasible-force polytope is empty", name);
            return FP_ERROR;
        }
        lo = -lo;
        if (s1 != FP_WLS_OPTIMAL || s2 != FP_WLS_OPTIMAL || hi > 1e6 || lo < -1e6) {
            fp_check_error(c,
                           "parameters %s: the feasible-force polytope is unbounded along body "
                           "axis %d",
                           name, axis + 1);
            return FP_ERROR;
        }
        if (axis == 2) {
            *fz_min = lo;
            *fz_max = hi;
        }
    }
    return FP_OK;
}

/* Offsets d of {A f <= b} scaled by the margin about the hover force; 0 when the
 * hover force is outside the set (d = b then). */
static int32_t scale_about_hover(const double (*A)[3], const double *b, int n, double hover_fz,
                                 double margin, double *d) {
    double hover[3] = {0.0, 0.0, 0.0};
    int i;
    int32_t inside = 1;
    hover[2] = hover_fz;
    for (i = 0; i < n; i++)
        if (!(v3_dot(A[i], hover) <= b[i] + 1e-9 * (1.0 + fabs(b[i])))) inside = 0;
    for (i = 0; i < n; i++) {
        double ah = v3_dot(A[i], hover);
        d[i] = inside ? ah + margin * (b[i] - ah) : b[i];
    }
    return inside;
}

FpStatus ctrl_force_set_prepare(FpCheck *c, const char *name, const double (*A)[3],
                                const double *b, int n, double hover_fz, double margin,
                                FpWls *scratch, double d[], double *fz_min, double *fz_max,
                                int32_t *hover_ok) {
    double lo = 0.0, hi = 0.0;
    if (check_facets(c, name, A, b, n, scratch, &lo, &hi) != FP_OK) return FP_ERROR;
    *hover_ok = scale_about_hover(A, b, n, hover_fz, margin, d);
    if (*hover_ok) { /* scaling about the hover force maps the f_bz range the same way */
        lo = hover_fz + margin * (lo - hover_fz);
        hi = hover_fz + margin * (hi - hover_fz);
    }
    *fz_min = lo;
    *fz_max = hi;
    return FP_OK;
}

void ctrl_rotor_losses(int n_rotors, const double rotor_health[], int32_t detected_lost,
                       const int32_t fail_poly_n[], const int32_t hover_ok[], CtrlLosses *out) {
    int i, lost = -1;
    out->lost_mask = 0;
    out->rotors_lost = 0;
    for (i = 0; i < n_rotors; i++)
        if (rotor_health[i] < 0.5 || ((detected_lost >> i) & 1)) {
            out->lost_mask |= (int32_t)1 << i;
            out->rotors_lost++;
            lost = i;
        }
    if (out->rotors_lost == 0) {
        out->active_polytope = 0;
        out->hover_possible = hover_ok[0];
    } else if (out->rotors_lost == 1 && fail_poly_n[lost] > 0) {
        out->active_polytope = lost + 1;
        out->hover_possible = hover_ok[lost + 1];
    } else {
        out->active_polytope = -1;
        out->hover_possible = 0;
    }
}

void ctrl_log_losses(const CtrlLosses *l, const FpLogger *logger) {
    if (l->rotors_lost == 0)
        fp_log(logger, FP_WARNING, FP_LOG_WARNING, "all rotors healthy: nominal force set");
    else if (l->active_polytope > 0)
        fp_log(logger, FP_WARNING, FP_LOG_WARNING,
               "rotor %d lost: allocations exclude it, guidance uses its feasible force set%s",
               (int)l->active_polytope, l->hover_possible ? "" : " (which cannot hold hover)");
    else
        fp_log(logger, FP_WARNING, FP_LOG_WARNING,
               "%d rotors lost (mask 0x%x): no feasible force set for this loss, hovering may "
               "be impossible; flying on with the remaining rotors",
               (int)l->rotors_lost, (unsigned)l->lost_mask);
}

/* ------------------------------------------------------------------------ */
/* The sets in use: given, or derived from the airframe                     */

/* The largest amount by which the given set {A f <= b} reaches beyond a facet of the
 * derived set (dA, db), and that facet (the given set checked bounded and non-empty). */
static double given_excess(FpWls *scratch, const CtrlGivenSet *g, const double dA[][3],
                           const double db[], int dn, int *worst) {
    double most = -INFINITY;
    int j;
    *worst = -1;
    for (j = 0; j < dn; j++) {
        double h;
        FpWlsStatus st = polytope_support(scratch, g->A, g->b, g->n, dA[j], &h);
        double excess = st == FP_WLS_OPTIMAL ? h - db[j] : -INFINITY;
        if (excess > most) most = excess, *worst = j;
    }
    return most;
}

/* One set: copy the given one (after checking it against the derivation) or derive it.
 * *n_out 0 with FP_OK: the derivation found the set empty. */
static FpStatus resolve_one(FpCheck *c, const FpRotorSet *rs, int32_t lost_mask,
                            const CtrlGivenSet *given, const char *name, int cap,
                            CtrlSetWork *work, FpWls *scratch, int32_t *n_out, double A[][3],
                            double b[], int *derived, CtrlSetStatus *status) {
    double dA[FP_POLYTOPE_MAX_FACETS][3], db[FP_POLYTOPE_MAX_FACETS];
    int32_t dn = 0, dim = 0, k;
    char why[120];
    double scale = rs->n * rs->k_t * rs->omega_max * rs->omega_max;
    *status = ctrl_derive_force_set(rs, lost_mask, cap, work, dA, db, &dn, &dim, why,
                                    (int)sizeof why);
    if (*status == CTRL_SET_FAILED && given->n == 0) {
        fp_check_error(c, "parameters %s: deriving the set from the airframe failed (%s); give "
                       "it explicitly", name, why);
        return FP_ERROR;
    }
    if (*status == CTRL_SET_FAILED)
        fp_check_warning(c, "parameters %s: the given set is used unchecked: deriving the "
                         "airframe's own failed (%s)", name, why);
    *derived = given->n == 0;
    if (given->n == 0) {
        *n_out = *status == CTRL_SET_OK ? dn : 0;
        for (k = 0; k < *n_out; k++) {
            A[k][0] = dA[k][0], A[k][1] = dA[k][1], A[k][2] = dA[k][2];
            b[k] = db[k];
        }
        return FP_OK;
    }
    {
        double lo, hi; /* a given set must be a bounded, non-empty polytope to compare */
        if (check_facets(c, name, given->A, given->b, given->n, scratch, &lo, &hi) != FP_OK)
            return FP_ERROR;
    }
    if (*status == CTRL_SET_OK) {
        int worst;
        double excess = given_excess(scratch, given, (const double(*)[3])dA, db, dn, &worst);
        if (excess > CTRL_SET_MISMATCH * scale) {
            fp_check_error(c,
                           "parameters %s: the given set reaches %.3g N beyond what the "
                           "airframe's rotors can produce (along [%.3f, %.3f, %.3f]; more than "
                           "%g of their total thrust %.3g N): it belongs to another vehicle; "
                           "set the count to 0 to derive it from the airframe",
                           name, excess, dA[worst][0], dA[worst][1], dA[worst][2],
                           CTRL_SET_MISMATCH, scale);
            return FP_ERROR;
        }
    } else if (*status == CTRL_SET_EMPTY) {
        fp_check_error(c,
                       "parameters %s: the airframe's remaining rotors cannot balance their "
                       "torques at any thrust, yet a non-empty set is given: it belongs to "
                       "another vehicle",
                       name);
        return FP_ERROR;
    }
    *n_out = given->n;
    for (k = 0; k < given->n; k++) {
        A[k][0] = given->A[k][0], A[k][1] = given->A[k][1], A[k][2] = given->A[k][2];
        b[k] = given->b[k];
    }
    return FP_OK;
}

FpStatus ctrl_force_sets_resolve(FpCheck *c, const FpRotorSet *rs, const CtrlGivenSet *s0, const CtrlGivenSet fail[],
                                 FpWls *scratch, int32_t *n_out, double A_out[][3],
                                 double b_out[], int32_t fail_n_out[], double fail_A_out[][3],
                                 double fail_b_out[], int32_t *derived) {
    CtrlSetWork work; /* ~53 kB, this call only */
    CtrlSetStatus status;
    int i, was_derived;
    char name[64];
    *derived = 0;
    if (resolve_one(c, rs, 0, s0, "poly_A, poly_b", FP_POLYTOPE_MAX_FACETS, &work, scratch,
                    n_out, A_out, b_out, &was_derived, &status) != FP_OK)
        return FP_ERROR;
    if (was_derived && status == CTRL_SET_EMPTY) {
        fp_check_error(c,
                       "parameters rotor_pos, rotor_dir, rotor_gamma, alpha/beta limits: no "
                       "combination of rotor thrusts and tilts balances the torques, so the "
                       "airframe has no force set to hover with (S(0) is empty)");
        return FP_ERROR;
    }
    *derived |= was_derived;
    for (i = 0; i < FP_MAX_ROTORS; i++) {
        int base = i * FP_FAIL_POLYTOPE_FACETS;
        fail_n_out[i] = 0;
        if (i >= rs->n) continue;
        snprintf(name, sizeof name, "fail_poly_A, fail_poly_b (rotor %d)", i + 1);
        if (resolve_one(c, rs, (int32_t)1 << i, &fail[i], name, FP_FAIL_POLYTOPE_FACETS, &work,
                        scratch, &fail_n_out[i], &fail_A_out[base], &fail_b_out[base],
                        &was_derived, &status) != FP_OK)
            return FP_ERROR;
        if (was_derived) *derived |= (int32_t)1 << (i + 1);
    }
    return FP_OK;
}
