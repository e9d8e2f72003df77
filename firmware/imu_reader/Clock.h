// The IMU reader's millisecond clock, on Timer1 instead of Arduino's
// millis(). Timer0's overflow interrupt, which advances millis(), woke the
// CPU every 1.024 ms: ~980 wake-ups a second, and with the loop pass each
// one made, about a tenth of the reader's awake time. Timer1 interrupts
// once every TICK_MS and its counter gives the milliseconds in between, so
// the time read is exact, where millis() lags by up to 1 ms and now and then
// steps by 2. begin() stops Timer0's interrupt: from then on Arduino's
// millis(), micros() and delay() stand still, and the reader uses nowMs().
#ifndef THERMOTILT_CLOCK_H
#define THERMOTILT_CLOCK_H

#include <stdint.h>

namespace Clock {

// The longest the CPU sleeps through with nothing else to wake it: what
// the reader checks on a timer (a silent data-ready line, STATUS_REG_A when
// polling, the TWI's timeout) is seen at most this late.
const uint8_t TICK_MS = 4;

void begin();
// Milliseconds since begin(); wraps after 49.7 days, as millis().
uint32_t nowMs();
// nowMs() at the last tick: at most TICK_MS behind, and cheaper, for the
// checks a wake-up makes (the CPU can wake on every TWI and UART byte);
// they would see nowMs() change only at a tick anyway.
uint32_t tickMs();

}  // namespace Clock

#endif
