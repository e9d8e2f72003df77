#include <unity.h>

#include "Thermistor.h"

// Expected values computed independently in Python (float64) from the beta
// equation with R0 = 100 kOhm, T0 = 298.15 K, beta = 3950 K, R_ref = 100 kOhm:
//   R(T) = R0 * exp(beta * (1/T - 1/T0)),  R_t(adc) = R_ref * adc / (1024 - adc)
//   0 degC -> 336206.04 Ohm     50 degC -> 35881.83 Ohm   -10 degC -> 582457.13 Ohm
//   45 degC -> 43481.37 Ohm     adc 300 -> 46.2392 degC   adc 700 -> 8.6165 degC
//   adc 1016 -> -54.83 degC     adc 1017 -> -56.44 degC   adc 21 -> 147.86 degC
//   adc 20 -> 150.11 degC
static const float kTolC = 0.01f;

void setUp(void) {}
void tearDown(void) {}

static const Thermistor thermistor;

static void test_defaults_match_paper(void)
{
    ThermistorParams params;
    TEST_ASSERT_FLOAT_WITHIN(0.0f, 100000.0f, params.referenceOhms);
    TEST_ASSERT_FLOAT_WITHIN(0.0f, 100000.0f, params.nominalOhms);
    TEST_ASSERT_FLOAT_WITHIN(0.0f, 25.0f, params.nominalCelsius);
    TEST_ASSERT_FLOAT_WITHIN(0.0f, 3950.0f, params.betaKelvin);
}

static void test_beta_at_nominal(void)
{
    TEST_ASSERT_FLOAT_WITHIN(kTolC, 25.0f, thermistor.celsiusFromOhms(100000.0f));
}

static void test_beta_at_other_temperatures(void)
{
    TEST_ASSERT_FLOAT_WITHIN(kTolC, 0.0f, thermistor.celsiusFromOhms(336206.04f));
    TEST_ASSERT_FLOAT_WITHIN(kTolC, 50.0f, thermistor.celsiusFromOhms(35881.83f));
    TEST_ASSERT_FLOAT_WITHIN(kTolC, -10.0f, thermistor.celsiusFromOhms(582457.13f));
    TEST_ASSERT_FLOAT_WITHIN(kTolC, 45.0f, thermistor.celsiusFromOhms(43481.37f));
}

static void test_custom_params(void)
{
    // 10 kOhm / beta 3435 part: at R = R0 the result is T0 whatever beta is,
    // and 10 kOhm * exp(3435 * (1/273.15 - 1/298.15)) = 28704.29 Ohm at 0 degC (Python).
    ThermistorParams params;
    params.nominalOhms = 10000.0f;
    params.betaKelvin = 3435.0f;
    Thermistor ntc10k(params);
    TEST_ASSERT_FLOAT_WITHIN(kTolC, 25.0f, ntc10k.celsiusFromOhms(10000.0f));
    TEST_ASSERT_FLOAT_WITHIN(kTolC, 0.0f, ntc10k.celsiusFromOhms(28704.29f));
}

static void test_divider_resistance(void)
{
    TEST_ASSERT_FLOAT_WITHIN(0.5f, 100000.0f, thermistor.resistanceOhms(512));
    TEST_ASSERT_FLOAT_WITHIN(0.5f, 41436.46f, thermistor.resistanceOhms(300));
    TEST_ASSERT_FLOAT_WITHIN(1.0f, 216049.38f, thermistor.resistanceOhms(700));
}

static void test_adc_to_celsius(void)
{
    ThermistorReading mid = thermistor.read(512);
    TEST_ASSERT_EQUAL(ThermistorStatus::Ok, mid.status);
    TEST_ASSERT_FLOAT_WITHIN(kTolC, 25.0f, mid.celsius);
    TEST_ASSERT_FLOAT_WITHIN(kTolC, 46.2392f, thermistor.read(300).celsius);
    TEST_ASSERT_FLOAT_WITHIN(kTolC, 8.6165f, thermistor.read(700).celsius);
}

static void test_open_circuit(void)
{
    TEST_ASSERT_EQUAL(ThermistorStatus::Open, thermistor.read(1023).status);
    TEST_ASSERT_EQUAL(ThermistorStatus::Open, thermistor.read(Thermistor::kOpenCircuitAdc).status);
    ThermistorReading open = thermistor.read(1023);
    TEST_ASSERT_TRUE(open.celsius != open.celsius);  // NaN
}

static void test_short_circuit(void)
{
    TEST_ASSERT_EQUAL(ThermistorStatus::Short, thermistor.read(0).status);
    TEST_ASSERT_EQUAL(ThermistorStatus::Short, thermistor.read(Thermistor::kShortCircuitAdc).status);
}

static void test_plausible_range(void)
{
    TEST_ASSERT_EQUAL(ThermistorStatus::Ok, thermistor.read(1016).status);
    TEST_ASSERT_FLOAT_WITHIN(0.02f, -54.83f, thermistor.read(1016).celsius);
    TEST_ASSERT_EQUAL(ThermistorStatus::OutOfRange, thermistor.read(1017).status);
    TEST_ASSERT_EQUAL(ThermistorStatus::OutOfRange, thermistor.read(1019).status);
    TEST_ASSERT_EQUAL(ThermistorStatus::Ok, thermistor.read(21).status);
    TEST_ASSERT_EQUAL(ThermistorStatus::OutOfRange, thermistor.read(20).status);
    TEST_ASSERT_EQUAL(ThermistorStatus::OutOfRange, thermistor.read(4).status);
}

static void test_average_of_two_readings(void)
{
    ThermistorReading same = thermistor.readAveraged(512, 512);
    TEST_ASSERT_EQUAL(ThermistorStatus::Ok, same.status);
    TEST_ASSERT_FLOAT_WITHIN(kTolC, 25.0f, same.celsius);
    // (46.2392 + 8.6165) / 2 = 27.4278; averaging the codes (500) would give 26.06.
    TEST_ASSERT_FLOAT_WITHIN(kTolC, 27.4278f, thermistor.readAveraged(300, 700).celsius);
    TEST_ASSERT_FLOAT_WITHIN(kTolC, 27.4278f, thermistor.readAveraged(700, 300).celsius);
}

static void test_average_reports_any_fault(void)
{
    TEST_ASSERT_EQUAL(ThermistorStatus::Open, thermistor.readAveraged(512, 1023).status);
    TEST_ASSERT_EQUAL(ThermistorStatus::Open, thermistor.readAveraged(1023, 512).status);
    TEST_ASSERT_EQUAL(ThermistorStatus::Short, thermistor.readAveraged(0, 512).status);
    TEST_ASSERT_EQUAL(ThermistorStatus::OutOfRange, thermistor.readAveraged(512, 1017).status);
}

int runUnityTests(void)
{
    UNITY_BEGIN();
    RUN_TEST(test_defaults_match_paper);
    RUN_TEST(test_beta_at_nominal);
    RUN_TEST(test_beta_at_other_temperatures);
    RUN_TEST(test_custom_params);
    RUN_TEST(test_divider_resistance);
    RUN_TEST(test_adc_to_celsius);
    RUN_TEST(test_open_circuit);
    RUN_TEST(test_short_circuit);
    RUN_TEST(test_plausible_range);
    RUN_TEST(test_average_of_two_readings);
    RUN_TEST(test_average_reports_any_fault);
    return UNITY_END();
}
