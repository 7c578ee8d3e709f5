/* Arm semihosting (the debugger's, here QEMU's): files on the host, exit with a code. */
#ifndef PIL_SEMIHOST_H
#define PIL_SEMIHOST_H

#include <stddef.h>

/* A host file opened for reading ("rb") or writing ("wb"): a handle >= 0, else -1. */
int semihost_open(const char *path, int write);
/* Read exactly n bytes: 0, or -1 when the file ended or failed first. */
int semihost_read_all(int handle, void *buf, size_t n);
/* Write n bytes: 0, or -1. */
int semihost_write_all(int handle, const void *buf, size_t n);
/* Write a line of text to the host's console (QEMU's standard error). */
void semihost_say(const char *text);
/* Stop the machine: QEMU exits with code. */
void semihost_exit(int code);

#endif
