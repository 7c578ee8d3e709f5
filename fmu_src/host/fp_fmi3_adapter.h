/*
 * libfp_cosim: an FMI 3.0 co-simulation instance seen through FMI 2.0-shaped entry points,
 * so the step kernel (fp_cosim.h) flies FMI 3.0 FMUs with the same call sequence on the same
 * buffers.  FMI 3.0 addresses a whole array variable by one value reference; the master
 * addresses elements (the recording has a column per element, a rotor-count slice of an
 * array among them).  The adapter numbers the elements of the variables it is given
 * (element reference e = the e-th element of the list), keeps the current value of every
 * element, and turns a set or get of elements into one fmi3Set/GetFloat64 (Int32, Boolean)
 * of the whole variables they belong to: elements not named keep their value.
 */
#ifndef FP_FMI3_ADAPTER_H
#define FP_FMI3_ADAPTER_H

#include <stddef.h>
#include <stdint.h>

#include "fp_api.h"
#include "fp_cosim.h"

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
