#ifndef THERMOTILT_CHAMBERCONTROL_H
#define THERMOTILT_CHAMBERCONTROL_H

#include <stdint.h>

// Peltier drive law of the paper (section 3.1, eq. 2): P = Kp * e with
// Kp = 350 and e = setpoint - measured in degC. Positive output heats the
// reference face, negative cools it; the magnitude goes to an 8-bit PWM and
// saturates at 255, which happens for |e| >= 255 / 350 = 0.73 degC.
//
// Ki > 0 adds an integral term (not in the paper) to remove the ~0.5 degC
// steady offset the paper reports. Anti-windup: the integral does not grow
// while the output is saturated in the direction of the error, and is
// clamped to +-255.
//
// All arithmetic is in float: in 16-bit int, 350 * error in centidegrees
// wraps already at 0.94 degC.

enum class Direction : uint8_t { Off = 0, Heat = 1, Cool = 2 };

struct DriveCommand {
    uint8_t pwm;
    Direction direction;
};

class ChamberController {
public:
    static const float kPaperProportionalGain;
    static const uint8_t kMaxPwm = 255;

    explicit ChamberController(float proportionalGain = kPaperProportionalGain,
                               float integralGain = 0.0f);

    void setProportionalGain(float gain) { proportionalGain_ = gain; }
    void setIntegralGain(float gain);
    float proportionalGain() const { return proportionalGain_; }
    float integralGain() const { return integralGain_; }

    // PWM units (-255..255). reset() clears it, e.g. when the program rests.
    float integral() const { return integral_; }
    void reset() { integral_ = 0.0f; }

    // A NaN or infinite temperature (failed sensor) gives Off and leaves the
    // integral untouched.
    DriveCommand update(float setpointCelsius, float measuredCelsius, float dtSeconds);

private:
    float proportionalGain_;
    float integralGain_;
    float integral_;
};

// L298N wiring on the Mega (paper Figure 6): ENA takes the PWM, IN1/IN2 set
// the current direction. Which direction heats the reference face depends on
// how the Peltier leads are connected; Heat below assumes the wiring in the
// README, and swapping the leads swaps heating and cooling.
const uint8_t kL298nEnaPin = 9;
const uint8_t kL298nIn1Pin = 7;
const uint8_t kL298nIn2Pin = 6;

struct L298nOutputs {
    uint8_t enaDuty;
    bool in1High;
    bool in2High;
};

// Heat: IN1 high, IN2 low. Cool: IN1 low, IN2 high. Off: both low, duty 0
// (both low with ENA low lets the Peltier current decay freely).
L298nOutputs l298nPins(const DriveCommand &command);

#endif
