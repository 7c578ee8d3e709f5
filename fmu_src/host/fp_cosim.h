/*
 * libfp_cosim (installed in orchestrator/lib/, used by orchestrator/native.py): the step
 * kernel of the co-simulation master.  It calls the FMI entry points of two fmpy-loaded
 * FMU instances in the master's order on the master's buffers (see fp_cosim.c).
 */
#ifndef FP_COSIM_H
#define FP_COSIM_H

#include <stddef.h>
#include <stdint.h>

#include "fp_api.h"

/* Any function pointer; the kernel casts each to its FMI type before calling. */
typedef void (*FpFn)(void);

/* fns[FP_COSIM_N_FNS]: controller fmi2SetReal, fmi2DoStep, fmi2GetReal, fmi2GetInteger,
 * fmi2GetBoolean; plant fmi2SetReal, fmi2DoStep, fmi2GetReal, fmi2GetInteger. */
#define FP_COSIM_N_FNS 9
/* vrs[], counts[FP_COSIM_N_VRS]: value references of the controller inputs, Real outputs,
 * Integer outputs, Boolean outputs; of the plant inputs (Gauss-Seidel: disturbances and
 * commands), commands, disturbances (Jacobi), Real outputs, Integer outputs. */
#define FP_COSIM_N_VRS 9
/* offsets[FP_COSIM_N_OFFSETS], in elements of their matrix: references, plant outputs,
 * disturbances, controller Real outputs, controller Integer and Boolean outputs, plant
 * Integer outputs. */
#define FP_COSIM_N_OFFSETS 7

/*
 * Steps k = first .. last-1 of a run (time t0 + k h): the controller samples [r_k, y_k] (row k),
 * its outputs go to row k; the plant integrates with [dist_k, u_k] (Gauss-Seidel)
 * or u_{k-1} (Jacobi; row -1 is the spare row `spare`), its outputs go to row
 * k+1.  With comps[0] == NULL (the plant alone) the controller is not called and the
 * plant's commands are read from the rows as written.  Returns 0, or the first FMI status
 * above fmi2Warning with *failed_step set to its step.
 */
FP_API int fp_cosim_steps(const FpFn fns[FP_COSIM_N_FNS], void *const comps[2],
                          const unsigned int *const vrs[FP_COSIM_N_VRS],
                          const size_t counts[FP_COSIM_N_VRS], double *data, long stride,
                          int32_t *ints, long istride, double *spare,
                          const long offsets[FP_COSIM_N_OFFSETS], double t0, double h,
                          int jacobi, long first, long last, long *failed_step);

#endif
