#ifndef THERMOTILT_THERMALGUARD_H
#define THERMOTILT_THERMALGUARD_H

#include <stdint.h>

#include <ChamberControl.h>

// Runaway protection in the manner of Klipper's verify_heater and Marlin's
// thermal runaway protection, but for an element that heats and cools: a
// Peltier cell whose leads may be reversed, whose thermistor may come off
// its face, or whose heatsink may fail. Checked on every control tick with
// the readings and the drive applied since the previous tick:
//
// * limits: either face outside its absolute range trips at once, whether
//   or not a program runs (a dead heatsink fan overheats the outer face
//   first);
// * no response: while the drive is at full power towards a target more
//   than band_c away, the inner face must gain gain_c towards it within
//   window_s (restarted by each gain and each new target): catches a
//   disconnected Peltier and a thermistor that no longer reads its face;
// * wrong way: under that full drive, the face must not fall back from the
//   closest it came to the target by wrong_way_c: catches reversed leads in
//   seconds, in the heating and the cooling direction alike;
// * hold lost: once the face has reached a target, the time integral of its
//   error beyond band_c must stay below max_error_c_s.
//
// docs/reliability.md gives the reasoning behind each default.
struct GuardSettings {
    float band_c = 1.0f;
    float gain_c = 1.0f;
    float window_s = 90.0f;
    float wrong_way_c = 2.0f;
    float max_error_c_s = 120.0f;
    float inner_min_c = -20.0f;
    float inner_max_c = 55.0f;
    float outer_min_c = -20.0f;
    float outer_max_c = 70.0f;
};

// Numeric values are stable: the firmware reports them by name.
enum class GuardFault : uint8_t {
    None = 0,
    InnerHot = 1,
    InnerCold = 2,
    OuterHot = 3,
    OuterCold = 4,
    NoResponse = 5,
    WrongWay = 6,
    HoldLost = 7,
};

enum class GuardError : uint8_t {
    None = 0,
    CheckOutOfRange = 1,  // band, gain or wrong-way distance not in (0, 10] degC, window not in
                          // (0, 600] s, error budget not in (0, 3600] degC s (or NaN)
    LimitOutOfRange = 2,  // a face limit outside kHardMinCelsius..kHardMaxCelsius (or NaN)
    LimitsInverted = 3,   // a minimum not below its maximum
};

class ThermalGuard {
public:
    // No setting may widen the limits past these: the LSM9DS0's operating
    // range on the inner face (-40..85 degC); the outer face likewise.
    static const float kHardMinCelsius;
    static const float kHardMaxCelsius;

    static GuardError validate(const GuardSettings &settings);

    // Starts with the default settings.
    ThermalGuard();

    // Rejected settings leave the current ones in force; accepted ones
    // restart the checks.
    GuardError configure(const GuardSettings &settings);
    const GuardSettings &settings() const { return settings_; }

    // Forgets what it saw, e.g. when a program starts.
    void reset();

    // The absolute limits alone, e.g. before a latched fault may be cleared.
    GuardFault limitFault(float innerC, float outerC) const;

    // target_c is NaN while the program does not drive the face (idle, rest,
    // done): then only the limits apply. A NaN reading trips nothing here;
    // the thermistor checks own that case.
    GuardFault update(float targetC, float innerC, float outerC, const DriveCommand &drive, float dtSeconds);

private:
    void restartApproach(float innerC, int8_t direction);

    GuardSettings settings_;
    float lastTargetC_;
    float goalC_;     // the reading that counts as the next gain
    float closestC_;  // the closest the reading came to the target under full drive
    float sinceGainS_;
    float holdErrorCS_;
    int8_t approachDirection_;  // +1 heating, -1 cooling, 0 not under full drive
    bool reached_;              // the reading was within band_c of the current target
};

#endif
