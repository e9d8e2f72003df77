// libthermotilt_host.so (firmware_algorithms.h): lib/Program's staircase,
// lib/Compensation's trend detector, set blend, surface, coefficient block and sensor
// ID rule, lib/ChamberControl's drive law, for the host.
#include "firmware_algorithms.h"

#include <ChamberControl.h>
#include <Compensation.h>
#include <Program.h>

extern "C" int thermotilt_program_steps(size_t count, const float* startC, const float* maxC, const float* stepC,
                                        uint8_t* error, uint16_t* stepsPerCycle)
{
    if (count > 0 && !(startC && maxC && stepC && error && stepsPerCycle)) {
        return THERMOTILT_HOST_BAD_ARGUMENT;
    }
    ProgramSettings settings;
    settings.hold_s = 1;
    settings.rest_s = 0;
    settings.cycles = 0;
    settings.hold_start = HoldStart::Timed;
    TemperatureProgram program;
    for (size_t i = 0; i < count; ++i) {
        settings.start_c = startC[i];
        settings.max_c = maxC[i];
        settings.step_c = stepC[i];
        ProgramError result = program.configure(settings);
        error[i] = (uint8_t)result;
        stepsPerCycle[i] = result == ProgramError::None ? program.stepsPerCycle() : 0;
    }
    return 0;
}

extern "C" int thermotilt_trend_sets(size_t count, const float* temperatureC, float hysteresisC, uint8_t* set)
{
    if (count > 0 && !(temperatureC && set)) {
        return THERMOTILT_HOST_BAD_ARGUMENT;
    }
    TrendDetector trend(hysteresisC);
    for (size_t i = 0; i < count; ++i) {
        set[i] = (uint8_t)trend.update(temperatureC[i]);
    }
    return 0;
}

extern "C" int thermotilt_set_blend_shares(size_t count, const float* temperatureC, float transitionC, float* share)
{
    if (count > 0 && !(temperatureC && share)) {
        return THERMOTILT_HOST_BAD_ARGUMENT;
    }
    SetBlend blend(transitionC);
    for (size_t i = 0; i < count; ++i) {
        share[i] = blend.update(temperatureC[i]);
    }
    return 0;
}

extern "C" int thermotilt_surface_corrections(size_t count, const float* p, const float* temperatureC,
                                              const float* accelLsb, float* correction)
{
    if (count > 0 && !(p && temperatureC && accelLsb && correction)) {
        return THERMOTILT_HOST_BAD_ARGUMENT;
    }
    AxisSurface surface;
    for (uint8_t k = 0; k < COMP_COEFFICIENT_COUNT; ++k) {
        surface.p[k] = p[k];
    }
    for (size_t i = 0; i < count; ++i) {
        correction[i] = surfaceCorrection(surface, temperatureC[i], accelLsb[i]);
    }
    return 0;
}

namespace {

const uint8_t DOMAIN_VALUES = COMP_SET_COUNT * (1 + COMP_AXIS_COUNT) * 2;
static_assert(DOMAIN_VALUES == 16, "firmware_algorithms.h gives the domain as 16 int16");

void domainFromValues(const int16_t* values, CalibratedDomain& out)
{
    for (uint8_t s = 0; s < COMP_SET_COUNT; ++s) {
        const int16_t* set = values + 8 * s;
        out.set[s].temperatureCentiC = Int16Range{set[0], set[1]};
        for (uint8_t a = 0; a < COMP_AXIS_COUNT; ++a) {
            out.set[s].accelLsb[a] = Int16Range{set[2 + 2 * a], set[3 + 2 * a]};
        }
    }
}

void domainToValues(const CalibratedDomain& in, int16_t* values)
{
    for (uint8_t s = 0; s < COMP_SET_COUNT; ++s) {
        int16_t* set = values + 8 * s;
        set[0] = in.set[s].temperatureCentiC.min;
        set[1] = in.set[s].temperatureCentiC.max;
        for (uint8_t a = 0; a < COMP_AXIS_COUNT; ++a) {
            set[2 + 2 * a] = in.set[s].accelLsb[a].min;
            set[3 + 2 * a] = in.set[s].accelLsb[a].max;
        }
    }
}

float* firstTerm(Coefficients& coefficients)
{
    return &coefficients.set[0].axis[0].p[0];
}

const uint8_t TERMS = COMP_SET_COUNT * COMP_AXIS_COUNT * COMP_COEFFICIENT_COUNT;

void tableFromValues(const float* values, Coefficients& out)
{
    for (uint8_t i = 0; i < TERMS; ++i) {
        firstTerm(out)[i] = values[i];
    }
}

}  // namespace

extern "C" int thermotilt_coefficient_block_encode(const float* coefficients, const int16_t* domain,
                                                   const char* sensorId, uint8_t* block)
{
    if (!(coefficients && domain && sensorId && block) || !isValidSensorId(sensorId)) {
        return THERMOTILT_HOST_BAD_ARGUMENT;
    }
    Coefficients table;
    tableFromValues(coefficients, table);
    CalibratedDomain calibrated;
    domainFromValues(domain, calibrated);
    encodeCoefficients(table, calibrated, sensorId, block);
    return 0;
}

extern "C" int thermotilt_coefficient_block_decode(const uint8_t* block, const char* boardSensorId, uint8_t* status,
                                                   float* coefficients, int16_t* domain)
{
    if (!(block && boardSensorId && status && coefficients && domain)) {
        return THERMOTILT_HOST_BAD_ARGUMENT;
    }
    Coefficients table;
    tableFromValues(coefficients, table);
    CalibratedDomain calibrated;
    domainFromValues(domain, calibrated);
    *status = (uint8_t)decodeCoefficients(block, boardSensorId, table, calibrated);
    for (uint8_t i = 0; i < TERMS; ++i) {
        coefficients[i] = firstTerm(table)[i];
    }
    domainToValues(calibrated, domain);
    return 0;
}

extern "C" int thermotilt_sensor_ids_valid(size_t count, const char* const* texts, uint8_t* valid)
{
    if (count > 0 && !(texts && valid)) {
        return THERMOTILT_HOST_BAD_ARGUMENT;
    }
    for (size_t i = 0; i < count; ++i) {
        if (!texts[i]) {
            return THERMOTILT_HOST_BAD_ARGUMENT;
        }
    }
    for (size_t i = 0; i < count; ++i) {
        valid[i] = isValidSensorId(texts[i]) ? 1 : 0;
    }
    return 0;
}

extern "C" int thermotilt_chamber_drive(size_t count, const float* setpointC, const float* measuredC, float dtS,
                                        float proportionalGain, float integralGain, uint8_t roundedError, uint8_t* pwm,
                                        uint8_t* direction)
{
    if (count > 0 && !(setpointC && measuredC && pwm && direction)) {
        return THERMOTILT_HOST_BAD_ARGUMENT;
    }
    ChamberController controller(proportionalGain, integralGain);
    controller.setRoundedError(roundedError != 0);
    for (size_t i = 0; i < count; ++i) {
        DriveCommand command = controller.update(setpointC[i], measuredC[i], dtS);
        pwm[i] = command.pwm;
        direction[i] = (uint8_t)command.direction;
    }
    return 0;
}
