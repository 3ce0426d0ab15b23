/* The paper's sonar board: an ATmega128 at 16 MHz with an SRF04 ultrasonic
 * ranger and RS232C on UART0 (docs/mcu.md, "The SRF04 board").
 *
 * Wiring (pins fixed by this header; a different board changes them here):
 *   UART0  RXD0 = PE0, TXD0 = PE1  19,200 baud 8N1 (UBRR0 = 51, 0.2 % error)
 *   SRF04  trigger = PB0 (output), echo = PD4 = ICP1 (Timer1 input capture)
 *
 * Timers: Timer0 makes the millisecond clock (CTC, /64, OCR0 = 249), Timer1
 * runs free at F_CPU / 8 (0.5 us per tick) and times the echo pulse by input
 * capture. Timer2, Timer3 and UART1 are free for the application. */
#ifndef HERM_SRF04_BOARD_H
#define HERM_SRF04_BOARD_H

#ifndef F_CPU
#error "F_CPU must be defined (16000000UL for the sonar board)"
#endif

/* The line rate of UART0, bits/s. */
#ifndef BOARD_UART0_BAUD
#define BOARD_UART0_BAUD 19200UL
#endif

/* The trigger pin: PORTB bit 0. */
#define BOARD_TRIG_PORT PORTB
#define BOARD_TRIG_DDR DDRB
#define BOARD_TRIG_BIT 0

/* The echo pin: PD4, the ATmega128's ICP1. */
#define BOARD_ECHO_PORT PORTD
#define BOARD_ECHO_DDR DDRD
#define BOARD_ECHO_BIT 4

#endif
