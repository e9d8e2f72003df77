#include "frame_input.h"

#include "invariant.h"

#include <string.h>

namespace {

const uint8_t APPEND_CHECKSUM = 1 << 0;
const uint8_t LOWER_CASE = 1 << 1;
const uint8_t LINE_END_SHIFT = 2;
const char* const LINE_ENDS[] = {"\r\n", "\n", "\r", ""};

}  // namespace

std::string LineChecksum::trailer(const std::string& content, bool lowerCase)
{
    size_t length = content.size() > 255 ? 255 : content.size();
    Value sum = Protocol::checksum(content.data(), (uint8_t)length);
    const char* digits = lowerCase ? "0123456789abcdef" : "0123456789ABCDEF";
    std::string text = "*";
    for (int shift = 4 * (DIGITS - 1); shift >= 0; shift -= 4) {
        text += digits[(sum >> shift) & 0x0F];
    }
    return text;
}

void LineChecksum::checkAgainstWriter()
{
    char line[Protocol::LINE_BUFFER_SIZE];
    FrameWriter writer(line, sizeof line);
    writer.begin("AB", 65535);
    writer.addText("x y");
    writer.addInt(-1);
    const char* written = writer.finish();
    std::string content = "AB,65535,x y,-1";
    std::string expected = "$" + content + trailer(content, false) + "\r\n";
    require(written != 0 && expected == written,
            "the harness's checksum differs from FrameWriter's: update fuzz/frame_input.h");
}

void LineTracker::push(char c)
{
    if (c == '$' || c == '\r' || c == '\n') {
        content_.clear();
    } else {
        content_ += c;
    }
}

bool RecordReader::next(const uint8_t*& record, size_t& length)
{
    if (at_ >= size_) {
        return false;
    }
    record = data_ + at_;
    const void* end = memchr(record, '\n', size_ - at_);
    length = end ? (size_t)((const uint8_t*)end - record) : size_ - at_;
    at_ += length + 1;
    return true;
}

void SerialLineEncoder::send(char c, std::string& out)
{
    out += c;
    line_.push(c);
}

void SerialLineEncoder::encode(const uint8_t* record, size_t length, std::string& out)
{
    if (length == 0) {
        return;
    }
    uint8_t control = record[0];
    for (size_t i = 1; i < length; ++i) {
        send((char)record[i], out);
    }
    if (control & APPEND_CHECKSUM) {
        for (char c : LineChecksum::trailer(line_.content(), (control & LOWER_CASE) != 0)) {
            send(c, out);
        }
    }
    for (const char* end = LINE_ENDS[(control >> LINE_END_SHIFT) & 3]; *end; ++end) {
        send(*end, out);
    }
}
