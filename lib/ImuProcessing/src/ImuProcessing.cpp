#include "ImuProcessing.h"

#include <LSM9DS0.h>

#if defined(__GNUC__)
#define IMU_PROCESSING_NOINLINE __attribute__((noinline))
#else
#define IMU_PROCESSING_NOINLINE
#endif

ImuProcessing::ImuProcessing(uint8_t decimation, float hysteresisC) : decimator_(decimation), trend_(hysteresisC) {}

namespace {

// temperatureRawToC(raw) * KalmanFilter::FIXED_ONE, exactly: raw / 8 + 21
// degC is a whole number of 2^-15 degC, and the shift divides by
// TEMP_LSB_PER_C (test_every_sensor_temperature_seeds_exactly checks both).
int32_t temperatureRawToFixed(int16_t raw)
{
    return (KalmanFilter::fixedFromWhole(raw) >> 3) + (int32_t)(Lsm9ds0::PAPER_TEMP_OFFSET_C * KalmanFilter::FIXED_ONE);
}

}  // namespace

// One loop over the four channels' filters, and out of line: written as
// one call per channel, avr-gcc 5.4 (-Os -flto) inlined a copy of
// the filter per call into loop(), which cost the Nano 406 B of flash and
// 15 B of stack more than this.
IMU_PROCESSING_NOINLINE bool ImuProcessing::update(const int16_t raw[IMU_AXES], int16_t temperatureRaw,
                                                   const Coefficients& coefficients, ImuOutput& out, bool counting)
{
    for (uint8_t channel = 0; channel <= IMU_AXES; ++channel) {
        bool isAxis = channel < IMU_AXES;
        KalmanFilter& filter = isAxis ? accelFilters_[channel] : temperatureFilter_;
        filter.updateFixed(isAxis ? KalmanFilter::fixedFromWhole(raw[channel]) : temperatureRawToFixed(temperatureRaw));
    }
    return finish(coefficients, out, counting);
}

bool ImuProcessing::updateUnrounded(const float accelLsb[IMU_AXES], float temperatureC,
                                    const Coefficients& coefficients, ImuOutput& out, bool counting)
{
    for (uint8_t axis = 0; axis < IMU_AXES; ++axis) {
        accelFilters_[axis].update(accelLsb[axis]);
    }
    temperatureFilter_.update(temperatureC);
    return finish(coefficients, out, counting);
}

bool ImuProcessing::finish(const Coefficients& coefficients, ImuOutput& out, bool counting)
{
    out.temperatureC = temperatureFilter_.estimate();
    out.set = trend_.update(out.temperatureC);
    out.warmingShare = blend_.update(out.temperatureC);
    if (!counting || !decimator_.push()) {
        return false;
    }
    readFiltered(out);
    compensate(coefficients, out);
    return true;
}

void ImuProcessing::readFiltered(ImuOutput& out) const
{
    for (uint8_t axis = 0; axis < IMU_AXES; ++axis) {
        out.filtered[axis] = accelFilters_[axis].estimate();
    }
}

void ImuProcessing::compensate(const Coefficients& coefficients, ImuOutput& out)
{
    const CoefficientSet& warming = coefficients.forTrend(CompSet::Warming);
    const CoefficientSet& cooling = coefficients.forTrend(CompSet::Cooling);
    for (uint8_t axis = 0; axis < IMU_AXES; ++axis) {
        out.compensated[axis] = compensateBlended(warming.axis[axis], cooling.axis[axis], out.warmingShare,
                                                  out.temperatureC, out.filtered[axis]);
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
