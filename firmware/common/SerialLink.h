// The board's end of the serial protocol (docs/protocol.md): parses command
// frames from the serial port (Uart0), numbers every frame it sends, and
// answers commands with ACK or ERR. Malformed input is counted by the
// parser and reported, never acted on. Nothing the host sends can hold the board's loop: each poll
// reads a bounded number of bytes and malformed lines are reported at a
// bounded rate.
#ifndef THERMOTILT_SERIAL_LINK_H
#define THERMOTILT_SERIAL_LINK_H

#include <CommandTable.h>
#include <Protocol.h>

// Both boards and the host use one speed; see docs/protocol.md.
const unsigned long SERIAL_BAUD = 115200;
// Fewer than Uart0's 64-byte receive ring holds, so a flood is read over
// several loop passes with the control work in between.
const uint8_t MAX_BYTES_PER_POLL = 32;
// A line-rate flood of short bad lines would need ~15x the line's capacity
// to answer each one; one BAD_FRAME a second says enough.
const uint32_t MALFORMED_REPORT_MS = 1000;

class SerialLink {
public:
    SerialLink();

    void begin();

    // Reads up to MAX_BYTES_PER_POLL bytes; true when a command frame is
    // ready for dispatch(). Frames a board sends (IMU, ACK, ERR, ...) are
    // ignored, so an echoing terminal cannot start a conversation of the
    // board with itself. A malformed line is answered with an unsolicited
    // ERR, at most once per MALFORMED_REPORT_MS. nowMs is the board's clock.
    bool poll(uint32_t nowMs);

    // Carries out the command poll() found with its entry of commands, a
    // table in program memory: ERR UNKNOWN_CMD when it has none, ERR BAD_ARG
    // when the command has fewer fields than the entry needs, else the
    // entry's handler, which answers.
    void dispatch(const Protocol::Command* commands, uint8_t count);
    template <uint8_t count>
    void dispatch(const Protocol::Command (&commands)[count])
    {
        dispatch(commands, count);
    }

    // nowMs of the poll() that read the last valid frame from the host.
    uint32_t lastHostFrameMs() const { return lastHostFrameMs_; }

    // Starts a frame with the next sequence number; add the type's fields,
    // then send(). A frame that does not encode (too long, a bad character,
    // another field count than its type's) is not sent; it is counted and
    // reported as ERR FRAME_ENCODE with its type. Like reject() and report(),
    // always inline: a call that takes a FrameType or ErrorCode whole reads
    // the constant from memory, which on the AVR keeps it in RAM.
    __attribute__((always_inline)) FrameWriter& start(Protocol::FrameType type)
    {
        finishPending();
        writer_.begin(type, nextSeq_++);
        return writer_;
    }
    // Hands the frame to Uart0 as far as its transmit ring has room; the
    // rest waits for writePending(), so the loop never spins on the UART (an
    // IMU frame is longer than the 64-byte ring). The next start(), or
    // flush(), writes what is still waiting first, so frames never interleave.
    void send();
    // Call every loop pass: more of a frame that did not fit.
    void writePending();
    // Everything sent is on the line (before a reset cuts it).
    void flush();
    // Whether a loop pass would find something to do here: a received byte,
    // or room in Uart0's ring for the rest of a waiting frame.
    bool hasWork() const;
    uint16_t encodeFailures() const { return encodeFailures_; }

    // The VER frame: which firmware, which protocol, why the board last reset.
    void sendVersion(const char* device, const char* firmwareVersion);
    // VER at start-up, and ERR RESET after a watchdog or brown-out reset.
    void announceStart(const char* device, const char* firmwareVersion);

    void acknowledge();
    // ERR answering the current command, and ERR on the board's own account
    // (cmd_seq -1); codes and fixed details come from Protocol::Error and
    // Protocol::ErrorDetail.
    __attribute__((always_inline)) void reject(Protocol::ErrorCode code, const char* detail)
    {
        sendError(parser_.seq(), code.text, detail);
    }
    __attribute__((always_inline)) void report(Protocol::ErrorCode code, const char* detail)
    {
        sendError(-1, code.text, detail);
    }

private:
    void sendError(int32_t commandSeq, const char* code, const char* detail);
    void finishPending();

    char line_[Protocol::LINE_BUFFER_SIZE];
    FrameWriter writer_;
    // What of writer_'s last frame Uart0 has not taken yet.
    const char* pending_;
    uint8_t pendingLength_;
    FrameParser parser_;
    uint16_t nextSeq_;
    uint16_t malformedSeen_;
    uint16_t encodeFailures_;
    uint32_t lastMalformedReportMs_;
    bool malformedReported_;
    uint32_t lastHostFrameMs_;
};

// Sleeps in idle mode until the next interrupt (the 1 ms timer tick or a
// received byte), so the board does nothing between ticks.
void idleUntilInterrupt();

#endif
