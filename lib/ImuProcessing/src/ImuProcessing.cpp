#include "ImuProcessing.h"

#include <LSM9DS0.h>

#if defined(__GNUC__)
#define IMU_PROCESSING_NOINLINE __attribute__((noinline))
#else
#define IMU_PROCESSING_NOINLINE
#endif

ImuProcessing::ImuProcessing(uint8_t decimation, float hysteresisC)
    : decimator_(decimation), trend_(hysteresisC)
{
}

bool ImuProcessing::update(const int16_t raw[IMU_AXES], int16_t temperatureRaw, const Coefficients& coefficients,
                           ImuOutput& out, bool counting)
{
    return process(raw, 0, temperatureRawToC(temperatureRaw), coefficients, out, counting);
}

bool ImuProcessing::updateUnrounded(const float accelLsb[IMU_AXES], float temperatureC,
                                    const Coefficients& coefficients, ImuOutput& out, bool counting)
{
    return process(0, accelLsb, temperatureC, coefficients, out, counting);
}

// One loop over the four channels' filters, and out of line: written as
// one call per channel, avr-gcc 5.4 (-Os -flto) inlined a copy of
// the filter per call into loop(), which cost the Nano 406 B of flash and
// 15 B of stack more than this.
IMU_PROCESSING_NOINLINE bool ImuProcessing::process(const int16_t* raw, const float* accelLsb, float temperatureC,
                                                    const Coefficients& coefficients, ImuOutput& out, bool counting)
{
    for (uint8_t channel = 0; channel <= IMU_AXES; ++channel) {
        bool isAxis = channel < IMU_AXES;
        KalmanFilter& filter = isAxis ? accelFilters_[channel] : temperatureFilter_;
        float estimate = !isAxis ? filter.update(temperatureC)
                         : raw   ? filter.updateInteger(raw[channel])
                                 : filter.update(accelLsb[channel]);
        (isAxis ? out.filtered[channel] : out.temperatureC) = estimate;
    }
    out.set = trend_.update(out.temperatureC);
    if (!counting || !decimator_.push()) {
        return false;
    }
    compensate(coefficients, out);
    return true;
}

void ImuProcessing::compensate(const Coefficients& coefficients, ImuOutput& out)
{
    const CoefficientSet& surfaces = coefficients.forTrend(out.set);
    for (uint8_t axis = 0; axis < IMU_AXES; ++axis) {
        out.compensated[axis] = ::compensate(surfaces.axis[axis], out.temperatureC, out.filtered[axis]);
    }
}

void ImuProcessing::reset()
{
    for (uint8_t axis = 0; axis < IMU_AXES; ++axis) {
        accelFilters_[axis].reset();
    }
    temperatureFilter_.reset();
    decimator_.restart();
}
