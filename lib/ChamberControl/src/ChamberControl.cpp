#include "ChamberControl.h"

#include <math.h>

const float ChamberController::kPaperProportionalGain = 350.0f;
const uint8_t ChamberController::kMaxPwm;

static const float kMaxOutput = (float)ChamberController::kMaxPwm;

static float clampOutput(float value)
{
    if (value > kMaxOutput)
        return kMaxOutput;
    if (value < -kMaxOutput)
        return -kMaxOutput;
    return value;
}

ChamberController::ChamberController(float proportionalGain, float integralGain)
    : proportionalGain_(proportionalGain), integralGain_(integralGain), integral_(0.0f), roundedError_(false)
{
}

void ChamberController::setIntegralGain(float gain)
{
    integralGain_ = gain;
    if (gain == 0.0f)
        integral_ = 0.0f;
}

DriveCommand ChamberController::update(float setpointCelsius, float measuredCelsius, float dtSeconds)
{
    DriveCommand off = {0, Direction::Off};
    float error = setpointCelsius - measuredCelsius;
    if (!isfinite(error))
        return off;
    if (roundedError_)
        error = roundf(error);

    float proportional = proportionalGain_ * error;
    if (integralGain_ != 0.0f) {
        float unsaturated = proportional + integral_;
        bool pushingFurtherIntoSaturation = (unsaturated >= kMaxOutput && error > 0.0f) ||
                                            (unsaturated <= -kMaxOutput && error < 0.0f);
        if (!pushingFurtherIntoSaturation)
            integral_ = clampOutput(integral_ + integralGain_ * error * dtSeconds);
    }

    float output = clampOutput(proportional + integral_);
    float magnitude = output < 0.0f ? -output : output;
    uint8_t pwm = (uint8_t)(magnitude + 0.5f);
    if (pwm == 0)
        return off;
    DriveCommand command = {pwm, output > 0.0f ? Direction::Heat : Direction::Cool};
    return command;
}

L298nOutputs l298nPins(const DriveCommand &command)
{
    L298nOutputs pins = {0, false, false};
    if (command.pwm == 0)
        return pins;
    switch (command.direction) {
    case Direction::Heat:
        pins.enaDuty = command.pwm;
        pins.in1High = true;
        break;
    case Direction::Cool:
        pins.enaDuty = command.pwm;
        pins.in2High = true;
        break;
    case Direction::Off: break;
    }
    return pins;
}
