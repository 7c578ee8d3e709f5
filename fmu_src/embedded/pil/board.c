/*
 * The board support of the processor-in-the-loop image: the timer that measures a sample,
 * fp_clock_seconds() for the controller's own timing outputs (t_step, t_guid, t_alloc), the
 * C library's system calls it needs (a bounded heap pool for _sbrk), and counters of the
 * C library's use.  Board code, not the controller's: its few statics are the image's.
 */
#include "board.h"

#include <stdarg.h>
#include <stdio.h>
#include <errno.h>

#include "fp_clock.h"

/* CMSDK APB timer 0 of the MPS2 FPGA images: a 32-bit down-counter on the peripheral clock */
#define TIMER0_CTRL (*(volatile uint32_t *)0x40000000u)
#define TIMER0_VALUE (*(volatile uint32_t *)0x40000004u)
#define TIMER0_RELOAD (*(volatile uint32_t *)0x40000008u)

void board_timer_restart(void) {
    TIMER0_CTRL = 0u;
    TIMER0_RELOAD = 0xFFFFFFFFu;
    TIMER0_VALUE = 0xFFFFFFFFu;
    TIMER0_CTRL = 1u; /* enable, no interrupt */
}

uint32_t board_timer_ticks(void) { return 0xFFFFFFFFu - TIMER0_VALUE; }

/* The controller's clock (common/fp_clock.h): the board timer in seconds.  Under QEMU with
 * -icount the timer follows the instructions executed, so differences of these are
 * instruction counts (orchestrator/pil.py converts them). */
double fp_clock_seconds(void) { return (double)board_timer_ticks() / BOARD_TICK_HZ; }

/* The C library's heap: a fixed pool.  newlib's float formatting takes a little of it the
 * first time a message shows a number; nothing else does (board_heap_used tells). */
#define HEAP_POOL 16384
static unsigned char heap_pool[HEAP_POOL] __attribute__((aligned(8)));
static size_t heap_top;

void *_sbrk(ptrdiff_t increment);
void *_sbrk(ptrdiff_t increment) {
    size_t old = heap_top;
    if (increment < 0 || (size_t)increment > HEAP_POOL - heap_top) {
        errno = ENOMEM;
        return (void *)-1;
    }
    heap_top += (size_t)increment;
    return heap_pool + old;
}

size_t board_heap_used(void) { return heap_top; }

/* snprintf and vsnprintf, counted (the image links with --wrap for both) */
static uint32_t format_calls;

int __real_vsnprintf(char *buf, size_t size, const char *fmt, va_list args);
int __wrap_vsnprintf(char *buf, size_t size, const char *fmt, va_list args);
int __wrap_snprintf(char *buf, size_t size, const char *fmt, ...);

int __wrap_vsnprintf(char *buf, size_t size, const char *fmt, va_list args) {
    format_calls++;
    return __real_vsnprintf(buf, size, fmt, args);
}

int __wrap_snprintf(char *buf, size_t size, const char *fmt, ...) {
    va_list args;
    int n;
    format_calls++;
    va_start(args, fmt);
    n = __real_vsnprintf(buf, size, fmt, args);
    va_end(args);
    return n;
}

uint32_t board_format_calls(void) { return format_calls; }

/* libm's inexact functions, recorded while asked (the tracing image links with --wrap for
 * each) */
static struct {
    int on;
    uint32_t n, dropped;
    BoardLibmCall calls[BOARD_LIBM_LOG];
} libm_log;

int board_libm_record(int on) {
#if defined(BOARD_LIBM_TRACE)
    libm_log.on = on;
    libm_log.n = libm_log.dropped = 0;
    return 1;
#else
    (void)on;
    return 0;
#endif
}

const BoardLibmCall *board_libm_take(uint32_t *n, uint32_t *dropped) {
    *n = libm_log.n;
    *dropped = libm_log.dropped;
    libm_log.n = libm_log.dropped = 0;
    return libm_log.calls;
}

#if defined(BOARD_LIBM_TRACE)
static double noted(int fn, double x, double y, double r) {
    if (libm_log.on) {
        if (libm_log.n < BOARD_LIBM_LOG) {
            BoardLibmCall *c = &libm_log.calls[libm_log.n++];
            c->fn = (double)fn;
            c->x = x;
            c->y = y;
            c->result = r;
        } else {
            libm_log.dropped++;
        }
    }
    return r;
}

#define WRAP1(name, id)                                                   \
    double __real_##name(double x);                                       \
    double __wrap_##name(double x);                                       \
    double __wrap_##name(double x) { return noted(id, x, 0.0, __real_##name(x)); }
#define WRAP2(name, id)                                                   \
    double __real_##name(double x, double y);                             \
    double __wrap_##name(double x, double y);                             \
    double __wrap_##name(double x, double y) { return noted(id, x, y, __real_##name(x, y)); }
WRAP1(sin, 0)
WRAP1(cos, 1)
WRAP1(tan, 2)
WRAP1(asin, 3)
WRAP1(acos, 4)
WRAP2(atan2, 5)
WRAP2(hypot, 6)
#endif

/* The stack: painted with a pattern at start; the deepest word overwritten since tells. */
#define STACK_PAINT 0x5AC3C35Au
extern uint32_t __stack_limit[], __stack_top[];

void board_paint_stack(void) {
    uintptr_t sp;
    uint32_t *p = __stack_limit, *below;
    __asm__ volatile("mov %0, sp" : "=r"(sp));
    below = (uint32_t *)(sp - 256u); /* leave this frame and the caller's */
    while (p < below) *p++ = STACK_PAINT;
}

size_t board_stack_used(void) {
    const uint32_t *p = __stack_limit;
    while (p < __stack_top && *p == STACK_PAINT) p++;
    return (size_t)((const char *)__stack_top - (const char *)p);
}
