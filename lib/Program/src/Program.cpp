#include "Program.h"

#include <math.h>

const float TemperatureProgram::kMinCelsius = -10.0f;
const float TemperatureProgram::kMaxCelsius = 45.0f;
const uint16_t TemperatureProgram::kMaxWarmingSteps;
const float TemperatureProgram::kReachedBandC = 1.0f;

static const uint32_t kMaxMs = 0xFFFFFFFFUL;
static const uint32_t kMsPerSecond = 1000;

static bool inRange(float celsius)
{
    return celsius >= TemperatureProgram::kMinCelsius && celsius <= TemperatureProgram::kMaxCelsius;
}

// Warming setpoints are start, start + step, ... and finally max; a span that
// is a multiple of the step up to float rounding must not get an extra,
// near-duplicate top step, hence the small tolerance.
static float warmingStepCount(const ProgramSettings &settings)
{
    float intervals = ceilf((settings.max_c - settings.start_c) / settings.step_c - 1e-4f);
    return intervals + 1.0f;
}

ProgramError TemperatureProgram::validate(const ProgramSettings &settings)
{
    if (!inRange(settings.start_c))
        return ProgramError::StartOutOfRange;
    if (!inRange(settings.max_c))
        return ProgramError::MaxOutOfRange;
    if (!(settings.start_c < settings.max_c))
        return ProgramError::StartNotBelowMax;
    if (!(settings.step_c > 0.0f))
        return ProgramError::StepNotPositive;
    if (settings.step_c > settings.max_c - settings.start_c)
        return ProgramError::StepLargerThanSpan;
    float warming = warmingStepCount(settings);
    if (warming > (float)kMaxWarmingSteps)
        return ProgramError::StepTooSmall;
    if (settings.hold_s == 0)
        return ProgramError::HoldZero;
    if ((uint8_t)settings.hold_start > (uint8_t)HoldStart::AllStepsWait)
        return ProgramError::HoldStartUnknown;

    uint32_t steps = 2 * (uint32_t)warming - 1;
    if (settings.hold_s > kMaxMs / kMsPerSecond / steps)
        return ProgramError::CycleTooLong;
    uint32_t activeMs = steps * settings.hold_s * kMsPerSecond;
    if (settings.rest_s > (kMaxMs - activeMs) / kMsPerSecond)
        return ProgramError::CycleTooLong;
    uint32_t cycleMs = activeMs + settings.rest_s * kMsPerSecond;
    if (settings.cycles > 1 && (uint32_t)(settings.cycles - 1) > (kMaxMs - activeMs) / cycleMs)
        return ProgramError::CycleTooLong;
    return ProgramError::None;
}

TemperatureProgram::TemperatureProgram()
{
    configure(ProgramSettings());
}

ProgramError TemperatureProgram::configure(const ProgramSettings &settings)
{
    ProgramError error = validate(settings);
    if (error != ProgramError::None)
        return error;
    settings_ = settings;
    warmingSteps_ = (uint16_t)warmingStepCount(settings);
    return ProgramError::None;
}

uint32_t TemperatureProgram::cycleDurationMs() const
{
    return heatingCoolingMs() + settings_.rest_s * kMsPerSecond;
}

uint32_t TemperatureProgram::totalDurationMs() const
{
    if (settings_.cycles == 0)
        return 0;
    return (uint32_t)(settings_.cycles - 1) * cycleDurationMs() + heatingCoolingMs();
}

float TemperatureProgram::setpointOfStep(uint16_t step) const
{
    if (step >= stepsPerCycle())
        return settings_.start_c;
    uint16_t top = (uint16_t)(warmingSteps_ - 1);
    uint16_t level = step <= top ? step : (uint16_t)(2 * top - step);
    if (level >= top)
        return settings_.max_c;
    return settings_.start_c + (float)level * settings_.step_c;
}

ProgramState TemperatureProgram::stateAt(uint32_t program_ms) const
{
    ProgramState state;
    state.setpoint_c = settings_.start_c;
    state.driveEnabled = false;

    uint32_t total = totalDurationMs();
    if (total != 0 && program_ms >= total) {
        state.phase = ProgramPhase::Done;
        state.cycle = settings_.cycles;
        state.step = stepsPerCycle();
        return state;
    }

    uint32_t cycleMs = cycleDurationMs();
    uint32_t inCycle = program_ms % cycleMs;
    state.cycle = program_ms / cycleMs;
    if (inCycle >= heatingCoolingMs()) {
        state.phase = ProgramPhase::Rest;
        state.step = stepsPerCycle();
        return state;
    }
    state.step = (uint16_t)(inCycle / holdMs());
    state.phase = state.step < warmingSteps_ ? ProgramPhase::Warming : ProgramPhase::Cooling;
    state.setpoint_c = setpointOfStep(state.step);
    state.driveEnabled = true;
    return state;
}

bool TemperatureProgram::holdWaits(const ProgramState &state) const
{
    if (!state.driveEnabled)
        return false;
    switch (settings_.hold_start) {
    case HoldStart::AllStepsWait: return true;
    case HoldStart::FirstStepWaits: return state.step == 0;
    default: return false;
    }
}

uint32_t TemperatureProgram::msToNextStep(uint32_t program_ms) const
{
    uint32_t cycleMs = cycleDurationMs();
    uint32_t inCycle = program_ms % cycleMs;
    if (inCycle >= heatingCoolingMs())
        return cycleMs - inCycle;
    return holdMs() - inCycle % holdMs();
}

ProgramRun::ProgramRun(const TemperatureProgram &program) : program_(program), programMs_(0), waiting_(false) {}

bool ProgramRun::reached(const ProgramState &state, float innerC) const
{
    return fabsf(state.setpoint_c - innerC) <= TemperatureProgram::kReachedBandC;
}

ProgramState ProgramRun::start(float innerC)
{
    programMs_ = 0;
    ProgramState state = program_.stateAt(0);
    waiting_ = program_.holdWaits(state) && !reached(state, innerC);
    return state;
}

ProgramState ProgramRun::advance(uint32_t dtMs, float innerC)
{
    if (waiting_ && reached(program_.stateAt(programMs_), innerC))
        waiting_ = false;
    while (!waiting_ && program_.stateAt(programMs_).phase != ProgramPhase::Done) {
        uint32_t toNext = program_.msToNextStep(programMs_);
        if (dtMs < toNext) {
            programMs_ += dtMs;
            break;
        }
        programMs_ += toNext;
        dtMs -= toNext;
        ProgramState next = program_.stateAt(programMs_);
        waiting_ = program_.holdWaits(next) && !reached(next, innerC);
    }
    return program_.stateAt(programMs_);
}
