/* Stack high-water mark by painting (the usual avr-libc way).
 *
 * Before anything else runs (.init1, ahead of avr-libc's stack pointer set-up
 * in .init2), every byte of SRAM from _end (the end of .data and .bss) to
 * RAMEND is written with STACK_PAINT_BYTE. The stack grows down from RAMEND
 * and overwrites the paint; the lowest address that no longer holds the paint
 * is the deepest the stack has been. The harness (herm-avr-sim
 * --report-stack) scans the same area from outside; the firmware can ask
 * itself with stack_paint_unused. The board uses no heap, so nothing else
 * writes between _end and the stack. */
#ifndef HERM_SRF04_STACK_PAINT_H
#define HERM_SRF04_STACK_PAINT_H

#include <stdint.h>

#define STACK_PAINT_BYTE 0xC5u

/* Bytes between _end and the deepest stack use that were never touched:
 * the stack's headroom so far (O(headroom) scan from _end). */
uint16_t stack_paint_unused(void);

#endif
