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
// A step's hold time includes the transition to it (Figure 8: 1-minute steps,
// each 2 degC change settles in ~13 s), so the program is a pure function of
// the time since start. Times are uint32_t milliseconds: 1200 s is already
// 1 200 000 ms. A uint32_t elapsed time (e.g. millis() - start) wraps after
// 49.7 days; with cycles = 0 the program then jumps within its cycle.

struct ProgramSettings {
    float start_c = -10.0f;
    float max_c = 45.0f;
    float step_c = 2.0f;
    uint32_t hold_s = 60;
    uint32_t rest_s = 1200;
    uint16_t cycles = 0; // 0 = repeat forever
};

// Numeric values are stable so firmware can report them over serial.
enum class ProgramError : uint8_t {
    None = 0,
    StartOutOfRange = 1, // start_c outside kMinCelsius..kMaxCelsius (or NaN)
    MaxOutOfRange = 2,   // max_c outside kMinCelsius..kMaxCelsius (or NaN)
    StartNotBelowMax = 3,
    StepNotPositive = 4, // step_c <= 0 (or NaN)
    StepLargerThanSpan = 5,
    StepTooSmall = 6,    // more than kMaxWarmingSteps warming steps
    HoldZero = 7,
    CycleTooLong = 8,    // cycles * cycle duration does not fit in uint32_t ms
};

enum class ProgramPhase : uint8_t { Warming = 0, Cooling = 1, Rest = 2, Done = 3 };

struct ProgramState {
    ProgramPhase phase;
    uint32_t cycle;    // 0-based; in Done, the number of cycles run
    uint16_t step;     // warming 0..W-1, cooling W..2W-2; stepsPerCycle() in Rest/Done
    float setpoint_c;  // in Rest and Done: start_c, but the drive is off
    bool driveEnabled; // false in Rest and Done: the Peltier must be off
};

class TemperatureProgram {
public:
    static const float kMinCelsius; // -10, the paper's calibration range
    static const float kMaxCelsius; // 45
    static const uint16_t kMaxWarmingSteps = 1000;

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
    ProgramState stateAt(uint32_t elapsed_ms) const;

private:
    uint32_t holdMs() const { return settings_.hold_s * (uint32_t)1000; }
    uint32_t heatingCoolingMs() const { return (uint32_t)stepsPerCycle() * holdMs(); }

    ProgramSettings settings_;
    uint16_t warmingSteps_;
};

#endif
