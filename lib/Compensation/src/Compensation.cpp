#include "Compensation.h"

#include <math.h>

#include <ProgramMemory.h>

namespace {

const uint8_t DEFAULT_TERM_COUNT = COMP_SET_COUNT * COMP_AXIS_COUNT * COMP_COEFFICIENT_COUNT;

// In flash on AVR: as a plain const table it would cost 144 bytes of RAM.
// One row per surface: p00, p10, p01, p20, p11, p02.
const float DEFAULT_TERMS[DEFAULT_TERM_COUNT] PROGMEM = {
    // clang-format off
    // Warming: Table 2 (X), Table 3 (Y), Z uncorrected.
    571.5f, -20.23f, 1.569e-3f, -0.1044f, -6.936e-5f, 6.327e-9f,
    354.0f, -13.96f, 5.747e-3f, -2.931e-3f, -1.915e-4f, -5.363e-8f,
    0.0f, 0.0f, 0.0f, 0.0f, 0.0f, 0.0f,
    // Cooling. X p01 is as printed (7.23e-4) although its own 95 % bounds are
    // (7.535e-4, 7.91e-4), likely a dropped digit of 7.723e-4; the difference
    // is under 0.6 LSB across +-45 degrees.
    582.9f, -21.29f, 7.23e-4f, -7.898e-2f, -6.362e-5f, -7.354e-8f,
    338.1f, -12.82f, 4.439e-3f, -3.299e-2f, -1.579e-4f, -1.455e-8f,
    0.0f, 0.0f, 0.0f, 0.0f, 0.0f, 0.0f,
    // clang-format on
};

}  // namespace

void loadDefaultCoefficients(Coefficients& out)
{
    uint8_t index = 0;
    for (uint8_t s = 0; s < COMP_SET_COUNT; ++s) {
        for (uint8_t a = 0; a < COMP_AXIS_COUNT; ++a) {
            for (uint8_t k = 0; k < COMP_COEFFICIENT_COUNT; ++k) {
                out.set[s].axis[a].p[k] = pgm_read_float(&DEFAULT_TERMS[index++]);
            }
        }
    }
}

float surfaceCorrection(const AxisSurface& surface, float tempC, float accelLsb)
{
    const float* p = surface.p;
    // Grouped so a^2 (up to 2.7e8 LSB^2) is never formed on its own: each
    // product stays near the size of its contribution, which keeps float's
    // 24-bit mantissa well below 0.01 LSB of error.
    float temperaturePart = tempC * (p[P10] + p[P20] * tempC + p[P11] * accelLsb);
    float accelPart = accelLsb * (p[P01] + p[P02] * accelLsb);
    return p[P00] + temperaturePart + accelPart;
}

float compensate(const AxisSurface& surface, float tempC, float rawLsb)
{
    return rawLsb - surfaceCorrection(surface, tempC, rawLsb);
}

float compensateBlended(const AxisSurface& warming, const AxisSurface& cooling, float warmingShare, float tempC,
                        float rawLsb)
{
    if (warmingShare >= 1.0f) {
        return compensate(warming, tempC, rawLsb);
    }
    if (warmingShare <= 0.0f) {
        return compensate(cooling, tempC, rawLsb);
    }
    float correction = warmingShare * surfaceCorrection(warming, tempC, rawLsb) +
                       (1.0f - warmingShare) * surfaceCorrection(cooling, tempC, rawLsb);
    return rawLsb - correction;
}

SetBlend::SetBlend(float transitionC)
    : sharePerC_(1.0f / transitionC), lastC_(0.0f), share_(COMP_SET_POWER_UP_SHARE), haveSample_(false)
{
}

float SetBlend::update(float tempC)
{
    if (haveSample_) {
        float change = tempC - lastC_;
        // At an end and still going its way, the clamp would undo the sum:
        // the Nano skips it on every sample of a steady warming or cooling.
        bool held = (share_ >= 1.0f && change >= 0.0f) || (share_ <= 0.0f && change <= 0.0f);
        if (!held) {
            float share = share_ + change * sharePerC_;
            share_ = share > 1.0f ? 1.0f : (share < 0.0f ? 0.0f : share);
        }
    }
    lastC_ = tempC;
    haveSample_ = true;
    return share_;
}

namespace {

float clampTo(float value, float low, float high)
{
    // A term of zero puts a vertex at infinity or 0/0; any point of the
    // domain is a harmless candidate, so those fall back to an end.
    if (!(value > low)) {
        return low;
    }
    return value < high ? value : high;
}

// Collects whether every point it is shown has a compensated output that fits.
class FrameFitCheck {
public:
    explicit FrameFitCheck(const AxisSurface& surface) : surface_(surface), fits_(true) {}

    void at(float tempC, float accelLsb)
    {
        float output = compensate(surface_, clampTo(tempC, COMP_TEMPERATURE_MIN_C, COMP_TEMPERATURE_MAX_C),
                                  clampTo(accelLsb, COMP_ACCEL_MIN_LSB, COMP_ACCEL_MAX_LSB));
        // Written so that NaN fails too.
        if (!(fabsf(output) < COMP_OUTPUT_LIMIT_LSB)) {
            fits_ = false;
        }
    }

    bool fits() const { return fits_; }

private:
    const AxisSurface& surface_;
    bool fits_;
};

}  // namespace

bool surfaceOutputFitsFrame(const AxisSurface& surface)
{
    // g(T, a) = a - f(T, a) = -p00 - p10 T + (1 - p01) a - p20 T^2 - p11 T a - p02 a^2.
    const float* p = surface.p;
    const float accelSlope = 1.0f - p[P01];
    FrameFitCheck check(surface);
    // Not arrays of the two ends: on AVR a constant array is copied to RAM.
    for (uint8_t end = 0; end < 2; ++end) {
        float tempC = end == 0 ? COMP_TEMPERATURE_MIN_C : COMP_TEMPERATURE_MAX_C;
        float accelLsb = end == 0 ? COMP_ACCEL_MIN_LSB : COMP_ACCEL_MAX_LSB;
        check.at(tempC, COMP_ACCEL_MIN_LSB);
        check.at(tempC, COMP_ACCEL_MAX_LSB);
        // Vertex along a at fixed T: dg/da = 1 - p01 - p11 T - 2 p02 a = 0.
        check.at(tempC, (accelSlope - p[P11] * tempC) / (2.0f * p[P02]));
        // Vertex along T at fixed a: dg/dT = -p10 - 2 p20 T - p11 a = 0.
        check.at(-(p[P10] + p[P11] * accelLsb) / (2.0f * p[P20]), accelLsb);
    }
    // Both derivatives zero: [2 p20, p11; p11, 2 p02] (T, a) = (-p10, 1 - p01).
    float determinant = 4.0f * p[P20] * p[P02] - p[P11] * p[P11];
    check.at((-2.0f * p[P02] * p[P10] - p[P11] * accelSlope) / determinant,
             (2.0f * p[P20] * accelSlope + p[P11] * p[P10]) / determinant);
    return check.fits();
}

TrendDetector::TrendDetector(float hysteresisC, CompSet initial)
    : hysteresisC_(hysteresisC), extremeC_(0.0f), state_(initial), haveSample_(false)
{
}

void TrendDetector::reset(CompSet initial)
{
    state_ = initial;
    haveSample_ = false;
}

CompSet TrendDetector::update(float tempC)
{
    if (!haveSample_) {
        extremeC_ = tempC;
        haveSample_ = true;
        return state_;
    }
    if (state_ == CompSet::Warming) {
        if (tempC > extremeC_) {
            extremeC_ = tempC;
        } else if (extremeC_ - tempC > hysteresisC_) {
            state_ = CompSet::Cooling;
            extremeC_ = tempC;
        }
    } else {
        if (tempC < extremeC_) {
            extremeC_ = tempC;
        } else if (tempC - extremeC_ > hysteresisC_) {
            state_ = CompSet::Warming;
            extremeC_ = tempC;
        }
    }
    return state_;
}

void clearDomain(SetDomain& domain)
{
    domain.temperatureCentiC = NO_RANGE;
    for (uint8_t a = 0; a < COMP_AXIS_COUNT; ++a) {
        domain.accelLsb[a] = NO_RANGE;
    }
}

void clearDomain(CalibratedDomain& domain)
{
    for (uint8_t s = 0; s < COMP_SET_COUNT; ++s) {
        clearDomain(domain.set[s]);
    }
}

DomainCheck checkTemperature(const SetDomain& domain, float tempC)
{
    const Int16Range& range = domain.temperatureCentiC;
    if (!range.known()) {
        return DomainCheck::Unknown;
    }
    // In the bounds' unit; the product's rounding (under 0.001 of it) is far
    // below the sensor's 1/8 degC step.
    float centiC = tempC * 100.0f;
    return centiC >= (float)range.min && centiC <= (float)range.max ? DomainCheck::Inside : DomainCheck::Outside;
}
