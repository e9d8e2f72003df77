#include "LSM9DS0.h"

Lsm9ds0Accel::Lsm9ds0Accel(I2cBus& bus, uint8_t address7) : bus_(bus), address7_(address7) {}

Lsm9ds0Accel::Status Lsm9ds0Accel::begin()
{
    uint8_t id = 0;
    if (!bus_.readRegisters(address7_, Lsm9ds0::WHO_AM_I_XM, &id, 1)) {
        return NoAnswer;
    }
    if (id != Lsm9ds0::WHO_AM_I_XM_VALUE) {
        return WrongId;
    }
    if (!bus_.writeRegister(address7_, Lsm9ds0::CTRL_REG1_XM, Lsm9ds0::CTRL_REG1_XM_100HZ_BDU_XYZ) ||
        !bus_.writeRegister(address7_, Lsm9ds0::CTRL_REG2_XM, Lsm9ds0::CTRL_REG2_XM_ABW50_2G) ||
        !bus_.writeRegister(address7_, Lsm9ds0::CTRL_REG4_XM, Lsm9ds0::CTRL_REG4_XM_P2_DRDYA) ||
        !bus_.writeRegister(address7_, Lsm9ds0::CTRL_REG5_XM, Lsm9ds0::CTRL_REG5_XM_TEMP_EN) ||
        !bus_.writeRegister(address7_, Lsm9ds0::CTRL_REG7_XM, Lsm9ds0::CTRL_REG7_XM_MAG_CONTINUOUS)) {
        return WriteFailed;
    }
    return Ok;
}

static void decodeAxes(const uint8_t bytes[6], int16_t out[3])
{
    for (uint8_t axis = 0; axis < 3; ++axis) {
        uint16_t word = (uint16_t)((uint16_t)bytes[2 * axis + 1] << 8) | bytes[2 * axis];
        out[axis] = (int16_t)word;
    }
}

bool Lsm9ds0Accel::readAcceleration(int16_t out[3])
{
    uint8_t bytes[6];
    if (!bus_.readRegisters(address7_, Lsm9ds0::OUT_X_L_A | Lsm9ds0::AUTO_INCREMENT, bytes, 6)) {
        return false;
    }
    decodeAxes(bytes, out);
    return true;
}

bool Lsm9ds0Accel::readFreshAcceleration(int16_t out[3], bool& fresh)
{
    uint8_t bytes[7];
    if (!bus_.readRegisters(address7_, Lsm9ds0::STATUS_REG_A | Lsm9ds0::AUTO_INCREMENT, bytes, 7)) {
        return false;
    }
    fresh = (bytes[0] & Lsm9ds0::STATUS_REG_A_ZYXADA) != 0;
    decodeAxes(bytes + 1, out);
    return true;
}

bool Lsm9ds0Accel::readTemperatureRaw(int16_t& out)
{
    uint8_t bytes[2];
    if (!bus_.readRegisters(address7_, Lsm9ds0::OUT_TEMP_L_XM | Lsm9ds0::AUTO_INCREMENT, bytes, 2)) {
        return false;
    }
    out = temperatureRawFromBytes(bytes[0], bytes[1]);
    return true;
}

bool Lsm9ds0Accel::dataReady()
{
    uint8_t status = 0;
    if (!bus_.readRegisters(address7_, Lsm9ds0::STATUS_REG_A, &status, 1)) {
        return false;
    }
    return (status & Lsm9ds0::STATUS_REG_A_ZYXADA) != 0;
}

void DataReadyLine::sampleRead(bool levelWhenReady, bool levelAfterRead)
{
    if (levelWhenReady == levelAfterRead) {
        agreeing_ = 0;
        return;
    }
    if (levelWhenReady != activeLevel_) {
        activeLevel_ = levelWhenReady;
        agreeing_ = 0;
    }
    if (agreeing_ < SAMPLES_TO_TRUST) {
        ++agreeing_;
    }
}

int16_t temperatureRawFromBytes(uint8_t low, uint8_t high)
{
    int16_t value = (int16_t)(((uint16_t)(high & 0x0F) << 8) | low);
    if (value & 0x0800) {
        value = (int16_t)(value - 0x1000);
    }
    return value;
}

float accelLsbToG(int16_t lsb)
{
    return (float)lsb * (Lsm9ds0::ACCEL_MG_PER_LSB_2G / 1000.0f);
}

float temperatureRawToC(int16_t raw, float offsetC)
{
    return (float)raw / Lsm9ds0::TEMP_LSB_PER_C + offsetC;
}
