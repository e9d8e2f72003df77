#ifndef THERMOTILT_PROGRAM_H
#define THERMOTILT_PROGRAM_H

#include <stdint.h>

// The chamber's temperature staircase (paper sections 3.1-3.2, Figure 8):
// warming steps of step_c from start_c up to max_c (the last one is max_c
// exactly even if the span is not a multiple of the step), then cooling steps
// back down through the same setpoints in reverse to start_c, then rest_s with
// the Peltier off, then the next cycle. Revisiting the warming setpoints gives
// every cooling step a warming twin at the same temperature for hysteresis
// comparison; with the default odd span (55 degC) the first cooling step is
// therefore 44 degC, not 43.
//
// Defaults (-10..45 degC, 2 degC, 60 s) give 29 warming + 28 cooling = 57
// steps and a 57 * 60 s + 1200 s = 4 620 000 ms cycle.
//
// stateAt() is a pure function of program time. When that time runs is
// hold_start's choice (ProgramRun): Timed, a step's hold includes the
// transition to it (Figure 8: 1-minute steps, each 2 degC change settles in
// ~13 s) and program time is the time since start; or a step waits (section
// 3.1, Figure 7: the next step comes "after temperature stabilization for the
// predefined time interval"): program time stops at the start of its hold
// until the face is within kReachedBandC of the setpoint. Times are uint32_t
// milliseconds: 1200 s is already 1 200 000 ms. A uint32_t program time wraps
// after 49.7 days; with cycles = 0 the program then jumps within its cycle.

// Numeric values are stable; the protocol sends them as T, F, A.
enum class HoldStart : uint8_t {
    Timed = 0,           // every hold starts when its step does
    FirstStepWaits = 1,  // step 0 of each cycle waits (the run from ambient or rest)
    AllStepsWait = 2,    // every driven step waits
};

struct ProgramSettings {
    float start_c = -10.0f;
    float max_c = 45.0f;
    float step_c = 2.0f;
    uint32_t hold_s = 60;
    uint32_t rest_s = 1200;
    uint16_t cycles = 0;  // 0 = repeat forever
    // Timed by default: a SETPRG without hold_start means what it meant
    // before the field was appended (docs/architecture.md).
    HoldStart hold_start = HoldStart::Timed;
};

// Numeric values are stable so firmware can report them over serial.
enum class ProgramError : uint8_t {
    None = 0,
    StartOutOfRange = 1,  // start_c outside kMinCelsius..kMaxCelsius (or NaN)
    MaxOutOfRange = 2,    // max_c outside kMinCelsius..kMaxCelsius (or NaN)
    StartNotBelowMax = 3,
    StepNotPositive = 4,  // step_c <= 0 (or NaN)
    StepLargerThanSpan = 5,
    StepTooSmall = 6,  // more than kMaxWarmingSteps warming steps
    HoldZero = 7,
    CycleTooLong = 8,  // cycles * cycle duration does not fit in uint32_t ms
    HoldStartUnknown = 9,
};

enum class ProgramPhase : uint8_t { Warming = 0, Cooling = 1, Rest = 2, Done = 3 };

struct ProgramState {
    ProgramPhase phase;
    uint32_t cycle;     // 0-based; in Done, the number of cycles run
    uint16_t step;      // warming 0..W-1, cooling W..2W-2; stepsPerCycle() in Rest/Done
    float setpoint_c;   // in Rest and Done: start_c, but the drive is off
    bool driveEnabled;  // false in Rest and Done: the Peltier must be off
};

class TemperatureProgram {
public:
    static const float kMinCelsius;  // -10, the paper's calibration range
    static const float kMaxCelsius;  // 45
    static const uint16_t kMaxWarmingSteps = 1000;
    // A waiting step counts as reached within this of its setpoint: ThermalGuard's
    // default band_c, which is wider than the P law's droop at -10 degC (0.6
    // degC) and than 255 / 350 = 0.73 degC, beyond which the drive is full, so
    // a target that is never reached leaves the guard's no-response check to
    // stop it.
    static const float kReachedBandC;

    static ProgramError validate(const ProgramSettings &settings);

    // Starts with the default settings.
    TemperatureProgram();

    // Rejected settings leave the current ones in force.
    ProgramError configure(const ProgramSettings &settings);
    const ProgramSettings &settings() const { return settings_; }

    uint16_t warmingSteps() const { return warmingSteps_; }
    uint16_t stepsPerCycle() const { return (uint16_t)(2 * warmingSteps_ - 1); }
    uint32_t cycleDurationMs() const;
    // Until Done (the last cycle ends after its cooling steps; no final rest);
    // 0 when the program repeats forever.
    uint32_t totalDurationMs() const;

    // start_c for a step beyond the cycle.
    float setpointOfStep(uint16_t step) const;
    ProgramState stateAt(uint32_t program_ms) const;

    // Whether the hold of the step in this state waits for its setpoint.
    bool holdWaits(const ProgramState &state) const;
    // Program time from program_ms to the start of the next step (or cycle).
    uint32_t msToNextStep(uint32_t program_ms) const;

private:
    uint32_t holdMs() const { return settings_.hold_s * (uint32_t)1000; }
    uint32_t heatingCoolingMs() const { return (uint32_t)stepsPerCycle() * holdMs(); }

    ProgramSettings settings_;
    uint16_t warmingSteps_;
};

// Runs a program in real time: keeps its program time, which stops while a
// waiting step has not reached its setpoint. Reads the program it was given,
// so configure that first and start() again after a change.
class ProgramRun {
public:
    explicit ProgramRun(const TemperatureProgram &program);

    // Program time 0; the first step waits for inner_c if its hold does.
    ProgramState start(float innerC);
    // dt_ms of real time passed with the inner face now at inner_c (NaN
    // never counts as reached).
    ProgramState advance(uint32_t dtMs, float innerC);

    uint32_t programMs() const { return programMs_; }
    bool waiting() const { return waiting_; }

private:
    bool reached(const ProgramState &state, float innerC) const;

    const TemperatureProgram &program_;
    uint32_t programMs_;
    bool waiting_;
};

#endif
