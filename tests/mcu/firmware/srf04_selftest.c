/* The sonar board's self-test firmware: the board support of
 * apps/mcu/firmware/srf04 (UART0, the millisecond clock, the SRF04 driver,
 * stack painting) without the HERM client. Every SELFTEST_PERIOD_MS it
 * measures and prints one line of text on UART0:
 *
 *   selftest srf04 period_ms=P            once, at boot
 *   reading SEQ DISTANCE_MM ECHO_US T_MS  per measurement (T_MS: the trigger time)
 *   failed SEQ T_MS                       when the sensor did not answer
 *
 * and answers what it receives on UART0, line by line (at most
 * SELFTEST_LINE - 1 characters; longer lines are cut):
 *
 *   stats        -> stats rx_dropped=N rx_overruns=N rx_framing_errors=N
 *                         srf04_failures=N stack_unused=N
 *   anything     -> echo anything
 *
 * tests/mcu/avr_sim_test.cpp runs it in herm-avr-sim against a scripted
 * distance and checks the printed distances follow the script. */
#include <avr/interrupt.h>
#include <avr/sleep.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include "clock.h"
#include "srf04.h"
#include "stack_paint.h"
#include "uart0.h"

#ifndef SELFTEST_PERIOD_MS
#define SELFTEST_PERIOD_MS 100u
#endif
#ifndef SELFTEST_LINE
#define SELFTEST_LINE 48u
#endif

/* Waits (asleep) for room in the transmit ring: the self-test prints whole
 * lines and never drops any. */
static void put(char c) {
  while (!uart0_write((uint8_t)c))
    sleep_mode();
}

static void put_str(const char *s) {
  while (*s)
    put(*s++);
}

static void put_u32(uint32_t v) {
  char buf[11];
  ultoa(v, buf, 10);
  put_str(buf);
}

static char line[SELFTEST_LINE];
static uint8_t line_len;

static void answer_line(void) {
  line[line_len] = 0;
  if (strcmp(line, "stats") == 0) {
    uart0_counters_t c = uart0_counters();
    put_str("stats rx_dropped=");
    put_u32(c.rx_dropped);
    put_str(" rx_overruns=");
    put_u32(c.rx_overruns);
    put_str(" rx_framing_errors=");
    put_u32(c.rx_framing_errors);
    put_str(" srf04_failures=");
    put_u32(srf04_failures());
    put_str(" stack_unused=");
    put_u32(stack_paint_unused());
  } else {
    put_str("echo ");
    put_str(line);
  }
  put('\n');
  line_len = 0;
}

int main(void) {
  cli();
  clock_init();
  uart0_init();
  srf04_init();
  set_sleep_mode(SLEEP_MODE_IDLE);
  sei();

  put_str("selftest srf04 period_ms=");
  put_u32(SELFTEST_PERIOD_MS);
  put('\n');

  uint16_t seq = 0;
  uint32_t started = 0;
  uint32_t last = 0;
  bool first = true;
  for (;;) {
    uint32_t now = clock_ms();
    if (first || (uint32_t)(now - last) >= SELFTEST_PERIOD_MS) {
      if (srf04_trigger(now)) {
        first = false;
        last = now;
        started = now;
        seq++;
      }
    }
    srf04_measurement_t m;
    switch (srf04_poll(clock_ms(), &m)) {
    case SRF04_READY:
      put_str("reading ");
      put_u32(seq);
      put(' ');
      put_u32(m.distance_mm);
      put(' ');
      put_u32(m.echo_us);
      put(' ');
      put_u32(started);
      put('\n');
      break;
    case SRF04_FAILED:
      put_str("failed ");
      put_u32(seq);
      put(' ');
      put_u32(started);
      put('\n');
      break;
    default:
      break;
    }
    uint8_t byte;
    while (uart0_read(&byte)) {
      if (byte == '\n')
        answer_line();
      else if (line_len < SELFTEST_LINE - 1u)
        line[line_len++] = (char)byte;
    }
    /* Every event comes with an interrupt (the 1 ms tick at least). */
    cli();
    sleep_enable();
    sei();
    sleep_cpu();
    sleep_disable();
  }
}
