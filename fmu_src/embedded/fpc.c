/*
 * fpc (fpc.h): the controller model behind a firmware's API.  The calls are the FMI glue's
 * calls of the model (FpModelInfo: set_defaults, initialize, step, tunables_changed), in the
 * order the glue makes them, so a sample here is the FMU's sample; what the glue adds for an
 * importer (the call-sequence state machine, FMU states, logging categories) is left out.
 */
#include "fpc.h"

#include <math.h>
#include <string.h>

static void forward(void *env, FpStatus status, FpLogCategory category, const char *message) {
    const FpcController *c = (const FpcController *)env;
    (void)category;
    if (c->log != NULL) c->log(c->log_env, status, message);
}

static void set_marker(FpcController *c, int32_t on) {
    const FpModelInfo *info = controller_model_info();
    memcpy((char *)&c->model + info->initialized_offset, &on, sizeof on);
}

FpStatus fpc_defaults(FpcController *c, FpcLogFn log, void *log_env) {
    if (c == NULL) return FP_ERROR;
    memset(c, 0, sizeof *c);
    controller_model_info()->set_defaults(&c->model);
    c->log = log;
    c->log_env = log_env;
    c->logger.log = forward;
    c->logger.env = c;
    c->logger.table = NULL;
    set_marker(c, 0);
    return FP_OK;
}

/* The table row holding value reference vr, and the element's index in it, or NULL. */
static const FpVar *row_of(uint32_t vr, uint32_t *k) {
    const FpModelInfo *info = controller_model_info();
    size_t i;
    for (i = 0; i < info->n_vars; i++) {
        const FpVar *v = &info->vars[i];
        uint32_t n = (uint32_t)v->rows * v->cols;
        if (vr >= v->vr && vr - v->vr < n) {
            *k = vr - v->vr;
            return v;
        }
    }
    return NULL;
}

static char *element_address(FpcController *c, const FpVar *v, uint32_t k) {
    size_t size = v->type == FP_REAL ? sizeof(double) : sizeof(int32_t);
    return (char *)&c->model + v->offset + (size_t)k * size;
}

/* FP_OK when element k of v may be set now with a value of type `real`, else said why. */
static FpStatus may_set(FpcController *c, const FpVar *v, uint32_t k, int real) {
    const char *why = NULL;
    if ((v->type == FP_REAL) != (real != 0))
        why = real ? "it is an Integer or Boolean (fpc_set_ints)" : "it is a Real (fpc_set_reals)";
    else if (v->kind == FP_PARAM_FIXED && c->started)
        why = "it is a fixed parameter and the controller has started";
    else if (v->kind != FP_PARAM_FIXED && v->kind != FP_PARAM_TUNABLE && v->kind != FP_INPUT)
        why = "it is computed by the controller";
    if (why == NULL) return FP_OK;
    fp_log(&c->logger, FP_ERROR, FP_LOG_ERROR, "cannot set %s[%u]: %s", v->name,
           (unsigned)(k + 1), why);
    return FP_ERROR;
}

static void note_change(FpcController *c, const FpVar *v) {
    if (c->started && v->kind == FP_PARAM_TUNABLE) c->changed = 1;
}

static FpStatus set_vr(FpcController *c, const uint32_t *vr, size_t n, const void *values,
                       int real) {
    size_t i;
    uint32_t k;
    const FpVar *v;
    if (c == NULL || (n > 0 && (vr == NULL || values == NULL))) return FP_ERROR;
    for (i = 0; i < n; i++) { /* everything checked before anything moves */
        v = row_of(vr[i], &k);
        if (v == NULL) {
            fp_log(&c->logger, FP_ERROR, FP_LOG_ERROR, "no variable has value reference %lu",
                   (unsigned long)vr[i]);
            return FP_ERROR;
        }
        if (may_set(c, v, k, real) != FP_OK) return FP_ERROR;
        if (!real && v->type == FP_BOOLEAN) {
            int32_t b = ((const int32_t *)values)[i];
            if (b != 0 && b != 1) {
                fp_log(&c->logger, FP_ERROR, FP_LOG_ERROR,
                       "cannot set %s[%u] = %ld: a Boolean is 0 or 1", v->name,
                       (unsigned)(k + 1), (long)b);
                return FP_ERROR;
            }
        }
    }
    for (i = 0; i < n; i++) {
        v = row_of(vr[i], &k);
        if (real) memcpy(element_address(c, v, k), (const double *)values + i, sizeof(double));
        else memcpy(element_address(c, v, k), (const int32_t *)values + i, sizeof(int32_t));
        note_change(c, v);
    }
    return FP_OK;
}

FpStatus fpc_set_reals_vr(FpcController *c, const uint32_t *vr, size_t n, const double *values) {
    return set_vr(c, vr, n, values, 1);
}

FpStatus fpc_set_ints_vr(FpcController *c, const uint32_t *vr, size_t n, const int32_t *values) {
    return set_vr(c, vr, n, values, 0);
}

static FpStatus get_vr(const FpcController *c, const uint32_t *vr, size_t n, void *values,
                       int real) {
    size_t i;
    uint32_t k;
    if (c == NULL || (n > 0 && (vr == NULL || values == NULL))) return FP_ERROR;
    for (i = 0; i < n; i++) {
        const FpVar *v = row_of(vr[i], &k);
        const char *at;
        if (v == NULL || (v->type == FP_REAL) != (real != 0)) {
            fp_log(&c->logger, FP_ERROR, FP_LOG_ERROR,
                   v == NULL ? "no variable has value reference %lu"
                             : "value reference %lu is not of the type asked for",
                   (unsigned long)vr[i]);
            return FP_ERROR;
        }
        at = (const char *)&c->model + v->offset;
        if (real) memcpy((double *)values + i, at + (size_t)k * sizeof(double), sizeof(double));
        else memcpy((int32_t *)values + i, at + (size_t)k * sizeof(int32_t), sizeof(int32_t));
    }
    return FP_OK;
}

FpStatus fpc_get_reals_vr(const FpcController *c, const uint32_t *vr, size_t n, double *values) {
    return get_vr(c, vr, n, values, 1);
}

FpStatus fpc_get_ints_vr(const FpcController *c, const uint32_t *vr, size_t n, int32_t *values) {
    return get_vr(c, vr, n, values, 0);
}

FpStatus fpc_find(const FpcController *c, const char *name, uint32_t *vr, uint32_t *count,
                  FpVarType *type, FpVarKind *kind) {
    const FpModelInfo *info = controller_model_info();
    const FpVar *v;
    if (c == NULL || name == NULL) return FP_ERROR;
    v = fp_var_find(info->vars, info->n_vars, name);
    if (v == NULL) {
        fp_log(&c->logger, FP_ERROR, FP_LOG_ERROR, "the controller has no variable %s", name);
        return FP_ERROR;
    }
    if (vr != NULL) *vr = v->vr;
    if (count != NULL) *count = (uint32_t)v->rows * v->cols;
    if (type != NULL) *type = v->type;
    if (kind != NULL) *kind = v->kind;
    return FP_OK;
}

/* Set n elements of a variable by name, through the value-reference path (its checks). */
static FpStatus set_named(FpcController *c, const char *name, const void *values, size_t n,
                          int real) {
    uint32_t vr, count, i;
    uint32_t refs[FP_POLYTOPE_MAX_FACETS * 3]; /* the largest variable (poly_A) */
    FpStatus s = fpc_find(c, name, &vr, &count, NULL, NULL);
    if (s != FP_OK) return s;
    if (n > count || n > sizeof refs / sizeof refs[0]) {
        fp_log(&c->logger, FP_ERROR, FP_LOG_ERROR, "%s has %lu elements, %lu given", name,
               (unsigned long)count, (unsigned long)n);
        return FP_ERROR;
    }
    for (i = 0; i < (uint32_t)n; i++) refs[i] = vr + i;
    return set_vr(c, refs, n, values, real);
}

FpStatus fpc_set_reals(FpcController *c, const char *name, const double *values, size_t n) {
    return set_named(c, name, values, n, 1);
}

FpStatus fpc_set_ints(FpcController *c, const char *name, const int32_t *values, size_t n) {
    return set_named(c, name, values, n, 0);
}

static void copy_inputs(ControllerModel *m, const FpcInputs *in) {
    memcpy(m->pos_ref, in->pos_ref, sizeof m->pos_ref);
    memcpy(m->euler_ref, in->euler_ref, sizeof m->euler_ref);
    memcpy(m->vel_ref, in->vel_ref, sizeof m->vel_ref);
    memcpy(m->acc_ref, in->acc_ref, sizeof m->acc_ref);
    memcpy(m->euler_rate_ref, in->euler_rate_ref, sizeof m->euler_rate_ref);
    memcpy(m->rotor_health, in->rotor_health, sizeof m->rotor_health);
    memcpy(m->pos, in->pos, sizeof m->pos);
    memcpy(m->vel, in->vel, sizeof m->vel);
    memcpy(m->acc, in->acc, sizeof m->acc);
    memcpy(m->euler, in->euler, sizeof m->euler);
    memcpy(m->rate, in->rate, sizeof m->rate);
    memcpy(m->omega, in->omega, sizeof m->omega);
    memcpy(m->alpha, in->alpha, sizeof m->alpha);
    memcpy(m->beta, in->beta, sizeof m->beta);
    m->pose_age = in->pose_age;
    m->armed = in->armed != 0;
}

void fpc_outputs(const FpcController *c, FpcOutputs *out) {
    const ControllerModel *m = &c->model;
    memcpy(out->omega_cmd, m->omega_cmd, sizeof out->omega_cmd);
    memcpy(out->alpha_cmd, m->alpha_cmd, sizeof out->alpha_cmd);
    memcpy(out->beta_cmd, m->beta_cmd, sizeof out->beta_cmd);
    memcpy(out->mu_c, m->mu_c, sizeof out->mu_c);
    memcpy(out->f_b_ref, m->f_b_ref, sizeof out->f_b_ref);
    out->feasible = m->feasible;
    out->guid_status = m->guid_status;
    out->alloc_status = m->alloc_status;
    out->rotors_lost = m->rotors_lost;
    out->landed = m->landed;
    out->idle = m->idle;
}

FpStatus fpc_start(FpcController *c, double t0, const FpcInputs *in) {
    const FpModelInfo *info = controller_model_info();
    FpStatus s;
    if (c == NULL) return FP_ERROR;
    if (!isfinite(t0)) {
        fp_log(&c->logger, FP_ERROR, FP_LOG_ERROR, "start time %g is not finite", t0);
        return FP_ERROR;
    }
    if (c->started) {
        fp_log(&c->logger, FP_ERROR, FP_LOG_ERROR,
               "the controller has started: fpc_defaults first to start again");
        return FP_ERROR;
    }
    if (in != NULL) copy_inputs(&c->model, in);
    s = info->initialize(&c->model, t0, &c->logger);
    if (s == FP_ERROR || s == FP_DISCARD) return FP_ERROR;
    set_marker(c, 1);
    c->started = 1;
    c->changed = 0;
    return s;
}

FpStatus fpc_step(FpcController *c, double t, const FpcInputs *in, FpcOutputs *out) {
    const FpModelInfo *info = controller_model_info();
    ControllerModel *m;
    double due, tol;
    FpStatus s;
    if (c == NULL) return FP_ERROR;
    m = &c->model;
    if (!c->started) {
        fp_log(&c->logger, FP_ERROR, FP_LOG_ERROR, "fpc_step before fpc_start");
        return FP_ERROR;
    }
    due = m->grid_t0 + (double)m->samples_run * m->Ts;
    tol = FP_STEP_TOL * m->Ts + FP_TIME_TOL * (fabs(t) + fabs(m->grid_t0));
    if (!(fabs(t - due) <= tol)) {
        fp_log(&c->logger, FP_ERROR, FP_LOG_ERROR,
               "sample at t = %.12g s: the sample due is at %.12g s (t0 + k Ts)", t, due);
        return FP_ERROR;
    }
    if (c->changed && info->tunables_changed != NULL) {
        s = info->tunables_changed(m, &c->logger);
        if (s == FP_ERROR || s == FP_DISCARD) return FP_ERROR;
    }
    c->changed = 0;
    if (in != NULL) copy_inputs(m, in);
    s = info->step(m, t, m->Ts, &c->logger);
    if (s == FP_ERROR || s == FP_DISCARD) return FP_ERROR;
    if (out != NULL) fpc_outputs(c, out);
    return s;
}
