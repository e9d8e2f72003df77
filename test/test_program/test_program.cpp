#include <unity.h>

#include "Program.h"

#include <math.h>

// Expected values are hand arithmetic on the staircase definition (checked in
// Python): a cycle has W warming + (W - 1) cooling steps of hold_s, then rest_s.

static const uint32_t kMinute = 60000UL;

void setUp(void) {}
void tearDown(void) {}

static void assertState(ProgramPhase phase, uint32_t cycle, uint16_t step, float setpoint, ProgramState state)
{
    TEST_ASSERT_EQUAL(phase, state.phase);
    TEST_ASSERT_EQUAL_UINT32(cycle, state.cycle);
    TEST_ASSERT_EQUAL_UINT16(step, state.step);
    TEST_ASSERT_FLOAT_WITHIN(1e-4f, setpoint, state.setpoint_c);
    bool driving = phase == ProgramPhase::Warming || phase == ProgramPhase::Cooling;
    TEST_ASSERT_EQUAL(driving, state.driveEnabled);
}

// Figure 8: 16 -> 22 degC in 2 degC steps of 1 minute.
static TemperatureProgram figure8(uint16_t cycles, HoldStart holdStart = HoldStart::Timed)
{
    ProgramSettings settings;
    settings.start_c = 16.0f;
    settings.max_c = 22.0f;
    settings.cycles = cycles;
    settings.hold_start = holdStart;
    TemperatureProgram program;
    TEST_ASSERT_EQUAL(ProgramError::None, program.configure(settings));
    return program;
}

static void test_figure8_staircase(void)
{
    TemperatureProgram program = figure8(0);
    TEST_ASSERT_EQUAL_UINT16(4, program.warmingSteps());
    TEST_ASSERT_EQUAL_UINT16(7, program.stepsPerCycle());
    // 7 min of steps + 20 min rest = 1 620 000 ms.
    TEST_ASSERT_EQUAL_UINT32(1620000UL, program.cycleDurationMs());
    assertState(ProgramPhase::Warming, 0, 0, 16.0f, program.stateAt(0));
    assertState(ProgramPhase::Warming, 0, 0, 16.0f, program.stateAt(kMinute - 1));
    assertState(ProgramPhase::Warming, 0, 1, 18.0f, program.stateAt(kMinute));
    assertState(ProgramPhase::Warming, 0, 2, 20.0f, program.stateAt(2 * kMinute));
    assertState(ProgramPhase::Warming, 0, 3, 22.0f, program.stateAt(3 * kMinute + 30000));
    assertState(ProgramPhase::Cooling, 0, 4, 20.0f, program.stateAt(4 * kMinute));
    assertState(ProgramPhase::Cooling, 0, 5, 18.0f, program.stateAt(5 * kMinute));
    assertState(ProgramPhase::Cooling, 0, 6, 16.0f, program.stateAt(7 * kMinute - 1));
}

static void test_rest_and_repeat(void)
{
    TemperatureProgram program = figure8(0);
    assertState(ProgramPhase::Rest, 0, 7, 16.0f, program.stateAt(7 * kMinute));
    assertState(ProgramPhase::Rest, 0, 7, 16.0f, program.stateAt(1620000UL - 1));
    assertState(ProgramPhase::Warming, 1, 0, 16.0f, program.stateAt(1620000UL));
    assertState(ProgramPhase::Warming, 1, 1, 18.0f, program.stateAt(1620000UL + kMinute));
    TEST_ASSERT_EQUAL_UINT32(0, program.totalDurationMs());
}

static void test_done_after_cycles(void)
{
    // 2 cycles: 1 620 000 + 7 min (no final rest) = 2 040 000 ms.
    TemperatureProgram program = figure8(2);
    TEST_ASSERT_EQUAL_UINT32(2040000UL, program.totalDurationMs());
    assertState(ProgramPhase::Cooling, 1, 6, 16.0f, program.stateAt(2040000UL - 1));
    assertState(ProgramPhase::Done, 2, 7, 16.0f, program.stateAt(2040000UL));
    assertState(ProgramPhase::Done, 2, 7, 16.0f, program.stateAt(0xFFFFFFFFUL));
    TemperatureProgram once = figure8(1);
    assertState(ProgramPhase::Done, 1, 7, 16.0f, once.stateAt(7 * kMinute));
}

static void test_default_sequence(void)
{
    TemperatureProgram program;
    const ProgramSettings &settings = program.settings();
    TEST_ASSERT_FLOAT_WITHIN(0.0f, -10.0f, settings.start_c);
    TEST_ASSERT_FLOAT_WITHIN(0.0f, 45.0f, settings.max_c);
    TEST_ASSERT_FLOAT_WITHIN(0.0f, 2.0f, settings.step_c);
    TEST_ASSERT_EQUAL_UINT32(60, settings.hold_s);
    TEST_ASSERT_EQUAL_UINT32(1200, settings.rest_s);
    // -10, -8, ..., 44 is 28 steps, plus 45: 29 warming, 28 cooling, 57 total.
    TEST_ASSERT_EQUAL_UINT16(29, program.warmingSteps());
    TEST_ASSERT_EQUAL_UINT16(57, program.stepsPerCycle());
    // 57 * 60 000 + 1 200 000 = 4 620 000 ms.
    TEST_ASSERT_EQUAL_UINT32(4620000UL, program.cycleDurationMs());
    assertState(ProgramPhase::Warming, 0, 0, -10.0f, program.stateAt(0));
    assertState(ProgramPhase::Warming, 0, 1, -8.0f, program.stateAt(kMinute));
    assertState(ProgramPhase::Warming, 0, 27, 44.0f, program.stateAt(27 * kMinute));
    assertState(ProgramPhase::Warming, 0, 28, 45.0f, program.stateAt(28 * kMinute));
    assertState(ProgramPhase::Cooling, 0, 29, 44.0f, program.stateAt(29 * kMinute));
    assertState(ProgramPhase::Cooling, 0, 30, 42.0f, program.stateAt(30 * kMinute));
    assertState(ProgramPhase::Cooling, 0, 56, -10.0f, program.stateAt(56 * kMinute));
    assertState(ProgramPhase::Rest, 0, 57, -10.0f, program.stateAt(57 * kMinute));
}

static void test_span_not_multiple_of_step(void)
{
    ProgramSettings settings;
    settings.start_c = 0.0f;
    settings.max_c = 5.0f;
    TemperatureProgram program;
    TEST_ASSERT_EQUAL(ProgramError::None, program.configure(settings));
    // 0, 2, 4, 5 then 4, 2, 0.
    TEST_ASSERT_EQUAL_UINT16(4, program.warmingSteps());
    TEST_ASSERT_FLOAT_WITHIN(0.0f, 4.0f, program.setpointOfStep(2));
    TEST_ASSERT_FLOAT_WITHIN(0.0f, 5.0f, program.setpointOfStep(3));
    TEST_ASSERT_FLOAT_WITHIN(0.0f, 4.0f, program.setpointOfStep(4));
    TEST_ASSERT_FLOAT_WITHIN(0.0f, 0.0f, program.setpointOfStep(6));
    TEST_ASSERT_FLOAT_WITHIN(0.0f, 0.0f, program.setpointOfStep(7));
}

static void test_fractional_step_has_no_extra_top(void)
{
    // 55 / 0.1 = 550 intervals, 551 warming steps; float rounding of 55 / 0.1
    // must not add a 552nd step.
    ProgramSettings settings;
    settings.step_c = 0.1f;
    TemperatureProgram program;
    TEST_ASSERT_EQUAL(ProgramError::None, program.configure(settings));
    TEST_ASSERT_EQUAL_UINT16(551, program.warmingSteps());
    TEST_ASSERT_FLOAT_WITHIN(1e-3f, 44.9f, program.setpointOfStep(549));
    TEST_ASSERT_FLOAT_WITHIN(0.0f, 45.0f, program.setpointOfStep(550));
    // In float, (20.7 - 20.1) / 0.2 = 3.0000019: still 20.1, 20.3, 20.5, 20.7.
    settings.start_c = 20.1f;
    settings.max_c = 20.7f;
    settings.step_c = 0.2f;
    TEST_ASSERT_EQUAL(ProgramError::None, program.configure(settings));
    TEST_ASSERT_EQUAL_UINT16(4, program.warmingSteps());
    TEST_ASSERT_FLOAT_WITHIN(1e-4f, 20.5f, program.setpointOfStep(2));
}

static void test_times_beyond_16_and_31_bits(void)
{
    TemperatureProgram program;
    // 65 536 ms is in minute 1.
    assertState(ProgramPhase::Warming, 0, 1, -8.0f, program.stateAt(65536UL));
    // 3e9 = 649 * 4 620 000 + 1 620 000: step 27 -> 44 degC.
    assertState(ProgramPhase::Warming, 649, 27, 44.0f, program.stateAt(3000000000UL));
    // 2^31 = 464 * 4 620 000 + 3 803 648: past 3 420 000, so resting.
    assertState(ProgramPhase::Rest, 464, 57, -10.0f, program.stateAt(2147483648UL));
    // 2^31 + 1 800 000 = 465 * 4 620 000 + 983 648: step 16 -> 22 degC.
    assertState(ProgramPhase::Warming, 465, 16, 22.0f, program.stateAt(2149283648UL));
    // 2^32 - 1 = 929 * 4 620 000 + 2 987 295: step 49, mirror of step 7 -> 4 degC.
    assertState(ProgramPhase::Cooling, 929, 49, 4.0f, program.stateAt(0xFFFFFFFFUL));
}

static ProgramError validateWith(float start, float max, float step, uint32_t hold, uint32_t rest, uint16_t cycles)
{
    ProgramSettings settings;
    settings.start_c = start;
    settings.max_c = max;
    settings.step_c = step;
    settings.hold_s = hold;
    settings.rest_s = rest;
    settings.cycles = cycles;
    return TemperatureProgram::validate(settings);
}

static void test_validation_errors(void)
{
    TEST_ASSERT_EQUAL(ProgramError::None, validateWith(-10, 45, 2, 60, 1200, 0));
    TEST_ASSERT_EQUAL(ProgramError::StartOutOfRange, validateWith(-11, 45, 2, 60, 1200, 0));
    TEST_ASSERT_EQUAL(ProgramError::StartOutOfRange, validateWith(NAN, 45, 2, 60, 1200, 0));
    TEST_ASSERT_EQUAL(ProgramError::MaxOutOfRange, validateWith(-10, 45.5f, 2, 60, 1200, 0));
    TEST_ASSERT_EQUAL(ProgramError::StartNotBelowMax, validateWith(20, 20, 2, 60, 1200, 0));
    TEST_ASSERT_EQUAL(ProgramError::StartNotBelowMax, validateWith(30, 20, 2, 60, 1200, 0));
    TEST_ASSERT_EQUAL(ProgramError::StepNotPositive, validateWith(-10, 45, 0, 60, 1200, 0));
    TEST_ASSERT_EQUAL(ProgramError::StepNotPositive, validateWith(-10, 45, -2, 60, 1200, 0));
    TEST_ASSERT_EQUAL(ProgramError::StepNotPositive, validateWith(-10, 45, NAN, 60, 1200, 0));
    TEST_ASSERT_EQUAL(ProgramError::StepLargerThanSpan, validateWith(16, 22, 6.5f, 60, 1200, 0));
    TEST_ASSERT_EQUAL(ProgramError::None, validateWith(16, 22, 6, 60, 1200, 0));
    TEST_ASSERT_EQUAL(ProgramError::StepTooSmall, validateWith(-10, 45, 0.01f, 60, 1200, 0));
    TEST_ASSERT_EQUAL(ProgramError::HoldZero, validateWith(-10, 45, 2, 0, 1200, 0));
    TEST_ASSERT_EQUAL(ProgramError::None, validateWith(-10, 45, 2, 60, 0, 0));
}

static void test_validation_overflow(void)
{
    // 57 steps * 80 000 s = 4.56e9 ms > 2^32.
    TEST_ASSERT_EQUAL(ProgramError::CycleTooLong, validateWith(-10, 45, 2, 80000, 0, 0));
    // 3 420 000 ms active + 4 300 000 s rest > 2^32 ms.
    TEST_ASSERT_EQUAL(ProgramError::CycleTooLong, validateWith(-10, 45, 2, 60, 4300000, 0));
    // 929 * 4 620 000 + 3 420 000 = 4 295 400 000 > 2^32 - 1 = 4 294 967 295,
    // 928 * 4 620 000 + 3 420 000 = 4 290 780 000 fits.
    TEST_ASSERT_EQUAL(ProgramError::None, validateWith(-10, 45, 2, 60, 1200, 929));
    TEST_ASSERT_EQUAL(ProgramError::CycleTooLong, validateWith(-10, 45, 2, 60, 1200, 930));
}

static void test_rejected_settings_keep_current(void)
{
    TemperatureProgram program = figure8(0);
    ProgramSettings bad;
    bad.hold_s = 0;
    TEST_ASSERT_EQUAL(ProgramError::HoldZero, program.configure(bad));
    TEST_ASSERT_FLOAT_WITHIN(0.0f, 16.0f, program.settings().start_c);
    TEST_ASSERT_EQUAL_UINT16(4, program.warmingSteps());
}

static const uint32_t kTickMs = 250;

// Ticks of kTickMs with the face at inner_c; the state after the last one.
static ProgramState runFor(ProgramRun &run, uint32_t ms, float innerC)
{
    ProgramState state = {};
    for (uint32_t done = 0; done < ms; done += kTickMs)
        state = run.advance(kTickMs, innerC);
    return state;
}

static void test_timed_run_follows_the_clock(void)
{
    TemperatureProgram program = figure8(1);
    ProgramRun run(program);
    // The face far from every setpoint does not stop a timed program.
    assertState(ProgramPhase::Warming, 0, 0, 16.0f, run.start(30.0f));
    TEST_ASSERT_FALSE(run.waiting());
    assertState(ProgramPhase::Warming, 0, 1, 18.0f, runFor(run, kMinute, 30.0f));
    TEST_ASSERT_EQUAL_UINT32(kMinute, run.programMs());
    assertState(ProgramPhase::Done, 1, 7, 16.0f, runFor(run, 6 * kMinute, 30.0f));
    TEST_ASSERT_EQUAL_UINT32(7 * kMinute, run.programMs());
    // Done stays done.
    assertState(ProgramPhase::Done, 1, 7, 16.0f, runFor(run, kMinute, 30.0f));
    TEST_ASSERT_EQUAL_UINT32(7 * kMinute, run.programMs());
}

static void test_all_steps_wait_for_their_setpoint(void)
{
    TemperatureProgram program = figure8(1, HoldStart::AllStepsWait);
    ProgramRun run(program);
    // From 19 degC ambient, 16 degC is 3 degC away: the clock stays at 0.
    assertState(ProgramPhase::Warming, 0, 0, 16.0f, run.start(19.0f));
    TEST_ASSERT_TRUE(run.waiting());
    runFor(run, 10 * kMinute, 17.5f);
    TEST_ASSERT_TRUE(run.waiting());
    TEST_ASSERT_EQUAL_UINT32(0, run.programMs());
    // Within kReachedBandC (1 degC, inclusive) the hold starts.
    run.advance(kTickMs, 17.0f);
    TEST_ASSERT_FALSE(run.waiting());
    TEST_ASSERT_EQUAL_UINT32(kTickMs, run.programMs());
    // A whole hold at the setpoint, then step 1 waits at its start for 18 degC.
    assertState(ProgramPhase::Warming, 0, 1, 18.0f, runFor(run, kMinute, 16.2f));
    TEST_ASSERT_TRUE(run.waiting());
    TEST_ASSERT_EQUAL_UINT32(kMinute, run.programMs());
    runFor(run, kMinute, 16.99f);
    TEST_ASSERT_EQUAL_UINT32(kMinute, run.programMs());
    run.advance(kTickMs, 17.01f);
    TEST_ASSERT_FALSE(run.waiting());
    // A failed thermistor (NaN) never counts as reached.
    runFor(run, kMinute - kTickMs, 18.0f);
    TEST_ASSERT_EQUAL_UINT32(2 * kMinute, run.programMs());
    assertState(ProgramPhase::Warming, 0, 2, 20.0f, runFor(run, kMinute, NAN));
    TEST_ASSERT_TRUE(run.waiting());
    TEST_ASSERT_EQUAL_UINT32(2 * kMinute, run.programMs());
}

static void test_a_step_already_reached_does_not_wait(void)
{
    TemperatureProgram program = figure8(1, HoldStart::AllStepsWait);
    ProgramRun run(program);
    run.start(16.5f);
    TEST_ASSERT_FALSE(run.waiting());
    // A face that follows each setpoint: a step waits only for the tick whose
    // reading sees the new setpoint, and the program ends after 7 holds.
    for (uint16_t step = 0; step < 7; ++step)
        runFor(run, kMinute, program.setpointOfStep(step));
    TEST_ASSERT_EQUAL(ProgramPhase::Done, runFor(run, kTickMs, 16.0f).phase);
    TEST_ASSERT_EQUAL_UINT32(7 * kMinute, run.programMs());
}

static void test_first_step_of_each_cycle_waits(void)
{
    ProgramSettings settings;
    settings.start_c = 16.0f;
    settings.max_c = 20.0f;
    settings.rest_s = 120;
    settings.cycles = 2;
    settings.hold_start = HoldStart::FirstStepWaits;
    TemperatureProgram program;
    TEST_ASSERT_EQUAL(ProgramError::None, program.configure(settings));
    ProgramRun run(program);
    run.start(22.0f);
    runFor(run, kMinute, 22.0f);
    TEST_ASSERT_EQUAL_UINT32(0, run.programMs());
    run.advance(kTickMs, 16.8f);
    // Steps 1..4 and the rest run on the clock, the face wherever it is.
    assertState(ProgramPhase::Warming, 0, 1, 18.0f, runFor(run, kMinute, 16.8f));
    TEST_ASSERT_FALSE(run.waiting());
    // 5 steps and 2 min of rest: cycle 1's first step starts at 7 min and waits.
    assertState(ProgramPhase::Warming, 1, 0, 16.0f, runFor(run, 6 * kMinute, 25.0f));
    TEST_ASSERT_TRUE(run.waiting());
    TEST_ASSERT_EQUAL_UINT32(7 * kMinute, run.programMs());
    run.advance(kTickMs, 15.0f);
    TEST_ASSERT_FALSE(run.waiting());
}

static void test_a_long_tick_stops_at_a_waiting_step(void)
{
    TemperatureProgram program = figure8(1, HoldStart::AllStepsWait);
    ProgramRun run(program);
    run.start(16.0f);
    // 2.5 min in one call: the clock stops at step 1, whose setpoint is not reached.
    assertState(ProgramPhase::Warming, 0, 1, 18.0f, run.advance(150000UL, 16.0f));
    TEST_ASSERT_EQUAL_UINT32(kMinute, run.programMs());
    TEST_ASSERT_TRUE(run.waiting());
}

static void test_hold_start_validated(void)
{
    ProgramSettings settings;
    settings.hold_start = (HoldStart)3;
    TEST_ASSERT_EQUAL(ProgramError::HoldStartUnknown, TemperatureProgram::validate(settings));
    settings.hold_start = HoldStart::Timed;
    TEST_ASSERT_EQUAL(ProgramError::None, TemperatureProgram::validate(settings));
    TEST_ASSERT_EQUAL(HoldStart::Timed, ProgramSettings().hold_start);
}

int runUnityTests(void)
{
    UNITY_BEGIN();
    RUN_TEST(test_figure8_staircase);
    RUN_TEST(test_rest_and_repeat);
    RUN_TEST(test_done_after_cycles);
    RUN_TEST(test_default_sequence);
    RUN_TEST(test_span_not_multiple_of_step);
    RUN_TEST(test_fractional_step_has_no_extra_top);
    RUN_TEST(test_times_beyond_16_and_31_bits);
    RUN_TEST(test_validation_errors);
    RUN_TEST(test_validation_overflow);
    RUN_TEST(test_rejected_settings_keep_current);
    RUN_TEST(test_timed_run_follows_the_clock);
    RUN_TEST(test_all_steps_wait_for_their_setpoint);
    RUN_TEST(test_a_step_already_reached_does_not_wait);
    RUN_TEST(test_first_step_of_each_cycle_waits);
    RUN_TEST(test_a_long_tick_stops_at_a_waiting_step);
    RUN_TEST(test_hold_start_validated);
    return UNITY_END();
}
