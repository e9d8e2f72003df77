#include <math.h>
#include <string.h>
#include <unity.h>

#include <Crc16.h>

#include "Compensation.h"

// The coefficient block in EEPROM (lib/Compensation, docs/protocol.md) and
// the calibrated domain it carries. Expected bytes and CRCs come from Python
// (struct.pack, binascii.crc_hqx(data, 0)); none are copied from this code's
// output.

static Coefficients coefficients;
static CalibratedDomain domain;
static uint8_t block[COEFFICIENT_BLOCK_SIZE];

void setUp(void)
{
    loadDefaultCoefficients(coefficients);
    clearDomain(domain);
}

void tearDown(void) {}

static void test_crc_vector(void)
{
    const uint8_t check[] = {'1', '2', '3', '4', '5', '6', '7', '8', '9'};
    TEST_ASSERT_EQUAL_HEX16(0x31C3, crc16Xmodem(check, sizeof(check)));
}

static void putCrc(uint8_t* bytes, uint8_t length)
{
    uint16_t crc = crc16Xmodem(bytes, length);
    bytes[length] = (uint8_t)crc;
    bytes[length + 1] = (uint8_t)(crc >> 8);
}

static void test_block_default_bytes(void)
{
    encodeCoefficients(coefficients, domain, "", block);
    TEST_ASSERT_EQUAL_HEX8(0x54, block[0]);
    TEST_ASSERT_EQUAL_HEX8(0x02, block[1]);
    // Python struct.pack('<f', 571.5) and ('<f', -20.23)
    const uint8_t p00p10[] = {0x00, 0xE0, 0x0E, 0x44, 0x0A, 0xD7, 0xA1, 0xC1};
    TEST_ASSERT_EQUAL_MEMORY(p00p10, &block[2], 8);
    // No ID: eight NULs; no domain: every range (32767, -32768).
    const uint8_t unbound[8] = {0};
    TEST_ASSERT_EQUAL_MEMORY(unbound, &block[146], 8);
    const uint8_t noRange[] = {0xFF, 0x7F, 0x00, 0x80};
    for (uint8_t range = 0; range < 8; ++range) {
        TEST_ASSERT_EQUAL_MEMORY(noRange, &block[154 + 4 * range], 4);
    }
    // Python binascii.crc_hqx of bytes 0..185 of this block: 0x5093
    TEST_ASSERT_EQUAL_HEX8(0x93, block[186]);
    TEST_ASSERT_EQUAL_HEX8(0x50, block[187]);
}

// A domain like a campaign's at -10..45 degC and +-1 g, Z not fitted.
static void setCampaignDomain(CalibratedDomain& out)
{
    const int16_t bounds[COMP_SET_COUNT][8] = {
        {-1012, 4498, -16500, 16400, -16450, 16420, INT16_MAX, INT16_MIN},
        {-1005, 4501, -16510, 16390, -16440, 16410, INT16_MAX, INT16_MIN},
    };
    for (uint8_t s = 0; s < COMP_SET_COUNT; ++s) {
        out.set[s].temperatureCentiC.min = bounds[s][0];
        out.set[s].temperatureCentiC.max = bounds[s][1];
        for (uint8_t a = 0; a < COMP_AXIS_COUNT; ++a) {
            out.set[s].accelLsb[a].min = bounds[s][2 + 2 * a];
            out.set[s].accelLsb[a].max = bounds[s][3 + 2 * a];
        }
    }
}

static void test_block_id_and_domain_bytes(void)
{
    setCampaignDomain(domain);
    encodeCoefficients(coefficients, domain, "NODE-07", block);
    const uint8_t id[] = {'N', 'O', 'D', 'E', '-', '0', '7', 0};
    TEST_ASSERT_EQUAL_MEMORY(id, &block[146], 8);
    // Python struct.pack('<4h', -1012, 4498, -16500, 16400): warming's
    // temperature range, then X's.
    const uint8_t warming[] = {0x0C, 0xFC, 0x92, 0x11, 0x8C, 0xBF, 0x10, 0x40};
    TEST_ASSERT_EQUAL_MEMORY(warming, &block[154], 8);
    // Python struct.pack('<2h', -1005, 4501): cooling's temperature range.
    const uint8_t cooling[] = {0x13, 0xFC, 0x95, 0x11};
    TEST_ASSERT_EQUAL_MEMORY(cooling, &block[170], 4);
    // Python binascii.crc_hqx of bytes 0..185: 0x9062
    TEST_ASSERT_EQUAL_HEX8(0x62, block[186]);
    TEST_ASSERT_EQUAL_HEX8(0x90, block[187]);
}

static void test_block_round_trip(void)
{
    // Each term scaled to the size of the paper's, so that decoding accepts
    // the surfaces (an output of at most a few thousand LSB).
    const float termScale[COMP_COEFFICIENT_COUNT] = {1.0f, 1e-1f, 1e-3f, 1e-3f, 1e-5f, 1e-9f};
    Coefficients original;
    for (uint8_t s = 0; s < COMP_SET_COUNT; ++s) {
        for (uint8_t a = 0; a < COMP_AXIS_COUNT; ++a) {
            for (uint8_t k = 0; k < COMP_COEFFICIENT_COUNT; ++k) {
                original.set[s].axis[a].p[k] = ((float)(s * 100 + a * 10 + k) * -1.25e-3f + 7.0f) * termScale[k];
            }
        }
    }
    CalibratedDomain originalDomain;
    setCampaignDomain(originalDomain);
    encodeCoefficients(original, originalDomain, "a_Z-9", block);
    TEST_ASSERT(decodeCoefficients(block, "a_Z-9", coefficients, domain) == BlockStatus::Ok);
    TEST_ASSERT_EQUAL_MEMORY(&original, &coefficients, sizeof(Coefficients));
    TEST_ASSERT_EQUAL_MEMORY(&originalDomain, &domain, sizeof(CalibratedDomain));
}

static uint8_t nextWrite;

static bool writesInOrder;

static uint8_t highestRead;

static void writeInOrder(void* context, uint8_t index, uint8_t value)
{
    writesInOrder = writesInOrder && index == nextWrite;
    ++nextWrite;
    static_cast<uint8_t*>(context)[index] = value;
}

static uint8_t readNoted(const void* context, uint8_t index)
{
    highestRead = index > highestRead ? index : highestRead;
    return static_cast<const uint8_t*>(context)[index];
}

static void test_block_through_byte_callbacks(void)
{
    setCampaignDomain(domain);
    nextWrite = 0;
    writesInOrder = true;
    encodeCoefficients(coefficients, domain, "NODE-07", writeInOrder, block);
    TEST_ASSERT_TRUE(writesInOrder);
    TEST_ASSERT_EQUAL_UINT8(COEFFICIENT_BLOCK_SIZE, nextWrite);
    // The bytes of test_block_id_and_domain_bytes, CRC included.
    TEST_ASSERT_EQUAL_HEX8(0x62, block[186]);
    TEST_ASSERT_EQUAL_HEX8(0x90, block[187]);

    Coefficients loaded;
    CalibratedDomain loadedDomain;
    highestRead = 0;
    TEST_ASSERT(decodeCoefficients(readNoted, block, "NODE-07", loaded, loadedDomain) == BlockStatus::Ok);
    TEST_ASSERT_EQUAL_UINT8(COEFFICIENT_BLOCK_SIZE - 1, highestRead);
    TEST_ASSERT_EQUAL_MEMORY(&coefficients, &loaded, sizeof(Coefficients));
    TEST_ASSERT_EQUAL_MEMORY(&domain, &loadedDomain, sizeof(CalibratedDomain));
}

static void test_version_1_block_still_loads(void)
{
    // Version 1: the surfaces, then the CRC; the rest of the EEPROM erased.
    encodeCoefficients(coefficients, domain, "", block);
    block[1] = 1;
    putCrc(block, 146);
    memset(block + COEFFICIENT_BLOCK_V1_SIZE, 0xFF, COEFFICIENT_BLOCK_SIZE - COEFFICIENT_BLOCK_V1_SIZE);
    // Python binascii.crc_hqx of the paper-default version 1 block: 0xD9E0
    TEST_ASSERT_EQUAL_HEX8(0xE0, block[146]);
    TEST_ASSERT_EQUAL_HEX8(0xD9, block[147]);

    Coefficients loaded;
    memset(&loaded, 0, sizeof loaded);
    setCampaignDomain(domain);
    // Fitted for no sensor: it loads on a board with or without an ID.
    TEST_ASSERT(decodeCoefficients(block, "NODE-07", loaded, domain) == BlockStatus::Ok);
    TEST_ASSERT_EQUAL_MEMORY(&coefficients, &loaded, sizeof(Coefficients));
    for (uint8_t s = 0; s < COMP_SET_COUNT; ++s) {
        TEST_ASSERT_FALSE(domain.set[s].temperatureCentiC.known());
        TEST_ASSERT_FALSE(domain.set[s].accelLsb[0].known());
    }
    TEST_ASSERT(decodeCoefficients(block, "", loaded, domain) == BlockStatus::Ok);

    // A damaged version 1 block fails its own CRC.
    block[100] ^= 0x10;
    TEST_ASSERT(decodeCoefficients(block, "", loaded, domain) == BlockStatus::BadCrc);
}

static void test_block_rejects(void)
{
    encodeCoefficients(coefficients, domain, "", block);
    Coefficients untouched;
    memset(&untouched, 0, sizeof(untouched));

    block[77] ^= 0x04;
    TEST_ASSERT(decodeCoefficients(block, "", untouched, domain) == BlockStatus::BadCrc);
    block[77] ^= 0x04;
    block[160] ^= 0x01;
    TEST_ASSERT(decodeCoefficients(block, "", untouched, domain) == BlockStatus::BadCrc);
    block[160] ^= 0x01;
    block[187] ^= 0x80;
    TEST_ASSERT(decodeCoefficients(block, "", untouched, domain) == BlockStatus::BadCrc);
    block[187] ^= 0x80;

    block[0] = 'X';
    TEST_ASSERT(decodeCoefficients(block, "", untouched, domain) == BlockStatus::BadMagic);
    block[0] = 0x54;

    // Well-formed blocks of other versions, CRC recomputed.
    block[1] = 3;
    putCrc(block, 186);
    TEST_ASSERT(decodeCoefficients(block, "", untouched, domain) == BlockStatus::BadVersion);
    block[1] = 0;
    putCrc(block, 146);
    TEST_ASSERT(decodeCoefficients(block, "", untouched, domain) == BlockStatus::BadVersion);

    TEST_ASSERT_FLOAT_WITHIN(1e-6f, 0.0f, untouched.set[0].axis[0].p[0]);
    TEST_ASSERT_FLOAT_WITHIN(1e-6f, 0.0f, untouched.set[1].axis[1].p[0]);
}

static void test_temperature_domain(void)
{
    setCampaignDomain(domain);
    const SetDomain& warming = domain.set[(uint8_t)CompSet::Warming];
    const SetDomain& cooling = domain.set[(uint8_t)CompSet::Cooling];
    TEST_ASSERT(checkTemperature(warming, 25.0f) == DomainCheck::Inside);
    TEST_ASSERT(checkTemperature(warming, -10.12f) == DomainCheck::Inside);
    TEST_ASSERT(checkTemperature(warming, 44.98f) == DomainCheck::Inside);
    TEST_ASSERT(checkTemperature(warming, -10.125f) == DomainCheck::Outside);
    TEST_ASSERT(checkTemperature(warming, 45.0f) == DomainCheck::Outside);
    TEST_ASSERT(checkTemperature(cooling, 45.0f) == DomainCheck::Inside);
    TEST_ASSERT(checkTemperature(cooling, -10.125f) == DomainCheck::Outside);
    TEST_ASSERT(checkTemperature(warming, -40.0f) == DomainCheck::Outside);
    TEST_ASSERT(checkTemperature(warming, NAN) == DomainCheck::Outside);
    clearDomain(domain);
    TEST_ASSERT(checkTemperature(warming, 25.0f) == DomainCheck::Unknown);
    TEST_ASSERT(checkTemperature(cooling, 25.0f) == DomainCheck::Unknown);
}

static bool allBytesZero(const Coefficients& value)
{
    const uint8_t* bytes = (const uint8_t*)&value;
    for (size_t i = 0; i < sizeof value; ++i) {
        if (bytes[i] != 0) {
            return false;
        }
    }
    return true;
}

static void test_block_blank_and_bad_values(void)
{
    // A single Coefficients (144 bytes) on the stack, for the Nano's sake.
    Coefficients untouched;
    memset(&untouched, 0, sizeof(untouched));

    memset(block, 0xFF, sizeof(block));
    TEST_ASSERT(decodeCoefficients(block, "", untouched, domain) == BlockStatus::Blank);

    // Power lost while saving over a blank EEPROM: the first 100 bytes written.
    encodeCoefficients(coefficients, domain, "", block);
    memset(block + 100, 0xFF, sizeof(block) - 100);
    TEST_ASSERT(decodeCoefficients(block, "", untouched, domain) == BlockStatus::BadCrc);

    // An erased magic byte in front of written data is damage, not blank.
    encodeCoefficients(coefficients, domain, "", block);
    block[0] = 0xFF;
    TEST_ASSERT(decodeCoefficients(block, "", untouched, domain) == BlockStatus::BadMagic);

    // Sound blocks (CRC computed over them) carrying values no frame can hold.
    coefficients.set[1].axis[2].p[P20] = NAN;
    encodeCoefficients(coefficients, domain, "", block);
    TEST_ASSERT(decodeCoefficients(block, "", untouched, domain) == BlockStatus::BadValues);
    loadDefaultCoefficients(coefficients);
    coefficients.set[0].axis[1].p[P00] = 2e6f;
    encodeCoefficients(coefficients, domain, "", block);
    TEST_ASSERT(decodeCoefficients(block, "", untouched, domain) == BlockStatus::BadValues);

    TEST_ASSERT_TRUE(allBytesZero(untouched));
}

int runUnityTests(void)
{
    UNITY_BEGIN();
    RUN_TEST(test_crc_vector);
    RUN_TEST(test_block_default_bytes);
    RUN_TEST(test_block_id_and_domain_bytes);
    RUN_TEST(test_block_round_trip);
    RUN_TEST(test_block_through_byte_callbacks);
    RUN_TEST(test_version_1_block_still_loads);
    RUN_TEST(test_block_rejects);
    RUN_TEST(test_temperature_domain);
    RUN_TEST(test_block_blank_and_bad_values);
    return UNITY_END();
}
