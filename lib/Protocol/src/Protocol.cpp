#include "Protocol.h"

#include <errno.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include <Crc16.h>
#include <ProgramMemory.h>
#ifndef __AVR__
#include <stdio.h>
#endif

using namespace Protocol;

namespace {

// '*', the checksum digits, CR LF and the terminating NUL.
const uint8_t TRAILER_SIZE = 1 + CHECKSUM_DIGITS + 3;
// Enough for a 32-bit integer, or a float with |value| < 1e9 and up to 8
// decimals, or 8 significant digits in scientific notation.
const uint8_t NUMBER_BUFFER_SIZE = 24;
const uint8_t MAX_UINT32_DIGITS = 10;
const uint8_t MAX_DECIMALS = 8;
const float LARGEST_FIXED = 1e9f;

bool isPrintableAscii(char c)
{
    return (uint8_t)c >= 0x20 && (uint8_t)c <= 0x7E;
}

bool isAllowedInField(char c)
{
    return isPrintableAscii(c) && c != ',' && c != '*' && c != '$';
}

bool isValidType(const char *type)
{
    uint8_t length = 0;
    for (; type[length] != '\0'; ++length) {
        if (type[length] < 'A' || type[length] > 'Z' || length >= MAX_TYPE_LENGTH) {
            return false;
        }
    }
    return length >= 2;
}

char hexDigit(uint8_t nibble)
{
    return (char)(nibble < 10u ? '0' + nibble : 'A' + (nibble - 10u));
}

int8_t hexValue(char c)
{
    if (c >= '0' && c <= '9')
        return (int8_t)(c - '0');
    if (c >= 'A' && c <= 'F')
        return (int8_t)(c - 'A' + 10);
    if (c >= 'a' && c <= 'f')
        return (int8_t)(c - 'a' + 10);
    return -1;
}

// Powers of ten, in flash; below 10^4 the digits are taken in 16-bit arithmetic.
const uint32_t LARGE_POWERS_OF_TEN[] PROGMEM = {1000000000UL, 100000000UL, 10000000UL, 1000000UL, 100000UL, 10000UL};
const uint16_t SMALL_POWERS_OF_TEN[] PROGMEM = {1000u, 100u, 10u};

// value's digit at power, counted by subtracting, after digit; none while
// it would be a leading zero (digit still at text).
template <typename Number>
char *takeDigit(Number &value, Number power, char *digit, const char *text)
{
    if (digit == text && value < power) {
        return digit;
    }
    char count = '0';
    for (; value >= power; value -= power) {
        ++count;
    }
    *digit = count;
    return digit + 1;
}

// The digits of value as text that ends at or before end, with room before
// it for a sign. The AVR has no divide instruction: avr-libc's ultoa took
// ~2000 cycles for six digits where counting subtractions takes ~470
// (measured in simavr). The same code runs everywhere, so the host and the
// boards format alike.
const char *formatUnsigned(uint32_t value, char *end)
{
    char *text = end - MAX_UINT32_DIGITS;
    char *digit = text;
    for (uint8_t i = 0; i < sizeof LARGE_POWERS_OF_TEN / sizeof *LARGE_POWERS_OF_TEN; ++i) {
        digit = takeDigit(value, (uint32_t)pgm_read_dword(&LARGE_POWERS_OF_TEN[i]), digit, text);
    }
    uint16_t rest = (uint16_t)value;
    for (uint8_t i = 0; i < sizeof SMALL_POWERS_OF_TEN / sizeof *SMALL_POWERS_OF_TEN; ++i) {
        digit = takeDigit(rest, (uint16_t)pgm_read_word(&SMALL_POWERS_OF_TEN[i]), digit, text);
    }
    *digit++ = (char)('0' + rest);
    *digit = '\0';
    return text;
}

// value * 10^decimals rounded to an integer, exactly, from the float's bits:
// value = mantissa * 2^exponent, and 10^decimals = 5^decimals * 2^decimals
// keeps mantissa * 5^decimals within 31 bits. Ties round away from zero, as
// avr-libc's dtostrf rounds them (0.25 to one decimal is 0.3; glibc's
// printf says 0.2). False beyond EXACT_FIXED_LIMIT, where dtostrf's own
// digits run out, or for more than MAX_EXACT_DECIMALS.
const uint8_t MAX_EXACT_DECIMALS = 3;
const uint32_t EXACT_FIXED_LIMIT = 10000000UL;

bool roundToDecimals(float value, uint8_t decimals, uint32_t &rounded)
{
    uint32_t bits;
    memcpy(&bits, &value, sizeof bits);
    uint8_t biasedExponent = (uint8_t)(bits >> 23);
    uint32_t mantissa = bits & 0x7FFFFFUL;
    if (biasedExponent != 0) {
        mantissa |= 0x800000UL;
    }
    // value * 10^decimals = mantissa * 5^decimals / 2^shift, exactly
    int16_t shift = (int16_t)(biasedExponent == 0 ? 149 : 150 - biasedExponent) - decimals;
    if (decimals > MAX_EXACT_DECIMALS || biasedExponent == 0xFF || shift <= 0) {
        return false;
    }
    uint32_t scaled = mantissa;
    for (uint8_t i = 0; i < decimals; ++i) {
        scaled = (scaled << 2) + scaled;
    }
    rounded = shift > 31 ? 0 : ((scaled >> (shift - 1)) + 1) >> 1;
    return rounded < EXACT_FIXED_LIMIT;
}

// The text dtostrf gives ("-0.0" for -0.04 too) in ~1000 cycles where
// dtostrf takes ~1400 (simavr). avr-libc's printf has no floating point
// unless a special library is linked, so beyond roundToDecimals' range the
// AVR still uses dtostrf, elsewhere snprintf.
void formatFixed(float value, uint8_t decimals, char *out)
{
    uint32_t rounded;
    if (!roundToDecimals(value, decimals, rounded)) {
#ifdef __AVR__
        dtostrf(value, 0, decimals, out);
#else
        snprintf(out, NUMBER_BUFFER_SIZE, "%.*f", (int)decimals, (double)value);
#endif
        return;
    }
    char buffer[MAX_UINT32_DIGITS + 1];
    const char *digits = formatUnsigned(rounded, buffer + MAX_UINT32_DIGITS);
    uint8_t length = (uint8_t)strlen(digits);
    if (signbit(value)) {
        *out++ = '-';
    }
    if (length > decimals) {
        uint8_t integerDigits = (uint8_t)(length - decimals);
        memcpy(out, digits, integerDigits);
        out += integerDigits;
        digits += integerDigits;
        length = decimals;
    } else {
        *out++ = '0';
    }
    if (decimals > 0) {
        *out++ = '.';
        for (uint8_t zeros = (uint8_t)(decimals - length); zeros > 0; --zeros) {
            *out++ = '0';
        }
        memcpy(out, digits, length);
        out += length;
    }
    *out = '\0';
}

void formatScientific(float value, uint8_t decimals, char *out)
{
#ifdef __AVR__
    dtostre(value, out, decimals, 0);
#else
    snprintf(out, NUMBER_BUFFER_SIZE, "%.*e", (int)decimals, (double)value);
#endif
}

bool isNonEmptyWithoutLeadingSpace(const char *text)
{
    char first = text[0];
    return first != '\0' && first != ' ' && first != '\t';
}

}  // namespace

uint16_t Protocol::checksum(const char *text, uint8_t length)
{
    return crc16Xmodem((const uint8_t *)text, length);
}

#define THERMOTILT_FRAME(tag, role, fields) const char Protocol::ProgmemTag::tag[] PROGMEM = #tag;
#include "ProtocolFrames.def"
#define THERMOTILT_ERROR(code, meaning) const char Protocol::ErrorText::code[] = #code;
#include "ProtocolFrames.def"
#define THERMOTILT_ERROR_DETAIL(token, codes) const char Protocol::ErrorDetail::token[] = #token;
#include "ProtocolFrames.def"

bool Protocol::isBoardFrame(const char *type)
{
#define THERMOTILT_FRAME(tag, role, fields) \
    if (FrameRole::role != FrameRole::COMMAND && strcmp_P(type, ProgmemTag::tag) == 0) \
        return true;
#include "ProtocolFrames.def"
    return false;
}

FrameWriter::FrameWriter(char *buffer, uint16_t capacity)
    : buffer_(buffer),
      contentLimit_(0),
      length_(0),
      fieldCount_(0),
      expectedFieldCount_(ANY_FIELD_COUNT),
      ok_(false),
      finished_(false)
{
    uint16_t limit = capacity > TRAILER_SIZE ? (uint16_t)(capacity - TRAILER_SIZE) : 0u;
    const uint8_t longestContent = MAX_LINE - 1 - CHECKSUM_DIGITS;
    contentLimit_ = limit > longestContent ? longestContent : (uint8_t)limit;
}

void FrameWriter::beginFrame(const char *type, uint16_t seq, uint8_t expectedFieldCount)
{
    expectedFieldCount_ = expectedFieldCount;
    length_ = 0;
    finished_ = false;
    ok_ = isValidType(type);
    append("$");
    append(type);
    char digits[NUMBER_BUFFER_SIZE];
    append(",");
    append(formatUnsigned(seq, digits + sizeof digits - 1));
    fieldCount_ = 0;
}

void FrameWriter::beginFrame_P(const char *type, uint16_t seq, uint8_t expectedFieldCount)
{
    // Room for one character more than a TYPE may have: a longer one, cut
    // here, stays too long.
    char tag[MAX_TYPE_LENGTH + 2];
    strncpy_P(tag, type, sizeof tag - 1);
    tag[sizeof tag - 1] = '\0';
    beginFrame(tag, seq, expectedFieldCount);
}

void FrameWriter::append(const char *text)
{
    if (!ok_ || finished_) {
        return;
    }
    for (; *text != '\0'; ++text) {
        if (length_ >= contentLimit_) {
            ok_ = false;
            return;
        }
        buffer_[length_++] = *text;
    }
}

bool FrameWriter::startField()
{
    if (fieldCount_ >= MAX_FIELDS) {
        ok_ = false;
    }
    ++fieldCount_;
    append(",");
    return ok_ && !finished_;
}

void FrameWriter::addUnsigned(uint32_t value)
{
    char digits[NUMBER_BUFFER_SIZE];
    if (startField()) {
        append(formatUnsigned(value, digits + sizeof digits - 1));
    }
}

void FrameWriter::addInt(int32_t value)
{
    char digits[NUMBER_BUFFER_SIZE];
    if (!startField()) {
        return;
    }
    // Negating in 32-bit unsigned keeps INT32_MIN correct.
    uint32_t magnitude = value < 0 ? 0u - (uint32_t)value : (uint32_t)value;
    char *text = (char *)formatUnsigned(magnitude, digits + sizeof digits - 1);
    if (value < 0) {
        *--text = '-';
    }
    append(text);
}

bool FrameWriter::addNonFinite(float value)
{
    if (isnan(value)) {
        append("nan");
    } else if (isinf(value)) {
        append(value < 0.0f ? "-inf" : "inf");
    } else {
        return false;
    }
    return true;
}

void FrameWriter::addFixed(float value, uint8_t decimals)
{
    if (!(fabsf(value) < LARGEST_FIXED) && !isnan(value) && !isinf(value)) {
        addScientific(value, MAX_DECIMALS);
        return;
    }
    if (!startField() || addNonFinite(value)) {
        return;
    }
    char text[NUMBER_BUFFER_SIZE];
    formatFixed(value, decimals > MAX_DECIMALS ? MAX_DECIMALS : decimals, text);
    append(text);
}

void FrameWriter::addScientific(float value, uint8_t significantDigits)
{
    if (!startField() || addNonFinite(value)) {
        return;
    }
    if (significantDigits < 1)
        significantDigits = 1;
    if (significantDigits > MAX_DECIMALS)
        significantDigits = MAX_DECIMALS;
    char text[NUMBER_BUFFER_SIZE];
    formatScientific(value, (uint8_t)(significantDigits - 1), text);
    append(text);
}

void FrameWriter::addText(const char *text)
{
    for (const char *c = text; *c != '\0'; ++c) {
        if (!isAllowedInField(*c)) {
            ok_ = false;
        }
    }
    if (startField()) {
        append(text);
    }
}

void FrameWriter::addChar(char value)
{
    char text[2] = {value, '\0'};
    if (value == '\0') {
        ok_ = false;
    }
    addText(text);
}

const char *FrameWriter::finish()
{
    if (!ok_ || (expectedFieldCount_ != ANY_FIELD_COUNT && fieldCount_ != expectedFieldCount_)) {
        return 0;
    }
    if (!finished_) {
        uint16_t sum = checksum(buffer_ + 1, (uint8_t)(length_ - 1));
        buffer_[length_++] = '*';
        for (int8_t shift = 4 * (CHECKSUM_DIGITS - 1); shift >= 0; shift -= 4) {
            buffer_[length_++] = hexDigit((uint8_t)((sum >> shift) & 0x0Fu));
        }
        buffer_[length_++] = '\r';
        buffer_[length_++] = '\n';
        buffer_[length_] = '\0';
        finished_ = true;
    }
    return buffer_;
}

FrameParser::FrameParser()
    : length_(0),
      fieldCount_(0),
      seq_(0),
      malformedCount_(0),
      state_(WAITING_FOR_START),
      lastMalformed_(MALFORMED_NONE),
      discardReason_(MALFORMED_NONE)
{
    line_[0] = '\0';
}

bool FrameParser::feed(char c)
{
    if (c == '$') {
        if (state_ == IN_LINE) {
            reject(MALFORMED_TRUNCATED);
        } else if (state_ == DISCARDING) {
            reject((MalformedReason)discardReason_);
        }
        state_ = IN_LINE;
        length_ = 0;
        fieldCount_ = 0;
        return false;
    }
    if (c == '\r' || c == '\n') {
        uint8_t previous = state_;
        state_ = WAITING_FOR_START;
        if (previous == IN_LINE) {
            return endLine();
        }
        if (previous == DISCARDING) {
            reject((MalformedReason)discardReason_);
        }
        return false;
    }
    if (state_ != IN_LINE) {
        return false;
    }
    // One byte of line_ stays free for the NUL; '$' itself is not stored.
    if (!isPrintableAscii(c) || length_ >= MAX_LINE - 1) {
        discardReason_ = isPrintableAscii(c) ? MALFORMED_TOO_LONG : MALFORMED_BAD_CHAR;
        state_ = DISCARDING;
        return false;
    }
    line_[length_++] = c;
    return false;
}

void FrameParser::reject(MalformedReason reason)
{
    ++malformedCount_;
    lastMalformed_ = reason;
    fieldCount_ = 0;
}

bool FrameParser::endLine()
{
    line_[length_] = '\0';
    const char *star = strchr(line_, '*');
    if (star == 0 || length_ - (uint8_t)(star - line_) != 1 + CHECKSUM_DIGITS) {
        reject(MALFORMED_NO_CHECKSUM);
        return false;
    }
    uint8_t starPosition = (uint8_t)(star - line_);
    uint16_t received = 0;
    for (uint8_t i = 1; i <= CHECKSUM_DIGITS; ++i) {
        int8_t digit = hexValue(star[i]);
        if (digit < 0) {
            reject(MALFORMED_BAD_CHECKSUM);
            return false;
        }
        received = (uint16_t)((received << 4) | (uint8_t)digit);
    }
    if (checksum(line_, starPosition) != received) {
        reject(MALFORMED_BAD_CHECKSUM);
        return false;
    }
    MalformedReason reason = splitLine(starPosition);
    if (reason != MALFORMED_NONE) {
        reject(reason);
        return false;
    }
    return true;
}

MalformedReason FrameParser::splitLine(uint8_t end)
{
    line_[end] = '\0';
    uint8_t tokenIndex = 0;
    uint8_t tokenStart = 0;
    uint8_t seqStart = 0;
    bool tooManyFields = false;
    fieldCount_ = 0;
    for (uint8_t i = 0; i <= end; ++i) {
        if (i < end && line_[i] != ',') {
            continue;
        }
        line_[i] = '\0';
        if (tokenIndex == 1) {
            seqStart = tokenStart;
        } else if (tokenIndex >= 2) {
            if (fieldCount_ < MAX_FIELDS) {
                fieldStart_[fieldCount_++] = tokenStart;
            } else {
                tooManyFields = true;
            }
        }
        ++tokenIndex;
        tokenStart = (uint8_t)(i + 1);
    }
    if (!isValidType(line_)) {
        return MALFORMED_BAD_TYPE;
    }
    const char *seqText = line_ + seqStart;
    uint8_t digits = (uint8_t)strlen(seqText);
    if (tokenIndex < 2 || digits == 0 || digits > 5) {
        return MALFORMED_BAD_SEQ;
    }
    uint32_t seq = 0;
    for (uint8_t i = 0; i < digits; ++i) {
        if (seqText[i] < '0' || seqText[i] > '9') {
            return MALFORMED_BAD_SEQ;
        }
        seq = seq * 10u + (uint32_t)(seqText[i] - '0');
    }
    if (seq > 0xFFFFu) {
        return MALFORMED_BAD_SEQ;
    }
    if (tooManyFields) {
        return MALFORMED_TOO_MANY_FIELDS;
    }
    seq_ = (uint16_t)seq;
    return MALFORMED_NONE;
}

bool FrameParser::typeIs(const char *tag) const
{
    return strcmp(line_, tag) == 0;
}

const char *FrameParser::field(uint8_t index) const
{
    return index < fieldCount_ ? line_ + fieldStart_[index] : 0;
}

bool FrameParser::fieldInt(uint8_t index, int32_t &value) const
{
    const char *text = field(index);
    if (text == 0 || !isNonEmptyWithoutLeadingSpace(text)) {
        return false;
    }
    char *end = 0;
    errno = 0;
    long parsed = strtol(text, &end, 10);
    if (*end != '\0' || errno == ERANGE || parsed > 2147483647L || parsed < -2147483647L - 1L) {
        return false;
    }
    value = (int32_t)parsed;
    return true;
}

bool FrameParser::fieldFloat(uint8_t index, float &value) const
{
    const char *text = field(index);
    if (text == 0 || !isNonEmptyWithoutLeadingSpace(text)) {
        return false;
    }
    char *end = 0;
    double parsed = strtod(text, &end);
    if (*end != '\0') {
        return false;
    }
    value = (float)parsed;
    return true;
}
