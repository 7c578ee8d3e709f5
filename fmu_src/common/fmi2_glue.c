/*
 * Generic FMI 2.0 co-simulation layer shared by every fullpose FMU.
 *
 * It owns the FMI call-sequence state machine, logging through the
 * importer's callback, value-reference dispatch into the model struct and
 * FMU state snapshots (their format: fmu_state.c).  The model behind it is reached only through
 * FpModelInfo (fp_model.h) and never sees an FMI type.
 */
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <string.h>

#include "fmi2Functions.h"
#include "fmu_state.h"
#include "fp_model.h"

/* fmi2Get{Real,Integer,Boolean,String}: from initialization on, and in Error for diagnosis */
#define S_READABLE (S_INIT | S_STEP_COMPLETE | S_STEP_FAILED | S_TERMINATED | S_ERROR)
/* fmi2Get*Status (FMI 2.0.4 co-simulation state table): StepComplete, StepInProgress,
 * StepFailed, Terminated; this FMU has no asynchronous step, so no StepInProgress */
#define S_STATUS (S_STEP_COMPLETE | S_STEP_FAILED | S_TERMINATED)

/* The distinct warnings one initialization reports once each (beyond them, repeats show). */
#define MAX_WARNINGS_SEEN 32

/* logCalls shows at most this many values of one get or set. */
#define CALL_VALUES 8

/* Marks a live instance; cleared to INSTANCE_FREED by fmi2FreeInstance. */
#define INSTANCE_LIVE 0x4650494eu  /* "FPIN" */
#define INSTANCE_FREED 0x46524545u /* "FREE" */

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
} Instance;



static fmi2Status to_fmi(FpStatus s) {
    switch (s) {
    case FP_OK: return fmi2OK;
    case FP_WARNING: return fmi2Warning;
    case FP_DISCARD: return fmi2Discard;
    default: return fmi2Error;
    }
}

/* Importers treat the message as a printf format string: escape '%'. */
static void emit(Instance *inst, fmi2Status status, const char *category, const char *message) {
    char escaped[1024];
    size_t i = 0;
    if (inst->logger == NULL) return;
    for (; *message != '\0' && i + 2 < sizeof escaped; message++) {
        if (*message == '%') escaped[i++] = '%';
        escaped[i++] = *message;
    }
    escaped[i] = '\0';
    inst->logger(inst->env, inst->name, status, category, escaped);
}

static int wants(const Instance *inst, FpStatus status, FpLogCategory category) {
    if (status != FP_OK) return 1; /* warnings and errors are always reported */
    return inst->logging_on && (inst->categories & (1u << category));
}

/* 1 if this warning of a parameter check was reported already in this initialization
 * (else it is remembered, while there is room). */
static int warned_before(Instance *inst, const char *message) {
    uint64_t h = fp_fnv1a64(FP_FNV1A64_BASIS, message, strlen(message));
    int i;
    for (i = 0; i < inst->n_warned; i++)
        if (inst->warned[i] == h) return 1;
    if (inst->n_warned < MAX_WARNINGS_SEEN) inst->warned[inst->n_warned++] = h;
    return 0;
}

static void model_log(void *env, FpStatus status, FpLogCategory category, const char *message) {
    Instance *inst = (Instance *)env;
    if (!wants(inst, status, category)) return;
    if (inst->checking && status == FP_WARNING && warned_before(inst, message)) return;
    emit(inst, to_fmi(status), fp_log_category_name(category), message);
}

static void logf_(Instance *inst, FpStatus status, FpLogCategory category, const char *fmt, ...)
#if defined(__GNUC__)
    __attribute__((format(printf, 4, 5)))
#endif
    ;

static void logf_(Instance *inst, FpStatus status, FpLogCategory category, const char *fmt, ...) {
    char message[768];
    va_list args;
    if (!wants(inst, status, category)) return;
    va_start(args, fmt);
    vsnprintf(message, sizeof message, fmt, args);
    va_end(args);
    emit(inst, to_fmi(status), fp_log_category_name(category), message);
}

/* A call on an instance fmi2FreeInstance has freed.  Best effort: the memory is freed, so
 * this only works while the allocator has not reused it; the logger is called without the
 * (freed) instance name. */
static void log_freed(const Instance *inst, const char *fn) {
    char message[160];
    if (inst->logger == NULL) return;
    snprintf(message, sizeof message,
             "%s: the instance was freed by fmi2FreeInstance; the call is refused", fn);
    inst->logger(inst->env, "", fmi2Error, fp_log_category_name(FP_LOG_ERROR), message);
}

/* The instance behind c, or NULL (with a message where one can be given) when c is not a
 * live instance: NULL, freed, or not an instance of this FMU. */
static Instance *instance(fmi2Component c, const char *fn) {
    Instance *inst = (Instance *)c;
    if (inst == NULL) return NULL; /* no instance, no logger to report through */
    if (inst->magic == INSTANCE_LIVE) return inst;
    if (inst->magic == INSTANCE_FREED) log_freed(inst, fn);
    return NULL;
}

/* Checks a call is legal in the current state; illegal calls change nothing (and are
 * logged as errors, not as calls). */
static int allowed(Instance *inst, const char *fn, int states) {
    if (inst->state & states) return 1;
    logf_(inst, FP_ERROR, FP_LOG_ERROR, "%s may not be called in state %s", fn,
          fp_lifecycle_name(inst->state));
    return 0;
}

/* Entry of every function taking an instance: a live instance in one of `states`. */
static Instance *enter(fmi2Component c, const char *fn, int states) {
    Instance *inst = instance(c, fn);
    if (inst == NULL || !allowed(inst, fn, states)) return NULL;
    return inst;
}

#define CHECK(fn, states)                                     \
    Instance *inst = enter(c, fn, states);                    \
    if (inst == NULL) return fmi2Error

/* logCalls: every accepted call with its arguments, e.g. "fmi2DoStep(currentCommunication
 * Point = 0.5, communicationStepSize = 0.002, ...)"; formatted only when enabled. */
static int calls_on(const Instance *inst) {
    return inst->logging_on && (inst->categories & (1u << FP_LOG_CALLS));
}

#define LOG_CALL(inst, ...)                                             \
    do {                                                                \
        if (calls_on(inst)) logf_(inst, FP_OK, FP_LOG_CALLS, __VA_ARGS__); \
    } while (0)

/* A bounded message built piece by piece (what does not fit is cut). */
typedef struct {
    char text[640];
    size_t used;
} Text;

static void text_add(Text *t, const char *fmt, ...)
#if defined(__GNUC__)
    __attribute__((format(printf, 2, 3)))
#endif
    ;

static void text_add(Text *t, const char *fmt, ...) {
    va_list args;
    int n;
    if (t->used >= sizeof t->text - 1) return;
    va_start(args, fmt);
    n = vsnprintf(t->text + t->used, sizeof t->text - t->used, fmt, args);
    va_end(args);
    if (n > 0) t->used += (size_t)n;
    if (t->used > sizeof t->text - 1) t->used = sizeof t->text - 1;
}

/* The arguments of a get or set, "fmi2SetReal(nvr = 2: mass (vr 2) = 1.5, k_t (vr 13) =
 * 2e-05)", at most CALL_VALUES of them ("..., 12 more").  A get logs what it returned:
 * `shown` values are given (0 when the call failed: only the references are listed). */
static void log_values(Instance *inst, const char *fn, const fmi2ValueReference vr[],
                       size_t nvr, const void *values, FpVarType type, size_t shown) {
    Text t;
    size_t i, n = nvr < CALL_VALUES ? nvr : CALL_VALUES;
    if (!calls_on(inst)) return;
    t.used = 0;
    t.text[0] = '\0';
    text_add(&t, "%s(nvr = %lu%s", fn, (unsigned long)nvr, nvr > 0 && vr != NULL ? ":" : "");
    for (i = 0; i < n && vr != NULL; i++) {
        char name[96] = "?", value[FP_REAL_TEXT];
        uint32_t r = vr[i];
        if (r < inst->n_vr && inst->vr_map[r] >= 0) {
            const FpVar *v = &inst->info->vars[inst->vr_map[r]];
            fp_var_element_name(v, r - v->vr, name, sizeof name);
        }
        text_add(&t, "%s %s (vr %u)", i > 0 ? "," : "", name, (unsigned)r);
        if (values == NULL || i >= shown) continue;
        if (type == FP_REAL) text_add(&t, " = %s", fp_real_text(value, ((const fmi2Real *)values)[i]));
        else if (type == FP_INTEGER) text_add(&t, " = %d", (int)((const fmi2Integer *)values)[i]);
        else text_add(&t, " = %s", ((const fmi2Boolean *)values)[i] ? "true" : "false");
    }
    if (nvr > n && vr != NULL) text_add(&t, ", ... %lu more", (unsigned long)(nvr - n));
    text_add(&t, ")");
    logf_(inst, FP_OK, FP_LOG_CALLS, "%s", t.text);
}

/* A NULL array or pointer argument: refused with a message naming it. */
static fmi2Status null_argument(Instance *inst, const char *fn, const char *what) {
    logf_(inst, FP_ERROR, FP_LOG_ERROR, "%s: %s is NULL", fn, what);
    return fmi2Error;
}

static fmi2Status null_arrays(Instance *inst, const char *fn, const void *vr, size_t nvr,
                              const void *value) {
    char what[64];
    if (nvr == 0 || (vr != NULL && value != NULL)) return fmi2OK;
    snprintf(what, sizeof what, "%s (nvr = %lu)", vr == NULL ? "vr" : "value",
             (unsigned long)nvr);
    return null_argument(inst, fn, what);
}

/* A failure of the model's computation (initialization, a step): Error (or StepFailed). */
static fmi2Status fail(Instance *inst, fmi2Status status) {
    if (status == fmi2Error) inst->state = S_ERROR;
    if (status == fmi2Discard) inst->state = S_STEP_FAILED;
    return status;
}

static const FpVar *lookup(Instance *inst, fmi2ValueReference vr, FpVarType type, uint32_t *k,
                           const char *fn) {
    static const char *const type_names[] = {"Real", "Integer", "Boolean"};
    const FpVar *v;
    if (vr >= inst->n_vr || inst->vr_map[vr] < 0) {
        logf_(inst, FP_ERROR, FP_LOG_ERROR, "%s: unknown value reference %u", fn, (unsigned)vr);
        return NULL;
    }
    v = &inst->info->vars[inst->vr_map[vr]];
    if (v->type != type) {
        logf_(inst, FP_ERROR, FP_LOG_ERROR, "%s: variable %s (vr %u) is of type %s", fn, v->name,
              (unsigned)vr, type_names[v->type]);
        return NULL;
    }
    *k = vr - v->vr;
    return v;
}

static void *element(Instance *inst, const FpVar *v, uint32_t k) {
    size_t size = v->type == FP_REAL ? sizeof(double) : sizeof(int32_t);
    return (char *)inst->model + v->offset + (size_t)k * size;
}

/* Brings initial outputs up to date after parameter changes (FMI 2.0: values
 * read in initialization mode are computed from what was set). */
static fmi2Status refresh(Instance *inst) {
    FpStatus s;
    if (!(inst->state & (S_INIT | S_INSTANTIATED)) || !inst->dirty) return fmi2OK;
    inst->checking = 1;
    s = inst->info->initialize(inst->model, inst->time, &inst->model_logger);
    inst->checking = 0;
    if (s == FP_ERROR || s == FP_DISCARD) return fail(inst, fmi2Error);
    inst->dirty = 0;
    return to_fmi(s);
}

static fmi2Status may_set(Instance *inst, const FpVar *v, uint32_t k, const char *fn) {
    char name[96];
    const char *why = NULL;
    switch (v->kind) {
    case FP_OUTPUT: why = "it is an output"; break;
    case FP_PARAM_FIXED:
        if (!(inst->state & (S_INSTANTIATED | S_INIT)))
            why = "it is a fixed parameter and initialization has ended";
        break;
    case FP_PARAM_TUNABLE:
    case FP_INPUT:
        if (!(inst->state & (S_INSTANTIATED | S_INIT | S_STEP_COMPLETE)))
            why = "the FMU is not initialized or stepping";
        break;
    }
    if (why == NULL) return fmi2OK;
    fp_var_element_name(v, k, name, sizeof name);
    logf_(inst, FP_ERROR, FP_LOG_ERROR, "%s: cannot set %s: %s", fn, name, why);
    return fmi2Error;
}

static void mark_changed(Instance *inst, const FpVar *v) {
    if (inst->state & (S_INSTANTIATED | S_INIT)) inst->dirty = 1;
    else if (v->kind == FP_PARAM_TUNABLE) inst->tunables_dirty = 1;
}

/* ------------------------------------------------------------------------ */
/* Inquiry and logging                                                      */

const char *fmi2GetTypesPlatform(void) { return fmi2TypesPlatform; }

const char *fmi2GetVersion(void) { return fmi2Version; }

fmi2Status fmi2SetDebugLogging(fmi2Component c, fmi2Boolean loggingOn, size_t nCategories,
                               const fmi2String categories[]) {
    size_t i;
    int j;
    unsigned mask = 0;
    CHECK("fmi2SetDebugLogging", S_ANY_BUT_FATAL);
    LOG_CALL(inst, "fmi2SetDebugLogging(loggingOn = %d, nCategories = %lu%s%s%s)",
             (int)loggingOn, (unsigned long)nCategories,
             nCategories > 0 && categories != NULL ? ": " : "",
             nCategories > 0 && categories != NULL && categories[0] ? categories[0] : "",
             nCategories > 1 ? ", ..." : "");
    if (nCategories > 0 && categories == NULL)
        return null_argument(inst, "fmi2SetDebugLogging", "categories");
    if (nCategories == 0) {
        mask = (1u << FP_LOG_N_CATEGORIES) - 1u;
    } else {
        for (i = 0; i < nCategories; i++) {
            int found = 0;
            for (j = 0; j < FP_LOG_N_CATEGORIES; j++) {
                if (categories[i] != NULL && strcmp(categories[i], fp_log_category_name(j)) == 0) {
                    mask |= 1u << j;
                    found = 1;
                }
            }
            if (!found) {
                logf_(inst, FP_ERROR, FP_LOG_ERROR, "fmi2SetDebugLogging: unknown category %s",
                      categories[i] ? categories[i] : "(null)");
                return fmi2Error;
            }
        }
    }
    if (loggingOn) {
        inst->logging_on = 1;
        inst->categories |= mask;
    } else {
        inst->categories &= ~mask;
        inst->logging_on = inst->categories != 0;
    }
    return fmi2OK;
}

/* ------------------------------------------------------------------------ */
/* Lifecycle                                                                */

static void release_instance(Instance *inst) {
    fmi2CallbackFreeMemory release = inst->release;
    if (inst->model) release(inst->model);
    if (inst->scratch) release(inst->scratch);
    if (inst->vr_map) release(inst->vr_map);
    if (inst->name) release(inst->name);
    inst->magic = INSTANCE_FREED;
    release(inst);
}

/* The fixed Real scalar parameter holding the model's internal step (fp_model.h). */
static const FpVar *find_internal_step(const FpModelInfo *info) {
    static const char *const names[] = FP_INTERNAL_STEP_NAMES;
    size_t i, j;
    for (i = 0; i < info->n_vars; i++) {
        const FpVar *v = &info->vars[i];
        if (v->type != FP_REAL || v->kind != FP_PARAM_FIXED || fp_var_count(v) != 1) continue;
        for (j = 0; j < sizeof names / sizeof names[0]; j++)
            if (strcmp(v->name, names[j]) == 0) return v;
    }
    return NULL;
}

fmi2Component fmi2Instantiate(fmi2String instanceName, fmi2Type fmuType, fmi2String fmuGUID,
                              fmi2String fmuResourceLocation,
                              const fmi2CallbackFunctions *functions, fmi2Boolean visible,
                              fmi2Boolean loggingOn) {
    const FpModelInfo *info = fp_model_info();
    Instance *inst;
    uint32_t max_vr = 0;
    size_t i;
    if (functions == NULL) return NULL; /* no logger to report through */
    if (functions->allocateMemory == NULL || functions->freeMemory == NULL) {
        if (functions->logger != NULL)
            functions->logger(functions->componentEnvironment, instanceName ? instanceName : "",
                              fmi2Error, fp_log_category_name(FP_LOG_ERROR),
                              "fmi2Instantiate: the allocateMemory and freeMemory callbacks are "
                              "required");
        return NULL;
    }
    inst = (Instance *)functions->allocateMemory(1, sizeof(Instance));
    if (inst == NULL) {
        if (functions->logger != NULL)
            functions->logger(functions->componentEnvironment, instanceName ? instanceName : "",
                              fmi2Error, fp_log_category_name(FP_LOG_ERROR),
                              "fmi2Instantiate: out of memory");
        return NULL;
    }
    memset(inst, 0, sizeof *inst);
    inst->magic = INSTANCE_LIVE;
    inst->logger = functions->logger;
    inst->allocate = functions->allocateMemory;
    inst->release = functions->freeMemory;
    inst->env = functions->componentEnvironment;
    inst->info = info;
    inst->state = S_INSTANTIATED;
    inst->logging_on = loggingOn ? 1 : 0;
    inst->categories = loggingOn ? (1u << FP_LOG_N_CATEGORIES) - 1u : 0u;
    inst->model_logger.log = model_log;
    inst->model_logger.env = inst;
    inst->name = (char *)inst->allocate(strlen(instanceName ? instanceName : "") + 1, 1);
    if (inst->name == NULL) {
        inst->name = (char *)""; /* for the message only; never released */
        logf_(inst, FP_ERROR, FP_LOG_ERROR, "fmi2Instantiate: out of memory");
        inst->name = NULL;
        release_instance(inst);
        return NULL;
    }
    strcpy(inst->name, instanceName ? instanceName : "");
    fp_model_guid(info, inst->guid);

    if (instanceName == NULL || instanceName[0] == '\0') {
        logf_(inst, FP_ERROR, FP_LOG_ERROR, "fmi2Instantiate: instanceName must not be empty");
        release_instance(inst);
        return NULL;
    }
    if (fmuType != fmi2CoSimulation) {
        logf_(inst, FP_ERROR, FP_LOG_ERROR,
              "fmi2Instantiate: %s supports co-simulation only (fmuType must be fmi2CoSimulation)",
              info->model_name);
        release_instance(inst);
        return NULL;
    }
    if (fmuGUID == NULL || strcmp(fmuGUID, inst->guid) != 0) {
        logf_(inst, FP_ERROR, FP_LOG_ERROR,
              "fmi2Instantiate: GUID %s does not match this binary (%s); the FMU is inconsistent",
              fmuGUID ? fmuGUID : "(null)", inst->guid);
        release_instance(inst);
        return NULL;
    }
    for (i = 0; i < info->n_vars; i++) {
        uint32_t last = info->vars[i].vr + fp_var_count(&info->vars[i]) - 1;
        if (last > max_vr) max_vr = last;
    }
    inst->n_vr = max_vr + 1;
    inst->vr_map = (int32_t *)inst->allocate(inst->n_vr, sizeof(int32_t));
    inst->model = inst->allocate(1, info->model_size);
    inst->scratch = inst->allocate(1, info->model_size);
    if (inst->vr_map == NULL || inst->model == NULL || inst->scratch == NULL) {
        logf_(inst, FP_ERROR, FP_LOG_ERROR, "fmi2Instantiate: out of memory");
        release_instance(inst);
        return NULL;
    }
    for (i = 0; i < inst->n_vr; i++) inst->vr_map[i] = -1;
    for (i = 0; i < info->n_vars; i++) {
        uint32_t k, n = fp_var_count(&info->vars[i]);
        for (k = 0; k < n; k++) inst->vr_map[info->vars[i].vr + k] = (int32_t)i;
    }
    inst->internal_step = find_internal_step(info);
    info->set_defaults(inst->model);
    inst->dirty = 1;
    LOG_CALL(inst,
             "fmi2Instantiate(instanceName = \"%.64s\", fmuType = %d, fmuGUID = \"%s\", "
             "fmuResourceLocation = \"%.200s\", visible = %d, loggingOn = %d)",
             instanceName, (int)fmuType, fmuGUID,
             fmuResourceLocation ? fmuResourceLocation : "(null)", (int)visible, (int)loggingOn);
    logf_(inst, FP_OK, FP_LOG_EVENTS, "instantiated %s", info->model_name);
    return inst;
}

void fmi2FreeInstance(fmi2Component c) {
    Instance *inst = enter(c, "fmi2FreeInstance", S_ANY_BUT_FATAL | S_FATAL);
    if (inst == NULL) return;
    LOG_CALL(inst, "fmi2FreeInstance()");
    release_instance(inst);
}

fmi2Status fmi2SetupExperiment(fmi2Component c, fmi2Boolean toleranceDefined,
                               fmi2Real tolerance, fmi2Real startTime,
                               fmi2Boolean stopTimeDefined, fmi2Real stopTime) {
    CHECK("fmi2SetupExperiment", S_INSTANTIATED);
    LOG_CALL(inst,
             "fmi2SetupExperiment(toleranceDefined = %d, tolerance = %.17g, startTime = %.17g, "
             "stopTimeDefined = %d, stopTime = %.17g)",
             (int)toleranceDefined, tolerance, startTime, (int)stopTimeDefined, stopTime);
    if (!isfinite(startTime) || (stopTimeDefined && !(stopTime >= startTime))) {
        logf_(inst, FP_ERROR, FP_LOG_ERROR,
              "fmi2SetupExperiment: startTime %g / stopTime %g are not a valid interval",
              startTime, stopTime);
        return fmi2Error;
    }
    inst->time = startTime;
    inst->dirty = 1;
    return fmi2OK;
}

fmi2Status fmi2EnterInitializationMode(fmi2Component c) {
    CHECK("fmi2EnterInitializationMode", S_INSTANTIATED);
    LOG_CALL(inst, "fmi2EnterInitializationMode()");
    inst->state = S_INIT;
    return fmi2OK;
}

fmi2Status fmi2ExitInitializationMode(fmi2Component c) {
    fmi2Status s;
    CHECK("fmi2ExitInitializationMode", S_INIT);
    LOG_CALL(inst, "fmi2ExitInitializationMode()");
    inst->dirty = 1; /* always validate the final parameter set */
    s = refresh(inst);
    if (s > fmi2Warning) return s;
    inst->state = S_STEP_COMPLETE;
    inst->tunables_dirty = 0;
    logf_(inst, FP_OK, FP_LOG_EVENTS, "initialized at t = %g", inst->time);
    return s;
}

fmi2Status fmi2Terminate(fmi2Component c) {
    CHECK("fmi2Terminate", S_STEP_COMPLETE | S_STEP_FAILED);
    LOG_CALL(inst, "fmi2Terminate()");
    inst->state = S_TERMINATED;
    return fmi2OK;
}

fmi2Status fmi2Reset(fmi2Component c) {
    CHECK("fmi2Reset", S_ANY_BUT_FATAL);
    LOG_CALL(inst, "fmi2Reset()");
    memset(inst->model, 0, inst->info->model_size);
    inst->info->set_defaults(inst->model);
    inst->state = S_INSTANTIATED;
    inst->time = 0.0;
    inst->dirty = 1;
    inst->tunables_dirty = 0;
    inst->n_warned = 0; /* a new initialization: its warnings are news again */
    logf_(inst, FP_OK, FP_LOG_EVENTS, "reset");
    return fmi2OK;
}

/* ------------------------------------------------------------------------ */
/* Getting and setting values                                               */

fmi2Status fmi2GetReal(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                       fmi2Real value[]) {
    fmi2Status s;
    size_t i;
    CHECK("fmi2GetReal", S_READABLE);
    if (null_arrays(inst, "fmi2GetReal", vr, nvr, value) != fmi2OK) return fmi2Error;
    s = refresh(inst);
    for (i = 0; i < nvr && s <= fmi2Warning; i++) {
        uint32_t k;
        const FpVar *v = lookup(inst, vr[i], FP_REAL, &k, "fmi2GetReal");
        if (v == NULL) s = fmi2Error;
        else value[i] = *(const double *)element(inst, v, k);
    }
    log_values(inst, "fmi2GetReal", vr, nvr, value, FP_REAL, s <= fmi2Warning ? nvr : 0);
    return s;
}

static fmi2Status get_ints(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, int *value,
                           FpVarType type, const char *fn) {
    fmi2Status s;
    size_t i;
    CHECK(fn, S_READABLE);
    if (null_arrays(inst, fn, vr, nvr, value) != fmi2OK) return fmi2Error;
    s = refresh(inst);
    for (i = 0; i < nvr && s <= fmi2Warning; i++) {
        uint32_t k;
        const FpVar *v = lookup(inst, vr[i], type, &k, fn);
        if (v == NULL) s = fmi2Error;
        else value[i] = (int)*(const int32_t *)element(inst, v, k);
    }
    log_values(inst, fn, vr, nvr, value, type, s <= fmi2Warning ? nvr : 0);
    return s;
}

fmi2Status fmi2GetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                          fmi2Integer value[]) {
    return get_ints(c, vr, nvr, value, FP_INTEGER, "fmi2GetInteger");
}

fmi2Status fmi2GetBoolean(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                          fmi2Boolean value[]) {
    return get_ints(c, vr, nvr, value, FP_BOOLEAN, "fmi2GetBoolean");
}

fmi2Status fmi2GetString(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                         fmi2String value[]) {
    CHECK("fmi2GetString", S_READABLE);
    log_values(inst, "fmi2GetString", vr, nvr, NULL, FP_REAL, 0);
    if (null_arrays(inst, "fmi2GetString", vr, nvr, value) != fmi2OK) return fmi2Error;
    if (nvr == 0) return fmi2OK;
    logf_(inst, FP_ERROR, FP_LOG_ERROR, "fmi2GetString: unknown value reference %u (no strings)",
          (unsigned)vr[0]);
    return fmi2Error;
}

/* Every element is checked before any is written: a refused set changes nothing. */
static fmi2Status check_sets(Instance *inst, const fmi2ValueReference vr[], size_t nvr,
                             FpVarType type, const char *fn) {
    size_t i;
    for (i = 0; i < nvr; i++) {
        uint32_t k;
        const FpVar *v = lookup(inst, vr[i], type, &k, fn);
        if (v == NULL || may_set(inst, v, k, fn) != fmi2OK) return fmi2Error;
    }
    return fmi2OK;
}

fmi2Status fmi2SetReal(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                       const fmi2Real value[]) {
    size_t i;
    CHECK("fmi2SetReal", S_INSTANTIATED | S_INIT | S_STEP_COMPLETE);
    if (null_arrays(inst, "fmi2SetReal", vr, nvr, value) != fmi2OK) return fmi2Error;
    log_values(inst, "fmi2SetReal", vr, nvr, value, FP_REAL, nvr);
    if (check_sets(inst, vr, nvr, FP_REAL, "fmi2SetReal") != fmi2OK) return fmi2Error;
    for (i = 0; i < nvr; i++) {
        uint32_t k = 0;
        const FpVar *v = lookup(inst, vr[i], FP_REAL, &k, "fmi2SetReal");
        *(double *)element(inst, v, k) = value[i];
        mark_changed(inst, v);
    }
    return fmi2OK;
}

static fmi2Status set_ints(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                           const int *value, FpVarType type, const char *fn) {
    size_t i;
    CHECK(fn, S_INSTANTIATED | S_INIT | S_STEP_COMPLETE);
    if (null_arrays(inst, fn, vr, nvr, value) != fmi2OK) return fmi2Error;
    log_values(inst, fn, vr, nvr, value, type, nvr);
    if (check_sets(inst, vr, nvr, type, fn) != fmi2OK) return fmi2Error;
    for (i = 0; i < nvr; i++) {
        uint32_t k = 0;
        const FpVar *v = lookup(inst, vr[i], type, &k, fn);
        *(int32_t *)element(inst, v, k) = type == FP_BOOLEAN ? (value[i] != 0) : value[i];
        mark_changed(inst, v);
    }
    return fmi2OK;
}

fmi2Status fmi2SetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                          const fmi2Integer value[]) {
    return set_ints(c, vr, nvr, value, FP_INTEGER, "fmi2SetInteger");
}

fmi2Status fmi2SetBoolean(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                          const fmi2Boolean value[]) {
    return set_ints(c, vr, nvr, value, FP_BOOLEAN, "fmi2SetBoolean");
}

fmi2Status fmi2SetString(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                         const fmi2String value[]) {
    CHECK("fmi2SetString", S_INSTANTIATED | S_INIT | S_STEP_COMPLETE);
    log_values(inst, "fmi2SetString", vr, nvr, NULL, FP_REAL, 0);
    if (null_arrays(inst, "fmi2SetString", vr, nvr, value) != fmi2OK) return fmi2Error;
    if (nvr == 0) return fmi2OK;
    logf_(inst, FP_ERROR, FP_LOG_ERROR, "fmi2SetString: unknown value reference %u (no strings)",
          (unsigned)vr[0]);
    return fmi2Error;
}

/* ------------------------------------------------------------------------ */
/* FMU state                                                                */

static size_t snapshot_size(const Instance *inst) { return fp_state_size(inst->info->model_size); }

static void snapshot_write(const Instance *inst, unsigned char *buf) {
    fp_state_write(buf, inst->guid, (int32_t)inst->state,
                   (inst->dirty ? STATE_FLAG_DIRTY : 0u) |
                       (inst->tunables_dirty ? STATE_FLAG_TUNABLES_DIRTY : 0u),
                   inst->time, inst->model, inst->info->model_size);
}

/* fp_state_check (fmu_state.h) for this instance: what is wrong is logged as "FN: WHAT
 * REASON"; 1 and *out filled, or 0. */
static int check_state(Instance *inst, const unsigned char *buf, size_t size, int level,
                       const char *fn, const char *what, StateHeader *out) {
    char why[320];
    if (fp_state_check(buf, size, level, inst->guid, inst->info->model_name,
                       inst->info->model_size, out, why, sizeof why) == FP_OK)
        return 1;
    logf_(inst, FP_ERROR, FP_LOG_ERROR, "%s: %s %s", fn, what, why);
    return 0;
}

/* Restores a state: checked whole, its model checked on the aligned scratch copy by the
 * model, and only then copied into the live model. */
static fmi2Status snapshot_read(Instance *inst, const unsigned char *buf, const char *fn) {
    StateHeader h;
    if (!check_state(inst, buf, 0, STATE_ALL, fn, "FMUstate", &h)) return fmi2Error;
    memcpy(inst->scratch, buf + sizeof h, inst->info->model_size);
    if (inst->info->check_restored != NULL) {
        FpStatus s;
        inst->checking = 1;
        s = inst->info->check_restored(inst->scratch, (h.state & S_INITIALIZED) != 0,
                                       &inst->model_logger);
        inst->checking = 0;
        if (s != FP_OK) {
            logf_(inst, FP_ERROR, FP_LOG_ERROR, "%s: the state is refused", fn);
            return fmi2Error;
        }
    }
    memcpy(inst->model, inst->scratch, inst->info->model_size);
    inst->state = h.state;
    inst->dirty = (h.flags & STATE_FLAG_DIRTY) != 0;
    inst->tunables_dirty = (h.flags & STATE_FLAG_TUNABLES_DIRTY) != 0;
    inst->time = h.time;
    return fmi2OK;
}

fmi2Status fmi2GetFMUstate(fmi2Component c, fmi2FMUstate *FMUstate) {
    unsigned char *buf;
    CHECK("fmi2GetFMUstate", S_ANY_BUT_FATAL);
    LOG_CALL(inst, "fmi2GetFMUstate(FMUstate = %p -> %p)", (void *)FMUstate,
             FMUstate ? *FMUstate : NULL);
    if (FMUstate == NULL) return null_argument(inst, "fmi2GetFMUstate", "FMUstate");
    buf = (unsigned char *)*FMUstate;
    if (buf != NULL) {
        /* a state to reuse: only one of ours has room for this one */
        if (!check_state(inst, buf, 0, STATE_HEADER, "fmi2GetFMUstate", "the FMUstate to reuse",
                         NULL))
            return fmi2Error;
    } else {
        buf = (unsigned char *)inst->allocate(1, snapshot_size(inst));
        if (buf == NULL) {
            logf_(inst, FP_ERROR, FP_LOG_ERROR, "fmi2GetFMUstate: out of memory");
            return fmi2Error;
        }
    }
    snapshot_write(inst, buf);
    *FMUstate = buf;
    return fmi2OK;
}

fmi2Status fmi2SetFMUstate(fmi2Component c, fmi2FMUstate FMUstate) {
    CHECK("fmi2SetFMUstate", S_ANY_BUT_FATAL);
    LOG_CALL(inst, "fmi2SetFMUstate(FMUstate = %p)", FMUstate);
    return snapshot_read(inst, (const unsigned char *)FMUstate, "fmi2SetFMUstate");
}

fmi2Status fmi2FreeFMUstate(fmi2Component c, fmi2FMUstate *FMUstate) {
    CHECK("fmi2FreeFMUstate", S_ANY_BUT_FATAL);
    LOG_CALL(inst, "fmi2FreeFMUstate(FMUstate = %p -> %p)", (void *)FMUstate,
             FMUstate ? *FMUstate : NULL);
    if (FMUstate == NULL) return null_argument(inst, "fmi2FreeFMUstate", "FMUstate");
    if (*FMUstate == NULL) return fmi2OK; /* FMI 2.0: a NULL state is ignored */
    if (!check_state(inst, (const unsigned char *)*FMUstate, 0, STATE_HEADER, "fmi2FreeFMUstate",
                     "FMUstate", NULL))
        return fmi2Error; /* not ours: never handed to the allocator */
    memset(*FMUstate, 0, sizeof(StateHeader)); /* a second free is refused (best effort) */
    inst->release(*FMUstate);
    *FMUstate = NULL;
    return fmi2OK;
}

fmi2Status fmi2SerializedFMUstateSize(fmi2Component c, fmi2FMUstate FMUstate, size_t *size) {
    CHECK("fmi2SerializedFMUstateSize", S_ANY_BUT_FATAL);
    LOG_CALL(inst, "fmi2SerializedFMUstateSize(FMUstate = %p)", FMUstate);
    if (size == NULL) return null_argument(inst, "fmi2SerializedFMUstateSize", "size");
    if (!check_state(inst, (const unsigned char *)FMUstate, 0, STATE_HEADER,
                     "fmi2SerializedFMUstateSize", "FMUstate", NULL))
        return fmi2Error;
    *size = snapshot_size(inst);
    return fmi2OK;
}

fmi2Status fmi2SerializeFMUstate(fmi2Component c, fmi2FMUstate FMUstate, fmi2Byte serializedState[],
                                 size_t size) {
    CHECK("fmi2SerializeFMUstate", S_ANY_BUT_FATAL);
    LOG_CALL(inst, "fmi2SerializeFMUstate(FMUstate = %p, serializedState = %p, size = %lu)",
             FMUstate, (void *)serializedState, (unsigned long)size);
    if (!check_state(inst, (const unsigned char *)FMUstate, 0, STATE_ALL,
                     "fmi2SerializeFMUstate", "FMUstate", NULL))
        return fmi2Error;
    if (serializedState == NULL)
        return null_argument(inst, "fmi2SerializeFMUstate", "serializedState");
    if (size < snapshot_size(inst)) {
        logf_(inst, FP_ERROR, FP_LOG_ERROR,
              "fmi2SerializeFMUstate: a buffer of %lu bytes is too small, the state has %lu",
              (unsigned long)size, (unsigned long)snapshot_size(inst));
        return fmi2Error;
    }
    memcpy(serializedState, FMUstate, snapshot_size(inst));
    return fmi2OK;
}

fmi2Status fmi2DeSerializeFMUstate(fmi2Component c, const fmi2Byte serializedState[], size_t size,
                                   fmi2FMUstate *FMUstate) {
    unsigned char *buf;
    CHECK("fmi2DeSerializeFMUstate", S_ANY_BUT_FATAL);
    LOG_CALL(inst, "fmi2DeSerializeFMUstate(serializedState = %p, size = %lu, FMUstate = %p)",
             (const void *)serializedState, (unsigned long)size, (void *)FMUstate);
    if (FMUstate == NULL) return null_argument(inst, "fmi2DeSerializeFMUstate", "FMUstate");
    if (serializedState == NULL)
        return null_argument(inst, "fmi2DeSerializeFMUstate", "serializedState");
    if (size == 0) {
        logf_(inst, FP_ERROR, FP_LOG_ERROR,
              "fmi2DeSerializeFMUstate: the data is empty; a state of %s has %lu bytes",
              inst->info->model_name, (unsigned long)snapshot_size(inst));
        return fmi2Error;
    }
    if (!check_state(inst, (const unsigned char *)serializedState, size, STATE_ALL,
                     "fmi2DeSerializeFMUstate", "the data", NULL))
        return fmi2Error;
    buf = (unsigned char *)*FMUstate;
    if (buf != NULL) {
        if (!check_state(inst, buf, 0, STATE_HEADER, "fmi2DeSerializeFMUstate",
                         "the FMUstate to reuse", NULL))
            return fmi2Error;
    } else {
        buf = (unsigned char *)inst->allocate(1, size);
        if (buf == NULL) {
            logf_(inst, FP_ERROR, FP_LOG_ERROR, "fmi2DeSerializeFMUstate: out of memory");
            return fmi2Error;
        }
    }
    memcpy(buf, serializedState, size);
    *FMUstate = buf;
    return fmi2OK;
}

/* ------------------------------------------------------------------------ */
/* Unsupported optional features: answered with a message, never silence.   */

fmi2Status fmi2GetDirectionalDerivative(fmi2Component c, const fmi2ValueReference vUnknown_ref[],
                                        size_t nUnknown, const fmi2ValueReference vKnown_ref[],
                                        size_t nKnown, const fmi2Real dvKnown[],
                                        fmi2Real dvUnknown[]) {
    CHECK("fmi2GetDirectionalDerivative", S_ANY_BUT_FATAL);
    LOG_CALL(inst, "fmi2GetDirectionalDerivative(nUnknown = %lu, nKnown = %lu)",
             (unsigned long)nUnknown, (unsigned long)nKnown);
    (void)vUnknown_ref, (void)nUnknown, (void)vKnown_ref, (void)nKnown, (void)dvKnown,
        (void)dvUnknown;
    logf_(inst, FP_ERROR, FP_LOG_ERROR,
          "fmi2GetDirectionalDerivative: not provided (providesDirectionalDerivative=false)");
    return fmi2Error;
}

fmi2Status fmi2SetRealInputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                                       const fmi2Integer order[], const fmi2Real value[]) {
    CHECK("fmi2SetRealInputDerivatives", S_ANY_BUT_FATAL);
    LOG_CALL(inst, "fmi2SetRealInputDerivatives(nvr = %lu)", (unsigned long)nvr);
    (void)vr, (void)nvr, (void)order, (void)value;
    logf_(inst, FP_ERROR, FP_LOG_ERROR,
          "fmi2SetRealInputDerivatives: inputs are held constant (canInterpolateInputs=false)");
    return fmi2Error;
}

fmi2Status fmi2GetRealOutputDerivatives(fmi2Component c, const fmi2ValueReference vr[],
                                        size_t nvr, const fmi2Integer order[], fmi2Real value[]) {
    CHECK("fmi2GetRealOutputDerivatives", S_ANY_BUT_FATAL);
    LOG_CALL(inst, "fmi2GetRealOutputDerivatives(nvr = %lu)", (unsigned long)nvr);
    (void)vr, (void)nvr, (void)order, (void)value;
    logf_(inst, FP_ERROR, FP_LOG_ERROR,
          "fmi2GetRealOutputDerivatives: not provided (maxOutputDerivativeOrder=0)");
    return fmi2Error;
}

fmi2Status fmi2CancelStep(fmi2Component c) {
    CHECK("fmi2CancelStep", S_ANY_BUT_FATAL);
    LOG_CALL(inst, "fmi2CancelStep()");
    logf_(inst, FP_ERROR, FP_LOG_ERROR, "fmi2CancelStep: steps are synchronous, nothing to cancel");
    return fmi2Error;
}

/* ------------------------------------------------------------------------ */
/* Stepping                                                                 */

/* Refuses a step of more than FP_MAX_INTERNAL_STEPS internal steps (fp_model.h). */
static int within_work_cap(Instance *inst, double h) {
    double hi, n;
    if (inst->internal_step == NULL) return 1;
    hi = *(const double *)element(inst, inst->internal_step, 0);
    if (!(hi > 0.0) || !isfinite(hi)) return 1; /* the model refuses it itself */
    n = fp_steps_to_cover(h, hi, FP_STEP_TOL * h);
    if (n <= FP_MAX_INTERNAL_STEPS) return 1;
    logf_(inst, FP_ERROR, FP_LOG_ERROR,
          "fmi2DoStep: communication step h = %.12g s would take %.0f internal steps of %s = "
          "%.12g s; the cap is %.0f internal steps per fmi2DoStep (%.12g s); use shorter steps",
          h, n, inst->internal_step->name, hi, FP_MAX_INTERNAL_STEPS,
          FP_MAX_INTERNAL_STEPS * hi);
    return 0;
}

fmi2Status fmi2DoStep(fmi2Component c, fmi2Real currentCommunicationPoint,
                      fmi2Real communicationStepSize, fmi2Boolean noSetFMUStatePriorToCurrentPoint) {
    FpStatus s;
    double tol;
    CHECK("fmi2DoStep", S_STEP_COMPLETE);
    LOG_CALL(inst,
             "fmi2DoStep(currentCommunicationPoint = %.17g, communicationStepSize = %.17g, "
             "noSetFMUStatePriorToCurrentPoint = %d)",
             currentCommunicationPoint, communicationStepSize,
             (int)noSetFMUStatePriorToCurrentPoint);
    if (!(communicationStepSize > 0.0) || !isfinite(communicationStepSize)) {
        logf_(inst, FP_ERROR, FP_LOG_ERROR,
              "fmi2DoStep: communicationStepSize %g must be positive and finite",
              communicationStepSize);
        return fail(inst, fmi2Error);
    }
    tol = 1e-9 * (1.0 + fabs(inst->time));
    if (!isfinite(currentCommunicationPoint) ||
        fabs(currentCommunicationPoint - inst->time) > tol) {
        logf_(inst, FP_ERROR, FP_LOG_ERROR,
              "fmi2DoStep: currentCommunicationPoint %.12g does not match the FMU time %.12g",
              currentCommunicationPoint, inst->time);
        return fail(inst, fmi2Error);
    }
    if (!within_work_cap(inst, communicationStepSize)) return fail(inst, fmi2Error);
    if (inst->tunables_dirty && inst->info->tunables_changed != NULL) {
        s = inst->info->tunables_changed(inst->model, &inst->model_logger);
        if (s == FP_ERROR || s == FP_DISCARD) return fail(inst, fmi2Error);
    }
    inst->tunables_dirty = 0;
    s = inst->info->step(inst->model, inst->time, communicationStepSize, &inst->model_logger);
    if (s == FP_ERROR) return fail(inst, fmi2Error);
    if (s == FP_DISCARD) return fail(inst, fmi2Discard);
    inst->time = currentCommunicationPoint + communicationStepSize;
    return to_fmi(s);
}

/* fmi2Get*Status: only StepComplete, StepFailed and Terminated (S_STATUS). */
static Instance *status_call(fmi2Component c, const char *fn, fmi2StatusKind s,
                             const void *value) {
    Instance *inst = enter(c, fn, S_STATUS);
    if (inst != NULL) LOG_CALL(inst, "%s(s = %d, value = %p)", fn, (int)s, value);
    if (inst != NULL && value == NULL) {
        null_argument(inst, fn, "value");
        return NULL;
    }
    return inst;
}

static fmi2Status unsupported_status(Instance *inst, const char *fn, fmi2StatusKind s) {
    static const char *const kinds[] = {"fmi2DoStepStatus", "fmi2PendingStatus",
                                        "fmi2LastSuccessfulTime", "fmi2Terminated"};
    const char *kind = ((int)s >= 0 && (int)s < 4) ? kinds[(int)s] : "unknown";
    logf_(inst, FP_WARNING, FP_LOG_WARNING,
          "%s: status kind %d (%s) is not provided: steps are synchronous (no fmi2Pending)", fn,
          (int)s, kind);
    return fmi2Discard;
}

fmi2Status fmi2GetStatus(fmi2Component c, const fmi2StatusKind s, fmi2Status *value) {
    Instance *inst = status_call(c, "fmi2GetStatus", s, value);
    if (inst == NULL) return fmi2Error;
    return unsupported_status(inst, "fmi2GetStatus", s);
}

fmi2Status fmi2GetRealStatus(fmi2Component c, const fmi2StatusKind s, fmi2Real *value) {
    Instance *inst = status_call(c, "fmi2GetRealStatus", s, value);
    if (inst == NULL) return fmi2Error;
    if (s == fmi2LastSuccessfulTime) {
        *value = inst->time;
        return fmi2OK;
    }
    return unsupported_status(inst, "fmi2GetRealStatus", s);
}

fmi2Status fmi2GetIntegerStatus(fmi2Component c, const fmi2StatusKind s, fmi2Integer *value) {
    Instance *inst = status_call(c, "fmi2GetIntegerStatus", s, value);
    if (inst == NULL) return fmi2Error;
    return unsupported_status(inst, "fmi2GetIntegerStatus", s);
}

fmi2Status fmi2GetBooleanStatus(fmi2Component c, const fmi2StatusKind s, fmi2Boolean *value) {
    Instance *inst = status_call(c, "fmi2GetBooleanStatus", s, value);
    if (inst == NULL) return fmi2Error;
    if (s == fmi2Terminated) {
        *value = fmi2False;
        return fmi2OK;
    }
    return unsupported_status(inst, "fmi2GetBooleanStatus", s);
}

fmi2Status fmi2GetStringStatus(fmi2Component c, const fmi2StatusKind s, fmi2String *value) {
    Instance *inst = status_call(c, "fmi2GetStringStatus", s, value);
    if (inst == NULL) return fmi2Error;
    return unsupported_status(inst, "fmi2GetStringStatus", s);
}

/* Model-exchange entry points are absent on purpose: this is a CS-only FMU. */
