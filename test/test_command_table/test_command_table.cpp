#include <unity.h>

#include "CommandTable.h"
#include "ProgramMemory.h"
#include "Protocol.h"

// A board's commands as a table in program memory, as the sketches keep
// theirs for firmware/common/SerialLink::dispatch.

static char buffer[Protocol::LINE_BUFFER_SIZE];
static FrameParser parser;
static const FrameParser *handled;
static uint8_t handlerCalls;

static void handleStart(const FrameParser &command)
{
    handled = &command;
    handlerCalls += 1;
}

static void handleSetPrg(const FrameParser &command)
{
    handled = &command;
    handlerCalls += 10;
}

static const Protocol::Command COMMANDS[] PROGMEM = {
    Protocol::command(Protocol::Frame::START, handleStart),
    Protocol::command(Protocol::Frame::SETDEC, handleStart, Protocol::ErrorDetail::FACTOR_1_255),
    Protocol::command(Protocol::Frame::SETPRG, handleSetPrg),
};
static const uint8_t COMMAND_COUNT = sizeof COMMANDS / sizeof COMMANDS[0];

void setUp(void)
{
    parser = FrameParser();
    handled = 0;
    handlerCalls = 0;
}

void tearDown(void) {}

// Parses a frame of that type with `fields` fields.
static void receive(const char *type, uint8_t fields)
{
    FrameWriter writer(buffer, sizeof buffer);
    writer.begin(type, 3);
    for (uint8_t i = 0; i < fields; ++i) {
        writer.addUnsigned(i);
    }
    const char *line = writer.finish();
    TEST_ASSERT_NOT_NULL(line);
    uint8_t frames = 0;
    for (; *line != '\0'; ++line) {
        frames += parser.feed(*line) ? 1 : 0;
    }
    TEST_ASSERT_EQUAL_UINT8(1, frames);
}

static void test_a_command_is_found_with_its_handler(void)
{
    Protocol::Command found;
    receive(Protocol::Tag::SETPRG, 6);
    TEST_ASSERT_TRUE(Protocol::findCommand(COMMANDS, COMMAND_COUNT, parser.type(), found));
    found.handler(parser);
    TEST_ASSERT_EQUAL_UINT8(10, handlerCalls);
    TEST_ASSERT_TRUE(handled == &parser);

    receive(Protocol::Tag::START, 0);
    TEST_ASSERT_TRUE(Protocol::findCommand(COMMANDS, COMMAND_COUNT, parser.type(), found));
    found.handler(parser);
    TEST_ASSERT_EQUAL_UINT8(11, handlerCalls);
}

static void test_a_command_with_fields_needs_its_types_count(void)
{
    Protocol::Command found;
    receive(Protocol::Tag::SETDEC, 0);
    TEST_ASSERT_TRUE(Protocol::findCommand(COMMANDS, COMMAND_COUNT, parser.type(), found));
    TEST_ASSERT_EQUAL_UINT8(Protocol::FieldCount::SETDEC, found.minFields);
    TEST_ASSERT_EQUAL_STRING("FACTOR_1_255", found.fieldsDetail);
}

static void test_a_command_that_checks_its_own_fields_needs_none(void)
{
    Protocol::Command found;
    receive(Protocol::Tag::SETPRG, 0);
    TEST_ASSERT_TRUE(Protocol::findCommand(COMMANDS, COMMAND_COUNT, parser.type(), found));
    TEST_ASSERT_EQUAL_UINT8(0, found.minFields);
    TEST_ASSERT_NULL(found.fieldsDetail);
}

static void test_a_type_without_an_entry_is_not_found(void)
{
    Protocol::Command found;
    receive(Protocol::Tag::STOP, 0);
    TEST_ASSERT_FALSE(Protocol::findCommand(COMMANDS, COMMAND_COUNT, parser.type(), found));
    // Only the first count entries are looked at.
    receive(Protocol::Tag::SETPRG, 7);
    TEST_ASSERT_FALSE(Protocol::findCommand(COMMANDS, 2, parser.type(), found));
    TEST_ASSERT_EQUAL_UINT8(0, handlerCalls);
}

int runUnityTests(void)
{
    UNITY_BEGIN();
    RUN_TEST(test_a_command_is_found_with_its_handler);
    RUN_TEST(test_a_command_with_fields_needs_its_types_count);
    RUN_TEST(test_a_command_that_checks_its_own_fields_needs_none);
    RUN_TEST(test_a_type_without_an_entry_is_not_found);
    return UNITY_END();
}
