/*
 * Generic FMI 2.0 co-simulation layer shared by every fullpose FMU.
 *
 * It owns the FMI call-sequence state machine (instantiation, initialization, stepping,
 * termination, reset, the status inquiries) and logging through the importer's callback.
 * The value-reference dispatch into the model struct is fmi2_values.c, FMU state snapshots
 * fmi2_fmustate.c (their format: fmu_state.c); what the three share is
 * fmi2_glue_internal.h.  The model behind it is reached only through FpModelInfo
 * (fp_model.h) and never sees an FMI type.
 */
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <string.h>

#include "fmi2_glue_internal.h"

/* fmi2Get*Status (FMI 2.0.4 co-simulation state table): StepComplete, StepInProgress,
 * StepFailed, Terminated; this FMU has no asynchronous step, so no StepInProgress */
#define S_STATUS (S_STEP_COMPLETE | S_STEP_FAILED | S_TERMINATED)

/* Marks a live instance; cleared to INSTANCE_FREED by fmi2FreeInstance. */
#define INSTANCE_LIVE 0x4650494eu  /* "FPIN" */
#define INSTANCE_FREED 0x46524545u /* "FREE" */

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

void glue_logf(Instance *inst, FpStatus status, FpLogCategory category, const char *fmt, ...) {
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
    glue_logf(inst, FP_ERROR, FP_LOG_ERROR, "%s may not be called in state %s", fn,
              fp_lifecycle_name(inst->state));
    return 0;
}

/* Entry of every function taking an instance: a live instance in one of `states`. */
Instance *glue_enter(fmi2Component c, const char *fn, int states) {
    Instance *inst = instance(c, fn);
    if (inst == NULL || !allowed(inst, fn, states)) return NULL;
    return inst;
}

/* A NULL array or pointer argument: refused with a message naming it. */
fmi2Status glue_null_argument(Instance *inst, const char *fn, const char *what) {
    glue_logf(inst, FP_ERROR, FP_LOG_ERROR, "%s: %s is NULL", fn, what);
    return fmi2Error;
}

/* A failure of the model's computation (initialization, a step): Error (or StepFailed). */
static fmi2Status fail(Instance *inst, fmi2Status status) {
    if (status == fmi2Error) inst->state = S_ERROR;
    if (status == fmi2Discard) inst->state = S_STEP_FAILED;
    return status;
}

fmi2Status glue_fail(Instance *inst, fmi2Status status) { return fail(inst, status); }

/* Model Exchange: the model's derivatives and outputs at the time, states and inputs set
 * (the model evaluates once per change, however often they are read). */
static fmi2Status me_refresh(Instance *inst) {
    FpStatus s;
    if (!inst->me_stale) return fmi2OK;
    if (inst->tunables_dirty && inst->info->tunables_changed != NULL) {
        s = inst->info->tunables_changed(inst->model, &inst->model_logger);
        if (s == FP_ERROR || s == FP_DISCARD) return fail(inst, fmi2Error);
    }
    inst->tunables_dirty = 0;
    s = inst->info->me->evaluate(inst->model, inst->time, &inst->model_logger);
    if (s == FP_ERROR || s == FP_DISCARD) return fail(inst, fmi2Error);
    inst->me_stale = 0;
    return fmi2OK;
}

/* Brings initial outputs up to date after parameter changes (FMI 2.0: values
 * read in initialization mode are computed from what was set); a Model Exchange instance
 * also checks that its parameters leave it something a solver can integrate. */
fmi2Status glue_refresh(Instance *inst) {
    FpStatus s;
    if (inst->state & S_ME_RUNNING) return me_refresh(inst);
    if (!(inst->state & (S_INIT | S_INSTANTIATED)) || !inst->dirty) return fmi2OK;
    inst->checking = 1;
    s = inst->info->initialize(inst->model, inst->time, &inst->model_logger);
    if (s != FP_ERROR && s != FP_DISCARD && inst->me) {
        FpStatus me = inst->info->me->check(inst->model, &inst->model_logger);
        if (me != FP_OK) s = me;
    }
    inst->checking = 0;
    if (s == FP_ERROR || s == FP_DISCARD) return fail(inst, fmi2Error);
    inst->dirty = 0;
    inst->me_stale = 1;
    return to_fmi(s);
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
        return glue_null_argument(inst, "fmi2SetDebugLogging", "categories");
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
                glue_logf(inst, FP_ERROR, FP_LOG_ERROR, "fmi2SetDebugLogging: unknown category %s",
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
    if (inst->table.data) release(inst->table.data);
    if (inst->name) release(inst->name);
    inst->magic = INSTANCE_FREED;
    release(inst);
}

/* The fixed Real scalar parameter holding the model's internal step (fp_model.h). */
/* The model's initialized marker (FpModelInfo.initialized_offset): kept here, carried by
 * every FMU state, checked against a restored state's lifecycle (fmu_state.c). */
static void set_initialized(Instance *inst, int32_t on) {
    memcpy((char *)inst->model + inst->info->initialized_offset, &on, sizeof on);
}

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
        glue_logf(inst, FP_ERROR, FP_LOG_ERROR, "fmi2Instantiate: out of memory");
        inst->name = NULL;
        release_instance(inst);
        return NULL;
    }
    strcpy(inst->name, instanceName ? instanceName : "");
    fp_model_guid(info, inst->guid);

    if (instanceName == NULL || instanceName[0] == '\0') {
        glue_logf(inst, FP_ERROR, FP_LOG_ERROR, "fmi2Instantiate: instanceName must not be empty");
        release_instance(inst);
        return NULL;
    }
    if (fmuType == fmi2ModelExchange && info->me == NULL) {
        glue_logf(inst, FP_ERROR, FP_LOG_ERROR,
                  "fmi2Instantiate: %s supports co-simulation only (fmuType must be "
                  "fmi2CoSimulation): it has no continuous state to hand to a solver, it "
                  "computes on its own sample grid",
                  info->model_name);
        release_instance(inst);
        return NULL;
    }
    if (fmuType != fmi2CoSimulation && fmuType != fmi2ModelExchange) {
        glue_logf(inst, FP_ERROR, FP_LOG_ERROR,
                  "fmi2Instantiate: fmuType %d is neither fmi2ModelExchange nor "
                  "fmi2CoSimulation",
                  (int)fmuType);
        release_instance(inst);
        return NULL;
    }
    inst->me = fmuType == fmi2ModelExchange;
    if (fmuGUID == NULL || strcmp(fmuGUID, inst->guid) != 0) {
        glue_logf(inst, FP_ERROR, FP_LOG_ERROR,
                  "fmi2Instantiate: GUID %s does not match this binary (%s); the FMU is "
                  "inconsistent",
                  fmuGUID ? fmuGUID : "(null)", inst->guid);
        release_instance(inst);
        return NULL;
    }
    for (i = 0; i < info->n_vars; i++) {
        uint32_t last = info->vars[i].vr + fp_var_count(&info->vars[i]) - 1;
        if (last > max_vr) max_vr = last;
    }
    inst->n_vr = max_vr + 1;
    if (info->model_size < sizeof(int32_t) ||
        info->initialized_offset > info->model_size - sizeof(int32_t)) {
        glue_logf(inst, FP_ERROR, FP_LOG_ERROR,
                  "fmi2Instantiate: the model's initialized marker (at %lu) lies beyond its "
                  "%lu bytes; the FMU is inconsistent",
                  (unsigned long)info->initialized_offset, (unsigned long)info->model_size);
        release_instance(inst);
        return NULL;
    }
    inst->vr_map = (int32_t *)inst->allocate(inst->n_vr, sizeof(int32_t));
    inst->model = inst->allocate(1, info->model_size);
    inst->scratch = inst->allocate(1, info->model_size);
    if (inst->vr_map == NULL || inst->model == NULL || inst->scratch == NULL) {
        glue_logf(inst, FP_ERROR, FP_LOG_ERROR, "fmi2Instantiate: out of memory");
        release_instance(inst);
        return NULL;
    }
    for (i = 0; i < inst->n_vr; i++) inst->vr_map[i] = -1;
    for (i = 0; i < info->n_vars; i++) {
        uint32_t k, n = fp_var_count(&info->vars[i]);
        for (k = 0; k < n; k++) inst->vr_map[info->vars[i].vr + k] = (int32_t)i;
    }
    inst->internal_step = find_internal_step(info);
    if (info->table_resource != NULL) {
        char why[640];
        if (glue_load_table(inst, fmuResourceLocation, why, sizeof why) != 0) {
            glue_logf(inst, FP_ERROR, FP_LOG_ERROR, "fmi2Instantiate: %s", why);
            release_instance(inst);
            return NULL;
        }
        glue_logf(inst, FP_OK, FP_LOG_EVENTS, "read resources/%s: %lu rows of %lu signals",
                  info->table_resource, (unsigned long)inst->table.rows,
                  (unsigned long)inst->table.cols);
    }
    info->set_defaults(inst->model);
    set_initialized(inst, 0);
    inst->dirty = 1;
    LOG_CALL(inst,
             "fmi2Instantiate(instanceName = \"%.64s\", fmuType = %d, fmuGUID = \"%s\", "
             "fmuResourceLocation = \"%.200s\", visible = %d, loggingOn = %d)",
             instanceName, (int)fmuType, fmuGUID,
             fmuResourceLocation ? fmuResourceLocation : "(null)", (int)visible, (int)loggingOn);
    glue_logf(inst, FP_OK, FP_LOG_EVENTS, "instantiated %s", info->model_name);
    return inst;
}

void fmi2FreeInstance(fmi2Component c) {
    Instance *inst = glue_enter(c, "fmi2FreeInstance", S_ANY_BUT_FATAL | S_FATAL);
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
        glue_logf(inst, FP_ERROR, FP_LOG_ERROR,
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
    s = glue_refresh(inst);
    if (s > fmi2Warning) return s;
    set_initialized(inst, 1);
    inst->state = inst->me ? S_EVENT_MODE : S_STEP_COMPLETE;
    inst->tunables_dirty = 0;
    glue_logf(inst, FP_OK, FP_LOG_EVENTS, "initialized at t = %g", inst->time);
    return s;
}

fmi2Status fmi2Terminate(fmi2Component c) {
    CHECK("fmi2Terminate", S_STEP_COMPLETE | S_STEP_FAILED | S_ME_RUNNING);
    LOG_CALL(inst, "fmi2Terminate()");
    inst->state = S_TERMINATED;
    return fmi2OK;
}

fmi2Status fmi2Reset(fmi2Component c) {
    CHECK("fmi2Reset", S_ANY_BUT_FATAL);
    LOG_CALL(inst, "fmi2Reset()");
    memset(inst->model, 0, inst->info->model_size);
    inst->info->set_defaults(inst->model);
    set_initialized(inst, 0);
    inst->state = S_INSTANTIATED;
    inst->time = 0.0;
    inst->dirty = 1;
    inst->tunables_dirty = 0;
    inst->n_warned = 0; /* a new initialization: its warnings are news again */
    glue_logf(inst, FP_OK, FP_LOG_EVENTS, "reset");
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
    glue_logf(inst, FP_ERROR, FP_LOG_ERROR,
              "fmi2GetDirectionalDerivative: not provided (providesDirectionalDerivative=false)");
    return fmi2Error;
}

fmi2Status fmi2SetRealInputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                                       const fmi2Integer order[], const fmi2Real value[]) {
    CHECK("fmi2SetRealInputDerivatives", S_ANY_BUT_FATAL);
    LOG_CALL(inst, "fmi2SetRealInputDerivatives(nvr = %lu)", (unsigned long)nvr);
    (void)vr, (void)nvr, (void)order, (void)value;
    glue_logf(inst, FP_ERROR, FP_LOG_ERROR,
              "fmi2SetRealInputDerivatives: inputs are held constant (canInterpolateInputs=false)");
    return fmi2Error;
}

fmi2Status fmi2GetRealOutputDerivatives(fmi2Component c, const fmi2ValueReference vr[],
                                        size_t nvr, const fmi2Integer order[], fmi2Real value[]) {
    CHECK("fmi2GetRealOutputDerivatives", S_ANY_BUT_FATAL);
    LOG_CALL(inst, "fmi2GetRealOutputDerivatives(nvr = %lu)", (unsigned long)nvr);
    (void)vr, (void)nvr, (void)order, (void)value;
    glue_logf(inst, FP_ERROR, FP_LOG_ERROR,
              "fmi2GetRealOutputDerivatives: not provided (maxOutputDerivativeOrder=0)");
    return fmi2Error;
}

fmi2Status fmi2CancelStep(fmi2Component c) {
    CHECK("fmi2CancelStep", S_ANY_BUT_FATAL);
    LOG_CALL(inst, "fmi2CancelStep()");
    glue_logf(inst, FP_ERROR, FP_LOG_ERROR,
              "fmi2CancelStep: steps are synchronous, nothing to cancel");
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
    glue_logf(inst, FP_ERROR, FP_LOG_ERROR,
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
        glue_logf(inst, FP_ERROR, FP_LOG_ERROR,
                  "fmi2DoStep: communicationStepSize %g must be positive and finite",
                  communicationStepSize);
        return fail(inst, fmi2Error);
    }
    tol = 1e-9 * (1.0 + fabs(inst->time));
    if (!isfinite(currentCommunicationPoint) ||
        fabs(currentCommunicationPoint - inst->time) > tol) {
        glue_logf(inst, FP_ERROR, FP_LOG_ERROR,
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
    /* A step that completed returns fmi2OK, also when the model has something to say (a held
     * command, a communication step longer than the sample time): that is logged with status
     * fmi2Warning (category logStatusWarning) as it happens, never answered as fmi2Warning,
     * which some importers take for a failed step (OMSimulator stops the run; fmpy, fmusim and
     * the Compliance Checker continue either way).  docs/fmus.md, "What doStep returns". */
    return s == FP_WARNING ? fmi2OK : to_fmi(s);
}

/* fmi2Get*Status: only StepComplete, StepFailed and Terminated (S_STATUS). */
static Instance *status_call(fmi2Component c, const char *fn, fmi2StatusKind s,
                             const void *value) {
    Instance *inst = glue_enter(c, fn, S_STATUS);
    if (inst != NULL) LOG_CALL(inst, "%s(s = %d, value = %p)", fn, (int)s, value);
    if (inst != NULL && value == NULL) {
        glue_null_argument(inst, fn, "value");
        return NULL;
    }
    return inst;
}

static fmi2Status unsupported_status(Instance *inst, const char *fn, fmi2StatusKind s) {
    static const char *const kinds[] = {"fmi2DoStepStatus", "fmi2PendingStatus",
                                        "fmi2LastSuccessfulTime", "fmi2Terminated"};
    const char *kind = ((int)s >= 0 && (int)s < 4) ? kinds[(int)s] : "unknown";
    glue_logf(inst, FP_WARNING, FP_LOG_WARNING,
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

/* The Model Exchange entry points are fmi2_me.c's, in the FMUs whose model has them
 * (FpModelInfo.me). */
