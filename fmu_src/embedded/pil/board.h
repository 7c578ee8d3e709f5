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

/* The image's program (pil_main.c), called by the reset handler: its exit code. */
int pil_main(void);

#endif
