#include <unity.h>

#include <string.h>

#include "ResetCause.h"

#include <Protocol.h>

// The MCUSR bits as the ATmega328P and ATmega2560 datasheets number them.
static const uint8_t PORF = 1 << 0;
static const uint8_t EXTRF = 1 << 1;
static const uint8_t BORF = 1 << 2;
static const uint8_t WDRF = 1 << 3;

void setUp(void) {}
void tearDown(void) {}

static void test_flags_match_the_datasheets(void)
{
    TEST_ASSERT_EQUAL_UINT8(PORF, ResetCause::POWER_ON_FLAG);
    TEST_ASSERT_EQUAL_UINT8(EXTRF, ResetCause::EXTERNAL_FLAG);
    TEST_ASSERT_EQUAL_UINT8(BORF, ResetCause::BROWNOUT_FLAG);
    TEST_ASSERT_EQUAL_UINT8(WDRF, ResetCause::WATCHDOG_FLAG);
}

static void test_each_flag_alone(void)
{
    TEST_ASSERT_EQUAL_STRING("POWER_ON", ResetCause::name(PORF, false));
    TEST_ASSERT_EQUAL_STRING("EXTERNAL", ResetCause::name(EXTRF, false));
    TEST_ASSERT_EQUAL_STRING("BROWNOUT", ResetCause::name(BORF, false));
    TEST_ASSERT_EQUAL_STRING("WATCHDOG", ResetCause::name(WDRF, false));
    TEST_ASSERT_EQUAL_STRING("UNKNOWN", ResetCause::name(0, false));
}

// Several latched flags (causes close together): the order VER has always used.
static void test_watchdog_then_brownout_then_external_then_power_on(void)
{
    TEST_ASSERT_EQUAL_STRING("WATCHDOG", ResetCause::name(WDRF | BORF | EXTRF | PORF, false));
    TEST_ASSERT_EQUAL_STRING("BROWNOUT", ResetCause::name(BORF | EXTRF | PORF, false));
    TEST_ASSERT_EQUAL_STRING("EXTERNAL", ResetCause::name(EXTRF | PORF, false));
}

static void test_a_marked_watchdog_reset_was_commanded(void)
{
    TEST_ASSERT_TRUE(ResetCause::wasCommanded(WDRF, true));
    TEST_ASSERT_EQUAL_STRING("COMMANDED", ResetCause::name(WDRF, true));
    TEST_ASSERT_FALSE(ResetCause::wasAbnormal(WDRF, true));
}

static void test_an_unmarked_watchdog_reset_is_a_fault(void)
{
    TEST_ASSERT_FALSE(ResetCause::wasCommanded(WDRF, false));
    TEST_ASSERT_TRUE(ResetCause::wasAbnormal(WDRF, false));
    TEST_ASSERT_TRUE(ResetCause::wasAbnormal(BORF, false));
    TEST_ASSERT_FALSE(ResetCause::wasAbnormal(EXTRF, false));
    TEST_ASSERT_FALSE(ResetCause::wasAbnormal(PORF, false));
    TEST_ASSERT_FALSE(ResetCause::wasAbnormal(0, false));
}

// Optiboot clears MCUSR before the sketch runs; the marker still tells.
static void test_a_marked_reset_without_flags_was_commanded(void)
{
    TEST_ASSERT_EQUAL_STRING("COMMANDED", ResetCause::name(0, true));
    TEST_ASSERT_FALSE(ResetCause::wasAbnormal(0, true));
}

// Power, the reset pin or a brown-out in the milliseconds before the
// watchdog fired: that is what reset the board, whatever the marker says.
static void test_another_cause_overrides_the_marker(void)
{
    TEST_ASSERT_EQUAL_STRING("POWER_ON", ResetCause::name(PORF, true));
    TEST_ASSERT_EQUAL_STRING("EXTERNAL", ResetCause::name(EXTRF, true));
    TEST_ASSERT_EQUAL_STRING("BROWNOUT", ResetCause::name(BORF, true));
    TEST_ASSERT_TRUE(ResetCause::wasAbnormal(BORF, true));
    TEST_ASSERT_EQUAL_STRING("WATCHDOG", ResetCause::name(WDRF | BORF, true));
    TEST_ASSERT_TRUE(ResetCause::wasAbnormal(WDRF | BORF, true));
}

// VER carries the name as a text field: a token of A-Z and '_'.
static void test_every_name_is_a_frame_token(void)
{
    for (uint16_t flags = 0; flags < 16; ++flags) {
        for (uint8_t marked = 0; marked < 2; ++marked) {
            const char* text = ResetCause::name((uint8_t)flags, marked != 0);
            TEST_ASSERT_TRUE(strlen(text) > 0);
            TEST_ASSERT_EQUAL_UINT(strlen(text), strspn(text, "ABCDEFGHIJKLMNOPQRSTUVWXYZ_"));
        }
    }
}

// After an abnormal reset a board sends ERR RESET with the name as its
// detail, which ProtocolFrames.def defines for RESET: WATCHDOG or BROWNOUT.
static void test_every_abnormal_reset_is_named_by_a_RESET_detail_token(void)
{
    for (uint16_t flags = 0; flags < 16; ++flags) {
        for (uint8_t marked = 0; marked < 2; ++marked) {
            if (!ResetCause::wasAbnormal((uint8_t)flags, marked != 0)) {
                continue;
            }
            const char* text = ResetCause::name((uint8_t)flags, marked != 0);
            TEST_ASSERT_TRUE(strcmp(text, Protocol::ErrorDetail::WATCHDOG) == 0 ||
                             strcmp(text, Protocol::ErrorDetail::BROWNOUT) == 0);
        }
    }
}

int runUnityTests(void)
{
    UNITY_BEGIN();
    RUN_TEST(test_flags_match_the_datasheets);
    RUN_TEST(test_each_flag_alone);
    RUN_TEST(test_watchdog_then_brownout_then_external_then_power_on);
    RUN_TEST(test_a_marked_watchdog_reset_was_commanded);
    RUN_TEST(test_an_unmarked_watchdog_reset_is_a_fault);
    RUN_TEST(test_a_marked_reset_without_flags_was_commanded);
    RUN_TEST(test_another_cause_overrides_the_marker);
    RUN_TEST(test_every_name_is_a_frame_token);
    RUN_TEST(test_every_abnormal_reset_is_named_by_a_RESET_detail_token);
    return UNITY_END();
}
