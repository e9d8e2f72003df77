#ifndef THERMOTILT_KALMAN_H
#define THERMOTILT_KALMAN_H

#include <stdint.h>

// Scalar (one-state, random-walk) Kalman filter, one instance per axis, as in
// section 2 of the paper: Q = 1e-8, R = 0.01, chosen there by trial and error.
//
// With these values the gain settles at about sqrt(Q/R) = 1e-3, so the filter
// behaves like a first-order low-pass with a time constant of ~1000 samples,
// i.e. ~10 s at 100 Hz. The first sample seeds the state (x = z) and P starts
// at R, so the gain begins near 1/2 and falls like 1/n: early samples are
// averaged quickly and the gain is within 0.5 % of steady state after ~3000.
// The covariance's update depends on nothing but the covariance, so once it
// returns the same float (after ~5500 samples in IEEE single precision) the
// gain is fixed and update() skips that arithmetic, a division among it.
//
// The estimate is held in fixed point, not in float: a float near 16000 LSB
// resolves 0.002 LSB while a steady correction is gain * 1 LSB = 0.001 LSB,
// which float addition would round away (the filter would stall up to ~1 LSB
// short of its input). Here the estimate has 47 fractional bits and each
// update adds gain * (measurement - estimate) exactly, in integer arithmetic
// that costs the AVR about half the soft-float operations it replaces; the
// estimate returned is that value to float precision. Measurements are
// rounded to 2^-15 and held to the range of an int16 (an LSM9DS0 register).
class KalmanFilter {
public:
    static const float kPaperProcessNoise;      // Q
    static const float kPaperMeasurementNoise;  // R
    // A measurement unit in updateFixed()'s input.
    static const int32_t FIXED_ONE = 32768;

    KalmanFilter(float processNoise = kPaperProcessNoise, float measurementNoise = kPaperMeasurementNoise);

    // Feeds one measurement and returns the new estimate.
    float update(float measurement);
    // Feeds measurement / FIXED_ONE, which must lie within an int16's range,
    // with no float to convert either way: for a caller that reads estimate()
    // less often than it updates, e.g. once per frame.
    void updateFixed(int32_t measurement);
    // whole * FIXED_ONE in a few instructions: avr-gcc 5.4 turns the
    // multiplication into a 15-step shift loop, but a multiplication by 2^16
    // into byte moves. The right shift of a negative number is arithmetic in
    // GCC (its manual, "Integers implementation").
    static int32_t fixedFromWhole(int16_t whole) { return ((int32_t)whole * 65536) >> 1; }

    // Forgets the state: the next measurement seeds the filter again.
    void reset();

    bool isSeeded() const { return seeded_; }
    float estimate() const;
    float lastGain() const { return gain_; }
    float errorCovariance() const { return covariance_; }
    bool gainSettled() const { return gainSettled_; }

private:
    float processNoise_;
    float measurementNoise_;
    // The estimate to the nearest 2^-15 of a unit, in those.
    int32_t roundedEstimate() const;

    // The estimate in measurement units * 2^47, as two halves: the high one
    // is units * FIXED_ONE, the low one its fraction.
    int32_t estimateHigh_;
    uint32_t estimateLow_;
    float covariance_;
    float gain_;
    uint32_t gainFraction_;  // gain_ * 2^32
    bool seeded_;
    bool gainSettled_;
};

// Passes every factor-th sample. push() is called once per sample and returns
// true on the factor-th, 2*factor-th, ... call. A factor of 0 counts as 1.
class Decimator {
public:
    explicit Decimator(uint8_t factor = 1);

    // Changing the factor restarts the count.
    void setFactor(uint8_t factor);
    uint8_t factor() const { return factor_; }

    bool push();
    void restart() { count_ = 0; }

private:
    uint8_t factor_;
    uint8_t count_;
};

#endif
