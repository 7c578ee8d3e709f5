/*
 * The FMU's resources/ folder (FMI 3.0 resourcePath): the table a model plays back
 * (FpModelInfo.table_resource) is read from it at instantiation.  FMI 3.0 passes the folder
 * as a native path ending with the platform's separator ("/tmp/x/resources/",
 * "C:\\x\\resources\\"), no longer as the file: URI of FMI 2.0 (fmi2_resources.c); a path
 * given without the final separator is taken as well.  Part of the FMI 3.0 glue
 * (fmi3_glue_internal.h); it calls nothing of the other glue files.
 */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fmi3_glue_internal.h"

/* Longest path to a resource this glue opens; beyond it instantiation is refused. */
#define G3_RESOURCE_PATH_MAX 4096

static void *table_alloc(void *env, size_t n, size_t size) {
    (void)env;
    return calloc(n, size);
}

int g3_load_table(Fmi3Instance *inst, fmi3String resource_path, char *why, size_t why_size) {
    const char *name = inst->info->table_resource;
    char path[G3_RESOURCE_PATH_MAX], reason[256];
    size_t n;
    FILE *f;
    FpStatus s;
    if (resource_path == NULL || resource_path[0] == '\0') {
        snprintf(why, why_size,
                 "%s needs resources/%s: resourcePath is %s: the importer gave no resources/ "
                 "folder",
                 inst->info->model_name, name, resource_path == NULL ? "NULL" : "empty");
        return -1;
    }
    n = strlen(resource_path);
    if (n + 1 + strlen(name) + 1 > sizeof path) {
        snprintf(why, why_size, "%s needs resources/%s: its path is longer than %d bytes",
                 inst->info->model_name, name, G3_RESOURCE_PATH_MAX - 1);
        return -1;
    }
    strcpy(path, resource_path);
    if (path[n - 1] != '/' && path[n - 1] != '\\') {
#if defined(_WIN32)
        path[n++] = '\\';
#else
        path[n++] = '/';
#endif
        path[n] = '\0';
    }
    strcpy(path + n, name);
    f = fopen(path, "rb");
    if (f == NULL) {
        snprintf(why, why_size,
                 "%s cannot open its table %.300s (resources/%s is missing or unreadable)",
                 inst->info->model_name, path, name);
        return -1;
    }
    s = fp_table_read(&inst->table, f, table_alloc, inst, reason, sizeof reason);
    fclose(f);
    if (s != FP_OK) {
        free(inst->table.data);
        inst->table.data = NULL;
        snprintf(why, why_size, "%s: table %.300s: %s", inst->info->model_name, path, reason);
        return -1;
    }
    inst->model_logger.table = &inst->table;
    return 0;
}
