/*
 * Step kernel of the Python co-simulation master (orchestrator/engine.py), libfp_cosim.
 *
 * The master builds the whole plan in Python on fmpy-loaded FMUs: connection
 * table, value references, the recording matrix and its layout, the coupling.
 * Running the per-step call sequence from Python costs ~0.35 us per FMI call
 * (ctypes), as much as a third of both FMUs' own work at 500 Hz; this kernel
 * issues the same calls, in the same order, on the same buffers, from C.  The
 * pure-Python loop stays as the reference (tests: bit-identical results).
 */
#include "fp_cosim.h"

#include <stddef.h>
#include <stdint.h>

#include "fmi2FunctionTypes.h"

/* The orders of fns, vrs/counts and offsets (fp_cosim.h). */
enum { F_C_SET, F_C_STEP, F_C_GET, F_C_GETI, F_C_GETB, F_P_SET, F_P_STEP, F_P_GET, F_P_GETI,
       F_COUNT };
enum { V_C_IN, V_C_OUT, V_C_INT, V_C_BOOL, V_P_IN, V_P_CMD, V_P_DIST, V_P_OUT, V_P_INT, V_COUNT };
enum { O_REF, O_PLANT, O_DIST, O_CTRL, O_CINT, O_CBOOL, O_PINT, O_COUNT };
typedef char fp_cosim_layout_matches_header[(F_COUNT == FP_COSIM_N_FNS &&
                                             V_COUNT == FP_COSIM_N_VRS &&
                                             O_COUNT == FP_COSIM_N_OFFSETS) ? 1 : -1];

/* See fp_cosim.h.  Offsets are in elements of their matrix. */
FP_API int fp_cosim_steps(const FpFn fns[FP_COSIM_N_FNS], void *const comps[2],
                          const unsigned int *const vrs[FP_COSIM_N_VRS],
                          const size_t counts[FP_COSIM_N_VRS], double *data, long stride,
                          int32_t *ints, long istride, double *spare,
                          const long offsets[FP_COSIM_N_OFFSETS], double t0, double h,
                          int jacobi, long first, long last, long *failed_step) {
    fmi2SetRealTYPE *c_set, *p_set;
    fmi2DoStepTYPE *c_step, *p_step;
    fmi2GetRealTYPE *c_get, *p_get;
    fmi2GetIntegerTYPE *c_geti, *p_geti;
    fmi2GetBooleanTYPE *c_getb;
    fmi2Component cc, pc;
    long k;
    if (fns == NULL || comps == NULL || vrs == NULL || counts == NULL || data == NULL ||
        ints == NULL || spare == NULL || offsets == NULL || failed_step == NULL)
        return (int)fmi2Error;
    c_set = (fmi2SetRealTYPE *)fns[F_C_SET];
    c_step = (fmi2DoStepTYPE *)fns[F_C_STEP];
    c_get = (fmi2GetRealTYPE *)fns[F_C_GET];
    c_geti = (fmi2GetIntegerTYPE *)fns[F_C_GETI];
    c_getb = (fmi2GetBooleanTYPE *)fns[F_C_GETB];
    p_set = (fmi2SetRealTYPE *)fns[F_P_SET];
    p_step = (fmi2DoStepTYPE *)fns[F_P_STEP];
    p_get = (fmi2GetRealTYPE *)fns[F_P_GET];
    p_geti = (fmi2GetIntegerTYPE *)fns[F_P_GETI];
    cc = comps[0];
    pc = comps[1];
    if (pc == NULL || p_set == NULL || p_step == NULL || p_get == NULL || p_geti == NULL ||
        (cc != NULL && (c_set == NULL || c_step == NULL || c_get == NULL || c_geti == NULL ||
                        c_getb == NULL)))
        return (int)fmi2Error;
    for (k = first; k < last; k++) {
        double *row = data + k * stride;
        int32_t *irow = ints + k * istride;
        double t = t0 + (double)k * h;
        /* every status is checked before the next call: after an error neither FMU is
         * called again (after fmi2Fatal the standard forbids it) */
#define FP_CALL(expr)                                   \
    do {                                                \
        fmi2Status st_ = (expr);                        \
        if (st_ > fmi2Warning) {                        \
            *failed_step = k;                           \
            return (int)st_;                            \
        }                                               \
    } while (0)
        if (cc != NULL) { /* open loop (no controller): the commands are held in the rows */
            FP_CALL(c_set(cc, vrs[V_C_IN], counts[V_C_IN], row + offsets[O_REF]));
            FP_CALL(c_step(cc, t, h, fmi2True));
            FP_CALL(c_get(cc, vrs[V_C_OUT], counts[V_C_OUT], row + offsets[O_CTRL]));
            FP_CALL(c_geti(cc, vrs[V_C_INT], counts[V_C_INT], irow + offsets[O_CINT]));
            FP_CALL(c_getb(cc, vrs[V_C_BOOL], counts[V_C_BOOL], irow + offsets[O_CBOOL]));
        }
        if (jacobi) {
            const double *prev = (k > 0 ? row - stride : spare) + offsets[O_CTRL];
            FP_CALL(p_set(pc, vrs[V_P_CMD], counts[V_P_CMD], prev));
            FP_CALL(p_set(pc, vrs[V_P_DIST], counts[V_P_DIST], row + offsets[O_DIST]));
        } else {
            FP_CALL(p_set(pc, vrs[V_P_IN], counts[V_P_IN], row + offsets[O_DIST]));
        }
        FP_CALL(p_step(pc, t, h, fmi2True));
        FP_CALL(p_get(pc, vrs[V_P_OUT], counts[V_P_OUT], row + stride + offsets[O_PLANT]));
        FP_CALL(p_geti(pc, vrs[V_P_INT], counts[V_P_INT], irow + istride + offsets[O_PINT]));
#undef FP_CALL
    }
    return 0;
}
