#include <math.h>
#include <unity.h>

#include "Compensation.h"

// Expected numbers below come from a Python (double precision) evaluation of
// the paper's equation (3) with the Table 2/3 coefficients; none are copied
// from this code's output. The coefficient block has its own program,
// test_coefficient_block: together they would not fit a Nano's 2 KB.

static Coefficients coefficients;

void setUp(void)
{
    loadDefaultCoefficients(coefficients);
}

void tearDown(void) {}

static const AxisSurface& surface(CompSet set, uint8_t axis)
{
    return coefficients.forTrend(set).axis[axis];
}

static float absolute(float value)
{
    return value < 0.0f ? -value : value;
}

static void test_surface_values(void)
{
    // Python: 571.5 - 20.23*9 + 1.569e-3*-2653 - 0.1044*81 ... = 378.5117
    TEST_ASSERT_FLOAT_WITHIN(0.01f, 378.5117f, surfaceCorrection(surface(CompSet::Warming, 0), 9.0f, -2653.0f));
    TEST_ASSERT_FLOAT_WITHIN(0.01f, -637.0686f, surfaceCorrection(surface(CompSet::Warming, 0), 48.0f, -1699.0f));
}

static void test_surface_large_accel(void)
{
    // a = +-16000 LSB (~1 g) makes a^2 ~ 2.6e8; Python double results.
    TEST_ASSERT_FLOAT_WITHIN(0.01f, -573.4755f, surfaceCorrection(surface(CompSet::Warming, 0), 45.0f, 16000.0f));
    TEST_ASSERT_FLOAT_WITHIN(0.01f, 356.9856f, surfaceCorrection(surface(CompSet::Warming, 1), -10.0f, -16000.0f));
    TEST_ASSERT_FLOAT_WITHIN(0.01f, -588.1491f, surfaceCorrection(surface(CompSet::Cooling, 0), 45.0f, 16000.0f));
}

// Compensated spread between two field-test endpoints.
static float compensatedSpread(CompSet set, uint8_t axis, float t1, float a1, float t2, float a2)
{
    const AxisSurface& s = surface(set, axis);
    return absolute(compensate(s, t1, a1) - compensate(s, t2, a2));
}

static void test_sign_cooling_field(void)
{
    // Section 4.3, 26 -> 16 degC read in time order: X -1831 at 26, -1596 at
    // 16 (spread 235). Python, raw - f: -1808.43 and -1818.32, spread 9.9;
    // raw + f would give -1853.57 and -1373.68, spread 480.
    const AxisSurface& x = surface(CompSet::Cooling, 0);
    TEST_ASSERT_FLOAT_WITHIN(0.05f, -1808.4279f, compensate(x, 26.0f, -1831.0f));
    TEST_ASSERT_FLOAT_WITHIN(0.05f, -1818.3245f, compensate(x, 16.0f, -1596.0f));
    TEST_ASSERT_LESS_THAN(23, (long)compensatedSpread(CompSet::Cooling, 0, 26.0f, -1831.0f, 16.0f, -1596.0f));
    float plusSpread = absolute((-1831.0f + surfaceCorrection(x, 26.0f, -1831.0f)) -
                                (-1596.0f + surfaceCorrection(x, 16.0f, -1596.0f)));
    TEST_ASSERT_GREATER_THAN(235, (long)plusSpread);
    // Y -424 at 26, -286 at 16 (spread 138): Python spread 3.7.
    TEST_ASSERT_LESS_THAN(13, (long)compensatedSpread(CompSet::Cooling, 1, 26.0f, -424.0f, 16.0f, -286.0f));
}

static void test_sign_warming_field(void)
{
    // Section 4.3, 9 -> 48 degC, paired as the cooling test implies (raw falls
    // as temperature rises): X -1699 at 9, -2653 at 48 (spread 954). Python,
    // raw - f: -2078.39 and -2017.64, spread 60.7 (6.4 %).
    const AxisSurface& x = surface(CompSet::Warming, 0);
    TEST_ASSERT_FLOAT_WITHIN(0.05f, -2078.3867f, compensate(x, 9.0f, -1699.0f));
    TEST_ASSERT_FLOAT_WITHIN(0.05f, -2017.6370f, compensate(x, 48.0f, -2653.0f));
    TEST_ASSERT_LESS_THAN(95, (long)compensatedSpread(CompSet::Warming, 0, 9.0f, -1699.0f, 48.0f, -2653.0f));
    // Y -431 at 9, -937 at 48 (spread 506): Python spread 40.0 (7.9 %).
    TEST_ASSERT_LESS_THAN(50, (long)compensatedSpread(CompSet::Warming, 1, 9.0f, -431.0f, 48.0f, -937.0f));
}

static void test_zero_at_reference(void)
{
    // Residuals are taken against 25 degC (section 3.3). Python f(25, 0):
    // X warm 0.50, Y warm 3.17, X cool 1.29, Y cool -3.02: all within 5 LSB.
    for (uint8_t s = 0; s < COMP_SET_COUNT; ++s) {
        for (uint8_t axis = 0; axis < 2; ++axis) {
            TEST_ASSERT_FLOAT_WITHIN(5.0f, 0.0f, surfaceCorrection(surface((CompSet)s, axis), 25.0f, 0.0f));
        }
    }
}

static void test_drift_span(void)
{
    // Section 4.1: drift over -10..45 degC is about 1300 LSB on X and 850 on
    // Y, read off a figure. Python f(-10,0) - f(45,0): X 1313.6 / 1323.0,
    // Y 773.4 / 768.6 (warming / cooling). Tolerance: 50 LSB on X, 100 on Y.
    for (uint8_t s = 0; s < COMP_SET_COUNT; ++s) {
        const AxisSurface& x = surface((CompSet)s, 0);
        const AxisSurface& y = surface((CompSet)s, 1);
        TEST_ASSERT_FLOAT_WITHIN(50.0f, 1300.0f,
                                 surfaceCorrection(x, -10.0f, 0.0f) - surfaceCorrection(x, 45.0f, 0.0f));
        TEST_ASSERT_FLOAT_WITHIN(100.0f, 850.0f,
                                 surfaceCorrection(y, -10.0f, 0.0f) - surfaceCorrection(y, 45.0f, 0.0f));
    }
}

static void test_z_uncorrected(void)
{
    TEST_ASSERT_FLOAT_WITHIN(0.001f, 16393.0f, compensate(surface(CompSet::Warming, 2), 40.0f, 16393.0f));
    TEST_ASSERT_FLOAT_WITHIN(0.001f, -16393.0f, compensate(surface(CompSet::Cooling, 2), -5.0f, -16393.0f));
}

static float eighths(int16_t n)
{
    return (float)n / 8.0f;
}

static void test_trend_ramps(void)
{
    TrendDetector trend;
    TEST_ASSERT(trend.current() == CompSet::Warming);
    uint8_t switches = 0;
    CompSet last = CompSet::Warming;
    int16_t firstCoolingAt = 0;
    int16_t firstWarmingAt = 0;
    // 10 -> 40 -> 10 -> 20 degC in 1/8 degC steps.
    int16_t n = 80;
    int16_t step = 1;
    for (uint16_t i = 0; i < 560; ++i) {
        CompSet now = trend.update(eighths(n));
        if (now != last) {
            ++switches;
            if (now == CompSet::Cooling) {
                firstCoolingAt = n;
            } else {
                firstWarmingAt = n;
            }
            last = now;
        }
        if (n == 320) {
            step = -1;
        } else if (n == 80 && step < 0) {
            step = 1;
        }
        n = (int16_t)(n + step);
    }
    TEST_ASSERT_EQUAL(2, switches);
    TEST_ASSERT_EQUAL(315, firstCoolingAt);  // 40 - 0.625 = 39.375 degC
    TEST_ASSERT_EQUAL(85, firstWarmingAt);   // 10 + 0.625 = 10.625 degC
}

static void test_trend_plateau(void)
{
    // +-0.25 degC of noise in 1/8 degC steps around 30 degC, from a pseudo
    // random sequence (Numerical Recipes LCG).
    for (uint8_t s = 0; s < COMP_SET_COUNT; ++s) {
        TrendDetector trend(0.5f, (CompSet)s);
        uint32_t seed = 12345u;
        for (uint16_t i = 0; i < 500; ++i) {
            seed = seed * 1664525u + 1013904223u;
            int16_t noise = (int16_t)((seed >> 24) % 5u) - 2;
            TEST_ASSERT(trend.update(eighths((int16_t)(240 + noise))) == (CompSet)s);
        }
    }
}

static void test_trend_threshold(void)
{
    TrendDetector trend;
    trend.update(30.0f);
    TEST_ASSERT(trend.update(29.5f) == CompSet::Warming);    // 0.5 below: not more than
    TEST_ASSERT(trend.update(29.375f) == CompSet::Cooling);  // 0.625 below
    TEST_ASSERT(trend.update(29.875f) == CompSet::Cooling);  // 0.5 above the new minimum
    TEST_ASSERT(trend.update(30.0f) == CompSet::Warming);

    TrendDetector wide(1.0f);
    wide.update(20.0f);
    TEST_ASSERT(wide.update(19.0f) == CompSet::Warming);
    TEST_ASSERT(wide.update(18.875f) == CompSet::Cooling);
}

// The frame limit, 9.99e5 LSB: 1e6 (nine characters at one decimal in the
// longest IMU line, Compensation.h) less 0.1 %.
static const float FRAME_LIMIT_LSB = 9.99e5f;

static const float INT16_SPAN_LSB = 32768.0f;

static AxisSurface constantSurface(float p00, float p01)
{
    AxisSurface surface = {{p00, 0.0f, p01, 0.0f, 0.0f, 0.0f}};
    return surface;
}

static void test_default_surfaces_fit_the_frame(void)
{
    for (uint8_t s = 0; s < COMP_SET_COUNT; ++s) {
        for (uint8_t axis = 0; axis < COMP_AXIS_COUNT; ++axis) {
            TEST_ASSERT(surfaceOutputFitsFrame(surface((CompSet)s, axis)));
        }
    }
}

static void test_output_limit_includes_the_raw_reading(void)
{
    // raw - p00 is largest at raw = -32768 (or 32767 for a negative p00); all
    // values here are integers below 2^24, exact in a float.
    TEST_ASSERT(surfaceOutputFitsFrame(constantSurface(FRAME_LIMIT_LSB - INT16_SPAN_LSB - 16.0f, 0.0f)));
    TEST_ASSERT_FALSE(surfaceOutputFitsFrame(constantSurface(FRAME_LIMIT_LSB - INT16_SPAN_LSB + 16.0f, 0.0f)));
    TEST_ASSERT(surfaceOutputFitsFrame(constantSurface(-(FRAME_LIMIT_LSB - INT16_SPAN_LSB - 16.0f), 0.0f)));
    TEST_ASSERT_FALSE(surfaceOutputFitsFrame(constantSurface(-(FRAME_LIMIT_LSB - INT16_SPAN_LSB + 16.0f), 0.0f)));
    // p01 = 1 removes the raw reading: the output is -p00 everywhere.
    TEST_ASSERT(surfaceOutputFitsFrame(constantSurface(9.98e5f, 1.0f)));
    TEST_ASSERT_FALSE(surfaceOutputFitsFrame(constantSurface(1.0e6f, 1.0f)));
}

// raw - f = peak * (1 - ((T - 22.5) / 62.5)^2): zero at -40 and 85 degC, so
// every corner is zero; the peak sits at 22.5 degC along both a-edges.
static AxisSurface edgePeak(float peak)
{
    float curvature = peak / (62.5f * 62.5f);
    AxisSurface surface = {{-peak + curvature * 22.5f * 22.5f, -45.0f * curvature, 1.0f, curvature, 0.0f, 0.0f}};
    return surface;
}

// raw - f = peak - (peak / 2) ((T - 22.5) / 62.5)^2 - (peak / 2) (a / 32768)^2:
// zero at the corners, peak / 2 at every edge vertex, the peak only inside.
static AxisSurface insidePeak(float peak)
{
    float temperatureCurvature = peak / (2.0f * 62.5f * 62.5f);
    float accelCurvature = peak / (2.0f * INT16_SPAN_LSB * INT16_SPAN_LSB);
    AxisSurface surface = {{-peak + temperatureCurvature * 22.5f * 22.5f, -45.0f * temperatureCurvature, 1.0f,
                            temperatureCurvature, 0.0f, accelCurvature}};
    return surface;
}

static void test_output_peaks_between_the_corners_are_found(void)
{
    TEST_ASSERT_FLOAT_WITHIN(1.0f, 1.2e6f, compensate(edgePeak(1.2e6f), 22.5f, 32767.0f));
    TEST_ASSERT_FLOAT_WITHIN(1.0f, 0.0f, compensate(edgePeak(1.2e6f), 85.0f, 32767.0f));
    TEST_ASSERT_FALSE(surfaceOutputFitsFrame(edgePeak(1.2e6f)));
    TEST_ASSERT(surfaceOutputFitsFrame(edgePeak(9.9e5f)));

    TEST_ASSERT_FLOAT_WITHIN(1.0f, 1.5e6f, compensate(insidePeak(1.5e6f), 22.5f, 0.0f));
    TEST_ASSERT_FLOAT_WITHIN(1.0f, 7.5e5f, compensate(insidePeak(1.5e6f), 22.5f, -32768.0f));
    TEST_ASSERT_FLOAT_WITHIN(1.0f, 7.5e5f, compensate(insidePeak(1.5e6f), 85.0f, 0.0f));
    TEST_ASSERT_FALSE(surfaceOutputFitsFrame(insidePeak(1.5e6f)));
    TEST_ASSERT(surfaceOutputFitsFrame(insidePeak(9.9e5f)));
}

static void test_non_finite_outputs_do_not_fit(void)
{
    for (uint8_t k = 0; k < COMP_COEFFICIENT_COUNT; ++k) {
        AxisSurface surface = constantSurface(0.0f, 0.0f);
        surface.p[k] = NAN;
        TEST_ASSERT_FALSE(surfaceOutputFitsFrame(surface));
        surface.p[k] = -INFINITY;
        TEST_ASSERT_FALSE(surfaceOutputFitsFrame(surface));
    }
    // Finite, but p02 a^2 overflows a float (3e38 * 32768^2).
    AxisSurface overflowing = constantSurface(0.0f, 0.0f);
    overflowing.p[P02] = 3e38f;
    TEST_ASSERT_FALSE(surfaceOutputFitsFrame(overflowing));
}

static void test_blend_is_undecided_until_the_temperature_moves(void)
{
    // Halfway at power-up; half the transition either way settles the set.
    SetBlend falling;
    TEST_ASSERT_FLOAT_WITHIN(0.0f, 0.5f, falling.update(20.0f));
    TEST_ASSERT_FLOAT_WITHIN(1e-6f, 0.25f, falling.update(20.0f - 0.25f * COMP_SET_TRANSITION_C));
    TEST_ASSERT_FLOAT_WITHIN(0.0f, 0.0f, falling.update(20.0f - 0.5f * COMP_SET_TRANSITION_C));
    SetBlend rising;
    TEST_ASSERT_FLOAT_WITHIN(0.0f, 0.5f, rising.update(20.0f));
    TEST_ASSERT_FLOAT_WITHIN(0.0f, 1.0f, rising.update(20.0f + 0.5f * COMP_SET_TRANSITION_C));
}

static void test_blend_crosses_over_the_transition(void)
{
    // Up to 30 degC (wholly warming), down 0.75 (half of 1.5) and 0.75 more
    // (wholly cooling), further down (held at 0), then up 0.375 (a quarter).
    SetBlend blend;
    TEST_ASSERT_FLOAT_WITHIN(0.0f, COMP_SET_POWER_UP_SHARE, blend.update(20.0f));
    TEST_ASSERT_FLOAT_WITHIN(0.0f, 1.0f, blend.update(30.0f));
    TEST_ASSERT_FLOAT_WITHIN(0.0f, 0.5f, blend.update(29.25f));
    TEST_ASSERT_FLOAT_WITHIN(0.0f, 0.0f, blend.update(28.5f));
    TEST_ASSERT_FLOAT_WITHIN(0.0f, 0.0f, blend.update(25.0f));
    TEST_ASSERT_FLOAT_WITHIN(0.0f, 0.25f, blend.update(25.375f));
    TEST_ASSERT_FLOAT_WITHIN(0.0f, 0.25f, blend.warmingShare());
}

static void test_blend_plateau_noise_moves_it_in_proportion(void)
{
    // test_trend_plateau's +-0.25 degC of 1/8 degC noise about 30 degC after
    // a rise: the share never leaves 1 - 0.5 / 1.5 (the noise's full span
    // over the transition), so the compensation blends, it does not chatter
    // between the sets' surfaces.
    SetBlend blend;
    blend.update(25.0f);
    blend.update(30.0f);
    uint32_t seed = 12345u;
    float lowest = 1.0f;
    for (uint16_t i = 0; i < 500; ++i) {
        seed = seed * 1664525u + 1013904223u;
        int16_t noise = (int16_t)((seed >> 24) % 5u) - 2;
        float share = blend.update(eighths((int16_t)(240 + noise)));
        lowest = share < lowest ? share : lowest;
    }
    TEST_ASSERT(lowest >= 1.0f - 0.5f / COMP_SET_TRANSITION_C - 1e-6f);
}

static void test_blended_compensation_is_each_set_at_the_ends(void)
{
    Coefficients c;
    loadDefaultCoefficients(c);
    const AxisSurface& warming = c.set[0].axis[0];
    const AxisSurface& cooling = c.set[1].axis[0];
    const float t = 38.0f;
    const float raw = -1900.0f;
    TEST_ASSERT_FLOAT_WITHIN(0.0f, compensate(warming, t, raw), compensateBlended(warming, cooling, 1.0f, t, raw));
    TEST_ASSERT_FLOAT_WITHIN(0.0f, compensate(cooling, t, raw), compensateBlended(warming, cooling, 0.0f, t, raw));
    float half = 0.5f * (compensate(warming, t, raw) + compensate(cooling, t, raw));
    TEST_ASSERT_FLOAT_WITHIN(0.01f, half, compensateBlended(warming, cooling, 0.5f, t, raw));
}

int runUnityTests(void)
{
    UNITY_BEGIN();
    RUN_TEST(test_surface_values);
    RUN_TEST(test_surface_large_accel);
    RUN_TEST(test_sign_cooling_field);
    RUN_TEST(test_sign_warming_field);
    RUN_TEST(test_zero_at_reference);
    RUN_TEST(test_drift_span);
    RUN_TEST(test_z_uncorrected);
    RUN_TEST(test_trend_ramps);
    RUN_TEST(test_trend_plateau);
    RUN_TEST(test_trend_threshold);
    RUN_TEST(test_blend_is_undecided_until_the_temperature_moves);
    RUN_TEST(test_blend_crosses_over_the_transition);
    RUN_TEST(test_blend_plateau_noise_moves_it_in_proportion);
    RUN_TEST(test_blended_compensation_is_each_set_at_the_ends);
    RUN_TEST(test_default_surfaces_fit_the_frame);
    RUN_TEST(test_output_limit_includes_the_raw_reading);
    RUN_TEST(test_output_peaks_between_the_corners_are_found);
    RUN_TEST(test_non_finite_outputs_do_not_fit);
    return UNITY_END();
}
