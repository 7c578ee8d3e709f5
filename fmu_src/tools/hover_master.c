/*
 * hover_master: a minimal FMI 2.0 co-simulation master, to prove that an FMU binary of any
 * platform runs (natively, under Wine or under qemu-user) and to compare its trajectory
 * with the native one.  It knows nothing about our models: a script says what to load,
 * what to set, what to connect and what to print.
 *
 *     hover_master SCRIPT
 *
 * SCRIPT holds one command per line, run in order ('#' starts a comment):
 *
 *     fmu ID LIBRARY GUID RESOURCE_URI  load LIBRARY and instantiate it (co-simulation)
 *     real|integer|boolean ID VR VALUE  set one variable now
 *     enter ID START_TIME               fmi2SetupExperiment + fmi2EnterInitializationMode
 *     exit ID                           fmi2ExitInitializationMode
 *     link FROM VR TO VR                a Real output of FROM feeds a Real input of TO
 *     sync ID                           copy every link into ID now
 *     print ID VR                       one more Real column of the printed trajectory
 *     run STEP N EVERY ID...            N communication steps of STEP seconds: in each, the
 *                                       FMUs in the order given take their links (sync) and
 *                                       do the step; prints "t col..." (%.17g) at step 0,
 *                                       every EVERY steps, and after the last
 *
 * Everything ends with fmi2Terminate and fmi2FreeInstance.  Exit status 0: every FMI call
 * returned fmi2OK or fmi2Warning; 1: a call failed, a library or function was missing, or
 * the script is wrong (the message says which line); 2: usage.
 */
#if !defined(_WIN32)
#define _POSIX_C_SOURCE 200809L
#endif

#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fmi2FunctionTypes.h"

#if defined(_WIN32)
#include <windows.h>
#else
#include <dlfcn.h>
#endif

#define MAX_FMUS 4
#define MAX_LINKS 256
#define MAX_COLUMNS 64
#define MAX_LINE 4096
#define ID_LEN 32

typedef struct {
    char id[ID_LEN];
    void *library;
    fmi2Component c;
    int instantiated;
    fmi2InstantiateTYPE *instantiate;
    fmi2FreeInstanceTYPE *free_instance;
    fmi2SetupExperimentTYPE *setup_experiment;
    fmi2EnterInitializationModeTYPE *enter_init;
    fmi2ExitInitializationModeTYPE *exit_init;
    fmi2TerminateTYPE *terminate;
    fmi2GetRealTYPE *get_real;
    fmi2SetRealTYPE *set_real;
    fmi2SetIntegerTYPE *set_integer;
    fmi2SetBooleanTYPE *set_boolean;
    fmi2DoStepTYPE *do_step;
} Fmu;

typedef struct {
    int from, to;
    fmi2ValueReference from_vr, to_vr;
} Link;

typedef struct {
    int fmu;
    fmi2ValueReference vr;
} Column;

typedef struct {
    Fmu fmus[MAX_FMUS];
    int n_fmus;
    Link links[MAX_LINKS];
    int n_links;
    Column columns[MAX_COLUMNS];
    int n_columns;
    fmi2CallbackFunctions callbacks;
    const char *script;
    int line;
} Master;

static void logger(fmi2ComponentEnvironment env, fmi2String instance, fmi2Status status,
                   fmi2String category, fmi2String message, ...) {
    va_list args;
    (void)env;
    fprintf(stderr, "[%s] %s (status %d): ", instance ? instance : "?", category ? category : "",
            (int)status);
    va_start(args, message);
    vfprintf(stderr, message ? message : "", args);
    va_end(args);
    fputc('\n', stderr);
}

static int fail(const Master *m, const char *what, const char *detail) {
    fprintf(stderr, "hover_master: %s:%d: %s%s%s\n", m->script, m->line, what,
            detail ? ": " : "", detail ? detail : "");
    return -1;
}

static int check(const Master *m, fmi2Status status, const char *call) {
    if (status == fmi2OK || status == fmi2Warning) return 0;
    fprintf(stderr, "hover_master: %s:%d: %s returned status %d\n", m->script, m->line, call,
            (int)status);
    return -1;
}

/* A function of the loaded library; an object pointer copied into a function pointer with
 * memcpy, as ISO C has no conversion between the two. */
static int symbol(const Master *m, void *library, const char *name, void *fn, size_t size) {
#if defined(_WIN32)
    FARPROC p = GetProcAddress((HMODULE)library, name);
    if (p == NULL || size != sizeof p) return fail(m, "function not exported", name);
    memcpy(fn, &p, size);
#else
    void *p = dlsym(library, name);
    if (p == NULL || size != sizeof p) return fail(m, "function not exported", name);
    memcpy(fn, &p, size);
#endif
    return 0;
}

#define SYMBOL(m, f, member, name) symbol(m, (f)->library, name, &(f)->member, sizeof (f)->member)

static int load(Master *m, Fmu *f, const char *path) {
#if defined(_WIN32)
    f->library = (void *)LoadLibraryA(path);
    if (f->library == NULL) return fail(m, "cannot load library", path);
#else
    f->library = dlopen(path, RTLD_NOW | RTLD_LOCAL);
    if (f->library == NULL) return fail(m, "cannot load library", dlerror());
#endif
    if (SYMBOL(m, f, instantiate, "fmi2Instantiate")
        || SYMBOL(m, f, free_instance, "fmi2FreeInstance")
        || SYMBOL(m, f, setup_experiment, "fmi2SetupExperiment")
        || SYMBOL(m, f, enter_init, "fmi2EnterInitializationMode")
        || SYMBOL(m, f, exit_init, "fmi2ExitInitializationMode")
        || SYMBOL(m, f, terminate, "fmi2Terminate") || SYMBOL(m, f, get_real, "fmi2GetReal")
        || SYMBOL(m, f, set_real, "fmi2SetReal") || SYMBOL(m, f, set_integer, "fmi2SetInteger")
        || SYMBOL(m, f, set_boolean, "fmi2SetBoolean") || SYMBOL(m, f, do_step, "fmi2DoStep"))
        return -1;
    return 0;
}

static void unload(Fmu *f) {
    if (f->instantiated) {
        f->terminate(f->c);
        f->free_instance(f->c);
        f->instantiated = 0;
    }
    if (f->library != NULL) {
#if defined(_WIN32)
        FreeLibrary((HMODULE)f->library);
#else
        dlclose(f->library);
#endif
        f->library = NULL;
    }
}

static int find(const Master *m, const char *id) {
    int i;
    for (i = 0; i < m->n_fmus; i++)
        if (strcmp(m->fmus[i].id, id) == 0) return i;
    fail(m, "unknown FMU", id);
    return -1;
}

static int parse_vr(const Master *m, const char *text, fmi2ValueReference *vr) {
    char *end;
    unsigned long v = strtoul(text, &end, 10);
    if (*text == '\0' || *end != '\0' || v > 0xFFFFFFFFul)
        return fail(m, "bad value reference", text);
    *vr = (fmi2ValueReference)v;
    return 0;
}

static int parse_real(const Master *m, const char *text, double *x) {
    char *end;
    *x = strtod(text, &end);
    if (*text == '\0' || *end != '\0') return fail(m, "bad number", text);
    return 0;
}

static int parse_long(const Master *m, const char *text, long lo, long *x) {
    char *end;
    *x = strtol(text, &end, 10);
    if (*text == '\0' || *end != '\0' || *x < lo) return fail(m, "bad integer", text);
    return 0;
}

static int sync_inputs(Master *m, int to) {
    int i;
    for (i = 0; i < m->n_links; i++) {
        const Link *l = &m->links[i];
        fmi2Real v;
        if (l->to != to) continue;
        if (check(m, m->fmus[l->from].get_real(m->fmus[l->from].c, &l->from_vr, 1, &v),
                  "fmi2GetReal")
            || check(m, m->fmus[to].set_real(m->fmus[to].c, &l->to_vr, 1, &v), "fmi2SetReal"))
            return -1;
    }
    return 0;
}

static int print_row(const Master *m, double t) {
    int i;
    printf("%.17g", t);
    for (i = 0; i < m->n_columns; i++) {
        const Fmu *f = &m->fmus[m->columns[i].fmu];
        fmi2Real v;
        if (check(m, f->get_real(f->c, &m->columns[i].vr, 1, &v), "fmi2GetReal")) return -1;
        printf(" %.17g", v);
    }
    putchar('\n');
    return 0;
}

static int cmd_fmu(Master *m, char **arg, int n) {
    Fmu *f;
    if (n != 5) return fail(m, "usage", "fmu ID LIBRARY GUID RESOURCE_URI");
    if (m->n_fmus == MAX_FMUS) return fail(m, "too many FMUs", NULL);
    if (strlen(arg[1]) >= ID_LEN) return fail(m, "FMU id too long", arg[1]);
    f = &m->fmus[m->n_fmus++];
    memcpy(f->id, arg[1], strlen(arg[1]) + 1);
    if (load(m, f, arg[2]) != 0) return -1;
    f->c = f->instantiate(f->id, fmi2CoSimulation, arg[3], arg[4], &m->callbacks, fmi2False,
                          fmi2False);
    if (f->c == NULL) return fail(m, "fmi2Instantiate failed", f->id);
    f->instantiated = 1;
    return 0;
}

static int cmd_set(Master *m, char **arg, int n) {
    fmi2ValueReference vr;
    int i;
    Fmu *f;
    if (n != 4) return fail(m, "usage", "real|integer|boolean ID VR VALUE");
    if ((i = find(m, arg[1])) < 0 || parse_vr(m, arg[2], &vr) != 0) return -1;
    f = &m->fmus[i];
    if (strcmp(arg[0], "real") == 0) {
        double x;
        if (parse_real(m, arg[3], &x) != 0) return -1;
        return check(m, f->set_real(f->c, &vr, 1, &x), "fmi2SetReal");
    } else {
        long x;
        fmi2Integer iv;
        fmi2Boolean bv;
        if (parse_long(m, arg[3], -2147483647L - 1, &x) != 0) return -1;
        if (strcmp(arg[0], "integer") == 0) {
            iv = (fmi2Integer)x;
            return check(m, f->set_integer(f->c, &vr, 1, &iv), "fmi2SetInteger");
        }
        bv = x != 0 ? fmi2True : fmi2False;
        return check(m, f->set_boolean(f->c, &vr, 1, &bv), "fmi2SetBoolean");
    }
}

static int cmd_link(Master *m, char **arg, int n) {
    Link *l;
    if (n != 5) return fail(m, "usage", "link FROM VR TO VR");
    if (m->n_links == MAX_LINKS) return fail(m, "too many links", NULL);
    l = &m->links[m->n_links];
    if ((l->from = find(m, arg[1])) < 0 || parse_vr(m, arg[2], &l->from_vr) != 0
        || (l->to = find(m, arg[3])) < 0 || parse_vr(m, arg[4], &l->to_vr) != 0)
        return -1;
    m->n_links++;
    return 0;
}

static int cmd_run(Master *m, char **arg, int n) {
    double h;
    long steps, every, k;
    int order[MAX_FMUS], n_order = n - 4, i;
    if (n < 5 || n_order > MAX_FMUS) return fail(m, "usage", "run STEP N EVERY ID...");
    if (parse_real(m, arg[1], &h) != 0 || parse_long(m, arg[2], 1, &steps) != 0
        || parse_long(m, arg[3], 1, &every) != 0)
        return -1;
    if (!(h > 0.0)) return fail(m, "the step must be positive", arg[1]);
    for (i = 0; i < n_order; i++)
        if ((order[i] = find(m, arg[4 + i])) < 0) return -1;
    for (k = 0; k < steps; k++) {
        double t = (double)k * h;
        if (k % every == 0 && print_row(m, t) != 0) return -1;
        for (i = 0; i < n_order; i++) {
            Fmu *f = &m->fmus[order[i]];
            if (sync_inputs(m, order[i]) != 0
                || check(m, f->do_step(f->c, t, h, fmi2True), "fmi2DoStep"))
                return -1;
        }
    }
    return print_row(m, (double)steps * h);
}

static int command(Master *m, char **arg, int n) {
    int i;
    double t0;
    fmi2ValueReference vr;
    if (strcmp(arg[0], "fmu") == 0) return cmd_fmu(m, arg, n);
    if (strcmp(arg[0], "real") == 0 || strcmp(arg[0], "integer") == 0
        || strcmp(arg[0], "boolean") == 0)
        return cmd_set(m, arg, n);
    if (strcmp(arg[0], "link") == 0) return cmd_link(m, arg, n);
    if (strcmp(arg[0], "run") == 0) return cmd_run(m, arg, n);
    if (strcmp(arg[0], "enter") == 0) {
        if (n != 3) return fail(m, "usage", "enter ID START_TIME");
        if ((i = find(m, arg[1])) < 0 || parse_real(m, arg[2], &t0) != 0) return -1;
        return check(m, m->fmus[i].setup_experiment(m->fmus[i].c, fmi2False, 0.0, t0, fmi2False,
                                                    0.0),
                     "fmi2SetupExperiment")
               || check(m, m->fmus[i].enter_init(m->fmus[i].c), "fmi2EnterInitializationMode");
    }
    if (strcmp(arg[0], "exit") == 0) {
        if (n != 2) return fail(m, "usage", "exit ID");
        if ((i = find(m, arg[1])) < 0) return -1;
        return check(m, m->fmus[i].exit_init(m->fmus[i].c), "fmi2ExitInitializationMode");
    }
    if (strcmp(arg[0], "sync") == 0) {
        if (n != 2) return fail(m, "usage", "sync ID");
        if ((i = find(m, arg[1])) < 0) return -1;
        return sync_inputs(m, i);
    }
    if (strcmp(arg[0], "print") == 0) {
        if (n != 3) return fail(m, "usage", "print ID VR");
        if (m->n_columns == MAX_COLUMNS) return fail(m, "too many columns", NULL);
        if ((i = find(m, arg[1])) < 0 || parse_vr(m, arg[2], &vr) != 0) return -1;
        m->columns[m->n_columns].fmu = i;
        m->columns[m->n_columns++].vr = vr;
        return 0;
    }
    return fail(m, "unknown command", arg[0]);
}

/* Splits a line into at most max words separated by blanks; '#' starts a comment. */
static int split(char *line, char **arg, int max) {
    int n = 0;
    char *p = line;
    char *hash = strchr(line, '#');
    if (hash != NULL) *hash = '\0';
    while (*p != '\0') {
        while (*p == ' ' || *p == '\t' || *p == '\r' || *p == '\n') *p++ = '\0';
        if (*p == '\0') break;
        if (n == max) return -1;
        arg[n++] = p;
        while (*p != '\0' && *p != ' ' && *p != '\t' && *p != '\r' && *p != '\n') p++;
    }
    return n;
}

static int run_script(Master *m, FILE *in) {
    char line[MAX_LINE];
    char *arg[4 + MAX_FMUS];
    while (fgets(line, sizeof line, in) != NULL) {
        int n;
        m->line++;
        if (strchr(line, '\n') == NULL && !feof(in)) return fail(m, "line too long", NULL);
        n = split(line, arg, (int)(sizeof arg / sizeof arg[0]));
        if (n < 0) return fail(m, "too many words", NULL);
        if (n > 0 && command(m, arg, n) != 0) return -1;
    }
    return ferror(in) ? fail(m, "read error", NULL) : 0;
}

int main(int argc, char **argv) {
    Master *m;
    FILE *in;
    int status, i;
    if (argc != 2) {
        fprintf(stderr, "usage: hover_master SCRIPT\n");
        return 2;
    }
    m = calloc(1, sizeof *m);
    if (m == NULL) return 1;
    m->script = argv[1];
    m->callbacks.logger = logger;
    m->callbacks.allocateMemory = calloc;
    m->callbacks.freeMemory = free;
    in = fopen(argv[1], "r");
    if (in == NULL) {
        perror(argv[1]);
        free(m);
        return 1;
    }
    status = run_script(m, in);
    fclose(in);
    for (i = m->n_fmus - 1; i >= 0; i--) unload(&m->fmus[i]);
    free(m);
    return fflush(stdout) == 0 && status == 0 ? 0 : 1;
}
