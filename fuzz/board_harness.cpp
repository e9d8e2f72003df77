#include "board_harness.h"

#include "arduino_shim/ArduinoShim.h"
#include "arduino_shim/avr/io.h"
#include "frame_input.h"
#include "invariant.h"
#include "sketch_state/sketch_state.h"

#include <stdlib.h>
#include <string.h>
#include <deque>
#include <string>

void setup();
void loop();
// The sketch's reset-flags reader, which the AVR runs from .init3 before
// the C runtime; weak, since a sketch need not have one.
void captureResetFlags() __attribute__((weak));

namespace {

// 115200 baud at 10 bits a byte.
const uint32_t SERIAL_BYTES_PER_MS = 11;
// Loop passes one input may run, so that every input stays quick.
const uint32_t MAX_PASSES = 20000;
const char WORLD_RECORD = '~';
const char WORLD_BYTES = '|';
const uint8_t POWER_ON_FLAGS = _BV(PORF);
uint8_t bootFlags = POWER_ON_FLAGS;

struct FrameSpec {
    const char* tag;
    const char* role;
    const char* fields;
};

const FrameSpec FRAME_SPECS[] = {
#define THERMOTILT_FRAME(tag, role, fields) {#tag, #role, fields},
#include <ProtocolFrames.def>
};

struct ErrorDetailSpec {
    const char* token;
    const char* codes;
};

const char* const ERROR_CODES[] = {
#define THERMOTILT_ERROR(code, meaning) #code,
#include <ProtocolFrames.def>
};

const ErrorDetailSpec ERROR_DETAILS[] = {
#define THERMOTILT_ERROR_DETAIL(token, codes) {#token, codes},
#include <ProtocolFrames.def>
};

// Whether a space-separated list holds the word.
bool listsWord(const char* list, const char* word)
{
    size_t length = strlen(word);
    for (const char* at = strstr(list, word); at; at = strstr(at + 1, word)) {
        bool starts = at == list || at[-1] == ' ';
        bool ends = at[length] == '\0' || at[length] == ' ';
        if (starts && ends) {
            return true;
        }
    }
    return false;
}

bool isFrameType(const char* text)
{
    size_t length = strlen(text);
    return length >= 2 && length <= Protocol::MAX_TYPE_LENGTH && strspn(text, "ABCDEFGHIJKLMNOPQRSTUVWXYZ") == length;
}

// An ERR's code is one of ProtocolFrames.def's, and its detail a token the
// file gives that code or, for a code it gives none, a frame TYPE.
void checkErrorAgainstTable(const FrameParser& frame)
{
    const char* code = frame.field(1);
    bool defined = false;
    for (const char* known : ERROR_CODES) {
        defined = defined || strcmp(known, code) == 0;
    }
    require(defined, "the board sent an ERR code ProtocolFrames.def does not define");
    const char* detail = frame.field(2);
    bool codeHasTokens = false;
    for (const ErrorDetailSpec& spec : ERROR_DETAILS) {
        if (listsWord(spec.codes, code)) {
            codeHasTokens = true;
            if (strcmp(spec.token, detail) == 0) {
                return;
            }
        }
    }
    require(!codeHasTokens && isFrameType(detail),
            "the board sent an ERR detail ProtocolFrames.def does not give its code");
}

const FrameSpec* specOf(const char* type)
{
    for (const FrameSpec& spec : FRAME_SPECS) {
        if (strcmp(spec.tag, type) == 0) {
            return &spec;
        }
    }
    return 0;
}

// The 32-bit numbers a board writes: optional '-' and decimal digits.
bool isBoardInteger(const char* text)
{
    const char* digits = text[0] == '-' ? text + 1 : text;
    size_t length = strlen(digits);
    if (length == 0 || length > 10 || strspn(digits, "0123456789") != length) {
        return false;
    }
    long long value = strtoll(text, 0, 10);
    return value >= INT32_MIN && value <= (long long)UINT32_MAX;
}

void checkAgainstTable(const FrameParser& frame)
{
    const FrameSpec* spec = specOf(frame.type());
    require(spec != 0 && strcmp(spec->role, "COMMAND") != 0, "the board sent a type that is no board frame");
    uint8_t index = 0;
    for (const char* kind = strchr(spec->fields, ':'); kind; kind = strchr(kind + 1, ':'), ++index) {
        require(index < frame.fieldCount(), "a board frame has fewer fields than ProtocolFrames.def");
        float real = 0.0f;
        if (kind[1] == 'i') {
            require(isBoardInteger(frame.field(index)), "an integer field of a board frame is no integer");
        } else if (kind[1] == 'f') {
            require(frame.fieldFloat(index, real), "a float field of a board frame is no number");
        }
    }
    require(frame.fieldCount() == index, "a board frame has more fields than ProtocolFrames.def");
    if (frame.typeIs(Protocol::Tag::ERR)) {
        checkErrorAgainstTable(frame);
    }
}

// The commands the board read (as its own parser saw them), which it still
// has to answer, and how many bad lines it could report.
class CommandLog {
public:
    void restart()
    {
        parser_ = FrameParser();
        unanswered_.clear();
        badLines_ = 0;
        badFrameReports_ = 0;
    }

    void read(const std::string& bytes)
    {
        for (char c : bytes) {
            uint16_t malformed = parser_.malformedCount();
            if (parser_.feed(c) && !Protocol::isBoardFrame(parser_.type())) {
                unanswered_.push_back(Command{parser_.seq(), parser_.type()});
            }
            if (parser_.malformedCount() != malformed) {
                ++badLines_;
            }
        }
    }

    // An ACK (with the command's type) or an ERR (type 0) for command `seq`.
    void answered(int64_t seq, const char* type)
    {
        require(!unanswered_.empty(), "the board answered a command it did not get");
        const Command& oldest = unanswered_.front();
        require(seq == oldest.seq, "an answer carries another SEQ than the command's");
        require(type == 0 || oldest.type == type, "an ACK carries another type than the command's");
        unanswered_.pop_front();
    }

    void reportedBadFrame()
    {
        require(++badFrameReports_ <= badLines_, "the board reported more BAD_FRAMEs than it read bad lines");
    }

    void requireAllAnswered() const
    {
        require(unanswered_.empty(), "a command was not answered in the loop pass that read it");
    }

private:
    struct Command {
        uint16_t seq;
        std::string type;
    };

    FrameParser parser_;
    std::deque<Command> unanswered_;
    uint32_t badLines_ = 0;
    uint32_t badFrameReports_ = 0;
};

// Checks the byte stream the board sends, frame by frame.
class BoardOutput {
public:
    void restart()
    {
        parser_ = FrameParser();
        inLine_ = false;
        awaitingLf_ = false;
        haveSeq_ = false;
    }

    void sent(const std::string& bytes, CommandLog& commands, Board& board)
    {
        for (char c : bytes) {
            if (awaitingLf_) {
                require(c == '\n', "a board line ends in CR without LF");
                awaitingLf_ = false;
                inLine_ = false;
                continue;
            }
            if (!inLine_) {
                require(c == '$', "the board sent a byte outside a frame");
                inLine_ = true;
            }
            require(c != '\n', "a board line ends in LF without CR");
            bool complete = parser_.feed(c);
            require(parser_.malformedCount() == 0, "the board sent a line its own parser rejects");
            if (c == '\r') {
                require(complete, "the board sent a line its own parser does not accept");
                awaitingLf_ = true;
                frameSent(commands, board);
            }
        }
    }

private:
    void frameSent(CommandLog& commands, Board& board)
    {
        checkAgainstTable(parser_);
        bool isError = parser_.typeIs(Protocol::Tag::ERR);
        require(!isError || strcmp(parser_.field(1), "FRAME_ENCODE") != 0,
                "the board built a frame it could not encode (ERR FRAME_ENCODE)");
        require(!haveSeq_ || parser_.seq() == (uint16_t)(lastSeq_ + 1), "the board's SEQ skipped or repeated");
        haveSeq_ = true;
        lastSeq_ = parser_.seq();
        if (parser_.typeIs(Protocol::Tag::ACK)) {
            commands.answered(BoardHarness::integer(parser_, 0), parser_.field(1));
        } else if (isError && BoardHarness::integer(parser_, 0) >= 0) {
            commands.answered(BoardHarness::integer(parser_, 0), 0);
        } else if (isError && strcmp(parser_.field(1), "BAD_FRAME") == 0) {
            commands.reportedBadFrame();
        }
        board.sentFrame(parser_);
    }

    FrameParser parser_;
    bool inLine_ = false;
    bool awaitingLf_ = false;
    bool haveSeq_ = false;
    uint16_t lastSeq_ = 0;
};

class Runner {
public:
    explicit Runner(Board& board) : board_(board) {}

    void run(const uint8_t* data, size_t size)
    {
        ArduinoShim::powerOn();
        board_.powerOn();
        RecordReader records(data, size);
        const uint8_t* record = 0;
        size_t length = 0;
        while (passes_ < MAX_PASSES && records.next(record, length)) {
            if (length > 0 && record[0] == WORLD_RECORD) {
                changeWorld(record + 1, length - 1);
            } else {
                std::string bytes;
                encoder_.encode(record, length, bytes);
                sendToBoard(bytes);
            }
        }
    }

private:
    void changeWorld(const uint8_t* tokens, size_t length)
    {
        uint32_t stepMs = 1;
        int32_t repeat = 1;
        size_t at = 0;
        while (at < length && tokens[at] != WORLD_BYTES) {
            char key = (char)tokens[at++];
            if (!((key >= 'a' && key <= 'z') || (key >= 'A' && key <= 'Z'))) {
                continue;
            }
            int32_t value = readNumber(tokens, length, at);
            if (key == 't') {
                stepMs = (uint32_t)value;
            } else if (key == 'r') {
                repeat = value < 0 ? 0 : value > BoardHarness::MAX_REPEAT ? BoardHarness::MAX_REPEAT : value;
            } else if (key == 'R') {
                resetFlags_ = (uint8_t)value;
                booted_ = false;
            } else {
                board_.setWorld(key, value, booted_);
            }
        }
        if (at < length) {
            board_.setWorldBytes(tokens + at + 1, length - at - 1, booted_);
        }
        for (int32_t i = 0; i < repeat && passes_ < MAX_PASSES; ++i) {
            pass(stepMs, 0);
        }
    }

    // An optional '-' and digits from `at`, saturated to int32_t; 0 if none.
    static int32_t readNumber(const uint8_t* text, size_t length, size_t& at)
    {
        bool negative = at < length && text[at] == '-';
        at += negative ? 1 : 0;
        int64_t value = 0;
        for (; at < length && text[at] >= '0' && text[at] <= '9'; ++at) {
            value = value * 10 + (text[at] - '0');
            if (value > INT32_MAX) {
                value = INT32_MAX;
            }
        }
        return (int32_t)(negative ? -value : value);
    }

    // At the line's pace, one pass per millisecond, until the board has read
    // it all; bytes that find its receive buffer full are lost, as on the AVR.
    void sendToBoard(const std::string& bytes)
    {
        size_t at = 0;
        while ((at < bytes.size() || ArduinoShim::serialBytesWaiting() > 0) && passes_ < MAX_PASSES) {
            size_t count = bytes.size() - at < SERIAL_BYTES_PER_MS ? bytes.size() - at : SERIAL_BYTES_PER_MS;
            pass(1, &bytes, at, count);
            at += count;
        }
    }

    void pass(uint32_t stepMs, const std::string* bytes, size_t from = 0, size_t count = 0)
    {
        if (!booted_) {
            boot();
        }
        ArduinoShim::advanceMillis(stepMs);
        // Between passes the sketch idles for at most a timer tick on the AVR;
        // a step past its watchdog's timeout is a stall, which resets the
        // board before loop() could see the whole step as elapsed time.
        if (ArduinoShim::watchdogExpired()) {
            resetByWatchdog();
        }
        for (size_t i = 0; i < count; ++i) {
            ArduinoShim::receiveSerial((uint8_t)(*bytes)[from + i]);
        }
        loop();
        ++passes_;
        collect();
        if (ArduinoShim::watchdogExpired()) {
            resetFlags_ = _BV(WDRF);
            booted_ = false;
        }
    }

    void resetByWatchdog()
    {
        resetFlags_ = _BV(WDRF);
        boot();
    }

    void boot()
    {
        commands_.requireAllAnswered();
        SketchState::restore();
        ArduinoShim::reset();
        MCUSR = resetFlags_;
        bootFlags = resetFlags_;
        if (captureResetFlags) {
            captureResetFlags();
        }
        commands_.restart();
        output_.restart();
        board_.boot();
        booted_ = true;
        setup();
        collect();
    }

    void collect()
    {
        commands_.read(ArduinoShim::takeSerialRead());
        output_.sent(ArduinoShim::takeSerialWritten(), commands_, board_);
        commands_.requireAllAnswered();
        board_.afterPass();
    }

    Board& board_;
    SerialLineEncoder encoder_;
    CommandLog commands_;
    BoardOutput output_;
    uint8_t resetFlags_ = POWER_ON_FLAGS;
    bool booted_ = false;
    uint32_t passes_ = 0;
};

}  // namespace

extern "C" int LLVMFuzzerInitialize(int*, char***)
{
    LineChecksum::checkAgainstWriter();
    SketchState::capture();
    return 0;
}

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size)
{
    std::unique_ptr<Board> board = makeBoard();
    Runner(*board).run(data, size);
    return 0;
}

uint8_t BoardHarness::bootResetFlags()
{
    return bootFlags;
}

const char* BoardHarness::text(const FrameParser& frame, uint8_t index)
{
    const char* field = frame.field(index);
    return field ? field : "";
}

int64_t BoardHarness::integer(const FrameParser& frame, uint8_t index)
{
    return strtoll(text(frame, index), 0, 10);
}
