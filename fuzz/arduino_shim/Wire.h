// Arduino's TwoWire over the shim's I2C devices (ArduinoShim::attachI2cDevice):
// a transmission goes to the device at its address as one write, a
// requestFrom() as one read; no device, or a device that says no, is a NACK.
#ifndef THERMOTILT_FUZZ_WIRE_H
#define THERMOTILT_FUZZ_WIRE_H

#include <stddef.h>
#include <stdint.h>

#define BUFFER_LENGTH 32

class TwoWire {
public:
    void begin();
    void end();
    void setClock(uint32_t hz);
    void setWireTimeout(uint32_t timeoutUs = 25000, bool resetWithTimeout = false);
    bool getWireTimeoutFlag();
    void clearWireTimeoutFlag();

    void beginTransmission(uint8_t address7);
    void beginTransmission(int address7) { beginTransmission((uint8_t)address7); }
    // 0 sent, 1 too long for the buffer, 2 NACK on the address.
    uint8_t endTransmission(uint8_t sendStop);
    uint8_t endTransmission() { return endTransmission(true); }
    size_t write(uint8_t value);
    size_t write(const uint8_t* data, size_t length);

    uint8_t requestFrom(uint8_t address7, uint8_t quantity);
    uint8_t requestFrom(uint8_t address7, uint8_t quantity, uint8_t sendStop);
    uint8_t requestFrom(int address7, int quantity) { return requestFrom((uint8_t)address7, (uint8_t)quantity); }
    uint8_t requestFrom(int address7, int quantity, int sendStop)
    {
        return requestFrom((uint8_t)address7, (uint8_t)quantity, (uint8_t)sendStop);
    }
    int available();
    int read();
    int peek();

private:
    uint8_t txAddress_ = 0;
    uint8_t txBuffer_[BUFFER_LENGTH];
    uint8_t txLength_ = 0;
    bool txOverflow_ = false;
    uint8_t rxBuffer_[BUFFER_LENGTH];
    uint8_t rxLength_ = 0;
    uint8_t rxIndex_ = 0;
};

extern TwoWire Wire;

#endif
