/*
 * A table of samples a model plays back (FpModelInfo.table_resource): time in the first
 * column, named value columns beside it, read once from a file of the FMU's resources/ and
 * read-only after that.  The glue loads it and hands it to the model through its FpLogger
 * (fp_model.h), so the model struct stays free of pointers and FMU states stay memcpy
 * snapshots: a restored state finds the instance's own table.
 *
 * The file ("fullpose signal table", version 1), every number little-endian:
 *
 *     8 bytes   "FPTABLE1"
 *     uint32    rows (at least 1)
 *     uint32    cols, the value columns (1..FP_TABLE_MAX_COLUMNS)
 *     cols x FP_TABLE_NAME_SIZE bytes   the columns' names, NUL-padded (e.g. "pos_ref[1]")
 *     rows x (1 + cols) float64   row by row: time (s), then the values
 *
 * and nothing after.  Times are finite and strictly increasing; values finite.  Binary, so
 * that every double reads back to the bit on every platform and in every locale (a decimal
 * text would depend on the C library's strtod and the importer's locale).
 */
#ifndef FP_TABLE_H
#define FP_TABLE_H

#include <stddef.h>
#include <stdint.h>
#include <stdio.h>

#include "fp_model.h"

#define FP_TABLE_MAGIC "FPTABLE1"
#define FP_TABLE_MAX_COLUMNS 64
#define FP_TABLE_NAME_SIZE 32
/* 2^27 rows: 74 hours at 2 ms; beyond it a table is refused before anything is allocated */
#define FP_TABLE_MAX_ROWS 134217728u

typedef struct FpTable {
    uint32_t rows, cols;
    char names[FP_TABLE_MAX_COLUMNS][FP_TABLE_NAME_SIZE];
    double *data; /* rows x (1 + cols), row-major: time, then the values */
    double min_spacing; /* the smallest time between consecutive rows (0 for one row) */
} FpTable;

/* Memory for the table's data (the importer's allocator, through the glue): n zeroed
 * elements of size bytes, or NULL. */
typedef void *(*FpTableAlloc)(void *env, size_t n, size_t size);

/*
 * Reads a table file into *t (its data from alloc).  FP_OK, or FP_ERROR with the reason in
 * why (a truncated file, a bad header, times not increasing, a value not finite, naming the
 * row and column); *t then holds no data.
 */
FpStatus fp_table_read(FpTable *t, FILE *f, FpTableAlloc alloc, void *env, char *why,
                       size_t why_size);

/* The value column called name, or -1. */
int fp_table_column(const FpTable *t, const char *name);

/* The last row whose time is at most time + tol (row 0 before the first row's time). */
uint32_t fp_table_row_at(const FpTable *t, double time, double tol);

/* Element [row, 0] is the row's time, [row, 1 + c] value column c. */
static inline const double *fp_table_row(const FpTable *t, uint32_t row) {
    return t->data + (size_t)row * (1u + t->cols);
}

#endif
