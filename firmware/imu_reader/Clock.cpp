#include "Clock.h"

#include <avr/interrupt.h>
#include <avr/io.h>

namespace {

// Timer1 at F_CPU / 64 counts 250 times a millisecond at 16 MHz; in CTC mode
// it restarts after TICK_MS of them.
const uint16_t COUNTS_PER_MS = F_CPU / 64 / 1000;
const uint16_t COUNTS_PER_TICK = Clock::TICK_MS * COUNTS_PER_MS;
static_assert(F_CPU % (64UL * 1000UL) == 0, "Timer1 at F_CPU / 64 must count whole ticks per millisecond");

volatile uint32_t msAtLastTick = 0;

}  // namespace

ISR(TIMER1_COMPA_vect)
{
    msAtLastTick += Clock::TICK_MS;
}

namespace Clock {

void begin()
{
    TIMSK0 &= (uint8_t)~_BV(TOIE0);
    TCCR1A = 0;
    TCCR1B = 0;
    TCNT1 = 0;
    OCR1A = COUNTS_PER_TICK - 1;
    TIFR1 = _BV(OCF1A);
    TIMSK1 = _BV(OCIE1A);
    TCCR1B = _BV(WGM12) | _BV(CS11) | _BV(CS10);
}

uint32_t nowMs()
{
    uint8_t savedStatus = SREG;
    cli();
    uint32_t ms = msAtLastTick;
    uint16_t counts = TCNT1;
    // The counter restarted, but its interrupt waits for this function.
    if ((TIFR1 & _BV(OCF1A)) && counts < COUNTS_PER_TICK - 1) {
        ms += TICK_MS;
    }
    SREG = savedStatus;
    uint8_t msInTick = 0;
    while (counts >= COUNTS_PER_MS) {
        counts -= COUNTS_PER_MS;
        ++msInTick;
    }
    return ms + msInTick;
}

uint32_t tickMs()
{
    uint8_t savedStatus = SREG;
    cli();
    uint32_t ms = msAtLastTick;
    SREG = savedStatus;
    return ms;
}

}  // namespace Clock
