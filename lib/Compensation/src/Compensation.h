// Thermal-drift compensation of the Sensors 2018 paper (sections 3.3, 4.2, 4.3):
// per axis a 2nd-order surface f(T, a) of temperature T (degC) and that axis'
// raw acceleration a (LSB at +-2 g), one coefficient set for warming and one
// for cooling, chosen on the device by a trend detector. Coefficients travel
// to EEPROM in a fixed, CRC-checked block shared with the host.
#ifndef THERMOTILT_COMPENSATION_H
#define THERMOTILT_COMPENSATION_H

#include <stdint.h>

#include "SensorId.h"

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

// How far the sensor is from its cooling set toward its warming set after a
// reversal, from 1 (warming: the warming surfaces whole) to 0 (cooling):
// Prandtl's stop operator on the filtered temperature. Each change of the
// temperature moves the share by change / transitionC, held within 0..1, so
// a reversal crosses from one set to the other over transitionC degC at any
// rate, and a wiggle of w degC moves it by at most w / transitionC (no
// chatter: a plateau's noise blends, it never switches). The sensor's own
// crossing is gradual: its offset and drift move from one set's to the
// other's as the package relaxes (docs/physics-model.md); 1.5 degC is an
// assumption, less than the paper's 2 degC calibration step (section 3.2),
// on whose plateaus each set shows whole.
const float COMP_SET_TRANSITION_C = 1.5f;
// At power-up the sensor's set is whatever its history left, which the
// device does not know: halfway halves the worst error either way, and the
// first transitionC / 2 degC of movement in either direction settles it.
const float COMP_SET_POWER_UP_SHARE = 0.5f;

class SetBlend {
public:
    explicit SetBlend(float transitionC = COMP_SET_TRANSITION_C);

    // The warming share after the filtered temperature tempC.
    float update(float tempC);
    float warmingShare() const { return share_; }

private:
    float sharePerC_;  // 1 / transitionC: a multiplication per sample, not the AVR's division
    float lastC_;
    float share_;
    bool haveSample_;
};

// raw - (s f_W(T, raw) + (1 - s) f_C(T, raw)) for the warming share s: the
// surfaces blended as far as the sensor has crossed; at s = 1 or 0 exactly
// compensate() with that set's surface.
float compensateBlended(const AxisSurface& warming, const AxisSurface& cooling, float warmingShare, float tempC,
                        float rawLsb);

// Largest |raw - f(T, raw)| an IMU frame carries. The longest IMU line of
// protocol 2 has 89 characters besides the three compensated values
// ("$IMU", seq 65535, t_ms 4294967295, raws -32768, filtered -32768.0,
// temperature -235.000, set, source, temperature domain, "*HHHH" and
// commas), which leaves 31 of the 120: nine characters a value at one
// decimal, "-999999.9", so |x| < 1e6 (about 61 g, far beyond any int16
// reading and its drift). 0.1 % below that covers the float rounding of f.
const float COMP_OUTPUT_LIMIT_LSB = 9.99e5f;

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

// Where a fit had data, per set: the calibrated domain. Temperatures in
// 1/100 degC and accelerations in LSB, as int16: two bytes a bound, finer
// than the sensor resolves (1/8 degC, 1 LSB), and -327.68..327.67 degC and
// the whole int16 reading range fit. A range whose min is above its max is
// none: a temperature range so is unknown (the defaults, a version 1 block,
// surfaces sent without SETDOM), an axis range so was not fitted.
struct Int16Range {
    int16_t min;
    int16_t max;

    bool known() const { return min <= max; }
};

struct SetDomain {
    Int16Range temperatureCentiC;
    Int16Range accelLsb[COMP_AXIS_COUNT];  // X, Y, Z
};

struct CalibratedDomain {
    SetDomain set[COMP_SET_COUNT];  // indexed by CompSet
};

const Int16Range NO_RANGE = {INT16_MAX, INT16_MIN};

// Every range none.
void clearDomain(SetDomain& domain);
void clearDomain(CalibratedDomain& domain);

enum class DomainCheck : uint8_t { Inside, Outside, Unknown };

// Whether tempC lies within the set's calibrated temperature range (bounds
// included); Unknown without one.
DomainCheck checkTemperature(const SetDomain& domain, float tempC);

// EEPROM/upload block, little-endian, shared byte for byte with the host.
// Version 2: [0] magic 'T', [1] version, [2..145] 36 float32 in order set
// (warming, cooling) x axis (X, Y, Z) x term (p00..p02), [146..153] the
// sensor ID it was fitted for (putSensorIdField; all NUL: any sensor),
// [154..185] the calibrated domain, per set (W, C) temperature min, max then
// per axis (X, Y, Z) acceleration min, max, int16 each, [186..187]
// CRC-16/XMODEM of bytes 0..185. Version 1 ends after the floats with its
// CRC at [146..147] and has no ID (any sensor) and no domain (unknown).
const uint8_t COEFFICIENT_BLOCK_MAGIC = 0x54;
const uint8_t COEFFICIENT_BLOCK_VERSION = 2;
const uint8_t COEFFICIENT_BLOCK_V1_SIZE = 148;
// The size of the version written, and enough bytes for any version read.
const uint8_t COEFFICIENT_BLOCK_SIZE = 188;

// Blank: every byte 0xFF, an erased EEPROM that was never saved to.
// BadValues: a sound block with a surface surfaceOutputFitsFrame refuses or
// an ID that is not one. OtherSensor: a sound block fitted for another ID
// than the board's.
enum class BlockStatus : uint8_t { Ok, Blank, BadMagic, BadVersion, BadCrc, BadValues, OtherSensor };

// A block read or written a byte at a time, by index from 0: where it is
// stored (the board's EEPROM) the block then needs no copy of its 188 bytes
// on the Nano's stack. context is passed on as it was given.
typedef uint8_t (*ReadBlockByte)(const void* context, uint8_t index);
typedef void (*WriteBlockByte)(void* context, uint8_t index, uint8_t value);

// Writes bytes 0..COEFFICIENT_BLOCK_SIZE - 1 in order, each once.
void encodeCoefficients(const Coefficients& in, const CalibratedDomain& domain, const char* sensorId,
                        WriteBlockByte write, void* context);
void encodeCoefficients(const Coefficients& in, const CalibratedDomain& domain, const char* sensorId,
                        uint8_t out[COEFFICIENT_BLOCK_SIZE]);
// For the board whose ID is boardSensorId ("" unassigned): a block fitted for
// an ID loads only there, one fitted for none (version 1, or an empty ID)
// anywhere. Leaves `out` and `domain` untouched unless the block is valid.
// Checks for a blank block, then magic, version (another version may have
// another layout), CRC, the values, and last the ID. Reads bytes
// 0..COEFFICIENT_BLOCK_SIZE - 1, some more than once.
BlockStatus decodeCoefficients(ReadBlockByte read, const void* context, const char* boardSensorId, Coefficients& out,
                               CalibratedDomain& domain);
BlockStatus decodeCoefficients(const uint8_t in[COEFFICIENT_BLOCK_SIZE], const char* boardSensorId, Coefficients& out,
                               CalibratedDomain& domain);

#endif
