#ifndef THERMOTILT_FUZZ_AVR_SLEEP_H
#define THERMOTILT_FUZZ_AVR_SLEEP_H

#include <stdint.h>

#define SLEEP_MODE_IDLE 0
#define SLEEP_MODE_ADC 1
#define SLEEP_MODE_PWR_DOWN 2
#define SLEEP_MODE_PWR_SAVE 3
#define SLEEP_MODE_STANDBY 6

#include "../ArduinoShim.h"

// The harness advances the clock itself between loop() calls, so sleep_mode()
// returns at once, as on the next interrupt. sleep_cpu() is a sketch's own
// sleep loop, which waits for a condition within one loop() call: it is
// woken by the next 1 ms timer tick, as on the AVR.
inline void set_sleep_mode(uint8_t) {}
inline void sleep_enable() {}
inline void sleep_disable() {}
inline void sleep_cpu()
{
    ArduinoShim::advanceMillis(1);
}
inline void sleep_mode() {}

#endif
