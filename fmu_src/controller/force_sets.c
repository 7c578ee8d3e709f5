/*
 * The feasible-force sets of the guidance: S(0) of the vehicle (paper eq. 6) and, for each
 * rotor, S(0) after losing it, given as polytopes {f_b : A f_b <= b}.  At initialization each
 * is validated and scaled about the hover force by poly_margin (the reserve for attitude
 * torques, which S(0) assumes zero, that also absorbs the outer approximation); while
 * flying the rotor losses pick the set in use.
 */
#include "fp_math.h"
#include "stages.h"

/* Support of the polytope {A f <= d} along +-e_axis, found with the WLS solver as
 * min (e.f - target)^2 + eps |f|^2: infeasible -> empty; huge -> unbounded. */
static FpWlsStatus polytope_support(FpWls *w, const double (*A)[3], const double *d, int n,
                                    int axis, double sign, double *value) {
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
        double lo, hi;
        FpWlsStatus s1 = polytope_support(scratch, A, b, n, axis, -1.0, &lo);
        FpWlsStatus s2 = polytope_support(scratch, A, b, n, axis, 1.0, &hi);
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

void ctrl_rotor_losses(int n_rotors, const double rotor_health[], const int32_t fail_poly_n[],
                       const int32_t hover_ok[], CtrlLosses *out) {
    int i, lost = -1;
    out->lost_mask = 0;
    out->rotors_lost = 0;
    for (i = 0; i < n_rotors; i++)
        if (rotor_health[i] < 0.5) {
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
