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
        /* the declared kind and range are part of the contract the XML states */
        h = fnv1a_str(h, fp_declared_type(v->dtype)->name);
        h = fnv1a_str(h, fp_declared_type(v->dtype)->unit);
        h = fp_fnv1a64(h, &v->range.lo, sizeof v->range.lo);
        h = fp_fnv1a64(h, &v->range.hi, sizeof v->range.hi);
        h = fp_fnv1a64(h, &v->range.flags, sizeof v->range.flags);
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

#define FP_TYPE_ROW(id, name, quantity, unit, nominal) {name, quantity, unit, nominal},
static const FpDeclaredType declared_types[FP_N_TYPES] = {FP_DECLARED_TYPES(FP_TYPE_ROW)};
#undef FP_TYPE_ROW

const FpDeclaredType *fp_declared_type(FpTypeId id) {
    return &declared_types[(unsigned)id < (unsigned)FP_N_TYPES ? id : FP_T_NONE];
}

FpTypeId fp_var_element_type(const FpVar *v, uint32_t k) {
    if (v->dtype == FP_T_WRENCH) return k % 6 < 3 ? FP_T_FORCE : FP_T_TORQUE;
    return v->dtype;
}

const FpVar *fp_var_find(const FpVar *vars, size_t n_vars, const char *name) {
    size_t i;
    for (i = 0; i < n_vars; i++)
        if (strcmp(vars[i].name, name) == 0) return &vars[i];
    return NULL;
}

/* A bound as a message shows it: the servo limits read "pi/2", not 1.5707963267948966. */
static const char *bound_text(char *buf, double x, int integer) {
    static const double quarter_pi = 0.78539816339744830962;
    double k = floor(x / quarter_pi + 0.5);
    if (integer) {
        snprintf(buf, FP_REAL_TEXT, "%.0f", x);
    } else if (x != 0.0 && fabs(k) <= 8.0 && fabs(x - k * quarter_pi) <= 1e-15 * fabs(x)) {
        /* k pi/4 in lowest terms */
        int n = (int)fabs(k), d = 4;
        while (d > 1 && n % 2 == 0) n /= 2, d /= 2;
        char num[16] = "", den[16] = "";
        if (n != 1) snprintf(num, sizeof num, "%d", n);
        if (d != 1) snprintf(den, sizeof den, "/%d", d);
        snprintf(buf, FP_REAL_TEXT, "%s%spi%s", k < 0 ? "-" : "", num, den);
    } else {
        fp_real_text(buf, x);
    }
    return buf;
}

const char *fp_range_text(const FpRange *r, int integer, char *buf, size_t size) {
    char lo[FP_REAL_TEXT], hi[FP_REAL_TEXT];
    int has_lo = (r->flags & FP_RANGE_LO) != 0, has_hi = (r->flags & FP_RANGE_HI) != 0;
    if (integer && has_lo && has_hi) {
        snprintf(buf, size, "%s..%s", bound_text(lo, r->lo, 1), bound_text(hi, r->hi, 1));
        return buf;
    }
    snprintf(buf, size, "%c%s, %s%c", has_lo && !(r->flags & FP_RANGE_LO_OPEN) ? '[' : '(',
             has_lo ? bound_text(lo, r->lo, integer) : "-inf",
             has_hi ? bound_text(hi, r->hi, integer) : "inf",
             has_hi && !(r->flags & FP_RANGE_HI_OPEN) ? ']' : ')');
    return buf;
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
