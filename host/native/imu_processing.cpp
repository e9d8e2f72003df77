// libthermotilt_host.so (imu_processing.h): lib/ImuProcessing, the class the
// IMU reader's firmware runs on every sample, over a series for the host.
#include "imu_processing.h"

#include <math.h>

#include <Compensation.h>
#include <ImuProcessing.h>
#include <Kalman.h>

namespace {

bool validSamples(size_t count, const size_t* at, size_t atCount)
{
    if (at) {
        for (size_t k = 0; k < atCount; ++k) {
            if (at[k] >= count || (k > 0 && at[k] < at[k - 1])) {
                return false;
            }
        }
    }
    return true;
}

bool validArguments(size_t count, const void* accel, const void* temperature, unsigned decimation, float hysteresisC,
                    const size_t* at, size_t atCount, const float* filtered, const float* temperatureC,
                    const uint8_t* set, const float* compensated, const uint8_t* frameDue)
{
    if (decimation < 1 || decimation > 255 || !isfinite(hysteresisC) || !validSamples(count, at, atCount)) {
        return false;
    }
    size_t written = at ? atCount : count;
    return (count == 0 || (accel && temperature)) &&
           (written == 0 || (filtered && temperatureC && set && compensated && frameDue));
}

void loadCoefficients(const float* values, Coefficients& out)
{
    if (!values) {
        loadDefaultCoefficients(out);
        return;
    }
    for (uint8_t s = 0; s < COMP_SET_COUNT; ++s) {
        for (uint8_t a = 0; a < COMP_AXIS_COUNT; ++a) {
            for (uint8_t k = 0; k < COMP_COEFFICIENT_COUNT; ++k) {
                out.set[s].axis[a].p[k] = *values++;
            }
        }
    }
}

// Runs the series; Update(processing, i, coefficients, out) feeds sample i.
// Outputs go to row k for sample at[k] (every sample when at is NULL), so a
// caller that keeps a few samples neither compensates nor copies the others.
template <typename Update>
int run(size_t count, const uint8_t* reset, unsigned decimation, float hysteresisC, const float* coefficientValues,
        const size_t* at, size_t atCount, float* filtered, float* temperatureC, uint8_t* set, float* compensated,
        uint8_t* frameDue, Update update)
{
    Coefficients coefficients;
    loadCoefficients(coefficientValues, coefficients);
    ImuProcessing processing((uint8_t)decimation, hysteresisC);
    size_t row = 0;
    for (size_t i = 0; i < count; ++i) {
        if (reset && reset[i]) {
            processing.reset();
        }
        ImuOutput out;
        bool due = update(processing, i, coefficients, out);
        if (at && (row == atCount || at[row] != i)) {
            continue;
        }
        if (!due) {
            processing.readFiltered(out);
            ImuProcessing::compensate(coefficients, out);
        }
        do {
            for (uint8_t axis = 0; axis < IMU_AXES; ++axis) {
                filtered[IMU_AXES * row + axis] = out.filtered[axis];
                compensated[IMU_AXES * row + axis] = out.compensated[axis];
            }
            temperatureC[row] = out.temperatureC;
            set[row] = (uint8_t)out.set;
            frameDue[row] = due ? 1 : 0;
            ++row;
        } while (at && row < atCount && at[row] == i);
    }
    return 0;
}

}  // namespace

extern "C" int thermotilt_host_abi_version(void)
{
    return THERMOTILT_HOST_ABI_VERSION;
}

extern "C" int thermotilt_imu_process(size_t count, const int16_t* accel, const int16_t* temperatureRaw,
                                      const uint8_t* reset, unsigned decimation, float hysteresisC,
                                      const float* coefficients, const size_t* at, size_t atCount, float* filtered,
                                      float* temperatureC, uint8_t* set, float* compensated, uint8_t* frameDue)
{
    if (!validArguments(count, accel, temperatureRaw, decimation, hysteresisC, at, atCount, filtered, temperatureC, set,
                        compensated, frameDue)) {
        return THERMOTILT_HOST_BAD_ARGUMENT;
    }
    return run(count, reset, decimation, hysteresisC, coefficients, at, atCount, filtered, temperatureC, set,
               compensated, frameDue, [&](ImuProcessing& processing, size_t i, const Coefficients& c, ImuOutput& out) {
                   return processing.update(accel + IMU_AXES * i, temperatureRaw[i], c, out);
               });
}

extern "C" int thermotilt_imu_process_unrounded(size_t count, const float* accel, const float* temperatureCIn,
                                                const uint8_t* reset, unsigned decimation, float hysteresisC,
                                                const float* coefficients, const size_t* at, size_t atCount,
                                                float* filtered, float* temperatureC, uint8_t* set, float* compensated,
                                                uint8_t* frameDue)
{
    if (!validArguments(count, accel, temperatureCIn, decimation, hysteresisC, at, atCount, filtered, temperatureC, set,
                        compensated, frameDue)) {
        return THERMOTILT_HOST_BAD_ARGUMENT;
    }
    return run(count, reset, decimation, hysteresisC, coefficients, at, atCount, filtered, temperatureC, set,
               compensated, frameDue, [&](ImuProcessing& processing, size_t i, const Coefficients& c, ImuOutput& out) {
                   return processing.updateUnrounded(accel + IMU_AXES * i, temperatureCIn[i], c, out);
               });
}

extern "C" int thermotilt_kalman_estimates(size_t count, const float* measurements, const uint8_t* reset,
                                           const size_t* at, size_t atCount, float* estimates)
{
    size_t written = at ? atCount : count;
    if (!validSamples(count, at, atCount) || (count > 0 && !measurements) || (written > 0 && !estimates)) {
        return THERMOTILT_HOST_BAD_ARGUMENT;
    }
    KalmanFilter filter;
    size_t row = 0;
    for (size_t i = 0; i < count && row < written; ++i) {
        if (reset && reset[i]) {
            filter.reset();
        }
        filter.update(measurements[i]);
        if (!at) {
            estimates[row++] = filter.estimate();
            continue;
        }
        while (row < atCount && at[row] == i) {
            estimates[row++] = filter.estimate();
        }
    }
    return 0;
}
