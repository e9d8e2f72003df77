#include "Kalman.h"

const float KalmanFilter::kPaperProcessNoise = 1e-8f;
const float KalmanFilter::kPaperMeasurementNoise = 0.01f;

KalmanFilter::KalmanFilter(float processNoise, float measurementNoise)
    : processNoise_(processNoise), measurementNoise_(measurementNoise)
{
    reset();
}

void KalmanFilter::reset()
{
    estimate_ = 0.0f;
    lostLowBits_ = 0.0f;
    covariance_ = measurementNoise_;
    gain_ = 1.0f;
    seeded_ = false;
    gainSettled_ = false;
}

float KalmanFilter::update(float measurement)
{
    if (!seeded_) {
        estimate_ = measurement;
        seeded_ = true;
        return estimate_;
    }
    if (!gainSettled_) {
        float predicted = covariance_ + processNoise_;
        gain_ = predicted / (predicted + measurementNoise_);
        float updated = (1.0f - gain_) * predicted;
        gainSettled_ = updated == covariance_;
        covariance_ = updated;
    }

    // A float near 16000 LSB has a resolution of 0.002 LSB, while a correction
    // of gain * 1 LSB is 0.001 LSB: plain "estimate += correction" would round
    // it away and leave the filter stuck up to ~1 LSB from the input.
    // Kahan summation carries the rounded-off part to the next update.
    float correction = gain_ * (measurement - estimate_) - lostLowBits_;
    float sum = estimate_ + correction;
    lostLowBits_ = (sum - estimate_) - correction;
    estimate_ = sum;
    return estimate_;
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
