#include <math.h>
#include <string.h>
#include <unity.h>

#include <Crc16.h>

#include "Compensation.h"

// Expected numbers below come from a Python (double precision) evaluation of
// the paper's equation (3) with the Table 2/3 coefficients, and from
// binascii.crc_hqx(data, 0) for CRCs; none are copied from this code's output.

static Coefficients coefficients;
static CalibratedDomain domain;
static uint8_t block[COEFFICIENT_BLOCK_SIZE];

void setUp(void)
{
    loadDefaultCoefficients(coefficients);
    clearDomain(domain);
}

void tearDown(void) {}

static const AxisSurface& surface(CompSet set, uint8_t axis)
{
    return coefficients.forTrend(set).axis[axis];
}

static float absolute(float value)
{
    return value < 0.0f ? -value : value;
}

static void test_surface_values(void)
{
    // Python: 571.5 - 20.23*9 + 1.569e-3*-2653 - 0.1044*81 ... = 378.5117
    TEST_ASSERT_FLOAT_WITHIN(0.01f, 378.5117f, surfaceCorrection(surface(CompSet::Warming, 0), 9.0f, -2653.0f));
    TEST_ASSERT_FLOAT_WITHIN(0.01f, -637.0686f, surfaceCorrection(surface(CompSet::Warming, 0), 48.0f, -1699.0f));
}

static void test_surface_large_accel(void)
{
    // a = +-16000 LSB (~1 g) makes a^2 ~ 2.6e8; Python double results.
    TEST_ASSERT_FLOAT_WITHIN(0.01f, -573.4755f, surfaceCorrection(surface(CompSet::Warming, 0), 45.0f, 16000.0f));
    TEST_ASSERT_FLOAT_WITHIN(0.01f, 356.9856f, surfaceCorrection(surface(CompSet::Warming, 1), -10.0f, -16000.0f));
    TEST_ASSERT_FLOAT_WITHIN(0.01f, -588.1491f, surfaceCorrection(surface(CompSet::Cooling, 0), 45.0f, 16000.0f));
}

// Compensated spread between two field-test endpoints.
static float compensatedSpread(CompSet set, uint8_t axis, float t1, float a1, float t2, float a2)
{
    const AxisSurface& s = surface(set, axis);
    return absolute(compensate(s, t1, a1) - compensate(s, t2, a2));
}

static void test_sign_cooling_field(void)
{
    // Section 4.3, 26 -> 16 degC read in time order: X -1831 at 26, -1596 at
    // 16 (spread 235). Python, raw - f: -1808.43 and -1818.32, spread 9.9;
    // raw + f would give -1853.57 and -1373.68, spread 480.
    const AxisSurface& x = surface(CompSet::Cooling, 0);
    TEST_ASSERT_FLOAT_WITHIN(0.05f, -1808.4279f, compensate(x, 26.0f, -1831.0f));
    TEST_ASSERT_FLOAT_WITHIN(0.05f, -1818.3245f, compensate(x, 16.0f, -1596.0f));
    TEST_ASSERT_LESS_THAN(23, (long)compensatedSpread(CompSet::Cooling, 0, 26.0f, -1831.0f, 16.0f, -1596.0f));
    float plusSpread = absolute((-1831.0f + surfaceCorrection(x, 26.0f, -1831.0f)) -
                                (-1596.0f + surfaceCorrection(x, 16.0f, -1596.0f)));
    TEST_ASSERT_GREATER_THAN(235, (long)plusSpread);
    // Y -424 at 26, -286 at 16 (spread 138): Python spread 3.7.
    TEST_ASSERT_LESS_THAN(13, (long)compensatedSpread(CompSet::Cooling, 1, 26.0f, -424.0f, 16.0f, -286.0f));
}

static void test_sign_warming_field(void)
{
    // Section 4.3, 9 -> 48 degC, paired as the cooling test implies (raw falls
    // as temperature rises): X -1699 at 9, -2653 at 48 (spread 954). Python,
    // raw - f: -2078.39 and -2017.64, spread 60.7 (6.4 %).
    const AxisSurface& x = surface(CompSet::Warming, 0);
    TEST_ASSERT_FLOAT_WITHIN(0.05f, -2078.3867f, compensate(x, 9.0f, -1699.0f));
    TEST_ASSERT_FLOAT_WITHIN(0.05f, -2017.6370f, compensate(x, 48.0f, -2653.0f));
    TEST_ASSERT_LESS_THAN(95, (long)compensatedSpread(CompSet::Warming, 0, 9.0f, -1699.0f, 48.0f, -2653.0f));
    // Y -431 at 9, -937 at 48 (spread 506): Python spread 40.0 (7.9 %).
    TEST_ASSERT_LESS_THAN(50, (long)compensatedSpread(CompSet::Warming, 1, 9.0f, -431.0f, 48.0f, -937.0f));
}

static void test_zero_at_reference(void)
{
    // Residuals are taken against 25 degC (section 3.3). Python f(25, 0):
    // X warm 0.50, Y warm 3.17, X cool 1.29, Y cool -3.02: all within 5 LSB.
    for (uint8_t s = 0; s < COMP_SET_COUNT; ++s) {
        for (uint8_t axis = 0; axis < 2; ++axis) {
            TEST_ASSERT_FLOAT_WITHIN(5.0f, 0.0f, surfaceCorrection(surface((CompSet)s, axis), 25.0f, 0.0f));
        }
    }
}

static void test_drift_span(void)
{
    // Section 4.1: drift over -10..45 degC is about 1300 LSB on X and 850 on
    // Y, read off a figure. Python f(-10,0) - f(45,0): X 1313.6 / 1323.0,
    // Y 773.4 / 768.6 (warming / cooling). Tolerance: 50 LSB on X, 100 on Y.
    for (uint8_t s = 0; s < COMP_SET_COUNT; ++s) {
        const AxisSurface& x = surface((CompSet)s, 0);
        const AxisSurface& y = surface((CompSet)s, 1);
        TEST_ASSERT_FLOAT_WITHIN(50.0f, 1300.0f,
                                 surfaceCorrection(x, -10.0f, 0.0f) - surfaceCorrection(x, 45.0f, 0.0f));
        TEST_ASSERT_FLOAT_WITHIN(100.0f, 850.0f,
                                 surfaceCorrection(y, -10.0f, 0.0f) - surfaceCorrection(y, 45.0f, 0.0f));
    }
}

static void test_z_uncorrected(void)
{
    TEST_ASSERT_FLOAT_WITHIN(0.001f, 16393.0f, compensate(surface(CompSet::Warming, 2), 40.0f, 16393.0f));
    TEST_ASSERT_FLOAT_WITHIN(0.001f, -16393.0f, compensate(surface(CompSet::Cooling, 2), -5.0f, -16393.0f));
}

static float eighths(int16_t n)
{
    return (float)n / 8.0f;
}

static void test_trend_ramps(void)
{
    TrendDetector trend;
    TEST_ASSERT(trend.current() == CompSet::Warming);
    uint8_t switches = 0;
    CompSet last = CompSet::Warming;
    int16_t firstCoolingAt = 0;
    int16_t firstWarmingAt = 0;
    // 10 -> 40 -> 10 -> 20 degC in 1/8 degC steps.
    int16_t n = 80;
    int16_t step = 1;
    for (uint16_t i = 0; i < 560; ++i) {
        CompSet now = trend.update(eighths(n));
        if (now != last) {
            ++switches;
            if (now == CompSet::Cooling) {
                firstCoolingAt = n;
            } else {
                firstWarmingAt = n;
            }
            last = now;
        }
        if (n == 320) {
            step = -1;
        } else if (n == 80 && step < 0) {
            step = 1;
        }
        n = (int16_t)(n + step);
    }
    TEST_ASSERT_EQUAL(2, switches);
    TEST_ASSERT_EQUAL(315, firstCoolingAt);  // 40 - 0.625 = 39.375 degC
    TEST_ASSERT_EQUAL(85, firstWarmingAt);   // 10 + 0.625 = 10.625 degC
}

static void test_trend_plateau(void)
{
    // +-0.25 degC of noise in 1/8 degC steps around 30 degC, from a pseudo
    // random sequence (Numerical Recipes LCG).
    for (uint8_t s = 0; s < COMP_SET_COUNT; ++s) {
        TrendDetector trend(0.5f, (CompSet)s);
        uint32_t seed = 12345u;
        for (uint16_t i = 0; i < 500; ++i) {
            seed = seed * 1664525u + 1013904223u;
            int16_t noise = (int16_t)((seed >> 24) % 5u) - 2;
            TEST_ASSERT(trend.update(eighths((int16_t)(240 + noise))) == (CompSet)s);
        }
    }
}

static void test_trend_threshold(void)
{
    TrendDetector trend;
    trend.update(30.0f);
    TEST_ASSERT(trend.update(29.5f) == CompSet::Warming);    // 0.5 below: not more than
    TEST_ASSERT(trend.update(29.375f) == CompSet::Cooling);  // 0.625 below
    TEST_ASSERT(trend.update(29.875f) == CompSet::Cooling);  // 0.5 above the new minimum
    TEST_ASSERT(trend.update(30.0f) == CompSet::Warming);

    TrendDetector wide(1.0f);
    wide.update(20.0f);
    TEST_ASSERT(wide.update(19.0f) == CompSet::Warming);
    TEST_ASSERT(wide.update(18.875f) == CompSet::Cooling);
}

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

// The frame limit, 9.99e5 LSB: 1e6 (nine characters at one decimal in the
// longest IMU line, Compensation.h) less 0.1 %.
static const float FRAME_LIMIT_LSB = 9.99e5f;
static const float INT16_SPAN_LSB = 32768.0f;

static AxisSurface constantSurface(float p00, float p01)
{
    AxisSurface surface = {{p00, 0.0f, p01, 0.0f, 0.0f, 0.0f}};
    return surface;
}

static void test_default_surfaces_fit_the_frame(void)
{
    for (uint8_t s = 0; s < COMP_SET_COUNT; ++s) {
        for (uint8_t axis = 0; axis < COMP_AXIS_COUNT; ++axis) {
            TEST_ASSERT(surfaceOutputFitsFrame(surface((CompSet)s, axis)));
        }
    }
}

static void test_output_limit_includes_the_raw_reading(void)
{
    // raw - p00 is largest at raw = -32768 (or 32767 for a negative p00); all
    // values here are integers below 2^24, exact in a float.
    TEST_ASSERT(surfaceOutputFitsFrame(constantSurface(FRAME_LIMIT_LSB - INT16_SPAN_LSB - 16.0f, 0.0f)));
    TEST_ASSERT_FALSE(surfaceOutputFitsFrame(constantSurface(FRAME_LIMIT_LSB - INT16_SPAN_LSB + 16.0f, 0.0f)));
    TEST_ASSERT(surfaceOutputFitsFrame(constantSurface(-(FRAME_LIMIT_LSB - INT16_SPAN_LSB - 16.0f), 0.0f)));
    TEST_ASSERT_FALSE(surfaceOutputFitsFrame(constantSurface(-(FRAME_LIMIT_LSB - INT16_SPAN_LSB + 16.0f), 0.0f)));
    // p01 = 1 removes the raw reading: the output is -p00 everywhere.
    TEST_ASSERT(surfaceOutputFitsFrame(constantSurface(9.98e5f, 1.0f)));
    TEST_ASSERT_FALSE(surfaceOutputFitsFrame(constantSurface(1.0e6f, 1.0f)));
}

// raw - f = peak * (1 - ((T - 22.5) / 62.5)^2): zero at -40 and 85 degC, so
// every corner is zero; the peak sits at 22.5 degC along both a-edges.
static AxisSurface edgePeak(float peak)
{
    float curvature = peak / (62.5f * 62.5f);
    AxisSurface surface = {{-peak + curvature * 22.5f * 22.5f, -45.0f * curvature, 1.0f, curvature, 0.0f, 0.0f}};
    return surface;
}

// raw - f = peak - (peak / 2) ((T - 22.5) / 62.5)^2 - (peak / 2) (a / 32768)^2:
// zero at the corners, peak / 2 at every edge vertex, the peak only inside.
static AxisSurface insidePeak(float peak)
{
    float temperatureCurvature = peak / (2.0f * 62.5f * 62.5f);
    float accelCurvature = peak / (2.0f * INT16_SPAN_LSB * INT16_SPAN_LSB);
    AxisSurface surface = {{-peak + temperatureCurvature * 22.5f * 22.5f, -45.0f * temperatureCurvature, 1.0f,
                            temperatureCurvature, 0.0f, accelCurvature}};
    return surface;
}

static void test_output_peaks_between_the_corners_are_found(void)
{
    TEST_ASSERT_FLOAT_WITHIN(1.0f, 1.2e6f, compensate(edgePeak(1.2e6f), 22.5f, 32767.0f));
    TEST_ASSERT_FLOAT_WITHIN(1.0f, 0.0f, compensate(edgePeak(1.2e6f), 85.0f, 32767.0f));
    TEST_ASSERT_FALSE(surfaceOutputFitsFrame(edgePeak(1.2e6f)));
    TEST_ASSERT(surfaceOutputFitsFrame(edgePeak(9.9e5f)));

    TEST_ASSERT_FLOAT_WITHIN(1.0f, 1.5e6f, compensate(insidePeak(1.5e6f), 22.5f, 0.0f));
    TEST_ASSERT_FLOAT_WITHIN(1.0f, 7.5e5f, compensate(insidePeak(1.5e6f), 22.5f, -32768.0f));
    TEST_ASSERT_FLOAT_WITHIN(1.0f, 7.5e5f, compensate(insidePeak(1.5e6f), 85.0f, 0.0f));
    TEST_ASSERT_FALSE(surfaceOutputFitsFrame(insidePeak(1.5e6f)));
    TEST_ASSERT(surfaceOutputFitsFrame(insidePeak(9.9e5f)));
}

static void test_non_finite_outputs_do_not_fit(void)
{
    for (uint8_t k = 0; k < COMP_COEFFICIENT_COUNT; ++k) {
        AxisSurface surface = constantSurface(0.0f, 0.0f);
        surface.p[k] = NAN;
        TEST_ASSERT_FALSE(surfaceOutputFitsFrame(surface));
        surface.p[k] = -INFINITY;
        TEST_ASSERT_FALSE(surfaceOutputFitsFrame(surface));
    }
    // Finite, but p02 a^2 overflows a float (3e38 * 32768^2).
    AxisSurface overflowing = constantSurface(0.0f, 0.0f);
    overflowing.p[P02] = 3e38f;
    TEST_ASSERT_FALSE(surfaceOutputFitsFrame(overflowing));
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
    // A single Coefficients (144 bytes) on the stack: with the real Unity's
    // strings in RAM the Nano has about 450 bytes of stack for this test.
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
    RUN_TEST(test_surface_values);
    RUN_TEST(test_surface_large_accel);
    RUN_TEST(test_sign_cooling_field);
    RUN_TEST(test_sign_warming_field);
    RUN_TEST(test_zero_at_reference);
    RUN_TEST(test_drift_span);
    RUN_TEST(test_z_uncorrected);
    RUN_TEST(test_trend_ramps);
    RUN_TEST(test_trend_plateau);
    RUN_TEST(test_trend_threshold);
    RUN_TEST(test_crc_vector);
    RUN_TEST(test_block_default_bytes);
    RUN_TEST(test_block_id_and_domain_bytes);
    RUN_TEST(test_block_round_trip);
    RUN_TEST(test_block_through_byte_callbacks);
    RUN_TEST(test_version_1_block_still_loads);
    RUN_TEST(test_block_rejects);
    RUN_TEST(test_temperature_domain);
    RUN_TEST(test_default_surfaces_fit_the_frame);
    RUN_TEST(test_output_limit_includes_the_raw_reading);
    RUN_TEST(test_output_peaks_between_the_corners_are_found);
    RUN_TEST(test_non_finite_outputs_do_not_fit);
    RUN_TEST(test_block_blank_and_bad_values);
    return UNITY_END();
}
