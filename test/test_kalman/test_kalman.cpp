#include <math.h>
#include <string.h>
#include <unity.h>

#include "Kalman.h"

// Steady state of P+ = (P + Q) R / (P + Q + R) with Q = 1e-8, R = 0.01, solved
// by hand/Python: P = (-Q + sqrt(Q^2 + 4QR)) / 2 = 9.995e-6, K = 9.995e-4,
// i.e. sqrt(Q/R) = 1e-3 within 0.05 %. A first-order lag with that gain
// reaches 1 - 1/e = 63.2 % of a step after -1/ln(1 - K) = 1000.0 samples.
static const float kSteadyGain = 1e-3f;
static const long kSamplesTo632 = 1000;
static const long kSamplesTo632Tolerance = 20;  // 2 %
// Gain is within 0.5 % of steady state after ~3000 samples (P ~ R/n, then
// coth-shaped convergence with time constant 500 samples).
static const int kConvergeSamples = 5000;

// 1 g on the LSM9DS0 at +-2 g is ~16393 LSB (0.061 mg/LSB).
static const float kOneG = 16393.0f;

void setUp(void) {}
void tearDown(void) {}

static void assertSameFloat(float expected, float actual)
{
    TEST_ASSERT_TRUE(memcmp(&expected, &actual, sizeof actual) == 0);
}

static void converge(KalmanFilter &filter, float value)
{
    for (int i = 0; i < kConvergeSamples; ++i)
        filter.update(value);
}

static void test_seeds_from_first_sample(void)
{
    KalmanFilter filter;
    TEST_ASSERT_FALSE(filter.isSeeded());
    TEST_ASSERT_FLOAT_WITHIN(0.0f, 1234.5f, filter.update(1234.5f));
    TEST_ASSERT_TRUE(filter.isSeeded());
    // P starts at R, so the second sample gets K = (R+Q)/(2R+Q) ~ 1/2.
    TEST_ASSERT_FLOAT_WITHIN(0.01f, 1235.5f, filter.update(1236.5f));
    TEST_ASSERT_FLOAT_WITHIN(0.001f, 0.5f, filter.lastGain());
}

static void test_reset_reseeds(void)
{
    KalmanFilter filter;
    converge(filter, 100.0f);
    filter.reset();
    TEST_ASSERT_FALSE(filter.isSeeded());
    TEST_ASSERT_FLOAT_WITHIN(0.0f, -42.0f, filter.update(-42.0f));
    TEST_ASSERT_FLOAT_WITHIN(0.0f, -42.0f, filter.estimate());
}

static void test_constant_input_stays_constant(void)
{
    KalmanFilter filter;
    for (int i = 0; i < 200; ++i)
        TEST_ASSERT_FLOAT_WITHIN(0.0f, -321.25f, filter.update(-321.25f));
}

static void test_steady_gain_is_sqrt_q_over_r(void)
{
    KalmanFilter filter;
    converge(filter, 0.0f);
    // 1 % tolerance; the exact steady value differs from sqrt(Q/R) by 0.05 %.
    TEST_ASSERT_FLOAT_WITHIN(kSteadyGain * 0.01f, kSteadyGain, filter.lastGain());
}

static long samplesToReach(KalmanFilter &filter, float target, float input)
{
    long samples = 0;
    while (filter.estimate() < target && samples < 3 * kSamplesTo632) {
        filter.update(input);
        ++samples;
    }
    return samples;
}

static void test_step_response_time_constant(void)
{
    KalmanFilter filter;
    converge(filter, kOneG);
    long samples = samplesToReach(filter, kOneG + 632.12f, kOneG + 1000.0f);
    TEST_ASSERT_INT_WITHIN(kSamplesTo632Tolerance, kSamplesTo632, samples);
}

static void test_one_g_holds_within_half_lsb(void)
{
    KalmanFilter filter;
    converge(filter, kOneG);
    TEST_ASSERT_FLOAT_WITHIN(0.5f, kOneG, filter.estimate());
    for (int i = 0; i < 1000; ++i) {
        // +-1 LSB alternating noise: at K = 1e-3 the ripple is ~0.001 LSB.
        float estimate = filter.update(kOneG + ((i & 1) ? 1.0f : -1.0f));
        TEST_ASSERT_FLOAT_WITHIN(0.01f, kOneG, estimate);
    }
}

// A float at 16393 resolves 0.002 LSB but a steady correction for a 1-LSB
// error is 0.001 LSB: a naive filter stalls ~1 LSB short and never reaches
// 63.2 %. The step must follow the same ~1000-sample curve as a large one.
static void test_one_lsb_step_at_one_g(void)
{
    KalmanFilter filter;
    converge(filter, kOneG);
    long samples = samplesToReach(filter, kOneG + 0.6321f, kOneG + 1.0f);
    TEST_ASSERT_INT_WITHIN(kSamplesTo632Tolerance, kSamplesTo632, samples);
    for (long i = samples; i < kConvergeSamples; ++i)
        filter.update(kOneG + 1.0f);
    // After 5000 samples the lag is exp(-5000 * 9.995e-4) = 0.0068 LSB.
    TEST_ASSERT_FLOAT_WITHIN(0.005f, kOneG + 1.0f - 0.0068f, filter.estimate());
}

// The filter as it was written before the settled-gain shortcut and the
// fixed-point estimate: every update computes the covariance and the gain,
// and the estimate is a float with Kahan summation.
struct FloatFilter {
    float estimate, lostLowBits, covariance;
    bool seeded;

    float update(float measurement)
    {
        if (!seeded) {
            seeded = true;
            return estimate = measurement;
        }
        covariance += KalmanFilter::kPaperProcessNoise;
        float gain = covariance / (covariance + KalmanFilter::kPaperMeasurementNoise);
        float correction = gain * (measurement - estimate) - lostLowBits;
        float sum = estimate + correction;
        lostLowBits = (sum - estimate) - correction;
        estimate = sum;
        covariance = (1.0f - gain) * covariance;
        return estimate;
    }
};

// Two ulps of a float between 2^14 and 2^15 LSB, where 1 g lies: what the
// two estimates' roundings to float may differ by. A twelfth of the 0.1 LSB
// an IMU frame prints.
static const float kFloatFilterTolerance = 2.0f / 256.0f;

// Neither change may show in a frame: every estimate within the tolerance of
// the float filter's, before and after the gain settles and across a 45
// degree table move; the shortcut leaves the covariance bit for bit the same.
static void test_matches_the_float_filter(void)
{
    KalmanFilter filter;
    FloatFilter reference = {0.0f, 0.0f, KalmanFilter::kPaperMeasurementNoise, false};
    long settledAt = -1;
    for (long i = 0; i < 4L * kConvergeSamples; ++i) {
        // A slow ramp with +-3 LSB of pattern noise around 1 g, then the move.
        float move = i >= 2L * kConvergeSamples ? -11600.0f : 0.0f;
        float input = kOneG + 0.01f * (float)i + (float)((i * 5) % 7 - 3) + move;
        int16_t raw = (int16_t)(input + 0.5f);
        filter.updateFixed((int32_t)raw * KalmanFilter::FIXED_ONE);
        TEST_ASSERT_FLOAT_WITHIN(kFloatFilterTolerance, reference.update((float)raw), filter.estimate());
        if (settledAt < 0 && filter.gainSettled())
            settledAt = i;
    }
    // Settled within the run (about 5500 updates on x86 and on the AVR), or
    // the shortcut never saves anything.
    TEST_ASSERT_TRUE(settledAt > 0);
    float covariance = filter.errorCovariance();
    TEST_ASSERT_TRUE(memcmp(&reference.covariance, &covariance, sizeof covariance) == 0);
}

// The estimate's 2^-15 and two float ulps between 32 and 64: a 25th of the
// 0.001 degC an IMU frame prints.
static const float kTemperatureTolerance = 1.0f / 32768.0f + 2.0f / 262144.0f;

// The same at the temperature filter's scale: the LSM9DS0's 1/8 degC steps,
// from 9 to 48 degC and back, as a field test's ramps.
static void test_matches_the_float_filter_on_temperatures(void)
{
    KalmanFilter filter;
    FloatFilter reference = {0.0f, 0.0f, KalmanFilter::kPaperMeasurementNoise, false};
    for (long i = 0; i < 4L * kConvergeSamples; ++i) {
        long eighths = i < 2L * kConvergeSamples ? i / 32 : (4L * kConvergeSamples - i) / 32;
        float temperatureC = 9.0f + (float)eighths / 8.0f;
        TEST_ASSERT_FLOAT_WITHIN(kTemperatureTolerance, reference.update(temperatureC), filter.update(temperatureC));
    }
}

// A measurement in float and in fixed point is one measurement.
static void test_fixed_and_float_updates_agree(void)
{
    KalmanFilter asFloat;
    KalmanFilter asFixed;
    for (int16_t i = 0; i < 2000; ++i) {
        int16_t raw = (int16_t)(-1700 + (i * 37L) % 101);
        // Whole numbers, then eighths (the LSM9DS0's temperature steps).
        int32_t fixed = i < 1000 ? KalmanFilter::fixedFromWhole(raw) : (int32_t)raw * (KalmanFilter::FIXED_ONE / 8);
        float expected = asFloat.update(i < 1000 ? (float)raw : (float)raw / 8.0f);
        asFixed.updateFixed(fixed);
        assertSameFloat(expected, asFixed.estimate());
    }
}

// The estimate's 32-bit halves carry and borrow as one int64 would: the
// filter against that sum, with the filter's own gains, bit for bit, over
// corrections of both signs and a table move's large ones.
static void test_halves_add_as_one_64_bit_estimate(void)
{
    KalmanFilter filter;
    int64_t reference = 0;
    // reference to the nearest 2^-15, as the filter's difference takes it.
    int32_t rounded = 0;
    for (long i = 0; i < 3000; ++i) {
        int16_t raw = (int16_t)(-1700 + (i * 37L) % 101 + (i >= 2000 ? 23000 : 0));
        int32_t measurement = KalmanFilter::fixedFromWhole(raw);
        filter.updateFixed(measurement);
        if (i == 0) {
            reference = (int64_t)measurement * 4294967296LL;
        } else {
            float gain = filter.lastGain();
            uint64_t fraction = gain < 1.0f ? (uint32_t)(gain * 4294967296.0f) : 0xFFFFFFFFull;
            int64_t difference = (int64_t)measurement - rounded;
            int64_t correction = (int64_t)((uint64_t)(difference < 0 ? -difference : difference) * fraction);
            reference += difference < 0 ? -correction : correction;
        }
        rounded = (int32_t)(reference >> 32) + (int32_t)((uint32_t)reference >> 31);
        assertSameFloat(ldexpf((float)rounded, -15), filter.estimate());
    }
}

static void test_fixed_from_whole_at_the_int16_ends(void)
{
    TEST_ASSERT_EQUAL_INT32(-32768L * 32768L, KalmanFilter::fixedFromWhole(-32768));
    TEST_ASSERT_EQUAL_INT32(32767L * 32768L, KalmanFilter::fixedFromWhole(32767));
    TEST_ASSERT_EQUAL_INT32(-32768L, KalmanFilter::fixedFromWhole(-1));
}

// Outside an int16's range a measurement counts as the range's end, so the
// fixed-point difference cannot overflow.
static void test_measurements_are_held_to_the_int16_range(void)
{
    KalmanFilter filter;
    TEST_ASSERT_FLOAT_WITHIN(0.0f, -32768.0f, filter.update(-1e9f));
    for (int i = 0; i < 100; ++i)
        filter.update(1e9f);
    float estimate = filter.estimate();
    TEST_ASSERT_TRUE(estimate > -32768.0f && estimate <= 32767.0f);
    KalmanFilter high;
    TEST_ASSERT_FLOAT_WITHIN(0.0f, 32767.0f, high.update(40000.0f));
}

static void test_decimator_passes_every_nth(void)
{
    Decimator decimator(4);
    int passed = 0;
    for (int i = 1; i <= 20; ++i) {
        bool out = decimator.push();
        TEST_ASSERT_EQUAL(i % 4 == 0, out);
        passed += out;
    }
    TEST_ASSERT_EQUAL(5, passed);
}

static void test_decimator_factor_one_and_zero(void)
{
    Decimator decimator(1);
    TEST_ASSERT_TRUE(decimator.push());
    TEST_ASSERT_TRUE(decimator.push());
    decimator.setFactor(0);
    TEST_ASSERT_EQUAL_UINT8(1, decimator.factor());
    TEST_ASSERT_TRUE(decimator.push());
}

static void test_decimator_factor_change_restarts(void)
{
    Decimator decimator(5);
    decimator.push();
    decimator.push();
    decimator.push();
    decimator.setFactor(3);
    TEST_ASSERT_FALSE(decimator.push());
    TEST_ASSERT_FALSE(decimator.push());
    TEST_ASSERT_TRUE(decimator.push());
}

static void test_decimator_factor_255(void)
{
    Decimator decimator(255);
    for (int i = 1; i < 255; ++i)
        TEST_ASSERT_FALSE(decimator.push());
    TEST_ASSERT_TRUE(decimator.push());
    TEST_ASSERT_FALSE(decimator.push());
}

int runUnityTests(void)
{
    UNITY_BEGIN();
    RUN_TEST(test_seeds_from_first_sample);
    RUN_TEST(test_reset_reseeds);
    RUN_TEST(test_constant_input_stays_constant);
    RUN_TEST(test_steady_gain_is_sqrt_q_over_r);
    RUN_TEST(test_step_response_time_constant);
    RUN_TEST(test_one_g_holds_within_half_lsb);
    RUN_TEST(test_one_lsb_step_at_one_g);
    RUN_TEST(test_matches_the_float_filter);
    RUN_TEST(test_matches_the_float_filter_on_temperatures);
    RUN_TEST(test_fixed_and_float_updates_agree);
    RUN_TEST(test_fixed_from_whole_at_the_int16_ends);
    RUN_TEST(test_halves_add_as_one_64_bit_estimate);
    RUN_TEST(test_measurements_are_held_to_the_int16_range);
    RUN_TEST(test_decimator_passes_every_nth);
    RUN_TEST(test_decimator_factor_one_and_zero);
    RUN_TEST(test_decimator_factor_change_restarts);
    RUN_TEST(test_decimator_factor_255);
    return UNITY_END();
}
