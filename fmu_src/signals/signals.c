/*
 * ScenarioSignals: the reference and disturbance signals of a scenario, played from a table.
 *
 * At every communication point t the outputs hold the table's row for t: the last row whose
 * time is at most t (within a tolerance, below), the first row before it.  Between rows they
 * hold (a zero-order hold), as a fixed-step master samples a scenario: a table sampled on the
 * master's grid gives at each communication point exactly the values of its row, to the bit.
 *
 * The tolerance: FP_STEP_TOL of the table's smallest row spacing plus FP_TIME_TOL of |t|
 * (fp_model.h), so that a communication point meant to fall on a row's time takes that row
 * although the importer's summed time (t += h) lies a hair below it.
 */
#include "signals.h"

#include <math.h>
#include <stddef.h>
#include <string.h>

#include "fp_table.h"
#include "signals_vars.h"

#define ELEM_SIZE_REAL sizeof(double)
#define ELEM_SIZE_INTEGER sizeof(int32_t)
#define SIGNALS_CHECK(name, vr, type, kind, rows, cols, dtype, range, desc)                     \
    FP_STATIC_ASSERT(sizeof(((SignalsModel *)0)->name) == (rows) * (cols) * ELEM_SIZE_##type,   \
                     name##_size);                                                              \
    FP_STATIC_ASSERT((FP_##type == FP_REAL) == (FP_T_##dtype != FP_T_NONE), name##_dtype);
SIGNALS_VARIABLES(SIGNALS_CHECK)

#define SIGNALS_ROW(name, vr, type, kind, rows, cols, dtype, range, desc)                       \
    {#name, vr, FP_##type, FP_##kind, rows, cols, offsetof(SignalsModel, name), FP_T_##dtype,    \
     range, desc},
static const FpVar signals_vars[] = {SIGNALS_VARIABLES(SIGNALS_ROW)};
#define N_SIGNALS_VARS (sizeof signals_vars / sizeof signals_vars[0])

/* The Real outputs' element count is SIGNALS_N_OUTPUTS */
#define SIGNALS_COUNT(name, vr, type, kind, rows, cols, dtype, range, desc)                     \
    +(FP_##type == FP_REAL ? (rows) * (cols) : 0)
FP_STATIC_ASSERT((0 SIGNALS_VARIABLES(SIGNALS_COUNT)) == SIGNALS_N_OUTPUTS, n_outputs);

static void signals_set_defaults(void *model) {
    SignalsModel *m = (SignalsModel *)model;
    int i;
    memset(m, 0, sizeof *m);
    for (i = 0; i < 8; i++) m->rotor_health[i] = m->efficiency[i] = 1.0;
    for (i = 0; i < SIGNALS_N_OUTPUTS; i++) m->column[i] = -1;
}

static const FpTable *table_of(const FpLogger *logger) {
    if (logger->table == NULL)
        fp_log(logger, FP_ERROR, FP_LOG_ERROR,
               "ScenarioSignals has no table (resources/" SIGNALS_RESOURCE " was not read)");
    return logger->table;
}

/* Calls fn(model, var, element k of it, its index e among the Real output elements). */
#define FOR_EACH_OUTPUT(v, k, e)                                                                \
    for (v = signals_vars, e = 0; v < signals_vars + N_SIGNALS_VARS; v++)                        \
        if (v->type == FP_REAL)                                                                  \
            for (k = 0; k < fp_var_count(v); k++, e++)

static double *output_element(SignalsModel *m, const FpVar *v, uint32_t k) {
    return (double *)((char *)m + v->offset) + k;
}

/* The outputs from the row for time t. */
static void play_row(SignalsModel *m, const FpTable *t, double time) {
    double tol = FP_STEP_TOL * t->min_spacing + FP_TIME_TOL * fabs(time);
    uint32_t r = fp_table_row_at(t, time, tol), k;
    const double *row = fp_table_row(t, r);
    const FpVar *v;
    int e;
    FOR_EACH_OUTPUT(v, k, e) {
        if (m->column[e] >= 0) *output_element(m, v, k) = row[1 + m->column[e]];
    }
    m->row = (int32_t)r + 1;
}

/* Every table column is an output element, and every value in its range. */
static FpStatus map_table_columns(SignalsModel *m, const FpTable *t, const FpLogger *logger) {
    char name[64];
    const FpVar *v;
    uint32_t k, c, r;
    int e;
    int used[FP_TABLE_MAX_COLUMNS];
    for (c = 0; c < t->cols; c++) used[c] = 0;
    FOR_EACH_OUTPUT(v, k, e) {
        fp_var_element_name(v, k, name, sizeof name);
        m->column[e] = fp_table_column(t, name);
        if (m->column[e] < 0) continue;
        used[m->column[e]] = 1;
        for (r = 0; r < t->rows; r++) {
            double x = fp_table_row(t, r)[1 + m->column[e]];
            if (!fp_range_contains(&v->range, x)) {
                char buf[48], xs[FP_REAL_TEXT];
                fp_log(logger, FP_ERROR, FP_LOG_ERROR,
                       "table column %s, row %lu (t = %.17g s): %s is outside %s", name,
                       (unsigned long)r + 1, fp_table_row(t, r)[0], fp_real_text(xs, x),
                       fp_range_text(&v->range, 0, buf, sizeof buf));
                return FP_ERROR;
            }
        }
    }
    for (c = 0; c < t->cols; c++) {
        if (!used[c]) {
            fp_log(logger, FP_ERROR, FP_LOG_ERROR,
                   "table column %s is no output of ScenarioSignals (its outputs are the "
                   "controller's references and the plant's disturbances, e.g. pos_ref[1], "
                   "f_d[3], efficiency[8])", t->names[c]);
            return FP_ERROR;
        }
    }
    return FP_OK;
}

static FpStatus signals_initialize(void *model, double t0, const FpLogger *logger) {
    SignalsModel *m = (SignalsModel *)model;
    const FpTable *t = table_of(logger);
    if (t == NULL || map_table_columns(m, t, logger) != FP_OK) return FP_ERROR;
    play_row(m, t, t0);
    return FP_OK;
}

static FpStatus signals_step(void *model, double time, double h, const FpLogger *logger) {
    SignalsModel *m = (SignalsModel *)model;
    const FpTable *t = table_of(logger);
    if (t == NULL) return FP_ERROR;
    play_row(m, t, time + h);
    return FP_OK;
}

static FpStatus signals_check_restored(const void *model, int initialized,
                                       const FpLogger *logger) {
    const SignalsModel *m = (const SignalsModel *)model;
    const FpTable *t = table_of(logger);
    int e;
    if (t == NULL) return FP_ERROR;
    for (e = 0; e < SIGNALS_N_OUTPUTS; e++) {
        if (m->column[e] < -1 || m->column[e] >= (int32_t)t->cols) {
            fp_log(logger, FP_ERROR, FP_LOG_ERROR,
                   "restored state: output element %d plays column %ld, outside the table's "
                   "%lu columns", e + 1, (long)m->column[e], (unsigned long)t->cols);
            return FP_ERROR;
        }
    }
    (void)initialized;
    return FP_OK;
}

static const FpModelInfo signals_info = {
    "ScenarioSignals",
    "A scenario's reference and disturbance signals, played from the table in its resources/ "
    "(" SIGNALS_RESOURCE "), on outputs named like the controller's and the plant's inputs "
    "they feed; held between rows",
    sizeof(SignalsModel),
    signals_vars,
    N_SIGNALS_VARS,
    0.002,
    10.0,
    signals_set_defaults,
    signals_initialize,
    signals_step,
    NULL,
    signals_check_restored,
    offsetof(SignalsModel, initialized),
    SIGNALS_RESOURCE,
    NULL, /* co-simulation only: a table played on the communication points */
};

const FpModelInfo *signals_model_info(void) { return &signals_info; }
