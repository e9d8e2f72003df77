#include <unity.h>

#include "ChamberControl.h"

#include <math.h>

// Expected PWM values are Kp * e = 350 * e by hand, rounded, clamped to 255.

void setUp(void) {}
void tearDown(void) {}

static void assertDrive(uint8_t pwm, Direction direction, DriveCommand command)
{
    TEST_ASSERT_EQUAL_UINT8(pwm, command.pwm);
    TEST_ASSERT_EQUAL(direction, command.direction);
}

// Error e = setpoint - measured, measured fixed at 20 degC where it matters not.
static DriveCommand pOnly(float error)
{
    ChamberController controller;
    return controller.update(20.0f + error, 20.0f, 1.0f);
}

static void test_paper_gain_default(void)
{
    ChamberController controller;
    TEST_ASSERT_FLOAT_WITHIN(0.0f, 350.0f, controller.proportionalGain());
    TEST_ASSERT_FLOAT_WITHIN(0.0f, 0.0f, controller.integralGain());
}

static void test_saturation(void)
{
    assertDrive(255, Direction::Heat, pOnly(1.0f));   // 350 -> 255
    assertDrive(255, Direction::Cool, pOnly(-3.0f));  // -1050 -> 255 cool
    assertDrive(255, Direction::Heat, pOnly(0.75f));  // 262.5 -> 255
}

static void test_near_zero_error(void)
{
    assertDrive(35, Direction::Heat, pOnly(0.1f));
    assertDrive(175, Direction::Cool, pOnly(-0.5f));
    assertDrive(0, Direction::Off, pOnly(0.0f));
    assertDrive(0, Direction::Off, pOnly(0.001f));   // 0.35 rounds to 0
    assertDrive(1, Direction::Heat, pOnly(0.002f));  // 0.7 rounds to 1
}

static void test_large_errors_saturate_not_wrap(void)
{
    assertDrive(255, Direction::Heat, pOnly(100.0f));
    assertDrive(255, Direction::Cool, pOnly(-200.0f));
    // int16: 350 * 95 centidegrees = 33250 wraps to -32286 (would cool).
    assertDrive(255, Direction::Heat, pOnly(0.95f));
    assertDrive(255, Direction::Cool, pOnly(-0.95f));
    // int16: 350 * 94 degrees = 32900 wraps to -32636.
    assertDrive(255, Direction::Heat, pOnly(94.0f));
    // uint8 of 350 * 1 = 350 would be 94.
    assertDrive(255, Direction::Heat, pOnly(1.0f));
}

static void test_bad_temperature_turns_off(void)
{
    ChamberController controller;
    assertDrive(0, Direction::Off, controller.update(25.0f, NAN, 1.0f));
    assertDrive(0, Direction::Off, controller.update(NAN, 25.0f, 1.0f));
    assertDrive(0, Direction::Off, controller.update(25.0f, INFINITY, 1.0f));
    assertDrive(0, Direction::Off, controller.update(25.0f, -INFINITY, 1.0f));
}

static void test_pi_integrates(void)
{
    ChamberController controller(350.0f, 10.0f);
    DriveCommand command = {0, Direction::Off};
    // Each second adds Ki * e * dt = 10 * 0.1 * 1 = 1 PWM step.
    for (int i = 0; i < 10; ++i)
        command = controller.update(20.1f, 20.0f, 1.0f);
    TEST_ASSERT_FLOAT_WITHIN(0.01f, 10.0f, controller.integral());
    assertDrive(45, Direction::Heat, command);  // 35 + 10
    controller.reset();
    TEST_ASSERT_FLOAT_WITHIN(0.0f, 0.0f, controller.integral());
}

static void test_pi_no_windup_when_saturated(void)
{
    ChamberController controller(350.0f, 10.0f);
    for (int i = 0; i < 1000; ++i)
        assertDrive(255, Direction::Heat, controller.update(25.0f, 20.0f, 1.0f));
    TEST_ASSERT_FLOAT_WITHIN(0.0f, 0.0f, controller.integral());
    // Recovers on the first sample: -35 - 1 = 36 cool. A wound-up integral
    // (255) would still heat at 220.
    assertDrive(36, Direction::Cool, controller.update(20.0f, 20.1f, 1.0f));

    for (int i = 0; i < 1000; ++i)
        assertDrive(255, Direction::Cool, controller.update(15.0f, 20.0f, 1.0f));
    TEST_ASSERT_FLOAT_WITHIN(0.01f, -1.0f, controller.integral());
}

static void test_pi_stops_at_saturation(void)
{
    // Ki = 100, e = 0.5 (P = 175): I = 50 -> out 225; I = 100 -> out 275
    // (saturated); from then on the integral must stay at 100.
    ChamberController controller(350.0f, 100.0f);
    for (int i = 0; i < 50; ++i)
        controller.update(20.5f, 20.0f, 1.0f);
    TEST_ASSERT_FLOAT_WITHIN(0.01f, 100.0f, controller.integral());
}

static void test_pi_integral_clamped(void)
{
    // One step adds 1e6 * 0.1 = 1e5, clamped to 255.
    ChamberController controller(350.0f, 1.0e6f);
    controller.update(20.1f, 20.0f, 1.0f);
    TEST_ASSERT_FLOAT_WITHIN(0.0f, 255.0f, controller.integral());
    controller.update(25.0f, 25.1f, 1.0f);
    controller.update(25.0f, 25.1f, 1.0f);
    TEST_ASSERT_FLOAT_WITHIN(0.0f, -255.0f, controller.integral());
}

static void test_l298n_pin_numbers(void)
{
    // Paper Figure 6: ENA, IN1, IN2 on Mega pins 9, 7, 6.
    TEST_ASSERT_EQUAL_UINT8(9, kL298nEnaPin);
    TEST_ASSERT_EQUAL_UINT8(7, kL298nIn1Pin);
    TEST_ASSERT_EQUAL_UINT8(6, kL298nIn2Pin);
}

static void assertPins(uint8_t duty, bool in1, bool in2, L298nOutputs pins)
{
    TEST_ASSERT_EQUAL_UINT8(duty, pins.enaDuty);
    TEST_ASSERT_EQUAL(in1, pins.in1High);
    TEST_ASSERT_EQUAL(in2, pins.in2High);
}

static void test_l298n_mapping(void)
{
    DriveCommand heat = {200, Direction::Heat};
    DriveCommand cool = {100, Direction::Cool};
    DriveCommand off = {0, Direction::Off};
    DriveCommand offWithDuty = {50, Direction::Off};
    DriveCommand heatWithoutDuty = {0, Direction::Heat};
    assertPins(200, true, false, l298nPins(heat));
    assertPins(100, false, true, l298nPins(cool));
    assertPins(0, false, false, l298nPins(off));
    assertPins(0, false, false, l298nPins(offWithDuty));
    assertPins(0, false, false, l298nPins(heatWithoutDuty));
}

static DriveCommand rounded(float setpoint, float measured)
{
    ChamberController controller;
    controller.setRoundedError(true);
    return controller.update(setpoint, measured, 1.0f);
}

static void test_rounded_error_is_a_half_degree_dead_band(void)
{
    TEST_ASSERT_FALSE(ChamberController().roundedError());
    // |e| < 0.5 rounds to 0: off, where the float law would drive 35..171.
    assertDrive(0, Direction::Off, rounded(20.0f, 19.9f));
    assertDrive(0, Direction::Off, rounded(20.0f, 20.49f));
    assertDrive(0, Direction::Off, rounded(20.0f, 19.51f));
    // |e| >= 0.5 rounds away from zero to 1: 350 saturates at 255.
    assertDrive(255, Direction::Heat, rounded(20.0f, 19.5f));
    assertDrive(255, Direction::Cool, rounded(20.0f, 20.5f));
    assertDrive(255, Direction::Heat, rounded(-10.0f, -11.2f));
    // The sign is the error's on both sides of zero and of ambient: truncation
    // (int) would leave 18.0 - 18.9 = -0.9 off, rounding cools.
    assertDrive(255, Direction::Cool, rounded(18.0f, 18.9f));
    // A smaller gain shows the rounded error itself: 100 * round(1.4) = 100.
    ChamberController controller(100.0f);
    controller.setRoundedError(true);
    assertDrive(100, Direction::Heat, controller.update(21.4f, 20.0f, 1.0f));
    assertDrive(200, Direction::Cool, controller.update(20.0f, 21.6f, 1.0f));
    controller.setRoundedError(false);
    assertDrive(160, Direction::Cool, controller.update(20.0f, 21.6f, 1.0f));
}

int runUnityTests(void)
{
    UNITY_BEGIN();
    RUN_TEST(test_paper_gain_default);
    RUN_TEST(test_saturation);
    RUN_TEST(test_near_zero_error);
    RUN_TEST(test_large_errors_saturate_not_wrap);
    RUN_TEST(test_rounded_error_is_a_half_degree_dead_band);
    RUN_TEST(test_bad_temperature_turns_off);
    RUN_TEST(test_pi_integrates);
    RUN_TEST(test_pi_no_windup_when_saturated);
    RUN_TEST(test_pi_stops_at_saturation);
    RUN_TEST(test_pi_integral_clamped);
    RUN_TEST(test_l298n_pin_numbers);
    RUN_TEST(test_l298n_mapping);
    return UNITY_END();
}
