#include <string.h>
#include <unity.h>

#include <Compensation.h>
#include <ImuProcessing.h>
#include <Kalman.h>
#include <LSM9DS0.h>

#include "imu_processing_series.h"

// Static, not on the stack: the Nano's 2 KB hold them with Unity's own.
static Coefficients coefficients;
static ImuProcessing processing;

// The IMU reader's sample() and resetFilters() before lib/ImuProcessing,
// line for line: the class must give these numbers bit for bit.
static KalmanFilter referenceAccel[IMU_AXES];
static KalmanFilter referenceTemperature;
static Decimator referenceDecimator(IMU_DEFAULT_DECIMATION);
static TrendDetector referenceTrend;
static SetBlend referenceBlend;

void setUp(void)
{
    loadTestCoefficients(coefficients);
    processing = ImuProcessing();
}

void tearDown(void) {}

static void test_first_sample_seeds_every_channel(void)
{
    const int16_t raw[IMU_AXES] = {-1700, 400, -16384};
    ImuOutput out;
    TEST_ASSERT_FALSE(processing.update(raw, 40, coefficients, out));
    processing.readFiltered(out);
    TEST_ASSERT_FLOAT_WITHIN(0.0f, -1700.0f, out.filtered[0]);
    TEST_ASSERT_FLOAT_WITHIN(0.0f, 400.0f, out.filtered[1]);
    TEST_ASSERT_FLOAT_WITHIN(0.0f, -16384.0f, out.filtered[2]);
    // 40 raw at 8 LSB/degC plus the paper's 21 degC.
    TEST_ASSERT_FLOAT_WITHIN(0.0f, 26.0f, out.temperatureC);
    TEST_ASSERT_EQUAL_UINT8((uint8_t)CompSet::Warming, (uint8_t)out.set);
}

static void test_frame_every_decimation_samples_with_compensation(void)
{
    const int16_t raw[IMU_AXES] = {-1700, 400, 16000};
    ImuOutput out;
    for (int16_t i = 1; i <= 3 * IMU_DEFAULT_DECIMATION; ++i) {
        memset(out.compensated, 0, sizeof out.compensated);
        bool due = processing.update(raw, 32, coefficients, out);
        TEST_ASSERT_EQUAL(i % IMU_DEFAULT_DECIMATION == 0, due);
        for (uint8_t axis = 0; axis < IMU_AXES; ++axis) {
            // A still temperature leaves the device halfway between its sets.
            float expected = due ? compensateBlended(coefficients.set[0].axis[axis], coefficients.set[1].axis[axis],
                                                     COMP_SET_POWER_UP_SHARE, out.temperatureC, out.filtered[axis])
                                 : 0.0f;
            assertSameFloat(expected, out.compensated[axis]);
        }
    }
    // Python, Table 3's Y at 25 degC and 400 LSB: warming 400 - (354 - 13.96*25
    // + 5.747e-3*400 - 2.931e-3*25**2 - 1.915e-4*25*400 - 5.363e-8*400**2)
    // = 396.4567, cooling 402.8245 (338.1, -12.82, 4.439e-3, -3.299e-2,
    // -1.579e-4, -1.455e-8); the mean of the two.
    TEST_ASSERT_FLOAT_WITHIN(0.01f, 399.6406f, out.compensated[1]);
}

static void test_not_counting_filters_without_frames(void)
{
    const int16_t raw[IMU_AXES] = {100, 200, 300};
    const int16_t other[IMU_AXES] = {110, 190, 300};
    ImuOutput out;
    for (uint8_t i = 0; i < 25; ++i) {
        TEST_ASSERT_FALSE(processing.update(i == 0 ? raw : other, 0, coefficients, out, false));
    }
    processing.readFiltered(out);
    TEST_ASSERT_TRUE(out.filtered[0] > 100.0f && out.filtered[0] < 110.0f);
    // Counting again starts from where the count was: a frame after ten.
    for (uint8_t i = 1; i < IMU_DEFAULT_DECIMATION; ++i) {
        TEST_ASSERT_FALSE(processing.update(other, 0, coefficients, out));
    }
    TEST_ASSERT_TRUE(processing.update(other, 0, coefficients, out));
}

static void test_reset_reseeds_restarts_count_and_keeps_trend(void)
{
    processing = ImuProcessing(IMU_DEFAULT_DECIMATION, 0.5f);
    const int16_t raw[IMU_AXES] = {0, 0, 0};
    const int16_t moved[IMU_AXES] = {5000, -5000, 0};
    ImuOutput out;
    processing.update(raw, 80, coefficients, out);  // 31 degC
    for (uint8_t i = 0; i < 4; ++i) {
        processing.update(raw, 0, coefficients, out);  // 21 degC: cooling
    }
    TEST_ASSERT_EQUAL_UINT8((uint8_t)CompSet::Cooling, (uint8_t)processing.currentSet());
    processing.reset();
    TEST_ASSERT_FALSE(processing.update(moved, 0, coefficients, out));
    processing.readFiltered(out);
    TEST_ASSERT_FLOAT_WITHIN(0.0f, 5000.0f, out.filtered[0]);
    TEST_ASSERT_FLOAT_WITHIN(0.0f, -5000.0f, out.filtered[1]);
    TEST_ASSERT_FLOAT_WITHIN(0.0f, 21.0f, out.temperatureC);
    TEST_ASSERT_EQUAL_UINT8((uint8_t)CompSet::Cooling, (uint8_t)out.set);
    for (uint8_t i = 2; i < IMU_DEFAULT_DECIMATION; ++i) {
        TEST_ASSERT_FALSE(processing.update(moved, 0, coefficients, out));
    }
    TEST_ASSERT_TRUE(processing.update(moved, 0, coefficients, out));
    // The cooling surfaces compensate.
    assertSameFloat(compensate(coefficients.set[1].axis[2], 21.0f, 0.0f), out.compensated[2]);
}

static void test_decimation_and_hysteresis_settings(void)
{
    processing = ImuProcessing(3, 0.25f);
    TEST_ASSERT_EQUAL_UINT8(3, processing.decimation());
    TEST_ASSERT_FLOAT_WITHIN(0.0f, 0.25f, processing.hysteresisC());
    const int16_t raw[IMU_AXES] = {1, 2, 3};
    ImuOutput out;
    processing.update(raw, 0, coefficients, out);
    processing.update(raw, 0, coefficients, out);
    // SETDEC restarts the count; START/STOP too.
    processing.setDecimation(2);
    TEST_ASSERT_FALSE(processing.update(raw, 0, coefficients, out));
    processing.restartDecimation();
    TEST_ASSERT_FALSE(processing.update(raw, 0, coefficients, out));
    TEST_ASSERT_TRUE(processing.update(raw, 0, coefficients, out));
    processing.setDecimation(0);
    TEST_ASSERT_EQUAL_UINT8(1, processing.decimation());
    TEST_ASSERT_TRUE(processing.update(raw, 0, coefficients, out));
}

// The firmware's steps written out, with a RESEED at 150 and STOP..START over
// 400..450: the same filtered values, sets, frames and compensated values.
static void test_matches_the_firmware_code_it_replaced(void)
{
    noiseState = 7;
    int16_t switches = 0;
    CompSet previous = CompSet::Warming;
    bool streaming = true;
    for (int16_t i = 0; i < 600; ++i) {
        int16_t raw[IMU_AXES];
        int16_t temperatureRaw;
        sampleAt(i, raw, temperatureRaw);
        if (i == 150) {
            for (uint8_t axis = 0; axis < IMU_AXES; ++axis) {
                referenceAccel[axis].reset();
            }
            referenceTemperature.reset();
            referenceDecimator.restart();
            processing.reset();
        }
        if (i == 400 || i == 450) {
            streaming = i == 450;
            referenceDecimator.restart();
            processing.restartDecimation();
        }
        ImuOutput expected;
        expected.temperatureC = referenceTemperature.update(temperatureRawToC(temperatureRaw));
        for (uint8_t axis = 0; axis < IMU_AXES; ++axis) {
            expected.filtered[axis] = referenceAccel[axis].update(raw[axis]);
        }
        expected.set = referenceTrend.update(expected.temperatureC);
        float share = referenceBlend.update(expected.temperatureC);
        bool expectedDue = streaming && referenceDecimator.push();
        if (expectedDue) {
            for (uint8_t axis = 0; axis < IMU_AXES; ++axis) {
                expected.compensated[axis] = compensateBlended(coefficients.set[0].axis[axis],
                                                               coefficients.set[1].axis[axis], share,
                                                               expected.temperatureC, expected.filtered[axis]);
            }
        }
        ImuOutput out;
        TEST_ASSERT_EQUAL(expectedDue, processing.update(raw, temperatureRaw, coefficients, out, streaming));
        if (!expectedDue) {
            processing.readFiltered(out);
        }
        assertSameOutput(expected, out, expectedDue);
        switches += expected.set != previous;
        previous = expected.set;
    }
    // The series turned the trend both ways.
    TEST_ASSERT_GREATER_THAN(1, switches);
}

// Each of the LSM9DS0's 12-bit temperatures seeds the filter with exactly
// temperatureRawToC's value, though update() feeds it in fixed point.
static void test_every_sensor_temperature_seeds_exactly(void)
{
    const int16_t raw[IMU_AXES] = {0, 0, 0};
    for (int16_t temperatureRaw = -2048; temperatureRaw < 2048; ++temperatureRaw) {
        ImuOutput out;
        processing.reset();
        processing.update(raw, temperatureRaw, coefficients, out);
        assertSameFloat(temperatureRawToC(temperatureRaw), out.temperatureC);
    }
}

int runUnityTests(void)
{
    UNITY_BEGIN();
    RUN_TEST(test_first_sample_seeds_every_channel);
    RUN_TEST(test_frame_every_decimation_samples_with_compensation);
    RUN_TEST(test_not_counting_filters_without_frames);
    RUN_TEST(test_reset_reseeds_restarts_count_and_keeps_trend);
    RUN_TEST(test_decimation_and_hysteresis_settings);
    RUN_TEST(test_matches_the_firmware_code_it_replaced);
    RUN_TEST(test_every_sensor_temperature_seeds_exactly);
    return UNITY_END();
}
