#pragma once

// libsimavr's C headers (Debian's simavr 1.6, include dir /usr/include/simavr)
// for the harness's C++ sources.

extern "C" {
#include <avr_eeprom.h>
#include <avr_ioport.h>
#include <avr_uart.h>
#include <sim_avr.h>
#include <sim_elf.h>
#include <sim_irq.h>
#include <sim_regbit.h>
#include <sim_time.h>
}
