#include "ThermalGuard.h"

#include <math.h>

const float ThermalGuard::kHardMinCelsius = -40.0f;
const float ThermalGuard::kHardMaxCelsius = 85.0f;

namespace {

// Beyond these a check no longer protects anything: a 10 degC band or gain
// is a fifth of the chamber's span, and ten minutes at full drive moves the
// face through all of it.
const float kMaxDistanceC = 10.0f;
const float kMaxWindowS = 600.0f;
const float kMaxErrorCS = 3600.0f;

bool inOpenClosed(float value, float maximum)
{
    return value > 0.0f && value <= maximum;
}

bool isHardLimit(float celsius)
{
    return celsius >= ThermalGuard::kHardMinCelsius && celsius <= ThermalGuard::kHardMaxCelsius;
}

}  // namespace

GuardError ThermalGuard::validate(const GuardSettings &settings)
{
    if (!inOpenClosed(settings.band_c, kMaxDistanceC) || !inOpenClosed(settings.gain_c, kMaxDistanceC) ||
        !inOpenClosed(settings.wrong_way_c, kMaxDistanceC) || !inOpenClosed(settings.window_s, kMaxWindowS) ||
        !inOpenClosed(settings.max_error_c_s, kMaxErrorCS)) {
        return GuardError::CheckOutOfRange;
    }
    if (!isHardLimit(settings.inner_min_c) || !isHardLimit(settings.inner_max_c) ||
        !isHardLimit(settings.outer_min_c) || !isHardLimit(settings.outer_max_c)) {
        return GuardError::LimitOutOfRange;
    }
    if (!(settings.inner_min_c < settings.inner_max_c) || !(settings.outer_min_c < settings.outer_max_c)) {
        return GuardError::LimitsInverted;
    }
    return GuardError::None;
}

ThermalGuard::ThermalGuard()
{
    reset();
}

GuardError ThermalGuard::configure(const GuardSettings &settings)
{
    GuardError error = validate(settings);
    if (error == GuardError::None) {
        settings_ = settings;
        reset();
    }
    return error;
}

void ThermalGuard::reset()
{
    lastTargetC_ = NAN;
    goalC_ = NAN;
    closestC_ = NAN;
    sinceGainS_ = 0.0f;
    holdErrorCS_ = 0.0f;
    approachDirection_ = 0;
    reached_ = false;
}

GuardFault ThermalGuard::limitFault(float innerC, float outerC) const
{
    if (innerC > settings_.inner_max_c)
        return GuardFault::InnerHot;
    if (innerC < settings_.inner_min_c)
        return GuardFault::InnerCold;
    if (outerC > settings_.outer_max_c)
        return GuardFault::OuterHot;
    if (outerC < settings_.outer_min_c)
        return GuardFault::OuterCold;
    return GuardFault::None;
}

void ThermalGuard::restartApproach(float innerC, int8_t direction)
{
    approachDirection_ = direction;
    goalC_ = innerC + (float)direction * settings_.gain_c;
    closestC_ = innerC;
    sinceGainS_ = 0.0f;
}

GuardFault ThermalGuard::update(float targetC, float innerC, float outerC, const DriveCommand &drive, float dtSeconds)
{
    GuardFault limit = limitFault(innerC, outerC);
    if (limit != GuardFault::None) {
        return limit;
    }
    if (isnan(targetC) || isnan(innerC)) {
        reset();
        return GuardFault::None;
    }
    if (targetC != lastTargetC_) {
        lastTargetC_ = targetC;
        reached_ = false;
        holdErrorCS_ = 0.0f;
        approachDirection_ = 0;
    }
    float error = targetC - innerC;
    float distance = fabsf(error);
    if (distance <= settings_.band_c) {
        reached_ = true;
        holdErrorCS_ = 0.0f;
        approachDirection_ = 0;
        return GuardFault::None;
    }
    if (reached_) {
        holdErrorCS_ += (distance - settings_.band_c) * dtSeconds;
        if (holdErrorCS_ >= settings_.max_error_c_s) {
            return GuardFault::HoldLost;
        }
    }

    int8_t needed = error > 0.0f ? 1 : -1;
    Direction towardsTarget = needed > 0 ? Direction::Heat : Direction::Cool;
    bool fullDrive = drive.pwm == ChamberController::kMaxPwm && drive.direction == towardsTarget;
    if (!fullDrive) {
        approachDirection_ = 0;
        return GuardFault::None;
    }
    if (approachDirection_ != needed) {
        restartApproach(innerC, needed);
        return GuardFault::None;
    }
    float towards = (float)needed;
    if (towards * (innerC - closestC_) > 0.0f) {
        closestC_ = innerC;
    }
    if (towards * (closestC_ - innerC) >= settings_.wrong_way_c) {
        return GuardFault::WrongWay;
    }
    if (towards * (innerC - goalC_) >= 0.0f) {
        restartApproach(innerC, needed);
        return GuardFault::None;
    }
    sinceGainS_ += dtSeconds;
    if (sinceGainS_ >= settings_.window_s) {
        return GuardFault::NoResponse;
    }
    return GuardFault::None;
}
