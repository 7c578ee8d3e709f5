/*
 * Writes modelDescription.xml for the model it is linked with, straight from
 * the model's variable table and default values, so the XML and the binary
 * cannot drift.  Run at build time:
 *
 *     mdgen OUTPUT.xml VERSION [--sources DIR FILE.c ...]
 *
 * With --sources, the C files the FMU's binary is built from (the build's one list of them,
 * as laid out flat in the FMU's sources/ folder DIR) go into the FMI 2.0 <SourceFiles> of
 * <CoSimulation> and into DIR/buildDescription.xml (the FMI 2.0.4 / FMI 3.0 form).
 */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fp_model.h"

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
    {"rad", 0, 0, 0, 1, {"deg", NULL}, {57.295779513082323, 0}},
    {"rad/s", 0, 0, -1, 1, {"rpm", "deg/s"}, {9.5492965855137202, 57.295779513082323}},
    {"rad/s2", 0, 0, -2, 1, {"deg/s2", NULL}, {57.295779513082323, 0}},
    {"N", 1, 1, -2, 0, {NULL, NULL}, {0, 0}},
    {"N.m", 1, 2, -2, 0, {NULL, NULL}, {0, 0}},
    {"N.s2/rad2", 1, 1, 0, -2, {NULL, NULL}, {0, 0}},
    {"N.m.s2/rad2", 1, 2, 0, -2, {NULL, NULL}, {0, 0}},
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

static void write_units(FILE *f, const FpModelInfo *info) {
    size_t i, j;
    fputs("  <UnitDefinitions>\n", f);
    for (i = 0; i < N_UNITS; i++) {
        int used = 0;
        const Unit *u = &units[i];
        for (j = 0; j < info->n_vars; j++) used |= strcmp(info->vars[j].unit, u->name) == 0;
        if (!used) continue;
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

static int write_variable(FILE *f, const FpVar *v, uint32_t k, const void *model) {
    static const char *const causality[] = {"parameter", "parameter", "input", "output"};
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
    fprintf(f, "\">\n      <%s", tag[v->type]);
    if (v->type == FP_REAL && v->unit[0] != '\0') fprintf(f, " unit=\"%s\"", v->unit);
    if (v->kind != FP_OUTPUT) {
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

static int check_table(const FpModelInfo *info) {
    size_t i, j;
    for (i = 0; i < info->n_vars; i++) {
        const FpVar *a = &info->vars[i];
        if (a->type == FP_REAL && find_unit(a->unit) == NULL && a->unit[0] != '\0') {
            fprintf(stderr, "mdgen: variable %s uses undefined unit '%s'\n", a->name, a->unit);
            return -1;
        }
        if (a->type != FP_REAL && a->unit[0] != '\0') {
            fprintf(stderr, "mdgen: non-Real variable %s has a unit\n", a->name);
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

int main(int argc, char **argv) {
    const FpModelInfo *info = fp_model_info();
    char guid[40];
    void *model;
    FILE *f;
    size_t i;
    uint32_t k, index = 0;
    int c;
    SourceList src = {NULL, NULL, 0};
    if (argc < 3 || (argc > 3 && (strcmp(argv[3], "--sources") != 0 || argc < 6))) {
        fprintf(stderr, "usage: mdgen OUTPUT.xml VERSION [--sources DIR FILE.c ...]\n");
        return 2;
    }
    if (argc > 3) {
        src.dir = argv[4];
        src.files = argv + 5;
        src.n = argc - 5;
        if (write_build_description(info, &src) != 0) return 1;
    }
    if (check_table(info) != 0) return 1;
    model = calloc(1, info->model_size);
    if (model == NULL) return 1;
    info->set_defaults(model);
    fp_model_guid(info, guid);
    f = fopen(argv[1], "w");
    if (f == NULL) {
        perror(argv[1]);
        free(model);
        return 1;
    }
    fputs("<?xml version=\"1.0\" encoding=\"UTF-8\"?>\n", f);
    fprintf(f,
            "<fmiModelDescription fmiVersion=\"2.0\" modelName=\"%s\" guid=\"%s\"\n"
            "  description=\"",
            info->model_name, guid);
    xml_text(f, info->description);
    fprintf(f,
            "\"\n  version=\"%s\" generationTool=\"fullpose mdgen\""
            " variableNamingConvention=\"structured\" numberOfEventIndicators=\"0\">\n",
            argv[2]);
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
    write_units(f, info);
    fputs("  <LogCategories>\n", f);
    for (c = 0; c < FP_LOG_N_CATEGORIES; c++)
        fprintf(f, "    <Category name=\"%s\" description=\"%s\"/>\n", fp_log_category_name(c),
                fp_log_category_description(c));
    fputs("  </LogCategories>\n", f);
    fprintf(f, "  <DefaultExperiment startTime=\"0\" stopTime=\"%.17g\" stepSize=\"%.17g\"/>\n",
            info->default_stop, info->default_step);
    fputs("  <ModelVariables>\n", f);
    for (i = 0; i < info->n_vars; i++)
        for (k = 0; k < fp_var_count(&info->vars[i]); k++)
            if (write_variable(f, &info->vars[i], k, model) != 0) {
                fprintf(stderr, "mdgen: name of %s too long\n", info->vars[i].name);
                fclose(f);
                free(model);
                return 1;
            }
    /* Outputs are computed at the end of a step from the held inputs: no direct
     * feedthrough, so no output depends on an input (no algebraic loop for masters). */
    fputs("  </ModelVariables>\n  <ModelStructure>\n    <Outputs>\n", f);
    for (i = 0; i < info->n_vars; i++)
        for (k = 0; k < fp_var_count(&info->vars[i]); k++) {
            index++;
            if (info->vars[i].kind == FP_OUTPUT)
                fprintf(f, "      <Unknown index=\"%u\" dependencies=\"\"/>\n", (unsigned)index);
        }
    fputs("    </Outputs>\n    <InitialUnknowns>\n", f);
    index = 0;
    for (i = 0; i < info->n_vars; i++)
        for (k = 0; k < fp_var_count(&info->vars[i]); k++) {
            index++;
            if (info->vars[i].kind == FP_OUTPUT)
                fprintf(f, "      <Unknown index=\"%u\"/>\n", (unsigned)index);
        }
    fputs("    </InitialUnknowns>\n  </ModelStructure>\n</fmiModelDescription>\n", f);
    free(model);
    return fclose(f) == 0 ? 0 : 1;
}
