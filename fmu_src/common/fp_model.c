#include "fp_model.h"

#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

const char *fp_real_text(char *buf, double x) {
    int digits;
    for (digits = 15; digits < 17; digits++) {
        snprintf(buf, FP_REAL_TEXT, "%.*g", digits, x);
        if (strtod(buf, NULL) == x) return buf;
    }
    snprintf(buf, FP_REAL_TEXT, "%.17g", x);
    return buf;
}

void fp_log(const FpLogger *logger, FpStatus status, FpLogCategory category, const char *fmt, ...) {
    char message[512];
    va_list args;
    if (logger == NULL || logger->log == NULL) return;
    va_start(args, fmt);
    vsnprintf(message, sizeof message, fmt, args);
    va_end(args);
    logger->log(logger->env, status, category, message);
}

double fp_steps_to_cover(double span, double step, double tol) {
    double n;
    if (!(span - tol > 0.0)) return 0.0;
    n = ceil((span - tol) / step);
    return n < 1.0 ? 1.0 : n; /* a span far below step may underflow the ratio to 0 */
}

FpStatus fp_check_step_work(double h, double n, double cap, const char *what,
                            const FpLogger *logger) {
    if (!(h > 0.0) || !isfinite(h)) {
        fp_log(logger, FP_ERROR, FP_LOG_ERROR,
               "communication step %g s must be positive and finite", h);
        return FP_ERROR;
    }
    if (!(n <= cap)) {
        fp_log(logger, FP_ERROR, FP_LOG_ERROR,
               "communication step %.12g s would take %.0f %s (limit %.0f)", h, n, what, cap);
        return FP_ERROR;
    }
    return FP_OK;
}

uint64_t fp_fnv1a64(uint64_t h, const void *data, size_t n) {
    const unsigned char *p = (const unsigned char *)data;
    size_t i;
    for (i = 0; i < n; i++) {
        h ^= p[i];
        h *= 1099511628211ULL;
    }
    return h;
}

static uint64_t fnv1a_str(uint64_t h, const char *s) {
    return fp_fnv1a64(h, s, strlen(s) + 1);
}

static uint64_t hash_model(const FpModelInfo *info, uint64_t seed) {
    uint64_t h = fnv1a_str(seed, info->model_name);
    uint64_t layout = (uint64_t)info->model_size;
    size_t i;
    h = fp_fnv1a64(h, &layout, sizeof layout); /* a state saved by another build must not fit */
    for (i = 0; i < info->n_vars; i++) {
        const FpVar *v = &info->vars[i];
        uint32_t fields[6];
        fields[0] = v->vr;
        fields[1] = (uint32_t)v->type;
        fields[2] = (uint32_t)v->kind;
        fields[3] = v->rows;
        fields[4] = v->cols;
        fields[5] = (uint32_t)v->offset;
        h = fnv1a_str(h, v->name);
        h = fp_fnv1a64(h, fields, sizeof fields);
        h = fnv1a_str(h, v->unit);
    }
    return h;
}

void fp_model_guid(const FpModelInfo *info, char buf[40]) {
    uint64_t a = hash_model(info, FP_FNV1A64_BASIS);
    uint64_t b = hash_model(info, 0x9e3779b97f4a7c15ULL);
    snprintf(buf, 40, "{%08llx-%04llx-%04llx-%04llx-%012llx}", (unsigned long long)(a >> 32),
             (unsigned long long)((a >> 16) & 0xffffULL), (unsigned long long)(a & 0xffffULL),
             (unsigned long long)(b >> 48), (unsigned long long)(b & 0xffffffffffffULL));
}

int fp_var_element_name(const FpVar *v, uint32_t k, char *buf, size_t size) {
    int n;
    if (v->rows == 1 && v->cols == 1) {
        n = snprintf(buf, size, "%s", v->name);
    } else if (v->cols == 1) {
        n = snprintf(buf, size, "%s[%u]", v->name, (unsigned)(k + 1));
    } else {
        n = snprintf(buf, size, "%s[%u,%u]", v->name, (unsigned)(k / v->cols + 1),
                     (unsigned)(k % v->cols + 1));
    }
    return (n < 0 || (size_t)n >= size) ? -1 : 0;
}

static const char *const category_names[FP_LOG_N_CATEGORIES] = {
    "logEvents", "logStatusWarning", "logStatusError", "logCalls", "logModel"};
static const char *const category_descriptions[FP_LOG_N_CATEGORIES] = {
    "Lifecycle: instantiation, initialization, reset, termination",
    "Warnings: odd but usable parameters, saturations",
    "Errors: invalid parameters or inputs, illegal calls",
    "Every FMI call with its arguments (verbose)",
    "Model diagnostics (verbose)"};

const char *fp_log_category_name(int category) {
    return (category >= 0 && category < FP_LOG_N_CATEGORIES) ? category_names[category] : "";
}

const char *fp_log_category_description(int category) {
    return (category >= 0 && category < FP_LOG_N_CATEGORIES) ? category_descriptions[category]
                                                              : "";
}
