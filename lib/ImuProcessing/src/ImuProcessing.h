// The IMU reader's processing of one 100 Hz sample, as firmware/imu_reader
// runs it and as the host replays it (host/native, thermotilt.native): the
// temperature and each axis through their Kalman filters, the filtered
// temperature into the trend detector (which set, warming or cooling, the
// frame reports) and the set blend (how far the sensor has crossed between
// the sets), the decimator (whether this sample is a frame), and for a frame
// the compensated acceleration a - f(T, a) of the filtered values with the
// two sets' surfaces blended by that share.
#ifndef THERMOTILT_IMU_PROCESSING_H
#define THERMOTILT_IMU_PROCESSING_H

#include <stdint.h>

#include <Compensation.h>
#include <Kalman.h>

const uint8_t IMU_AXES = 3;
const uint8_t IMU_DEFAULT_DECIMATION = 10;
const float IMU_DEFAULT_HYSTERESIS_C = 0.5f;

// What one sample gives. filtered and compensated are written only for a
// frame (update's result true), or by ImuProcessing::readFiltered and
// ImuProcessing::compensate: the firmware needs them for nothing else, and
// the AVR would spend ~5 % of its awake time converting them to float.
struct ImuOutput {
    float filtered[IMU_AXES];  // LSB
    float temperatureC;        // filtered, degC
    CompSet set;
    float warmingShare;           // SetBlend's: 1 the warming surfaces, 0 the cooling ones
    float compensated[IMU_AXES];  // LSB, filtered - f(temperatureC, filtered), the sets blended by warmingShare
};

class ImuProcessing {
public:
    explicit ImuProcessing(uint8_t decimation = IMU_DEFAULT_DECIMATION, float hysteresisC = IMU_DEFAULT_HYSTERESIS_C);

    // One sample as the LSM9DS0 gives it: raw X, Y, Z and OUT_TEMP_XM (8
    // LSB/degC, temperatureRawToC). Filters, updates the trend and, while
    // counting (the firmware's streaming), the decimator; for the sample that
    // completes a frame also compensates with `coefficients` and returns
    // true. Not counting, it filters alike and never returns true.
    bool update(const int16_t raw[IMU_AXES], int16_t temperatureRaw, const Coefficients& coefficients, ImuOutput& out,
                bool counting = true);

    // The same with unquantised inputs: acceleration in LSB and temperature in
    // degC, before the filters. update() is this with raw[a] and
    // temperatureRawToC(temperatureRaw), which float holds exactly.
    bool updateUnrounded(const float accelLsb[IMU_AXES], float temperatureC, const Coefficients& coefficients,
                         ImuOutput& out, bool counting = true);

    // out.filtered: the axes' filters' estimates, after any sample.
    void readFiltered(ImuOutput& out) const;

    // out.compensated from out.filtered, out.temperatureC and out.warmingShare.
    static void compensate(const Coefficients& coefficients, ImuOutput& out);

    // RESEED and a (re)connected sensor: the filters forget their state, so the
    // next sample seeds them, and the decimation count starts again. The trend
    // and the blend keep their state: the temperature history is still the
    // sensor's.
    void reset();

    // START/STOP: the next frame is `decimation` counted samples away.
    void restartDecimation() { decimator_.restart(); }
    // SETDEC (0 counts as 1); restarts the count.
    void setDecimation(uint8_t factor) { decimator_.setFactor(factor); }
    uint8_t decimation() const { return decimator_.factor(); }
    float hysteresisC() const { return trend_.hysteresisC(); }
    CompSet currentSet() const { return trend_.current(); }

private:
    // Both updates, after the filters: the trend, the decimator, a frame.
    bool finish(const Coefficients& coefficients, ImuOutput& out, bool counting);

    KalmanFilter accelFilters_[IMU_AXES];
    // Temperature goes through the same filter as acceleration, so f(T, a)
    // sees the two with the same lag.
    KalmanFilter temperatureFilter_;
    Decimator decimator_;
    TrendDetector trend_;
    SetBlend blend_;
};

#endif
