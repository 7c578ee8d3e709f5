/*
 * The FMU's resources/ folder (FMI 2.0 fmuResourceLocation): the table a model plays back
 * (FpModelInfo.table_resource) is read from it at instantiation.  Part of the FMI 2.0 glue
 * (fmi2_glue_internal.h): the location is an FMI argument, the table it holds is not.
 */
#include <stdio.h>
#include <string.h>

#include "fmi2_glue_internal.h"

/* Longest path to a resource this glue opens; beyond it instantiation is refused. */
#define RESOURCE_PATH_MAX 4096

static int resource_hex_digit(char c) {
    if (c >= '0' && c <= '9') return c - '0';
    if (c >= 'a' && c <= 'f') return c - 'a' + 10;
    if (c >= 'A' && c <= 'F') return c - 'A' + 10;
    return -1;
}

/*
 * The local path of the file `name` inside the folder that the URI `location` names: "file:"
 * URIs as importers write them ("file:///home/u/x/resources/", "file:/home/u/x/resources",
 * "file://localhost/...", on Windows "file:///C:/..." and "file://server/share/..."),
 * percent-escapes decoded.  0, or -1 with the reason in why.
 */
static int resource_path(const char *location, const char *name, char *path, size_t size,
                         char *why, size_t why_size) {
    const char *p;
    size_t n = 0;
    if (location == NULL || location[0] == '\0') {
        snprintf(why, why_size, "fmuResourceLocation is empty: the importer gave no resources/ "
                 "folder");
        return -1;
    }
    if (strncmp(location, "file:", 5) != 0 && strncmp(location, "FILE:", 5) != 0) {
        snprintf(why, why_size, "fmuResourceLocation \"%.200s\" is no file: URI", location);
        return -1;
    }
    p = location + 5;
    if (strncmp(p, "//", 2) == 0) { /* an authority: empty, localhost, or a server */
        p += 2;
        if (strncmp(p, "localhost/", 10) == 0) {
            p += 9;
        } else if (*p != '/') {
#if defined(_WIN32)
            path[n++] = '\\'; /* a UNC path: \\server\share\... */
            path[n++] = '\\';
#else
            snprintf(why, why_size, "fmuResourceLocation \"%.200s\" names another host",
                     location);
            return -1;
#endif
        }
    }
#if defined(_WIN32)
    /* "/C:/..." is the drive C: */
    if (p[0] == '/' && p[1] != '\0' && p[2] == ':') p++;
#endif
    while (*p != '\0') {
        char c = *p++;
        if (c == '%') {
            int hi = resource_hex_digit(p[0]), lo = hi < 0 ? -1 : resource_hex_digit(p[1]);
            if (hi < 0 || lo < 0) {
                snprintf(why, why_size, "fmuResourceLocation \"%.200s\": a bad %%-escape",
                         location);
                return -1;
            }
            c = (char)(hi * 16 + lo);
            p += 2;
        }
        if (n + 1 >= size) break;
        path[n++] = c;
    }
    if (n > 0 && path[n - 1] != '/' && path[n - 1] != '\\' && n + 1 < size) path[n++] = '/';
    if (n + strlen(name) + 1 > size) {
        snprintf(why, why_size, "the path of resources/%s is longer than %d bytes", name,
                 RESOURCE_PATH_MAX - 1);
        return -1;
    }
    strcpy(path + n, name);
    return 0;
}

static void *table_alloc(void *env, size_t n, size_t size) {
    Instance *inst = (Instance *)env;
    return inst->allocate(n, size);
}

int glue_load_table(Instance *inst, fmi2String location, char *why, size_t why_size) {
    const char *name = inst->info->table_resource;
    char path[RESOURCE_PATH_MAX], reason[256];
    FILE *f;
    FpStatus s;
    if (resource_path(location, name, path, sizeof path, reason, sizeof reason) != 0) {
        snprintf(why, why_size, "%s needs resources/%s: %s", inst->info->model_name, name,
                 reason);
        return -1;
    }
    f = fopen(path, "rb");
    if (f == NULL) {
        snprintf(why, why_size, "%s cannot open its table %.300s (resources/%s is missing or "
                 "unreadable)", inst->info->model_name, path, name);
        return -1;
    }
    s = fp_table_read(&inst->table, f, table_alloc, inst, reason, sizeof reason);
    fclose(f);
    if (s != FP_OK) {
        if (inst->table.data != NULL) inst->release(inst->table.data);
        inst->table.data = NULL;
        snprintf(why, why_size, "%s: table %.300s: %s", inst->info->model_name, path, reason);
        return -1;
    }
    inst->model_logger.table = &inst->table;
    return 0;
}
