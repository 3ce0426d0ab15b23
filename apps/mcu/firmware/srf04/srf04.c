#include "srf04.h"

#include <avr/interrupt.h>
#include <avr/io.h>
#include <util/atomic.h>
#include <util/delay.h>

#include "board.h"

enum { WAIT_RISE, WAIT_FALL, DONE, IDLE };

static volatile uint8_t state = IDLE;
static volatile uint16_t overflows; /* Timer1 overflows: bits 16..31 of the time */
static volatile uint32_t rise_ticks;
static volatile uint32_t width_ticks;
static uint32_t started_ms;
static uint16_t failures;

void srf04_init(void) {
  BOARD_TRIG_PORT &= (uint8_t)~_BV(BOARD_TRIG_BIT);
  BOARD_TRIG_DDR |= _BV(BOARD_TRIG_BIT);
  BOARD_ECHO_DDR &= (uint8_t)~_BV(BOARD_ECHO_BIT);
  BOARD_ECHO_PORT &= (uint8_t)~_BV(BOARD_ECHO_BIT); /* no pull-up: the SRF04 drives it */
  TCCR1A = 0;                                     /* normal mode, free running */
  TCCR1B = (uint8_t)(_BV(ICNC1) | _BV(CS11));     /* noise canceller, clk/8 */
  TIFR = (uint8_t)(_BV(TOV1) | _BV(ICF1));
  TIMSK |= _BV(TOIE1);
  state = IDLE;
}

ISR(TIMER1_OVF_vect) {
  overflows++;
}

ISR(TIMER1_CAPT_vect) {
  uint16_t icr = ICR1;
  uint16_t high = overflows;
  /* An overflow still pending with a small captured value happened before
   * the capture: count it here (its ISR runs after this one). */
  if ((TIFR & _BV(TOV1)) && icr < 0x8000u)
    high++;
  uint32_t t = ((uint32_t)high << 16) | icr;
  if (state == WAIT_RISE) {
    rise_ticks = t;
    TCCR1B &= (uint8_t)~_BV(ICES1); /* next: the falling edge */
    TIFR = _BV(ICF1);               /* the datasheet: clear ICF1 after changing ICES1 */
    state = WAIT_FALL;
  } else if (state == WAIT_FALL) {
    width_ticks = t - rise_ticks;
    TIMSK &= (uint8_t)~_BV(TICIE1);
    state = DONE;
  }
}

bool srf04_trigger(uint32_t now_ms) {
  if (state == WAIT_RISE || state == WAIT_FALL)
    return false;
  ATOMIC_BLOCK(ATOMIC_RESTORESTATE) {
    TCCR1B |= _BV(ICES1); /* rising edge first */
    TIFR = _BV(ICF1);
    TIMSK |= _BV(TICIE1);
    state = WAIT_RISE;
  }
  started_ms = now_ms;
  BOARD_TRIG_PORT |= _BV(BOARD_TRIG_BIT);
  _delay_us(12); /* the trigger pulse itself; the echo is timed by hardware */
  BOARD_TRIG_PORT &= (uint8_t)~_BV(BOARD_TRIG_BIT);
  return true;
}

uint16_t srf04_distance_mm(uint32_t echo_us) {
  if (echo_us >= SRF04_MAX_ECHO_US)
    return SRF04_OUT_OF_RANGE;
  return (uint16_t)((echo_us * 343u + 1000u) / 2000u);
}

srf04_status_t srf04_poll(uint32_t now_ms, srf04_measurement_t *out) {
  uint8_t s;
  uint32_t ticks = 0;
  bool timed_out = false;
  ATOMIC_BLOCK(ATOMIC_RESTORESTATE) {
    s = state;
    if (s == DONE) {
      ticks = width_ticks;
      state = IDLE;
    } else if (s != IDLE && (uint32_t)(now_ms - started_ms) >= SRF04_TIMEOUT_MS) {
      TIMSK &= (uint8_t)~_BV(TICIE1);
      state = IDLE;
      timed_out = true;
    }
  }
  if (s == IDLE)
    return SRF04_IDLE;
  if (timed_out) {
    failures++;
    return SRF04_FAILED;
  }
  if (s != DONE)
    return SRF04_BUSY;
  out->echo_us = (ticks + 1u) / 2u; /* 0.5 us ticks, rounded */
  out->distance_mm = srf04_distance_mm(out->echo_us);
  return SRF04_READY;
}

uint16_t srf04_failures(void) {
  return failures;
}
