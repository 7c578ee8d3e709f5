/*
 * Reset and exceptions of the processor-in-the-loop image (Cortex-M7): .data copied from
 * flash, .bss cleared, the FPU enabled (full access for CP10 and CP11), then pil_main.  A
 * fault stops QEMU with exit code 3 and says which.
 */
#include <stdint.h>
#include <string.h>

#include "board.h"
#include "semihost.h"

extern uint32_t __stack_top[], __data_start[], __data_end[], __data_load[], __bss_start[],
    __bss_end[];

void pil_reset(void);
void pil_fault(void);

#define SCB_CPACR (*(volatile uint32_t *)0xE000ED88u)

void pil_reset(void) {
    memcpy(__data_start, __data_load, (size_t)((char *)__data_end - (char *)__data_start));
    memset(__bss_start, 0, (size_t)((char *)__bss_end - (char *)__bss_start));
    SCB_CPACR |= 0xFu << 20;
    __asm__ volatile("dsb\n\tisb" ::: "memory");
    semihost_exit(pil_main());
}

void pil_fault(void) {
    semihost_say("pil: processor fault (hard fault, memory, bus or usage fault)\n");
    semihost_exit(3);
}

/* The vector table: the initial stack pointer, reset, then the faults and the rest. */
typedef void (*Vector)(void);
__attribute__((section(".vectors"), used)) static const Vector vectors[16] = {
    (Vector)(uintptr_t)__stack_top, pil_reset, pil_fault, pil_fault, pil_fault, pil_fault,
    pil_fault, 0, 0, 0, 0, pil_fault, pil_fault, 0, pil_fault, pil_fault,
};
