/*
 * Writes modelDescription.xml for the model it is linked with, straight from
 * the model's variable table and default values, so the XML and the binary
 * cannot drift.  Run at build time:
 *
 *     mdgen [--fmi3 [--scheduled-execution] [--model-exchange]] OUTPUT.xml VERSION
 *           [--sources DIR FILE.c ...]
 *
 * With --fmi3, the FMI 3.0 modelDescription.xml of the same table (write_fmi3): each row one
 * variable (a scalar or an array with <Dimension>), value references the rows', the
 * independent variable time at value reference 0, the ModelStructure by value reference.
 * With --scheduled-execution besides, the FMU provides FMI 3.0 Scheduled Execution too
 * (common/fmi3_scheduled.h): a <ScheduledExecution> beside the <CoSimulation>, the input
 * clock of constant interval (the default of the model's internal step, Ts), and the inputs
 * and outputs in its model partition (variability "discrete", clocks="<clock>"; clocked
 * outputs are no InitialUnknowns).
 * With --model-exchange besides, the FMI 3.0 FMU provides Model Exchange too (common/
 * fmi3_me.c, for a model with FpModelInfo.me): a <ModelExchange> beside the <CoSimulation>.
 * The state, derivative and local rows are listed either way, with the <ModelStructure>'s
 * <ContinuousStateDerivative> and <EventIndicator> (as in FMI 2.0, below).
 * With --sources, the C files the FMU's binary is built from (the build's one list of them,
 * as laid out flat in the FMU's sources/ folder DIR) go into the FMI 2.0 <SourceFiles> of
 * <CoSimulation> and into DIR/buildDescription.xml (the FMI 2.0.4 / FMI 3.0 form).
 *
 * The output depends on nothing but the sources and VERSION, so builds are
 * reproducible: generationDateAndTime is SOURCE_DATE_EPOCH when the builder
 * sets it (reproducible-builds.org: the tool reads it itself), else the fixed
 * date of the release (RELEASE_DATE), never the clock.
 *
 * What importers read first comes first: the ScalarVariables are listed inputs, then outputs,
 * then parameters, each in table order (importers that look a connector up by name scan the
 * list from its start, past ~1,470 controller parameters before).  The order is the XML's
 * alone: value references are the table's, and the GUID hashes the table, not this listing
 * (fp_model.c).  <ModelStructure> names variables by their 1-based index in this order: the
 * <Outputs> without dependencies (no direct feedthrough at communication points), the
 * <InitialUnknowns> with the knowns that the model's table declares for each output
 * (PLANT_INITIAL_DEPENDENCIES, CONTROLLER_INITIAL_DEPENDENCIES, SIGNALS_INITIAL_DEPENDENCIES).
 *
 * A model with a Model Exchange side (FpModelInfo.me) gets, in FMI 2.0, a <ModelExchange>
 * beside the <CoSimulation> (one archive, both interfaces), numberOfEventIndicators, its state
 * and derivative rows (fp_model.h FP_STATE, FP_DERIVATIVE) listed last as local continuous
 * variables, each derivative naming its state (derivative="index"), the <Derivatives> in the
 * order of the state vector, the states and derivatives among the <InitialUnknowns>, and the
 * <Outputs> with the dependencies its table declares (PLANT_OUTPUT_DEPENDENCIES: in Model
 * Exchange the outputs are functions of the states, some of inputs).
 */
#include <errno.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "fmi3_scheduled.h"
#include "fp_model.h"

/* The InitialUnknowns declarations of both models' tables (only these macros are used here;
 * the tables themselves are the linked model's, through fp_model_info). */
#include "../controller/controller_vars.h"
#include "../plant/plant_vars.h"
#include "../signals/signals_vars.h"

/* Who the FMUs are from and under which terms (pyproject.toml: license MIT; a test compares
 * them).  RELEASE_DATE is the day of the release VERSION names: set it with the version. */
#define AUTHOR "The fullpose authors"
#define LICENSE "MIT"
#define RELEASE_DATE "2026-12-02T00:00:00Z"

typedef struct {
    const char *name;
    int kg, m, s, rad;
    const char *display[2];
    double factor[2];
} Unit;

/* Every unit a variable may use; an unknown unit fails the build. */
static const Unit units[] = {
    {"1", 0, 0, 0, 0, {NULL, NULL}, {0, 0}},
    {"s", 0, 0, 1, 0, {"ms", NULL}, {1e3, 0}},
    {"kg", 1, 0, 0, 0, {NULL, NULL}, {0, 0}},
    {"kg.m2", 1, 2, 0, 0, {NULL, NULL}, {0, 0}},
    {"m", 0, 1, 0, 0, {NULL, NULL}, {0, 0}},
    {"m/s", 0, 1, -1, 0, {NULL, NULL}, {0, 0}},
    {"m/s2", 0, 1, -2, 0, {NULL, NULL}, {0, 0}},
    {"m/s3", 0, 1, -3, 0, {NULL, NULL}, {0, 0}},
    {"rad", 0, 0, 0, 1, {"deg", NULL}, {57.295779513082323, 0}},
    {"rad/s", 0, 0, -1, 1, {"rpm", "deg/s"}, {9.5492965855137202, 57.295779513082323}},
    {"rad/s2", 0, 0, -2, 1, {"deg/s2", NULL}, {57.295779513082323, 0}},
    {"N", 1, 1, -2, 0, {NULL, NULL}, {0, 0}},
    {"N.m", 1, 2, -2, 0, {NULL, NULL}, {0, 0}},
    {"N/m", 1, 0, -2, 0, {NULL, NULL}, {0, 0}},
    {"N.s/m", 1, 0, -1, 0, {NULL, NULL}, {0, 0}},
    {"N.s2/rad2", 1, 1, 0, -2, {NULL, NULL}, {0, 0}},
    {"N.m.s2/rad2", 1, 2, 0, -2, {NULL, NULL}, {0, 0}},
    {"1/s", 0, 0, -1, 0, {NULL, NULL}, {0, 0}},
};
#define N_UNITS (sizeof units / sizeof units[0])

static void xml_text(FILE *f, const char *s) {
    for (; *s; s++) {
        switch (*s) {
        case '&': fputs("&amp;", f); break;
        case '<': fputs("&lt;", f); break;
        case '>': fputs("&gt;", f); break;
        case '"': fputs("&quot;", f); break;
        default: fputc(*s, f);
        }
    }
}

static const Unit *find_unit(const char *name) {
    size_t i;
    for (i = 0; i < N_UNITS; i++)
        if (strcmp(units[i].name, name) == 0) return &units[i];
    return NULL;
}

/* 1 if some element of the table has declared type t. */
static int type_used(const FpModelInfo *info, FpTypeId t) {
    size_t i;
    uint32_t k;
    for (i = 0; i < info->n_vars; i++)
        for (k = 0; k < fp_var_count(&info->vars[i]); k++)
            if (fp_var_element_type(&info->vars[i], k) == t) return 1;
    return 0;
}

static int unit_used(const FpModelInfo *info, const char *unit) {
    int t;
    for (t = 0; t < FP_N_TYPES; t++)
        if (strcmp(fp_declared_type((FpTypeId)t)->unit, unit) == 0 && type_used(info, (FpTypeId)t))
            return 1;
    return 0;
}

/* <UnitDefinitions>: the units in use, and `also` (NULL: none; FMI 3.0's time: "s"). */
static void write_units(FILE *f, const FpModelInfo *info, const char *also) {
    size_t i, j;
    fputs("  <UnitDefinitions>\n", f);
    for (i = 0; i < N_UNITS; i++) {
        const Unit *u = &units[i];
        if (!unit_used(info, u->name) && !(also != NULL && strcmp(also, u->name) == 0)) continue;
        fprintf(f, "    <Unit name=\"%s\">\n      <BaseUnit", u->name);
        if (u->kg) fprintf(f, " kg=\"%d\"", u->kg);
        if (u->m) fprintf(f, " m=\"%d\"", u->m);
        if (u->s) fprintf(f, " s=\"%d\"", u->s);
        if (u->rad) fprintf(f, " rad=\"%d\"", u->rad);
        fputs("/>\n", f);
        for (j = 0; j < 2; j++)
            if (u->display[j])
                fprintf(f, "      <DisplayUnit name=\"%s\" factor=\"%.17g\"/>\n", u->display[j],
                        u->factor[j]);
        fputs("    </Unit>\n", f);
    }
    fputs("  </UnitDefinitions>\n", f);
}

/* One <SimpleType> per declared type in use: what a variable of that kind is. */
static void write_types(FILE *f, const FpModelInfo *info) {
    int t;
    fputs("  <TypeDefinitions>\n", f);
    for (t = 0; t < FP_N_TYPES; t++) {
        const FpDeclaredType *d = fp_declared_type((FpTypeId)t);
        if (d->name[0] == '\0' || !type_used(info, (FpTypeId)t)) continue;
        fprintf(f, "    <SimpleType name=\"%s\">\n      <Real quantity=\"%s\" unit=\"%s\"", d->name,
                d->quantity, d->unit);
        if (d->nominal != 0.0) fprintf(f, " nominal=\"%.17g\"", d->nominal);
        fputs("/>\n    </SimpleType>\n", f);
    }
    fputs("  </TypeDefinitions>\n", f);
}

/* The inclusive bound FMI declares for a bound of a row: the bound itself when the check
 * accepts it, else (an open bound) the nearest value inside it, which the check accepts and
 * every value beyond it it refuses (a Real: the adjacent double, so (0, inf) has min
 * 4.9406564584124654e-324 and (-1, 1) max 0.99999999999999989; an Integer: the next integer). */
static double declared_bound(const FpVar *v, int upper) {
    double b = upper ? v->range.hi : v->range.lo;
    unsigned open = upper ? FP_RANGE_HI_OPEN : FP_RANGE_LO_OPEN;
    if (!(v->range.flags & open)) return b;
    if (v->type != FP_REAL) return upper ? b - 1.0 : b + 1.0;
    return nextafter(b, upper ? -INFINITY : INFINITY);
}

/* min/max of a row (FMI's are inclusive: declared_bound). */
static void write_range(FILE *f, const FpVar *v) {
    const char *format = v->type == FP_REAL ? "%s=\"%.17g\"" : "%s=\"%.0f\"";
    if (v->type == FP_BOOLEAN) return;
    if (v->range.flags & FP_RANGE_LO) {
        fputc(' ', f);
        fprintf(f, format, "min", declared_bound(v, 0));
    }
    if (v->range.flags & FP_RANGE_HI) {
        fputc(' ', f);
        fprintf(f, format, "max", declared_bound(v, 1));
    }
}

/* Parameters and inputs have start values; outputs, states and derivatives are calculated. */
static int has_start(const FpVar *v) { return v->kind <= FP_INPUT; }

/* derivative: the listing index of the state element this one is the derivative of (an
 * FP_DERIVATIVE row), 0 for none. */
static int write_variable(FILE *f, const FpVar *v, uint32_t k, const void *model,
                          uint32_t derivative) {
    static const char *const causality[] = {"parameter", "parameter", "input", "output",
                                            "local",     "local",     "local"};
    static const char *const tag[] = {"Real", "Integer", "Boolean"};
    char name[128];
    const char *variability;
    const char *p = (const char *)model + v->offset;
    if (fp_var_element_name(v, k, name, sizeof name) != 0) return -1;
    if (v->kind == FP_PARAM_FIXED) variability = "fixed";
    else if (v->kind == FP_PARAM_TUNABLE) variability = "tunable";
    else variability = v->type == FP_REAL ? "continuous" : "discrete";
    fprintf(f, "    <ScalarVariable name=\"%s\" valueReference=\"%u\" causality=\"%s\"", name,
            (unsigned)(v->vr + k), causality[v->kind]);
    fprintf(f, " variability=\"%s\"", variability);
    if (v->kind == FP_PARAM_FIXED || v->kind == FP_PARAM_TUNABLE) fputs(" initial=\"exact\"", f);
    fputs(" description=\"", f);
    xml_text(f, v->description);
    if (v->range.flags & (FP_RANGE_LO_OPEN | FP_RANGE_HI_OPEN)) {
        /* min/max are the first values accepted inside an open bound: the description states
         * the interval as the check and its messages do */
        char range[96];
        fputs("; range ", f);
        xml_text(f, fp_range_text(&v->range, v->type != FP_REAL, range, sizeof range));
    }
    fprintf(f, "\">\n      <%s", tag[v->type]);
    if (v->type == FP_REAL) {
        /* the unit also on the variable: importers that do not resolve declared types (and
         * fmpy's ScalarVariable.unit) still see it */
        const FpDeclaredType *d = fp_declared_type(fp_var_element_type(v, k));
        fprintf(f, " declaredType=\"%s\" unit=\"%s\"", d->name, d->unit);
    }
    write_range(f, v);
    if (derivative > 0) fprintf(f, " derivative=\"%u\"", (unsigned)derivative);
    if (has_start(v)) {
        if (v->type == FP_REAL) {
            fprintf(f, " start=\"%.17g\"", ((const double *)p)[k]);
        } else if (v->type == FP_INTEGER) {
            fprintf(f, " start=\"%d\"", (int)((const int32_t *)p)[k]);
        } else {
            fprintf(f, " start=\"%s\"", ((const int32_t *)p)[k] ? "true" : "false");
        }
    }
    fputs("/>\n    </ScalarVariable>\n", f);
    return 0;
}

/* The start value of element k as a double (Integer and Boolean converted exactly). */
static double start_value(const FpVar *v, uint32_t k, const void *model) {
    const char *p = (const char *)model + v->offset;
    if (v->type == FP_REAL) return ((const double *)p)[k];
    return (double)((const int32_t *)p)[k];
}

/* The generation date: SOURCE_DATE_EPOCH (seconds since 1970, UTC) or RELEASE_DATE. */
static int generation_date(char buf[32]) {
    const char *epoch = getenv("SOURCE_DATE_EPOCH");
    char *end;
    long long seconds;
    time_t t;
    struct tm *tm;
    if (epoch == NULL || epoch[0] == '\0') {
        strcpy(buf, RELEASE_DATE);
        return 0;
    }
    errno = 0;
    seconds = strtoll(epoch, &end, 10);
    t = (time_t)seconds;
    if (errno != 0 || *end != '\0' || seconds < 0 || (long long)t != seconds ||
        (tm = gmtime(&t)) == NULL || strftime(buf, 32, "%Y-%m-%dT%H:%M:%SZ", tm) == 0) {
        fprintf(stderr, "mdgen: SOURCE_DATE_EPOCH='%s' is not a time in seconds since 1970\n",
                epoch);
        return -1;
    }
    return 0;
}

/* The table as FMI needs it: every Real of a declared type with a defined unit, ranges
 * that are intervals, every start value inside its range (strictly for an open bound: the
 * model would refuse its own default), no overlapping value references or names. */
static int check_table(const FpModelInfo *info, const void *model) {
    size_t i, j;
    uint32_t k;
    for (i = 0; i < info->n_vars; i++) {
        const FpVar *a = &info->vars[i];
        const FpRange *r = &a->range;
        for (k = 0; k < fp_var_count(a); k++) {
            const FpDeclaredType *d = fp_declared_type(fp_var_element_type(a, k));
            if (a->type == FP_REAL && (d->name[0] == '\0' || find_unit(d->unit) == NULL)) {
                fprintf(stderr, "mdgen: Real variable %s has no declared type with a unit\n",
                        a->name);
                return -1;
            }
            if (has_start(a) && !fp_range_contains(r, start_value(a, k, model))) {
                fprintf(stderr, "mdgen: the start value %.17g of %s (element %u) is outside its "
                        "range\n", start_value(a, k, model), a->name, (unsigned)(k + 1));
                return -1;
            }
        }
        if (a->type != FP_REAL && a->dtype != FP_T_NONE) {
            fprintf(stderr, "mdgen: non-Real variable %s has a declared type\n", a->name);
            return -1;
        }
        if ((r->flags & FP_RANGE_LO) && (r->flags & FP_RANGE_HI) && !(r->lo <= r->hi)) {
            fprintf(stderr, "mdgen: the range of %s is empty\n", a->name);
            return -1;
        }
        if (a->type == FP_BOOLEAN && r->flags != 0) {
            fprintf(stderr, "mdgen: Boolean variable %s has a range\n", a->name);
            return -1;
        }
        for (j = i + 1; j < info->n_vars; j++) {
            const FpVar *b = &info->vars[j];
            uint32_t a_end = a->vr + fp_var_count(a), b_end = b->vr + fp_var_count(b);
            if (a->vr < b_end && b->vr < a_end) {
                fprintf(stderr, "mdgen: value references of %s and %s overlap\n", a->name, b->name);
                return -1;
            }
            if (strcmp(a->name, b->name) == 0) {
                fprintf(stderr, "mdgen: variable %s declared twice\n", a->name);
                return -1;
            }
        }
    }
    return 0;
}

/* ------------------------------------------------------------------------ */
/* The listing order and the ModelStructure                                 */

/* Where a kind comes in the listing: inputs, outputs, the parameters, then the local variables
 * (Model Exchange states and derivatives, other locals). */
#define N_RANKS 4
static int listing_rank(FpVarKind kind) {
    if (kind == FP_STATE || kind == FP_DERIVATIVE || kind == FP_LOCAL) return 3;
    return kind == FP_INPUT ? 0 : kind == FP_OUTPUT ? 1 : 2;
}

/* The state row whose derivative row d is ("der_" and its name), or NULL. */
static const FpVar *state_of(const FpModelInfo *info, const FpVar *d) {
    const FpVar *x;
    if (d->kind != FP_DERIVATIVE || strncmp(d->name, "der_", 4) != 0) return NULL;
    x = fp_var_find(info->vars, info->n_vars, d->name + 4);
    return x != NULL && x->kind == FP_STATE ? x : NULL;
}

/* The Model Exchange rows as FMI 2.0 needs them: Real rows of states that lie one after the
 * other in the model (in table order: the order of fmi2GetContinuousStates, which is the
 * order of <Derivatives>), as many elements as the model has states, each with one
 * derivative row of its shape, the derivative rows in the order of their states; none for a
 * model without Model Exchange. */
static int check_model_exchange(const FpModelInfo *info) {
    size_t i, j, n_states = 0;
    const FpVar *prev = NULL, *prev_state = NULL;
    for (i = 0; i < info->n_vars; i++) {
        const FpVar *v = &info->vars[i], *x;
        int n_der = 0;
        if (v->kind != FP_STATE && v->kind != FP_DERIVATIVE) continue;
        if (info->me == NULL || v->type != FP_REAL) {
            fprintf(stderr, "mdgen: %s: row %s is a Model Exchange row of %s\n",
                    info->model_name, v->name,
                    info->me == NULL ? "a model without Model Exchange" : "a non-Real type");
            return -1;
        }
        if (v->kind == FP_DERIVATIVE) {
            x = state_of(info, v);
            if (x == NULL || x->rows != v->rows || x->cols != v->cols || x <= prev_state) {
                fprintf(stderr, "mdgen: %s: derivative row %s names no state row \"der_<state>\" "
                        "of its shape after the previous derivative's\n", info->model_name,
                        v->name);
                return -1;
            }
            prev_state = x;
            continue;
        }
        if (prev != NULL && v->offset != prev->offset + fp_var_count(prev) * sizeof(double)) {
            fprintf(stderr, "mdgen: %s: state row %s does not follow %s in the model\n",
                    info->model_name, v->name, prev->name);
            return -1;
        }
        for (j = 0; j < info->n_vars; j++)
            if (state_of(info, &info->vars[j]) == v) n_der++;
        if (n_der != 1) {
            fprintf(stderr, "mdgen: %s: state row %s has %d derivative rows, not 1\n",
                    info->model_name, v->name, n_der);
            return -1;
        }
        prev = v;
        n_states += fp_var_count(v);
    }
    if (info->me != NULL && n_states != info->me->n_states) {
        fprintf(stderr, "mdgen: %s: its state rows hold %lu elements, the model %lu states\n",
                info->model_name, (unsigned long)n_states, (unsigned long)info->me->n_states);
        return -1;
    }
    if (info->me != NULL && info->me->indicators != NULL) {
        const FpVar *z = fp_var_find(info->vars, info->n_vars, info->me->indicators);
        if (z == NULL || z->kind != FP_LOCAL || z->type != FP_REAL ||
            fp_var_count(z) != info->me->n_event_indicators) {
            fprintf(stderr, "mdgen: %s: its event indicators %s are no local Real row of %lu "
                    "elements\n", info->model_name, info->me->indicators,
                    (unsigned long)info->me->n_event_indicators);
            return -1;
        }
    }
    return 0;
}

/* The ScalarVariable index (1-based, listing order) of element 0 of every row; returns the
 * number of elements listed, 0 when out of memory. */
static uint32_t listing_indices(const FpModelInfo *info, uint32_t **first) {
    uint32_t index = 0;
    size_t i;
    int rank;
    *first = (uint32_t *)calloc(info->n_vars, sizeof **first);
    if (*first == NULL) return 0;
    for (rank = 0; rank < N_RANKS; rank++)
        for (i = 0; i < info->n_vars; i++)
            if (listing_rank(info->vars[i].kind) == rank) {
                (*first)[i] = index + 1;
                index += fp_var_count(&info->vars[i]);
            }
    return index;
}

/* A table's InitialUnknowns declaration: the outputs (row names) and the knowns they are
 * functions of at initialization (row names, FP_ALL_PARAMETERS), plant/plant_vars.h. */
typedef struct {
    const char *unknowns, *knowns;
} InitialDeclaration;

#define DECLARATION_ROW(unknowns, knowns) {unknowns, knowns},
static const InitialDeclaration plant_declarations[] = {
    PLANT_INITIAL_DEPENDENCIES(DECLARATION_ROW)};
static const InitialDeclaration controller_declarations[] = {
    CONTROLLER_INITIAL_DEPENDENCIES(DECLARATION_ROW)};
static const InitialDeclaration signals_declarations[] = {
    SIGNALS_INITIAL_DEPENDENCIES(DECLARATION_ROW)};
#undef DECLARATION_ROW

static const struct {
    const char *model;
    const InitialDeclaration *rows;
    size_t n;
} declarations[] = {
    {"MultirotorPlant", plant_declarations, sizeof plant_declarations / sizeof plant_declarations[0]},
    {"FullPoseController", controller_declarations,
     sizeof controller_declarations / sizeof controller_declarations[0]},
    {"ScenarioSignals", signals_declarations,
     sizeof signals_declarations / sizeof signals_declarations[0]},
};

/* The <Outputs> declarations of a model with Model Exchange (plant/plant_vars.h): the
 * outputs (row names) and the knowns they are functions of (inputs, state rows, "@states").
 * A model without one declares every output independent of every known (dependencies=""). */
#define DECLARATION_ROW(unknowns, knowns) {unknowns, knowns},
static const InitialDeclaration plant_output_declarations[] = {
    PLANT_OUTPUT_DEPENDENCIES(DECLARATION_ROW)};
#undef DECLARATION_ROW

static const struct {
    const char *model;
    const InitialDeclaration *rows;
    size_t n;
} output_declarations[] = {
    {"MultirotorPlant", plant_output_declarations,
     sizeof plant_output_declarations / sizeof plant_output_declarations[0]},
};

/* The next space-separated name of *p into buf: its length, 0 at the end, -1 if too long. */
static int next_name(const char **p, char *buf, size_t size) {
    size_t n = 0;
    while (**p == ' ') (*p)++;
    while (**p != '\0' && **p != ' ') {
        if (n + 1 >= size) return -1;
        buf[n++] = *(*p)++;
    }
    buf[n] = '\0';
    return (int)n;
}

/* The model's InitialUnknowns, resolved: for every row the declaration it is an unknown of
 * (-1 for the knowns), for every declaration its dependencies as the attribute's text.  Every
 * output in exactly one declaration, every name a row of the right kind, or the build fails. */
typedef struct {
    int *declaration; /* per row */
    char **dependencies; /* per declaration */
    unsigned char **known_rows; /* per declaration: per row, 1 if a known (FMI 3.0) */
    size_t n;
} InitialUnknowns;

static void free_initial_unknowns(InitialUnknowns *u) {
    size_t d;
    for (d = 0; d < u->n && u->dependencies != NULL; d++) free(u->dependencies[d]);
    for (d = 0; d < u->n && u->known_rows != NULL; d++) free(u->known_rows[d]);
    free(u->dependencies);
    free(u->known_rows);
    free(u->declaration);
}

/* The dependencies attribute of a set of elements (mask[index], 1-based): ascending indices. */
static char *dependency_text(const unsigned char *mask, uint32_t n) {
    char *text = (char *)malloc((size_t)n * 11 + 1), *end;
    uint32_t i;
    if (text == NULL) return NULL;
    end = text;
    *end = '\0';
    for (i = 1; i <= n; i++)
        if (mask[i]) end += sprintf(end, "%s%u", end == text ? "" : " ", (unsigned)i);
    return text;
}

/* What a declaration lists: the InitialUnknowns (outputs, states and derivatives as functions
 * of inputs and parameters, "@parameters") or the Outputs (outputs as functions of inputs and
 * states, "@states"). */
enum { DECLARE_INITIAL = 0, DECLARE_OUTPUTS = 1 };
static const char *const declaration_kind[] = {"InitialUnknowns", "Outputs"};

/* 1 if a row of this kind is a known of that kind of declaration. */
static int known_kind(FpVarKind kind, int what) {
    if (kind == FP_INPUT) return 1;
    return what == DECLARE_INITIAL ? listing_rank(kind) == 2 : kind == FP_STATE;
}

/* 1 if a row of this kind is an unknown of that kind of declaration (every one is declared). */
static int unknown_kind(FpVarKind kind, int what) {
    if (kind == FP_OUTPUT) return 1;
    return what == DECLARE_INITIAL && (kind == FP_STATE || kind == FP_DERIVATIVE);
}

/* Marks the elements of the knowns one declaration names (mask, by listing index) and their
 * rows (rows, by table index: the variables of FMI 3.0); -1 (with a message) on a bad name. */
static int mark_knowns(const FpModelInfo *info, const uint32_t *first, const char *knowns,
                       int what, unsigned char *mask, unsigned char *rows) {
    char name[128];
    const char *p = knowns;
    size_t i;
    uint32_t k;
    int len;
    while ((len = next_name(&p, name, sizeof name)) != 0) {
        int all = strcmp(name, what == DECLARE_INITIAL ? "@parameters" : "@states") == 0;
        const FpVar *row = all ? NULL : fp_var_find(info->vars, info->n_vars, name);
        if (len < 0 || (!all && (row == NULL || !known_kind(row->kind, what)))) {
            fprintf(stderr, "mdgen: %s of %s: known %s is no %s\n", declaration_kind[what],
                    info->model_name, len < 0 ? "(too long)" : name,
                    what == DECLARE_INITIAL ? "input or parameter" : "input or state");
            return -1;
        }
        for (i = 0; i < info->n_vars; i++) {
            const FpVar *v = &info->vars[i];
            if (all ? !known_kind(v->kind, what) || v->kind == FP_INPUT : v != row) continue;
            for (k = 0; k < fp_var_count(v); k++) mask[first[i] + k] = 1;
            rows[i] = 1;
        }
    }
    return 0;
}

/* A model's declarations (`rows`, n of them) of one kind, resolved into u. */
static int resolve_declarations(const FpModelInfo *info, const uint32_t *first, uint32_t n,
                                const InitialDeclaration *rows, size_t n_rows, int what,
                                InitialUnknowns *u) {
    unsigned char *mask = NULL;
    char name[128];
    size_t d, i;
    int len;
    memset(u, 0, sizeof *u);
    u->n = n_rows;
    u->declaration = (int *)malloc(info->n_vars * sizeof *u->declaration);
    u->dependencies = (char **)calloc(u->n, sizeof *u->dependencies);
    u->known_rows = (unsigned char **)calloc(u->n, sizeof *u->known_rows);
    mask = (unsigned char *)malloc((size_t)n + 1);
    if (u->declaration == NULL || u->dependencies == NULL || u->known_rows == NULL ||
        mask == NULL)
        goto fail;
    for (i = 0; i < info->n_vars; i++) u->declaration[i] = -1;
    for (d = 0; d < u->n; d++) {
        const char *p = rows[d].unknowns;
        while ((len = next_name(&p, name, sizeof name)) != 0) {
            const FpVar *row = len < 0 ? NULL : fp_var_find(info->vars, info->n_vars, name);
            if (row == NULL || !unknown_kind(row->kind, what) ||
                u->declaration[row - info->vars] >= 0) {
                fprintf(stderr, "mdgen: %s of %s: %s is no %s, or declared twice\n",
                        declaration_kind[what], info->model_name, len < 0 ? "(too long)" : name,
                        what == DECLARE_INITIAL ? "output, state or derivative" : "output");
                goto fail;
            }
            u->declaration[row - info->vars] = (int)d;
        }
        memset(mask, 0, (size_t)n + 1);
        u->known_rows[d] = (unsigned char *)calloc(info->n_vars, 1);
        if (u->known_rows[d] == NULL) goto fail;
        if (mark_knowns(info, first, rows[d].knowns, what, mask, u->known_rows[d]) != 0)
            goto fail;
        u->dependencies[d] = dependency_text(mask, n);
        if (u->dependencies[d] == NULL) goto fail;
    }
    for (i = 0; i < info->n_vars; i++)
        if (unknown_kind(info->vars[i].kind, what) && u->declaration[i] < 0) {
            fprintf(stderr, "mdgen: %s of %s: %s is in no declaration\n",
                    declaration_kind[what], info->model_name, info->vars[i].name);
            goto fail;
        }
    free(mask);
    return 0;
fail:
    free(mask);
    free_initial_unknowns(u);
    return -1;
}

static int resolve_initial_unknowns(const FpModelInfo *info, const uint32_t *first, uint32_t n,
                                    InitialUnknowns *u) {
    size_t d;
    for (d = 0; d < sizeof declarations / sizeof declarations[0]; d++)
        if (strcmp(declarations[d].model, info->model_name) == 0)
            return resolve_declarations(info, first, n, declarations[d].rows, declarations[d].n,
                                        DECLARE_INITIAL, u);
    fprintf(stderr, "mdgen: no InitialUnknowns declaration for %s\n", info->model_name);
    return -1;
}

/* The <Outputs> declarations (u->n = 0: none, every output's dependencies=""); a model with
 * Model Exchange must have them. */
static int resolve_output_dependencies(const FpModelInfo *info, const uint32_t *first,
                                       uint32_t n, InitialUnknowns *u) {
    size_t d;
    memset(u, 0, sizeof *u);
    for (d = 0; d < sizeof output_declarations / sizeof output_declarations[0]; d++)
        if (strcmp(output_declarations[d].model, info->model_name) == 0)
            return resolve_declarations(info, first, n, output_declarations[d].rows,
                                        output_declarations[d].n, DECLARE_OUTPUTS, u);
    if (info->me == NULL) return 0;
    fprintf(stderr, "mdgen: no Outputs declaration for %s, which has Model Exchange\n",
            info->model_name);
    return -1;
}

/* <ModelStructure>: every output (listing order) in <Outputs>, without dependencies when the
 * model declares none (computed at the end of a step from the inputs held over it: no direct
 * feedthrough at communication points, so no algebraic loop for masters), else with the
 * dependencies of its Model Exchange declaration (o); the state derivatives in <Derivatives>
 * (in the order of the state vector; every known, the attribute absent); in <InitialUnknowns>
 * the outputs, states and derivatives, ascending, with their declaration's knowns. */
static void write_model_structure(FILE *f, const FpModelInfo *info, const uint32_t *first,
                                  const InitialUnknowns *u, const InitialUnknowns *o) {
    size_t i;
    uint32_t k;
    int rank;
    fputs("  <ModelStructure>\n    <Outputs>\n", f);
    for (i = 0; i < info->n_vars; i++) {
        if (info->vars[i].kind != FP_OUTPUT) continue;
        for (k = 0; k < fp_var_count(&info->vars[i]); k++)
            fprintf(f, "      <Unknown index=\"%u\" dependencies=\"%s\"/>\n",
                    (unsigned)(first[i] + k), o->n == 0 ? "" : o->dependencies[o->declaration[i]]);
    }
    fputs("    </Outputs>\n", f);
    if (info->me != NULL) {
        fputs("    <Derivatives>\n", f);
        for (i = 0; i < info->n_vars; i++) {
            if (info->vars[i].kind != FP_DERIVATIVE) continue;
            for (k = 0; k < fp_var_count(&info->vars[i]); k++)
                fprintf(f, "      <Unknown index=\"%u\"/>\n", (unsigned)(first[i] + k));
        }
        fputs("    </Derivatives>\n", f);
    }
    fputs("    <InitialUnknowns>\n", f);
    for (rank = 0; rank < N_RANKS; rank++)
        for (i = 0; i < info->n_vars; i++) {
            if (u->declaration[i] < 0 || listing_rank(info->vars[i].kind) != rank) continue;
            for (k = 0; k < fp_var_count(&info->vars[i]); k++)
                fprintf(f, "      <Unknown index=\"%u\" dependencies=\"%s\"/>\n",
                        (unsigned)(first[i] + k), u->dependencies[u->declaration[i]]);
        }
    fputs("    </InitialUnknowns>\n  </ModelStructure>\n", f);
}

/* The FMU's C files: argv[first..argc-1] after "--sources DIR" (none without it). */
typedef struct {
    const char *dir;
    char **files;
    int n;
} SourceList;

static void write_source_files(FILE *f, const SourceList *src) {
    int i;
    if (src->n == 0) return;
    fputs("    <SourceFiles>\n", f);
    for (i = 0; i < src->n; i++) {
        fputs("      <File name=\"", f);
        xml_text(f, src->files[i]);
        fputs("\"/>\n", f);
    }
    fputs("    </SourceFiles>\n", f);
}

/* sources/buildDescription.xml: one build configuration, the C99 files compiled together with
 * sources/ as the include directory (the files are listed relative to it) and linked with the
 * system's maths library. */
static int write_build_description(const FpModelInfo *info, const SourceList *src) {
    char path[4096];
    FILE *f;
    int i;
    if (snprintf(path, sizeof path, "%s/buildDescription.xml", src->dir) >= (int)sizeof path) {
        fprintf(stderr, "mdgen: path of %s too long\n", src->dir);
        return -1;
    }
    f = fopen(path, "w");
    if (f == NULL) {
        perror(path);
        return -1;
    }
    fputs("<?xml version=\"1.0\" encoding=\"UTF-8\"?>\n", f);
    fputs("<fmiBuildDescription fmiVersion=\"3.0\">\n", f);
    fprintf(f, "  <BuildConfiguration modelIdentifier=\"%s\">\n", info->model_name);
    fputs("    <SourceFileSet language=\"C99\">\n", f);
    for (i = 0; i < src->n; i++) {
        fputs("      <SourceFile name=\"", f);
        xml_text(f, src->files[i]);
        fputs("\"/>\n", f);
    }
    fputs("    </SourceFileSet>\n", f);
    /* the maths functions: libm on Linux (-lm), part of the C runtime elsewhere */
    fputs("    <Library name=\"m\" external=\"true\" description=\"the C maths library\"/>\n", f);
    fputs("  </BuildConfiguration>\n</fmiBuildDescription>\n", f);
    return fclose(f) == 0 ? 0 : -1;
}

/* ------------------------------------------------------------------------ */
/* FMI 3.0: the same table, one variable per row                            */

/* One <Float64Type> per declared type in use (WRENCH, which no FMI 3.0 array can state per
 * element, has no name and is left out). */
static void write_types3(FILE *f, const FpModelInfo *info) {
    int t;
    fputs("  <TypeDefinitions>\n", f);
    for (t = 0; t < FP_N_TYPES; t++) {
        const FpDeclaredType *d = fp_declared_type((FpTypeId)t);
        if (d->name[0] == '\0' || !type_used(info, (FpTypeId)t)) continue;
        fprintf(f, "    <Float64Type name=\"%s\" quantity=\"%s\" unit=\"%s\"", d->name,
                d->quantity, d->unit);
        if (d->nominal != 0.0) fprintf(f, " nominal=\"%.17g\"", d->nominal);
        fputs("/>\n", f);
    }
    fputs("  </TypeDefinitions>\n", f);
}

/* A row as one FMI 3.0 variable: a scalar, or an array with <Dimension start="rows"/> (and a
 * second one of cols for a matrix, its elements row-major), its start values listed
 * element by element.  A WRENCH row (force then torque) has no declared type or unit: the
 * description says which elements are in N and which in N.m. */
static void write_variable3(FILE *f, const FpModelInfo *info, const FpVar *v, const void *model,
                            int clocked) {
    static const char *const causality[] = {"parameter", "parameter", "input", "output",
                                            "local",     "local",     "local"};
    const FpVar *x = state_of(info, v);
    static const char *const tag[] = {"Float64", "Int32", "Boolean"};
    const char *p = (const char *)model + v->offset;
    const char *variability;
    uint32_t k, n = fp_var_count(v);
    /* clocked: an input or output of the clock's model partition (Scheduled Execution),
     * which FMI 3.0 requires to be discrete */
    clocked = clocked && (v->kind == FP_INPUT || v->kind == FP_OUTPUT);
    if (v->kind == FP_PARAM_FIXED) variability = "fixed";
    else if (v->kind == FP_PARAM_TUNABLE) variability = "tunable";
    else variability = v->type == FP_REAL && !clocked ? "continuous" : "discrete";
    fprintf(f, "    <%s name=\"%s\" valueReference=\"%u\" causality=\"%s\" variability=\"%s\"",
            tag[v->type], v->name, (unsigned)v->vr, causality[v->kind], variability);
    if (clocked) fprintf(f, " clocks=\"%u\"", (unsigned)FP_SE_CLOCK_VR);
    if (v->kind == FP_PARAM_FIXED || v->kind == FP_PARAM_TUNABLE) fputs(" initial=\"exact\"", f);
    fputs(" description=\"", f);
    xml_text(f, v->description);
    if (v->range.flags & (FP_RANGE_LO_OPEN | FP_RANGE_HI_OPEN)) {
        char range[96];
        fputs("; range ", f);
        xml_text(f, fp_range_text(&v->range, v->type != FP_REAL, range, sizeof range));
    }
    if (v->dtype == FP_T_WRENCH) fputs("; unit N for elements 1-3, N.m for elements 4-6", f);
    fputc('"', f);
    if (v->type == FP_REAL && v->dtype != FP_T_WRENCH) {
        const FpDeclaredType *d = fp_declared_type(v->dtype);
        fprintf(f, " declaredType=\"%s\" unit=\"%s\"", d->name, d->unit);
    }
    write_range(f, v);
    if (x != NULL) fprintf(f, " derivative=\"%u\"", (unsigned)x->vr); /* (the whole array's) */
    if (has_start(v)) {
        fputs(" start=\"", f);
        for (k = 0; k < n; k++) {
            if (k > 0) fputc(' ', f);
            if (v->type == FP_REAL) fprintf(f, "%.17g", ((const double *)p)[k]);
            else if (v->type == FP_INTEGER) fprintf(f, "%d", (int)((const int32_t *)p)[k]);
            else fputs(((const int32_t *)p)[k] ? "true" : "false", f);
        }
        fputc('"', f);
    }
    if (v->rows == 1 && v->cols == 1) {
        fputs("/>\n", f);
        return;
    }
    fprintf(f, ">\n      <Dimension start=\"%u\"/>\n", (unsigned)v->rows);
    if (v->cols > 1) fprintf(f, "      <Dimension start=\"%u\"/>\n", (unsigned)v->cols);
    fprintf(f, "    </%s>\n", tag[v->type]);
}

static int compare_u32(const void *a, const void *b) {
    uint32_t x = *(const uint32_t *)a, y = *(const uint32_t *)b;
    return x < y ? -1 : x > y;
}

/* The value references of the knowns of a row's declaration in d, ascending, as the
 * dependencies attribute (the variables of FMI 3.0). */
static void write_known_vrs(FILE *f, const FpModelInfo *info, const InitialUnknowns *d, size_t i,
                            uint32_t *vrs) {
    const unsigned char *known = d->known_rows[d->declaration[i]];
    size_t j, n;
    for (j = 0, n = 0; j < info->n_vars; j++)
        if (known[j]) vrs[n++] = info->vars[j].vr;
    qsort(vrs, n, sizeof *vrs, compare_u32);
    for (j = 0; j < n; j++) fprintf(f, "%s%u", j > 0 ? " " : "", (unsigned)vrs[j]);
}

/* <ModelStructure> of FMI 3.0: the same declarations as FMI 2.0's, by value reference (a
 * known is a whole variable): every output an <Output>, without dependencies when the model
 * declares none (o->n = 0), else with its Model Exchange declaration's knowns; the state
 * derivatives as <ContinuousStateDerivative> (every known); an <InitialUnknown> for every
 * output, state and derivative with its declaration's knowns, ascending, but no output's when
 * the outputs are clocked (Scheduled Execution: FMI 3.0 excludes clocked variables from the
 * initial unknowns); with Model Exchange (`exchange`) its event indicators as
 * <EventIndicator>. */
static int write_model_structure3(FILE *f, const FpModelInfo *info, const InitialUnknowns *u,
                                  const InitialUnknowns *o, int clocked, int exchange) {
    uint32_t *vrs = (uint32_t *)malloc(info->n_vars * sizeof *vrs);
    size_t i;
    if (vrs == NULL) return -1;
    fputs("  <ModelStructure>\n", f);
    for (i = 0; i < info->n_vars; i++) {
        if (info->vars[i].kind != FP_OUTPUT) continue;
        fprintf(f, "    <Output valueReference=\"%u\" dependencies=\"", (unsigned)info->vars[i].vr);
        if (o->n > 0) write_known_vrs(f, info, o, i, vrs);
        fputs("\"/>\n", f);
    }
    for (i = 0; i < info->n_vars; i++)
        if (info->vars[i].kind == FP_DERIVATIVE)
            fprintf(f, "    <ContinuousStateDerivative valueReference=\"%u\"/>\n",
                    (unsigned)info->vars[i].vr);
    for (i = 0; i < info->n_vars; i++) {
        if (u->declaration[i] < 0 || (info->vars[i].kind == FP_OUTPUT && clocked)) continue;
        fprintf(f, "    <InitialUnknown valueReference=\"%u\" dependencies=\"",
                (unsigned)info->vars[i].vr);
        write_known_vrs(f, info, u, i, vrs);
        fputs("\"/>\n", f);
    }
    if (exchange && info->me->indicators != NULL)
        fprintf(f, "    <EventIndicator valueReference=\"%u\"/>\n",
                (unsigned)fp_var_find(info->vars, info->n_vars, info->me->indicators)->vr);
    fputs("  </ModelStructure>\n", f);
    free(vrs);
    return 0;
}

/* The fixed Real scalar parameter holding the model's internal step (fp_model.h), whose
 * default is the interval of the clock of Scheduled Execution; NULL if none. */
static const FpVar *internal_step(const FpModelInfo *info) {
    static const char *const names[] = FP_INTERNAL_STEP_NAMES;
    size_t i, j;
    for (i = 0; i < info->n_vars; i++) {
        const FpVar *v = &info->vars[i];
        if (v->type != FP_REAL || v->kind != FP_PARAM_FIXED || fp_var_count(v) != 1) continue;
        for (j = 0; j < sizeof names / sizeof names[0]; j++)
            if (strcmp(v->name, names[j]) == 0) return v;
    }
    return NULL;
}

/* The FMI 3.0 modelDescription.xml: the header, with `exchange` a <ModelExchange>, a
 * <CoSimulation> without Event Mode (and with `scheduled`, a <ScheduledExecution>), the units,
 * types and log categories, the independent variable time (value reference 0), with
 * `scheduled` the input clock, the rows in the listing order of FMI 2.0 (inputs, outputs,
 * parameters, locals) and the ModelStructure. */
static int write_fmi3(FILE *f, const FpModelInfo *info, const void *model, const char *guid,
                      const char *date, const char *version, const InitialUnknowns *u,
                      const InitialUnknowns *o, int scheduled, int exchange) {
    size_t i;
    int c, rank;
    fputs("<?xml version=\"1.0\" encoding=\"UTF-8\"?>\n", f);
    fprintf(f,
            "<fmiModelDescription fmiVersion=\"3.0\" modelName=\"%s\" instantiationToken=\"%s\"\n"
            "  description=\"",
            info->model_name, guid);
    xml_text(f, info->description);
    fprintf(f, "\"\n  author=\"%s\" version=\"", AUTHOR);
    xml_text(f, version);
    fprintf(f,
            "\"\n  copyright=\"Copyright (c) %.4s %s\" license=\"%s\"\n"
            "  generationTool=\"fullpose mdgen\" generationDateAndTime=\"%s\"\n"
            "  variableNamingConvention=\"structured\">\n",
            date, AUTHOR, LICENSE, date);
    if (exchange) /* (its completed integrator steps update the discrete state) */
        fprintf(f,
                "  <ModelExchange modelIdentifier=\"%s\" needsCompletedIntegratorStep=\"true\""
                " providesEvaluateDiscreteStates=\"false\""
                " canBeInstantiatedOnlyOncePerProcess=\"false\" canGetAndSetFMUState=\"true\""
                " canSerializeFMUState=\"true\" providesDirectionalDerivatives=\"false\""
                " providesAdjointDerivatives=\"false\"/>\n",
                info->model_name);
    fprintf(f,
            "  <CoSimulation modelIdentifier=\"%s\" canHandleVariableCommunicationStepSize=\"true\""
            " canBeInstantiatedOnlyOncePerProcess=\"false\" canGetAndSetFMUState=\"true\""
            " canSerializeFMUState=\"true\" providesDirectionalDerivatives=\"false\""
            " providesAdjointDerivatives=\"false\" maxOutputDerivativeOrder=\"0\""
            " hasEventMode=\"false\" providesIntermediateUpdate=\"false\""
            " mightReturnEarlyFromDoStep=\"false\""
            " canReturnEarlyAfterIntermediateUpdate=\"false\"/>\n",
            info->model_name);
    if (scheduled)
        fprintf(f,
                "  <ScheduledExecution modelIdentifier=\"%s\""
                " canBeInstantiatedOnlyOncePerProcess=\"false\" canGetAndSetFMUState=\"true\""
                " canSerializeFMUState=\"true\" providesDirectionalDerivatives=\"false\""
                " providesAdjointDerivatives=\"false\"/>\n",
                info->model_name);
    write_units(f, info, "s");
    write_types3(f, info);
    fputs("  <LogCategories>\n", f);
    for (c = 0; c < FP_LOG_N_CATEGORIES; c++)
        fprintf(f, "    <Category name=\"%s\" description=\"%s\"/>\n", fp_log_category_name(c),
                fp_log_category_description(c));
    fputs("  </LogCategories>\n", f);
    fprintf(f, "  <DefaultExperiment startTime=\"0\" stopTime=\"%.17g\" stepSize=\"%.17g\"/>\n",
            info->default_stop, info->default_step);
    fputs("  <ModelVariables>\n", f);
    fputs("    <Float64 name=\"time\" valueReference=\"0\" causality=\"independent\""
          " variability=\"continuous\" description=\"Simulation time\" unit=\"s\"/>\n",
          f);
    if (scheduled) {
        const FpVar *step = internal_step(info);
        fprintf(f,
                "    <Clock name=\"%s\" valueReference=\"%u\" causality=\"input\""
                " description=\"%s\" intervalVariability=\"constant\""
                " intervalDecimal=\"%.17g\" priority=\"%d\"/>\n",
                FP_SE_CLOCK_NAME, (unsigned)FP_SE_CLOCK_VR, FP_SE_CLOCK_DESCRIPTION,
                *(const double *)((const char *)model + step->offset), FP_SE_CLOCK_PRIORITY);
    }
    for (rank = 0; rank < N_RANKS; rank++)
        for (i = 0; i < info->n_vars; i++)
            if (listing_rank(info->vars[i].kind) == rank)
                write_variable3(f, info, &info->vars[i], model, scheduled);
    fputs("  </ModelVariables>\n", f);
    if (write_model_structure3(f, info, u, o, scheduled, exchange) != 0) return -1;
    fputs("</fmiModelDescription>\n", f);
    return 0;
}

int main(int argc, char **argv) {
    const FpModelInfo *info = fp_model_info();
    char guid[40], date[32];
    void *model;
    FILE *f;
    size_t i;
    uint32_t k, n_listed, *first = NULL;
    int c, rank;
    InitialUnknowns unknowns, outputs;
    SourceList src = {NULL, NULL, 0};
    int fmi3 = argc > 1 && strcmp(argv[1], "--fmi3") == 0, scheduled = 0, exchange = 0;
    if (fmi3) { /* the FMI 3.0 modelDescription.xml of the same table */
        argv++;
        argc--;
        scheduled = argc > 1 && strcmp(argv[1], "--scheduled-execution") == 0;
        if (scheduled) { /* and Scheduled Execution besides co-simulation */
            argv++;
            argc--;
        }
        exchange = argc > 1 && strcmp(argv[1], "--model-exchange") == 0;
        if (exchange) { /* and Model Exchange besides co-simulation */
            argv++;
            argc--;
        }
    }
    if (argc < 3 || (argc > 3 && (strcmp(argv[3], "--sources") != 0 || argc < 6))) {
        fprintf(stderr, "usage: mdgen [--fmi3 [--scheduled-execution] [--model-exchange]] "
                        "OUTPUT.xml VERSION [--sources DIR FILE.c ...]\n");
        return 2;
    }
    if (exchange && info->me == NULL) {
        fprintf(stderr, "mdgen: --model-exchange: %s has no Model Exchange (FpModelInfo.me)\n",
                info->model_name);
        return 1;
    }
    if (argc > 3) {
        src.dir = argv[4];
        src.files = argv + 5;
        src.n = argc - 5;
        if (write_build_description(info, &src) != 0) return 1;
    }
    if (generation_date(date) != 0) return 1;
    model = calloc(1, info->model_size);
    if (model == NULL) return 1;
    info->set_defaults(model);
    n_listed = listing_indices(info, &first);
    if (check_table(info, model) != 0 || check_model_exchange(info) != 0 || n_listed == 0 ||
        resolve_initial_unknowns(info, first, n_listed, &unknowns) != 0) {
        free(first);
        free(model);
        return 1;
    }
    fp_model_guid(info, guid);
    for (i = 0; fmi3 && i < info->n_vars; i++) {
        const FpVar *v = &info->vars[i];
        const char *clash = NULL;
        if (v->vr == 0) clash = "value reference 0, FMI 3.0's time";
        else if (scheduled && v->vr <= FP_SE_CLOCK_VR && FP_SE_CLOCK_VR < v->vr + fp_var_count(v))
            clash = "the value reference of the clock of Scheduled Execution "
                    "(fmi3_scheduled.h) among its elements";
        else if (scheduled && strcmp(v->name, FP_SE_CLOCK_NAME) == 0)
            clash = "the name of the clock of Scheduled Execution (fmi3_scheduled.h)";
        if (clash != NULL) {
            fprintf(stderr, "mdgen: %s has %s\n", v->name, clash);
            free_initial_unknowns(&unknowns);
            free(first);
            free(model);
            return 1;
        }
    }
    if (scheduled && internal_step(info) == NULL) {
        fprintf(stderr, "mdgen: --scheduled-execution: %s has no internal step parameter "
                        "(fp_model.h FP_INTERNAL_STEP_NAMES) to give the clock its interval\n",
                info->model_name);
        free_initial_unknowns(&unknowns);
        free(first);
        free(model);
        return 1;
    }
    f = fopen(argv[1], "w");
    if (f == NULL) {
        perror(argv[1]);
        free_initial_unknowns(&unknowns);
        free(first);
        free(model);
        return 1;
    }
    if (resolve_output_dependencies(info, first, n_listed, &outputs) != 0) {
        fclose(f);
        free_initial_unknowns(&unknowns);
        free(first);
        free(model);
        return 1;
    }
    if (fmi3) {
        int bad = write_fmi3(f, info, model, guid, date, argv[2], &unknowns, &outputs, scheduled,
                             exchange);
        free_initial_unknowns(&outputs);
        free_initial_unknowns(&unknowns);
        free(first);
        free(model);
        return fclose(f) == 0 && bad == 0 ? 0 : 1;
    }
    fputs("<?xml version=\"1.0\" encoding=\"UTF-8\"?>\n", f);
    fprintf(f,
            "<fmiModelDescription fmiVersion=\"2.0\" modelName=\"%s\" guid=\"%s\"\n"
            "  description=\"",
            info->model_name, guid);
    xml_text(f, info->description);
    fprintf(f, "\"\n  author=\"%s\" version=\"", AUTHOR);
    xml_text(f, argv[2]);
    /* the copyright year is the generation date's, so it too is reproducible */
    fprintf(f,
            "\"\n  copyright=\"Copyright (c) %.4s %s\" license=\"%s\"\n"
            "  generationTool=\"fullpose mdgen\" generationDateAndTime=\"%s\"\n"
            "  variableNamingConvention=\"structured\" numberOfEventIndicators=\"%lu\">\n",
            date, AUTHOR, LICENSE, date,
            (unsigned long)(info->me != NULL ? info->me->n_event_indicators : 0));
    if (info->me != NULL) {
        /* Model Exchange before co-simulation (the schema's order); completed integrator
         * steps are needed: they update the model's discrete state (fp_model.h) */
        fprintf(f,
                "  <ModelExchange modelIdentifier=\"%s\" needsExecutionTool=\"false\""
                " completedIntegratorStepNotNeeded=\"false\""
                " canBeInstantiatedOnlyOncePerProcess=\"false\""
                " canNotUseMemoryManagementFunctions=\"false\" canGetAndSetFMUstate=\"true\""
                " canSerializeFMUstate=\"true\" providesDirectionalDerivative=\"false\"%s\n",
                info->model_name, src.n > 0 ? ">" : "/>");
        if (src.n > 0) {
            write_source_files(f, &src);
            fputs("  </ModelExchange>\n", f);
        }
    }
    fprintf(f,
            "  <CoSimulation modelIdentifier=\"%s\" canHandleVariableCommunicationStepSize=\"true\""
            " canInterpolateInputs=\"false\" maxOutputDerivativeOrder=\"0\""
            " canRunAsynchronuously=\"false\" canBeInstantiatedOnlyOncePerProcess=\"false\""
            " canNotUseMemoryManagementFunctions=\"false\" canGetAndSetFMUstate=\"true\""
            " canSerializeFMUstate=\"true\" providesDirectionalDerivative=\"false\"%s\n",
            info->model_name, src.n > 0 ? ">" : "/>");
    if (src.n > 0) {
        write_source_files(f, &src);
        fputs("  </CoSimulation>\n", f);
    }
    write_units(f, info, NULL);
    write_types(f, info);
    fputs("  <LogCategories>\n", f);
    for (c = 0; c < FP_LOG_N_CATEGORIES; c++)
        fprintf(f, "    <Category name=\"%s\" description=\"%s\"/>\n", fp_log_category_name(c),
                fp_log_category_description(c));
    fputs("  </LogCategories>\n", f);
    fprintf(f, "  <DefaultExperiment startTime=\"0\" stopTime=\"%.17g\" stepSize=\"%.17g\"/>\n",
            info->default_stop, info->default_step);
    fputs("  <ModelVariables>\n", f);
    for (rank = 0; rank < N_RANKS; rank++)
        for (i = 0; i < info->n_vars; i++) {
            const FpVar *x = state_of(info, &info->vars[i]);
            if (listing_rank(info->vars[i].kind) != rank) continue;
            for (k = 0; k < fp_var_count(&info->vars[i]); k++)
                if (write_variable(f, &info->vars[i], k, model,
                                   x == NULL ? 0 : first[x - info->vars] + k) != 0) {
                    fprintf(stderr, "mdgen: name of %s too long\n", info->vars[i].name);
                    fclose(f);
                    free_initial_unknowns(&outputs);
                    free_initial_unknowns(&unknowns);
                    free(first);
                    free(model);
                    return 1;
                }
        }
    fputs("  </ModelVariables>\n", f);
    write_model_structure(f, info, first, &unknowns, &outputs);
    fputs("</fmiModelDescription>\n", f);
    free_initial_unknowns(&outputs);
    free_initial_unknowns(&unknowns);
    free(first);
    free(model);
    return fclose(f) == 0 ? 0 : 1;
}
