/* UART0 of the ATmega128: 8N1 at BOARD_UART0_BAUD, interrupt driven both
 * ways through two rings in static RAM.
 *
 * Receive: the RXC interrupt moves each byte into a ring of UART0_RX_RING
 * bytes; a byte that finds the ring full is dropped and counted in
 * uart0_counters.rx_dropped; a byte the hardware lost before the interrupt
 * ran (data overrun, DOR0) or received with a framing error (FE0) is
 * counted in rx_overruns / rx_framing_errors (the framing error byte is
 * dropped, the client's CRC would reject it anyway).
 * Transmit: uart0_write puts a byte into a ring of UART0_TX_RING bytes that
 * the UDRE interrupt drains at the line rate.
 *
 * Threading: uart0_read / uart0_write / uart0_tx_free are called from the
 * main loop only (one consumer, one producer per ring); the ISRs are the
 * other side. Ring sizes are powers of two, at most 128. */
#ifndef HERM_SRF04_UART0_H
#define HERM_SRF04_UART0_H

#include <stdbool.h>
#include <stdint.h>

#ifndef UART0_RX_RING
#define UART0_RX_RING 32u
#endif
#ifndef UART0_TX_RING
#define UART0_TX_RING 32u
#endif

typedef struct {
  uint16_t rx_dropped;        /* ring full when a byte arrived */
  uint16_t rx_overruns;       /* DOR0: the hardware lost bytes */
  uint16_t rx_framing_errors; /* FE0: the byte was dropped */
} uart0_counters_t;

/* Sets the line rate and enables receiver, transmitter and the receive
 * interrupt. Call with interrupts disabled, before sei(). */
void uart0_init(void);

/* Takes the oldest received byte into *out; false when none is waiting. */
bool uart0_read(uint8_t *out);

/* Queues one byte for sending; false (nothing queued) when the ring is
 * full. */
bool uart0_write(uint8_t byte);

/* How many bytes uart0_write would take now. */
uint8_t uart0_tx_free(void);

/* A copy of the counters (read with interrupts off, so consistent). */
uart0_counters_t uart0_counters(void);

#endif
