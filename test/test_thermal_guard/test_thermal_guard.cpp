#include <unity.h>

#include <math.h>

#include "ThermalGuard.h"

// Defaults: band 1 degC, gain 1 degC within 90 s, wrong way 2 degC, hold
// error budget 120 degC s, inner -20..55 degC, outer -20..70 degC. A tick is
// 0.25 s (the chamber's control period), exact in binary floating point.

static const float TICK_S = 0.25f;
static const DriveCommand FULL_HEAT = {255, Direction::Heat};
static const DriveCommand FULL_COOL = {255, Direction::Cool};
static const DriveCommand HALF_HEAT = {128, Direction::Heat};
static const DriveCommand OFF = {0, Direction::Off};

static ThermalGuard guard;

void setUp(void)
{
    guard = ThermalGuard();
}

void tearDown(void) {}

// Ticks with fixed readings until a fault or `limit` ticks; returns the
// ticks run, the fault in `fault`.
static uint16_t ticksUntilFault(float target, float inner, DriveCommand drive, uint16_t limit, GuardFault &fault)
{
    for (uint16_t tick = 1; tick <= limit; ++tick) {
        fault = guard.update(target, inner, 20.0f, drive, TICK_S);
        if (fault != GuardFault::None) {
            return tick;
        }
    }
    fault = GuardFault::None;
    return limit;
}

static void test_defaults_are_valid(void)
{
    TEST_ASSERT_EQUAL(GuardError::None, ThermalGuard::validate(GuardSettings()));
}

static void test_validate_rejects(void)
{
    GuardSettings settings;
    settings.band_c = 0.0f;
    TEST_ASSERT_EQUAL(GuardError::CheckOutOfRange, ThermalGuard::validate(settings));
    settings = GuardSettings();
    settings.window_s = NAN;
    TEST_ASSERT_EQUAL(GuardError::CheckOutOfRange, ThermalGuard::validate(settings));
    settings.window_s = 601.0f;
    TEST_ASSERT_EQUAL(GuardError::CheckOutOfRange, ThermalGuard::validate(settings));
    settings = GuardSettings();
    settings.max_error_c_s = INFINITY;
    TEST_ASSERT_EQUAL(GuardError::CheckOutOfRange, ThermalGuard::validate(settings));
    settings = GuardSettings();
    settings.inner_max_c = 86.0f;
    TEST_ASSERT_EQUAL(GuardError::LimitOutOfRange, ThermalGuard::validate(settings));
    settings = GuardSettings();
    settings.outer_min_c = NAN;
    TEST_ASSERT_EQUAL(GuardError::LimitOutOfRange, ThermalGuard::validate(settings));
    settings = GuardSettings();
    settings.outer_min_c = 70.0f;
    TEST_ASSERT_EQUAL(GuardError::LimitsInverted, ThermalGuard::validate(settings));

    GuardSettings rejected;
    rejected.inner_max_c = 90.0f;
    TEST_ASSERT_EQUAL(GuardError::LimitOutOfRange, guard.configure(rejected));
    TEST_ASSERT_FLOAT_WITHIN(0.0f, 55.0f, guard.settings().inner_max_c);
}

static void test_limits_apply_without_a_target(void)
{
    TEST_ASSERT_EQUAL(GuardFault::InnerHot, guard.update(NAN, 55.5f, 20.0f, OFF, TICK_S));
    TEST_ASSERT_EQUAL(GuardFault::InnerCold, guard.update(NAN, -20.5f, 20.0f, OFF, TICK_S));
    TEST_ASSERT_EQUAL(GuardFault::OuterHot, guard.update(NAN, 20.0f, 70.5f, OFF, TICK_S));
    TEST_ASSERT_EQUAL(GuardFault::OuterCold, guard.update(NAN, 20.0f, -20.5f, OFF, TICK_S));
    TEST_ASSERT_EQUAL(GuardFault::None, guard.update(NAN, 55.0f, 70.0f, OFF, TICK_S));
    TEST_ASSERT_EQUAL(GuardFault::None, guard.update(NAN, NAN, NAN, OFF, TICK_S));
}

static void test_no_response_after_window(void)
{
    // The first full-drive tick starts the window; 90 s = 360 ticks later it trips.
    GuardFault fault;
    TEST_ASSERT_EQUAL_UINT16(361, ticksUntilFault(30.0f, 20.0f, FULL_HEAT, 1000, fault));
    TEST_ASSERT_EQUAL(GuardFault::NoResponse, fault);
    guard.reset();
    TEST_ASSERT_EQUAL_UINT16(361, ticksUntilFault(-10.0f, 20.0f, FULL_COOL, 1000, fault));
    TEST_ASSERT_EQUAL(GuardFault::NoResponse, fault);
}

static void test_gain_restarts_window(void)
{
    // 1 degC every 80 s towards the target: slow, but never 90 s without a gain.
    float inner = 0.0f;
    for (uint16_t tick = 0; tick < 2400; ++tick) {
        inner += 1.0f / 320.0f;
        TEST_ASSERT_EQUAL(GuardFault::None, guard.update(44.0f, inner, 20.0f, FULL_HEAT, TICK_S));
    }
}

static void test_new_target_restarts_window(void)
{
    GuardFault fault;
    TEST_ASSERT_EQUAL_UINT16(300, ticksUntilFault(-10.0f, -6.0f, FULL_COOL, 300, fault));
    TEST_ASSERT_EQUAL(GuardFault::None, fault);
    TEST_ASSERT_EQUAL_UINT16(300, ticksUntilFault(-8.0f, -6.0f, FULL_COOL, 300, fault));
    TEST_ASSERT_EQUAL(GuardFault::None, fault);
}

static void test_partial_drive_is_not_judged(void)
{
    GuardFault fault;
    TEST_ASSERT_EQUAL_UINT16(4000, ticksUntilFault(30.0f, 20.0f, HALF_HEAT, 4000, fault));
    TEST_ASSERT_EQUAL(GuardFault::None, fault);
}

static void test_wrong_way_heating_and_cooling(void)
{
    // Reversed leads: full heat, the face cools by 0.05 degC a tick.
    float inner = 20.0f;
    GuardFault fault = GuardFault::None;
    uint16_t tick = 0;
    while (fault == GuardFault::None && tick < 100) {
        fault = guard.update(40.0f, inner, 20.0f, FULL_HEAT, TICK_S);
        inner -= 0.05f;
        ++tick;
    }
    TEST_ASSERT_EQUAL(GuardFault::WrongWay, fault);
    // 2 degC below the closest reading (20) is 40 ticks of 0.05 after the first.
    TEST_ASSERT_INT_WITHIN(1, 41, tick);

    guard.reset();
    inner = 20.0f;
    fault = GuardFault::None;
    tick = 0;
    while (fault == GuardFault::None && tick < 100) {
        fault = guard.update(-10.0f, inner, 20.0f, FULL_COOL, TICK_S);
        inner += 0.05f;
        ++tick;
    }
    TEST_ASSERT_EQUAL(GuardFault::WrongWay, fault);
    TEST_ASSERT_INT_WITHIN(1, 41, tick);
}

static void test_small_retreat_is_tolerated(void)
{
    // A thermistor lagging a turn of the drive keeps moving for a moment.
    TEST_ASSERT_EQUAL(GuardFault::None, guard.update(40.0f, 30.0f, 20.0f, FULL_HEAT, TICK_S));
    TEST_ASSERT_EQUAL(GuardFault::None, guard.update(40.0f, 29.0f, 20.0f, FULL_HEAT, TICK_S));
    TEST_ASSERT_EQUAL(GuardFault::None, guard.update(40.0f, 28.1f, 20.0f, FULL_HEAT, TICK_S));
    TEST_ASSERT_EQUAL(GuardFault::WrongWay, guard.update(40.0f, 27.9f, 20.0f, FULL_HEAT, TICK_S));
}

static void test_hold_lost(void)
{
    TEST_ASSERT_EQUAL(GuardFault::None, guard.update(20.0f, 20.0f, 20.0f, OFF, TICK_S));
    // 2 degC off is 1 degC beyond the band: 120 degC s after 120 s = 480 ticks.
    GuardFault fault;
    TEST_ASSERT_EQUAL_UINT16(480, ticksUntilFault(20.0f, 22.0f, OFF, 1000, fault));
    TEST_ASSERT_EQUAL(GuardFault::HoldLost, fault);
}

static void test_within_band_never_trips(void)
{
    TEST_ASSERT_EQUAL(GuardFault::None, guard.update(20.0f, 20.0f, 20.0f, OFF, TICK_S));
    GuardFault fault;
    TEST_ASSERT_EQUAL_UINT16(4000, ticksUntilFault(20.0f, 20.9f, FULL_COOL, 4000, fault));
    TEST_ASSERT_EQUAL(GuardFault::None, fault);
}

static void test_hold_error_is_not_counted_before_the_target_is_reached(void)
{
    // Approaching from afar with gains: no hold budget is spent on the way.
    float inner = 0.0f;
    for (uint16_t tick = 0; tick < 1200; ++tick) {
        inner += 0.01f;
        TEST_ASSERT_EQUAL(GuardFault::None, guard.update(30.0f, inner, 20.0f, FULL_HEAT, TICK_S));
    }
}

int runUnityTests(void)
{
    UNITY_BEGIN();
    RUN_TEST(test_defaults_are_valid);
    RUN_TEST(test_validate_rejects);
    RUN_TEST(test_limits_apply_without_a_target);
    RUN_TEST(test_no_response_after_window);
    RUN_TEST(test_gain_restarts_window);
    RUN_TEST(test_new_target_restarts_window);
    RUN_TEST(test_partial_drive_is_not_judged);
    RUN_TEST(test_wrong_way_heating_and_cooling);
    RUN_TEST(test_small_retreat_is_tolerated);
    RUN_TEST(test_hold_lost);
    RUN_TEST(test_within_band_never_trips);
    RUN_TEST(test_hold_error_is_not_counted_before_the_target_is_reached);
    return UNITY_END();
}
