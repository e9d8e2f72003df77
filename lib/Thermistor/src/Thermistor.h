#ifndef THERMOTILT_THERMISTOR_H
#define THERMOTILT_THERMISTOR_H

#include <stdint.h>

// NTC thermistor read through a voltage divider by a 10-bit ADC:
//
//   VCC --[ R_ref 100 kOhm ]--+--[ NTC R_t ]-- GND
//                             |
//                          ADC pin   (ADC reference = VCC, so ratiometric)
//
// The AVR ADC returns adc = V_in * 1024 / V_ref (datasheet), so the divider
// ratio R_t / (R_ref + R_t) is adc / 1024 -- not adc / 1023 -- and
//   R_t = R_ref * adc / (1024 - adc).
// Ratiometric reading cancels the supply voltage. Mid-scale (512) means
// R_t = R_ref, i.e. 25 degC for the paper's 100 kOhm parts.
//
// Temperature from the beta equation (paper eq. 1):
//   1/T = ln(R_t / R0) / beta + 1/T0     (T, T0 in kelvin)
//
// Faults: a missing thermistor pulls the pin to VCC (adc near 1023), a
// shorted one to GND (adc near 0).
//   adc >= kOpenCircuitAdc  (1020: R_t >= 25.5 MOhm, below -62 degC) -> Open
//   adc <= kShortCircuitAdc (3:    R_t <= 294 Ohm,   above 259 degC)  -> Short
// Between those, a temperature outside kMinPlausibleCelsius ..
// kMaxPlausibleCelsius (-55..150 degC, the usual NTC rating) is OutOfRange.

struct ThermistorParams {
    float referenceOhms = 100000.0f;  // divider resistor from VCC to the pin
    float nominalOhms = 100000.0f;    // R0, thermistor resistance at T0
    float nominalCelsius = 25.0f;     // T0
    float betaKelvin = 3950.0f;       // beta
};

enum class ThermistorStatus : uint8_t { Ok = 0, Open = 1, Short = 2, OutOfRange = 3 };

struct ThermistorReading {
    float celsius;  // NaN unless status is Ok
    ThermistorStatus status;
};

class Thermistor {
public:
    static const uint16_t kAdcFullScale = 1024;
    static const uint16_t kOpenCircuitAdc = 1020;
    static const uint16_t kShortCircuitAdc = 3;
    static const float kMinPlausibleCelsius;
    static const float kMaxPlausibleCelsius;

    explicit Thermistor(const ThermistorParams &params = ThermistorParams());

    const ThermistorParams &params() const { return params_; }
    void setParams(const ThermistorParams &params) { params_ = params; }

    float resistanceOhms(uint16_t adc) const;
    float celsiusFromOhms(float ohms) const;

    ThermistorReading read(uint16_t adc) const;

    // The paper estimates each temperature as the average of two successive
    // measurements. Temperatures (not ADC codes) are averaged so that one
    // faulty sample cannot blend into a plausible value: any fault wins.
    ThermistorReading readAveraged(uint16_t firstAdc, uint16_t secondAdc) const;

private:
    ThermistorParams params_;
};

#endif
