/*
 * Generic FMI 3.0 co-simulation layer shared by every fullpose FMU: the FMI 3.0 twin of
 * fmi2_glue.c, over the same model contract (fp_model.h) and the same variable tables.
 *
 * It owns the call-sequence state machine of a Co-Simulation FMU without Event Mode
 * (hasEventMode="false"): Instantiated -> Initialization Mode -> (fmi3ExitInitializationMode)
 * Step Mode -> Terminated, fmi3Reset back to Instantiated from any state but Fatal, an
 * fmi3Discard of fmi3DoStep leaving Step Mode with only termination, reading and the FMU
 * state functions allowed, an fmi3Error leaving Error.  Every call out of sequence answers
 * fmi3Error with a message naming the function and the state.  Logging goes through the
 * importer's fmi3LogMessageCallback by category.
 *
 * The FMU built with FP_FMI3_SCHEDULED_EXECUTION (fmi3_scheduled.h: the controller) also
 * provides Scheduled Execution over the same model: Instantiated -> Initialization Mode ->
 * (fmi3ExitInitializationMode) Clock Activation Mode -> Terminated, with fmi3Reset and the
 * FMU states as above; its one input clock's model partition, one sample of the model, runs
 * in fmi3ActivateModelPartition, the same model step fmi3DoStep runs for a step of one
 * sample time.  Clock Activation Mode is the lifecycle state of Step Mode (S_STEP_COMPLETE),
 * told apart by the instance's interface.
 *
 * The FMU built with FP_FMI3_MODEL_EXCHANGE (the plant, whose model has FpModelInfo.me)
 * also provides Model Exchange: Instantiated -> Initialization Mode ->
 * (fmi3ExitInitializationMode) Event Mode <-> Continuous-Time Mode -> Terminated, with
 * fmi3Reset and the FMU states as above; its functions are fmi3_me.c's.
 *
 * The value access is fmi3_values.c, FMU states fmi3_fmustate.c (the format of
 * fmu_state.c, as for FMI 2.0), the resources/ folder fmi3_resources.c; what they share is
 * fmi3_glue_internal.h.  Model Exchange and Scheduled Execution are not provided by the FMUs
 * built without them: their instantiation answers NULL with a message, and every function
 * of theirs (as every other function this FMU does not provide) is exported and answers
 * fmi3Error naming itself.
 */
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fmi3_glue_internal.h"

/* Marks a live instance; cleared to G3_INSTANCE_FREED by fmi3FreeInstance. */
#define G3_INSTANCE_LIVE 0x46503349u  /* "FP3I" */
#define G3_INSTANCE_FREED 0x46524533u /* "FRE3" */

const char *g3_state_name(int state) {
    switch (state) {
    case S_INSTANTIATED: return "Instantiated";
    case S_INIT: return "Initialization Mode";
    case S_STEP_COMPLETE: return "Step Mode";
    case S_STEP_FAILED: return "Step Mode after a discarded step";
    case S_TERMINATED: return "Terminated";
    case S_ERROR: return "Error";
    case S_EVENT_MODE: return "Event Mode";
    case S_CONTINUOUS_TIME: return "Continuous-Time Mode";
    default: return "Fatal";
    }
}

const char *g3_mode_name(const Fmi3Instance *inst) {
    if (inst->interface == G3_SCHEDULED_EXECUTION && inst->state == S_STEP_COMPLETE)
        return "Clock Activation Mode";
    return g3_state_name(inst->state);
}

static fmi3Status to_fmi3(FpStatus s) {
    switch (s) {
    case FP_OK: return fmi3OK;
    case FP_WARNING: return fmi3Warning;
    case FP_DISCARD: return fmi3Discard;
    default: return fmi3Error;
    }
}

/* FMI 3.0 messages are plain text (no format string, unlike FMI 2.0): passed as they are. */
static void emit(Fmi3Instance *inst, fmi3Status status, const char *category,
                 const char *message) {
    if (inst->logger == NULL) return;
    inst->logger(inst->env, status, category, message);
}

static int wants(const Fmi3Instance *inst, FpStatus status, FpLogCategory category) {
    if (status != FP_OK) return 1; /* warnings and errors are always reported */
    return inst->logging_on && (inst->categories & (1u << category));
}

/* 1 if this warning of a parameter check was reported already in this initialization. */
static int warned_before(Fmi3Instance *inst, const char *message) {
    uint64_t h = fp_fnv1a64(FP_FNV1A64_BASIS, message, strlen(message));
    int i;
    for (i = 0; i < inst->n_warned; i++)
        if (inst->warned[i] == h) return 1;
    if (inst->n_warned < G3_MAX_WARNINGS_SEEN) inst->warned[inst->n_warned++] = h;
    return 0;
}

static void model_log(void *env, FpStatus status, FpLogCategory category, const char *message) {
    Fmi3Instance *inst = (Fmi3Instance *)env;
    if (!wants(inst, status, category)) return;
    if (inst->checking && status == FP_WARNING && warned_before(inst, message)) return;
    emit(inst, to_fmi3(status), fp_log_category_name(category), message);
}

void g3_logf(Fmi3Instance *inst, FpStatus status, FpLogCategory category, const char *fmt, ...) {
    char message[768];
    va_list args;
    if (!wants(inst, status, category)) return;
    va_start(args, fmt);
    vsnprintf(message, sizeof message, fmt, args);
    va_end(args);
    emit(inst, to_fmi3(status), fp_log_category_name(category), message);
}

/* A call on an instance fmi3FreeInstance has freed: best effort, while the allocator has not
 * reused the memory. */
static void log_freed(const Fmi3Instance *inst, const char *fn) {
    char message[160];
    if (inst->logger == NULL) return;
    snprintf(message, sizeof message,
             "%s: the instance was freed by fmi3FreeInstance; the call is refused", fn);
    inst->logger(inst->env, fmi3Error, fp_log_category_name(FP_LOG_ERROR), message);
}

static Fmi3Instance *instance(fmi3Instance c, const char *fn) {
    Fmi3Instance *inst = (Fmi3Instance *)c;
    if (inst == NULL) return NULL; /* no instance, no logger to report through */
    if (inst->magic == G3_INSTANCE_LIVE) return inst;
    if (inst->magic == G3_INSTANCE_FREED) log_freed(inst, fn);
    return NULL;
}

Fmi3Instance *g3_enter(fmi3Instance c, const char *fn, int states) {
    Fmi3Instance *inst = instance(c, fn);
    if (inst == NULL) return NULL;
    if (inst->state & states) return inst;
    g3_logf(inst, FP_ERROR, FP_LOG_ERROR, "%s may not be called in state %s", fn,
            g3_mode_name(inst));
    return NULL;
}

fmi3Status g3_null_argument(Fmi3Instance *inst, const char *fn, const char *what) {
    g3_logf(inst, FP_ERROR, FP_LOG_ERROR, "%s: %s is NULL", fn, what);
    return fmi3Error;
}

/* A failure of the model's computation (initialization, a step). */
static fmi3Status fail(Fmi3Instance *inst, fmi3Status status) {
    if (status == fmi3Error) inst->state = S_ERROR;
    if (status == fmi3Discard) inst->state = S_STEP_FAILED;
    return status;
}

fmi3Status g3_fail(Fmi3Instance *inst, fmi3Status status) { return fail(inst, status); }

/* Model Exchange: the model's derivatives and outputs at the time, states and inputs set
 * (the model evaluates once per change, however often they are read). */
static fmi3Status me_refresh(Fmi3Instance *inst) {
    FpStatus s;
    if (!inst->me_stale) return fmi3OK;
    if (inst->tunables_dirty && inst->info->tunables_changed != NULL) {
        s = inst->info->tunables_changed(inst->model, &inst->model_logger);
        if (s == FP_ERROR || s == FP_DISCARD) return fail(inst, fmi3Error);
    }
    inst->tunables_dirty = 0;
    s = inst->info->me->evaluate(inst->model, inst->time, &inst->model_logger);
    if (s == FP_ERROR || s == FP_DISCARD) return fail(inst, fmi3Error);
    inst->me_stale = 0;
    return fmi3OK;
}

/* A Model Exchange instance also checks that its parameters leave it something a solver can
 * integrate (FpModelExchange.check). */
fmi3Status g3_refresh(Fmi3Instance *inst) {
    FpStatus s;
    if (inst->state & S_ME_RUNNING) return me_refresh(inst);
    if (!(inst->state & (S_INIT | S_INSTANTIATED)) || !inst->dirty) return fmi3OK;
    inst->checking = 1;
    s = inst->info->initialize(inst->model, inst->time, &inst->model_logger);
    if (s != FP_ERROR && s != FP_DISCARD && inst->interface == G3_MODEL_EXCHANGE) {
        FpStatus me = inst->info->me->check(inst->model, &inst->model_logger);
        if (me != FP_OK) s = me;
    }
    inst->checking = 0;
    if (s == FP_ERROR || s == FP_DISCARD) return fail(inst, fmi3Error);
    inst->dirty = 0;
    inst->me_stale = 1;
    return to_fmi3(s);
}

void g3_se_anchor(Fmi3Instance *inst) {
    inst->se_base = inst->time;
    inst->se_k = 0;
    inst->se_set_pending = 0;
}

/* ------------------------------------------------------------------------ */
/* Inquiry and logging                                                      */

const char *fmi3GetVersion(void) { return fmi3Version; }

fmi3Status fmi3SetDebugLogging(fmi3Instance c, fmi3Boolean loggingOn, size_t nCategories,
                               const fmi3String categories[]) {
    size_t i;
    int j;
    unsigned mask = 0;
    G3_CHECK("fmi3SetDebugLogging", S_ANY_BUT_FATAL);
    G3_LOG_CALL(inst, "fmi3SetDebugLogging(loggingOn = %d, nCategories = %lu%s%s%s)",
                (int)loggingOn, (unsigned long)nCategories,
                nCategories > 0 && categories != NULL ? ": " : "",
                nCategories > 0 && categories != NULL && categories[0] ? categories[0] : "",
                nCategories > 1 ? ", ..." : "");
    if (nCategories > 0 && categories == NULL)
        return g3_null_argument(inst, "fmi3SetDebugLogging", "categories");
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
                g3_logf(inst, FP_ERROR, FP_LOG_ERROR, "fmi3SetDebugLogging: unknown category %s",
                        categories[i] ? categories[i] : "(null)");
                return fmi3Error;
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
    return fmi3OK;
}

/* ------------------------------------------------------------------------ */
/* Lifecycle                                                                */

static void release_instance(Fmi3Instance *inst) {
    free(inst->model);
    free(inst->scratch);
    free(inst->vr_map);
    free(inst->table.data);
    inst->magic = G3_INSTANCE_FREED;
    free(inst);
}

/* The model's initialized marker (FpModelInfo.initialized_offset), as in the FMI 2.0 glue. */
static void set_initialized(Fmi3Instance *inst, int32_t on) {
    memcpy((char *)inst->model + inst->info->initialized_offset, &on, sizeof on);
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

/* A message to the importer's logger before there is an instance to log through. */
static void early_error(fmi3LogMessageCallback logger, fmi3InstanceEnvironment env,
                        const char *message) {
    if (logger != NULL) logger(env, fmi3Error, fp_log_category_name(FP_LOG_ERROR), message);
}

/* An instance with its logger, name and token checked, nothing allocated but itself; NULL
 * with the reason logged.  fn names the instantiation function in messages. */
static Fmi3Instance *new_instance(const char *fn, fmi3String instanceName,
                                  fmi3String instantiationToken, fmi3Boolean loggingOn,
                                  fmi3InstanceEnvironment instanceEnvironment,
                                  fmi3LogMessageCallback logMessage) {
    const FpModelInfo *info = fp_model_info();
    Fmi3Instance *inst = (Fmi3Instance *)calloc(1, sizeof(Fmi3Instance));
    char message[96];
    if (inst == NULL) {
        snprintf(message, sizeof message, "%s: out of memory", fn);
        early_error(logMessage, instanceEnvironment, message);
        return NULL;
    }
    inst->magic = G3_INSTANCE_LIVE;
    inst->logger = logMessage;
    inst->env = instanceEnvironment;
    inst->info = info;
    inst->state = S_INSTANTIATED;
    inst->logging_on = loggingOn ? 1 : 0;
    inst->categories = loggingOn ? (1u << FP_LOG_N_CATEGORIES) - 1u : 0u;
    inst->model_logger.log = model_log;
    inst->model_logger.env = inst;
    fp_model_guid(info, inst->guid);

    if (instanceName == NULL || instanceName[0] == '\0') {
        g3_logf(inst, FP_ERROR, FP_LOG_ERROR, "%s: instanceName must not be empty", fn);
        release_instance(inst);
        return NULL;
    }
    if (instantiationToken == NULL || strcmp(instantiationToken, inst->guid) != 0) {
        g3_logf(inst, FP_ERROR, FP_LOG_ERROR,
                "%s: instantiationToken %s does not match this binary (%s); the FMU is "
                "inconsistent",
                fn, instantiationToken ? instantiationToken : "(null)", inst->guid);
        release_instance(inst);
        return NULL;
    }
    return inst;
}

/* The rest of an instantiation: the value reference map, the model and its scratch copy,
 * the table from resources/, the defaults.  0, or -1 with the reason logged (the caller
 * releases the instance). */
static int complete_instance(Fmi3Instance *inst, const char *fn, fmi3String resourcePath) {
    const FpModelInfo *info = inst->info;
    uint32_t max_vr = 0;
    size_t i;
    for (i = 0; i < info->n_vars; i++)
        if (info->vars[i].vr > max_vr) max_vr = info->vars[i].vr;
    inst->n_vr = max_vr + 1;
    if (info->model_size < sizeof(int32_t) ||
        info->initialized_offset > info->model_size - sizeof(int32_t)) {
        g3_logf(inst, FP_ERROR, FP_LOG_ERROR,
                "%s: the model's initialized marker (at %lu) lies beyond its %lu bytes; the "
                "FMU is inconsistent",
                fn, (unsigned long)info->initialized_offset, (unsigned long)info->model_size);
        return -1;
    }
    inst->vr_map = (int32_t *)calloc(inst->n_vr, sizeof(int32_t));
    inst->model = calloc(1, info->model_size);
    inst->scratch = calloc(1, info->model_size);
    if (inst->vr_map == NULL || inst->model == NULL || inst->scratch == NULL) {
        g3_logf(inst, FP_ERROR, FP_LOG_ERROR, "%s: out of memory", fn);
        return -1;
    }
    /* one variable per row, its value reference the row's (element k of the FMI 2.0 FMU's
     * vr + k is not an FMI 3.0 value reference); 0 is the independent variable time */
    for (i = 0; i < inst->n_vr; i++) inst->vr_map[i] = -1;
    for (i = 0; i < info->n_vars; i++) inst->vr_map[info->vars[i].vr] = (int32_t)i;
    inst->internal_step = find_internal_step(info);
    if (info->table_resource != NULL) {
        char why[640];
        if (g3_load_table(inst, resourcePath, why, sizeof why) != 0) {
            g3_logf(inst, FP_ERROR, FP_LOG_ERROR, "%s: %s", fn, why);
            return -1;
        }
        g3_logf(inst, FP_OK, FP_LOG_EVENTS, "read resources/%s: %lu rows of %lu signals",
                info->table_resource, (unsigned long)inst->table.rows,
                (unsigned long)inst->table.cols);
    }
    info->set_defaults(inst->model);
    set_initialized(inst, 0);
    inst->dirty = 1;
    return 0;
}

fmi3Instance fmi3InstantiateCoSimulation(
    fmi3String instanceName, fmi3String instantiationToken, fmi3String resourcePath,
    fmi3Boolean visible, fmi3Boolean loggingOn, fmi3Boolean eventModeUsed,
    fmi3Boolean earlyReturnAllowed, const fmi3ValueReference requiredIntermediateVariables[],
    size_t nRequiredIntermediateVariables, fmi3InstanceEnvironment instanceEnvironment,
    fmi3LogMessageCallback logMessage, fmi3IntermediateUpdateCallback intermediateUpdate) {
    static const char fn[] = "fmi3InstantiateCoSimulation";
    Fmi3Instance *inst;
    (void)intermediateUpdate; /* providesIntermediateUpdate="false": never called */
    inst = new_instance(fn, instanceName, instantiationToken, loggingOn, instanceEnvironment,
                        logMessage);
    if (inst == NULL) return NULL;
    if (eventModeUsed) {
        g3_logf(inst, FP_ERROR, FP_LOG_ERROR,
                "fmi3InstantiateCoSimulation: eventModeUsed = true, but %s has no Event Mode "
                "(hasEventMode=\"false\"); instantiate it with eventModeUsed = false",
                inst->info->model_name);
        release_instance(inst);
        return NULL;
    }
    if (nRequiredIntermediateVariables > 0) {
        g3_logf(inst, FP_ERROR, FP_LOG_ERROR,
                "fmi3InstantiateCoSimulation: %lu requiredIntermediateVariables (the first: vr "
                "%u), but %s provides no intermediate update "
                "(providesIntermediateUpdate=\"false\")",
                (unsigned long)nRequiredIntermediateVariables,
                requiredIntermediateVariables ? (unsigned)requiredIntermediateVariables[0] : 0u,
                inst->info->model_name);
        release_instance(inst);
        return NULL;
    }
    if (complete_instance(inst, fn, resourcePath) != 0) {
        release_instance(inst);
        return NULL;
    }
    inst->interface = G3_CO_SIMULATION;
    G3_LOG_CALL(inst,
                "fmi3InstantiateCoSimulation(instanceName = \"%.64s\", instantiationToken = "
                "\"%s\", resourcePath = \"%.200s\", visible = %d, loggingOn = %d, eventModeUsed "
                "= %d, earlyReturnAllowed = %d)",
                instanceName, instantiationToken, resourcePath ? resourcePath : "(null)",
                (int)visible, (int)loggingOn, (int)eventModeUsed, (int)earlyReturnAllowed);
    g3_logf(inst, FP_OK, FP_LOG_EVENTS, "instantiated %s (FMI 3.0 co-simulation)",
            inst->info->model_name);
    return inst;
}

/* Model Exchange (the FMU built with FP_FMI3_MODEL_EXCHANGE: fmi3_me.c). */
fmi3Instance fmi3InstantiateModelExchange(fmi3String instanceName, fmi3String instantiationToken,
                                          fmi3String resourcePath, fmi3Boolean visible,
                                          fmi3Boolean loggingOn,
                                          fmi3InstanceEnvironment instanceEnvironment,
                                          fmi3LogMessageCallback logMessage) {
    static const char fn[] = "fmi3InstantiateModelExchange";
    Fmi3Instance *inst;
    if (!G3_ME_PROVIDED || fp_model_info()->me == NULL) {
        char message[320];
        (void)instanceName, (void)instantiationToken, (void)resourcePath, (void)visible,
            (void)loggingOn;
        snprintf(message, sizeof message,
                 "fmi3InstantiateModelExchange: %s provides %s only (no <ModelExchange> in its "
                 "modelDescription.xml): it has no continuous state to hand to a solver, it "
                 "computes on its own sample grid; use fmi3InstantiateCoSimulation",
                 fp_model_info()->model_name,
                 G3_SE_PROVIDED ? "co-simulation and scheduled execution" : "co-simulation");
        early_error(logMessage, instanceEnvironment, message);
        return NULL;
    }
    inst = new_instance(fn, instanceName, instantiationToken, loggingOn, instanceEnvironment,
                        logMessage);
    if (inst == NULL) return NULL;
    if (complete_instance(inst, fn, resourcePath) != 0) {
        release_instance(inst);
        return NULL;
    }
    inst->interface = G3_MODEL_EXCHANGE;
    G3_LOG_CALL(inst,
                "fmi3InstantiateModelExchange(instanceName = \"%.64s\", instantiationToken = "
                "\"%s\", resourcePath = \"%.200s\", visible = %d, loggingOn = %d)",
                instanceName, instantiationToken, resourcePath ? resourcePath : "(null)",
                (int)visible, (int)loggingOn);
    g3_logf(inst, FP_OK, FP_LOG_EVENTS, "instantiated %s (FMI 3.0 model exchange)",
            inst->info->model_name);
    return inst;
}

/*
 * Scheduled Execution (the FMU built with FP_FMI3_SCHEDULED_EXECUTION, fmi3_scheduled.h): an
 * instance as a co-simulation one, with the interval of its input clock taken from the
 * internal step's default.  The three callbacks are kept, none is required (NULL is taken)
 * and none is called: the FMU has no output or countdown clock whose activation
 * clockUpdate would report, and its one model partition touches nothing but its own
 * instance, so no code of it needs lockPreemption / unlockPreemption around it.
 */
fmi3Instance fmi3InstantiateScheduledExecution(
    fmi3String instanceName, fmi3String instantiationToken, fmi3String resourcePath,
    fmi3Boolean visible, fmi3Boolean loggingOn, fmi3InstanceEnvironment instanceEnvironment,
    fmi3LogMessageCallback logMessage, fmi3ClockUpdateCallback clockUpdate,
    fmi3LockPreemptionCallback lockPreemption, fmi3UnlockPreemptionCallback unlockPreemption) {
    static const char fn[] = "fmi3InstantiateScheduledExecution";
    Fmi3Instance *inst;
    if (!G3_SE_PROVIDED) {
        char message[256];
        (void)instanceName, (void)instantiationToken, (void)resourcePath, (void)visible,
            (void)loggingOn, (void)clockUpdate, (void)lockPreemption, (void)unlockPreemption;
        snprintf(message, sizeof message,
                 "fmi3InstantiateScheduledExecution: %s provides co-simulation only (no "
                 "<ScheduledExecution> in its modelDescription.xml); use "
                 "fmi3InstantiateCoSimulation",
                 fp_model_info()->model_name);
        early_error(logMessage, instanceEnvironment, message);
        return NULL;
    }
    inst = new_instance(fn, instanceName, instantiationToken, loggingOn, instanceEnvironment,
                        logMessage);
    if (inst == NULL) return NULL;
    if (complete_instance(inst, fn, resourcePath) != 0) {
        release_instance(inst);
        return NULL;
    }
    if (inst->internal_step == NULL) { /* (mdgen --scheduled-execution refuses such a model) */
        g3_logf(inst, FP_ERROR, FP_LOG_ERROR,
                "%s: %s has no internal step parameter to give its clock %s an interval; the "
                "FMU is inconsistent",
                fn, inst->info->model_name, FP_SE_CLOCK_NAME);
        release_instance(inst);
        return NULL;
    }
    inst->interface = G3_SCHEDULED_EXECUTION;
    inst->clock_update = clockUpdate;
    inst->lock_preemption = lockPreemption;
    inst->unlock_preemption = unlockPreemption;
    inst->se_interval = *(const double *)g3_element(inst, inst->internal_step, 0);
    G3_LOG_CALL(inst,
                "fmi3InstantiateScheduledExecution(instanceName = \"%.64s\", instantiationToken "
                "= \"%s\", resourcePath = \"%.200s\", visible = %d, loggingOn = %d, clockUpdate "
                "%s, lockPreemption %s, unlockPreemption %s)",
                instanceName, instantiationToken, resourcePath ? resourcePath : "(null)",
                (int)visible, (int)loggingOn, clockUpdate ? "given" : "NULL",
                lockPreemption ? "given" : "NULL", unlockPreemption ? "given" : "NULL");
    g3_logf(inst, FP_OK, FP_LOG_EVENTS,
            "instantiated %s (FMI 3.0 scheduled execution: clock %s, vr %u, interval %s = "
            "%.17g s)",
            inst->info->model_name, FP_SE_CLOCK_NAME, (unsigned)FP_SE_CLOCK_VR,
            inst->internal_step->name, inst->se_interval);
    return inst;
}

void fmi3FreeInstance(fmi3Instance c) {
    Fmi3Instance *inst = g3_enter(c, "fmi3FreeInstance", S_ANY_BUT_FATAL | S_FATAL);
    if (inst == NULL) return;
    G3_LOG_CALL(inst, "fmi3FreeInstance()");
    release_instance(inst);
}

fmi3Status fmi3EnterInitializationMode(fmi3Instance c, fmi3Boolean toleranceDefined,
                                       fmi3Float64 tolerance, fmi3Float64 startTime,
                                       fmi3Boolean stopTimeDefined, fmi3Float64 stopTime) {
    G3_CHECK("fmi3EnterInitializationMode", S_INSTANTIATED);
    G3_LOG_CALL(inst,
                "fmi3EnterInitializationMode(toleranceDefined = %d, tolerance = %.17g, startTime "
                "= %.17g, stopTimeDefined = %d, stopTime = %.17g)",
                (int)toleranceDefined, tolerance, startTime, (int)stopTimeDefined, stopTime);
    if (!isfinite(startTime) || (stopTimeDefined && !(stopTime >= startTime))) {
        g3_logf(inst, FP_ERROR, FP_LOG_ERROR,
                "fmi3EnterInitializationMode: startTime %g / stopTime %g are not a valid "
                "interval",
                startTime, stopTime);
        return fmi3Error;
    }
    inst->time = startTime;
    inst->dirty = 1;
    inst->state = S_INIT;
    return fmi3OK;
}

fmi3Status fmi3ExitInitializationMode(fmi3Instance c) {
    fmi3Status s;
    G3_CHECK("fmi3ExitInitializationMode", S_INIT);
    G3_LOG_CALL(inst, "fmi3ExitInitializationMode()");
    inst->dirty = 1; /* always validate the final parameter set */
    s = g3_refresh(inst);
    if (s > fmi3Warning) return s;
    if (inst->interface == G3_SCHEDULED_EXECUTION) {
        /* the clock's interval is constant, the model's sample time is a parameter: they
         * must be one */
        double ts = *(const double *)g3_element(inst, inst->internal_step, 0);
        if (ts != inst->se_interval) {
            g3_logf(inst, FP_ERROR, FP_LOG_ERROR,
                    "fmi3ExitInitializationMode: %s = %.17g s, but in Scheduled Execution the "
                    "clock %s (vr %u) activates the samples at its constant interval %.17g s "
                    "(intervalVariability=\"constant\"): leave %s at %.17g s, or use "
                    "co-simulation",
                    inst->internal_step->name, ts, FP_SE_CLOCK_NAME, (unsigned)FP_SE_CLOCK_VR,
                    inst->se_interval, inst->internal_step->name, inst->se_interval);
            return fail(inst, fmi3Error);
        }
    }
    set_initialized(inst, 1);
    /* Co-Simulation without Event Mode: Step Mode follows Initialization Mode directly;
     * Scheduled Execution: Clock Activation Mode (the same lifecycle state), its first
     * activation due at the start time; Model Exchange: Event Mode */
    inst->state = inst->interface == G3_MODEL_EXCHANGE ? S_EVENT_MODE : S_STEP_COMPLETE;
    inst->tunables_dirty = 0;
    g3_se_anchor(inst);
    g3_logf(inst, FP_OK, FP_LOG_EVENTS, "initialized at t = %g", inst->time);
    return s;
}

fmi3Status fmi3Terminate(fmi3Instance c) {
    G3_CHECK("fmi3Terminate", S_STEP_COMPLETE | S_STEP_FAILED | S_ME_RUNNING);
    G3_LOG_CALL(inst, "fmi3Terminate()");
    inst->state = S_TERMINATED;
    return fmi3OK;
}

fmi3Status fmi3Reset(fmi3Instance c) {
    G3_CHECK("fmi3Reset", S_ANY_BUT_FATAL);
    G3_LOG_CALL(inst, "fmi3Reset()");
    memset(inst->model, 0, inst->info->model_size);
    inst->info->set_defaults(inst->model);
    set_initialized(inst, 0);
    inst->state = S_INSTANTIATED;
    inst->time = 0.0;
    inst->dirty = 1;
    inst->tunables_dirty = 0;
    inst->n_warned = 0; /* a new initialization: its warnings are news again */
    g3_se_anchor(inst);
    g3_logf(inst, FP_OK, FP_LOG_EVENTS, "reset");
    return fmi3OK;
}

/* ------------------------------------------------------------------------ */
/* Stepping                                                                 */

/* Refuses a step of more than FP_MAX_INTERNAL_STEPS internal steps (fp_model.h). */
static int within_work_cap(Fmi3Instance *inst, double h) {
    double hi, n;
    if (inst->internal_step == NULL) return 1;
    hi = *(const double *)g3_element(inst, inst->internal_step, 0);
    if (!(hi > 0.0) || !isfinite(hi)) return 1; /* the model refuses it itself */
    n = fp_steps_to_cover(h, hi, FP_STEP_TOL * h);
    if (n <= FP_MAX_INTERNAL_STEPS) return 1;
    g3_logf(inst, FP_ERROR, FP_LOG_ERROR,
            "fmi3DoStep: communication step h = %.12g s would take %.0f internal steps of %s = "
            "%.12g s; the cap is %.0f internal steps per fmi3DoStep (%.12g s); use shorter steps",
            h, n, inst->internal_step->name, hi, FP_MAX_INTERNAL_STEPS,
            FP_MAX_INTERNAL_STEPS * hi);
    return 0;
}

fmi3Status fmi3DoStep(fmi3Instance c, fmi3Float64 currentCommunicationPoint,
                      fmi3Float64 communicationStepSize,
                      fmi3Boolean noSetFMUStatePriorToCurrentPoint,
                      fmi3Boolean *eventHandlingNeeded, fmi3Boolean *terminateSimulation,
                      fmi3Boolean *earlyReturn, fmi3Float64 *lastSuccessfulTime) {
    FpStatus s;
    double tol;
    G3_CHECK("fmi3DoStep", S_STEP_COMPLETE);
    if (inst->interface != G3_CO_SIMULATION) {
        g3_logf(inst, FP_ERROR, FP_LOG_ERROR,
                "fmi3DoStep may not be called in state %s: a Scheduled Execution instance "
                "runs its samples by fmi3ActivateModelPartition",
                g3_mode_name(inst));
        return fmi3Error;
    }
    G3_LOG_CALL(inst,
                "fmi3DoStep(currentCommunicationPoint = %.17g, communicationStepSize = %.17g, "
                "noSetFMUStatePriorToCurrentPoint = %d)",
                currentCommunicationPoint, communicationStepSize,
                (int)noSetFMUStatePriorToCurrentPoint);
    if (eventHandlingNeeded == NULL)
        return g3_null_argument(inst, "fmi3DoStep", "eventHandlingNeeded");
    if (terminateSimulation == NULL)
        return g3_null_argument(inst, "fmi3DoStep", "terminateSimulation");
    if (earlyReturn == NULL) return g3_null_argument(inst, "fmi3DoStep", "earlyReturn");
    if (lastSuccessfulTime == NULL)
        return g3_null_argument(inst, "fmi3DoStep", "lastSuccessfulTime");
    /* no events, no early return, never a request to stop: only the time varies */
    *eventHandlingNeeded = false;
    *terminateSimulation = false;
    *earlyReturn = false;
    *lastSuccessfulTime = inst->time;
    if (!(communicationStepSize > 0.0) || !isfinite(communicationStepSize)) {
        g3_logf(inst, FP_ERROR, FP_LOG_ERROR,
                "fmi3DoStep: communicationStepSize %g must be positive and finite",
                communicationStepSize);
        return fail(inst, fmi3Error);
    }
    tol = 1e-9 * (1.0 + fabs(inst->time));
    if (!isfinite(currentCommunicationPoint) ||
        fabs(currentCommunicationPoint - inst->time) > tol) {
        g3_logf(inst, FP_ERROR, FP_LOG_ERROR,
                "fmi3DoStep: currentCommunicationPoint %.12g does not match the FMU time %.12g",
                currentCommunicationPoint, inst->time);
        return fail(inst, fmi3Error);
    }
    if (!within_work_cap(inst, communicationStepSize)) return fail(inst, fmi3Error);
    if (inst->tunables_dirty && inst->info->tunables_changed != NULL) {
        s = inst->info->tunables_changed(inst->model, &inst->model_logger);
        if (s == FP_ERROR || s == FP_DISCARD) return fail(inst, fmi3Error);
    }
    inst->tunables_dirty = 0;
    s = inst->info->step(inst->model, inst->time, communicationStepSize, &inst->model_logger);
    if (s == FP_ERROR) return fail(inst, fmi3Error);
    if (s == FP_DISCARD) return fail(inst, fmi3Discard);
    inst->time = currentCommunicationPoint + communicationStepSize;
    *lastSuccessfulTime = inst->time;
    /* as fmi2DoStep: a completed step answers fmi3OK, its warnings logged as they happen
     * (docs/fmus.md, "What doStep returns") */
    return s == FP_WARNING ? fmi3OK : to_fmi3(s);
}

/* ------------------------------------------------------------------------ */
/* What this FMU does not provide: exported (importers look every function up), each
 * answering fmi3Error with a message naming itself and why.                 */

static fmi3Status not_provided(fmi3Instance c, const char *fn, const char *why) {
    G3_CHECK(fn, S_ANY_BUT_FATAL);
    G3_LOG_CALL(inst, "%s()", fn);
    g3_logf(inst, FP_ERROR, FP_LOG_ERROR, "%s: not provided: %s", fn, why);
    return fmi3Error;
}

#define G3_NO_EVENT_MODE "the FMU has no Event Mode (hasEventMode=\"false\")"
#define G3_NO_CLOCKS "the FMU has no clocks"
#if G3_SE_PROVIDED
#define G3_NO_ME "the FMU provides co-simulation and scheduled execution only"
#define G3_NO_EVALUATE "the FMU has no Event Mode (providesEvaluateDiscreteStates=\"false\")"
#else
#define G3_NO_ME "the FMU provides co-simulation only"
#define G3_NO_EVALUATE G3_NO_CLOCKS " (providesEvaluateDiscreteStates=\"false\")"
#endif
#define G3_NO_SE "the FMU provides co-simulation only (Scheduled Execution comes later)"

#if !G3_ME_PROVIDED /* (fmi3_me.c has them, answering these for the instances without) */
fmi3Status fmi3EnterEventMode(fmi3Instance c) {
    return not_provided(c, "fmi3EnterEventMode", G3_NO_EVENT_MODE);
}
#endif

fmi3Status fmi3EnterStepMode(fmi3Instance c) {
    return not_provided(c, "fmi3EnterStepMode",
                        G3_NO_EVENT_MODE ": fmi3ExitInitializationMode enters Step Mode itself");
}

#if !G3_ME_PROVIDED
fmi3Status fmi3UpdateDiscreteStates(fmi3Instance c, fmi3Boolean *discreteStatesNeedUpdate,
                                    fmi3Boolean *terminateSimulation,
                                    fmi3Boolean *nominalsOfContinuousStatesChanged,
                                    fmi3Boolean *valuesOfContinuousStatesChanged,
                                    fmi3Boolean *nextEventTimeDefined,
                                    fmi3Float64 *nextEventTime) {
    (void)discreteStatesNeedUpdate, (void)terminateSimulation,
        (void)nominalsOfContinuousStatesChanged, (void)valuesOfContinuousStatesChanged,
        (void)nextEventTimeDefined, (void)nextEventTime;
    return not_provided(c, "fmi3UpdateDiscreteStates", G3_NO_EVENT_MODE);
}
#endif

/* For fmi3_me.c: a function of Event Mode or Model Exchange called on an instance of another
 * interface, answered as the FMUs without Model Exchange answer it. */
fmi3Status g3_no_event_mode(fmi3Instance c, const char *fn) {
    return not_provided(c, fn, G3_NO_EVENT_MODE);
}

fmi3Status fmi3EvaluateDiscreteStates(fmi3Instance c) {
    return not_provided(c, "fmi3EvaluateDiscreteStates", G3_NO_EVALUATE);
}

fmi3Status fmi3GetNumberOfVariableDependencies(fmi3Instance c, fmi3ValueReference valueReference,
                                               size_t *nDependencies) {
    (void)valueReference, (void)nDependencies;
    return not_provided(c, "fmi3GetNumberOfVariableDependencies",
                        "the dependencies are those of <ModelStructure> in "
                        "modelDescription.xml");
}

fmi3Status fmi3GetVariableDependencies(fmi3Instance c, fmi3ValueReference dependent,
                                       size_t elementIndicesOfDependent[],
                                       fmi3ValueReference independents[],
                                       size_t elementIndicesOfIndependents[],
                                       fmi3DependencyKind dependencyKinds[],
                                       size_t nDependencies) {
    (void)dependent, (void)elementIndicesOfDependent, (void)independents,
        (void)elementIndicesOfIndependents, (void)dependencyKinds, (void)nDependencies;
    return not_provided(c, "fmi3GetVariableDependencies",
                        "the dependencies are those of <ModelStructure> in "
                        "modelDescription.xml");
}

fmi3Status fmi3GetDirectionalDerivative(fmi3Instance c, const fmi3ValueReference unknowns[],
                                        size_t nUnknowns, const fmi3ValueReference knowns[],
                                        size_t nKnowns, const fmi3Float64 seed[], size_t nSeed,
                                        fmi3Float64 sensitivity[], size_t nSensitivity) {
    (void)unknowns, (void)nUnknowns, (void)knowns, (void)nKnowns, (void)seed, (void)nSeed,
        (void)sensitivity, (void)nSensitivity;
    return not_provided(c, "fmi3GetDirectionalDerivative",
                        "providesDirectionalDerivatives=\"false\"");
}

fmi3Status fmi3GetAdjointDerivative(fmi3Instance c, const fmi3ValueReference unknowns[],
                                    size_t nUnknowns, const fmi3ValueReference knowns[],
                                    size_t nKnowns, const fmi3Float64 seed[], size_t nSeed,
                                    fmi3Float64 sensitivity[], size_t nSensitivity) {
    (void)unknowns, (void)nUnknowns, (void)knowns, (void)nKnowns, (void)seed, (void)nSeed,
        (void)sensitivity, (void)nSensitivity;
    return not_provided(c, "fmi3GetAdjointDerivative", "providesAdjointDerivatives=\"false\"");
}

fmi3Status fmi3EnterConfigurationMode(fmi3Instance c) {
    return not_provided(c, "fmi3EnterConfigurationMode", "the FMU has no structural parameters");
}

fmi3Status fmi3ExitConfigurationMode(fmi3Instance c) {
    return not_provided(c, "fmi3ExitConfigurationMode", "the FMU has no structural parameters");
}

fmi3Status fmi3GetOutputDerivatives(fmi3Instance c, const fmi3ValueReference valueReferences[],
                                    size_t nValueReferences, const fmi3Int32 orders[],
                                    fmi3Float64 values[], size_t nValues) {
    (void)valueReferences, (void)nValueReferences, (void)orders, (void)values, (void)nValues;
    return not_provided(c, "fmi3GetOutputDerivatives", "maxOutputDerivativeOrder=\"0\"");
}

/* Clocks.  Without Scheduled Execution the FMU has none.  With it, its one clock is the
 * input clock of Scheduled Execution (fmi3_scheduled.h), periodic with a constant interval
 * and no shift: a Scheduled Execution instance answers its interval (qualifier
 * fmi3IntervalUnchanged, the only one a constant clock has) and its shift (0); nothing sets
 * them, the fractions are not supported (supportsFraction="false"), and a Co-Simulation
 * instance, which steps without Event Mode, has no clock to ask about. */

#define G3_CONSTANT_CLOCK                                                               \
    "the clock " FP_SE_CLOCK_NAME " has a constant interval and no shift "              \
    "(intervalVariability=\"constant\"): nothing sets them"
#define G3_NO_FRACTION                                                                  \
    "the clock " FP_SE_CLOCK_NAME " has supportsFraction=\"false\": its interval and shift are " \
    "read by fmi3GetIntervalDecimal and fmi3GetShiftDecimal"

/* The checks of a clock inquiry on a Scheduled Execution instance: every reference the
 * clock, the arrays there.  The instance, or NULL with the reason logged. */
static Fmi3Instance *clock_inquiry(fmi3Instance c, const char *fn,
                                   const fmi3ValueReference vrs[], size_t n, const void *out,
                                   const void *out2) {
    size_t i;
    Fmi3Instance *inst = g3_enter(c, fn, S_INIT | S_STEP_COMPLETE);
    if (inst == NULL) return NULL;
    G3_LOG_CALL(inst, "%s(nValueReferences = %lu%s%u)", fn, (unsigned long)n,
                n > 0 && vrs != NULL ? ": vr " : ", vr ",
                n > 0 && vrs != NULL ? (unsigned)vrs[0] : 0u);
    if (inst->interface != G3_SCHEDULED_EXECUTION) {
        g3_logf(inst, FP_ERROR, FP_LOG_ERROR,
                "%s: a Co-Simulation instance has no active clock (no Event Mode); the clock "
                "%s (vr %u) is Scheduled Execution's",
                fn, FP_SE_CLOCK_NAME, (unsigned)FP_SE_CLOCK_VR);
        return NULL;
    }
    if (n > 0 && (vrs == NULL || out == NULL || out2 == NULL)) {
        g3_null_argument(inst, fn, vrs == NULL ? "valueReferences" : "an output array");
        return NULL;
    }
    for (i = 0; i < n; i++)
        if (!g3_is_clock(vrs[i])) {
            g3_logf(inst, FP_ERROR, FP_LOG_ERROR,
                    "%s: value reference %u is no clock; the FMU's one clock is %s (vr %u)", fn,
                    (unsigned)vrs[i], FP_SE_CLOCK_NAME, (unsigned)FP_SE_CLOCK_VR);
            return NULL;
        }
    return inst;
}

fmi3Status fmi3GetIntervalDecimal(fmi3Instance c, const fmi3ValueReference valueReferences[],
                                  size_t nValueReferences, fmi3Float64 intervals[],
                                  fmi3IntervalQualifier qualifiers[]) {
    Fmi3Instance *inst;
    size_t i;
    if (!G3_SE_PROVIDED) {
        (void)valueReferences, (void)nValueReferences, (void)intervals, (void)qualifiers;
        return not_provided(c, "fmi3GetIntervalDecimal", G3_NO_CLOCKS);
    }
    inst = clock_inquiry(c, "fmi3GetIntervalDecimal", valueReferences, nValueReferences,
                         intervals, qualifiers);
    if (inst == NULL) return fmi3Error;
    for (i = 0; i < nValueReferences; i++) {
        intervals[i] = inst->se_interval;
        qualifiers[i] = fmi3IntervalUnchanged;
    }
    return fmi3OK;
}

fmi3Status fmi3GetIntervalFraction(fmi3Instance c, const fmi3ValueReference valueReferences[],
                                   size_t nValueReferences, fmi3UInt64 counters[],
                                   fmi3UInt64 resolutions[], fmi3IntervalQualifier qualifiers[]) {
    (void)valueReferences, (void)nValueReferences, (void)counters, (void)resolutions,
        (void)qualifiers;
    return not_provided(c, "fmi3GetIntervalFraction",
                        G3_SE_PROVIDED ? G3_NO_FRACTION : G3_NO_CLOCKS);
}

fmi3Status fmi3GetShiftDecimal(fmi3Instance c, const fmi3ValueReference valueReferences[],
                               size_t nValueReferences, fmi3Float64 shifts[]) {
    Fmi3Instance *inst;
    size_t i;
    if (!G3_SE_PROVIDED) {
        (void)valueReferences, (void)nValueReferences, (void)shifts;
        return not_provided(c, "fmi3GetShiftDecimal", G3_NO_CLOCKS);
    }
    inst = clock_inquiry(c, "fmi3GetShiftDecimal", valueReferences, nValueReferences, shifts,
                         shifts);
    if (inst == NULL) return fmi3Error;
    for (i = 0; i < nValueReferences; i++) shifts[i] = 0.0;
    return fmi3OK;
}

fmi3Status fmi3GetShiftFraction(fmi3Instance c, const fmi3ValueReference valueReferences[],
                                size_t nValueReferences, fmi3UInt64 counters[],
                                fmi3UInt64 resolutions[]) {
    (void)valueReferences, (void)nValueReferences, (void)counters, (void)resolutions;
    return not_provided(c, "fmi3GetShiftFraction",
                        G3_SE_PROVIDED ? G3_NO_FRACTION : G3_NO_CLOCKS);
}

fmi3Status fmi3SetIntervalDecimal(fmi3Instance c, const fmi3ValueReference valueReferences[],
                                  size_t nValueReferences, const fmi3Float64 intervals[]) {
    (void)valueReferences, (void)nValueReferences, (void)intervals;
    return not_provided(c, "fmi3SetIntervalDecimal",
                        G3_SE_PROVIDED ? G3_CONSTANT_CLOCK : G3_NO_CLOCKS);
}

fmi3Status fmi3SetIntervalFraction(fmi3Instance c, const fmi3ValueReference valueReferences[],
                                   size_t nValueReferences, const fmi3UInt64 counters[],
                                   const fmi3UInt64 resolutions[]) {
    (void)valueReferences, (void)nValueReferences, (void)counters, (void)resolutions;
    return not_provided(c, "fmi3SetIntervalFraction",
                        G3_SE_PROVIDED ? G3_CONSTANT_CLOCK : G3_NO_CLOCKS);
}

fmi3Status fmi3SetShiftDecimal(fmi3Instance c, const fmi3ValueReference valueReferences[],
                               size_t nValueReferences, const fmi3Float64 shifts[]) {
    (void)valueReferences, (void)nValueReferences, (void)shifts;
    return not_provided(c, "fmi3SetShiftDecimal",
                        G3_SE_PROVIDED ? G3_CONSTANT_CLOCK : G3_NO_CLOCKS);
}

fmi3Status fmi3SetShiftFraction(fmi3Instance c, const fmi3ValueReference valueReferences[],
                                size_t nValueReferences, const fmi3UInt64 counters[],
                                const fmi3UInt64 resolutions[]) {
    (void)valueReferences, (void)nValueReferences, (void)counters, (void)resolutions;
    return not_provided(c, "fmi3SetShiftFraction",
                        G3_SE_PROVIDED ? G3_CONSTANT_CLOCK : G3_NO_CLOCKS);
}

/* Model Exchange (an instance of this FMU is never one: these answer on any instance; the FMU
 * with Model Exchange has fmi3_me.c's) */

#if !G3_ME_PROVIDED
fmi3Status fmi3EnterContinuousTimeMode(fmi3Instance c) {
    return not_provided(c, "fmi3EnterContinuousTimeMode", G3_NO_ME);
}

fmi3Status fmi3CompletedIntegratorStep(fmi3Instance c, fmi3Boolean noSetFMUStatePriorToCurrentPoint,
                                       fmi3Boolean *enterEventMode,
                                       fmi3Boolean *terminateSimulation) {
    (void)noSetFMUStatePriorToCurrentPoint, (void)enterEventMode, (void)terminateSimulation;
    return not_provided(c, "fmi3CompletedIntegratorStep", G3_NO_ME);
}

fmi3Status fmi3SetTime(fmi3Instance c, fmi3Float64 time) {
    (void)time;
    return not_provided(c, "fmi3SetTime", G3_NO_ME);
}

fmi3Status fmi3SetContinuousStates(fmi3Instance c, const fmi3Float64 continuousStates[],
                                   size_t nContinuousStates) {
    (void)continuousStates, (void)nContinuousStates;
    return not_provided(c, "fmi3SetContinuousStates", G3_NO_ME);
}

fmi3Status fmi3GetContinuousStateDerivatives(fmi3Instance c, fmi3Float64 derivatives[],
                                             size_t nContinuousStates) {
    (void)derivatives, (void)nContinuousStates;
    return not_provided(c, "fmi3GetContinuousStateDerivatives", G3_NO_ME);
}

fmi3Status fmi3GetEventIndicators(fmi3Instance c, fmi3Float64 eventIndicators[],
                                  size_t nEventIndicators) {
    (void)eventIndicators, (void)nEventIndicators;
    return not_provided(c, "fmi3GetEventIndicators", G3_NO_ME);
}

fmi3Status fmi3GetContinuousStates(fmi3Instance c, fmi3Float64 continuousStates[],
                                   size_t nContinuousStates) {
    (void)continuousStates, (void)nContinuousStates;
    return not_provided(c, "fmi3GetContinuousStates", G3_NO_ME);
}

fmi3Status fmi3GetNominalsOfContinuousStates(fmi3Instance c, fmi3Float64 nominals[],
                                             size_t nContinuousStates) {
    (void)nominals, (void)nContinuousStates;
    return not_provided(c, "fmi3GetNominalsOfContinuousStates", G3_NO_ME);
}

fmi3Status fmi3GetNumberOfEventIndicators(fmi3Instance c, size_t *nEventIndicators) {
    (void)nEventIndicators;
    return not_provided(c, "fmi3GetNumberOfEventIndicators", G3_NO_ME);
}

fmi3Status fmi3GetNumberOfContinuousStates(fmi3Instance c, size_t *nContinuousStates) {
    (void)nContinuousStates;
    return not_provided(c, "fmi3GetNumberOfContinuousStates", G3_NO_ME);
}
#endif

/* ------------------------------------------------------------------------ */
/* Scheduled Execution                                                      */

/* clockReference is no clock of the FMU: say what it is. */
static void not_a_clock(Fmi3Instance *inst, const char *fn, fmi3ValueReference r) {
    const char *what = NULL;
    if (r == G3_TIME_VR) what = "time";
    else if (r < inst->n_vr && inst->vr_map[r] >= 0) what = inst->info->vars[inst->vr_map[r]].name;
    if (what != NULL)
        g3_logf(inst, FP_ERROR, FP_LOG_ERROR,
                "%s: clockReference %u is the variable %s, not a clock; the FMU's one input "
                "clock is %s (vr %u)",
                fn, (unsigned)r, what, FP_SE_CLOCK_NAME, (unsigned)FP_SE_CLOCK_VR);
    else
        g3_logf(inst, FP_ERROR, FP_LOG_ERROR,
                "%s: unknown clock reference %u; the FMU's one input clock is %s (vr %u)", fn,
                (unsigned)r, FP_SE_CLOCK_NAME, (unsigned)FP_SE_CLOCK_VR);
}

/* An activation at another time than the next instant due: say which and why. */
static void off_schedule(Fmi3Instance *inst, const char *fn, double t, double due, double tol) {
    double ts = inst->se_interval, k;
    if (!isfinite(t)) {
        g3_logf(inst, FP_ERROR, FP_LOG_ERROR, "%s: activationTime %g is not finite", fn, t);
        return;
    }
    if (t < due && inst->se_k > 0 && fabs(t - (due - ts)) <= tol) {
        g3_logf(inst, FP_ERROR, FP_LOG_ERROR,
                "%s: clock %s was activated at t = %.17g already: each instant is activated "
                "once, in increasing time; the next one is t = %.17g",
                fn, FP_SE_CLOCK_NAME, t, due);
        return;
    }
    k = (t - due) / ts; /* instants from the one due to t (whole when t is on the grid) */
    g3_logf(inst, FP_ERROR, FP_LOG_ERROR,
            "%s: activationTime %.17g is not the next instant of clock %s (vr %u), t = %.17g "
            "(%.17g + %lld x %.17g s): %s; the clock is periodic (intervalDecimal = %.17g s), "
            "each instant activated once, in order",
            fn, t, FP_SE_CLOCK_NAME, (unsigned)FP_SE_CLOCK_VR, due, inst->se_base,
            (long long)inst->se_k, ts,
            t < due ? "it lies before it"
            : fabs(k - floor(k + 0.5)) * ts <= tol ? "it would skip the instants between"
                                                    : "it lies off the clock's grid",
            ts);
}

/*
 * One sample of the clock's model partition at activationTime: the model's step over one
 * interval from activationTime, the call fmi3DoStep(activationTime, Ts) makes in
 * co-simulation, so the sample and its outputs are those of co-simulation stepping by Ts, to
 * the bit.  activationTime must be the next instant of the clock's grid, t0 + k Ts (t0 the
 * start time, k the activations so far; from a restored FMU state, its time plus k Ts),
 * within half the tolerance the model's grid allows (fp_model.h: FP_STEP_TOL of Ts plus
 * FP_TIME_TOL of the time), so that the model runs exactly that sample, from the inputs set
 * before the call.  Any other time (off the grid, an instant skipped, an instant activated
 * twice) is refused with fmi3Error, naming both times, and leaves the instance in Error, as an
 * fmi3DoStep at the wrong communication point does.  No heap, no lock: the callbacks
 * lockPreemption / unlockPreemption are not called (fmi3InstantiateScheduledExecution).
 */
fmi3Status fmi3ActivateModelPartition(fmi3Instance c, fmi3ValueReference clockReference,
                                      fmi3Float64 activationTime) {
    static const char fn[] = "fmi3ActivateModelPartition";
    Fmi3Instance *inst;
    FpStatus s;
    double ts, due, tol;
    if (!G3_SE_PROVIDED) {
        (void)clockReference, (void)activationTime;
        return not_provided(c, fn, G3_NO_SE);
    }
    inst = g3_enter(c, fn, S_ANY_BUT_FATAL);
    if (inst == NULL) return fmi3Error;
    G3_LOG_CALL(inst, "fmi3ActivateModelPartition(clockReference = %u, activationTime = %.17g)",
                (unsigned)clockReference, activationTime);
    if (inst->interface != G3_SCHEDULED_EXECUTION) {
        g3_logf(inst, FP_ERROR, FP_LOG_ERROR,
                "%s: a Co-Simulation instance (fmi3InstantiateCoSimulation) runs its samples by "
                "fmi3DoStep; fmi3ActivateModelPartition is Scheduled Execution's "
                "(fmi3InstantiateScheduledExecution)",
                fn);
        return fmi3Error;
    }
    if (inst->state != S_STEP_COMPLETE) {
        g3_logf(inst, FP_ERROR, FP_LOG_ERROR, "%s may not be called in state %s", fn,
                g3_mode_name(inst));
        return fmi3Error;
    }
    if (!g3_is_clock(clockReference)) {
        not_a_clock(inst, fn, clockReference);
        return fmi3Error;
    }
    ts = inst->se_interval;
    due = inst->se_base + (double)inst->se_k * ts;
    tol = 0.5 * (FP_STEP_TOL * ts + FP_TIME_TOL * fabs(due));
    if (!isfinite(activationTime) || fabs(activationTime - due) > tol) {
        off_schedule(inst, fn, activationTime, due, tol);
        return fail(inst, fmi3Error);
    }
    if (inst->tunables_dirty && inst->info->tunables_changed != NULL) {
        s = inst->info->tunables_changed(inst->model, &inst->model_logger);
        if (s == FP_ERROR || s == FP_DISCARD) return fail(inst, fmi3Error);
    }
    inst->tunables_dirty = 0;
    s = inst->info->step(inst->model, activationTime, ts, &inst->model_logger);
    /* Scheduled Execution has no discarded step: fmi3Discard is treated as fmi3Error */
    if (s == FP_ERROR || s == FP_DISCARD) return fail(inst, fmi3Error);
    inst->se_k++;
    inst->time = inst->se_base + (double)inst->se_k * ts;
    inst->se_set_pending = 0;
    /* as fmi3DoStep: a completed sample answers fmi3OK, its warnings logged as they happen */
    return fmi3OK;
}
