#if !defined(_WIN32)
#define _POSIX_C_SOURCE 199309L
#endif

#include "fp_clock.h"

#if defined(_WIN32)
#include <windows.h>

double fp_clock_seconds(void) {
    LARGE_INTEGER f, c;
    if (!QueryPerformanceFrequency(&f) || !QueryPerformanceCounter(&c)) return 0.0;
    return (double)c.QuadPart / (double)f.QuadPart;
}
#else
#include <time.h>

double fp_clock_seconds(void) {
    struct timespec ts;
    if (clock_gettime(CLOCK_MONOTONIC, &ts) != 0) return 0.0;
    return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
}
#endif
