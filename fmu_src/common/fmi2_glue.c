/*
 * Generic FMI 2.0 co-simulation layer shared by every fullpose FMU.
 *
 * It owns the FMI call-sequence state machine, logging through the
 * importer's callback, value-reference dispatch into the model struct and
 * FMU state snapshots.  The model behind it is reached only through
 * FpModelInfo (fp_model.h) and never sees an FMI type.
 */
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <string.h>

#include "fmi2Functions.h"
#include "fp_model.h"

/* States of the FMI 2.0 co-simulation state machine (spec section 4.2.4). */
enum {
    S_INSTANTIATED = 1 << 0,
    S_INIT = 1 << 1,
    S_STEP_COMPLETE = 1 << 2,
    S_STEP_FAILED = 1 << 3,
    S_TERMINATED = 1 << 4,
    S_ERROR = 1 << 5,
    S_FATAL = 1 << 6
};

#define S_ANY_BUT_FATAL \
    (S_INSTANTIATED | S_INIT | S_STEP_COMPLETE | S_STEP_FAILED | S_TERMINATED | S_ERROR)
#define S_READABLE (S_INIT | S_STEP_COMPLETE | S_STEP_FAILED | S_TERMINATED | S_ERROR)

#define SNAPSHOT_MAGIC 0x31535046u /* "FPS1" */

typedef struct {
    uint32_t magic;
    uint32_t model_size;
    char guid[40];
    int32_t state;
    int32_t dirty;
    int32_t tunables_dirty;
    int32_t pad;
    double time;
} SnapshotHeader;

typedef struct {
    fmi2CallbackLogger logger;
    fmi2CallbackAllocateMemory allocate;
    fmi2CallbackFreeMemory release;
    fmi2ComponentEnvironment env;
    char *name;
    const FpModelInfo *info;
    char guid[40];
    int state;
    int logging_on;
    unsigned categories; /* bit per FpLogCategory enabled for debug logging */
    double time;
    int dirty;          /* parameters/inputs changed since the last initialize */
    int tunables_dirty; /* tunable parameters changed while stepping */
    uint32_t n_vr;      /* size of vr_map */
    int32_t *vr_map;    /* value reference -> index into info->vars, or -1 */
    void *model;
    FpLogger model_logger;
} Instance;

static const char *state_name(int state) {
    switch (state) {
    case S_INSTANTIATED: return "Instantiated";
    case S_INIT: return "InitializationMode";
    case S_STEP_COMPLETE: return "StepComplete";
    case S_STEP_FAILED: return "StepFailed";
    case S_TERMINATED: return "Terminated";
    case S_ERROR: return "Error";
    default: return "Fatal";
    }
}

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

static void model_log(void *env, FpStatus status, FpLogCategory category, const char *message) {
    Instance *inst = (Instance *)env;
    if (!wants(inst, status, category)) return;
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

/* Checks a call is legal in the current state; illegal calls change nothing. */
static int allowed(Instance *inst, const char *fn, int states) {
    if (inst == NULL) return 0;
    if (inst->state & states) {
        if (inst->logging_on && (inst->categories & (1u << FP_LOG_CALLS)))
            logf_(inst, FP_OK, FP_LOG_CALLS, "%s", fn);
        return 1;
    }
    logf_(inst, FP_ERROR, FP_LOG_ERROR, "%s may not be called in state %s", fn,
          state_name(inst->state));
    return 0;
}

#define CHECK(fn, states)                                                   \
    do {                                                                    \
        if (!allowed((Instance *)c, fn, states)) return fmi2Error;          \
    } while (0)

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
    s = inst->info->initialize(inst->model, inst->time, &inst->model_logger);
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
    Instance *inst = (Instance *)c;
    size_t i;
    int j;
    unsigned mask = 0;
    CHECK("fmi2SetDebugLogging", S_ANY_BUT_FATAL);
    if (nCategories > 0 && categories == NULL) {
        logf_(inst, FP_ERROR, FP_LOG_ERROR, "fmi2SetDebugLogging: categories is NULL");
        return fmi2Error;
    }
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
    if (inst->vr_map) release(inst->vr_map);
    if (inst->name) release(inst->name);
    release(inst);
}

fmi2Component fmi2Instantiate(fmi2String instanceName, fmi2Type fmuType, fmi2String fmuGUID,
                              fmi2String fmuResourceLocation,
                              const fmi2CallbackFunctions *functions, fmi2Boolean visible,
                              fmi2Boolean loggingOn) {
    const FpModelInfo *info = fp_model_info();
    Instance *inst;
    uint32_t max_vr = 0;
    size_t i;
    (void)fmuResourceLocation;
    (void)visible;
    if (functions == NULL || functions->allocateMemory == NULL || functions->freeMemory == NULL)
        return NULL;
    inst = (Instance *)functions->allocateMemory(1, sizeof(Instance));
    if (inst == NULL) return NULL;
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
        inst->release(inst);
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
    if (inst->vr_map == NULL || inst->model == NULL) {
        logf_(inst, FP_ERROR, FP_LOG_ERROR, "fmi2Instantiate: out of memory");
        release_instance(inst);
        return NULL;
    }
    for (i = 0; i < inst->n_vr; i++) inst->vr_map[i] = -1;
    for (i = 0; i < info->n_vars; i++) {
        uint32_t k, n = fp_var_count(&info->vars[i]);
        for (k = 0; k < n; k++) inst->vr_map[info->vars[i].vr + k] = (int32_t)i;
    }
    info->set_defaults(inst->model);
    inst->dirty = 1;
    logf_(inst, FP_OK, FP_LOG_EVENTS, "instantiated %s", info->model_name);
    return inst;
}

void fmi2FreeInstance(fmi2Component c) {
    Instance *inst = (Instance *)c;
    if (inst == NULL) return;
    if (!allowed(inst, "fmi2FreeInstance", S_ANY_BUT_FATAL | S_FATAL)) return;
    release_instance(inst);
}

fmi2Status fmi2SetupExperiment(fmi2Component c, fmi2Boolean toleranceDefined,
                               fmi2Real tolerance, fmi2Real startTime,
                               fmi2Boolean stopTimeDefined, fmi2Real stopTime) {
    Instance *inst = (Instance *)c;
    (void)toleranceDefined;
    (void)tolerance;
    CHECK("fmi2SetupExperiment", S_INSTANTIATED);
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
    Instance *inst = (Instance *)c;
    CHECK("fmi2EnterInitializationMode", S_INSTANTIATED);
    inst->state = S_INIT;
    return fmi2OK;
}

fmi2Status fmi2ExitInitializationMode(fmi2Component c) {
    Instance *inst = (Instance *)c;
    fmi2Status s;
    CHECK("fmi2ExitInitializationMode", S_INIT);
    inst->dirty = 1; /* always validate the final parameter set */
    s = refresh(inst);
    if (s > fmi2Warning) return s;
    inst->state = S_STEP_COMPLETE;
    inst->tunables_dirty = 0;
    logf_(inst, FP_OK, FP_LOG_EVENTS, "initialized at t = %g", inst->time);
    return s;
}

fmi2Status fmi2Terminate(fmi2Component c) {
    Instance *inst = (Instance *)c;
    CHECK("fmi2Terminate", S_STEP_COMPLETE | S_STEP_FAILED);
    inst->state = S_TERMINATED;
    return fmi2OK;
}

fmi2Status fmi2Reset(fmi2Component c) {
    Instance *inst = (Instance *)c;
    CHECK("fmi2Reset", S_ANY_BUT_FATAL);
    memset(inst->model, 0, inst->info->model_size);
    inst->info->set_defaults(inst->model);
    inst->state = S_INSTANTIATED;
    inst->time = 0.0;
    inst->dirty = 1;
    inst->tunables_dirty = 0;
    logf_(inst, FP_OK, FP_LOG_EVENTS, "reset");
    return fmi2OK;
}

/* ------------------------------------------------------------------------ */
/* Getting and setting values                                               */

fmi2Status fmi2GetReal(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                       fmi2Real value[]) {
    Instance *inst = (Instance *)c;
    fmi2Status s;
    size_t i;
    CHECK("fmi2GetReal", S_READABLE);
    if (nvr > 0 && (vr == NULL || value == NULL)) return fmi2Error;
    s = refresh(inst);
    if (s > fmi2Warning) return s;
    for (i = 0; i < nvr; i++) {
        uint32_t k;
        const FpVar *v = lookup(inst, vr[i], FP_REAL, &k, "fmi2GetReal");
        if (v == NULL) return fmi2Error;
        value[i] = *(const double *)element(inst, v, k);
    }
    return s;
}

static fmi2Status get_ints(Instance *inst, const fmi2ValueReference vr[], size_t nvr, int *value,
                           FpVarType type, const char *fn) {
    fmi2Status s;
    size_t i;
    if (!allowed(inst, fn, S_READABLE)) return fmi2Error;
    if (nvr > 0 && (vr == NULL || value == NULL)) return fmi2Error;
    s = refresh(inst);
    if (s > fmi2Warning) return s;
    for (i = 0; i < nvr; i++) {
        uint32_t k;
        const FpVar *v = lookup(inst, vr[i], type, &k, fn);
        if (v == NULL) return fmi2Error;
        value[i] = (int)*(const int32_t *)element(inst, v, k);
    }
    return s;
}

fmi2Status fmi2GetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                          fmi2Integer value[]) {
    return get_ints((Instance *)c, vr, nvr, value, FP_INTEGER, "fmi2GetInteger");
}

fmi2Status fmi2GetBoolean(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                          fmi2Boolean value[]) {
    return get_ints((Instance *)c, vr, nvr, value, FP_BOOLEAN, "fmi2GetBoolean");
}

fmi2Status fmi2GetString(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                         fmi2String value[]) {
    Instance *inst = (Instance *)c;
    (void)value;
    CHECK("fmi2GetString", S_READABLE);
    if (nvr == 0) return fmi2OK;
    if (vr == NULL) return fmi2Error;
    logf_(inst, FP_ERROR, FP_LOG_ERROR, "fmi2GetString: unknown value reference %u (no strings)",
          (unsigned)vr[0]);
    return fmi2Error;
}

fmi2Status fmi2SetReal(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                       const fmi2Real value[]) {
    Instance *inst = (Instance *)c;
    size_t i;
    CHECK("fmi2SetReal", S_INSTANTIATED | S_INIT | S_STEP_COMPLETE);
    if (nvr > 0 && (vr == NULL || value == NULL)) return fmi2Error;
    for (i = 0; i < nvr; i++) {
        uint32_t k;
        const FpVar *v = lookup(inst, vr[i], FP_REAL, &k, "fmi2SetReal");
        if (v == NULL || may_set(inst, v, k, "fmi2SetReal") != fmi2OK) return fmi2Error;
        *(double *)element(inst, v, k) = value[i];
        mark_changed(inst, v);
    }
    return fmi2OK;
}

static fmi2Status set_ints(Instance *inst, const fmi2ValueReference vr[], size_t nvr,
                           const int *value, FpVarType type, const char *fn) {
    size_t i;
    if (!allowed(inst, fn, S_INSTANTIATED | S_INIT | S_STEP_COMPLETE)) return fmi2Error;
    if (nvr > 0 && (vr == NULL || value == NULL)) return fmi2Error;
    for (i = 0; i < nvr; i++) {
        uint32_t k;
        const FpVar *v = lookup(inst, vr[i], type, &k, fn);
        if (v == NULL || may_set(inst, v, k, fn) != fmi2OK) return fmi2Error;
        *(int32_t *)element(inst, v, k) = type == FP_BOOLEAN ? (value[i] != 0) : value[i];
        mark_changed(inst, v);
    }
    return fmi2OK;
}

fmi2Status fmi2SetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                          const fmi2Integer value[]) {
    return set_ints((Instance *)c, vr, nvr, value, FP_INTEGER, "fmi2SetInteger");
}

fmi2Status fmi2SetBoolean(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                          const fmi2Boolean value[]) {
    return set_ints((Instance *)c, vr, nvr, value, FP_BOOLEAN, "fmi2SetBoolean");
}

fmi2Status fmi2SetString(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                         const fmi2String value[]) {
    Instance *inst = (Instance *)c;
    (void)value;
    CHECK("fmi2SetString", S_INSTANTIATED | S_INIT | S_STEP_COMPLETE);
    if (nvr == 0) return fmi2OK;
    if (vr == NULL) return fmi2Error;
    logf_(inst, FP_ERROR, FP_LOG_ERROR, "fmi2SetString: unknown value reference %u (no strings)",
          (unsigned)vr[0]);
    return fmi2Error;
}

/* ------------------------------------------------------------------------ */
/* FMU state                                                                */

static size_t snapshot_size(const Instance *inst) {
    return sizeof(SnapshotHeader) + inst->info->model_size;
}

static void snapshot_write(const Instance *inst, unsigned char *buf) {
    SnapshotHeader h;
    memset(&h, 0, sizeof h);
    h.magic = SNAPSHOT_MAGIC;
    h.model_size = (uint32_t)inst->info->model_size;
    memcpy(h.guid, inst->guid, sizeof h.guid);
    h.state = inst->state;
    h.dirty = inst->dirty;
    h.tunables_dirty = inst->tunables_dirty;
    h.time = inst->time;
    memcpy(buf, &h, sizeof h);
    memcpy(buf + sizeof h, inst->model, inst->info->model_size);
}

static fmi2Status snapshot_read(Instance *inst, const unsigned char *buf, size_t size,
                                const char *fn) {
    SnapshotHeader h;
    if (buf == NULL || size != snapshot_size(inst)) {
        logf_(inst, FP_ERROR, FP_LOG_ERROR, "%s: state of %lu bytes, expected %lu", fn,
              (unsigned long)size, (unsigned long)snapshot_size(inst));
        return fmi2Error;
    }
    memcpy(&h, buf, sizeof h);
    if (h.magic != SNAPSHOT_MAGIC || h.model_size != inst->info->model_size ||
        memcmp(h.guid, inst->guid, sizeof h.guid) != 0) {
        logf_(inst, FP_ERROR, FP_LOG_ERROR, "%s: the state was not saved by this model (%s)", fn,
              inst->info->model_name);
        return fmi2Error;
    }
    if (!(h.state & S_ANY_BUT_FATAL) || (h.state & (h.state - 1)) != 0 || !isfinite(h.time)) {
        logf_(inst, FP_ERROR, FP_LOG_ERROR, "%s: the state is corrupt", fn);
        return fmi2Error;
    }
    /* TODO(issue 13 glue): validate an aligned copy, not the importer's buffer */
    if (inst->info->check_restored != NULL &&
        inst->info->check_restored(
            buf + sizeof h, (h.state & (S_STEP_COMPLETE | S_STEP_FAILED | S_TERMINATED)) != 0,
            &inst->model_logger) != FP_OK) {
        logf_(inst, FP_ERROR, FP_LOG_ERROR, "%s: the state is refused", fn);
        return fmi2Error;
    }
    memcpy(inst->model, buf + sizeof h, inst->info->model_size);
    inst->state = h.state;
    inst->dirty = h.dirty;
    inst->tunables_dirty = h.tunables_dirty;
    inst->time = h.time;
    return fmi2OK;
}

fmi2Status fmi2GetFMUstate(fmi2Component c, fmi2FMUstate *FMUstate) {
    Instance *inst = (Instance *)c;
    unsigned char *buf;
    CHECK("fmi2GetFMUstate", S_ANY_BUT_FATAL);
    if (FMUstate == NULL) return fmi2Error;
    buf = (unsigned char *)*FMUstate;
    if (buf == NULL) {
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
    Instance *inst = (Instance *)c;
    CHECK("fmi2SetFMUstate", S_ANY_BUT_FATAL);
    return snapshot_read(inst, (const unsigned char *)FMUstate, snapshot_size(inst),
                         "fmi2SetFMUstate");
}

fmi2Status fmi2FreeFMUstate(fmi2Component c, fmi2FMUstate *FMUstate) {
    Instance *inst = (Instance *)c;
    CHECK("fmi2FreeFMUstate", S_ANY_BUT_FATAL);
    if (FMUstate != NULL && *FMUstate != NULL) {
        inst->release(*FMUstate);
        *FMUstate = NULL;
    }
    return fmi2OK;
}

fmi2Status fmi2SerializedFMUstateSize(fmi2Component c, fmi2FMUstate FMUstate, size_t *size) {
    Instance *inst = (Instance *)c;
    (void)FMUstate;
    CHECK("fmi2SerializedFMUstateSize", S_ANY_BUT_FATAL);
    if (size == NULL) return fmi2Error;
    *size = snapshot_size(inst);
    return fmi2OK;
}

fmi2Status fmi2SerializeFMUstate(fmi2Component c, fmi2FMUstate FMUstate, fmi2Byte serializedState[],
                                 size_t size) {
    Instance *inst = (Instance *)c;
    CHECK("fmi2SerializeFMUstate", S_ANY_BUT_FATAL);
    if (FMUstate == NULL || serializedState == NULL || size < snapshot_size(inst)) {
        logf_(inst, FP_ERROR, FP_LOG_ERROR,
              "fmi2SerializeFMUstate: need a state and a buffer of %lu bytes",
              (unsigned long)snapshot_size(inst));
        return fmi2Error;
    }
    memcpy(serializedState, FMUstate, snapshot_size(inst));
    return fmi2OK;
}

fmi2Status fmi2DeSerializeFMUstate(fmi2Component c, const fmi2Byte serializedState[], size_t size,
                                   fmi2FMUstate *FMUstate) {
    Instance *inst = (Instance *)c;
    SnapshotHeader h;
    unsigned char *buf;
    CHECK("fmi2DeSerializeFMUstate", S_ANY_BUT_FATAL);
    if (FMUstate == NULL || serializedState == NULL || size != snapshot_size(inst)) {
        logf_(inst, FP_ERROR, FP_LOG_ERROR,
              "fmi2DeSerializeFMUstate: serialized state of %lu bytes, expected %lu",
              (unsigned long)size, (unsigned long)snapshot_size(inst));
        return fmi2Error;
    }
    memcpy(&h, serializedState, sizeof h);
    if (h.magic != SNAPSHOT_MAGIC || memcmp(h.guid, inst->guid, sizeof h.guid) != 0) {
        logf_(inst, FP_ERROR, FP_LOG_ERROR,
              "fmi2DeSerializeFMUstate: the data was not serialized by this model (%s)",
              inst->info->model_name);
        return fmi2Error;
    }
    buf = (unsigned char *)(*FMUstate ? *FMUstate : inst->allocate(1, size));
    if (buf == NULL) return fmi2Error;
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
    Instance *inst = (Instance *)c;
    (void)vUnknown_ref, (void)nUnknown, (void)vKnown_ref, (void)nKnown, (void)dvKnown,
        (void)dvUnknown;
    CHECK("fmi2GetDirectionalDerivative", S_ANY_BUT_FATAL);
    logf_(inst, FP_ERROR, FP_LOG_ERROR,
          "fmi2GetDirectionalDerivative: not provided (providesDirectionalDerivative=false)");
    return fmi2Error;
}

fmi2Status fmi2SetRealInputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                                       const fmi2Integer order[], const fmi2Real value[]) {
    Instance *inst = (Instance *)c;
    (void)vr, (void)nvr, (void)order, (void)value;
    CHECK("fmi2SetRealInputDerivatives", S_ANY_BUT_FATAL);
    logf_(inst, FP_ERROR, FP_LOG_ERROR,
          "fmi2SetRealInputDerivatives: inputs are held constant (canInterpolateInputs=false)");
    return fmi2Error;
}

fmi2Status fmi2GetRealOutputDerivatives(fmi2Component c, const fmi2ValueReference vr[],
                                        size_t nvr, const fmi2Integer order[], fmi2Real value[]) {
    Instance *inst = (Instance *)c;
    (void)vr, (void)nvr, (void)order, (void)value;
    CHECK("fmi2GetRealOutputDerivatives", S_ANY_BUT_FATAL);
    logf_(inst, FP_ERROR, FP_LOG_ERROR,
          "fmi2GetRealOutputDerivatives: not provided (maxOutputDerivativeOrder=0)");
    return fmi2Error;
}

fmi2Status fmi2CancelStep(fmi2Component c) {
    Instance *inst = (Instance *)c;
    CHECK("fmi2CancelStep", S_ANY_BUT_FATAL);
    logf_(inst, FP_ERROR, FP_LOG_ERROR, "fmi2CancelStep: steps are synchronous, nothing to cancel");
    return fmi2Error;
}

/* ------------------------------------------------------------------------ */
/* Stepping                                                                 */

fmi2Status fmi2DoStep(fmi2Component c, fmi2Real currentCommunicationPoint,
                      fmi2Real communicationStepSize, fmi2Boolean noSetFMUStatePriorToCurrentPoint) {
    Instance *inst = (Instance *)c;
    FpStatus s;
    double tol;
    (void)noSetFMUStatePriorToCurrentPoint;
    CHECK("fmi2DoStep", S_STEP_COMPLETE);
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

fmi2Status fmi2GetStatus(fmi2Component c, const fmi2StatusKind s, fmi2Status *value) {
    Instance *inst = (Instance *)c;
    (void)value;
    CHECK("fmi2GetStatus", S_READABLE);
    logf_(inst, FP_WARNING, FP_LOG_WARNING,
          "fmi2GetStatus: status kind %d is only defined for asynchronous steps", (int)s);
    return fmi2Discard;
}

fmi2Status fmi2GetRealStatus(fmi2Component c, const fmi2StatusKind s, fmi2Real *value) {
    Instance *inst = (Instance *)c;
    CHECK("fmi2GetRealStatus", S_READABLE);
    if (s == fmi2LastSuccessfulTime && value != NULL) {
        *value = inst->time;
        return fmi2OK;
    }
    logf_(inst, FP_WARNING, FP_LOG_WARNING, "fmi2GetRealStatus: unsupported status kind %d", (int)s);
    return fmi2Discard;
}

fmi2Status fmi2GetIntegerStatus(fmi2Component c, const fmi2StatusKind s, fmi2Integer *value) {
    Instance *inst = (Instance *)c;
    (void)value;
    CHECK("fmi2GetIntegerStatus", S_READABLE);
    logf_(inst, FP_WARNING, FP_LOG_WARNING, "fmi2GetIntegerStatus: unsupported status kind %d",
          (int)s);
    return fmi2Discard;
}

fmi2Status fmi2GetBooleanStatus(fmi2Component c, const fmi2StatusKind s, fmi2Boolean *value) {
    Instance *inst = (Instance *)c;
    CHECK("fmi2GetBooleanStatus", S_READABLE);
    if (s == fmi2Terminated && value != NULL) {
        *value = fmi2False;
        return fmi2OK;
    }
    logf_(inst, FP_WARNING, FP_LOG_WARNING, "fmi2GetBooleanStatus: unsupported status kind %d",
          (int)s);
    return fmi2Discard;
}

fmi2Status fmi2GetStringStatus(fmi2Component c, const fmi2StatusKind s, fmi2String *value) {
    Instance *inst = (Instance *)c;
    (void)value;
    CHECK("fmi2GetStringStatus", S_READABLE);
    logf_(inst, FP_WARNING, FP_LOG_WARNING, "fmi2GetStringStatus: unsupported status kind %d",
          (int)s);
    return fmi2Discard;
}

/* Model-exchange entry points are absent on purpose: this is a CS-only FMU. */
