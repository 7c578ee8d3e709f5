/*
 * The FMI 3.0 FMU state functions of every fullpose FMU: fmi3GetFMUState, fmi3SetFMUState,
 * fmi3FreeFMUState and the serialization, over the checked format of fmu_state.c, with the
 * discipline of fmi2_fmustate.c (a restored state's model is checked by the model before it
 * is used).  The format and the lifecycle bits are those of the FMI 2.0 FMU of the same
 * model: its instantiation token is that FMU's GUID, so a state serialized by either
 * restores in the other.  FMI 3.0 has no memory callbacks: states are malloc'ed.  Part of
 * the FMI 3.0 glue (fmi3_glue_internal.h); the lifecycle it restores is fmi3_glue.c's.  A
 * Scheduled Execution instance takes the states of co-simulation ones and the reverse (Clock
 * Activation Mode is saved as Step Mode); restored, its next activation is due at the
 * state's time.
 */
#include <stdlib.h>
#include <string.h>

#include "fmi3_glue_internal.h"

/* ------------------------------------------------------------------------ */
/* FMU state                                                                */

static size_t snapshot_size(const Fmi3Instance *inst) {
    return fp_state_size(inst->info->model_size);
}

static void snapshot_write(const Fmi3Instance *inst, unsigned char *buf) {
    fp_state_write(buf, inst->guid, (int32_t)inst->state,
                   (inst->dirty ? STATE_FLAG_DIRTY : 0u) |
                       (inst->tunables_dirty ? STATE_FLAG_TUNABLES_DIRTY : 0u),
                   inst->time, inst->model, inst->info->model_size);
}

/* fp_state_check (fmu_state.h) for this instance: what is wrong is logged as "FN: WHAT
 * REASON"; 1 and *out filled, or 0. */
static int check_state(Fmi3Instance *inst, const unsigned char *buf, size_t size, int level,
                       const char *fn, const char *what, StateHeader *out) {
    char why[320];
    if (fp_state_check(buf, size, level, inst->guid, inst->info->model_name,
                       inst->info->model_size, inst->info->initialized_offset, out, why,
                       sizeof why) == FP_OK)
        return 1;
    g3_logf(inst, FP_ERROR, FP_LOG_ERROR, "%s: %s %s", fn, what, why);
    return 0;
}

/* Restores a state: checked whole, its model checked on the aligned scratch copy by the
 * model, and only then copied into the live model. */
static fmi3Status snapshot_read(Fmi3Instance *inst, const unsigned char *buf, const char *fn) {
    StateHeader h;
    if (!check_state(inst, buf, 0, STATE_ALL, fn, "FMUState", &h)) return fmi3Error;
    /* Model Exchange's states (Event Mode, Continuous-Time Mode) and the stepping ones
     * (Step Mode, Clock Activation Mode) belong to their interfaces */
    if (h.state & (inst->interface == G3_MODEL_EXCHANGE ? S_STEP_COMPLETE | S_STEP_FAILED
                                                         : S_ME_RUNNING)) {
        g3_logf(inst, FP_ERROR, FP_LOG_ERROR,
                "%s: the state was saved by a %s instance (in %s); this instance is %s", fn,
                inst->interface == G3_MODEL_EXCHANGE ? "co-simulation" : "Model Exchange",
                g3_state_name(h.state),
                inst->interface == G3_MODEL_EXCHANGE ? "Model Exchange"
                : inst->interface == G3_SCHEDULED_EXECUTION ? "Scheduled Execution"
                                                            : "co-simulation");
        return fmi3Error;
    }
    if (inst->interface == G3_SCHEDULED_EXECUTION && h.state == S_STEP_FAILED) {
        g3_logf(inst, FP_ERROR, FP_LOG_ERROR,
                "%s: the state was saved by a Co-Simulation instance after a discarded step, a "
                "state Scheduled Execution does not have",
                fn);
        return fmi3Error;
    }
    memcpy(inst->scratch, buf + sizeof h, inst->info->model_size);
    if (inst->interface == G3_SCHEDULED_EXECUTION && (h.state & S_INITIALIZED)) {
        /* the clock's interval is constant: a state of another sample time cannot go on */
        const FpVar *ts = inst->internal_step;
        double saved;
        memcpy(&saved, (const char *)inst->scratch + ts->offset, sizeof saved);
        if (saved != inst->se_interval) {
            g3_logf(inst, FP_ERROR, FP_LOG_ERROR,
                    "%s: the state's %s is %.17g s, but the clock %s activates samples every "
                    "%.17g s (a constant interval)",
                    fn, ts->name, saved, FP_SE_CLOCK_NAME, inst->se_interval);
            return fmi3Error;
        }
    }
    if (inst->info->check_restored != NULL) {
        FpStatus s;
        inst->checking = 1;
        s = inst->info->check_restored(inst->scratch, (h.state & S_INITIALIZED) != 0,
                                       &inst->model_logger);
        inst->checking = 0;
        if (s != FP_OK) {
            g3_logf(inst, FP_ERROR, FP_LOG_ERROR, "%s: the state is refused", fn);
            return fmi3Error;
        }
    }
    memcpy(inst->model, inst->scratch, inst->info->model_size);
    inst->state = h.state;
    inst->dirty = (h.flags & STATE_FLAG_DIRTY) != 0;
    inst->tunables_dirty = (h.flags & STATE_FLAG_TUNABLES_DIRTY) != 0;
    inst->time = h.time;
    inst->me_stale = 1;
    /* Scheduled Execution: the next activation is due at the state's time (a state saved by
     * either interface after a sample holds the instant of the next one) */
    g3_se_anchor(inst);
    return fmi3OK;
}

fmi3Status fmi3GetFMUState(fmi3Instance c, fmi3FMUState *FMUState) {
    unsigned char *buf;
    G3_CHECK("fmi3GetFMUState", S_ANY_BUT_FATAL);
    G3_LOG_CALL(inst, "fmi3GetFMUState(FMUState = %p -> %p)", (void *)FMUState,
             FMUState ? *FMUState : NULL);
    if (FMUState == NULL) return g3_null_argument(inst, "fmi3GetFMUState", "FMUState");
    buf = (unsigned char *)*FMUState;
    if (buf != NULL) {
        /* a state to reuse: only one of ours has room for this one */
        if (!check_state(inst, buf, 0, STATE_HEADER, "fmi3GetFMUState", "the FMUState to reuse",
                         NULL))
            return fmi3Error;
    } else {
        buf = (unsigned char *)malloc(snapshot_size(inst));
        if (buf == NULL) {
            g3_logf(inst, FP_ERROR, FP_LOG_ERROR, "fmi3GetFMUState: out of memory");
            return fmi3Error;
        }
    }
    snapshot_write(inst, buf);
    *FMUState = buf;
    return fmi3OK;
}

fmi3Status fmi3SetFMUState(fmi3Instance c, fmi3FMUState FMUState) {
    G3_CHECK("fmi3SetFMUState", S_ANY_BUT_FATAL);
    G3_LOG_CALL(inst, "fmi3SetFMUState(FMUState = %p)", FMUState);
    return snapshot_read(inst, (const unsigned char *)FMUState, "fmi3SetFMUState");
}

fmi3Status fmi3FreeFMUState(fmi3Instance c, fmi3FMUState *FMUState) {
    G3_CHECK("fmi3FreeFMUState", S_ANY_BUT_FATAL);
    G3_LOG_CALL(inst, "fmi3FreeFMUState(FMUState = %p -> %p)", (void *)FMUState,
             FMUState ? *FMUState : NULL);
    if (FMUState == NULL) return g3_null_argument(inst, "fmi3FreeFMUState", "FMUState");
    if (*FMUState == NULL) return fmi3OK; /* a NULL state: nothing to free */
    if (!check_state(inst, (const unsigned char *)*FMUState, 0, STATE_HEADER, "fmi3FreeFMUState",
                     "FMUState", NULL))
        return fmi3Error; /* not ours: never handed to the allocator */
    memset(*FMUState, 0, sizeof(StateHeader)); /* a second free is refused (best effort) */
    free(*FMUState);
    *FMUState = NULL;
    return fmi3OK;
}

fmi3Status fmi3SerializedFMUStateSize(fmi3Instance c, fmi3FMUState FMUState, size_t *size) {
    G3_CHECK("fmi3SerializedFMUStateSize", S_ANY_BUT_FATAL);
    G3_LOG_CALL(inst, "fmi3SerializedFMUStateSize(FMUState = %p)", FMUState);
    if (size == NULL) return g3_null_argument(inst, "fmi3SerializedFMUStateSize", "size");
    if (!check_state(inst, (const unsigned char *)FMUState, 0, STATE_HEADER,
                     "fmi3SerializedFMUStateSize", "FMUState", NULL))
        return fmi3Error;
    *size = snapshot_size(inst);
    return fmi3OK;
}

fmi3Status fmi3SerializeFMUState(fmi3Instance c, fmi3FMUState FMUState, fmi3Byte serializedState[],
                                 size_t size) {
    G3_CHECK("fmi3SerializeFMUState", S_ANY_BUT_FATAL);
    G3_LOG_CALL(inst, "fmi3SerializeFMUState(FMUState = %p, serializedState = %p, size = %lu)",
             FMUState, (void *)serializedState, (unsigned long)size);
    if (!check_state(inst, (const unsigned char *)FMUState, 0, STATE_ALL,
                     "fmi3SerializeFMUState", "FMUState", NULL))
        return fmi3Error;
    if (serializedState == NULL)
        return g3_null_argument(inst, "fmi3SerializeFMUState", "serializedState");
    if (size < snapshot_size(inst)) {
        g3_logf(inst, FP_ERROR, FP_LOG_ERROR,
                  "fmi3SerializeFMUState: a buffer of %lu bytes is too small, the state has %lu",
                  (unsigned long)size, (unsigned long)snapshot_size(inst));
        return fmi3Error;
    }
    memcpy(serializedState, FMUState, snapshot_size(inst));
    return fmi3OK;
}

fmi3Status fmi3DeserializeFMUState(fmi3Instance c, const fmi3Byte serializedState[], size_t size,
                                   fmi3FMUState *FMUState) {
    unsigned char *buf;
    G3_CHECK("fmi3DeserializeFMUState", S_ANY_BUT_FATAL);
    G3_LOG_CALL(inst, "fmi3DeserializeFMUState(serializedState = %p, size = %lu, FMUState = %p)",
             (const void *)serializedState, (unsigned long)size, (void *)FMUState);
    if (FMUState == NULL) return g3_null_argument(inst, "fmi3DeserializeFMUState", "FMUState");
    if (serializedState == NULL)
        return g3_null_argument(inst, "fmi3DeserializeFMUState", "serializedState");
    if (size == 0) {
        g3_logf(inst, FP_ERROR, FP_LOG_ERROR,
                  "fmi3DeserializeFMUState: the data is empty; a state of %s has %lu bytes",
                  inst->info->model_name, (unsigned long)snapshot_size(inst));
        return fmi3Error;
    }
    if (!check_state(inst, (const unsigned char *)serializedState, size, STATE_ALL,
                     "fmi3DeserializeFMUState", "the data", NULL))
        return fmi3Error;
    buf = (unsigned char *)*FMUState;
    if (buf != NULL) {
        if (!check_state(inst, buf, 0, STATE_HEADER, "fmi3DeserializeFMUState",
                         "the FMUState to reuse", NULL))
            return fmi3Error;
    } else {
        buf = (unsigned char *)malloc(size);
        if (buf == NULL) {
            g3_logf(inst, FP_ERROR, FP_LOG_ERROR, "fmi3DeserializeFMUState: out of memory");
            return fmi3Error;
        }
    }
    memcpy(buf, serializedState, size);
    *FMUState = buf;
    return fmi3OK;
}
