// A native stand-in for the parts of the Arduino AVR core the sketches use,
// so that they build unchanged for the fuzz targets. The harness sets what
// the AVR would see (clock, analog inputs, serial bytes received, I2C
// devices, EEPROM) and reads what it did, through ArduinoShim.h.
#ifndef THERMOTILT_FUZZ_ARDUINO_H
#define THERMOTILT_FUZZ_ARDUINO_H

#include <math.h>
#include <stddef.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include <avr/interrupt.h>
#include <avr/io.h>
#include <avr/pgmspace.h>

typedef uint8_t byte;
typedef bool boolean;

#define HIGH 0x1
#define LOW 0x0
#define INPUT 0x0
#define OUTPUT 0x1
#define INPUT_PULLUP 0x2

#define CHANGE 1
#define FALLING 2
#define RISING 3

#define interrupts() sei()
#define noInterrupts() cli()

// The analog pins' numbers on each board (Arduino's pins_arduino.h).
#ifdef ARDUINO_AVR_MEGA2560
#define NUM_DIGITAL_PINS 70
static const uint8_t A0 = 54;
#else
#define NUM_DIGITAL_PINS 20
static const uint8_t A0 = 14;
#endif
static const uint8_t A1 = A0 + 1;
static const uint8_t A2 = A0 + 2;
static const uint8_t A3 = A0 + 3;
static const uint8_t A4 = A0 + 4;
static const uint8_t A5 = A0 + 5;
static const uint8_t A6 = A0 + 6;
static const uint8_t A7 = A0 + 7;

// As on the AVR, millis() and micros() wrap at 2^32.
unsigned long millis();
unsigned long micros();
void delay(unsigned long ms);
void delayMicroseconds(unsigned int us);

void pinMode(uint8_t pin, uint8_t mode);
void digitalWrite(uint8_t pin, uint8_t value);
int digitalRead(uint8_t pin);
// A channel number (0..15) or an analog pin (A0...); 10 bits.
int analogRead(uint8_t pin);
// INT0 and INT1 are D2 and D3 on both boards' sketches' pins. Nothing
// interrupts a fuzz target, so the handler is never called.
#define digitalPinToInterrupt(pin) ((pin) == 2 ? 0 : ((pin) == 3 ? 1 : -1))
void attachInterrupt(uint8_t interruptNumber, void (*handler)(void), int mode);
void analogWrite(uint8_t pin, int value);

#endif
