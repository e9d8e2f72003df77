#include <unity.h>

#include <Compensation.h>
#include <ImuProcessing.h>

#include "imu_processing_series.h"

// ImuProcessing's unquantised path (float inputs, as the host's replay feeds
// it) against the firmware's own.

static Coefficients coefficients;
static ImuProcessing processing;
static ImuProcessing unrounded;

void setUp(void)
{
    loadTestCoefficients(coefficients);
    processing = ImuProcessing();
    unrounded = ImuProcessing();
}

void tearDown(void) {}

// The unquantised path on integer inputs: the same bits, frames included.
static void test_unrounded_equals_raw_on_integer_inputs(void)
{
    noiseState = 11;
    for (int16_t i = 0; i < 400; ++i) {
        int16_t raw[IMU_AXES];
        int16_t temperatureRaw;
        sampleAt(i, raw, temperatureRaw);
        const float accel[IMU_AXES] = {(float)raw[0], (float)raw[1], (float)raw[2]};
        float temperatureC = (float)temperatureRaw / 8.0f + 21.0f;
        if (i == 123) {
            processing.reset();
            unrounded.reset();
        }
        ImuOutput expected;
        ImuOutput out;
        bool due = processing.update(raw, temperatureRaw, coefficients, expected);
        TEST_ASSERT_EQUAL(due, unrounded.updateUnrounded(accel, temperatureC, coefficients, out));
        processing.readFiltered(expected);
        unrounded.readFiltered(out);
        assertSameOutput(expected, out, due);
    }
}

static void test_unrounded_takes_fractions(void)
{
    const float accel[IMU_AXES] = {-1700.25f, 0.5f, 16000.125f};
    ImuOutput out;
    unrounded.updateUnrounded(accel, 24.3f, coefficients, out);
    unrounded.readFiltered(out);
    TEST_ASSERT_FLOAT_WITHIN(0.0f, -1700.25f, out.filtered[0]);
    // The filter holds 2^-15 degC (lib/Kalman): 24.3 to within half of that.
    TEST_ASSERT_FLOAT_WITHIN(1.0f / 65536.0f, 24.3f, out.temperatureC);
    const float next[IMU_AXES] = {-1699.75f, 0.5f, 16000.125f};
    unrounded.updateUnrounded(next, 24.3f, coefficients, out);
    unrounded.readFiltered(out);
    // The second sample gets a gain of about 1/2 (test_kalman).
    TEST_ASSERT_FLOAT_WITHIN(0.001f, -1700.0f, out.filtered[0]);
    ImuProcessing::compensate(coefficients, out);
    assertSameFloat(compensateBlended(coefficients.set[0].axis[0], coefficients.set[1].axis[0], COMP_SET_POWER_UP_SHARE,
                                      out.temperatureC, out.filtered[0]),
                    out.compensated[0]);
}

int runUnityTests(void)
{
    UNITY_BEGIN();
    RUN_TEST(test_unrounded_equals_raw_on_integer_inputs);
    RUN_TEST(test_unrounded_takes_fractions);
    return UNITY_END();
}
