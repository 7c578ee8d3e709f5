/*
 * Internal to the FMI 3.0 glue (fmi3_glue.c, fmi3_values.c, fmi3_fmustate.c,
 * fmi3_resources.c): the instance, the entry check of every call and the logging the files
 * share, as fmi2_glue_internal.h is for the FMI 2.0 glue.  Not an API, and like those files
 * it includes the FMI headers (no model code does).  Calls go one way: fmi3_values.c,
 * fmi3_fmustate.c and fmi3_resources.c call fmi3_glue.c, never the other way round (the
 * instantiation in fmi3_glue.c calls g3_load_table, which calls nothing here).
 *
 * The names differ from the FMI 2.0 glue's (g3_*, Fmi3Instance) although the two are never
 * compiled into one binary: each FMU's translation unit holds one glue.
 */
#ifndef FP_FMI3_GLUE_INTERNAL_H
#define FP_FMI3_GLUE_INTERNAL_H

#include <stddef.h>
#include <stdint.h>

/* The FMI 3.0 headers declare fmi3LockPreemptionCallback as `void (*)()`, which is no
 * prototype in C; the project's -Wstrict-prototypes (an error in its builds) is silenced for
 * them alone. */
#if defined(__GNUC__)
#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wstrict-prototypes"
#endif
#include "fmi3Functions.h"
#if defined(__GNUC__)
#pragma GCC diagnostic pop
#endif
#include "fmi3_scheduled.h"
#include "fmu_state.h"
#include "fp_model.h"
#include "fp_table.h"

/* 1 in the FMU that provides Scheduled Execution (fmi3_scheduled.h), 0 in the others. */
#if defined(FP_FMI3_SCHEDULED_EXECUTION)
#define G3_SE_PROVIDED 1
#else
#define G3_SE_PROVIDED 0
#endif

/* 1 in the FMU that provides Model Exchange (its translation unit defines
 * FP_FMI3_MODEL_EXCHANGE and includes fmi3_me.c: the plant, whose model has
 * FpModelInfo.me), 0 in the others. */
#if defined(FP_FMI3_MODEL_EXCHANGE)
#define G3_ME_PROVIDED 1
#else
#define G3_ME_PROVIDED 0
#endif

/* The interface an instance was instantiated for. */
enum { G3_CO_SIMULATION = 0, G3_SCHEDULED_EXECUTION = 1, G3_MODEL_EXCHANGE = 2 };

/* The distinct warnings one initialization reports once each (beyond them, repeats show). */
#define G3_MAX_WARNINGS_SEEN 32

/* The value reference of the independent variable `time` (no table row uses 0). */
#define G3_TIME_VR 0u

typedef struct {
    /* First: an allocator may reuse the first words of a freed block for its own lists,
     * so the freed marker and the logger come after it. */
    char guid[40];
    uint32_t magic; /* G3_INSTANCE_LIVE while the instance exists */
    int state;      /* one S_* bit (fmu_state.h): the FMI 3.0 names are g3_state_name's */
    fmi3LogMessageCallback logger;
    fmi3InstanceEnvironment env;
    const FpModelInfo *info;
    int logging_on;
    unsigned categories; /* bit per FpLogCategory enabled for debug logging */
    double time;
    int dirty;          /* parameters/inputs changed since the last initialize */
    int tunables_dirty; /* tunable parameters changed while stepping */
    uint32_t n_vr;      /* size of vr_map */
    int32_t *vr_map;    /* value reference (a row's base vr) -> index into info->vars, or -1 */
    void *model;
    void *scratch;              /* model_size bytes: a restored state is checked here */
    const FpVar *internal_step; /* parameter of the internal step (NULL: none) */
    FpLogger model_logger;
    /* Each distinct warning of the model's parameter checks is reported once per
     * initialization (from instantiation or reset on), as in the FMI 2.0 glue. */
    int checking;
    uint64_t warned[G3_MAX_WARNINGS_SEEN];
    int n_warned;
    FpTable table; /* the model's table from resources/ (FpModelInfo.table_resource) */
    /* The interface (G3_CO_SIMULATION, G3_SCHEDULED_EXECUTION).  Scheduled Execution's Clock
     * Activation Mode is the lifecycle state S_STEP_COMPLETE (fmu_state.h): an FMU state
     * saved by either interface restores in the other. */
    int interface;
    /* Scheduled Execution: the importer's callbacks, kept but never called (one input clock,
     * no output or countdown clock to report; the one model partition shares nothing to
     * guard against preemption: docs/fmus.md, "Scheduled Execution"). */
    fmi3ClockUpdateCallback clock_update;
    fmi3LockPreemptionCallback lock_preemption;
    fmi3UnlockPreemptionCallback unlock_preemption;
    double se_interval;  /* the clock's constant interval: the internal step's default */
    double se_base;      /* the next activation is due at se_base + se_k * se_interval */
    int64_t se_k;
    int se_set_pending;  /* a value set in Clock Activation Mode, no activation since */
    /* Model Exchange (fmi3_me.c): the time, the states or the inputs changed since the model
     * last evaluated its derivatives and outputs (evaluated again before they are read) */
    int me_stale;
} Fmi3Instance;

/* The FMI 3.0 name of a lifecycle state ("Step Mode", ...). */
const char *g3_state_name(int state);

/* The name of an instance's state for its interface ("Clock Activation Mode" for
 * Scheduled Execution's S_STEP_COMPLETE). */
const char *g3_mode_name(const Fmi3Instance *inst);

/* Scheduled Execution: the next activation due at the instance's time, the count restarted
 * (at the end of initialization and when an FMU state is restored). */
void g3_se_anchor(Fmi3Instance *inst);

/* 1 if r is the input clock of Scheduled Execution (fmi3_scheduled.h) in this FMU. */
static inline int g3_is_clock(fmi3ValueReference r) {
    return G3_SE_PROVIDED && r == FP_SE_CLOCK_VR;
}

/* fmi3_glue.c: the logging through the importer's callback. */
void g3_logf(Fmi3Instance *inst, FpStatus status, FpLogCategory category, const char *fmt, ...)
#if defined(__GNUC__)
    __attribute__((format(printf, 4, 5)))
#endif
    ;

/* fmi3_resources.c: the model's table (FpModelInfo.table_resource) read from the FMU's
 * resources/ folder at instantiation (FMI 3.0 resourcePath: a native path): 0, or -1 with
 * the file and the reason in why. */
int g3_load_table(Fmi3Instance *inst, fmi3String resource_path, char *why, size_t why_size);

/* Entry of every function taking an instance: a live instance in one of `states`. */
Fmi3Instance *g3_enter(fmi3Instance c, const char *fn, int states);

/* A NULL array or pointer argument: refused with a message naming it. */
fmi3Status g3_null_argument(Fmi3Instance *inst, const char *fn, const char *what);

/* Brings initial outputs up to date after parameter changes (values read in Initialization
 * Mode are computed from what was set); in Model Exchange, the derivatives and outputs after
 * the time, the states or the inputs changed. */
fmi3Status g3_refresh(Fmi3Instance *inst);

/* A failure of the model's computation: fmi3Error leaves the instance in Error, fmi3Discard
 * (co-simulation) after a discarded step; the status is returned. */
fmi3Status g3_fail(Fmi3Instance *inst, fmi3Status status);

/* An Event Mode function called on an instance that has none (co-simulation without Event
 * Mode, Scheduled Execution): fmi3Error with the message the FMUs without Model Exchange give
 * (fmi3_me.c calls it). */
fmi3Status g3_no_event_mode(fmi3Instance c, const char *fn);

/* The entry of a function taking the instance c: `inst` declared, the call refused when c
 * is not a live instance in one of `states`. */
#define G3_CHECK(fn, states)                                \
    Fmi3Instance *inst = g3_enter(c, fn, states);           \
    if (inst == NULL) return fmi3Error

/* logCalls: every accepted call with its arguments; formatted only when enabled. */
static inline int g3_calls_on(const Fmi3Instance *inst) {
    return inst->logging_on && (inst->categories & (1u << FP_LOG_CALLS));
}

#define G3_LOG_CALL(inst, ...)                                                     \
    do {                                                                           \
        if (g3_calls_on(inst)) g3_logf(inst, FP_OK, FP_LOG_CALLS, __VA_ARGS__);    \
    } while (0)

/* Element k of variable v in the model struct. */
static inline void *g3_element(Fmi3Instance *inst, const FpVar *v, uint32_t k) {
    size_t size = v->type == FP_REAL ? sizeof(double) : sizeof(int32_t);
    return (char *)inst->model + v->offset + (size_t)k * size;
}

#endif
