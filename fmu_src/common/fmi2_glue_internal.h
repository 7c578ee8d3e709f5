/*
 * Internal to the FMI 2.0 glue (fmi2_glue.c, fmi2_values.c, fmi2_fmustate.c,
 * fmi2_resources.c): the instance,
 * the entry check of every call and the logging the three files share.  Not an API, and
 * like those files it includes the FMI headers (no model code does).  Calls go one way:
 * fmi2_values.c and fmi2_fmustate.c call fmi2_glue.c, never the other way round.
 */
#ifndef FP_FMI2_GLUE_INTERNAL_H
#define FP_FMI2_GLUE_INTERNAL_H

#include <stddef.h>
#include <stdint.h>

#include "fmi2Functions.h"
#include "fmu_state.h"
#include "fp_model.h"
#include "fp_table.h"

/* The distinct warnings one initialization reports once each (beyond them, repeats show). */
#define MAX_WARNINGS_SEEN 32

typedef struct {
    /* First: an allocator may reuse the first words of a freed block for its own lists,
     * so the freed marker and the logger come after it. */
    char guid[40];
    uint32_t magic; /* INSTANCE_LIVE while the instance exists */
    int state;
    fmi2CallbackLogger logger;
    fmi2CallbackAllocateMemory allocate;
    fmi2CallbackFreeMemory release;
    fmi2ComponentEnvironment env;
    char *name;
    const FpModelInfo *info;
    int logging_on;
    unsigned categories; /* bit per FpLogCategory enabled for debug logging */
    double time;
    int dirty;          /* parameters/inputs changed since the last initialize */
    int tunables_dirty; /* tunable parameters changed while stepping */
    uint32_t n_vr;      /* size of vr_map */
    int32_t *vr_map;    /* value reference -> index into info->vars, or -1 */
    void *model;
    void *scratch;                /* model_size bytes: a restored state is checked here */
    const FpVar *internal_step;   /* parameter of the internal step (NULL: none) */
    FpLogger model_logger;
    /* The model validates its parameters at every read in initialization mode, at its end
     * and on a restored state: each distinct warning of those checks is reported once per
     * initialization (from instantiation or reset on), not at every repeat. */
    int checking;                            /* the model is validating parameters */
    uint64_t warned[MAX_WARNINGS_SEEN];      /* FNV-1a of the warnings reported */
    int n_warned;
    FpTable table; /* the model's table from resources/ (FpModelInfo.table_resource) */
    /* Model Exchange (fmi2_me.c): instantiated as fmi2ModelExchange (the model has
     * FpModelInfo.me); the time, the states or the inputs changed since the model last
     * evaluated its derivatives and outputs (evaluated again before they are read) */
    int me;
    int me_stale;
} Instance;

/* fmi2_glue.c: the logging through the importer's callback, the entry checks, and the
 * initialization that brings the outputs up to date. */
void glue_logf(Instance *inst, FpStatus status, FpLogCategory category, const char *fmt, ...)
#if defined(__GNUC__)
    __attribute__((format(printf, 4, 5)))
#endif
    ;

/* fmi2_resources.c: the model's table (FpModelInfo.table_resource) read from the FMU's
 * resources/ folder at instantiation: 0, or -1 with the file and the reason in why (which
 * the caller logs: fmi2_resources.c calls nothing here). */
int glue_load_table(Instance *inst, fmi2String location, char *why, size_t why_size);

/* Entry of every function taking an instance: a live instance in one of `states`. */
Instance *glue_enter(fmi2Component c, const char *fn, int states);

/* A NULL array or pointer argument: refused with a message naming it. */
fmi2Status glue_null_argument(Instance *inst, const char *fn, const char *what);

/* Brings initial outputs up to date after parameter changes (FMI 2.0: values
 * read in initialization mode are computed from what was set); in Model Exchange, the
 * derivatives and outputs after the time, the states or the inputs changed. */
fmi2Status glue_refresh(Instance *inst);

/* A failure of the model's computation: fmi2Error leaves the instance in Error, fmi2Discard
 * (co-simulation) in StepFailed; the status is returned. */
fmi2Status glue_fail(Instance *inst, fmi2Status status);

/* The entry of a function taking the instance c: `inst` declared, the call refused when c
 * is not a live instance in one of `states`. */
#define CHECK(fn, states)                                     \
    Instance *inst = glue_enter(c, fn, states);               \
    if (inst == NULL) return fmi2Error

/* logCalls: every accepted call with its arguments, e.g. "fmi2DoStep(currentCommunication
 * Point = 0.5, communicationStepSize = 0.002, ...)"; formatted only when enabled. */
static inline int calls_on(const Instance *inst) {
    return inst->logging_on && (inst->categories & (1u << FP_LOG_CALLS));
}

#define LOG_CALL(inst, ...)                                                 \
    do {                                                                    \
        if (calls_on(inst)) glue_logf(inst, FP_OK, FP_LOG_CALLS, __VA_ARGS__); \
    } while (0)

/* Element k of variable v in the model struct. */
static inline void *element(Instance *inst, const FpVar *v, uint32_t k) {
    size_t size = v->type == FP_REAL ? sizeof(double) : sizeof(int32_t);
    return (char *)inst->model + v->offset + (size_t)k * size;
}

#endif
