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

/*
 * The FMI 3.0 adapter (fp_fmi3_adapter.c): an FMI 3.0 co-simulation instance seen through
 * FMI 2.0-shaped entry points, so fp_cosim_steps flies FMI 3.0 FMUs with the same call
 * sequence on the same buffers.  FMI 3.0 addresses a whole array variable by one value
 * reference; the master addresses elements (the recording has a column per element, a
 * rotor-count slice of an array among them).  The adapter numbers the elements of the
 * variables it is given (element reference e = the e-th element of the list), keeps the
 * current value of every element, and turns a set or get of elements into one
 * fmi3Set/GetFloat64 (Int32, Boolean) of the whole variables they belong to: elements not
 * named keep their value.  All its memory is taken at creation.
 */

/* Variable types of fp_fmi3_adapter_new's var_type. */
#define FP_FMI3_FLOAT64 0
#define FP_FMI3_INT32 1
#define FP_FMI3_BOOLEAN 2

/* fns of fp_fmi3_adapter_new: the FMU's fmi3SetFloat64, fmi3GetFloat64, fmi3GetInt32,
 * fmi3GetBoolean, fmi3DoStep. */
#define FP_FMI3_N_FNS 5

/*
 * An adapter on the fmi3Instance `instance` for n_vars variables (value reference var_vr[i],
 * var_size[i] elements, type var_type[i]), whose elements are numbered in order from 0.
 * The current values of every element are read from the instance (an initialized one).
 * *out: the adapter, the `component` of the fmi2-shaped entries below; free it with
 * fp_fmi3_adapter_free.  Returns 0, or an FMI status / -1 (bad arguments, no memory).
 */
FP_API int fp_fmi3_adapter_new(void *instance, const FpFn fns[FP_FMI3_N_FNS], size_t n_vars,
                               const unsigned int *var_vr, const unsigned int *var_size,
                               const int *var_type, void **out);
FP_API int fp_fmi3_adapter_free(void *adapter);

/* The fmi2-shaped entries (fmi2SetReal, fmi2GetReal, fmi2GetInteger, fmi2GetBoolean,
 * fmi2DoStep types) on element references; their returns are FMI status codes. */
FP_API int fp_fmi3_set_real(void *adapter, const unsigned int *refs, size_t n,
                            const double *values);
FP_API int fp_fmi3_get_real(void *adapter, const unsigned int *refs, size_t n, double *values);
FP_API int fp_fmi3_get_integer(void *adapter, const unsigned int *refs, size_t n,
                               int *values);
FP_API int fp_fmi3_get_boolean(void *adapter, const unsigned int *refs, size_t n,
                               int *values);
FP_API int fp_fmi3_do_step(void *adapter, double t, double h, int no_set_prior);

#endif
