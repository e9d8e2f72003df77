// The MCU status register and its reset flags (avr-libc's <avr/io.h>); the
// harness sets MCUSR to the cause of each boot it simulates.
#ifndef THERMOTILT_FUZZ_AVR_IO_H
#define THERMOTILT_FUZZ_AVR_IO_H

#include <stdint.h>

#ifndef _BV
#define _BV(bit) (1 << (bit))
#endif

#define PORF 0
#define EXTRF 1
#define BORF 2
#define WDRF 3
#define JTRF 4

extern volatile uint8_t MCUSR;

#endif
