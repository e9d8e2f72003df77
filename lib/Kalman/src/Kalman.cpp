#include "Kalman.h"

#include <math.h>

const float KalmanFilter::kPaperProcessNoise = 1e-8f;
const float KalmanFilter::kPaperMeasurementNoise = 0.01f;

namespace {

// A measurement unit in the estimate's high word is FIXED_ONE = 2^15.
const uint8_t HIGH_FRACTION_BITS = 15;
static_assert(KalmanFilter::FIXED_ONE == (int32_t)1 << HIGH_FRACTION_BITS, "FIXED_ONE is the high word's unit");

// value * 2^15 and value / 2^15, exact either way for the values here: a
// measurement within an int16's range, an estimate that is a whole int32.
// avr-libc's ldexpf scales at half the cost of a multiplication; a PC's
// ldexpf is a library call where a multiplication is one instruction, and
// the host runs this on every sample of a replay (thermotilt.native).
#if defined(__AVR__)
inline float toHighUnits(float value)
{
    return ldexpf(value, HIGH_FRACTION_BITS);
}
inline float fromHighUnits(float value)
{
    return ldexpf(value, -HIGH_FRACTION_BITS);
}
#else
inline float toHighUnits(float value)
{
    return value * (float)KalmanFilter::FIXED_ONE;
}
inline float fromHighUnits(float value)
{
    return value / (float)KalmanFilter::FIXED_ONE;
}
#endif
const float GAIN_TO_FRACTION = 4294967296.0f;
const float MEASUREMENT_MIN = -32768.0f;
const float MEASUREMENT_MAX = 32767.0f;

// The two 32-bit halves of a 64-bit product. Splitting it by shifts would
// be a bit-by-bit loop in avr-gcc's library; both targets, the AVR and the
// host, are little-endian, as checked here.
static_assert(__BYTE_ORDER__ == __ORDER_LITTLE_ENDIAN__, "the halves of Product assume a little-endian target");
union Product {
    uint64_t all;
    struct {
        uint32_t low;
        uint32_t high;
    } half;
};

}  // namespace

KalmanFilter::KalmanFilter(float processNoise, float measurementNoise)
    : processNoise_(processNoise), measurementNoise_(measurementNoise)
{
    reset();
}

void KalmanFilter::reset()
{
    estimateHigh_ = 0;
    estimateLow_ = 0;
    covariance_ = measurementNoise_;
    gain_ = 1.0f;
    gainFraction_ = 0;
    seeded_ = false;
    gainSettled_ = false;
}

float KalmanFilter::update(float measurement)
{
    // NaN, which no register gives, counts as the minimum.
    if (!(measurement > MEASUREMENT_MIN)) {
        measurement = MEASUREMENT_MIN;
    } else if (measurement > MEASUREMENT_MAX) {
        measurement = MEASUREMENT_MAX;
    }
    updateFixed((int32_t)lrintf(toHighUnits(measurement)));
    return estimate();
}

void KalmanFilter::updateFixed(int32_t measurement)
{
    if (!seeded_) {
        estimateHigh_ = measurement;
        estimateLow_ = 0;
        seeded_ = true;
        return;
    }
    if (!gainSettled_) {
        float predicted = covariance_ + processNoise_;
        gain_ = predicted / (predicted + measurementNoise_);
        float updated = (1.0f - gain_) * predicted;
        gainSettled_ = updated == covariance_;
        covariance_ = updated;
        // A process noise far above the measurement noise rounds the gain to 1.
        gainFraction_ = gain_ < 1.0f ? (uint32_t)(gain_ * GAIN_TO_FRACTION) : UINT32_MAX;
    }
    // Measurement and estimate both within an int16's range: the difference
    // fits 31 bits, and times a gain below 1 (32 fractional bits) 63. The
    // estimate's two halves take the correction as one 64-bit number would,
    // in 32-bit steps avr-gcc does inline rather than in its int64 library.
    int32_t difference = measurement - roundedEstimate();
    uint32_t magnitude = difference < 0 ? (uint32_t)0 - (uint32_t)difference : (uint32_t)difference;
    Product correction;
    correction.all = (uint64_t)magnitude * gainFraction_;
    uint32_t low = estimateLow_;
    uint32_t high = (uint32_t)estimateHigh_;
    if (difference < 0) {
        estimateLow_ = low - correction.half.low;
        high -= correction.half.high + (estimateLow_ > low ? 1u : 0u);
    } else {
        estimateLow_ = low + correction.half.low;
        high += correction.half.high + (estimateLow_ < low ? 1u : 0u);
    }
    estimateHigh_ = (int32_t)high;
}

int32_t KalmanFilter::roundedEstimate() const
{
    return estimateHigh_ + (int32_t)(estimateLow_ >> 31);
}

float KalmanFilter::estimate() const
{
    return fromHighUnits((float)roundedEstimate());
}

Decimator::Decimator(uint8_t factor) : factor_(1), count_(0)
{
    setFactor(factor);
}

void Decimator::setFactor(uint8_t factor)
{
    factor_ = factor == 0 ? 1 : factor;
    count_ = 0;
}

bool Decimator::push()
{
    ++count_;
    if (count_ < factor_)
        return false;
    count_ = 0;
    return true;
}
