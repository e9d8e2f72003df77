// Fuzz input to serial bytes, record by record. Random bytes almost never
// carry a valid checksum, so a record can ask for the library's own checksum
// to be appended, and the parser's later checks are reached.
#ifndef THERMOTILT_FUZZ_FRAME_INPUT_H
#define THERMOTILT_FUZZ_FRAME_INPUT_H

#include <Protocol.h>

#include <stddef.h>
#include <stdint.h>
#include <string>

namespace LineChecksum {

// Protocol::checksum's result, written as the library's number of hex
// digits, most significant first.
typedef decltype(Protocol::checksum("", 0)) Value;
const uint8_t DIGITS = Protocol::CHECKSUM_DIGITS;

// '*' and the checksum of a line's text after its '$'.
std::string trailer(const std::string& content, bool lowerCase);

// Aborts unless trailer() is what FrameWriter appends, so that a change of
// the line checksum cannot leave the harness silently sending bad ones.
void checkAgainstWriter();

}  // namespace LineChecksum

// The text after '$' of the line being sent, framed as FrameParser frames it.
class LineTracker {
public:
    void push(char c);
    const std::string& content() const { return content_; }

private:
    std::string content_;
};

// Splits an input at '\n'; the last record may lack its '\n'.
class RecordReader {
public:
    RecordReader(const uint8_t* data, size_t size) : data_(data), size_(size), at_(0) {}

    bool next(const uint8_t*& record, size_t& length);

private:
    const uint8_t* data_;
    size_t size_;
    size_t at_;
};

// A serial record: a control byte, then text sent as it is.
//   bit 0     then '*' and the library's checksum of the line so far
//   bit 1     the checksum in lower-case hex
//   bits 2-3  line end: 0 CR LF, 1 LF, 2 CR, 3 none (the line goes on in the next record)
// "A$START,17" is a valid frame ending in CR LF, "@$START,17*00" a line sent
// as written, "E..." one ending in LF, "M..." one left open.
class SerialLineEncoder {
public:
    void encode(const uint8_t* record, size_t length, std::string& out);

private:
    void send(char c, std::string& out);

    LineTracker line_;
};

#endif
