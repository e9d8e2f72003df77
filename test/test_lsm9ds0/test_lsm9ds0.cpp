#include <string.h>
#include <unity.h>

#include "LSM9DS0.h"

// A register file standing in for the XM die. Like the real chip, a read
// without the auto-increment bit returns the same register every time, so a
// driver that forgets the bit reads garbage.
class FakeBus : public I2cBus {
public:
    uint8_t regs[0x40];
    uint8_t deviceAddress;
    bool answers;
    bool acceptsWrites;
    uint8_t writeCount;
    uint8_t writtenReg[5];
    uint8_t writtenValue[5];
    uint8_t lastSubAddress;

    void reset()
    {
        memset(regs, 0, sizeof(regs));
        deviceAddress = 0x1D;
        answers = true;
        acceptsWrites = true;
        writeCount = 0;
        lastSubAddress = 0;
    }

    bool writeRegister(uint8_t address7, uint8_t reg, uint8_t value) override
    {
        if (!answers || address7 != deviceAddress || !acceptsWrites) {
            return false;
        }
        if (writeCount < 5) {
            writtenReg[writeCount] = reg;
            writtenValue[writeCount] = value;
        }
        ++writeCount;
        regs[reg & 0x3F] = value;
        return true;
    }

    bool readRegisters(uint8_t address7, uint8_t firstReg, uint8_t* out, uint8_t count) override
    {
        if (!answers || address7 != deviceAddress) {
            return false;
        }
        lastSubAddress = firstReg;
        uint8_t reg = firstReg & 0x7F;
        for (uint8_t i = 0; i < count; ++i) {
            out[i] = regs[reg & 0x3F];
            if (firstReg & 0x80) {
                ++reg;
            }
        }
        return true;
    }
};

static FakeBus bus;

void setUp(void)
{
    bus.reset();
    bus.regs[0x0F] = 0x49;  // WHO_AM_I_XM
}

void tearDown(void) {}

static void test_begin_writes_table1(void)
{
    Lsm9ds0Accel accel(bus);
    TEST_ASSERT_EQUAL(Lsm9ds0Accel::Ok, accel.begin());
    TEST_ASSERT_EQUAL(5, bus.writeCount);
    // CTRL_REG1_XM: AODR 0110 (100 Hz), BDU 1, Z/Y/X 111 -> 0110 1111 = 0x6F
    TEST_ASSERT_EQUAL_HEX8(0x20, bus.writtenReg[0]);
    TEST_ASSERT_EQUAL_HEX8(0x6F, bus.writtenValue[0]);
    // CTRL_REG2_XM: ABW 11 (50 Hz), AFS 000 (2 g), rest 0 -> 1100 0000 = 0xC0
    TEST_ASSERT_EQUAL_HEX8(0x21, bus.writtenReg[1]);
    TEST_ASSERT_EQUAL_HEX8(0xC0, bus.writtenValue[1]);
    // CTRL_REG4_XM: P2_DRDYA only, accelerometer data-ready on INT2_XM -> 0000 1000 = 0x08
    TEST_ASSERT_EQUAL_HEX8(0x23, bus.writtenReg[2]);
    TEST_ASSERT_EQUAL_HEX8(0x08, bus.writtenValue[2]);
    // CTRL_REG5_XM: TEMP_EN 1, M_RES 00, M_ODR 100, LIR 00 -> 1001 0000 = 0x90
    TEST_ASSERT_EQUAL_HEX8(0x24, bus.writtenReg[3]);
    TEST_ASSERT_EQUAL_HEX8(0x90, bus.writtenValue[3]);
    // CTRL_REG7_XM: MD 00, magnetometer running, so the temperature updates.
    TEST_ASSERT_EQUAL_HEX8(0x26, bus.writtenReg[4]);
    TEST_ASSERT_EQUAL_HEX8(0x00, bus.writtenValue[4]);
}

static void test_begin_wrong_id(void)
{
    bus.regs[0x0F] = 0xD4;  // the gyro die's WHO_AM_I_G: wrong address strap
    Lsm9ds0Accel accel(bus);
    TEST_ASSERT_EQUAL(Lsm9ds0Accel::WrongId, accel.begin());
    TEST_ASSERT_EQUAL(0, bus.writeCount);
}

static void test_begin_no_answer(void)
{
    bus.answers = false;
    Lsm9ds0Accel accel(bus);
    TEST_ASSERT_EQUAL(Lsm9ds0Accel::NoAnswer, accel.begin());
}

static void test_begin_write_nack(void)
{
    bus.acceptsWrites = false;
    Lsm9ds0Accel accel(bus);
    TEST_ASSERT_EQUAL(Lsm9ds0Accel::WriteFailed, accel.begin());
}

static void test_begin_other_address(void)
{
    bus.deviceAddress = 0x1E;
    Lsm9ds0Accel atDefault(bus);
    TEST_ASSERT_EQUAL(Lsm9ds0Accel::NoAnswer, atDefault.begin());
    Lsm9ds0Accel atLow(bus, Lsm9ds0::ADDRESS_XM_SDO_LOW);
    TEST_ASSERT_EQUAL(Lsm9ds0Accel::Ok, atLow.begin());
}

static void test_accel_burst_decode(void)
{
    const uint8_t sample[6] = {0x01, 0x40, 0x00, 0xC0, 0xFF, 0x7F};
    memcpy(&bus.regs[0x28], sample, 6);
    Lsm9ds0Accel accel(bus);
    int16_t xyz[3] = {0, 0, 0};
    TEST_ASSERT_TRUE(accel.readAcceleration(xyz));
    TEST_ASSERT_EQUAL_HEX8(0xA8, bus.lastSubAddress);  // 0x28 | auto-increment
    TEST_ASSERT_EQUAL_INT16(16385, xyz[0]);            // 0x4001
    TEST_ASSERT_EQUAL_INT16(-16384, xyz[1]);           // 0xC000
    TEST_ASSERT_EQUAL_INT16(32767, xyz[2]);            // 0x7FFF
}

static void test_fresh_accel_reads_status_and_sample_in_one_burst(void)
{
    const uint8_t statusAndSample[7] = {0x0F, 0x01, 0x40, 0x00, 0xC0, 0xFF, 0x7F};
    memcpy(&bus.regs[0x27], statusAndSample, 7);
    Lsm9ds0Accel accel(bus);
    int16_t xyz[3] = {0, 0, 0};
    bool fresh = false;
    TEST_ASSERT_TRUE(accel.readFreshAcceleration(xyz, fresh));
    TEST_ASSERT_EQUAL_HEX8(0xA7, bus.lastSubAddress);  // 0x27 | auto-increment
    TEST_ASSERT_TRUE(fresh);
    TEST_ASSERT_EQUAL_INT16(16385, xyz[0]);
    TEST_ASSERT_EQUAL_INT16(-16384, xyz[1]);
    TEST_ASSERT_EQUAL_INT16(32767, xyz[2]);
    bus.regs[0x27] = 0x07;  // per-axis flags without ZYXADA: an old sample
    TEST_ASSERT_TRUE(accel.readFreshAcceleration(xyz, fresh));
    TEST_ASSERT_FALSE(fresh);
    bus.answers = false;
    TEST_ASSERT_FALSE(accel.readFreshAcceleration(xyz, fresh));
}

static void test_accel_read_fails(void)
{
    bus.answers = false;
    Lsm9ds0Accel accel(bus);
    int16_t xyz[3];
    TEST_ASSERT_FALSE(accel.readAcceleration(xyz));
}

static void test_temp_sign_extension(void)
{
    Lsm9ds0Accel accel(bus);
    int16_t raw = 0;
    bus.regs[0x05] = 0xFF;
    bus.regs[0x06] = 0x0F;
    TEST_ASSERT_TRUE(accel.readTemperatureRaw(raw));
    TEST_ASSERT_EQUAL_HEX8(0x85, bus.lastSubAddress);
    TEST_ASSERT_EQUAL_INT16(-1, raw);
    // -1/8 + 21 = 20.875
    TEST_ASSERT_FLOAT_WITHIN(0.001f, 20.875f, temperatureRawToC(raw));

    bus.regs[0x05] = 0xC8;
    bus.regs[0x06] = 0x00;
    TEST_ASSERT_TRUE(accel.readTemperatureRaw(raw));
    TEST_ASSERT_EQUAL_INT16(200, raw);
    // 200/8 + 21 = 46
    TEST_ASSERT_FLOAT_WITHIN(0.001f, 46.0f, temperatureRawToC(raw));
}

static void test_temp_bytes(void)
{
    TEST_ASSERT_EQUAL_INT16(-1, temperatureRawFromBytes(0xFF, 0xFF));
    TEST_ASSERT_EQUAL_INT16(-2048, temperatureRawFromBytes(0x00, 0x08));
    TEST_ASSERT_EQUAL_INT16(2047, temperatureRawFromBytes(0xFF, 0x07));
    TEST_ASSERT_EQUAL_INT16(2047, temperatureRawFromBytes(0xFF, 0xF7));
}

static void test_temp_offset_param(void)
{
    TEST_ASSERT_FLOAT_WITHIN(0.001f, 25.0f, temperatureRawToC(200, 0.0f));
    TEST_ASSERT_FLOAT_WITHIN(0.001f, -5.0f, temperatureRawToC(-208, 21.0f));
}

static void test_data_ready(void)
{
    Lsm9ds0Accel accel(bus);
    bus.regs[0x27] = 0x08;  // ZYXADA
    TEST_ASSERT_TRUE(accel.dataReady());
    bus.regs[0x27] = 0x07;  // per-axis flags only
    TEST_ASSERT_FALSE(accel.dataReady());
    bus.regs[0x27] = 0x08;
    bus.answers = false;
    TEST_ASSERT_FALSE(accel.dataReady());
}

static void readSamples(DataReadyLine& line, uint8_t count, bool levelWhenReady, bool levelAfterRead)
{
    for (uint8_t i = 0; i < count; ++i) {
        line.sampleRead(levelWhenReady, levelAfterRead);
    }
}

static void test_data_ready_line_learns_either_polarity(void)
{
    const bool levels[2] = {true, false};
    for (uint8_t i = 0; i < 2; ++i) {
        const bool active = levels[i];
        DataReadyLine line;
        readSamples(line, DataReadyLine::SAMPLES_TO_TRUST - 1, active, !active);
        TEST_ASSERT_FALSE(line.trusted());
        TEST_ASSERT_FALSE(line.saysReady(active));
        line.sampleRead(active, !active);
        TEST_ASSERT_TRUE(line.trusted());
        TEST_ASSERT_EQUAL(active, line.activeHigh());
        TEST_ASSERT_TRUE(line.saysReady(active));
        TEST_ASSERT_FALSE(line.saysReady(!active));
    }
}

static void test_data_ready_line_that_does_not_toggle_is_never_trusted(void)
{
    // An unwired pin with its pull-up: high whether or not a sample is ready.
    DataReadyLine line;
    readSamples(line, 3 * DataReadyLine::SAMPLES_TO_TRUST, true, true);
    TEST_ASSERT_FALSE(line.trusted());
    TEST_ASSERT_FALSE(line.saysReady(true));
}

static void test_data_ready_line_loses_trust_on_one_bad_sample(void)
{
    DataReadyLine line;
    readSamples(line, DataReadyLine::SAMPLES_TO_TRUST, true, false);
    TEST_ASSERT_TRUE(line.trusted());
    // Stuck active after the read: the next pass would read a sample twice.
    line.sampleRead(true, true);
    TEST_ASSERT_FALSE(line.trusted());
    readSamples(line, DataReadyLine::SAMPLES_TO_TRUST, true, false);
    TEST_ASSERT_TRUE(line.trusted());
    // The polarity seen flips (a floating pin): trust starts again from that sample.
    line.sampleRead(false, true);
    TEST_ASSERT_FALSE(line.trusted());
    readSamples(line, DataReadyLine::SAMPLES_TO_TRUST - 1, false, true);
    TEST_ASSERT_TRUE(line.trusted());
    TEST_ASSERT_FALSE(line.activeHigh());
    line.distrust();
    TEST_ASSERT_FALSE(line.trusted());
}

static void test_accel_scale(void)
{
    // 1 g / 0.061 mg = 16393.4 LSB; 16393 * 0.000061 = 0.999973 g
    TEST_ASSERT_FLOAT_WITHIN(0.0001f, 1.0f, accelLsbToG(16393));
    TEST_ASSERT_FLOAT_WITHIN(0.0001f, -1.0f, accelLsbToG(-16393));
    TEST_ASSERT_FLOAT_WITHIN(0.00001f, 0.000061f, accelLsbToG(1));
}

int runUnityTests(void)
{
    UNITY_BEGIN();
    RUN_TEST(test_begin_writes_table1);
    RUN_TEST(test_begin_wrong_id);
    RUN_TEST(test_begin_no_answer);
    RUN_TEST(test_begin_write_nack);
    RUN_TEST(test_begin_other_address);
    RUN_TEST(test_accel_burst_decode);
    RUN_TEST(test_fresh_accel_reads_status_and_sample_in_one_burst);
    RUN_TEST(test_accel_read_fails);
    RUN_TEST(test_temp_sign_extension);
    RUN_TEST(test_temp_bytes);
    RUN_TEST(test_temp_offset_param);
    RUN_TEST(test_data_ready);
    RUN_TEST(test_data_ready_line_learns_either_polarity);
    RUN_TEST(test_data_ready_line_that_does_not_toggle_is_never_trusted);
    RUN_TEST(test_data_ready_line_loses_trust_on_one_bad_sample);
    RUN_TEST(test_accel_scale);
    return UNITY_END();
}
