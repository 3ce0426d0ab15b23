#include "stack_paint.h"

#include <avr/io.h>

extern uint8_t _end;
extern uint8_t __stack;

/* Naked, in .init1: no prologue, no stack, and r1 is not zero yet, so the
 * loop is written in assembly (Z walks from _end to __stack inclusive). */
void stack_paint_init1(void) __attribute__((naked, used, section(".init1")));

void stack_paint_init1(void) {
  __asm__ volatile("    ldi r30, lo8(_end)\n"
                   "    ldi r31, hi8(_end)\n"
                   "    ldi r24, %0\n"
                   "    ldi r25, hi8(__stack)\n"
                   "    rjmp 2f\n"
                   "1:  st Z+, r24\n"
                   "2:  cpi r30, lo8(__stack)\n"
                   "    cpc r31, r25\n"
                   "    brlo 1b\n"
                   "    breq 1b\n" ::"i"(STACK_PAINT_BYTE));
}

uint16_t stack_paint_unused(void) {
  const uint8_t *p = &_end;
  uint16_t n = 0;
  while (p <= &__stack && *p == STACK_PAINT_BYTE) {
    p++;
    n++;
  }
  return n;
}
