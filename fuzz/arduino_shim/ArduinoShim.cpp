#include "ArduinoShim.h"

#include <Arduino.h>
#include <EEPROM.h>
#include <Clock.h>
#include <SleepingTwi.h>
#include <Uart0.h>
#include <avr/io.h>
#include <avr/wdt.h>

#include <stdio.h>
#include <string.h>

#include "invariant.h"

EEPROMClass EEPROM;
volatile uint8_t MCUSR = 0;

namespace {

// Uart0's receive ring of 64 keeps one slot free.
const size_t SERIAL_RX_CAPACITY = 63;
const uint8_t I2C_ADDRESSES = 128;
const uint8_t ERASED = 0xFF;
// WDTO_15MS .. WDTO_8S, as avr-libc names them.
const uint32_t WATCHDOG_TIMEOUTS_MS[] = {15, 30, 60, 120, 250, 500, 1000, 2000, 4000, 8000};

struct Mcu {
    uint64_t clockUs;
    std::string serialReceived;
    size_t serialReadAt;
    std::string serialRead;
    std::string serialWritten;
    ArduinoShim::PinState pins[ArduinoShim::PIN_COUNT];
    bool watchdogOn;
    uint32_t watchdogTimeoutMs;
    uint64_t watchdogFedUs;
};

struct Surroundings {
    uint8_t eeprom[ArduinoShim::EEPROM_SIZE];
    uint16_t analog[ArduinoShim::ANALOG_CHANNELS];
    ArduinoShim::I2cDevice* i2c[I2C_ADDRESSES];
};

Mcu mcu;
Surroundings surroundings;
ArduinoShim::PinObserver pinObserver = 0;

ArduinoShim::PinState& pinState(uint8_t number)
{
    require(number < ArduinoShim::PIN_COUNT, "the sketch used a pin the board does not have");
    return mcu.pins[number];
}

void setPin(uint8_t number, uint8_t mode, uint8_t duty)
{
    ArduinoShim::PinState& state = pinState(number);
    ArduinoShim::PinState before = state;
    state.mode = mode;
    state.duty = duty;
    if (pinObserver) {
        pinObserver(number, before);
    }
}

uint8_t& eepromCell(int address)
{
    require(address >= 0 && address < ArduinoShim::EEPROM_SIZE, "EEPROM address outside the EEPROM");
    return surroundings.eeprom[address];
}

}  // namespace

void ArduinoShim::powerOn()
{
    memset(surroundings.eeprom, ERASED, sizeof surroundings.eeprom);
    for (uint16_t& value : surroundings.analog) {
        value = ANALOG_MID_SCALE;
    }
    memset(surroundings.i2c, 0, sizeof surroundings.i2c);
    pinObserver = 0;
    reset();
}

void ArduinoShim::reset()
{
    mcu.clockUs = 0;
    mcu.serialReceived.clear();
    mcu.serialReadAt = 0;
    mcu.serialRead.clear();
    mcu.serialWritten.clear();
    memset(mcu.pins, 0, sizeof mcu.pins);
    mcu.watchdogOn = false;
}

void ArduinoShim::advanceMillis(uint32_t ms)
{
    mcu.clockUs += (uint64_t)ms * 1000u;
}

bool ArduinoShim::receiveSerial(uint8_t value)
{
    if (serialBytesWaiting() >= SERIAL_RX_CAPACITY) {
        return false;
    }
    mcu.serialReceived += (char)value;
    return true;
}

size_t ArduinoShim::serialBytesWaiting()
{
    return mcu.serialReceived.size() - mcu.serialReadAt;
}

std::string ArduinoShim::takeSerialWritten()
{
    std::string written;
    written.swap(mcu.serialWritten);
    return written;
}

std::string ArduinoShim::takeSerialRead()
{
    std::string read;
    read.swap(mcu.serialRead);
    mcu.serialReceived.erase(0, mcu.serialReadAt);
    mcu.serialReadAt = 0;
    return read;
}

void ArduinoShim::setAnalogInput(uint8_t channel, uint16_t value)
{
    require(channel < ANALOG_CHANNELS, "no such analog channel");
    surroundings.analog[channel] = value;
}

const ArduinoShim::PinState& ArduinoShim::pin(uint8_t number)
{
    return pinState(number);
}

void ArduinoShim::observePins(PinObserver observer)
{
    pinObserver = observer;
}

uint8_t* ArduinoShim::eeprom()
{
    return surroundings.eeprom;
}

void ArduinoShim::attachI2cDevice(uint8_t address7, I2cDevice* device)
{
    require(address7 < I2C_ADDRESSES, "I2C addresses have 7 bits");
    surroundings.i2c[address7] = device;
}

bool ArduinoShim::watchdogEnabled()
{
    return mcu.watchdogOn;
}

bool ArduinoShim::watchdogExpired()
{
    return mcu.watchdogOn && mcu.clockUs - mcu.watchdogFedUs >= (uint64_t)mcu.watchdogTimeoutMs * 1000u;
}

unsigned long millis()
{
    return (uint32_t)(mcu.clockUs / 1000u);
}

// The IMU reader's clock (firmware/imu_reader/Clock.cpp runs it on Timer1).
void Clock::begin() {}

uint32_t Clock::nowMs()
{
    return millis();
}

uint32_t Clock::tickMs()
{
    return millis() / Clock::TICK_MS * Clock::TICK_MS;
}

unsigned long micros()
{
    return (uint32_t)mcu.clockUs;
}

void delay(unsigned long ms)
{
    ArduinoShim::advanceMillis((uint32_t)ms);
}

void delayMicroseconds(unsigned int us)
{
    mcu.clockUs += us;
}

void pinMode(uint8_t pin, uint8_t mode)
{
    setPin(pin, mode, pinState(pin).duty);
}

void digitalWrite(uint8_t pin, uint8_t value)
{
    setPin(pin, pinState(pin).mode, value == LOW ? 0 : 255);
}

int digitalRead(uint8_t pin)
{
    return pinState(pin).duty == 255 ? HIGH : LOW;
}

int analogRead(uint8_t pin)
{
    uint8_t channel = pin >= A0 ? (uint8_t)(pin - A0) : pin;
    require(channel < ArduinoShim::ANALOG_CHANNELS, "analogRead of a pin without an ADC channel");
    return surroundings.analog[channel] & 0x3FF;
}

void analogWrite(uint8_t pin, int value)
{
    uint8_t duty = value <= 0 ? 0 : value >= 255 ? 255 : (uint8_t)value;
    setPin(pin, OUTPUT, duty);
}

void wdt_enable(uint8_t timeout)
{
    require(timeout < sizeof WATCHDOG_TIMEOUTS_MS / sizeof WATCHDOG_TIMEOUTS_MS[0], "wdt_enable takes a WDTO_* value");
    mcu.watchdogOn = true;
    mcu.watchdogTimeoutMs = WATCHDOG_TIMEOUTS_MS[timeout];
    mcu.watchdogFedUs = mcu.clockUs;
}

void wdt_reset()
{
    mcu.watchdogFedUs = mcu.clockUs;
}

void wdt_disable()
{
    mcu.watchdogOn = false;
}

// The boards' serial port (firmware/common/Uart0.cpp drives USART0's
// registers): what the harness fed, and what the sketch wrote, whole.
void Uart0::begin(uint32_t) {}

uint8_t Uart0::available()
{
    return (uint8_t)ArduinoShim::serialBytesWaiting();
}

int Uart0::read()
{
    if (available() == 0) {
        return -1;
    }
    char value = mcu.serialReceived[mcu.serialReadAt++];
    mcu.serialRead += value;
    return (uint8_t)value;
}

uint8_t Uart0::availableForWrite()
{
    return (uint8_t)SERIAL_RX_CAPACITY;
}

void Uart0::write(const char* bytes, uint8_t count)
{
    mcu.serialWritten.append(bytes, count);
}

void Uart0::flush() {}

uint8_t EEPROMClass::read(int address)
{
    return eepromCell(address);
}

void EEPROMClass::write(int address, uint8_t value)
{
    eepromCell(address) = value;
}

void EEPROMClass::update(int address, uint8_t value)
{
    write(address, value);
}

uint16_t EEPROMClass::length()
{
    return ArduinoShim::EEPROM_SIZE;
}

uint8_t& EEPROMClass::operator[](int address)
{
    return eepromCell(address);
}

// The IMU reader's TWI master (firmware/imu_reader/SleepingTwi.cpp drives
// the AVR's TWI registers): a write is one write transaction to the device,
// a read one write of the register address and one read.
static ArduinoShim::I2cDevice* i2cDevice(uint8_t address7)
{
    return address7 < I2C_ADDRESSES ? surroundings.i2c[address7] : 0;
}

void SleepingTwi::begin(uint32_t, uint8_t) {}

bool SleepingTwi::writeRegister(uint8_t address7, uint8_t reg, uint8_t value)
{
    const uint8_t bytes[2] = {reg, value};
    ArduinoShim::I2cDevice* device = i2cDevice(address7);
    return device && device->write(bytes, 2);
}

bool SleepingTwi::readRegisters(uint8_t address7, uint8_t firstReg, uint8_t* out, uint8_t count)
{
    ArduinoShim::I2cDevice* device = i2cDevice(address7);
    return count > 0 && device && device->write(&firstReg, 1) && device->read(out, count);
}

void attachInterrupt(uint8_t, void (*)(void), int) {}
