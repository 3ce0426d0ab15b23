/* The board's millisecond clock: Timer0 in CTC mode at F_CPU / 64 with
 * OCR0 = 249 interrupts every 1 ms (exactly, at 16 MHz) and counts.
 * clock_ms wraps after 2^32 ms (49.7 days); compare times by subtraction. */
#ifndef HERM_SRF04_CLOCK_H
#define HERM_SRF04_CLOCK_H

#include <stdint.h>

/* Starts Timer0. Call with interrupts disabled, before sei(). */
void clock_init(void);

/* Milliseconds since clock_init (read atomically). */
uint32_t clock_ms(void);

#endif
