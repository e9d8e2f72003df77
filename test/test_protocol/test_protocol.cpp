#include <unity.h>

#include <string.h>

#include "Protocol.h"

// Expected lines and checksums were computed independently in Python:
//   "%04X" % binascii.crc_hqx(body.encode(), 0)
// (CRC-16/XMODEM) over the text between '$' and '*'.
// host/tests/test_protocol.py checks the same vectors. Frames written
// without being read back are test_frame_writer's: both would not fit a
// Nano's 2 KB in one program.

static char buffer[Protocol::LINE_BUFFER_SIZE];
static FrameParser parser;

void setUp(void)
{
    parser = FrameParser();
}

void tearDown(void) {}

// Feeds a whole text; returns how many frames completed.
static uint8_t feedText(const char *text)
{
    uint8_t frames = 0;
    for (; *text != '\0'; ++text) {
        if (parser.feed(*text)) {
            ++frames;
        }
    }
    return frames;
}

static void test_imu(void)
{
    FrameWriter writer(buffer, sizeof buffer);
    writer.begin(Protocol::Tag::IMU, 42);
    writer.addUnsigned(123456UL);
    writer.addInt(-1650);
    writer.addInt(-388);
    writer.addInt(16012);
    writer.addFixed(-1649.75f, 2);
    writer.addFixed(-388.5f, 2);
    writer.addFixed(16012.25f, 2);
    writer.addFixed(-1078.25f, 2);
    writer.addFixed(-34.5f, 2);
    writer.addFixed(16011.0f, 2);
    writer.addFixed(23.5f, 2);
    writer.addChar('W');
    writer.addChar('E');
    writer.addChar('I');
    const char *line = writer.finish();
    TEST_ASSERT_NOT_NULL(line);
    TEST_ASSERT_EQUAL_STRING("$IMU,42,123456,-1650,-388,16012,-1649.75,-388.50,16012.25,"
                             "-1078.25,-34.50,16011.00,23.50,W,E,I*765D\r\n",
                             line);
    TEST_ASSERT_EQUAL_UINT8(101, writer.length());

    TEST_ASSERT_EQUAL_UINT8(1, feedText(line));
    TEST_ASSERT_TRUE(parser.typeIs(Protocol::Tag::IMU));
    TEST_ASSERT_EQUAL_UINT16(42, parser.seq());
    TEST_ASSERT_EQUAL_UINT8(Protocol::FieldCount::IMU, parser.fieldCount());
    int32_t t_ms = 0;
    int32_t ax = 0;
    float azFilt = 0.0f;
    TEST_ASSERT_TRUE(parser.fieldInt(0, t_ms));
    TEST_ASSERT_EQUAL_INT32(123456L, t_ms);
    TEST_ASSERT_TRUE(parser.fieldInt(1, ax));
    TEST_ASSERT_EQUAL_INT32(-1650, ax);
    TEST_ASSERT_TRUE(parser.fieldFloat(6, azFilt));
    TEST_ASSERT_FLOAT_WITHIN(0.001f, 16012.25f, azFilt);
    TEST_ASSERT_EQUAL_STRING("E", parser.field(12));
    TEST_ASSERT_EQUAL_STRING("I", parser.field(13));
    TEST_ASSERT_NULL(parser.field(14));
    TEST_ASSERT_EQUAL_UINT16(0, parser.malformedCount());
}

static void test_coe(void)
{
    // Paper, Table 2, X axis warming.
    FrameWriter writer(buffer, sizeof buffer);
    writer.begin(Protocol::Tag::COE, 7);
    writer.addChar('W');
    writer.addChar('X');
    writer.addScientific(571.5f);
    writer.addScientific(-20.23f);
    writer.addScientific(1.569e-3f);
    writer.addScientific(-0.1044f);
    writer.addScientific(-6.936e-5f);
    writer.addScientific(6.327e-9f);
    const char *line = writer.finish();
    TEST_ASSERT_EQUAL_STRING("$COE,7,W,X,5.7150e+02,-2.0230e+01,1.5690e-03,-1.0440e-01,"
                             "-6.9360e-05,6.3270e-09*FCD1\r\n",
                             line);
    TEST_ASSERT_EQUAL_UINT8(1, feedText(line));
    float p02 = 0.0f;
    float p11 = 0.0f;
    TEST_ASSERT_TRUE(parser.fieldFloat(7, p02));
    TEST_ASSERT_FLOAT_WITHIN(1e-13f, 6.327e-9f, p02);
    TEST_ASSERT_TRUE(parser.fieldFloat(6, p11));
    TEST_ASSERT_FLOAT_WITHIN(1e-9f, -6.936e-5f, p11);
}

static void test_bad_sum(void)
{
    // Correct checksum is B192; lower-case hex is accepted.
    TEST_ASSERT_EQUAL_UINT8(0, feedText("$ACK,0,13,STOP*B193\r\n"));
    TEST_ASSERT_EQUAL_UINT16(1, parser.malformedCount());
    TEST_ASSERT_EQUAL_UINT8(Protocol::MALFORMED_BAD_CHECKSUM, parser.lastMalformedReason());
    TEST_ASSERT_EQUAL_UINT8(1, feedText("$GETCOE,3,C,Y*c2ac\n"));
    TEST_ASSERT_EQUAL_STRING("Y", parser.field(1));
    TEST_ASSERT_EQUAL_UINT8(0, feedText("$ACK,0,13,STOP\r\n"));
    TEST_ASSERT_EQUAL_UINT8(Protocol::MALFORMED_NO_CHECKSUM, parser.lastMalformedReason());
    TEST_ASSERT_EQUAL_UINT16(2, parser.malformedCount());
    // Protocol 1's two-digit XOR line is no longer a frame.
    TEST_ASSERT_EQUAL_UINT8(0, feedText("$START,1*5D\r\n"));
    TEST_ASSERT_EQUAL_UINT8(Protocol::MALFORMED_NO_CHECKSUM, parser.lastMalformedReason());
}

// Two flips in the same bit position of two bytes kept protocol 1's XOR:
// rest 1200 -> 1300 s and hold 60 -> 70 s ('2'->'3', '6'->'7': bit 0 twice)
// under the original line's check.
static void test_same_bit_flips(void)
{
    TEST_ASSERT_EQUAL_UINT8(0, feedText("$SETPRG,9,-10.00,45.00,2.00,70,1300,1*A843\r\n"));
    TEST_ASSERT_EQUAL_UINT8(Protocol::MALFORMED_BAD_CHECKSUM, parser.lastMalformedReason());
}

static void test_garbage(void)
{
    TEST_ASSERT_EQUAL_UINT8(1, feedText("\x01zz*12,\r\n$START,1*80BD\r\n"));
    TEST_ASSERT_TRUE(parser.typeIs(Protocol::Tag::START));
    TEST_ASSERT_EQUAL_UINT8(0, parser.fieldCount());
    TEST_ASSERT_EQUAL_UINT16(0, parser.malformedCount());
}

static void test_too_long(void)
{
    parser.feed('$');
    for (uint8_t i = 0; i < 130; ++i) {
        TEST_ASSERT_FALSE(parser.feed('A'));
    }
    TEST_ASSERT_EQUAL_UINT8(1, feedText("\r\n$START,1*80BD\r\n"));
    TEST_ASSERT_EQUAL_UINT16(1, parser.malformedCount());
    TEST_ASSERT_EQUAL_UINT8(Protocol::MALFORMED_TOO_LONG, parser.lastMalformedReason());
    // A cut-off line followed directly by the next '$' is also counted.
    TEST_ASSERT_EQUAL_UINT8(1, feedText("$ACK,0,1$START,1*80BD\r\n"));
    TEST_ASSERT_EQUAL_UINT8(Protocol::MALFORMED_TRUNCATED, parser.lastMalformedReason());
}

// "$LONG,0," + n x 'A' + "*HHHH": 120 characters when n = 107. Checksums
// by Python as above.
static uint8_t feedLongLine(uint8_t letters, const char *trailer)
{
    feedText("$LONG,0,");
    for (uint8_t i = 0; i < letters; ++i) {
        parser.feed('A');
    }
    return feedText(trailer);
}

static void test_longest(void)
{
    TEST_ASSERT_EQUAL_UINT8(1, feedLongLine(107, "*E008\r\n"));
    TEST_ASSERT_EQUAL_UINT8(107, strlen(parser.field(0)));
    TEST_ASSERT_EQUAL_UINT8(0, feedLongLine(108, "*ADCB\r\n"));
    TEST_ASSERT_EQUAL_UINT8(Protocol::MALFORMED_TOO_LONG, parser.lastMalformedReason());
}

static void test_numbers(void)
{
    TEST_ASSERT_EQUAL_UINT8(1, feedText("$SETPRG,9,-10.00,45.00,2.00,60,1200,1*A843\r\n"));
    float start = 0.0f;
    int32_t rest = 0;
    TEST_ASSERT_TRUE(parser.fieldFloat(0, start));
    TEST_ASSERT_FLOAT_WITHIN(1e-4f, -10.0f, start);
    TEST_ASSERT_TRUE(parser.fieldInt(4, rest));
    TEST_ASSERT_EQUAL_INT32(1200, rest);
    TEST_ASSERT_FALSE(parser.fieldInt(0, rest));
    TEST_ASSERT_EQUAL_INT32(1200, rest);

    TEST_ASSERT_EQUAL_UINT8(1, feedText("$ERR,8,-1,BAD_CHECKSUM,CMD*9211\r\n"));
    int32_t cmdSeq = 0;
    TEST_ASSERT_TRUE(parser.fieldInt(0, cmdSeq));
    TEST_ASSERT_EQUAL_INT32(-1, cmdSeq);
    TEST_ASSERT_FALSE(parser.fieldFloat(1, start));
}

static void test_seq_wrap(void)
{
    FrameWriter writer(buffer, sizeof buffer);
    uint16_t seq = 65535u;
    writer.begin(Protocol::Tag::ACK, seq);
    writer.addInt(12);
    writer.addText("SETPRG");
    TEST_ASSERT_EQUAL_STRING("$ACK,65535,12,SETPRG*7DCE\r\n", writer.finish());
    ++seq;
    writer.begin(Protocol::Tag::ACK, seq);
    writer.addInt(13);
    writer.addText("STOP");
    TEST_ASSERT_EQUAL_STRING("$ACK,0,13,STOP*B192\r\n", writer.finish());
    TEST_ASSERT_EQUAL_UINT8(1, feedText("$ACK,65535,12,SETPRG*7DCE\r\n"));
    TEST_ASSERT_EQUAL_UINT16(65535u, parser.seq());
    TEST_ASSERT_EQUAL_UINT8(0, feedText("$ACK,65536,1,X*35E4\r\n"));
    TEST_ASSERT_EQUAL_UINT8(Protocol::MALFORMED_BAD_SEQ, parser.lastMalformedReason());
}

int runUnityTests(void)
{
    UNITY_BEGIN();
    RUN_TEST(test_imu);
    RUN_TEST(test_coe);
    RUN_TEST(test_bad_sum);
    RUN_TEST(test_same_bit_flips);
    RUN_TEST(test_garbage);
    RUN_TEST(test_too_long);
    RUN_TEST(test_longest);
    RUN_TEST(test_numbers);
    RUN_TEST(test_seq_wrap);
    return UNITY_END();
}
