#include <string.h>
#include <unity.h>

#include <Crc16.h>

#include "Compensation.h"
#include "SensorId.h"

// The sensor ID: its rules, its EEPROM record and how a coefficient block
// binds to it. CRCs come from binascii.crc_hqx(data, 0), none from this code.

static Coefficients coefficients;
static CalibratedDomain domain;
static uint8_t block[COEFFICIENT_BLOCK_SIZE];

void setUp(void)
{
    loadDefaultCoefficients(coefficients);
    clearDomain(domain);
}

void tearDown(void) {}

static void putCrc(uint8_t* bytes, uint8_t length)
{
    uint16_t crc = crc16Xmodem(bytes, length);
    bytes[length] = (uint8_t)crc;
    bytes[length + 1] = (uint8_t)(crc >> 8);
}

static void setSomeDomain(CalibratedDomain& out)
{
    for (uint8_t s = 0; s < COMP_SET_COUNT; ++s) {
        out.set[s].temperatureCentiC.min = (int16_t)(-1000 - s);
        out.set[s].temperatureCentiC.max = (int16_t)(4500 + s);
        for (uint8_t a = 0; a < COMP_AXIS_COUNT; ++a) {
            out.set[s].accelLsb[a].min = (int16_t)(-16000 - a);
            out.set[s].accelLsb[a].max = (int16_t)(16000 + a);
        }
    }
}

static void test_block_loads_only_for_its_sensor(void)
{
    setSomeDomain(domain);
    encodeCoefficients(coefficients, domain, "NODE-07", block);
    Coefficients loaded;
    memset(&loaded, 0, sizeof loaded);
    CalibratedDomain loadedDomain;
    clearDomain(loadedDomain);

    TEST_ASSERT(decodeCoefficients(block, "NODE-08", loaded, loadedDomain) == BlockStatus::OtherSensor);
    TEST_ASSERT(decodeCoefficients(block, "NODE-0", loaded, loadedDomain) == BlockStatus::OtherSensor);
    TEST_ASSERT(decodeCoefficients(block, "node-07", loaded, loadedDomain) == BlockStatus::OtherSensor);
    // A board without an ID is not the sensor the block was fitted for.
    TEST_ASSERT(decodeCoefficients(block, "", loaded, loadedDomain) == BlockStatus::OtherSensor);
    TEST_ASSERT_FLOAT_WITHIN(1e-6f, 0.0f, loaded.set[0].axis[0].p[0]);
    TEST_ASSERT_FALSE(loadedDomain.set[0].temperatureCentiC.known());

    TEST_ASSERT(decodeCoefficients(block, "NODE-07", loaded, loadedDomain) == BlockStatus::Ok);
    TEST_ASSERT_EQUAL_MEMORY(&coefficients, &loaded, sizeof(Coefficients));
    TEST_ASSERT_EQUAL_MEMORY(&domain, &loadedDomain, sizeof(CalibratedDomain));

    // Fitted for no sensor: any board.
    encodeCoefficients(coefficients, domain, "", block);
    TEST_ASSERT(decodeCoefficients(block, "NODE-08", loaded, loadedDomain) == BlockStatus::Ok);
}

static void test_block_with_a_bad_id_field(void)
{
    Coefficients untouched;
    memset(&untouched, 0, sizeof untouched);
    encodeCoefficients(coefficients, domain, "AB", block);
    // A character an ID cannot hold, CRC recomputed: sound, but not an ID.
    block[147] = ' ';
    putCrc(block, 186);
    TEST_ASSERT(decodeCoefficients(block, "A B", untouched, domain) == BlockStatus::BadValues);
    // Text after the NUL padding.
    block[147] = 'B';
    block[150] = 'C';
    putCrc(block, 186);
    TEST_ASSERT(decodeCoefficients(block, "AB", untouched, domain) == BlockStatus::BadValues);
    TEST_ASSERT_FLOAT_WITHIN(1e-6f, 0.0f, untouched.set[0].axis[0].p[0]);
}

static void test_sensor_id_rules(void)
{
    TEST_ASSERT_TRUE(isValidSensorId(""));
    TEST_ASSERT_TRUE(isValidSensorId("N"));
    TEST_ASSERT_TRUE(isValidSensorId("az_AZ-09"));
    TEST_ASSERT_FALSE(isValidSensorId("NODE-0007"));
    TEST_ASSERT_FALSE(isValidSensorId("NODE 07"));
    TEST_ASSERT_FALSE(isValidSensorId("NODE.07"));
    TEST_ASSERT_FALSE(isValidSensorId("N,7"));
    TEST_ASSERT_FALSE(isValidSensorId("\xC3\xA9"));
}

static void test_sensor_id_record(void)
{
    uint8_t record[SENSOR_ID_RECORD_SIZE];
    SensorId id;
    encodeSensorIdRecord("NODE-07", record);
    // Python: b"INODE-07\0" and binascii.crc_hqx of it, 0xAB20.
    const uint8_t expected[] = {0x49, 'N', 'O', 'D', 'E', '-', '0', '7', 0x00, 0x20, 0xAB};
    TEST_ASSERT_EQUAL_MEMORY(expected, record, sizeof expected);
    TEST_ASSERT(decodeSensorIdRecord(record, id) == IdRecordStatus::Ok);
    TEST_ASSERT_EQUAL_STRING("NODE-07", id.text);

    encodeSensorIdRecord("ABCDEFGH", record);
    TEST_ASSERT(decodeSensorIdRecord(record, id) == IdRecordStatus::Ok);
    TEST_ASSERT_EQUAL_STRING("ABCDEFGH", id.text);
    encodeSensorIdRecord("", record);
    TEST_ASSERT(decodeSensorIdRecord(record, id) == IdRecordStatus::Ok);
    TEST_ASSERT_EQUAL_STRING("", id.text);

    memset(record, 0xFF, sizeof record);
    TEST_ASSERT(decodeSensorIdRecord(record, id) == IdRecordStatus::Blank);
    TEST_ASSERT_EQUAL_STRING("", id.text);

    encodeSensorIdRecord("NODE-07", record);
    record[7] = '8';
    TEST_ASSERT(decodeSensorIdRecord(record, id) == IdRecordStatus::Damaged);
    TEST_ASSERT_EQUAL_STRING("", id.text);
    encodeSensorIdRecord("NODE-07", record);
    record[0] = 'T';
    putCrc(record, 9);
    TEST_ASSERT(decodeSensorIdRecord(record, id) == IdRecordStatus::Damaged);
    // Power lost after the first bytes of a new record.
    encodeSensorIdRecord("NODE-07", record);
    memset(record + 4, 0xFF, sizeof record - 4);
    TEST_ASSERT(decodeSensorIdRecord(record, id) == IdRecordStatus::Damaged);
}

int runUnityTests(void)
{
    UNITY_BEGIN();
    RUN_TEST(test_sensor_id_rules);
    RUN_TEST(test_sensor_id_record);
    RUN_TEST(test_block_loads_only_for_its_sensor);
    RUN_TEST(test_block_with_a_bad_id_field);
    return UNITY_END();
}
