#include "clock.h"

#include <avr/interrupt.h>
#include <avr/io.h>
#include <util/atomic.h>

#if F_CPU != 16000000UL
#error "clock.c: OCR0 = 249 at /64 is 1 ms only at F_CPU = 16 MHz"
#endif

static volatile uint32_t ms;

void clock_init(void) {
  TCCR0 = (uint8_t)(_BV(WGM01) | _BV(CS02)); /* CTC, clk/64 (Timer0's CS table) */
  OCR0 = 249u;
  TCNT0 = 0;
  TIMSK |= _BV(OCIE0);
}

ISR(TIMER0_COMP_vect) {
  ms++;
}

uint32_t clock_ms(void) {
  uint32_t copy;
  ATOMIC_BLOCK(ATOMIC_RESTORESTATE) {
    copy = ms;
  }
  return copy;
}
