#include "Kalman.h"

#include <math.h>

const float KalmanFilter::kPaperProcessNoise = 1e-8f;
const float KalmanFilter::kPaperMeasurementNoise = 0.01f;

namespace {

// A measurement unit in the estimate's high word is FIXED_ONE = 2^15 (ldexpf
// scales exactly, and in the AVR's library at half the cost of a
// multiplication).
const uint8_t HIGH_FRACTION_BITS = 15;
static_assert(KalmanFilter::FIXED_ONE == (int32_t)1 << HIGH_FRACTION_BITS, "FIXED_ONE is the high word's unit");
const float GAIN_TO_FRACTION = 4294967296.0f;
const float MEASUREMENT_MIN = -32768.0f;
const float MEASUREMENT_MAX = 32767.0f;

// The estimate's two 32-bit halves. Splitting an int64 by shifts would be a
// bit-by-bit loop in avr-gcc's library; both targets, the AVR and the host,
// are little-endian, as checked here.
static_assert(__BYTE_ORDER__ == __ORDER_LITTLE_ENDIAN__, "the halves of Words assume a little-endian target");
union Words {
    int64_t all;
    struct {
        uint32_t low;
        int32_t high;
    } half;
};

// The estimate to the nearest 2^-15 of a unit.
int32_t roundedHigh(int64_t estimate)
{
    Words words;
    words.all = estimate;
    return words.half.high + (int32_t)(words.half.low >> 31);
}

}  // namespace

KalmanFilter::KalmanFilter(float processNoise, float measurementNoise)
    : processNoise_(processNoise), measurementNoise_(measurementNoise)
{
    reset();
}

void KalmanFilter::reset()
{
    estimate_ = 0;
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
    updateFixed((int32_t)lrintf(ldexpf(measurement, HIGH_FRACTION_BITS)));
    return estimate();
}

void KalmanFilter::updateFixed(int32_t measurement)
{
    if (!seeded_) {
        Words seed;
        seed.half.high = measurement;
        seed.half.low = 0;
        estimate_ = seed.all;
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
    // fits 31 bits, and times a gain below 1 (32 fractional bits) 63.
    int32_t difference = measurement - roundedHigh(estimate_);
    uint32_t magnitude = difference < 0 ? (uint32_t)0 - (uint32_t)difference : (uint32_t)difference;
    int64_t correction = (int64_t)((uint64_t)magnitude * gainFraction_);
    estimate_ = difference < 0 ? estimate_ - correction : estimate_ + correction;
}

float KalmanFilter::estimate() const
{
    return ldexpf((float)roundedHigh(estimate_), -HIGH_FRACTION_BITS);
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
