#include <unity.h>

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "Protocol.h"

// FrameWriter writes the digits of integers and of floats in fixed notation
// itself (Protocol.cpp's formatUnsigned and roundToDecimals), where the AVR
// used avr-libc's ultoa and dtostrf: the text must be the same, bit for bit,
// as those give on the AVR and as printf gives here.

static char buffer[Protocol::LINE_BUFFER_SIZE];

void setUp(void) {}

void tearDown(void) {}

// The text of the only field of the frame writer holds.
static const char *onlyField(FrameWriter &writer)
{
    char *line = (char *)writer.finish();
    TEST_ASSERT_NOT_NULL(line);
    *strchr(line, '*') = '\0';
    return line + strlen("$ERR,1,");
}

static const char *fixedField(float value, uint8_t decimals)
{
    FrameWriter writer(buffer, sizeof buffer);
    writer.begin(Protocol::Tag::ERR, 1);
    writer.addFixed(value, decimals);
    return onlyField(writer);
}

static const char *unsignedField(uint32_t value)
{
    FrameWriter writer(buffer, sizeof buffer);
    writer.begin(Protocol::Tag::ERR, 1);
    writer.addUnsigned(value);
    return onlyField(writer);
}

// Ties round away from zero, as avr-libc's dtostrf rounds them (the same
// floats through glibc's printf give 0.2, 2, 1649.7); a sign stays on zero.
static void test_fixed_rounds_ties_away_from_zero(void)
{
    TEST_ASSERT_EQUAL_STRING("0.3", fixedField(0.25f, 1));
    TEST_ASSERT_EQUAL_STRING("-0.3", fixedField(-0.25f, 1));
    TEST_ASSERT_EQUAL_STRING("3", fixedField(2.5f, 0));
    TEST_ASSERT_EQUAL_STRING("-1649.8", fixedField(-1649.75f, 1));
    TEST_ASSERT_EQUAL_STRING("0.063", fixedField(0.0625f, 3));
    TEST_ASSERT_EQUAL_STRING("-0.0", fixedField(-0.04f, 1));
    TEST_ASSERT_EQUAL_STRING("-0.000", fixedField(-0.0f, 3));
    TEST_ASSERT_EQUAL_STRING("0.000", fixedField(1e-45f, 3));
    TEST_ASSERT_EQUAL_STRING("9999999.0", fixedField(9999999.0f, 1));
}

static uint32_t randomState = 12345;

static uint32_t nextRandom(void)
{
    randomState ^= randomState << 13;
    randomState ^= randomState >> 17;
    randomState ^= randomState << 5;
    return randomState;
}

static float floatFromBits(uint32_t bits)
{
    float value;
    memcpy(&value, &bits, sizeof value);
    return value;
}

// The C library's text for value: on the AVR dtostrf, which FrameWriter's
// own digits replace; elsewhere printf, nudged by 2^-45 of value so that a
// tie rounds away from zero (a float that is not a tie is at least 2^-31 of
// itself from one, see Protocol.cpp's roundToDecimals).
static void libraryFixed(float value, uint8_t decimals, char *out, size_t size)
{
#ifdef __AVR__
    (void)size;
    dtostrf(value, 0, decimals, out);
#else
    snprintf(out, size, "%.*f", (int)decimals, (double)value * (1.0 + ldexp(1.0, -45)));
#endif
}

static uint16_t fixedMismatches = 0;
static uint16_t fixedCompared = 0;

// Only where FrameWriter writes the digits itself (value * 10^decimals
// rounds below 10^7): beyond, it hands value to the library too.
static void compareFixed(float value, uint8_t decimals)
{
    static const float LIMITS[] = {9999999.5f, 999999.95f, 99999.995f, 9999.9995f};
    if (!(fabsf(value) < LIMITS[decimals])) {
        return;
    }
    ++fixedCompared;
    char expected[32];
    libraryFixed(value, decimals, expected, sizeof expected);
    const char *field = fixedField(value, decimals);
    if (strcmp(expected, field) != 0 && fixedMismatches++ < 4) {
        char message[80];
        // As bits: avr-libc's snprintf has no %g.
        uint32_t bits;
        memcpy(&bits, &value, sizeof bits);
        snprintf(message, sizeof message, "float 0x%08lx to %u decimals: %s, not %s", (unsigned long)bits, decimals,
                 field, expected);
        TEST_MESSAGE(message);
    }
}

// Every binade from 2^-12 up to where the library takes over, random mantissas and both signs, at 0..3 decimals;
// next to each, the float nearest a tie (value * 10^decimals = j + 1/2) and
// its two neighbours either side, where a conversion that is not exact goes
// wrong first.
static void test_fixed_matches_the_c_library(void)
{
    static const uint8_t FIVE_POWERS[] = {1, 5, 25, 125};
    const uint32_t HIDDEN_BIT = 0x800000UL;
    fixedMismatches = 0;
    fixedCompared = 0;
    for (uint8_t decimals = 0; decimals <= 3; ++decimals) {
        for (int16_t exponent = -12; exponent <= 23; ++exponent) {
            uint32_t biased = (uint32_t)(exponent + 127) << 23;
            int16_t shift = (int16_t)(150 - (exponent + 127) - decimals);
            for (uint8_t draw = 0; draw < 8; ++draw) {
                uint32_t sign = (nextRandom() & 1u) ? 0x80000000UL : 0;
                uint32_t mantissa = HIDDEN_BIT | (nextRandom() & (HIDDEN_BIT - 1));
                compareFixed(floatFromBits(sign | biased | (mantissa - HIDDEN_BIT)), decimals);
                if (shift < 1 || shift > 31) {
                    continue;
                }
                uint32_t scaled = mantissa * FIVE_POWERS[decimals];
                uint32_t tie = (scaled & ~((1UL << shift) - 1)) | (1UL << (shift - 1));
                uint32_t nearest = tie / FIVE_POWERS[decimals];
                for (int8_t step = -2; step <= 2; ++step) {
                    uint32_t neighbour = nearest + (uint32_t)(int32_t)step;
                    if (neighbour >= HIDDEN_BIT && neighbour < 2 * HIDDEN_BIT) {
                        compareFixed(floatFromBits(sign | biased | (neighbour - HIDDEN_BIT)), decimals);
                    }
                }
            }
        }
    }
    TEST_ASSERT_GREATER_THAN(4000, fixedCompared);
    TEST_ASSERT_EQUAL_UINT16(0, fixedMismatches);
}

static uint16_t unsignedMismatches = 0;

static void compareUnsigned(uint32_t value)
{
    char expected[12];
#ifdef __AVR__
    ultoa(value, expected, 10);
#else
    snprintf(expected, sizeof expected, "%lu", (unsigned long)value);
#endif
    const char *field = unsignedField(value);
    if (strcmp(expected, field) != 0 && unsignedMismatches++ < 4) {
        TEST_MESSAGE(field);
    }
}

// Each power of ten, one either side of it, and random values of every bit
// length: every digit position, every leading digit.
static void test_unsigned_matches_the_c_library(void)
{
    unsignedMismatches = 0;
    uint32_t power = 1;
    for (uint8_t digits = 0; digits < 10; ++digits, power *= 10) {
        compareUnsigned(power - 1);
        compareUnsigned(power);
        compareUnsigned(power + 1);
    }
    compareUnsigned(0xFFFFFFFFUL);
    for (uint8_t bits = 1; bits <= 32; ++bits) {
        for (uint8_t draw = 0; draw < 32; ++draw) {
            compareUnsigned(nextRandom() >> (32 - bits));
        }
    }
    TEST_ASSERT_EQUAL_UINT16(0, unsignedMismatches);
}

int runUnityTests(void)
{
    UNITY_BEGIN();
    RUN_TEST(test_fixed_rounds_ties_away_from_zero);
    RUN_TEST(test_fixed_matches_the_c_library);
    RUN_TEST(test_unsigned_matches_the_c_library);
    return UNITY_END();
}
