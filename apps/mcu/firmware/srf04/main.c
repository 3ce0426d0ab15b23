/* The sonar board's firmware: the ATmega128 with its SRF04 as a HERM module
 * of its own on RS232C (UART0, 19,200 baud), a leaf that sends every reading
 * to the sensor module's `sonar` APO and serves the last one from an APO of
 * its own (docs/mcu.md, "The SRF04 board").
 *
 * Every SRF04_PERIOD_MS the board measures; each reading goes as a request
 * whose payload is one element `herm::hermd::srf04_reading` (seq:u16,
 * distance_mm:u16, echo_us:u32) to the APO named SRF04_TARGET_APO, found by
 * hermc's discovery. A reading taken while `sonar` is not discovered yet, or
 * while every pending slot is busy, is not sent and is counted
 * (readings_unsent); the sequence number still advances, so the receiver
 * sees the gap.
 *
 * The board's APO SRF04_APO_NAME (type SRF04_APO_TYPE) answers any request
 * (any payload, or none) with the last reading in the same payload; before
 * the first reading that is seq 0, distance 0, echo 0. So the main
 * controller can also ask the sensor directly (hermctl call, herm-apo-peer).
 *
 * Module id: SRF04_MODULE_ID (static, the board never claims one).
 * Instance: a boot counter in EEPROM (bytes 0..3), so a neighbour tells a
 * rebooted board from a live one. */
#include <avr/eeprom.h>
#include <avr/interrupt.h>
#include <avr/sleep.h>
#include <stdint.h>

#include "clock.h"
#include "hermc.h"
#include "hermc_payload.h"
#include "srf04.h"
#include "uart0.h"

#ifndef SRF04_MODULE_ID
#define SRF04_MODULE_ID 0x0A04u
#endif
#ifndef SRF04_PERIOD_MS
#define SRF04_PERIOD_MS 100u /* tests; the paper's testbed measures every 30 s */
#endif
#ifndef SRF04_TARGET_APO
#define SRF04_TARGET_APO "sonar"
#endif
#ifndef SRF04_APO_NAME
#define SRF04_APO_NAME "srf04"
#endif
#ifndef SRF04_APO_TYPE
#define SRF04_APO_TYPE "herm.srf04"
#endif

/* What the board counts besides hermc's and the drivers' counters (kept
 * for a debugger or a future status APO). */
struct board_counters {
  uint16_t readings;
  uint16_t readings_unsent;
  uint16_t responses_ok;
  uint16_t responses_failed;
};

static struct hermc_module module;
static struct board_counters counters;
/* The last reading (seq 0: none yet), what the srf04 APO answers. */
static struct hermc_srf04_reading last_reading;

static uint64_t boot_instance(void) {
  uint32_t *const at = (uint32_t *)0;
  uint32_t boots = eeprom_read_dword(at) + 1u;
  if (boots == 0u || boots == 0xFFFFFFFFu) /* erased EEPROM reads 0xFF.. */
    boots = 1u;
  eeprom_write_dword(at, boots);
  return ((uint64_t)boots << 16) | SRF04_MODULE_ID;
}

static void on_response(void *ctx, enum hermc_status status,
                        const uint8_t *payload, size_t len,
                        uint64_t err_category, uint8_t err_code) {
  (void)ctx;
  (void)payload;
  (void)len;
  (void)err_category;
  (void)err_code;
  if (status == HERMC_STATUS_OK)
    counters.responses_ok++;
  else
    counters.responses_failed++;
}

/* The board's APO: any request is answered with the last reading (the
 * request's payload is not read). resp_cap is HERMC_MAX_PACKET less the
 * data and response headers (19 B), at least 45 B as hermc_config.h
 * requires 64: the reading's HERMC_SRF04_SIZE (37) always fits. */
static uint8_t serve_reading(void *ctx, const uint8_t *req, size_t req_len,
                             uint8_t *resp, size_t resp_cap, size_t *resp_len) {
  (void)ctx;
  (void)req;
  (void)req_len;
  *resp_len = hermc_srf04_encode(&last_reading, resp, resp_cap);
  return 0;
}

static void send_reading(int sonar) {
  uint8_t payload[HERMC_SRF04_SIZE];
  size_t len = hermc_srf04_encode(&last_reading, payload, sizeof(payload));
  counters.readings++;
  if (len == 0u ||
      hermc_request(&module, sonar, payload, len, on_response, NULL, 0u) != HERMC_OK)
    counters.readings_unsent++;
}

/* Moves what the module has to send into UART0's transmit ring. */
static void drain_tx(void) {
  uint8_t chunk[16];
  for (;;) {
    uint8_t room = uart0_tx_free();
    if (room == 0u)
      return;
    size_t n = hermc_poll_tx(&module, chunk, room < sizeof(chunk) ? room : sizeof(chunk));
    if (n == 0u)
      return;
    for (size_t i = 0; i < n; i++)
      uart0_write(chunk[i]);
  }
}

int main(void) {
  cli();
  clock_init();
  uart0_init();
  srf04_init();
  set_sleep_mode(SLEEP_MODE_IDLE);

  struct hermc_config cfg;
  hermc_config_default(&cfg, SRF04_MODULE_ID, boot_instance());
  if (hermc_init(&module, &cfg) != HERMC_OK) {
    for (;;) /* a configuration error is a build error: stop here */
      sleep_mode();
  }
  int sonar = hermc_remote(&module, SRF04_TARGET_APO);
  /* The one APO of the build (HERMC_MAX_APOS=1): it cannot be refused. */
  (void)hermc_register_apo(&module, SRF04_APO_NAME, SRF04_APO_TYPE,
                           serve_reading, NULL);
  sei();

  uint32_t last = clock_ms();
  for (;;) {
    uint8_t byte;
    while (uart0_read(&byte))
      hermc_feed(&module, &byte, 1u);
    uint32_t now = clock_ms();
    hermc_tick(&module, now);
    if ((uint32_t)(now - last) >= SRF04_PERIOD_MS && srf04_trigger(now))
      last = now;
    srf04_measurement_t m;
    if (srf04_poll(clock_ms(), &m) == SRF04_READY) {
      if (++last_reading.seq == 0u) /* 0 means "no reading yet" */
        last_reading.seq = 1u;
      last_reading.distance_mm = m.distance_mm;
      last_reading.echo_us = m.echo_us;
      send_reading(sonar);
    }
    drain_tx();
    /* Every event comes with an interrupt (the 1 ms tick at least). */
    cli();
    sleep_enable();
    sei();
    sleep_cpu();
    sleep_disable();
  }
}
