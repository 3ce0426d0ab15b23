#include "uart0.h"

#include <avr/interrupt.h>
#include <avr/io.h>
#include <util/atomic.h>

#include "board.h"

#define UBRR_VALUE ((F_CPU + 8UL * BOARD_UART0_BAUD) / (16UL * BOARD_UART0_BAUD) - 1UL)

#if (UART0_RX_RING & (UART0_RX_RING - 1u)) != 0 || UART0_RX_RING > 128u
#error "UART0_RX_RING must be a power of two, at most 128"
#endif
#if (UART0_TX_RING & (UART0_TX_RING - 1u)) != 0 || UART0_TX_RING > 128u
#error "UART0_TX_RING must be a power of two, at most 128"
#endif

/* Free-running 8-bit indices: count = head - tail (mod 256). */
static uint8_t rx_buf[UART0_RX_RING];
static volatile uint8_t rx_head;
static volatile uint8_t rx_tail;
static uint8_t tx_buf[UART0_TX_RING];
static volatile uint8_t tx_head;
static volatile uint8_t tx_tail;
static volatile uart0_counters_t counters;

void uart0_init(void) {
  UBRR0H = (uint8_t)(UBRR_VALUE >> 8);
  UBRR0L = (uint8_t)UBRR_VALUE;
  UCSR0A = 0;
  UCSR0C = (uint8_t)(_BV(UCSZ01) | _BV(UCSZ00)); /* 8N1, asynchronous */
  UCSR0B = (uint8_t)(_BV(RXEN0) | _BV(TXEN0) | _BV(RXCIE0));
}

ISR(USART0_RX_vect) {
  uint8_t status = UCSR0A;
  uint8_t byte = UDR0;
  if (status & _BV(DOR0))
    counters.rx_overruns++;
  if (status & _BV(FE0)) {
    counters.rx_framing_errors++;
    return;
  }
  uint8_t head = rx_head;
  if ((uint8_t)(head - rx_tail) >= UART0_RX_RING) {
    counters.rx_dropped++;
    return;
  }
  rx_buf[head & (UART0_RX_RING - 1u)] = byte;
  rx_head = (uint8_t)(head + 1u);
}

ISR(USART0_UDRE_vect) {
  uint8_t tail = tx_tail;
  if (tail == tx_head) {
    UCSR0B &= (uint8_t)~_BV(UDRIE0); /* ring empty: stop until the next write */
    return;
  }
  UDR0 = tx_buf[tail & (UART0_TX_RING - 1u)];
  tx_tail = (uint8_t)(tail + 1u);
}

bool uart0_read(uint8_t *out) {
  uint8_t tail = rx_tail;
  if (tail == rx_head)
    return false;
  *out = rx_buf[tail & (UART0_RX_RING - 1u)];
  rx_tail = (uint8_t)(tail + 1u);
  return true;
}

bool uart0_write(uint8_t byte) {
  uint8_t head = tx_head;
  if ((uint8_t)(head - tx_tail) >= UART0_TX_RING)
    return false;
  tx_buf[head & (UART0_TX_RING - 1u)] = byte;
  tx_head = (uint8_t)(head + 1u);
  UCSR0B |= _BV(UDRIE0); /* one sbi: atomic against the UDRE ISR */
  return true;
}

uint8_t uart0_tx_free(void) {
  return (uint8_t)(UART0_TX_RING - (uint8_t)(tx_head - tx_tail));
}

uart0_counters_t uart0_counters(void) {
  uart0_counters_t copy;
  ATOMIC_BLOCK(ATOMIC_RESTORESTATE) {
    copy.rx_dropped = counters.rx_dropped;
    copy.rx_overruns = counters.rx_overruns;
    copy.rx_framing_errors = counters.rx_framing_errors;
  }
  return copy;
}
