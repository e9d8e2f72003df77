#include "Thermistor.h"

#include <math.h>

const uint16_t Thermistor::kAdcFullScale;
const uint16_t Thermistor::kOpenCircuitAdc;
const uint16_t Thermistor::kShortCircuitAdc;
const float Thermistor::kMinPlausibleCelsius = -55.0f;
const float Thermistor::kMaxPlausibleCelsius = 150.0f;

static const float kZeroCelsiusInKelvin = 273.15f;

static ThermistorReading fault(ThermistorStatus status)
{
    ThermistorReading reading = {NAN, status};
    return reading;
}

Thermistor::Thermistor(const ThermistorParams &params) : params_(params) {}

float Thermistor::resistanceOhms(uint16_t adc) const
{
    if (adc >= kAdcFullScale)
        return INFINITY;
    return params_.referenceOhms * (float)adc / (float)(kAdcFullScale - adc);
}

float Thermistor::celsiusFromOhms(float ohms) const
{
    float logRatio = logf(ohms / params_.nominalOhms);
    float inverseKelvin = logRatio / params_.betaKelvin + 1.0f / (params_.nominalCelsius + kZeroCelsiusInKelvin);
    return 1.0f / inverseKelvin - kZeroCelsiusInKelvin;
}

ThermistorReading Thermistor::read(uint16_t adc) const
{
    if (adc >= kOpenCircuitAdc)
        return fault(ThermistorStatus::Open);
    if (adc <= kShortCircuitAdc)
        return fault(ThermistorStatus::Short);
    float celsius = celsiusFromOhms(resistanceOhms(adc));
    // Written so that NaN (e.g. from bad params) also counts as out of range.
    if (!(celsius >= kMinPlausibleCelsius && celsius <= kMaxPlausibleCelsius))
        return fault(ThermistorStatus::OutOfRange);
    ThermistorReading reading = {celsius, ThermistorStatus::Ok};
    return reading;
}

ThermistorReading Thermistor::readAveraged(uint16_t firstAdc, uint16_t secondAdc) const
{
    ThermistorReading first = read(firstAdc);
    if (first.status != ThermistorStatus::Ok)
        return first;
    ThermistorReading second = read(secondAdc);
    if (second.status != ThermistorStatus::Ok)
        return second;
    ThermistorReading average = {0.5f * (first.celsius + second.celsius), ThermistorStatus::Ok};
    return average;
}
