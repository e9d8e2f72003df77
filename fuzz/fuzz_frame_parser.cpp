// FrameParser::feed on arbitrary serial bytes (records as in frame_input.h).
// Every frame it accepts must have well-formed parts, answer field queries
// in and out of range consistently, and survive FrameWriter: written back,
// it fits the line limit and parses to the same frame.
#include <Protocol.h>

#include "frame_input.h"
#include "invariant.h"

#include <math.h>
#include <stdint.h>
#include <string.h>
#include <strings.h>
#include <string>
#include <vector>

namespace {

const int32_t INT_UNTOUCHED = 0x5A5A5A5A;
const float FLOAT_UNTOUCHED = -7.25f;
const float LARGEST_FIXED = 1e9f;
const uint8_t MAX_DIGITS = 8;

bool isTypeText(const char* text)
{
    size_t length = strlen(text);
    for (size_t i = 0; i < length; ++i) {
        if (text[i] < 'A' || text[i] > 'Z') {
            return false;
        }
    }
    return length >= 2 && length <= Protocol::MAX_TYPE_LENGTH;
}

bool isFieldText(const char* text)
{
    for (; *text; ++text) {
        if ((uint8_t)*text < 0x20 || (uint8_t)*text > 0x7E || *text == ',' || *text == '*' || *text == '$') {
            return false;
        }
    }
    return true;
}

bool sameBits(float a, float b)
{
    return memcmp(&a, &b, sizeof a) == 0;
}

void checkFieldQueries(const FrameParser& frame)
{
    require(isTypeText(frame.type()) && frame.typeIs(frame.type()), "accepted a frame with a bad type");
    require(frame.fieldCount() <= Protocol::MAX_FIELDS, "more fields than MAX_FIELDS");
    for (unsigned index = 0; index <= UINT8_MAX; ++index) {
        const char* text = frame.field((uint8_t)index);
        int32_t integer = INT_UNTOUCHED;
        float real = FLOAT_UNTOUCHED;
        bool isInt = frame.fieldInt((uint8_t)index, integer);
        bool isFloat = frame.fieldFloat((uint8_t)index, real);
        if (!isInt) {
            require(integer == INT_UNTOUCHED, "fieldInt failed but changed its value");
        }
        if (!isFloat) {
            require(sameBits(real, FLOAT_UNTOUCHED), "fieldFloat failed but changed its value");
        }
        if (index >= frame.fieldCount()) {
            require(text == 0 && !isInt && !isFloat, "a field beyond fieldCount() answered");
            continue;
        }
        require(text != 0 && isFieldText(text), "a field holds a character the line format forbids");
        if (isInt) {
            require(isFloat && real == (float)integer, "an integer field does not read as the same float");
        }
    }
}

// One line (a frame and its line end) through a fresh parser; `parser` then
// holds the frame until its next feed().
void parseBack(const std::string& line, FrameParser& parser)
{
    require(line.size() >= 2 && line.compare(line.size() - 2, 2, "\r\n") == 0, "a written line lacks CR LF");
    require(line.size() - 2 <= Protocol::MAX_LINE, "a written line is longer than MAX_LINE");
    for (size_t i = 0; i + 1 < line.size(); ++i) {
        bool complete = parser.feed(line[i]);
        require(complete == (i + 2 == line.size()), "a written line does not parse as one frame at its CR");
    }
    require(parser.malformedCount() == 0, "a written line was malformed");
}

void requireSameFrame(const FrameParser& a, const FrameParser& b)
{
    require(strcmp(a.type(), b.type()) == 0 && a.seq() == b.seq() && a.fieldCount() == b.fieldCount(),
            "a written frame parses back to another type, seq or field count");
    for (uint8_t i = 0; i < a.fieldCount(); ++i) {
        require(strcmp(a.field(i), b.field(i)) == 0, "a written frame parses back to other fields");
    }
}

// The writer in a heap buffer of exactly `capacity` bytes, so ASan sees any
// write past it.
class SizedWriter {
public:
    explicit SizedWriter(size_t capacity) : buffer_(capacity), writer_(buffer_.data(), (uint16_t)capacity) {}

    FrameWriter& operator*() { return writer_; }
    FrameWriter* operator->() { return &writer_; }

    // The finished line, or an empty string when the writer refused it.
    std::string finish()
    {
        const char* text = writer_.finish();
        if (text == 0) {
            return std::string();
        }
        require(writer_.length() < buffer_.size() && text[writer_.length()] == '\0',
                "finish() length does not match its NUL-terminated line");
        return std::string(text, writer_.length());
    }

private:
    std::vector<char> buffer_;
    FrameWriter writer_;
};

std::string writeAsText(const FrameParser& frame, size_t capacity)
{
    SizedWriter writer(capacity);
    writer->begin(frame.type(), frame.seq());
    for (uint8_t i = 0; i < frame.fieldCount(); ++i) {
        writer->addText(frame.field(i));
    }
    return writer.finish();
}

// The frame with one more field, padded so that its line is MAX_LINE long,
// and once one character longer: the writer takes the first and refuses the
// second, the parser accepts the first and rejects the second as too long.
void checkLengthLimit(const FrameParser& frame, const std::string& line)
{
    size_t room = Protocol::MAX_LINE - (line.size() - 2);
    if (frame.fieldCount() >= Protocol::MAX_FIELDS || room == 0) {
        return;
    }
    std::string padding(room - 1, 'x');
    SizedWriter longest(Protocol::LINE_BUFFER_SIZE);
    SizedWriter tooLong(Protocol::LINE_BUFFER_SIZE);
    for (SizedWriter* writer : {&longest, &tooLong}) {
        (*writer)->begin(frame.type(), frame.seq());
        for (uint8_t i = 0; i < frame.fieldCount(); ++i) {
            (*writer)->addText(frame.field(i));
        }
    }
    longest->addText(padding.c_str());
    tooLong->addText((padding + 'x').c_str());
    std::string longestLine = longest.finish();
    require(longestLine.size() == Protocol::MAX_LINE + 2, "the writer refused a line of MAX_LINE characters");
    require(tooLong.finish().empty(), "the writer wrote a line longer than MAX_LINE");
    FrameParser reparsed;
    parseBack(longestLine, reparsed);

    size_t star = longestLine.rfind('*');
    std::string content = longestLine.substr(1, star - 1) + 'x';
    std::string overLimit = "$" + content + LineChecksum::trailer(content, false) + "\r\n";
    FrameParser rejecting;
    for (char c : overLimit) {
        require(!rejecting.feed(c), "the parser accepted a line longer than MAX_LINE");
    }
    require(rejecting.malformedCount() == 1 && rejecting.lastMalformedReason() == Protocol::MALFORMED_TOO_LONG,
            "a line one character over MAX_LINE was not rejected as too long");
}

// `content` is the accepted line after its '$'. With its SEQ written without
// leading zeros, the writer must reproduce it byte for byte up to '*'.
void checkTextRewrite(const FrameParser& frame, const std::string& content)
{
    std::string line = writeAsText(frame, Protocol::LINE_BUFFER_SIZE);
    require(!line.empty(), "the writer refused a frame the parser accepted");
    FrameParser reparsed;
    parseBack(line, reparsed);
    requireSameFrame(frame, reparsed);
    checkLengthLimit(frame, line);

    size_t seqStart = content.find(',') + 1;
    size_t seqEnd = content.find_first_of(",*", seqStart);
    size_t star = content.find('*');
    if (content.compare(seqStart, seqEnd - seqStart, std::to_string(frame.seq())) == 0) {
        require(line.compare(1, star + 1, content, 0, star + 1) == 0, "a canonical frame is written differently");
        require(strncasecmp(line.c_str() + 1 + star, content.c_str() + star, content.size() - star) == 0 &&
                    line.size() == content.size() + 3,
                "a canonical frame is written with another checksum");
    }

    // A smaller buffer may make the writer refuse the frame, never overflow.
    size_t smallCapacity = frame.seq() % Protocol::LINE_BUFFER_SIZE;
    std::string small = writeAsText(frame, smallCapacity);
    if (!small.empty()) {
        require(small == line, "a smaller buffer gave another line");
    }
}

// What the text of `written` can differ from it by, after `decimals` fixed
// decimals or `digits` significant digits, and the float rounding of reading.
double allowedError(float written, bool fixed, uint8_t decimals, uint8_t digits)
{
    double magnitude = fabs((double)written);
    double printing = fixed ? 0.5 * pow(10.0, -(double)decimals) : magnitude * 0.5 * pow(10.0, 1.0 - digits);
    return 1.01 * printing + magnitude * ldexp(1.0, -23) + ldexp(1.0, -149);
}

bool readsBackAs(float written, float read, double allowed)
{
    if (isnan(written) || isnan(read)) {
        return isnan(written) && isnan(read);
    }
    if (isinf(written) || isinf(read)) {
        return written == read;
    }
    return fabs((double)read - (double)written) <= allowed;
}

// Fields that are numbers go back through addInt, addFixed or addScientific
// (with a precision that varies by field); they must read back as the same
// integer, or as a float as close as the written digits allow.
void checkNumberRewrite(const FrameParser& frame)
{
    SizedWriter writer(Protocol::LINE_BUFFER_SIZE);
    writer->begin(frame.type(), frame.seq());
    for (uint8_t i = 0; i < frame.fieldCount(); ++i) {
        int32_t integer = 0;
        float real = 0.0f;
        if (frame.fieldInt(i, integer)) {
            writer->addInt(integer);
        } else if (frame.fieldFloat(i, real)) {
            if (i % 2 == 0) {
                writer->addFixed(real, (uint8_t)(i % (MAX_DIGITS + 1)));
            } else {
                writer->addScientific(real, (uint8_t)(1 + i % MAX_DIGITS));
            }
        } else {
            writer->addText(frame.field(i));
        }
    }
    std::string line = writer.finish();
    if (line.empty()) {
        return;  // numbers can be longer written than read, and not fit
    }
    FrameParser reparsed;
    parseBack(line, reparsed);
    require(strcmp(frame.type(), reparsed.type()) == 0 && frame.seq() == reparsed.seq() &&
                frame.fieldCount() == reparsed.fieldCount(),
            "numbers written back changed the type, seq or field count");
    for (uint8_t i = 0; i < frame.fieldCount(); ++i) {
        int32_t integer = 0;
        int32_t integerBack = 0;
        float real = 0.0f;
        float realBack = 0.0f;
        if (frame.fieldInt(i, integer)) {
            require(reparsed.fieldInt(i, integerBack) && integerBack == integer, "addInt did not read back");
        } else if (frame.fieldFloat(i, real)) {
            bool fixed = i % 2 == 0 && fabsf(real) < LARGEST_FIXED;
            uint8_t digits = i % 2 == 0 ? MAX_DIGITS : (uint8_t)(1 + i % MAX_DIGITS);
            double allowed = allowedError(real, fixed, (uint8_t)(i % (MAX_DIGITS + 1)), digits);
            require(reparsed.fieldFloat(i, realBack) && readsBackAs(real, realBack, allowed),
                    "addFixed or addScientific did not read back within its precision");
        } else {
            require(strcmp(frame.field(i), reparsed.field(i)) == 0, "addText did not read back");
        }
    }
}

}  // namespace

extern "C" int LLVMFuzzerInitialize(int*, char***)
{
    LineChecksum::checkAgainstWriter();
    return 0;
}

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size)
{
    std::string stream;
    SerialLineEncoder encoder;
    RecordReader records(data, size);
    const uint8_t* record = 0;
    size_t length = 0;
    while (records.next(record, length)) {
        encoder.encode(record, length, stream);
    }

    FrameParser parser;
    LineTracker line;
    for (char c : stream) {
        uint16_t malformedBefore = parser.malformedCount();
        bool complete = parser.feed(c);
        uint16_t malformedAdded = (uint16_t)(parser.malformedCount() - malformedBefore);
        require(malformedAdded <= 1, "one byte counted more than one malformed line");
        require(parser.lastMalformedReason() <= Protocol::MALFORMED_TOO_MANY_FIELDS, "unknown malformed reason");
        if (complete) {
            require(malformedAdded == 0 && (c == '\r' || c == '\n'), "a frame completed other than at its line end");
            checkFieldQueries(parser);
            checkTextRewrite(parser, line.content());
            checkNumberRewrite(parser);
        }
        line.push(c);
    }
    return 0;
}
