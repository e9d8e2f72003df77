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
// Rounded error (off by default) is a hypothesis about the paper's own code,
// not the paper's text: e rounded to whole degC before P = Kp * e, a
// +-0.5 degC dead band in which the drive is off and outside which it is full
// (350 * 1 > 255). It is the one candidate found that gives Figure 8's
// ~0.5 degC offset, with its sign flipping at ambient, in a chamber that
// still reaches -10 degC (docs/physics-model.md). Truncation instead of
// rounding gives a +-1 degC band and the wrong sign at 18 degC.
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

    explicit ChamberController(float proportionalGain = kPaperProportionalGain, float integralGain = 0.0f);

    void setProportionalGain(float gain) { proportionalGain_ = gain; }
    void setIntegralGain(float gain);
    void setRoundedError(bool rounded) { roundedError_ = rounded; }
    bool roundedError() const { return roundedError_; }
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
    bool roundedError_;
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
