#ifndef THERMOTILT_PROTOCOL_H
#define THERMOTILT_PROTOCOL_H

// ThermoTilt serial frames: $TYPE,SEQ,field,...*HHHH\r\n (see docs/protocol.md).
// Frame types and fields, ERR codes and their detail tokens are defined once,
// in ProtocolFrames.def.

#include <stdint.h>

#include "ProtocolFrames.def"

namespace Protocol {

const uint8_t VERSION = THERMOTILT_PROTOCOL_VERSION;
// Longest line, from '$' to the last checksum digit, without CR LF.
const uint8_t MAX_LINE = THERMOTILT_PROTOCOL_MAX_LINE;
// Most fields after TYPE and SEQ that a parser keeps.
const uint8_t MAX_FIELDS = THERMOTILT_PROTOCOL_MAX_FIELDS;
// A writer buffer of this size holds any legal line plus CR LF and NUL.
const uint8_t LINE_BUFFER_SIZE = MAX_LINE + 3;
const uint8_t MAX_TYPE_LENGTH = 7;
// The line check after '*': CRC-16/XMODEM as four hex digits.
const uint8_t CHECKSUM_DIGITS = 4;

constexpr uint8_t countCommas(const char *text)
{
    return *text == '\0' ? 0 : (uint8_t)((*text == ',' ? 1 : 0) + countCommas(text + 1));
}

constexpr uint8_t countFields(const char *fields)
{
    return *fields == '\0' ? 0 : (uint8_t)(countCommas(fields) + 1);
}

// Type tags, e.g. Protocol::Tag::IMU == "IMU", for tools and tests. The
// boards reach a tag through Frame, which keeps it in program memory.
namespace Tag {
#define THERMOTILT_FRAME(tag, role, fields) constexpr char tag[] = #tag;
#include "ProtocolFrames.def"
}

// The same in program memory (PROGMEM, Protocol.cpp).
namespace ProgmemTag {
#define THERMOTILT_FRAME(tag, role, fields) extern const char tag[];
#include "ProtocolFrames.def"
}

// Fields after TYPE and SEQ, e.g. Protocol::FieldCount::SETPRG == 7.
namespace FieldCount {
#define THERMOTILT_FRAME(tag, role, fields) constexpr uint8_t tag = countFields(fields);
#include "ProtocolFrames.def"
}

// A frame type with its field count, e.g. Protocol::Frame::ACK. A FrameWriter
// begun with one refuses to finish a frame with another number of fields.
// On the AVR a constant like this lives in RAM once a call takes it whole, so
// only inline functions take it and pass its members on.
struct FrameType {
    const char *tag;  // in program memory (PROGMEM)
    uint8_t fieldCount;
};

namespace Frame {
#define THERMOTILT_FRAME(tag, role, fields) constexpr FrameType tag = {ProgmemTag::tag, FieldCount::tag};
#include "ProtocolFrames.def"
}

// An ERR frame's code, e.g. Protocol::Error::BAD_ARG. The boards' SerialLink
// takes only this type (inline, as FrameType), so a board cannot send a code
// that is not defined.
struct ErrorCode {
    const char *text;
};

// Defined once (Protocol.cpp), so that a code used in two files is in RAM once.
namespace ErrorText {
#define THERMOTILT_ERROR(code, meaning) extern const char code[];
#include "ProtocolFrames.def"
}

namespace Error {
#define THERMOTILT_ERROR(code, meaning) constexpr ErrorCode code = {ErrorText::code};
#include "ProtocolFrames.def"
}

// Detail tokens of ERR frames, e.g. Protocol::ErrorDetail::FACTOR_1_255. Like
// string literals they take RAM on the AVR, and only those a board uses, each
// once (Protocol.cpp).
namespace ErrorDetail {
#define THERMOTILT_ERROR_DETAIL(token, codes) extern const char token[];
#include "ProtocolFrames.def"
}

// What a frame type is for (ProtocolFrames.def); all but COMMAND go from a
// board to the host.
enum class FrameRole : uint8_t { STREAM, ANSWER, OUTCOME, COMMAND };

// True for the types a board sends (IMU, CHS, ACK, ERR, ...): a board never
// answers those, so an echoing terminal cannot make it talk to itself.
bool isBoardFrame(const char *type);

// Why FrameParser dropped a line, e.g. MALFORMED_BAD_CHECKSUM; ERR BAD_FRAME
// names it with the detail token of the same name.
enum MalformedReason : uint8_t {
    MALFORMED_NONE = 0,
#define THERMOTILT_MALFORMED_REASON(token) MALFORMED_##token,
#include "ProtocolFrames.def"
};

// CRC-16/XMODEM of `length` bytes: the check of the text between '$' and '*'.
uint16_t checksum(const char *text, uint8_t length);

}  // namespace Protocol

// Builds one frame in a caller-supplied buffer. Any error (overflow, bad
// type, forbidden character in text, more than MAX_FIELDS fields, another
// field count than the FrameType's) is remembered and makes finish() fail,
// so a sketch can add all fields and check once.
class FrameWriter {
public:
    FrameWriter(char *buffer, uint16_t capacity);

    // A frame of a defined type: finish() fails unless exactly its field
    // count was added.
    __attribute__((always_inline)) void begin(Protocol::FrameType type, uint16_t seq)
    {
        beginFrame_P(type.tag, seq, type.fieldCount);
    }
    // Any valid TYPE with any number of fields (tools, tests, fuzzing).
    void begin(const char *type, uint16_t seq) { beginFrame(type, seq, ANY_FIELD_COUNT); }
    void addInt(int32_t value);
    void addUnsigned(uint32_t value);
    // Fixed point, e.g. addFixed(-12.345f, 2) -> "-12.35". Magnitudes of 1e9
    // and above are written in scientific notation instead.
    void addFixed(float value, uint8_t decimals);
    // Scientific, e.g. addScientific(-20.23f) -> "-2.0230e+01"; 1..8 digits.
    void addScientific(float value, uint8_t significantDigits = 5);
    void addText(const char *text);
    void addChar(char value);

    // Appends "*HHHH\r\n" and returns the NUL-terminated line, or 0 on error.
    const char *finish();
    // Characters of the finished line including CR LF.
    uint8_t length() const { return length_; }
    bool ok() const { return ok_; }

private:
    static const uint8_t ANY_FIELD_COUNT = 0xFF;

    void beginFrame(const char *type, uint16_t seq, uint8_t expectedFieldCount);
    // The same with the TYPE in program memory.
    void beginFrame_P(const char *type, uint16_t seq, uint8_t expectedFieldCount);
    bool startField();
    void append(const char *text);
    bool addNonFinite(float value);

    char *buffer_;
    uint8_t contentLimit_;
    uint8_t length_;
    uint8_t fieldCount_;
    uint8_t expectedFieldCount_;
    bool ok_;
    bool finished_;
};

// Assembles frames from a byte stream. feed() returns true when a valid
// frame is complete; its type, seq and fields stay readable until the next
// feed(). Invalid lines are counted and skipped without losing the next frame.
class FrameParser {
public:
    FrameParser();

    bool feed(char c);

    const char *type() const { return line_; }
    bool typeIs(const char *tag) const;
    uint16_t seq() const { return seq_; }
    uint8_t fieldCount() const { return fieldCount_; }
    // Field i after TYPE and SEQ, or 0 when i is out of range.
    const char *field(uint8_t index) const;
    // False (value unchanged) unless the whole field is a number in range.
    bool fieldInt(uint8_t index, int32_t &value) const;
    bool fieldFloat(uint8_t index, float &value) const;

    // Wraps at 65535.
    uint16_t malformedCount() const { return malformedCount_; }
    Protocol::MalformedReason lastMalformedReason() const { return (Protocol::MalformedReason)lastMalformed_; }

private:
    enum State : uint8_t { WAITING_FOR_START, IN_LINE, DISCARDING };

    bool endLine();
    Protocol::MalformedReason splitLine(uint8_t checksumPosition);
    void reject(Protocol::MalformedReason reason);

    // Characters after '$' of a line up to MAX_LINE long, plus NUL.
    char line_[Protocol::MAX_LINE];
    uint8_t fieldStart_[Protocol::MAX_FIELDS];
    uint8_t length_;
    uint8_t fieldCount_;
    uint16_t seq_;
    uint16_t malformedCount_;
    uint8_t state_;
    uint8_t lastMalformed_;
    uint8_t discardReason_;
};

#endif
