/*
 * The FMI 2.0 Model Exchange functions, for the FMUs whose model has a Model Exchange side
 * (FpModelInfo.me, fp_model.h): the model's continuous state handed to the importer's solver.
 * Part of the glue (fmi2_glue_internal.h): fmi2_glue.c instantiates a Model Exchange instance
 * (fmuType fmi2ModelExchange), initializes it into Event Mode, evaluates the model when a
 * value is read after the time, the states or the inputs changed (glue_refresh), and
 * terminates and resets it as any other; what is here is the rest of the state machine of FMI
 * 2.0 section 3.2.3:
 *
 *   Instantiated -> InitializationMode -> EventMode <-> ContinuousTimeMode -> Terminated
 *
 * with Error from any state.  Every call out of sequence answers fmi2Error with a message
 * naming the function and the state, a NULL array or pointer one naming the argument, a
 * size other than the model's one naming both sizes; such a refused call changes nothing.
 * The model behind it is reached only through FpModelExchange and never sees an FMI type.
 */
#include <math.h>
#include <string.h>

#include "fmi2_glue_internal.h"

/* The states each function may be called in (FMI 2.0 section 3.2.3, table of the
 * Model Exchange calls). */
#define S_ME_READ (S_INIT | S_ME_RUNNING | S_TERMINATED | S_ERROR)
#define S_ME_NOMINALS (S_INSTANTIATED | S_ME_READ)

/* Entry of every Model Exchange function: a live instance, instantiated as Model Exchange,
 * in one of `states`; else NULL with the reason logged. */
static Instance *me_enter(fmi2Component c, const char *fn, int states) {
    Instance *inst = glue_enter(c, fn, S_ANY_BUT_FATAL);
    if (inst == NULL) return NULL;
    if (!inst->me) {
        glue_logf(inst, FP_ERROR, FP_LOG_ERROR,
                  "%s: %s was instantiated for co-simulation (fmuType fmi2CoSimulation); the "
                  "Model Exchange functions need an instance of fmuType fmi2ModelExchange",
                  fn, inst->name);
        return NULL;
    }
    if (!(inst->state & states)) {
        glue_logf(inst, FP_ERROR, FP_LOG_ERROR, "%s may not be called in state %s", fn,
                  fp_lifecycle_name(inst->state));
        return NULL;
    }
    return inst;
}

#define ME_CHECK(fn, states)                                    \
    Instance *inst = me_enter(c, fn, states);                   \
    if (inst == NULL) return fmi2Error

/* An array of the model's size: n must be `expected` (what it counts: "nx", "ni"), the array
 * not NULL when n > 0. */
static int sized(Instance *inst, const char *fn, const char *what, const char *array,
                 size_t n, uint32_t expected, const void *values) {
    if (n != (size_t)expected) {
        glue_logf(inst, FP_ERROR, FP_LOG_ERROR,
                  "%s: %s = %lu, but %s has %lu %s", fn, what, (unsigned long)n,
                  inst->info->model_name, (unsigned long)expected,
                  strcmp(what, "ni") == 0 ? "event indicators" : "continuous states");
        return 0;
    }
    if (n > 0 && values == NULL) {
        glue_null_argument(inst, fn, array);
        return 0;
    }
    return 1;
}

/* In Initialization Mode the state follows the parameters set: brought up to date before it
 * is read (glue_refresh: the model's initialize).  Later the state is the solver's. */
static fmi2Status initialized_state(Instance *inst) {
    if (inst->state & (S_INSTANTIATED | S_INIT)) return glue_refresh(inst);
    return fmi2OK;
}

/* The model's discrete state after a completed step or in an event (the plant: the contact
 * anchors); its failure (the state left the model's range) leaves the instance in Error. */
static fmi2Status update_discrete(Instance *inst) {
    FpStatus s = inst->info->me->update_discrete(inst->model, inst->time, &inst->model_logger);
    inst->me_stale = 1;
    if (s == FP_ERROR || s == FP_DISCARD) return glue_fail(inst, fmi2Error);
    return fmi2OK;
}

/* ------------------------------------------------------------------------ */
/* Modes                                                                    */

fmi2Status fmi2EnterEventMode(fmi2Component c) {
    ME_CHECK("fmi2EnterEventMode", S_ME_RUNNING);
    LOG_CALL(inst, "fmi2EnterEventMode()");
    inst->state = S_EVENT_MODE;
    return fmi2OK;
}

/* The event iteration converges at once: the model has no discrete equations that wait for
 * another, no time events (nextEventTimeDefined false) and never changes the continuous
 * states or their nominals in an event. */
fmi2Status fmi2NewDiscreteStates(fmi2Component c, fmi2EventInfo *eventInfo) {
    fmi2Status s;
    ME_CHECK("fmi2NewDiscreteStates", S_EVENT_MODE);
    LOG_CALL(inst, "fmi2NewDiscreteStates(eventInfo = %p) at t = %.17g", (void *)eventInfo,
             inst->time);
    if (eventInfo == NULL) return glue_null_argument(inst, "fmi2NewDiscreteStates", "eventInfo");
    s = update_discrete(inst);
    if (s > fmi2Warning) return s;
    eventInfo->newDiscreteStatesNeeded = fmi2False;
    eventInfo->terminateSimulation = fmi2False;
    eventInfo->nominalsOfContinuousStatesChanged = fmi2False;
    eventInfo->valuesOfContinuousStatesChanged = fmi2False;
    eventInfo->nextEventTimeDefined = fmi2False;
    eventInfo->nextEventTime = 0.0;
    return s;
}

fmi2Status fmi2EnterContinuousTimeMode(fmi2Component c) {
    ME_CHECK("fmi2EnterContinuousTimeMode", S_EVENT_MODE);
    LOG_CALL(inst, "fmi2EnterContinuousTimeMode()");
    inst->state = S_CONTINUOUS_TIME;
    return fmi2OK;
}

/* The discrete state follows the step the solver completed (as the co-simulation step
 * updates it after every internal step); no step event, no termination asked. */
fmi2Status fmi2CompletedIntegratorStep(fmi2Component c,
                                       fmi2Boolean noSetFMUStatePriorToCurrentPoint,
                                       fmi2Boolean *enterEventMode,
                                       fmi2Boolean *terminateSimulation) {
    fmi2Status s;
    ME_CHECK("fmi2CompletedIntegratorStep", S_CONTINUOUS_TIME);
    LOG_CALL(inst,
             "fmi2CompletedIntegratorStep(noSetFMUStatePriorToCurrentPoint = %d) at t = %.17g",
             (int)noSetFMUStatePriorToCurrentPoint, inst->time);
    if (enterEventMode == NULL)
        return glue_null_argument(inst, "fmi2CompletedIntegratorStep", "enterEventMode");
    if (terminateSimulation == NULL)
        return glue_null_argument(inst, "fmi2CompletedIntegratorStep", "terminateSimulation");
    s = update_discrete(inst);
    if (s > fmi2Warning) return s;
    *enterEventMode = fmi2False;
    *terminateSimulation = fmi2False;
    return s;
}

/* ------------------------------------------------------------------------ */
/* Time and states                                                          */

fmi2Status fmi2SetTime(fmi2Component c, fmi2Real time) {
    ME_CHECK("fmi2SetTime", S_ME_RUNNING);
    LOG_CALL(inst, "fmi2SetTime(time = %.17g)", time);
    if (!isfinite(time)) {
        glue_logf(inst, FP_ERROR, FP_LOG_ERROR, "fmi2SetTime: time %g is not finite", time);
        return fmi2Error;
    }
    if (time != inst->time) inst->me_stale = 1;
    inst->time = time;
    return fmi2OK;
}

fmi2Status fmi2SetContinuousStates(fmi2Component c, const fmi2Real x[], size_t nx) {
    const FpModelExchange *me;
    size_t i;
    ME_CHECK("fmi2SetContinuousStates", S_CONTINUOUS_TIME);
    LOG_CALL(inst, "fmi2SetContinuousStates(x = %p, nx = %lu)", (const void *)x,
             (unsigned long)nx);
    me = inst->info->me;
    if (!sized(inst, "fmi2SetContinuousStates", "nx", "x", nx, me->n_states, x))
        return fmi2Error;
    for (i = 0; i < nx; i++)
        if (!isfinite(x[i])) {
            glue_logf(inst, FP_ERROR, FP_LOG_ERROR,
                      "fmi2SetContinuousStates: x[%lu] = %g is not finite; the states are kept",
                      (unsigned long)i, x[i]);
            return fmi2Error;
        }
    me->set_states(inst->model, x);
    inst->me_stale = 1;
    return fmi2OK;
}

fmi2Status fmi2GetContinuousStates(fmi2Component c, fmi2Real x[], size_t nx) {
    fmi2Status s;
    ME_CHECK("fmi2GetContinuousStates", S_ME_READ);
    LOG_CALL(inst, "fmi2GetContinuousStates(x = %p, nx = %lu)", (void *)x, (unsigned long)nx);
    if (!sized(inst, "fmi2GetContinuousStates", "nx", "x", nx, inst->info->me->n_states, x))
        return fmi2Error;
    s = initialized_state(inst);
    if (s > fmi2Warning) return s;
    inst->info->me->get_states(inst->model, x);
    return s;
}

fmi2Status fmi2GetNominalsOfContinuousStates(fmi2Component c, fmi2Real x_nominal[], size_t nx) {
    ME_CHECK("fmi2GetNominalsOfContinuousStates", S_ME_NOMINALS);
    LOG_CALL(inst, "fmi2GetNominalsOfContinuousStates(x_nominal = %p, nx = %lu)",
             (void *)x_nominal, (unsigned long)nx);
    if (!sized(inst, "fmi2GetNominalsOfContinuousStates", "nx", "x_nominal", nx,
               inst->info->me->n_states, x_nominal))
        return fmi2Error;
    inst->info->me->nominals(inst->model, x_nominal);
    return fmi2OK;
}

/* ------------------------------------------------------------------------ */
/* The model's equations                                                    */

fmi2Status fmi2GetDerivatives(fmi2Component c, fmi2Real derivatives[], size_t nx) {
    fmi2Status s;
    ME_CHECK("fmi2GetDerivatives", S_ME_READ);
    LOG_CALL(inst, "fmi2GetDerivatives(derivatives = %p, nx = %lu) at t = %.17g",
             (void *)derivatives, (unsigned long)nx, inst->time);
    if (!sized(inst, "fmi2GetDerivatives", "nx", "derivatives", nx, inst->info->me->n_states,
               derivatives))
        return fmi2Error;
    s = glue_refresh(inst);
    if (s > fmi2Warning) return s;
    inst->info->me->get_derivatives(inst->model, derivatives);
    return s;
}

/* Functions of the state alone: the model is not evaluated for them. */
fmi2Status fmi2GetEventIndicators(fmi2Component c, fmi2Real eventIndicators[], size_t ni) {
    fmi2Status s;
    ME_CHECK("fmi2GetEventIndicators", S_ME_READ);
    LOG_CALL(inst, "fmi2GetEventIndicators(eventIndicators = %p, ni = %lu)",
             (void *)eventIndicators, (unsigned long)ni);
    if (!sized(inst, "fmi2GetEventIndicators", "ni", "eventIndicators", ni,
               inst->info->me->n_event_indicators, eventIndicators))
        return fmi2Error;
    s = initialized_state(inst);
    if (s > fmi2Warning) return s;
    if (ni > 0) inst->info->me->event_indicators(inst->model, eventIndicators);
    return s;
}
