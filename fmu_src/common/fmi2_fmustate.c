/*
 * The FMI 2.0 FMU state functions of every fullpose FMU: fmi2GetFMUstate, fmi2SetFMUstate,
 * fmi2FreeFMUstate and the serialization, over the checked format of fmu_state.c (a restored
 * state's model is checked by the model before it is used).  Part of the glue
 * (fmi2_glue_internal.h); the lifecycle it restores is fmi2_glue.c's.
 */
#include <string.h>

#include "fmi2_glue_internal.h"

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
                       inst->info->model_size, inst->info->initialized_offset, out, why,
                       sizeof why) == FP_OK)
        return 1;
    glue_logf(inst, FP_ERROR, FP_LOG_ERROR, "%s: %s %s", fn, what, why);
    return 0;
}

/* Restores a state: checked whole, its model checked on the aligned scratch copy by the
 * model, and only then copied into the live model. */
static fmi2Status snapshot_read(Instance *inst, const unsigned char *buf, const char *fn) {
    StateHeader h;
    if (!check_state(inst, buf, 0, STATE_ALL, fn, "FMUstate", &h)) return fmi2Error;
    /* a state of the other interface would put this instance in a state it has not */
    if (h.state & (inst->me ? S_STEP_COMPLETE | S_STEP_FAILED : S_ME_RUNNING)) {
        glue_logf(inst, FP_ERROR, FP_LOG_ERROR,
                  "%s: the FMUstate was saved by a %s instance (in %s); this instance is %s",
                  fn, inst->me ? "co-simulation" : "Model Exchange", fp_lifecycle_name(h.state),
                  inst->me ? "Model Exchange" : "co-simulation");
        return fmi2Error;
    }
    memcpy(inst->scratch, buf + sizeof h, inst->info->model_size);
    if (inst->info->check_restored != NULL) {
        FpStatus s;
        inst->checking = 1;
        s = inst->info->check_restored(inst->scratch, (h.state & S_INITIALIZED) != 0,
                                       &inst->model_logger);
        inst->checking = 0;
        if (s != FP_OK) {
            glue_logf(inst, FP_ERROR, FP_LOG_ERROR, "%s: the state is refused", fn);
            return fmi2Error;
        }
    }
    memcpy(inst->model, inst->scratch, inst->info->model_size);
    inst->state = h.state;
    inst->dirty = (h.flags & STATE_FLAG_DIRTY) != 0;
    inst->tunables_dirty = (h.flags & STATE_FLAG_TUNABLES_DIRTY) != 0;
    inst->time = h.time;
    inst->me_stale = 1;
    return fmi2OK;
}

fmi2Status fmi2GetFMUstate(fmi2Component c, fmi2FMUstate *FMUstate) {
    unsigned char *buf;
    CHECK("fmi2GetFMUstate", S_ANY_BUT_FATAL);
    LOG_CALL(inst, "fmi2GetFMUstate(FMUstate = %p -> %p)", (void *)FMUstate,
             FMUstate ? *FMUstate : NULL);
    if (FMUstate == NULL) return glue_null_argument(inst, "fmi2GetFMUstate", "FMUstate");
    buf = (unsigned char *)*FMUstate;
    if (buf != NULL) {
        /* a state to reuse: only one of ours has room for this one */
        if (!check_state(inst, buf, 0, STATE_HEADER, "fmi2GetFMUstate", "the FMUstate to reuse",
                         NULL))
            return fmi2Error;
    } else {
        buf = (unsigned char *)inst->allocate(1, snapshot_size(inst));
        if (buf == NULL) {
            glue_logf(inst, FP_ERROR, FP_LOG_ERROR, "fmi2GetFMUstate: out of memory");
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
    if (FMUstate == NULL) return glue_null_argument(inst, "fmi2FreeFMUstate", "FMUstate");
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
    if (size == NULL) return glue_null_argument(inst, "fmi2SerializedFMUstateSize", "size");
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
        return glue_null_argument(inst, "fmi2SerializeFMUstate", "serializedState");
    if (size < snapshot_size(inst)) {
        glue_logf(inst, FP_ERROR, FP_LOG_ERROR,
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
    if (FMUstate == NULL) return glue_null_argument(inst, "fmi2DeSerializeFMUstate", "FMUstate");
    if (serializedState == NULL)
        return glue_null_argument(inst, "fmi2DeSerializeFMUstate", "serializedState");
    if (size == 0) {
        glue_logf(inst, FP_ERROR, FP_LOG_ERROR,
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
            glue_logf(inst, FP_ERROR, FP_LOG_ERROR, "fmi2DeSerializeFMUstate: out of memory");
            return fmi2Error;
        }
    }
    memcpy(buf, serializedState, size);
    *FMUstate = buf;
    return fmi2OK;
}
