// libthermotilt_host.so (imu_processing.h): lib/ImuProcessing, the class the
// IMU reader's firmware runs on every sample, over a series for the host.
#include "imu_processing.h"

#include <math.h>

#include <Compensation.h>
#include <ImuProcessing.h>

namespace {

bool validArguments(size_t count, const void* accel, const void* temperature, unsigned decimation, float hysteresisC,
                    const float* filtered, const float* temperatureC, const uint8_t* set, const float* compensated,
                    const uint8_t* frameDue)
{
    if (decimation < 1 || decimation > 255 || !isfinite(hysteresisC)) {
        return false;
    }
    return count == 0 || (accel && temperature && filtered && temperatureC && set && compensated && frameDue);
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
template <typename Update>
int run(size_t count, const uint8_t* reset, unsigned decimation, float hysteresisC, const float* coefficientValues,
        float* filtered, float* temperatureC, uint8_t* set, float* compensated, uint8_t* frameDue, Update update)
{
    Coefficients coefficients;
    loadCoefficients(coefficientValues, coefficients);
    ImuProcessing processing((uint8_t)decimation, hysteresisC);
    for (size_t i = 0; i < count; ++i) {
        if (reset && reset[i]) {
            processing.reset();
        }
        ImuOutput out;
        bool due = update(processing, i, coefficients, out);
        if (!due) {
            processing.readFiltered(out);
            ImuProcessing::compensate(coefficients, out);
        }
        for (uint8_t axis = 0; axis < IMU_AXES; ++axis) {
            filtered[IMU_AXES * i + axis] = out.filtered[axis];
            compensated[IMU_AXES * i + axis] = out.compensated[axis];
        }
        temperatureC[i] = out.temperatureC;
        set[i] = (uint8_t)out.set;
        frameDue[i] = due ? 1 : 0;
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
                                      const float* coefficients, float* filtered, float* temperatureC, uint8_t* set,
                                      float* compensated, uint8_t* frameDue)
{
    if (!validArguments(count, accel, temperatureRaw, decimation, hysteresisC, filtered, temperatureC, set, compensated,
                        frameDue)) {
        return THERMOTILT_HOST_BAD_ARGUMENT;
    }
    return run(count, reset, decimation, hysteresisC, coefficients, filtered, temperatureC, set, compensated, frameDue,
               [&](ImuProcessing& processing, size_t i, const Coefficients& c, ImuOutput& out) {
                   return processing.update(accel + IMU_AXES * i, temperatureRaw[i], c, out);
               });
}

extern "C" int thermotilt_imu_process_unrounded(size_t count, const float* accel, const float* temperatureCIn,
                                                const uint8_t* reset, unsigned decimation, float hysteresisC,
                                                const float* coefficients, float* filtered, float* temperatureC,
                                                uint8_t* set, float* compensated, uint8_t* frameDue)
{
    if (!validArguments(count, accel, temperatureCIn, decimation, hysteresisC, filtered, temperatureC, set, compensated,
                        frameDue)) {
        return THERMOTILT_HOST_BAD_ARGUMENT;
    }
    return run(count, reset, decimation, hysteresisC, coefficients, filtered, temperatureC, set, compensated, frameDue,
               [&](ImuProcessing& processing, size_t i, const Coefficients& c, ImuOutput& out) {
                   return processing.updateUnrounded(accel + IMU_AXES * i, temperatureCIn[i], c, out);
               });
}
