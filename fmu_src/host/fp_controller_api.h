/*
 * libfp_controller (installed in controller/lib/, used by controller/wls.py and
 * controller/qp_record.py): the constrained least-squares allocation solver of
 * common/wls.h, the very code the controller FMU runs, and the replay of the QPs a
 * FullPoseController solved.  Every function returns 0 on success, else a non-zero
 * FpStatus (fp_wls_solve_api, fp_wls_bench_api: FP_WARNING for a usable non-optimal x).
 *
 * The FpWls struct is opaque: allocate fp_wls_size() bytes.  The working set crosses the
 * API as int8[n_vars + n_cons]: first the bounds (-1 at lb, +1 at ub, 0 free), then the
 * rows of C (1 active, 0 not).  Arrays are packed row-major with row length n_vars.
 */
#ifndef FP_CONTROLLER_API_H
#define FP_CONTROLLER_API_H

#include <stdint.h>

#include "fp_api.h"

/* Size in bytes of the opaque solver buffer. */
FP_API int fp_wls_size(void);

/* caps[0..2] = FP_WLS_MAX_VARS, FP_WLS_MAX_ROWS, FP_WLS_MAX_CONS */
FP_API int fp_wls_caps(int32_t *caps);

/* fp_wls_setup: sizes checked against the caps, everything cleared. */
FP_API int fp_wls_setup_api(void *buffer, int n_vars, int n_rows, int n_cons);

/* fp_wls_set_data: any pointer NULL keeps the stored values. */
FP_API int fp_wls_set_data_api(void *buffer, const double *A, const double *b, const double *lb,
                               const double *ub, const double *C, const double *d);

/* Start of the next solve: x0[n_vars] (NULL keeps the stored x) and working set ws (NULL
 * keeps it). */
FP_API int fp_wls_set_start_api(void *buffer, const double *x0, const int8_t *ws);

/* The next solve's C is exactly the last solve's (FpWls.c_unchanged): it keeps the rows'
 * checks and norms and reads only d. */
FP_API int fp_wls_keep_rows_api(void *buffer);

/* The working set of the last solve into ws[n_vars + n_cons]. */
FP_API int fp_wls_get_working_set_api(const void *buffer, int8_t *ws);

/* Solve; x[n_vars] gets the solution, info[4] = status, iterations, phase-1 iterations,
 * warm start flag; fout[2] = objective, max violation. */
FP_API int fp_wls_solve_api(void *buffer, int max_iter, double *x, int32_t *info, double *fout);

/* Benchmark: solve the stored problem `repeats` times, each time from the same start (the
 * x and working set stored on entry), and write each solve's wall time in ns to
 * ns_out[repeats] (from the second solve on with C's rows kept, as the controller solves
 * with a constant force set); x, info and fout as fp_wls_solve_api for the last solve.  The struct
 * is left as after the last solve. */
FP_API int fp_wls_bench_api(void *buffer, int max_iter, int repeats, double *ns_out, double *x,
                            int32_t *info, double *fout);

/*
 * The last guidance (which = 0), inner-allocation (which = 1) or reference-twin (which = 2)
 * QP of a FullPoseController, read from its serialized FMU state (fmi2SerializeFMUstate):
 * the model struct is the tail of the serialized bytes.  dims receives
 * [n_vars, n_rows, n_cons]; the arrays are packed row-major with row length
 * n_vars and must hold the solver caps (FP_WLS_MAX_*).  x is the solution the
 * controller used.  Lets benchmarks and tests replay the very problems solved.
 */
FP_API int fp_controller_state_qp(const unsigned char *state, long size, int which,
                                  int32_t *dims, double *A, double *b, double *lb, double *ub,
                                  double *C, double *d, double *x);

/*
 * The controller's own derivation of a feasible-force set (controller/derive_sets.h): S(0)
 * of the rotors of rotor_set (a buffer made by libfp_multirotor's
 * fp_rotor_set_from_airframe: the same FpRotorSet) without those in lost_mask (bit i: rotor i + 1), as at most cap facets
 * A[cap][3] f <= b[cap].  info[5] = status (0 ok, 1 empty, 2 failed), facets, dimension,
 * LP solves, LP pivots; *ns the wall time in ns; why[why_size] the reason of a failure.
 */
FP_API int fp_derive_force_set_api(const void *rotor_set, int lost_mask, int cap, double *A,
                                   double *b, int32_t *info, double *ns, char *why,
                                   int why_size);

#endif
