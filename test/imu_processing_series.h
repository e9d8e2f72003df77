// What test_imu_processing and test_imu_processing_unrounded share (two
// programs, for the Nano's 2 KB): the coefficients they compensate with,
// comparisons to the bit and a deterministic series of samples.
#ifndef THERMOTILT_TEST_IMU_PROCESSING_SERIES_H
#define THERMOTILT_TEST_IMU_PROCESSING_SERIES_H

#include <unity.h>

#include <Compensation.h>
#include <ImuProcessing.h>

// The paper's surfaces; Z is uncorrected by default, so a surface of its own
// shows Z goes through.
inline void loadTestCoefficients(Coefficients& coefficients)
{
    loadDefaultCoefficients(coefficients);
    const float z[COMP_COEFFICIENT_COUNT] = {12.5f, -0.75f, 0.0625f, 0.01f, -1e-4f, 2e-8f};
    for (uint8_t term = 0; term < COMP_COEFFICIENT_COUNT; ++term) {
        coefficients.set[0].axis[2].p[term] = z[term];
        coefficients.set[1].axis[2].p[term] = -z[term];
    }
}

inline void assertSameFloat(float expected, float actual)
{
    TEST_ASSERT_EQUAL_MEMORY(&expected, &actual, sizeof(float));
}

inline void assertSameOutput(const ImuOutput& expected, const ImuOutput& actual, bool withCompensated)
{
    for (uint8_t axis = 0; axis < IMU_AXES; ++axis) {
        assertSameFloat(expected.filtered[axis], actual.filtered[axis]);
        if (withCompensated) {
            assertSameFloat(expected.compensated[axis], actual.compensated[axis]);
        }
    }
    assertSameFloat(expected.temperatureC, actual.temperatureC);
    TEST_ASSERT_EQUAL_UINT8((uint8_t)expected.set, (uint8_t)actual.set);
}

// A deterministic series: noisy tilt readings and a temperature that climbs
// and falls by a few degC (raw 8 LSB/degC), so the trend turns.
static uint32_t noiseState;

inline int16_t noise(int16_t span)
{
    noiseState = noiseState * 1664525UL + 1013904223UL;
    return (int16_t)((int32_t)((noiseState >> 16) % (uint32_t)(2 * span + 1)) - span);
}

inline void sampleAt(int16_t i, int16_t raw[IMU_AXES], int16_t& temperatureRaw)
{
    raw[0] = (int16_t)(-1700 + noise(40));
    raw[1] = (int16_t)(-400 + noise(40) + (i > 300 ? 2000 : 0));
    raw[2] = (int16_t)(16000 + noise(40));
    int16_t phase = (int16_t)(i % 200);
    temperatureRaw = (int16_t)((phase < 100 ? phase : 200 - phase) / 2 + noise(2));
}

#endif
