/*
 * FMI 3.0 co-simulation instances behind FMI 2.0-shaped entry points (declared in
 * fp_cosim.h, "The FMI 3.0 adapter").  All memory is taken at creation; a set, get or step
 * allocates nothing.
 */
#include "fp_cosim.h"

#include <stdbool.h>
#include <stdlib.h>
#include <string.h>

/* fmpy's FMI 3.0 header declares the preemption callbacks without a prototype, as the
 * standard's does */
#if defined(__GNUC__)
#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wstrict-prototypes"
#endif
#include "fmi3FunctionTypes.h"
#if defined(__GNUC__)
#pragma GCC diagnostic pop
#endif

#define STATUS_ERROR 3 /* fmi2Error == fmi3Error */

typedef struct {
    void *instance;
    fmi3SetFloat64TYPE *set_float64;
    fmi3GetFloat64TYPE *get_float64;
    fmi3GetInt32TYPE *get_int32;
    fmi3GetBooleanTYPE *get_boolean;
    fmi3DoStepTYPE *do_step;
    size_t n_vars, n_elems;
    unsigned int *var_vr;   /* [n_vars] */
    unsigned int *var_size; /* [n_vars] */
    int *var_type;          /* [n_vars] */
    size_t *var_off;        /* [n_vars]: first element in its type's buffer */
    size_t *elem_var;       /* [n_elems] */
    size_t *elem_k;         /* [n_elems] */
    double *f64;            /* the current values, by type */
    int32_t *i32;
    bool *b;
    /* per call */
    unsigned char *touched; /* [n_vars] */
    size_t *order;          /* [n_vars]: the variables of a call, first use first */
    fmi3ValueReference *vrs;
    double *f64_scratch;
    int32_t *i32_scratch;
    bool *b_scratch;
} Adapter;

static void adapter_release(Adapter *a) {
    if (a == NULL) return;
    free(a->var_vr);
    free(a->var_size);
    free(a->var_type);
    free(a->var_off);
    free(a->elem_var);
    free(a->elem_k);
    free(a->f64);
    free(a->i32);
    free(a->b);
    free(a->touched);
    free(a->order);
    free(a->vrs);
    free(a->f64_scratch);
    free(a->i32_scratch);
    free(a->b_scratch);
    free(a);
}

/* The variables the elements refs[0..n) belong to, in the order of first use, checked to be
 * of `type`: their count, or -1 for an unknown reference or another type. */
static long collect(Adapter *a, const unsigned int *refs, size_t n, int type) {
    size_t i, nt = 0;
    for (i = 0; i < n; i++) {
        size_t v;
        if ((size_t)refs[i] >= a->n_elems) break;
        v = a->elem_var[refs[i]];
        if (a->var_type[v] != type) break;
        if (!a->touched[v]) {
            a->touched[v] = 1;
            a->order[nt++] = v;
        }
    }
    {
        size_t j;
        for (j = 0; j < nt; j++) a->touched[a->order[j]] = 0;
    }
    return i < n ? -1 : (long)nt;
}

/* The value references of the collected variables and their element count. */
static size_t collected(Adapter *a, size_t nt) {
    size_t j, total = 0;
    for (j = 0; j < nt; j++) {
        a->vrs[j] = a->var_vr[a->order[j]];
        total += a->var_size[a->order[j]];
    }
    return total;
}

/* Reads every collected variable into the current values. */
static int refresh(Adapter *a, size_t nt, int type) {
    size_t j, pos = 0, total = collected(a, nt);
    fmi3Status st;
    if (nt == 0) return 0;
    if (type == FP_FMI3_FLOAT64)
        st = a->get_float64(a->instance, a->vrs, nt, a->f64_scratch, total);
    else if (type == FP_FMI3_INT32)
        st = a->get_int32(a->instance, a->vrs, nt, a->i32_scratch, total);
    else
        st = a->get_boolean(a->instance, a->vrs, nt, a->b_scratch, total);
    if (st > fmi3Warning) return (int)st;
    for (j = 0; j < nt; j++) {
        size_t v = a->order[j], size = a->var_size[v], off = a->var_off[v];
        if (type == FP_FMI3_FLOAT64)
            memcpy(a->f64 + off, a->f64_scratch + pos, size * sizeof(double));
        else if (type == FP_FMI3_INT32)
            memcpy(a->i32 + off, a->i32_scratch + pos, size * sizeof(int32_t));
        else
            memcpy(a->b + off, a->b_scratch + pos, size * sizeof(bool));
        pos += size;
    }
    return (int)st;
}

FP_API int fp_fmi3_adapter_new(void *instance, const FpFn fns[FP_FMI3_N_FNS], size_t n_vars,
                               const unsigned int *var_vr, const unsigned int *var_size,
                               const int *var_type, void **out) {
    Adapter *a;
    size_t v, e, count[3] = {0, 0, 0};
    int t, st;
    if (out == NULL) return -1;
    *out = NULL;
    if (instance == NULL || fns == NULL || var_vr == NULL || var_size == NULL ||
        var_type == NULL || n_vars == 0)
        return -1;
    for (v = 0; v < n_vars; v++) {
        if (var_type[v] < 0 || var_type[v] > 2 || var_size[v] == 0) return -1;
        count[var_type[v]] += var_size[v];
    }
    a = (Adapter *)calloc(1, sizeof *a);
    if (a == NULL) return -1;
    a->instance = instance;
    a->set_float64 = (fmi3SetFloat64TYPE *)fns[0];
    a->get_float64 = (fmi3GetFloat64TYPE *)fns[1];
    a->get_int32 = (fmi3GetInt32TYPE *)fns[2];
    a->get_boolean = (fmi3GetBooleanTYPE *)fns[3];
    a->do_step = (fmi3DoStepTYPE *)fns[4];
    a->n_vars = n_vars;
    a->n_elems = count[0] + count[1] + count[2];
    a->var_vr = (unsigned int *)malloc(n_vars * sizeof *a->var_vr);
    a->var_size = (unsigned int *)malloc(n_vars * sizeof *a->var_size);
    a->var_type = (int *)malloc(n_vars * sizeof *a->var_type);
    a->var_off = (size_t *)malloc(n_vars * sizeof *a->var_off);
    a->elem_var = (size_t *)malloc(a->n_elems * sizeof *a->elem_var);
    a->elem_k = (size_t *)malloc(a->n_elems * sizeof *a->elem_k);
    a->f64 = (double *)calloc(count[0] + 1, sizeof(double));
    a->i32 = (int32_t *)calloc(count[1] + 1, sizeof(int32_t));
    a->b = (bool *)calloc(count[2] + 1, sizeof(bool));
    a->touched = (unsigned char *)calloc(n_vars, 1);
    a->order = (size_t *)malloc(n_vars * sizeof *a->order);
    a->vrs = (fmi3ValueReference *)malloc(n_vars * sizeof *a->vrs);
    a->f64_scratch = (double *)calloc(count[0] + 1, sizeof(double));
    a->i32_scratch = (int32_t *)calloc(count[1] + 1, sizeof(int32_t));
    a->b_scratch = (bool *)calloc(count[2] + 1, sizeof(bool));
    if (a->var_vr == NULL || a->var_size == NULL || a->var_type == NULL || a->var_off == NULL ||
        a->elem_var == NULL || a->elem_k == NULL || a->f64 == NULL || a->i32 == NULL ||
        a->b == NULL || a->touched == NULL || a->order == NULL || a->vrs == NULL ||
        a->f64_scratch == NULL || a->i32_scratch == NULL || a->b_scratch == NULL ||
        a->set_float64 == NULL || a->get_float64 == NULL || a->get_int32 == NULL ||
        a->get_boolean == NULL || a->do_step == NULL) {
        adapter_release(a);
        return -1;
    }
    count[0] = count[1] = count[2] = 0;
    for (v = 0, e = 0; v < n_vars; v++) {
        size_t k;
        a->var_vr[v] = var_vr[v];
        a->var_size[v] = var_size[v];
        a->var_type[v] = var_type[v];
        a->var_off[v] = count[var_type[v]];
        count[var_type[v]] += var_size[v];
        for (k = 0; k < var_size[v]; k++, e++) {
            a->elem_var[e] = v;
            a->elem_k[e] = k;
        }
    }
    /* the current value of every element, one read per type */
    for (t = 0; t < 3; t++) {
        size_t nt = 0;
        for (v = 0; v < n_vars; v++)
            if (var_type[v] == t) a->order[nt++] = v;
        st = refresh(a, nt, t);
        if (st > (int)fmi3Warning) {
            adapter_release(a);
            return st;
        }
    }
    *out = a;
    return 0;
}

FP_API int fp_fmi3_adapter_free(void *adapter) {
    adapter_release((Adapter *)adapter);
    return 0;
}

/* The first part of every get: the arguments checked, the variables of the elements refs
 * read whole into the current values; an FMI status (above fmi3Warning: failed). */
static int read_elements(Adapter *a, const unsigned int *refs, size_t n, const void *values,
                         int type) {
    long nt;
    if (a == NULL || (n > 0 && (refs == NULL || values == NULL))) return STATUS_ERROR;
    nt = collect(a, refs, n, type);
    if (nt < 0) return STATUS_ERROR;
    return refresh(a, (size_t)nt, type);
}

/* Where element e's current value is in its type's buffer. */
static size_t slot(const Adapter *a, unsigned int e) {
    return a->var_off[a->elem_var[e]] + a->elem_k[e];
}

FP_API int fp_fmi3_set_real(void *adapter, const unsigned int *refs, size_t n,
                            const double *values) {
    Adapter *a = (Adapter *)adapter;
    size_t i, j, pos = 0, total;
    long nt;
    if (a == NULL || (n > 0 && (refs == NULL || values == NULL))) return STATUS_ERROR;
    nt = collect(a, refs, n, FP_FMI3_FLOAT64);
    if (nt < 0) return STATUS_ERROR;
    for (i = 0; i < n; i++) a->f64[slot(a, refs[i])] = values[i];
    total = collected(a, (size_t)nt);
    for (j = 0; j < (size_t)nt; j++) {
        size_t v = a->order[j];
        memcpy(a->f64_scratch + pos, a->f64 + a->var_off[v], a->var_size[v] * sizeof(double));
        pos += a->var_size[v];
    }
    if (nt == 0) return 0;
    return (int)a->set_float64(a->instance, a->vrs, (size_t)nt, a->f64_scratch, total);
}

FP_API int fp_fmi3_get_real(void *adapter, const unsigned int *refs, size_t n, double *values) {
    Adapter *a = (Adapter *)adapter;
    size_t i;
    int st = read_elements(a, refs, n, values, FP_FMI3_FLOAT64);
    if (st > (int)fmi3Warning) return st;
    for (i = 0; i < n; i++) values[i] = a->f64[slot(a, refs[i])];
    return st;
}

FP_API int fp_fmi3_get_integer(void *adapter, const unsigned int *refs, size_t n,
                               int *values) {
    Adapter *a = (Adapter *)adapter;
    size_t i;
    int st = read_elements(a, refs, n, values, FP_FMI3_INT32);
    if (st > (int)fmi3Warning) return st;
    for (i = 0; i < n; i++) values[i] = (int)a->i32[slot(a, refs[i])];
    return st;
}

FP_API int fp_fmi3_get_boolean(void *adapter, const unsigned int *refs, size_t n,
                               int *values) {
    Adapter *a = (Adapter *)adapter;
    size_t i;
    int st = read_elements(a, refs, n, values, FP_FMI3_BOOLEAN);
    if (st > (int)fmi3Warning) return st;
    for (i = 0; i < n; i++) values[i] = a->b[slot(a, refs[i])] ? 1 : 0;
    return st;
}

FP_API int fp_fmi3_do_step(void *adapter, double t, double h, int no_set_prior) {
    Adapter *a = (Adapter *)adapter;
    bool event = false, terminate = false, early = false;
    double last = t;
    fmi3Status st;
    if (a == NULL) return STATUS_ERROR;
    st = a->do_step(a->instance, t, h, no_set_prior != 0, &event, &terminate, &early, &last);
    /* a co-simulation FMU without event mode that asks to stop or returns early cannot be
     * stepped on by a fixed-step master: an error of the step */
    if (st <= fmi3Warning && (terminate || early)) return STATUS_ERROR;
    return (int)st;
}
