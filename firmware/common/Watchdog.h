// The watchdog of both boards (avr-libc <avr/wdt.h>) and why the board last
// reset. A loop pass that does not come back within WATCHDOG_TIMEOUT resets
// the MCU; after any reset the pins are inputs until setup() runs, so the
// L298N's ENA pull-down keeps the Peltier off (README, wiring).
#ifndef THERMOTILT_WATCHDOG_H
#define THERMOTILT_WATCHDOG_H

#include <avr/wdt.h>

// Longer than any loop pass (a blocking 120-byte write is ~10 ms, a Wire
// time-out 25 ms), short enough that a hung chamber stops heating at once.
const uint8_t WATCHDOG_TIMEOUT = WDTO_500MS;
// A reset the firmware asks for waits no longer than this.
const uint8_t COMMANDED_RESET_TIMEOUT = WDTO_15MS;

void startWatchdog();

inline void feedWatchdog()
{
    wdt_reset();
}

// Marks the coming reset as commanded and shortens the watchdog to
// COMMANDED_RESET_TIMEOUT. The caller must stop feeding it from now on: the
// watchdog then resets the MCU, and the next VER says COMMANDED, not WATCHDOG.
void startCommandedReset();

// From MCUSR as it was at start-up and the commanded-reset marker
// (lib/ResetCause): "POWER_ON", "EXTERNAL", "BROWNOUT", "WATCHDOG",
// "COMMANDED", or "UNKNOWN" when a bootloader cleared MCUSR first.
const char* resetCauseName();
// True after a reset the firmware did not ask for: watchdog or brown-out.
bool resetWasAbnormal();

#endif
