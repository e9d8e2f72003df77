// The real imu_reader sketch on the Arduino shim (board_harness.h), with a
// fake LSM9DS0 on I2C (a new sample every 10 ms) and the EEPROM set by the input:
//   p  sensor answers (1, the default) or NACKs (0)
//   w  its WHO_AM_I value (default the right one)
//   s  stuck: no new samples (1) or running (0)
//   x, y, z  acceleration readings, LSB;  T  temperature reading (12 bits)
//   e  what the bytes after '|' are, written to EEPROM address 0 before
//      boot: 0 the raw EEPROM (the block at 0, the sensor ID's record at
//      512), 1 coefficient floats (little-endian; the paper's defaults after
//      them) encoded as a valid block for no sensor by the library
// Besides the common checks, the state commands set must show in frames:
// - no IMU frame between an acknowledged STOP and the next START;
// - coef_source in IMU and ICF frames is U after SETCOE, D after DEFCOE,
//   E after SAVECOE, E or D after SETID; ICF's streaming follows START and
//   STOP; ICF's sensor_id is the ID the EEPROM's record holds (none when
//   it is blank or damaged);
// - an IMU frame with coef_source D has temp_domain U unless a SETDOM was
//   acknowledged since the boot, DEFCOE or SETID: the defaults come from no
//   fit;
// - after an acknowledged RESET the board sends nothing until it has reset;
//   VER's reset_cause is COMMANDED exactly when an acknowledged RESET came
//   before and no other reset flag than the watchdog's is set (the first
//   boot of an input aside, whose RAM another input left), and a commanded
//   reset is never reported as ERR RESET.
#include <Compensation.h>
#include <LSM9DS0.h>
#include <Protocol.h>

#include <Arduino.h>
#include <avr/io.h>

#include "arduino_shim/ArduinoShim.h"
#include "board_harness.h"
#include "invariant.h"

#include <string.h>

namespace {

const uint32_t SAMPLE_PERIOD_MS = 10;
const int32_t TEMPERATURE_MIN = -2048;
const int32_t TEMPERATURE_MAX = 2047;
const uint8_t IMU_COEF_SOURCE = 12;
const uint8_t IMU_TEMP_DOMAIN = 13;
const uint8_t ICF_STREAMING = 1;
const uint8_t ICF_COEF_SOURCE = 2;
const uint8_t ICF_SENSOR_ID = 4;
// The sketch's SENSOR_ID_EEPROM_ADDRESS.
const uint16_t SENSOR_ID_EEPROM_ADDRESS = 512;
const uint8_t VER_RESET_CAUSE = 3;
const uint8_t ERR_CODE = 1;
const uint8_t OTHER_THAN_WATCHDOG = _BV(PORF) | _BV(EXTRF) | _BV(BORF);
const char UNKNOWN = 0;
// After SETID: what the EEPROM holds for the new ID, E or D.
const char RELOADED = 1;

int16_t clampToInt16(int32_t value)
{
    return (int16_t)(value < INT16_MIN ? INT16_MIN : value > INT16_MAX ? INT16_MAX : value);
}

// The XM die's registers; reading the acceleration takes the sample.
class FakeLsm9ds0 : public ArduinoShim::I2cDevice {
public:
    FakeLsm9ds0()
    {
        memset(registers_, 0, sizeof registers_);
        registers_[Lsm9ds0::WHO_AM_I_XM] = Lsm9ds0::WHO_AM_I_XM_VALUE;
        setAcceleration(0, 0);
        setAcceleration(1, 0);
        setAcceleration(2, 16384);
    }

    bool present = true;
    bool stuck = false;

    bool write(const uint8_t* data, size_t length) override
    {
        if (!present) {
            return false;
        }
        if (length > 0) {
            selectRegister(data[0]);
        }
        for (size_t i = 1; i < length; ++i) {
            registers_[next()] = data[i];
        }
        return true;
    }

    bool read(uint8_t* out, size_t length) override
    {
        if (!present) {
            return false;
        }
        for (size_t i = 0; i < length; ++i) {
            out[i] = readRegister(next());
        }
        return true;
    }

    void setRegister(uint8_t reg, uint8_t value) { registers_[reg] = value; }

    void setAcceleration(uint8_t axis, int32_t lsb)
    {
        uint16_t value = (uint16_t)clampToInt16(lsb);
        registers_[Lsm9ds0::OUT_X_L_A + 2 * axis] = (uint8_t)value;
        registers_[Lsm9ds0::OUT_X_L_A + 2 * axis + 1] = (uint8_t)(value >> 8);
    }

    void setTemperature(int32_t raw)
    {
        uint16_t value = (uint16_t)(raw < TEMPERATURE_MIN   ? TEMPERATURE_MIN
                                    : raw > TEMPERATURE_MAX ? TEMPERATURE_MAX
                                                            : raw);
        registers_[Lsm9ds0::OUT_TEMP_L_XM] = (uint8_t)value;
        registers_[Lsm9ds0::OUT_TEMP_H_XM] = (uint8_t)((value >> 8) & 0x0F);
    }

private:
    void selectRegister(uint8_t subAddress)
    {
        pointer_ = subAddress & (uint8_t)~Lsm9ds0::AUTO_INCREMENT;
        autoIncrement_ = (subAddress & Lsm9ds0::AUTO_INCREMENT) != 0;
    }

    uint8_t next()
    {
        uint8_t reg = pointer_;
        if (autoIncrement_) {
            pointer_ = (uint8_t)((pointer_ + 1) & 0x7F);
        }
        return reg;
    }

    uint32_t samplePeriod() const { return (uint32_t)millis() / SAMPLE_PERIOD_MS; }

    uint8_t readRegister(uint8_t reg)
    {
        bool running = !stuck && (registers_[Lsm9ds0::CTRL_REG1_XM] >> 4) != 0;
        if (reg == Lsm9ds0::STATUS_REG_A) {
            return running && samplePeriod() != samplePeriodTaken_ ? Lsm9ds0::STATUS_REG_A_ZYXADA : 0;
        }
        if (reg == Lsm9ds0::OUT_X_L_A) {
            samplePeriodTaken_ = samplePeriod();
        }
        return registers_[reg];
    }

    uint8_t registers_[128];
    uint8_t pointer_ = 0;
    bool autoIncrement_ = false;
    uint32_t samplePeriodTaken_ = UINT32_MAX;
};

void writeCoefficientBlock(const uint8_t* floats, size_t length)
{
    Coefficients coefficients;
    loadDefaultCoefficients(coefficients);
    float* terms = &coefficients.set[0].axis[0].p[0];
    size_t count = COMP_SET_COUNT * COMP_AXIS_COUNT * COMP_COEFFICIENT_COUNT;
    for (size_t i = 0; i < count && 4 * i + 4 <= length; ++i) {
        uint32_t bits = (uint32_t)floats[4 * i] | (uint32_t)floats[4 * i + 1] << 8 | (uint32_t)floats[4 * i + 2] << 16 |
                        (uint32_t)floats[4 * i + 3] << 24;
        memcpy(&terms[i], &bits, sizeof bits);
    }
    CalibratedDomain domain;
    clearDomain(domain);
    encodeCoefficients(coefficients, domain, "", ArduinoShim::eeprom());
}

class Imu : public Board {
public:
    void powerOn() override { ArduinoShim::attachI2cDevice(Lsm9ds0::ADDRESS_XM_SDO_HIGH, &sensor_); }

    void setWorld(char key, int32_t value, bool) override
    {
        switch (key) {
        case 'p': sensor_.present = value != 0; break;
        case 'w': sensor_.setRegister(Lsm9ds0::WHO_AM_I_XM, (uint8_t)value); break;
        case 's': sensor_.stuck = value != 0; break;
        case 'x': sensor_.setAcceleration(0, value); break;
        case 'y': sensor_.setAcceleration(1, value); break;
        case 'z': sensor_.setAcceleration(2, value); break;
        case 'T': sensor_.setTemperature(value); break;
        case 'e': eepromAsCoefficients_ = value == 1; break;
        default: break;
        }
    }

    // The EEPROM changes only while the board is off.
    void setWorldBytes(const uint8_t* data, size_t length, bool booted) override
    {
        if (booted) {
            return;
        }
        if (eepromAsCoefficients_) {
            writeCoefficientBlock(data, length);
        } else {
            memcpy(ArduinoShim::eeprom(), data, length < ArduinoShim::EEPROM_SIZE ? length : ArduinoShim::EEPROM_SIZE);
        }
    }

    void boot() override
    {
        streaming_ = UNKNOWN;
        coefficientSource_ = UNKNOWN;
        bool otherCause = (BoardHarness::bootResetFlags() & OTHER_THAN_WATCHDOG) != 0;
        commandedBoot_ = resetAcknowledged_ && !otherCause;
        // The first boot's RAM may hold a marker an earlier input left.
        causeKnown_ = booted_ || otherCause;
        resetAcknowledged_ = false;
        domainGiven_ = false;
        booted_ = true;
    }

    void sentFrame(const FrameParser& frame) override
    {
        require(!resetAcknowledged_, "a frame after RESET was acknowledged, before the reset");
        if (frame.typeIs(Protocol::Tag::VER)) {
            bool commanded = strcmp(BoardHarness::text(frame, VER_RESET_CAUSE), "COMMANDED") == 0;
            require(commanded == commandedBoot_ || (!causeKnown_ && commanded),
                    "VER's reset_cause COMMANDED differs from an acknowledged RESET before the boot");
        } else if (frame.typeIs(Protocol::Tag::ERR)) {
            require(!(commandedBoot_ && strcmp(BoardHarness::text(frame, ERR_CODE), "RESET") == 0),
                    "a commanded reset was reported as ERR RESET");
        }
        if (frame.typeIs(Protocol::Tag::ACK)) {
            acknowledged(BoardHarness::text(frame, 1));
        } else if (frame.typeIs(Protocol::Tag::IMU)) {
            require(streaming_ != '0', "an IMU frame after STOP was acknowledged");
            const char* source = BoardHarness::text(frame, IMU_COEF_SOURCE);
            requireSource(source);
            const char* domain = BoardHarness::text(frame, IMU_TEMP_DOMAIN);
            require(strcmp(domain, "I") == 0 || strcmp(domain, "O") == 0 || strcmp(domain, "U") == 0,
                    "temp_domain is neither I, O nor U");
            require(strcmp(source, "D") != 0 || domainGiven_ || strcmp(domain, "U") == 0,
                    "an IMU frame on the defaults has a calibrated domain");
        } else if (frame.typeIs(Protocol::Tag::ICF)) {
            const char* streaming = BoardHarness::text(frame, ICF_STREAMING);
            require(streaming_ == UNKNOWN || (streaming[0] == streaming_ && streaming[1] == '\0'),
                    "ICF's streaming differs from the last START or STOP");
            requireSource(BoardHarness::text(frame, ICF_COEF_SOURCE));
            SensorId stored;
            decodeSensorIdRecord(ArduinoShim::eeprom() + SENSOR_ID_EEPROM_ADDRESS, stored);
            require(strcmp(BoardHarness::text(frame, ICF_SENSOR_ID), stored.text) == 0,
                    "ICF's sensor_id differs from the EEPROM's ID record");
        }
    }

private:
    void acknowledged(const char* command)
    {
        if (strcmp(command, Protocol::Tag::START) == 0) {
            streaming_ = '1';
        } else if (strcmp(command, Protocol::Tag::STOP) == 0) {
            streaming_ = '0';
        } else if (strcmp(command, Protocol::Tag::SETCOE) == 0) {
            coefficientSource_ = 'U';
        } else if (strcmp(command, Protocol::Tag::DEFCOE) == 0) {
            coefficientSource_ = 'D';
            domainGiven_ = false;
        } else if (strcmp(command, Protocol::Tag::SETDOM) == 0) {
            domainGiven_ = true;
        } else if (strcmp(command, Protocol::Tag::SAVECOE) == 0) {
            coefficientSource_ = 'E';
        } else if (strcmp(command, Protocol::Tag::SETID) == 0) {
            coefficientSource_ = RELOADED;
            domainGiven_ = false;
        } else if (strcmp(command, Protocol::Tag::RESET) == 0) {
            resetAcknowledged_ = true;
        }
    }

    void requireSource(const char* source) const
    {
        bool reloaded = coefficientSource_ == RELOADED && (source[0] == 'E' || source[0] == 'D');
        require(coefficientSource_ == UNKNOWN || ((reloaded || source[0] == coefficientSource_) && source[1] == '\0'),
                "coef_source differs from what the last SETCOE, DEFCOE, SAVECOE or SETID made it");
    }

    FakeLsm9ds0 sensor_;
    bool eepromAsCoefficients_ = false;
    char streaming_ = UNKNOWN;
    char coefficientSource_ = UNKNOWN;
    bool booted_ = false;
    bool domainGiven_ = false;
    bool resetAcknowledged_ = false;
    bool commandedBoot_ = false;
    bool causeKnown_ = false;
};

}  // namespace

std::unique_ptr<Board> makeBoard()
{
    return std::unique_ptr<Board>(new Imu);
}
