/*
 * libfp_controller: the C API of the allocation solver and of the controller's QP replay
 * (fp_controller_api.h), wrapping the very code the controller FMU runs.
 */
#if !defined(_WIN32) && !defined(_POSIX_C_SOURCE)
#define _POSIX_C_SOURCE 199309L /* clock_gettime for fp_wls_bench_api */
#endif
#include "fp_controller_api.h"

#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "controller.h"
#include "derive_sets.h"
#include "wls.h"

FP_API int fp_wls_size(void) { return (int)sizeof(FpWls); }

/* caps[0..2] = FP_WLS_MAX_VARS, FP_WLS_MAX_ROWS, FP_WLS_MAX_CONS */
FP_API int fp_wls_caps(int32_t *caps) {
    caps[0] = FP_WLS_MAX_VARS;
    caps[1] = FP_WLS_MAX_ROWS;
    caps[2] = FP_WLS_MAX_CONS;
    return FP_OK;
}

FP_API int fp_wls_setup_api(void *buffer, int n_vars, int n_rows, int n_cons) {
    return fp_wls_setup((FpWls *)buffer, n_vars, n_rows, n_cons);
}

FP_API int fp_wls_set_data_api(void *buffer, const double *A, const double *b, const double *lb,
                               const double *ub, const double *C, const double *d) {
    return fp_wls_set_data((FpWls *)buffer, A, b, lb, ub, C, d);
}

/* The buffer holds a set-up solver (sizes within the caps). */
static int wls_sizes_ok(const FpWls *w) {
    return w != NULL && w->n_vars >= 1 && w->n_vars <= FP_WLS_MAX_VARS && w->n_rows >= 0 &&
           w->n_rows <= FP_WLS_MAX_ROWS && w->n_cons >= 0 && w->n_cons <= FP_WLS_MAX_CONS;
}

FP_API int fp_wls_set_start_api(void *buffer, const double *x0, const int8_t *ws) {
    FpWls *w = (FpWls *)buffer;
    if (!wls_sizes_ok(w)) return FP_ERROR;
    if (x0 != NULL) memcpy(w->x, x0, (size_t)w->n_vars * sizeof(double));
    if (ws != NULL) {
        memcpy(w->bound_ws, ws, (size_t)w->n_vars);
        memcpy(w->cons_ws, ws + w->n_vars, (size_t)w->n_cons);
    }
    return FP_OK;
}

FP_API int fp_wls_keep_rows_api(void *buffer) {
    FpWls *w = (FpWls *)buffer;
    if (!wls_sizes_ok(w)) return FP_ERROR;
    w->c_unchanged = 1;
    return FP_OK;
}

FP_API int fp_wls_get_working_set_api(const void *buffer, int8_t *ws) {
    const FpWls *w = (const FpWls *)buffer;
    if (!wls_sizes_ok(w) || ws == NULL) return FP_ERROR;
    memcpy(ws, w->bound_ws, (size_t)w->n_vars);
    memcpy(ws + w->n_vars, w->cons_ws, (size_t)w->n_cons);
    return FP_OK;
}

/* A solve's result into the caller's arrays (see fp_wls_solve_api). */
static void report(const FpWls *w, const FpWlsResult *res, double *x, int32_t *info,
                   double *fout) {
    if (x != NULL) memcpy(x, w->x, (size_t)w->n_vars * sizeof(double));
    info[0] = (int32_t)res->status;
    info[1] = res->iterations;
    info[2] = res->phase1_iterations;
    info[3] = res->warm_start;
    fout[0] = res->objective;
    fout[1] = res->max_violation;
}

/* Solve; x[n_vars] gets the solution, info[4] = status, iterations,
 * phase-1 iterations, warm start flag; fout[2] = objective, max violation. */
FP_API int fp_wls_solve_api(void *buffer, int max_iter, double *x, int32_t *info, double *fout) {
    FpWls *w = (FpWls *)buffer;
    FpWlsResult res;
    FpStatus st;
    if (!wls_sizes_ok(w) || info == NULL || fout == NULL) return FP_ERROR;
    st = fp_wls_solve(w, max_iter, &res);
    report(w, &res, x, info, fout);
    return st;
}

static double fp_now_ns(void) {
#if defined(CLOCK_MONOTONIC)
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double)ts.tv_sec * 1e9 + (double)ts.tv_nsec;
#else
    return (double)clock() * (1e9 / (double)CLOCKS_PER_SEC);
#endif
}

/* Benchmark: solve the stored problem `repeats` times, each time from the same
 * start (the x and working set stored on entry), and write each solve's wall
 * time in ns to ns_out[repeats] (fp_wls_solve_brief, as the controller solves; from the
 * second solve on with C's rows kept, as the controller's guidance with a constant force
 * set); x, info
 * and fout as fp_wls_solve_api for the last solve.  The struct is left as after the last solve. */
FP_API int fp_wls_bench_api(void *buffer, int max_iter, int repeats, double *ns_out, double *x,
                            int32_t *info, double *fout) {
    FpWls *w = (FpWls *)buffer;
    double x0[FP_WLS_MAX_VARS];
    int8_t bws[FP_WLS_MAX_VARS], cws[FP_WLS_MAX_CONS];
    FpWlsResult res;
    FpStatus st = FP_OK;
    int r;
    if (!wls_sizes_ok(w) || repeats < 1 || ns_out == NULL || info == NULL || fout == NULL)
        return FP_ERROR;
    memcpy(x0, w->x, sizeof x0);
    memcpy(bws, w->bound_ws, sizeof bws);
    memcpy(cws, w->cons_ws, sizeof cws);
    for (r = 0; r < repeats; r++) {
        double t0, t1;
        memcpy(w->x, x0, sizeof x0);
        memcpy(w->bound_ws, bws, sizeof bws);
        memcpy(w->cons_ws, cws, sizeof cws);
        w->c_unchanged = r > 0; /* as the controller's constant force set: rows kept */
        t0 = fp_now_ns();
        st = fp_wls_solve_brief(w, max_iter, &res); /* as the controller solves */
        t1 = fp_now_ns();
        ns_out[r] = t1 - t0;
    }
    /* the last solve once more, untimed, for the objective and the violation */
    memcpy(w->x, x0, sizeof x0);
    memcpy(w->bound_ws, bws, sizeof bws);
    memcpy(w->cons_ws, cws, sizeof cws);
    st = fp_wls_solve(w, max_iter, &res);
    report(w, &res, x, info, fout);
    return st;
}

/*
 * The last guidance (which = 0), inner-allocation (which = 1) or reference-twin (which = 2)
 * QP of a FullPoseController, read from its serialized FMU state (fmi2SerializeFMUstate):
 * the model struct is the tail of the serialized bytes.  dims receives
 * [n_vars, n_rows, n_cons]; the arrays are packed row-major with row length
 * n_vars and must hold the solver caps (FP_WLS_MAX_*).  x is the solution the
 * controller used.  Lets benchmarks and tests replay the very problems solved.
 */
FP_API int fp_controller_state_qp(const unsigned char *state, long size, int which, int32_t *dims,
                                  double *A, double *b, double *lb, double *ub, double *C,
                                  double *d, double *x) {
    const ControllerModel *m;
    const FpWls *w;
    static const size_t model_size = sizeof(ControllerModel);
    size_t nv, nr, nc;
    if (state == NULL || size < (long)model_size || (which < 0 || which > 2)) return FP_ERROR;
    m = (const ControllerModel *)(const void *)(state + (size_t)size - model_size);
    w = which == 0 ? &m->guid : which == 1 ? &m->alloc : &m->twin_qp;
    if (w->n_vars < 1 || w->n_vars > FP_WLS_MAX_VARS || w->n_rows < 0 ||
        w->n_rows > FP_WLS_MAX_ROWS || w->n_cons < 0 || w->n_cons > FP_WLS_MAX_CONS)
        return FP_ERROR;
    nv = (size_t)w->n_vars, nr = (size_t)w->n_rows, nc = (size_t)w->n_cons;
    dims[0] = w->n_vars, dims[1] = w->n_rows, dims[2] = w->n_cons;
    memcpy(A, w->A, nr * nv * sizeof(double));
    memcpy(b, w->b, nr * sizeof(double));
    memcpy(lb, w->lb, nv * sizeof(double));
    memcpy(ub, w->ub, nv * sizeof(double));
    memcpy(C, w->C, nc * nv * sizeof(double));
    memcpy(d, w->d, nc * sizeof(double));
    memcpy(x, w->x, nv * sizeof(double));
    return FP_OK;
}

FP_API int fp_derive_force_set_api(const void *rotor_set, int lost_mask, int cap, double *A,
                                   double *b, int32_t *info, double *ns, char *why,
                                   int why_size) {
    CtrlSetWork *w = (CtrlSetWork *)malloc(sizeof *w); /* host code: the FMU uses its stack */
    double t0;
    int32_t n = 0, dim = -1;
    CtrlSetStatus s;
    if (!w) return FP_ERROR;
    memset(w, 0, sizeof *w);
    t0 = fp_now_ns();
    s = ctrl_derive_force_set((const FpRotorSet *)rotor_set, lost_mask, cap, w,
                              (double(*)[3])A, b, &n, &dim, why, why_size);
    *ns = fp_now_ns() - t0;
    info[0] = (int32_t)s, info[1] = n, info[2] = dim;
    info[3] = (int32_t)w->lp_solves, info[4] = (int32_t)w->lp_pivots;
    free(w);
    return FP_OK;
}
