/* The SRF04 ultrasonic ranger on the sonar board (pins in board.h).
 *
 * A measurement: srf04_trigger raises the trigger pin for 12 us (the sensor
 * wants at least 10 us); the sensor sends its 40 kHz burst and raises the
 * echo line for as long as the sound took to come back: 58 us per cm of
 * distance, about 36 ms when nothing is in range. Timer1 runs free at
 * F_CPU / 8 (0.5 us per tick, extended to 32 bits by its overflow
 * interrupt); its input capture unit (ICP1 = PD4) stamps the rising edge,
 * then the falling edge, in hardware, so the width does not depend on
 * interrupt latency. Nothing busy-waits on the echo.
 *
 * Units: echo_us in microseconds, distance_mm in millimetres,
 * distance_mm = echo_us * 343 / 2000 rounded (sound at 343 m/s, there and
 * back; docs/protocol.md, "SRF04 reading"). An echo of SRF04_MAX_ECHO_US or
 * longer is "nothing in range": distance_mm = SRF04_OUT_OF_RANGE. A sensor
 * that never answers (no echo edge within SRF04_TIMEOUT_MS) makes the
 * measurement fail: it is counted, and no reading comes out of it. */
#ifndef HERM_SRF04_SRF04_H
#define HERM_SRF04_SRF04_H

#include <stdbool.h>
#include <stdint.h>

/* Echoes this long or longer mean "nothing in range" (the SRF04 holds the
 * line 36 ms then; 4 m, its range, is 23.3 ms). */
#ifndef SRF04_MAX_ECHO_US
#define SRF04_MAX_ECHO_US 30000UL
#endif
/* A measurement with no complete echo after this long failed. */
#ifndef SRF04_TIMEOUT_MS
#define SRF04_TIMEOUT_MS 60u
#endif

#define SRF04_OUT_OF_RANGE 0xFFFFu

typedef struct {
  uint16_t distance_mm; /* SRF04_OUT_OF_RANGE when nothing is in range */
  uint32_t echo_us;     /* the echo pulse width, us */
} srf04_measurement_t;

typedef enum {
  SRF04_IDLE,     /* no measurement started (or the last one was collected) */
  SRF04_BUSY,     /* waiting for the echo */
  SRF04_READY,    /* *out holds the measurement; the driver is idle again */
  SRF04_FAILED    /* no echo within SRF04_TIMEOUT_MS; idle again */
} srf04_status_t;

/* Pins and Timer1 (free running, capture and overflow interrupts). Call
 * with interrupts disabled, before sei(). */
void srf04_init(void);

/* Starts a measurement at now_ms (the board's millisecond clock): arms the
 * input capture for the rising edge and sends the 12 us trigger pulse.
 * False, and nothing done, while a measurement is under way. */
bool srf04_trigger(uint32_t now_ms);

/* Where the measurement stands at now_ms; on SRF04_READY fills *out. */
srf04_status_t srf04_poll(uint32_t now_ms, srf04_measurement_t *out);

/* Measurements that failed (no echo) since srf04_init. */
uint16_t srf04_failures(void);

/* distance_mm for an echo of echo_us (pure; exposed for tests). */
uint16_t srf04_distance_mm(uint32_t echo_us);

#endif
