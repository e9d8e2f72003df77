// The harness's side of the Arduino shim: the board's surroundings, set
// before and between loop() calls, and what the sketch did to them.
#ifndef THERMOTILT_FUZZ_ARDUINO_SHIM_H
#define THERMOTILT_FUZZ_ARDUINO_SHIM_H

#include <stddef.h>
#include <stdint.h>
#include <string>

namespace ArduinoShim {

const uint16_t EEPROM_SIZE = 1024;
const uint8_t ANALOG_CHANNELS = 16;
const uint8_t PIN_COUNT = 70;
const uint16_t ANALOG_MID_SCALE = 512;

// duty: the share of time the pin is high, 0..255 (digitalWrite gives 0 or 255).
struct PinState {
    uint8_t mode;
    uint8_t duty;
};

// A device on the I2C bus.
class I2cDevice {
public:
    // The bytes of one write transaction; false is a NACK.
    virtual bool write(const uint8_t* data, size_t length) = 0;
    // Fills `out` for one read transaction; false is a NACK.
    virtual bool read(uint8_t* out, size_t length) = 0;

protected:
    ~I2cDevice() {}
};

// What is outside the MCU at power-on: an erased EEPROM, every analog input
// at mid-scale, no I2C device. A power-on is also a reset().
void powerOn();
// A reset of the MCU: clock at 0, serial buffers empty, pins inputs and low,
// watchdog off. The EEPROM, analog inputs and I2C devices are kept.
void reset();

void advanceMillis(uint32_t ms);

// Arduino's receive buffer holds 63 bytes: false when full and `value` lost.
bool receiveSerial(uint8_t value);
size_t serialBytesWaiting();
// The bytes the sketch wrote, and those it read, since the previous call.
std::string takeSerialWritten();
std::string takeSerialRead();

void setAnalogInput(uint8_t channel, uint16_t value);
const PinState& pin(uint8_t number);
// Called after every pinMode, digitalWrite and analogWrite, with the pin's
// state before it; 0 for none.
typedef void (*PinObserver)(uint8_t number, const PinState& before);
void observePins(PinObserver observer);

uint8_t* eeprom();
void attachI2cDevice(uint8_t address7, I2cDevice* device);
bool watchdogEnabled();
// On, and not fed for its timeout (wdt_enable's WDTO_*) of shim time: the
// AVR would have reset.
bool watchdogExpired();

}  // namespace ArduinoShim

#endif
