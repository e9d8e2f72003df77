#include <unity.h>

#include <string.h>

#include "ProgramMemory.h"
#include "Protocol.h"

// FrameWriter's lines and the protocol's tables; test_protocol reads frames
// back. Expected lines and checksums were computed independently in Python:
//   "%04X" % binascii.crc_hqx(body.encode(), 0)
// (CRC-16/XMODEM) over the text between '$' and '*'.
// host/tests/test_protocol.py checks the same vectors.

static char buffer[Protocol::LINE_BUFFER_SIZE];

void setUp(void) {}

void tearDown(void) {}

static void test_checksum(void)
{
    TEST_ASSERT_EQUAL_HEX16(0x31C3, Protocol::checksum("123456789", 9));
    TEST_ASSERT_EQUAL_HEX16(0x80BD, Protocol::checksum("START,1", 7));
    TEST_ASSERT_EQUAL_HEX16(0xB192, Protocol::checksum("ACK,0,13,STOP", 13));
}

static void test_table(void)
{
    // The field lists of docs/protocol.md's frame signatures, counted by hand
    // (after TYPE and SEQ).
    TEST_ASSERT_EQUAL_UINT8(14, Protocol::FieldCount::IMU);
    TEST_ASSERT_EQUAL_UINT8(9, Protocol::FieldCount::CHS);
    TEST_ASSERT_EQUAL_UINT8(8, Protocol::FieldCount::SETCOE);
    TEST_ASSERT_EQUAL_UINT8(7, Protocol::FieldCount::SETPRG);
    TEST_ASSERT_EQUAL_UINT8(0, Protocol::FieldCount::START);
    TEST_ASSERT_EQUAL_STRING("SAVECOE", Protocol::Tag::SAVECOE);
}

// Integers at their extremes (the AVR formats them with avr-libc's ultoa,
// elsewhere a division loop). The expected text stays in flash: the Nano's
// RAM has no room for it beside this program's other strings.
static const char INTEGER_EXTREMES[] PROGMEM = "$IMU,65535,0,4294967295,0,-1,2147483647,-2147483648,-16384";

static void test_integer_extremes(void)
{
    FrameWriter writer(buffer, sizeof buffer);
    writer.begin(Protocol::Tag::IMU, 65535);
    writer.addUnsigned(0UL);
    writer.addUnsigned(4294967295UL);
    writer.addInt(0);
    writer.addInt(-1);
    writer.addInt(2147483647L);
    writer.addInt(-2147483647L - 1);
    writer.addInt(-16384);
    const char *line = writer.finish();
    TEST_ASSERT_NOT_NULL(line);
    char body[64];
    size_t length = strcspn(line, "*");
    TEST_ASSERT_TRUE(length < sizeof body);
    memcpy(body, line, length);
    body[length] = '\0';
    TEST_ASSERT_EQUAL_INT(0, strcmp_P(body, INTEGER_EXTREMES));
}

static void test_writer_errs(void)
{
    FrameWriter small(buffer, 20);
    small.begin(Protocol::Tag::ACK, 1);
    small.addText("0123456789");
    TEST_ASSERT_NULL(small.finish());

    FrameWriter writer(buffer, sizeof buffer);
    writer.begin(Protocol::Tag::ERR, 1);
    writer.addText("A,B");
    TEST_ASSERT_NULL(writer.finish());
    writer.begin("imu", 1);
    TEST_ASSERT_NULL(writer.finish());
    writer.begin(Protocol::Tag::ERR, 1);
    writer.addFixed(-0.126f, 1);
    TEST_ASSERT_EQUAL_STRING("$ERR,1,-0.1*2330\r\n", writer.finish());

    writer.begin(Protocol::Tag::IMU, 1);
    for (uint8_t i = 0; i < Protocol::MAX_FIELDS; ++i) {
        writer.addUnsigned(i);
    }
    TEST_ASSERT_NOT_NULL(writer.finish());
    writer.begin(Protocol::Tag::IMU, 1);
    for (uint8_t i = 0; i <= Protocol::MAX_FIELDS; ++i) {
        writer.addUnsigned(i);
    }
    TEST_ASSERT_NULL(writer.finish());
}

static void test_writer_checks_the_field_count_of_its_frame_type(void)
{
    FrameWriter writer(buffer, sizeof buffer);
    writer.begin(Protocol::Frame::ACK, 1);
    writer.addUnsigned(12);
    TEST_ASSERT_NULL(writer.finish());

    writer.begin(Protocol::Frame::ACK, 2);
    writer.addUnsigned(12);
    writer.addText("STOP");
    TEST_ASSERT_EQUAL_STRING("$ACK,2,12,STOP*3255\r\n", writer.finish());

    writer.begin(Protocol::Frame::ACK, 3);
    writer.addUnsigned(12);
    writer.addText("STOP");
    writer.addText("EXTRA");
    TEST_ASSERT_NULL(writer.finish());

    writer.begin(Protocol::Frame::START, 4);
    TEST_ASSERT_EQUAL_STRING("$START,4*D018\r\n", writer.finish());

    // Begun with a bare TYPE, the writer takes any number of fields.
    writer.begin(Protocol::Tag::ACK, 5);
    writer.addUnsigned(12);
    TEST_ASSERT_EQUAL_STRING("$ACK,5,12*DDFE\r\n", writer.finish());
}

static void test_error_codes_and_details_are_their_tokens(void)
{
    FrameWriter writer(buffer, sizeof buffer);
    writer.begin(Protocol::Frame::ERR, 6);
    writer.addInt(-1);
    writer.addText(Protocol::Error::BAD_ARG.text);
    writer.addText(Protocol::ErrorDetail::SET_AXIS);
    TEST_ASSERT_EQUAL_STRING("$ERR,6,-1,BAD_ARG,SET_AXIS*A39D\r\n", writer.finish());
    TEST_ASSERT_EQUAL_STRING("THERMISTOR", Protocol::Error::THERMISTOR.text);
    TEST_ASSERT_EQUAL_STRING("STOP_FIRST", Protocol::ErrorDetail::STOP_FIRST);
}

static void test_directions(void)
{
    TEST_ASSERT_TRUE(Protocol::isBoardFrame(Protocol::Tag::IMU));
    TEST_ASSERT_TRUE(Protocol::isBoardFrame(Protocol::Tag::ERR));
    TEST_ASSERT_TRUE(Protocol::isBoardFrame(Protocol::Tag::ACK));
    TEST_ASSERT_FALSE(Protocol::isBoardFrame(Protocol::Tag::SETPRG));
    TEST_ASSERT_FALSE(Protocol::isBoardFrame("NOSUCH"));
}

int runUnityTests(void)
{
    UNITY_BEGIN();
    RUN_TEST(test_checksum);
    RUN_TEST(test_table);
    RUN_TEST(test_integer_extremes);
    RUN_TEST(test_writer_errs);
    RUN_TEST(test_writer_checks_the_field_count_of_its_frame_type);
    RUN_TEST(test_error_codes_and_details_are_their_tokens);
    RUN_TEST(test_directions);
    return UNITY_END();
}
