/*
 * The FMI 3.0 variable access of every fullpose FMU: fmi3Get/fmi3Set of Float64, Int32 and
 * Boolean by value reference into the model struct (FpModelInfo's variable table), the other
 * types and clocks refused with a message, as fmi2_values.c does for FMI 2.0.
 *
 * In FMI 3.0 each table row is ONE variable: a scalar, a vector or a row-major matrix, with
 * the row's value reference (the FMI 2.0 FMU numbers the elements vr, vr + 1, ...: those
 * element references are no FMI 3.0 value reference).  A get or set serializes the
 * variables' elements in the order of the value references, so nValues must be the sum of
 * their sizes.  Value reference 0 is the independent variable `time` (read only).
 * fmi3Boolean is a C bool (one byte); the model holds booleans as int32_t 0 or 1.
 *
 * Every variable of a call is checked (known, of the call's type, settable now, the sizes
 * adding up to nValues) before any value moves: a refused call changes nothing.
 */
#include <stdarg.h>
#include <stdio.h>
#include <string.h>

#include "fmi3_glue_internal.h"

/* fmi3Get*: from Initialization Mode on, and in Error for diagnosis */
#define S_READABLE \
    (S_INIT | S_STEP_COMPLETE | S_STEP_FAILED | S_TERMINATED | S_ERROR | S_ME_RUNNING)
/* fmi3Set*: before and during initialization, in Step Mode (tunables and inputs), and in
 * Model Exchange's Event Mode (both) and Continuous-Time Mode (continuous inputs) */
#define S_WRITABLE (S_INSTANTIATED | S_INIT | S_STEP_COMPLETE | S_ME_RUNNING)

/* logCalls shows at most this many values of one get or set. */
#define CALL_VALUES 8

static const char *type_name(FpVarType type) {
    return type == FP_REAL ? "Float64" : type == FP_INTEGER ? "Int32" : "Boolean";
}

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

/* The row of value reference r, NULL for time or an unknown reference. */
static const FpVar *row_of(const Fmi3Instance *inst, fmi3ValueReference r) {
    if (r >= inst->n_vr || inst->vr_map[r] < 0) return NULL;
    return &inst->info->vars[inst->vr_map[r]];
}

/* The number of values of value reference r (time: 1). */
static size_t size_of(const Fmi3Instance *inst, fmi3ValueReference r) {
    const FpVar *v = row_of(inst, r);
    return v == NULL ? 1u : fp_var_count(v);
}

/* The arguments of a get or set, "fmi3SetFloat64(nvr = 2, nValues = 4: mass (vr 2) = 1.5,
 * pos0 (vr 120) = [0, 0, -1])", at most CALL_VALUES values.  A get logs what it returned
 * (values NULL when the call failed: only the references are listed). */
static void log_values(Fmi3Instance *inst, const char *fn, const fmi3ValueReference vr[],
                       size_t nvr, size_t n_values, const void *values, FpVarType type) {
    Text t;
    size_t i, shown = 0, at = 0;
    if (!g3_calls_on(inst)) return;
    t.used = 0;
    t.text[0] = '\0';
    text_add(&t, "%s(nvr = %lu, nValues = %lu%s", fn, (unsigned long)nvr,
             (unsigned long)n_values, nvr > 0 && vr != NULL ? ":" : "");
    for (i = 0; i < nvr && vr != NULL && shown < CALL_VALUES; i++) {
        const FpVar *v = row_of(inst, vr[i]);
        size_t k, n = size_of(inst, vr[i]);
        text_add(&t, "%s %s (vr %u)", i > 0 ? "," : "",
                 v != NULL ? v->name : vr[i] == G3_TIME_VR ? "time" : "?", (unsigned)vr[i]);
        if (values != NULL && at + n <= n_values) {
            text_add(&t, " = %s", n > 1 ? "[" : "");
            for (k = 0; k < n && shown < CALL_VALUES; k++, shown++) {
                char value[FP_REAL_TEXT];
                size_t j = at + k;
                if (k > 0) text_add(&t, ", ");
                if (type == FP_REAL)
                    text_add(&t, "%s", fp_real_text(value, ((const fmi3Float64 *)values)[j]));
                else if (type == FP_INTEGER)
                    text_add(&t, "%d", (int)((const fmi3Int32 *)values)[j]);
                else
                    text_add(&t, "%s", ((const fmi3Boolean *)values)[j] ? "true" : "false");
            }
            text_add(&t, "%s%s", k < n ? ", ..." : "", n > 1 ? "]" : "");
        }
        at += n;
    }
    if (i < nvr && vr != NULL) text_add(&t, ", ... %lu more", (unsigned long)(nvr - i));
    text_add(&t, ")");
    g3_logf(inst, FP_OK, FP_LOG_CALLS, "%s", t.text);
}

static fmi3Status null_arrays(Fmi3Instance *inst, const char *fn, const void *vr, size_t nvr,
                              const void *values, size_t n_values) {
    char what[64];
    if (nvr > 0 && vr == NULL) {
        snprintf(what, sizeof what, "valueReferences (nValueReferences = %lu)",
                 (unsigned long)nvr);
        return g3_null_argument(inst, fn, what);
    }
    if (n_values > 0 && values == NULL) {
        snprintf(what, sizeof what, "values (nValues = %lu)", (unsigned long)n_values);
        return g3_null_argument(inst, fn, what);
    }
    return fmi3OK;
}

/* Why r is no variable: an element reference of the FMI 2.0 numbering says which. */
static void unknown_reference(Fmi3Instance *inst, fmi3ValueReference r, const char *fn) {
    size_t i;
    for (i = 0; i < inst->info->n_vars; i++) {
        const FpVar *v = &inst->info->vars[i];
        if (r > v->vr && r < v->vr + fp_var_count(v)) {
            g3_logf(inst, FP_ERROR, FP_LOG_ERROR,
                    "%s: unknown value reference %u: it numbers element %u of %s in the FMI 2.0 "
                    "FMU; in FMI 3.0 %s is one variable of %u values, value reference %u",
                    fn, (unsigned)r, (unsigned)(r - v->vr + 1), v->name, v->name,
                    (unsigned)fp_var_count(v), (unsigned)v->vr);
            return;
        }
    }
    if (g3_is_clock(r)) {
        g3_logf(inst, FP_ERROR, FP_LOG_ERROR,
                "%s: variable %s (vr %u) is of type Clock, the input clock of Scheduled "
                "Execution (fmi3ActivateModelPartition activates it)",
                fn, FP_SE_CLOCK_NAME, (unsigned)r);
        return;
    }
    g3_logf(inst, FP_ERROR, FP_LOG_ERROR, "%s: unknown value reference %u", fn, (unsigned)r);
}

static fmi3Status may_set(Fmi3Instance *inst, const FpVar *v, const char *fn) {
    const char *why = NULL;
    switch (v->kind) {
    case FP_OUTPUT: why = "it is an output"; break;
    case FP_PARAM_FIXED:
        if (!(inst->state & (S_INSTANTIATED | S_INIT)))
            why = "it is a fixed parameter and initialization has ended";
        break;
    case FP_PARAM_TUNABLE:
    case FP_INPUT:
        if (inst->state == S_CONTINUOUS_TIME &&
            (v->kind == FP_PARAM_TUNABLE || v->type != FP_REAL))
            why = "in Continuous-Time Mode only continuous inputs change (the others in Event "
                  "Mode)";
        else if (!(inst->state & S_WRITABLE))
            why = "the FMU is not initialized or stepping";
        break;
    case FP_STATE:
        why = "it is a continuous state (Model Exchange sets the states with "
              "fmi3SetContinuousStates)";
        break;
    case FP_DERIVATIVE: why = "it is a state derivative, computed"; break;
    case FP_LOCAL: why = "it is a local variable, computed"; break;
    }
    if (why == NULL) return fmi3OK;
    g3_logf(inst, FP_ERROR, FP_LOG_ERROR, "%s: cannot set %s (vr %u): %s", fn, v->name,
            (unsigned)v->vr, why);
    return fmi3Error;
}

/* Every variable of a get or set checked: known, of `type`, settable (`set`), and nValues
 * the sum of their sizes.  fmi3OK, or fmi3Error with the first problem logged. */
static fmi3Status check_call(Fmi3Instance *inst, const fmi3ValueReference vr[], size_t nvr,
                             size_t n_values, FpVarType type, int set, const char *fn) {
    size_t i, total = 0;
    for (i = 0; i < nvr; i++) {
        const FpVar *v = row_of(inst, vr[i]);
        if (vr[i] == G3_TIME_VR && type == FP_REAL) {
            if (set) {
                g3_logf(inst, FP_ERROR, FP_LOG_ERROR,
                        "%s: cannot set time (vr 0): it is the independent variable", fn);
                return fmi3Error;
            }
            total += 1;
            continue;
        }
        if (v == NULL) {
            unknown_reference(inst, vr[i], fn);
            return fmi3Error;
        }
        if (v->type != type) {
            g3_logf(inst, FP_ERROR, FP_LOG_ERROR, "%s: variable %s (vr %u) is of type %s", fn,
                    v->name, (unsigned)vr[i], type_name(v->type));
            return fmi3Error;
        }
        if (set && may_set(inst, v, fn) != fmi3OK) return fmi3Error;
        total += fp_var_count(v);
    }
    if (total != n_values) {
        Text t;
        t.used = 0;
        t.text[0] = '\0';
        for (i = 0; i < nvr && i < CALL_VALUES; i++) {
            const FpVar *v = row_of(inst, vr[i]);
            text_add(&t, "%s%s %lu", i > 0 ? ", " : "", v != NULL ? v->name : "time",
                     (unsigned long)size_of(inst, vr[i]));
        }
        if (nvr > i) text_add(&t, ", ...");
        g3_logf(inst, FP_ERROR, FP_LOG_ERROR,
                "%s: nValues = %lu, but the %lu variable(s) hold %lu value(s)%s%s%s", fn,
                (unsigned long)n_values, (unsigned long)nvr, (unsigned long)total,
                nvr > 0 ? " (" : "", t.text, nvr > 0 ? ")" : "");
        return fmi3Error;
    }
    return fmi3OK;
}

static void mark_changed(Fmi3Instance *inst, const FpVar *v) {
    if (inst->state & (S_INSTANTIATED | S_INIT)) inst->dirty = 1;
    else if (v->kind == FP_PARAM_TUNABLE) inst->tunables_dirty = 1;
    inst->me_stale = 1; /* (Model Exchange: outputs and derivatives follow the inputs) */
}

/* Scheduled Execution, Clock Activation Mode: "It is not allowed to call fmi3Get{VariableType}
 * functions after fmi3Set{VariableType} functions without an fmi3ActivateModelPartition call
 * in between" (FMI 3.0, the state Clock Activation Mode).  1 (the call refused, logged) if
 * this get would. */
static int set_before_get(Fmi3Instance *inst, const char *fn) {
    if (!inst->se_set_pending || inst->interface != G3_SCHEDULED_EXECUTION ||
        inst->state != S_STEP_COMPLETE)
        return 0;
    g3_logf(inst, FP_ERROR, FP_LOG_ERROR,
            "%s may not be called in Clock Activation Mode after an fmi3Set call without an "
            "fmi3ActivateModelPartition in between: the values set are the next sample's "
            "inputs, the values read its results",
            fn);
    return 1;
}

/* ------------------------------------------------------------------------ */
/* Float64, Int32, Boolean                                                  */

/* The get of one type: values[] filled variable after variable, element after element. */
static fmi3Status get_values(fmi3Instance c, const fmi3ValueReference vr[], size_t nvr,
                             void *values, size_t n_values, FpVarType type, const char *fn) {
    fmi3Status s;
    size_t i, at = 0;
    G3_CHECK(fn, S_READABLE);
    if (set_before_get(inst, fn)) return fmi3Error;
    if (null_arrays(inst, fn, vr, nvr, values, n_values) != fmi3OK) return fmi3Error;
    if (check_call(inst, vr, nvr, n_values, type, 0, fn) != fmi3OK) {
        log_values(inst, fn, vr, nvr, n_values, NULL, type);
        return fmi3Error;
    }
    s = g3_refresh(inst);
    if (s > fmi3Warning) {
        log_values(inst, fn, vr, nvr, n_values, NULL, type);
        return s;
    }
    for (i = 0; i < nvr; i++) {
        const FpVar *v = row_of(inst, vr[i]);
        uint32_t k, n;
        if (v == NULL) { /* time */
            ((fmi3Float64 *)values)[at++] = inst->time;
            continue;
        }
        n = fp_var_count(v);
        for (k = 0; k < n; k++, at++) {
            const void *p = g3_element(inst, v, k);
            if (type == FP_REAL) ((fmi3Float64 *)values)[at] = *(const double *)p;
            else if (type == FP_INTEGER) ((fmi3Int32 *)values)[at] = *(const int32_t *)p;
            else ((fmi3Boolean *)values)[at] = *(const int32_t *)p != 0;
        }
    }
    log_values(inst, fn, vr, nvr, n_values, values, type);
    return s;
}

static fmi3Status set_values(fmi3Instance c, const fmi3ValueReference vr[], size_t nvr,
                             const void *values, size_t n_values, FpVarType type,
                             const char *fn) {
    size_t i, at = 0;
    G3_CHECK(fn, S_WRITABLE);
    if (null_arrays(inst, fn, vr, nvr, values, n_values) != fmi3OK) return fmi3Error;
    log_values(inst, fn, vr, nvr, n_values, values, type);
    if (check_call(inst, vr, nvr, n_values, type, 1, fn) != fmi3OK) return fmi3Error;
    for (i = 0; i < nvr; i++) {
        const FpVar *v = row_of(inst, vr[i]);
        uint32_t k, n = fp_var_count(v);
        for (k = 0; k < n; k++, at++) {
            void *p = g3_element(inst, v, k);
            if (type == FP_REAL) *(double *)p = ((const fmi3Float64 *)values)[at];
            else if (type == FP_INTEGER) *(int32_t *)p = ((const fmi3Int32 *)values)[at];
            else *(int32_t *)p = ((const fmi3Boolean *)values)[at] ? 1 : 0;
        }
        mark_changed(inst, v);
    }
    if (inst->interface == G3_SCHEDULED_EXECUTION && inst->state == S_STEP_COMPLETE && nvr > 0)
        inst->se_set_pending = 1;
    return fmi3OK;
}

fmi3Status fmi3GetFloat64(fmi3Instance c, const fmi3ValueReference valueReferences[],
                          size_t nValueReferences, fmi3Float64 values[], size_t nValues) {
    return get_values(c, valueReferences, nValueReferences, values, nValues, FP_REAL,
                      "fmi3GetFloat64");
}

fmi3Status fmi3GetInt32(fmi3Instance c, const fmi3ValueReference valueReferences[],
                        size_t nValueReferences, fmi3Int32 values[], size_t nValues) {
    return get_values(c, valueReferences, nValueReferences, values, nValues, FP_INTEGER,
                      "fmi3GetInt32");
}

fmi3Status fmi3GetBoolean(fmi3Instance c, const fmi3ValueReference valueReferences[],
                          size_t nValueReferences, fmi3Boolean values[], size_t nValues) {
    return get_values(c, valueReferences, nValueReferences, values, nValues, FP_BOOLEAN,
                      "fmi3GetBoolean");
}

fmi3Status fmi3SetFloat64(fmi3Instance c, const fmi3ValueReference valueReferences[],
                          size_t nValueReferences, const fmi3Float64 values[], size_t nValues) {
    return set_values(c, valueReferences, nValueReferences, values, nValues, FP_REAL,
                      "fmi3SetFloat64");
}

fmi3Status fmi3SetInt32(fmi3Instance c, const fmi3ValueReference valueReferences[],
                        size_t nValueReferences, const fmi3Int32 values[], size_t nValues) {
    return set_values(c, valueReferences, nValueReferences, values, nValues, FP_INTEGER,
                      "fmi3SetInt32");
}

fmi3Status fmi3SetBoolean(fmi3Instance c, const fmi3ValueReference valueReferences[],
                          size_t nValueReferences, const fmi3Boolean values[], size_t nValues) {
    return set_values(c, valueReferences, nValueReferences, values, nValues, FP_BOOLEAN,
                      "fmi3SetBoolean");
}

/* ------------------------------------------------------------------------ */
/* The types without variables: a call naming a variable is refused, naming what the
 * reference is (no call with nothing to do fails).                          */

static fmi3Status no_such_type(fmi3Instance c, const fmi3ValueReference vr[], size_t nvr,
                               const void *values, size_t n_values, int set, const char *fn,
                               const char *type) {
    const FpVar *v;
    G3_CHECK(fn, set ? S_WRITABLE : S_READABLE);
    G3_LOG_CALL(inst, "%s(nvr = %lu, nValues = %lu)", fn, (unsigned long)nvr,
                (unsigned long)n_values);
    if (null_arrays(inst, fn, vr, nvr, values, n_values) != fmi3OK) return fmi3Error;
    if (nvr == 0 && n_values == 0) return fmi3OK;
    if (nvr == 0) {
        g3_logf(inst, FP_ERROR, FP_LOG_ERROR, "%s: nValues = %lu, but no variable is named", fn,
                (unsigned long)n_values);
        return fmi3Error;
    }
    v = row_of(inst, vr[0]);
    if (v != NULL || vr[0] == G3_TIME_VR)
        g3_logf(inst, FP_ERROR, FP_LOG_ERROR,
                "%s: variable %s (vr %u) is of type %s; the FMU has no %s variables", fn,
                v != NULL ? v->name : "time", (unsigned)vr[0],
                v != NULL ? type_name(v->type) : "Float64", type);
    else
        unknown_reference(inst, vr[0], fn);
    return fmi3Error;
}

#define G3_NO_TYPE_GET(Name, CType)                                                          \
    fmi3Status fmi3Get##Name(fmi3Instance c, const fmi3ValueReference valueReferences[],     \
                             size_t nValueReferences, CType values[], size_t nValues) {      \
        return no_such_type(c, valueReferences, nValueReferences, values, nValues, 0,         \
                            "fmi3Get" #Name, #Name);                                         \
    }
#define G3_NO_TYPE_SET(Name, CType)                                                          \
    fmi3Status fmi3Set##Name(fmi3Instance c, const fmi3ValueReference valueReferences[],     \
                             size_t nValueReferences, const CType values[], size_t nValues) { \
        return no_such_type(c, valueReferences, nValueReferences, values, nValues, 1,         \
                            "fmi3Set" #Name, #Name);                                         \
    }

G3_NO_TYPE_GET(Float32, fmi3Float32)
G3_NO_TYPE_GET(Int8, fmi3Int8)
G3_NO_TYPE_GET(UInt8, fmi3UInt8)
G3_NO_TYPE_GET(Int16, fmi3Int16)
G3_NO_TYPE_GET(UInt16, fmi3UInt16)
G3_NO_TYPE_GET(UInt32, fmi3UInt32)
G3_NO_TYPE_GET(Int64, fmi3Int64)
G3_NO_TYPE_GET(UInt64, fmi3UInt64)
G3_NO_TYPE_GET(String, fmi3String)
G3_NO_TYPE_SET(Float32, fmi3Float32)
G3_NO_TYPE_SET(Int8, fmi3Int8)
G3_NO_TYPE_SET(UInt8, fmi3UInt8)
G3_NO_TYPE_SET(Int16, fmi3Int16)
G3_NO_TYPE_SET(UInt16, fmi3UInt16)
G3_NO_TYPE_SET(UInt32, fmi3UInt32)
G3_NO_TYPE_SET(Int64, fmi3Int64)
G3_NO_TYPE_SET(UInt64, fmi3UInt64)
G3_NO_TYPE_SET(String, fmi3String)

fmi3Status fmi3GetBinary(fmi3Instance c, const fmi3ValueReference valueReferences[],
                         size_t nValueReferences, size_t valueSizes[], fmi3Binary values[],
                         size_t nValues) {
    (void)valueSizes;
    return no_such_type(c, valueReferences, nValueReferences, values, nValues, 0,
                        "fmi3GetBinary", "Binary");
}

fmi3Status fmi3SetBinary(fmi3Instance c, const fmi3ValueReference valueReferences[],
                         size_t nValueReferences, const size_t valueSizes[],
                         const fmi3Binary values[], size_t nValues) {
    (void)valueSizes;
    return no_such_type(c, valueReferences, nValueReferences, values, nValues, 1,
                        "fmi3SetBinary", "Binary");
}

/* Clocks: a clock call has one value per reference (no nValues).  The input clock of
 * Scheduled Execution (fmi3_scheduled.h) is neither read nor set: fmi3ActivateModelPartition
 * activates it; fmi3GetClock reads output clocks and fmi3SetClock sets clocks in Event
 * Mode, of which the FMU has none. */
static fmi3Status clock_values(fmi3Instance c, const fmi3ValueReference vr[], size_t nvr,
                               const void *values, int set, const char *fn) {
    size_t i;
    if (G3_SE_PROVIDED && vr != NULL)
        for (i = 0; i < nvr; i++)
            if (g3_is_clock(vr[i])) {
                G3_CHECK(fn, set ? S_WRITABLE : S_READABLE);
                G3_LOG_CALL(inst, "%s(nvr = %lu)", fn, (unsigned long)nvr);
                g3_logf(inst, FP_ERROR, FP_LOG_ERROR,
                        "%s: %s (vr %u) is the input clock of Scheduled Execution: "
                        "fmi3ActivateModelPartition activates it; the FMU has no %s",
                        fn, FP_SE_CLOCK_NAME, (unsigned)vr[i],
                        set ? "Event Mode to set a clock in" : "output clock to read");
                return fmi3Error;
            }
    return no_such_type(c, vr, nvr, values, nvr, set, fn, "Clock");
}

fmi3Status fmi3GetClock(fmi3Instance c, const fmi3ValueReference valueReferences[],
                        size_t nValueReferences, fmi3Clock values[]) {
    return clock_values(c, valueReferences, nValueReferences, values, 0, "fmi3GetClock");
}

fmi3Status fmi3SetClock(fmi3Instance c, const fmi3ValueReference valueReferences[],
                        size_t nValueReferences, const fmi3Clock values[]) {
    return clock_values(c, valueReferences, nValueReferences, values, 1, "fmi3SetClock");
}
