// Thermal-drift compensation of the Sensors 2018 paper (sections 3.3, 4.2, 4.3):
// per axis a 2nd-order surface f(T, a) of temperature T (degC) and that axis'
// raw acceleration a (LSB at +-2 g), one coefficient set for warming and one
// for cooling, chosen on the device by a trend detector. Coefficients travel
// to EEPROM in a fixed, CRC-checked block shared with the host.
#ifndef THERMOTILT_COMPENSATION_H
#define THERMOTILT_COMPENSATION_H

#include <stdint.h>

const uint8_t COMP_SET_COUNT = 2;
const uint8_t COMP_AXIS_COUNT = 3;
const uint8_t COMP_COEFFICIENT_COUNT = 6;

enum class CompSet : uint8_t { Warming = 0, Cooling = 1 };

// Index into AxisSurface::p, in the paper's equation (3) order.
enum SurfaceTerm : uint8_t { P00, P10, P01, P20, P11, P02 };

struct AxisSurface {
    float p[COMP_COEFFICIENT_COUNT];
};

struct CoefficientSet {
    AxisSurface axis[COMP_AXIS_COUNT];  // X, Y, Z
};

struct Coefficients {
    CoefficientSet set[COMP_SET_COUNT];  // indexed by CompSet

    const CoefficientSet& forTrend(CompSet trend) const { return set[(uint8_t)trend]; }
};

// The paper's Table 2 (X) and Table 3 (Y), warming and cooling columns. Z is
// all zero, i.e. left uncorrected: the paper's Z fits explain little (R^2 0.46
// and 0.03, Table 4) and it recommends tilt from X and Y only (section 5).
void loadDefaultCoefficients(Coefficients& out);

// f(T, a) = p00 + p10 T + p01 a + p20 T^2 + p11 T a + p02 a^2.
float surfaceCorrection(const AxisSurface& surface, float tempC, float accelLsb);

// raw - f(T, raw): f models the drift itself. Section 3.3 fits f to the
// residuals "measured minus reference at 25 degC", so removing the drift
// subtracts f. The field tests (section 4.3) agree: cooling 26 -> 16 degC took
// X from -1831 to -1596 LSB, which raw - f flattens to -1808/-1818 (raw + f
// would spread it to 480 LSB). The warming test's "-2653 to -1699" can then
// only be a range (-1699 at 9 degC, -2653 at 48 degC: -2078/-2018), since the
// sensor cannot drift one way when warming and the other when cooling; and
// raw - f puts the 25 degC readings nearest the offsets of section 4.1.
float compensate(const AxisSurface& surface, float tempC, float rawLsb);

// Where the firmware meets a surface: the LSM9DS0's operating temperature
// range (datasheet, -40..+85 degC) and any int16 acceleration reading.
const float COMP_TEMPERATURE_MIN_C = -40.0f;
const float COMP_TEMPERATURE_MAX_C = 85.0f;
const float COMP_ACCEL_MIN_LSB = -32768.0f;
const float COMP_ACCEL_MAX_LSB = 32767.0f;

// Largest |raw - f(T, raw)| an IMU frame carries. The longest IMU line of
// protocol 2 has 87 characters besides the three compensated values
// ("$IMU", seq 65535, t_ms 4294967295, raws -32768, filtered -32768.0,
// temperature -235.000, set, source, "*HHHH" and commas), which leaves 33 of
// the 120: ten characters a value at one decimal, "-9999999.9", so |x| < 1e7.
// 0.1 % below that covers the float rounding of f (~1 LSB near 1e7).
const float COMP_OUTPUT_LIMIT_LSB = 9.99e6f;

// True when raw - f(T, raw) is finite and below COMP_OUTPUT_LIMIT_LSB in
// magnitude everywhere in that domain. It is a quadratic, so its largest
// magnitude lies at a corner, at the vertex of an edge or at the stationary
// point inside, and only those are evaluated.
bool surfaceOutputFitsFrame(const AxisSurface& surface);

// Chooses the warming or cooling set from the temperature stream: a Schmitt
// trigger on the excursion from the running extreme. While warming it tracks
// the highest temperature seen and switches to cooling at the first sample
// MORE than hysteresisC below it; cooling mirrors this. With the default
// 0.5 degC and the sensor's 1/8 degC steps, a plateau wandering +-0.25 degC
// never switches and a real turn is seen after a 0.625 degC excursion.
// Starts in warming, as the paper's cycles do.
class TrendDetector {
public:
    explicit TrendDetector(float hysteresisC = 0.5f, CompSet initial = CompSet::Warming);

    CompSet update(float tempC);
    CompSet current() const { return state_; }
    float hysteresisC() const { return hysteresisC_; }
    void reset(CompSet initial = CompSet::Warming);

private:
    float hysteresisC_;
    float extremeC_;
    CompSet state_;
    bool haveSample_;
};

// EEPROM/upload block, little-endian, shared byte for byte with the host:
// [0] magic 'T', [1] version, [2..145] 36 float32 in order set (warming,
// cooling) x axis (X, Y, Z) x term (p00..p02), [146..147] CRC-16/XMODEM of
// bytes 0..145.
const uint8_t COEFFICIENT_BLOCK_MAGIC = 0x54;
const uint8_t COEFFICIENT_BLOCK_VERSION = 1;
const uint8_t COEFFICIENT_BLOCK_SIZE = 148;

// Blank: every byte 0xFF, an erased EEPROM that was never saved to.
// BadValues: a sound block with a surface surfaceOutputFitsFrame refuses.
enum class BlockStatus : uint8_t { Ok, Blank, BadMagic, BadVersion, BadCrc, BadValues };

void encodeCoefficients(const Coefficients& in, uint8_t out[COEFFICIENT_BLOCK_SIZE]);
// Leaves `out` untouched unless the block is valid. Checks for a blank block,
// then magic, version (another version may have another layout), CRC, and
// last the values.
BlockStatus decodeCoefficients(const uint8_t in[COEFFICIENT_BLOCK_SIZE], Coefficients& out);

#endif
