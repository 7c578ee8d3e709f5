/* The processor-in-the-loop board (QEMU's mps2-an500): a cycle counter of its own, the C
 * library's heap pool and what the image counts of the C library's use. */
#ifndef PIL_BOARD_H
#define PIL_BOARD_H

#include <stddef.h>
#include <stdint.h>

/* The board timer's ticks per second (the CMSDK APB timer on the 25 MHz peripheral clock). */
#define BOARD_TICK_HZ 25000000.0

/* Start counting from 0 (each sample's measurement starts here: no wrap within one). */
void board_timer_restart(void);
/* Ticks since board_timer_restart. */
uint32_t board_timer_ticks(void);

/* Bytes the C library took from its heap pool so far (its high-water mark). */
size_t board_heap_used(void);
/* Calls of the C library's text formatting (snprintf, vsnprintf) so far. */
uint32_t board_format_calls(void);
/* The deepest the stack has been (bytes): the painted stack's untouched part measured. */
size_t board_stack_used(void);
/* Paint the stack below the caller's frame, for board_stack_used. */
void board_paint_stack(void);

/* The controller's calls of libm's inexact functions, recorded while on (board_libm_record)
 * in the tracing image (fpc_pil_trace.elf, built with BOARD_LIBM_TRACE and --wrap for each;
 * the measuring image fpc_pil.elf records nothing, so its counts are the controller's own):
 * function (0 sin, 1 cos, 2 tan, 3 asin, 4 acos, 5 atan2, 6 hypot), arguments and result. */
typedef struct {
    double fn, x, y, result; /* (fn as a double: the record is four doubles on the wire) */
} BoardLibmCall;
#define BOARD_LIBM_LOG 256
/* 0 when the image cannot record (not the tracing image). */
int board_libm_record(int on);
/* The calls recorded since the last take (at most BOARD_LIBM_LOG; *dropped: the rest). */
const BoardLibmCall *board_libm_take(uint32_t *n, uint32_t *dropped);

/* The image's program (pil_main.c), called by the reset handler: its exit code. */
int pil_main(void);

#endif
