// The board's end of the serial protocol (docs/protocol.md): parses command
// frames from Serial, numbers every frame it sends, and answers commands with
// ACK or ERR. Malformed input is counted by the parser and reported, never
// acted on.
#ifndef THERMOTILT_SERIAL_LINK_H
#define THERMOTILT_SERIAL_LINK_H

#include <Protocol.h>

// Both boards and the host use one speed; see docs/protocol.md.
const unsigned long SERIAL_BAUD = 115200;

class SerialLink {
public:
    SerialLink();

    void begin();

    // Reads what Serial holds; true when a command frame is ready in command().
    // A malformed line is answered with an unsolicited ERR.
    bool poll();
    const FrameParser& command() const { return parser_; }
    bool commandIs(const char* tag) const { return parser_.typeIs(tag); }

    // Starts a frame with the next sequence number; add fields, then send().
    FrameWriter& start(const char* type);
    void send();

    // The VER frame: which firmware this is and which protocol it speaks.
    void sendVersion(const char* device, const char* firmwareVersion);

    void acknowledge();
    void reject(const char* code, const char* detail);
    void report(const char* code, const char* detail);

private:
    void sendError(int32_t commandSeq, const char* code, const char* detail);

    char line_[Protocol::LINE_BUFFER_SIZE];
    FrameWriter writer_;
    FrameParser parser_;
    uint16_t nextSeq_;
    uint16_t malformedSeen_;
};

// Sleeps in idle mode until the next interrupt (the 1 ms timer tick or a
// received byte), so the board does nothing between ticks.
void idleUntilInterrupt();

#endif
