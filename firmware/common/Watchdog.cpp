#include "Watchdog.h"

#include <avr/io.h>

namespace {

uint8_t resetFlags __attribute__((section(".noinit")));

}  // namespace

// Runs before the C runtime and Arduino's init(). After a watchdog reset the
// watchdog stays on at its shortest period (~15 ms), so it is switched off
// here, and WDRF must be cleared before that can work (avr-libc's <avr/wdt.h>
// documentation and the ATmega datasheets).
void captureResetFlags() __attribute__((naked, used, section(".init3")));
void captureResetFlags()
{
    resetFlags = MCUSR;
    MCUSR = 0;
    wdt_disable();
}

void startWatchdog()
{
    wdt_enable(WATCHDOG_TIMEOUT);
}

const char* resetCauseName()
{
    if (resetFlags & _BV(WDRF)) return "WATCHDOG";
    if (resetFlags & _BV(BORF)) return "BROWNOUT";
    if (resetFlags & _BV(EXTRF)) return "EXTERNAL";
    if (resetFlags & _BV(PORF)) return "POWER_ON";
    return "UNKNOWN";
}

bool resetWasAbnormal()
{
    return (resetFlags & (_BV(WDRF) | _BV(BORF))) != 0;
}
