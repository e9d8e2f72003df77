// The IMU reader's I2C master. Arduino's Wire drives the TWI from its
// interrupt too, but endTransmission() and requestFrom() spin until the
// transfer is over, and at 400 kHz that spinning was the largest share of
// the reader's awake time; here the CPU sleeps (idle mode) between the
// TWI's interrupts. No reachable library does that, hence this one. It follows the TWI chapter
// of the ATmega328P datasheet, with avr-libc's <util/twi.h> status codes.
#ifndef THERMOTILT_SLEEPING_TWI_H
#define THERMOTILT_SLEEPING_TWI_H

#include <stdint.h>

#include <LSM9DS0.h>

class SleepingTwi : public I2cBus {
public:
    // As Wire.begin() and Wire.setClock(): the pins' pull-ups on, the bit
    // rate for clockHz, the TWI enabled. A transfer the bus does not finish
    // within timeoutMs (give or take Clock's tick) is abandoned and the TWI
    // reset (Wire's setWireTimeout).
    void begin(uint32_t clockHz, uint8_t timeoutMs);

    bool writeRegister(uint8_t address7, uint8_t reg, uint8_t value) override;
    // The register address, a repeated start, then count bytes.
    bool readRegisters(uint8_t address7, uint8_t firstReg, uint8_t* out, uint8_t count) override;

private:
    bool transfer(uint8_t address7, const uint8_t* send, uint8_t sendCount, uint8_t* receive, uint8_t receiveCount);
    void reset();

    uint8_t bitRate_;
    uint8_t timeoutMs_;
};

#endif
