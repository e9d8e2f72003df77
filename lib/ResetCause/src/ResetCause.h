// Why a board last reset, as VER's reset_cause names it (docs/protocol.md):
// from the reset flags the MCU latched and whether the firmware had marked
// the reset as one it asked for itself (the IMU reader's RESET command, which
// resets through the watchdog). Portable: the flags are given as the MCUSR
// bits of the ATmega328P and ATmega2560, which firmware/common/Watchdog.cpp
// checks against avr-libc's names.
#ifndef THERMOTILT_RESET_CAUSE_H
#define THERMOTILT_RESET_CAUSE_H

#include <stdint.h>

namespace ResetCause {

const uint8_t POWER_ON_FLAG = 1 << 0;  // PORF
const uint8_t EXTERNAL_FLAG = 1 << 1;  // EXTRF: the reset pin, e.g. the host opening the port
const uint8_t BROWNOUT_FLAG = 1 << 2;  // BORF
const uint8_t WATCHDOG_FLAG = 1 << 3;  // WDRF

// A commanded reset is the watchdog's, or shows no flag at all when a
// bootloader cleared them; any other flag means something else reset the
// board in the few milliseconds the command waits for the watchdog.
bool wasCommanded(uint8_t flags, bool commandMarked);

// "COMMANDED", "WATCHDOG", "BROWNOUT", "EXTERNAL", "POWER_ON" or "UNKNOWN"
// (no flag: a bootloader such as Optiboot cleared them first).
const char* name(uint8_t flags, bool commandMarked);

// True after a reset nobody asked for: a watchdog (a hung loop) or a brown-out.
bool wasAbnormal(uint8_t flags, bool commandMarked);

}  // namespace ResetCause

#endif
