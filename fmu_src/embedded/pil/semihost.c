/*
 * Arm semihosting calls (Arm's "Semihosting for AArch32 and AArch64", operations SYS_OPEN
 * 0x01, SYS_WRITE0 0x04, SYS_WRITE 0x05, SYS_READ 0x06, SYS_EXIT_EXTENDED 0x20): on M-profile,
 * BKPT 0xAB with the operation in r0 and the argument block's address in r1; the result in
 * r0.  QEMU answers them with -semihosting-config enable=on,target=native.
 */
#include "semihost.h"

#include <stdint.h>
#include <string.h>

enum { SYS_OPEN = 0x01, SYS_WRITE0 = 0x04, SYS_WRITE = 0x05, SYS_READ = 0x06,
       SYS_EXIT_EXTENDED = 0x20 };

static int32_t call(int32_t op, const void *arg) {
    register int32_t r0 __asm__("r0") = op;
    register const void *r1 __asm__("r1") = arg;
    __asm__ volatile("bkpt 0xab" : "+r"(r0) : "r"(r1) : "memory");
    return r0;
}

int semihost_open(const char *path, int write) {
    /* mode 1 is "rb", 5 is "wb" (the ISO C modes in the order the specification lists) */
    uint32_t arg[3];
    arg[0] = (uint32_t)(uintptr_t)path;
    arg[1] = write ? 5u : 1u;
    arg[2] = (uint32_t)strlen(path);
    return call(SYS_OPEN, arg);
}

int semihost_read_all(int handle, void *buf, size_t n) {
    char *p = (char *)buf;
    while (n > 0) {
        uint32_t arg[3];
        int32_t left;
        arg[0] = (uint32_t)handle;
        arg[1] = (uint32_t)(uintptr_t)p;
        arg[2] = (uint32_t)n;
        left = call(SYS_READ, arg); /* the count NOT read */
        if (left < 0 || (size_t)left >= n) return -1;
        p += n - (size_t)left;
        n = (size_t)left;
    }
    return 0;
}

int semihost_write_all(int handle, const void *buf, size_t n) {
    uint32_t arg[3];
    arg[0] = (uint32_t)handle;
    arg[1] = (uint32_t)(uintptr_t)buf;
    arg[2] = (uint32_t)n;
    return call(SYS_WRITE, arg) == 0 ? 0 : -1;
}

void semihost_say(const char *text) { (void)call(SYS_WRITE0, text); }

void semihost_exit(int code) {
    uint32_t arg[2];
    arg[0] = 0x20026u; /* ADP_Stopped_ApplicationExit */
    arg[1] = (uint32_t)code;
    (void)call(SYS_EXIT_EXTENDED, arg);
    for (;;) {
    }
}
