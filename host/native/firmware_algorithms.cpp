// libthermotilt_host.so (firmware_algorithms.h): lib/Program's staircase and
// lib/Compensation's trend detector and surface, lib/ChamberControl's drive
// law, over arrays for the host.
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
