/*
 * The FMI 2.0 variable access of every fullpose FMU: fmi2Get/fmi2Set of Real, Integer,
 * Boolean and String, by value reference into the model struct (FpModelInfo's variable
 * table), with the checks of what may be set when and the logCalls lines of the values.
 * Part of the glue (fmi2_glue_internal.h); the lifecycle it checks against is fmi2_glue.c.
 */
#include <stdarg.h>
#include <stdio.h>

#include "fmi2_glue_internal.h"

/* fmi2Get{Real,Integer,Boolean,String}: from initialization on, and in Error for diagnosis */
#define S_READABLE \
    (S_INIT | S_STEP_COMPLETE | S_STEP_FAILED | S_TERMINATED | S_ERROR | S_ME_RUNNING)
/* fmi2SetReal: continuous inputs in Model Exchange's both modes too; fmi2SetInteger,
 * fmi2SetBoolean: discrete values change in Event Mode only */
#define S_SETTABLE_REAL (S_INSTANTIATED | S_INIT | S_STEP_COMPLETE | S_ME_RUNNING)
#define S_SETTABLE_DISCRETE (S_INSTANTIATED | S_INIT | S_STEP_COMPLETE | S_EVENT_MODE)

/* logCalls shows at most this many values of one get or set. */
#define CALL_VALUES 8

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
    glue_logf(inst, FP_OK, FP_LOG_CALLS, "%s", t.text);
}

static fmi2Status null_arrays(Instance *inst, const char *fn, const void *vr, size_t nvr,
                              const void *value) {
    char what[64];
    if (nvr == 0 || (vr != NULL && value != NULL)) return fmi2OK;
    snprintf(what, sizeof what, "%s (nvr = %lu)", vr == NULL ? "vr" : "value",
             (unsigned long)nvr);
    return glue_null_argument(inst, fn, what);
}

static const FpVar *lookup(Instance *inst, fmi2ValueReference vr, FpVarType type, uint32_t *k,
                           const char *fn) {
    static const char *const type_names[] = {"Real", "Integer", "Boolean"};
    const FpVar *v;
    if (vr >= inst->n_vr || inst->vr_map[vr] < 0) {
        glue_logf(inst, FP_ERROR, FP_LOG_ERROR, "%s: unknown value reference %u", fn, (unsigned)vr);
        return NULL;
    }
    v = &inst->info->vars[inst->vr_map[vr]];
    if (v->type != type) {
        glue_logf(inst, FP_ERROR, FP_LOG_ERROR, "%s: variable %s (vr %u) is of type %s", fn,
                  v->name, (unsigned)vr, type_names[v->type]);
        return NULL;
    }
    *k = vr - v->vr;
    return v;
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
        if (!(inst->state & (S_INSTANTIATED | S_INIT | S_STEP_COMPLETE | S_EVENT_MODE)))
            why = inst->state == S_CONTINUOUS_TIME
                      ? "a tunable parameter changes in Event Mode only"
                      : "the FMU is not initialized or stepping";
        break;
    case FP_INPUT:
        if (inst->state == S_CONTINUOUS_TIME && v->type != FP_REAL)
            why = "a discrete input changes in Event Mode only";
        else if (!(inst->state & (S_INSTANTIATED | S_INIT | S_STEP_COMPLETE | S_ME_RUNNING)))
            why = "the FMU is not initialized or stepping";
        break;
    case FP_STATE:
        why = "it is a continuous state (Model Exchange sets the states with "
              "fmi2SetContinuousStates)";
        break;
    case FP_DERIVATIVE: why = "it is a state derivative, computed"; break;
    case FP_LOCAL: why = "it is a local variable, computed"; break;
    }
    if (why == NULL) return fmi2OK;
    fp_var_element_name(v, k, name, sizeof name);
    glue_logf(inst, FP_ERROR, FP_LOG_ERROR, "%s: cannot set %s: %s", fn, name, why);
    return fmi2Error;
}

static void mark_changed(Instance *inst, const FpVar *v) {
    if (inst->state & (S_INSTANTIATED | S_INIT)) inst->dirty = 1;
    else if (v->kind == FP_PARAM_TUNABLE) inst->tunables_dirty = 1;
    inst->me_stale = 1; /* (Model Exchange: outputs and derivatives follow the inputs) */
}

/* ------------------------------------------------------------------------ */
/* Getting and setting values                                               */

fmi2Status fmi2GetReal(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                       fmi2Real value[]) {
    fmi2Status s;
    size_t i;
    CHECK("fmi2GetReal", S_READABLE);
    if (null_arrays(inst, "fmi2GetReal", vr, nvr, value) != fmi2OK) return fmi2Error;
    s = glue_refresh(inst);
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
    s = glue_refresh(inst);
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
    glue_logf(inst, FP_ERROR, FP_LOG_ERROR,
              "fmi2GetString: unknown value reference %u (no strings)", (unsigned)vr[0]);
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
    CHECK("fmi2SetReal", S_SETTABLE_REAL);
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
    CHECK(fn, S_SETTABLE_DISCRETE);
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
    CHECK("fmi2SetString", S_SETTABLE_DISCRETE);
    log_values(inst, "fmi2SetString", vr, nvr, NULL, FP_REAL, 0);
    if (null_arrays(inst, "fmi2SetString", vr, nvr, value) != fmi2OK) return fmi2Error;
    if (nvr == 0) return fmi2OK;
    glue_logf(inst, FP_ERROR, FP_LOG_ERROR,
              "fmi2SetString: unknown value reference %u (no strings)", (unsigned)vr[0]);
    return fmi2Error;
}
