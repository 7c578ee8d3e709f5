/* The signal table a model plays back: reading its file and finding a row (fp_table.h). */
#include "fp_table.h"

#include <math.h>
#include <string.h>

static uint32_t table_le32(const unsigned char *b) {
    return (uint32_t)b[0] | (uint32_t)b[1] << 8 | (uint32_t)b[2] << 16 | (uint32_t)b[3] << 24;
}

/* A little-endian IEEE double, whatever the host's byte order. */
static double table_le_double(const unsigned char *b) {
    uint64_t u = 0;
    double x;
    int i;
    for (i = 7; i >= 0; i--) u = u << 8 | b[i];
    memcpy(&x, &u, sizeof x);
    return x;
}

static FpStatus table_refuse(FpTable *t, char *why, size_t size, const char *text) {
    t->data = NULL;
    snprintf(why, size, "%s", text);
    return FP_ERROR;
}

FpStatus fp_table_read(FpTable *t, FILE *f, FpTableAlloc alloc, void *env, char *why,
                       size_t why_size) {
    unsigned char head[16], cell[1];
    size_t n, i, c;
    memset(t, 0, sizeof *t);
    if (fread(head, 1, sizeof head, f) != sizeof head || memcmp(head, FP_TABLE_MAGIC, 8) != 0)
        return table_refuse(t, why, why_size, "not a signal table (it must start with \"" FP_TABLE_MAGIC
                      "\")");
    t->rows = table_le32(head + 8);
    t->cols = table_le32(head + 12);
    if (t->rows < 1 || t->rows > FP_TABLE_MAX_ROWS) {
        snprintf(why, why_size, "%lu rows: a table has 1..%lu", (unsigned long)t->rows,
                 (unsigned long)FP_TABLE_MAX_ROWS);
        t->data = NULL;
        return FP_ERROR;
    }
    if (t->cols < 1 || t->cols > FP_TABLE_MAX_COLUMNS) {
        snprintf(why, why_size, "%lu value columns: a table has 1..%d", (unsigned long)t->cols,
                 FP_TABLE_MAX_COLUMNS);
        t->data = NULL;
        return FP_ERROR;
    }
    for (c = 0; c < t->cols; c++) {
        if (fread(t->names[c], 1, FP_TABLE_NAME_SIZE, f) != FP_TABLE_NAME_SIZE)
            return table_refuse(t, why, why_size, "the file ends inside the column names");
        if (t->names[c][FP_TABLE_NAME_SIZE - 1] != '\0' || t->names[c][0] == '\0') {
            snprintf(why, why_size, "column %lu: its name is empty or longer than %d bytes",
                     (unsigned long)c + 1, FP_TABLE_NAME_SIZE - 1);
            t->data = NULL;
            return FP_ERROR;
        }
    }
    if ((size_t)t->rows > (size_t)-1 / sizeof(double) / (1u + t->cols)) {
        snprintf(why, why_size, "%lu rows do not fit in this process's memory",
                 (unsigned long)t->rows);
        t->data = NULL;
        return FP_ERROR;
    }
    n = (size_t)t->rows * (1u + t->cols);
    t->data = (double *)alloc(env, n, sizeof(double));
    if (t->data == NULL) {
        snprintf(why, why_size, "out of memory for %lu rows", (unsigned long)t->rows);
        return FP_ERROR;
    }
    for (i = 0; i < t->rows; i++) {
        unsigned char buf[(1 + FP_TABLE_MAX_COLUMNS) * 8];
        size_t width = 1u + t->cols;
        if (fread(buf, 8, width, f) != width) {
            snprintf(why, why_size, "the file ends in row %lu of %lu (truncated)",
                     (unsigned long)i + 1, (unsigned long)t->rows);
            return FP_ERROR; /* the caller frees t->data */
        }
        for (c = 0; c < width; c++) t->data[i * width + c] = table_le_double(buf + 8 * c);
    }
    if (fread(cell, 1, 1, f) != 0) {
        snprintf(why, why_size, "bytes after the last of its %lu rows", (unsigned long)t->rows);
        return FP_ERROR;
    }
    t->min_spacing = 0.0;
    for (i = 0; i < t->rows; i++) {
        const double *row = fp_table_row(t, (uint32_t)i);
        for (c = 0; c <= t->cols; c++) {
            if (!isfinite(row[c])) {
                snprintf(why, why_size, "row %lu, column %s: %g is not finite",
                         (unsigned long)i + 1, c == 0 ? "time" : t->names[c - 1], row[c]);
                return FP_ERROR;
            }
        }
        if (i > 0) {
            double gap = row[0] - fp_table_row(t, (uint32_t)i - 1)[0];
            if (!(gap > 0.0)) {
                snprintf(why, why_size, "row %lu: time %.17g does not follow %.17g (times must "
                         "increase)", (unsigned long)i + 1, row[0],
                         fp_table_row(t, (uint32_t)i - 1)[0]);
                return FP_ERROR;
            }
            if (i == 1 || gap < t->min_spacing) t->min_spacing = gap;
        }
    }
    return FP_OK;
}

int fp_table_column(const FpTable *t, const char *name) {
    uint32_t c;
    for (c = 0; c < t->cols; c++)
        if (strcmp(t->names[c], name) == 0) return (int)c;
    return -1;
}

uint32_t fp_table_row_at(const FpTable *t, double time, double tol) {
    /* binary search: the first row after time + tol, minus one */
    uint32_t lo = 0, hi = t->rows;
    double limit = time + tol;
    while (lo < hi) {
        uint32_t mid = lo + (hi - lo) / 2;
        if (fp_table_row(t, mid)[0] <= limit)
            lo = mid + 1;
        else
            hi = mid;
    }
    return lo > 0 ? lo - 1 : 0;
}
