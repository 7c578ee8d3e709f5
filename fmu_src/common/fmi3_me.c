/*
 * The FMI 3.0 Model Exchange functions, for the FMU built with FP_FMI3_MODEL_EXCHANGE (its
 * model has a Model Exchange side, FpModelInfo.me: the plant), the twin of fmi2_me.c.  Part
 * of the FMI 3.0 glue (fmi3_glue_internal.h): fmi3_glue.c instantiates a Model Exchange
 * instance (fmi3InstantiateModelExchange), initializes it into Event Mode, evaluates the
 * model when a value is read after the time, the states or the inputs changed (g3_refresh),
 * and terminates and resets it as any other; what is here is the rest of the state machine
 * of FMI 3.0 Model Exchange:
 *
 *   Instantiated -> Initialization Mode -> Event Mode <-> Continuous-Time Mode -> Terminated
 *
 * with Error from any state.  Every call out of sequence answers fmi3Error with a message
 * naming the function and the state, a NULL array or pointer one naming the argument, a size
 * other than the model's one naming both sizes; such a refused call changes nothing.  On an
 * instance of another interface (co-simulation, which has no Event Mode) the Event Mode
 * functions answer as the FMUs without Model Exchange do, the others name the interface.
 * The model behind it is reached only through FpModelExchange and never sees an FMI type.
 */
#include <math.h>
#include <string.h>

#include "fmi3_glue_internal.h"

#if G3_ME_PROVIDED

/* The states each function may be called in (FMI 3.0, Model Exchange). */
#define S_ME_READ (S_INIT | S_ME_RUNNING | S_TERMINATED | S_ERROR)
#define S_ME_NOMINALS (S_INSTANTIATED | S_ME_READ)

/* Entry of every Model Exchange function: a live instance, instantiated as Model Exchange,
 * in one of `states`; else NULL with the reason logged. */
static Fmi3Instance *me_enter(fmi3Instance c, const char *fn, int states) {
    Fmi3Instance *inst = g3_enter(c, fn, S_ANY_BUT_FATAL);
    if (inst == NULL) return NULL;
    if (inst->interface != G3_MODEL_EXCHANGE) {
        g3_logf(inst, FP_ERROR, FP_LOG_ERROR,
                "%s: the instance was instantiated for %s; the Model Exchange functions need "
                "an instance of fmi3InstantiateModelExchange",
                fn, inst->interface == G3_SCHEDULED_EXECUTION
                        ? "scheduled execution (fmi3InstantiateScheduledExecution)"
                        : "co-simulation (fmi3InstantiateCoSimulation)");
        return NULL;
    }
    if (!(inst->state & states)) {
        g3_logf(inst, FP_ERROR, FP_LOG_ERROR, "%s may not be called in %s", fn,
                g3_state_name(inst->state));
        return NULL;
    }
    return inst;
}

#define ME_CHECK(fn, states)                                         \
    Fmi3Instance *inst = me_enter(c, fn, states);                    \
    if (inst == NULL) return fmi3Error

/* An array of the model's size: n must be `expected`, the array not NULL when n > 0. */
static int sized(Fmi3Instance *inst, const char *fn, const char *what, const char *array,
                 size_t n, uint32_t expected, const void *values) {
    if (n != (size_t)expected) {
        g3_logf(inst, FP_ERROR, FP_LOG_ERROR, "%s: %s = %lu, but %s has %lu %s", fn, what,
                (unsigned long)n, inst->info->model_name, (unsigned long)expected,
                strcmp(what, "nEventIndicators") == 0 ? "event indicators"
                                                      : "continuous states");
        return 0;
    }
    if (n > 0 && values == NULL) {
        g3_null_argument(inst, fn, array);
        return 0;
    }
    return 1;
}

/* In Initialization Mode the state follows the parameters set (g3_refresh: the model's
 * initialize); later it is the solver's. */
static fmi3Status initialized_state(Fmi3Instance *inst) {
    if (inst->state & (S_INSTANTIATED | S_INIT)) return g3_refresh(inst);
    return fmi3OK;
}

/* The model's discrete state after a completed step or in an event (the plant: the contact
 * anchors); its failure (the state left the model's range) leaves the instance in Error. */
static fmi3Status update_discrete(Fmi3Instance *inst) {
    FpStatus s = inst->info->me->update_discrete(inst->model, inst->time, &inst->model_logger);
    inst->me_stale = 1;
    if (s == FP_ERROR || s == FP_DISCARD) return g3_fail(inst, fmi3Error);
    return fmi3OK;
}

/* ------------------------------------------------------------------------ */
/* Modes                                                                    */

fmi3Status fmi3EnterEventMode(fmi3Instance c) {
    Fmi3Instance *inst = g3_enter(c, "fmi3EnterEventMode", S_ANY_BUT_FATAL);
    if (inst == NULL) return fmi3Error;
    if (inst->interface != G3_MODEL_EXCHANGE) return g3_no_event_mode(c, "fmi3EnterEventMode");
    if (!(inst->state & S_CONTINUOUS_TIME)) {
        g3_logf(inst, FP_ERROR, FP_LOG_ERROR, "fmi3EnterEventMode may not be called in %s",
                g3_state_name(inst->state));
        return fmi3Error;
    }
    G3_LOG_CALL(inst, "fmi3EnterEventMode()");
    inst->state = S_EVENT_MODE;
    return fmi3OK;
}

/* The event iteration converges at once: the model has no discrete equations that wait for
 * another, no time events and never changes the continuous states or their nominals. */
fmi3Status fmi3UpdateDiscreteStates(fmi3Instance c, fmi3Boolean *discreteStatesNeedUpdate,
                                    fmi3Boolean *terminateSimulation,
                                    fmi3Boolean *nominalsOfContinuousStatesChanged,
                                    fmi3Boolean *valuesOfContinuousStatesChanged,
                                    fmi3Boolean *nextEventTimeDefined,
                                    fmi3Float64 *nextEventTime) {
    static const char fn[] = "fmi3UpdateDiscreteStates";
    fmi3Status s;
    Fmi3Instance *inst = g3_enter(c, fn, S_ANY_BUT_FATAL);
    if (inst == NULL) return fmi3Error;
    if (inst->interface != G3_MODEL_EXCHANGE) return g3_no_event_mode(c, fn);
    if (!(inst->state & S_EVENT_MODE)) {
        g3_logf(inst, FP_ERROR, FP_LOG_ERROR, "%s may not be called in %s", fn,
                g3_state_name(inst->state));
        return fmi3Error;
    }
    G3_LOG_CALL(inst, "fmi3UpdateDiscreteStates() at t = %.17g", inst->time);
    if (discreteStatesNeedUpdate == NULL)
        return g3_null_argument(inst, fn, "discreteStatesNeedUpdate");
    if (terminateSimulation == NULL) return g3_null_argument(inst, fn, "terminateSimulation");
    if (nominalsOfContinuousStatesChanged == NULL)
        return g3_null_argument(inst, fn, "nominalsOfContinuousStatesChanged");
    if (valuesOfContinuousStatesChanged == NULL)
        return g3_null_argument(inst, fn, "valuesOfContinuousStatesChanged");
    if (nextEventTimeDefined == NULL) return g3_null_argument(inst, fn, "nextEventTimeDefined");
    if (nextEventTime == NULL) return g3_null_argument(inst, fn, "nextEventTime");
    s = update_discrete(inst);
    if (s > fmi3Warning) return s;
    *discreteStatesNeedUpdate = false;
    *terminateSimulation = false;
    *nominalsOfContinuousStatesChanged = false;
    *valuesOfContinuousStatesChanged = false;
    *nextEventTimeDefined = false;
    *nextEventTime = 0.0;
    return s;
}

fmi3Status fmi3EnterContinuousTimeMode(fmi3Instance c) {
    ME_CHECK("fmi3EnterContinuousTimeMode", S_EVENT_MODE);
    G3_LOG_CALL(inst, "fmi3EnterContinuousTimeMode()");
    inst->state = S_CONTINUOUS_TIME;
    return fmi3OK;
}

/* The discrete state follows the step the solver completed (as the co-simulation step
 * updates it after every internal step); no step event, no termination asked. */
fmi3Status fmi3CompletedIntegratorStep(fmi3Instance c, fmi3Boolean noSetFMUStatePriorToCurrentPoint,
                                       fmi3Boolean *enterEventMode,
                                       fmi3Boolean *terminateSimulation) {
    fmi3Status s;
    ME_CHECK("fmi3CompletedIntegratorStep", S_CONTINUOUS_TIME);
    G3_LOG_CALL(inst,
                "fmi3CompletedIntegratorStep(noSetFMUStatePriorToCurrentPoint = %d) at t = %.17g",
                (int)noSetFMUStatePriorToCurrentPoint, inst->time);
    if (enterEventMode == NULL)
        return g3_null_argument(inst, "fmi3CompletedIntegratorStep", "enterEventMode");
    if (terminateSimulation == NULL)
        return g3_null_argument(inst, "fmi3CompletedIntegratorStep", "terminateSimulation");
    s = update_discrete(inst);
    if (s > fmi3Warning) return s;
    *enterEventMode = false;
    *terminateSimulation = false;
    return s;
}

/* ------------------------------------------------------------------------ */
/* Time and states                                                          */

fmi3Status fmi3SetTime(fmi3Instance c, fmi3Float64 time) {
    ME_CHECK("fmi3SetTime", S_ME_RUNNING);
    G3_LOG_CALL(inst, "fmi3SetTime(time = %.17g)", time);
    if (!isfinite(time)) {
        g3_logf(inst, FP_ERROR, FP_LOG_ERROR, "fmi3SetTime: time %g is not finite", time);
        return fmi3Error;
    }
    if (time != inst->time) inst->me_stale = 1;
    inst->time = time;
    return fmi3OK;
}

fmi3Status fmi3SetContinuousStates(fmi3Instance c, const fmi3Float64 continuousStates[],
                                   size_t nContinuousStates) {
    const FpModelExchange *me;
    size_t i;
    ME_CHECK("fmi3SetContinuousStates", S_CONTINUOUS_TIME);
    G3_LOG_CALL(inst, "fmi3SetContinuousStates(continuousStates = %p, nContinuousStates = %lu)",
                (const void *)continuousStates, (unsigned long)nContinuousStates);
    me = inst->info->me;
    if (!sized(inst, "fmi3SetContinuousStates", "nContinuousStates", "continuousStates",
               nContinuousStates, me->n_states, continuousStates))
        return fmi3Error;
    for (i = 0; i < nContinuousStates; i++)
        if (!isfinite(continuousStates[i])) {
            g3_logf(inst, FP_ERROR, FP_LOG_ERROR,
                    "fmi3SetContinuousStates: continuousStates[%lu] = %g is not finite; the "
                    "states are kept",
                    (unsigned long)i, continuousStates[i]);
            return fmi3Error;
        }
    me->set_states(inst->model, continuousStates);
    inst->me_stale = 1;
    return fmi3OK;
}

fmi3Status fmi3GetContinuousStates(fmi3Instance c, fmi3Float64 continuousStates[],
                                   size_t nContinuousStates) {
    fmi3Status s;
    ME_CHECK("fmi3GetContinuousStates", S_ME_READ);
    G3_LOG_CALL(inst, "fmi3GetContinuousStates(continuousStates = %p, nContinuousStates = %lu)",
                (void *)continuousStates, (unsigned long)nContinuousStates);
    if (!sized(inst, "fmi3GetContinuousStates", "nContinuousStates", "continuousStates",
               nContinuousStates, inst->info->me->n_states, continuousStates))
        return fmi3Error;
    s = initialized_state(inst);
    if (s > fmi3Warning) return s;
    inst->info->me->get_states(inst->model, continuousStates);
    return s;
}

fmi3Status fmi3GetNominalsOfContinuousStates(fmi3Instance c, fmi3Float64 nominals[],
                                             size_t nContinuousStates) {
    ME_CHECK("fmi3GetNominalsOfContinuousStates", S_ME_NOMINALS);
    G3_LOG_CALL(inst, "fmi3GetNominalsOfContinuousStates(nominals = %p, nContinuousStates = %lu)",
                (void *)nominals, (unsigned long)nContinuousStates);
    if (!sized(inst, "fmi3GetNominalsOfContinuousStates", "nContinuousStates", "nominals",
               nContinuousStates, inst->info->me->n_states, nominals))
        return fmi3Error;
    inst->info->me->nominals(inst->model, nominals);
    return fmi3OK;
}

fmi3Status fmi3GetNumberOfContinuousStates(fmi3Instance c, size_t *nContinuousStates) {
    ME_CHECK("fmi3GetNumberOfContinuousStates", S_ANY_BUT_FATAL);
    G3_LOG_CALL(inst, "fmi3GetNumberOfContinuousStates()");
    if (nContinuousStates == NULL)
        return g3_null_argument(inst, "fmi3GetNumberOfContinuousStates", "nContinuousStates");
    *nContinuousStates = inst->info->me->n_states;
    return fmi3OK;
}

fmi3Status fmi3GetNumberOfEventIndicators(fmi3Instance c, size_t *nEventIndicators) {
    ME_CHECK("fmi3GetNumberOfEventIndicators", S_ANY_BUT_FATAL);
    G3_LOG_CALL(inst, "fmi3GetNumberOfEventIndicators()");
    if (nEventIndicators == NULL)
        return g3_null_argument(inst, "fmi3GetNumberOfEventIndicators", "nEventIndicators");
    *nEventIndicators = inst->info->me->n_event_indicators;
    return fmi3OK;
}

/* ------------------------------------------------------------------------ */
/* The model's equations                                                    */

fmi3Status fmi3GetContinuousStateDerivatives(fmi3Instance c, fmi3Float64 derivatives[],
                                             size_t nContinuousStates) {
    fmi3Status s;
    ME_CHECK("fmi3GetContinuousStateDerivatives", S_ME_READ);
    G3_LOG_CALL(inst,
                "fmi3GetContinuousStateDerivatives(derivatives = %p, nContinuousStates = %lu) "
                "at t = %.17g",
                (void *)derivatives, (unsigned long)nContinuousStates, inst->time);
    if (!sized(inst, "fmi3GetContinuousStateDerivatives", "nContinuousStates", "derivatives",
               nContinuousStates, inst->info->me->n_states, derivatives))
        return fmi3Error;
    s = g3_refresh(inst);
    if (s > fmi3Warning) return s;
    inst->info->me->get_derivatives(inst->model, derivatives);
    return s;
}

/* Functions of the state alone: the model is not evaluated for them. */
fmi3Status fmi3GetEventIndicators(fmi3Instance c, fmi3Float64 eventIndicators[],
                                  size_t nEventIndicators) {
    fmi3Status s;
    ME_CHECK("fmi3GetEventIndicators", S_ME_READ);
    G3_LOG_CALL(inst, "fmi3GetEventIndicators(eventIndicators = %p, nEventIndicators = %lu)",
                (void *)eventIndicators, (unsigned long)nEventIndicators);
    if (!sized(inst, "fmi3GetEventIndicators", "nEventIndicators", "eventIndicators",
               nEventIndicators, inst->info->me->n_event_indicators, eventIndicators))
        return fmi3Error;
    s = initialized_state(inst);
    if (s > fmi3Warning) return s;
    if (nEventIndicators > 0) inst->info->me->event_indicators(inst->model, eventIndicators);
    return s;
}

#else
/* (an FMU without Model Exchange: fmi3_glue.c answers these functions) */
typedef int fp_fmi3_me_not_provided;
#endif
