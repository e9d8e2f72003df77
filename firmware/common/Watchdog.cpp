#include "Watchdog.h"

#include <avr/io.h>

#include <ResetCause.h>

static_assert(ResetCause::POWER_ON_FLAG == _BV(PORF) && ResetCause::EXTERNAL_FLAG == _BV(EXTRF) &&
                  ResetCause::BROWNOUT_FLAG == _BV(BORF) && ResetCause::WATCHDOG_FLAG == _BV(WDRF),
              "lib/ResetCause names MCUSR's bits");

namespace {

// Two bytes that power-on RAM holds by chance once in 65536 boots, and then
// only matters without a power-on flag (ResetCause::wasCommanded).
const uint16_t COMMANDED_RESET_MARKER = 0x5254;

// .noinit: written before the C runtime clears .bss, and kept by a reset.
uint8_t resetFlags __attribute__((section(".noinit")));
uint16_t resetMarker __attribute__((section(".noinit")));
bool resetCommanded __attribute__((section(".noinit")));

}  // namespace

// Runs before the C runtime and Arduino's init(). After a watchdog reset the
// watchdog stays on at its shortest period (~15 ms), so it is switched off
// here, and WDRF must be cleared before that can work (avr-libc's <avr/wdt.h>
// documentation and the ATmega datasheets). The marker is read once and
// cleared, so a later hung loop is a watchdog reset again.
void captureResetFlags() __attribute__((naked, used, section(".init3")));
void captureResetFlags()
{
    resetFlags = MCUSR;
    MCUSR = 0;
    wdt_disable();
    resetCommanded = resetMarker == COMMANDED_RESET_MARKER;
    resetMarker = 0;
}

void startWatchdog()
{
    wdt_enable(WATCHDOG_TIMEOUT);
}

void startCommandedReset()
{
    resetMarker = COMMANDED_RESET_MARKER;
    wdt_enable(COMMANDED_RESET_TIMEOUT);
    // The chip counts the new timeout at once; simavr 1.6 only from the next
    // WDR (it compares the prescaler with itself after the write).
    wdt_reset();
}

const char* resetCauseName()
{
    return ResetCause::name(resetFlags, resetCommanded);
}

bool resetWasAbnormal()
{
    return ResetCause::wasAbnormal(resetFlags, resetCommanded);
}
