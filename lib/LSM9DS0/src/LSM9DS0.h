// Accelerometer and temperature sensor of the LSM9DS0 (its "XM" die) over I2C,
// set up as in Table 1 of the Sensors 2018 paper: 100 Hz, 50 Hz anti-alias
// filter, +-2 g, temperature sensor on. Register names follow the LSM9DS0
// datasheet (DocID024763).
#ifndef THERMOTILT_LSM9DS0_H
#define THERMOTILT_LSM9DS0_H

#include <stdint.h>

// The firmware implements this with Arduino Wire, the tests with a register
// file. Both calls return false on NACK or timeout.
class I2cBus {
public:
    virtual bool writeRegister(uint8_t address7, uint8_t reg, uint8_t value) = 0;
    virtual bool readRegisters(uint8_t address7, uint8_t firstReg, uint8_t* out, uint8_t count) = 0;

protected:
    // Not virtual: a virtual destructor would pull operator delete into AVR
    // images, and nothing deletes a bus through this interface.
    ~I2cBus() {}
};

namespace Lsm9ds0 {

// 7-bit address of the XM die: SDO_XM high (SparkFun breakout default) or low.
const uint8_t ADDRESS_XM_SDO_HIGH = 0x1D;
const uint8_t ADDRESS_XM_SDO_LOW = 0x1E;

const uint8_t OUT_TEMP_L_XM = 0x05;
const uint8_t OUT_TEMP_H_XM = 0x06;
const uint8_t WHO_AM_I_XM = 0x0F;
const uint8_t CTRL_REG1_XM = 0x20;
const uint8_t CTRL_REG2_XM = 0x21;
const uint8_t CTRL_REG4_XM = 0x23;
const uint8_t CTRL_REG5_XM = 0x24;
const uint8_t CTRL_REG7_XM = 0x26;
const uint8_t STATUS_REG_A = 0x27;
const uint8_t OUT_X_L_A = 0x28;  // X, Y, Z little-endian pairs up to OUT_Z_H_A (0x2D)

const uint8_t WHO_AM_I_XM_VALUE = 0x49;

// Setting the MSB of the sub-address makes the I2C read auto-increment.
const uint8_t AUTO_INCREMENT = 0x80;

// CTRL_REG1_XM: AODR[3:0] = 0110 (100 Hz) in bits 7:4, BDU (bit 3) so the low
// and high bytes of one axis come from the same sample, AZEN|AYEN|AXEN.
const uint8_t CTRL_REG1_XM_100HZ_BDU_XYZ = (0x6 << 4) | (1 << 3) | 0x07;
// CTRL_REG2_XM: ABW[1:0] = 11 (50 Hz anti-alias) in bits 7:6, AFS[2:0] = 000
// (+-2 g) in bits 5:3, self-test off, 4-wire SPI (unused on I2C).
const uint8_t CTRL_REG2_XM_ABW50_2G = (0x3 << 6) | (0x0 << 3);
// CTRL_REG5_XM: TEMP_EN (bit 7); M_RES = 00 and M_ODR[2:0] = 100 (50 Hz).
const uint8_t CTRL_REG5_XM_TEMP_EN = (1 << 7) | (0x4 << 2);
// CTRL_REG7_XM: MD[1:0] = 00, magnetometer in continuous conversion. It
// resets to power-down (10), and the temperature output is refreshed at the
// magnetometer's data rate, so without this the temperature would freeze.
const uint8_t CTRL_REG7_XM_MAG_CONTINUOUS = 0x00;
// CTRL_REG4_XM: P2_DRDYA (bit 3), the accelerometer's data-ready on INT2_XM,
// so a board that wires the pin need not poll STATUS_REG_A (DataReadyLine).
const uint8_t CTRL_REG4_XM_P2_DRDYA = 1 << 3;

const uint8_t STATUS_REG_A_ZYXADA = 1 << 3;

// +-2 g sensitivity (datasheet and paper section 2).
const float ACCEL_MG_PER_LSB_2G = 0.061f;
// The temperature sensor gives 8 LSB/degC around an unspecified zero; the
// paper adds 21.00 degC measured in its laboratory (section 2).
const float TEMP_LSB_PER_C = 8.0f;
const float PAPER_TEMP_OFFSET_C = 21.0f;

}  // namespace Lsm9ds0

class Lsm9ds0Accel {
public:
    enum Status : uint8_t { Ok, NoAnswer, WrongId, WriteFailed };

    explicit Lsm9ds0Accel(I2cBus& bus, uint8_t address7 = Lsm9ds0::ADDRESS_XM_SDO_HIGH);

    // Checks WHO_AM_I_XM and writes the Table 1 settings, with data-ready on INT2_XM.
    Status begin();

    // X, Y, Z in raw LSB from one 6-byte auto-increment read of OUT_X_L_A..OUT_Z_H_A.
    bool readAcceleration(int16_t out[3]);
    // The same from one 7-byte read that starts at STATUS_REG_A; fresh tells
    // whether ZYXADA said the sample was new.
    bool readFreshAcceleration(int16_t out[3], bool& fresh);
    // 12-bit two's complement from OUT_TEMP_L_XM/OUT_TEMP_H_XM, sign-extended.
    bool readTemperatureRaw(int16_t& out);
    // True when STATUS_REG_A reports a new X/Y/Z sample; false also on bus error.
    bool dataReady();

    uint8_t address() const { return address7_; }

private:
    I2cBus& bus_;
    uint8_t address7_;
};

// Whether INT2_XM's data-ready can stand in for polling STATUS_REG_A, learned
// from the samples themselves: the firmware does not set the line's polarity
// (INT_CTRL_REG_M's IEA, whose meaning the sources found disagree on), and
// the pin may not be wired at all (a pulled-up input then never changes). A
// line is trusted once, for SAMPLES_TO_TRUST samples in a row, it was at one
// level when a sample was ready and at the other once the sample was read
// (reading OUT_Z_H_A clears data-ready); one sample that breaks the rule, or
// distrust(), takes the trust away, and the caller polls again.
class DataReadyLine {
public:
    static const uint8_t SAMPLES_TO_TRUST = 8;

    DataReadyLine() : activeLevel_(true), agreeing_(0) {}

    // The pin's level when a sample was found ready (by the line or by
    // STATUS_REG_A) and just after that sample was read.
    void sampleRead(bool levelWhenReady, bool levelAfterRead);
    void distrust() { agreeing_ = 0; }

    bool trusted() const { return agreeing_ >= SAMPLES_TO_TRUST; }
    // True when a trusted line at this level says a sample is ready.
    bool saysReady(bool level) const { return trusted() && level == activeLevel_; }
    bool activeHigh() const { return activeLevel_; }

private:
    bool activeLevel_;
    uint8_t agreeing_;
};

// Two's complement of the 12 right-justified bits in OUT_TEMP_H_XM:OUT_TEMP_L_XM;
// the upper nibble of the high byte is ignored.
int16_t temperatureRawFromBytes(uint8_t low, uint8_t high);

float accelLsbToG(int16_t lsb);
float temperatureRawToC(int16_t raw, float offsetC = Lsm9ds0::PAPER_TEMP_OFFSET_C);

#endif
