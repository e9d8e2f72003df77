#include "unity_config.h"

#include <Arduino.h>
#include <avr/sleep.h>

// Through Arduino's Serial, as PlatformIO's Unity configuration for Arduino
// does: the test images run Arduino's init(), and simavr's USART model stops
// reporting "data register empty" to code that polls it after init() has
// written UCSR0B = 0, while the interrupt-driven Serial works.
void unityOutputStart(void)
{
    Serial.begin(115200);
}

void unityOutputChar(char c)
{
    Serial.write(c);
}

void unityOutputComplete(void)
{
    Serial.flush();
    // Sleeping with interrupts off is how a simulated test run ends.
    cli();
    sleep_enable();
    sleep_cpu();
}
