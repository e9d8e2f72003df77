// Runs one sketch, compiled against the Arduino shim, from a fuzz input as a
// host and the board's surroundings would, and checks everything the board
// sends. The input is records (frame_input.h): serial records go to the
// board at 115200 baud, one loop() pass per millisecond while bytes arrive;
// a record starting with '~' changes the world and runs loop passes:
//
//   ~ then tokens of a letter and an optional signed number, e.g. "~i600 t250 r40"
//     t  milliseconds the clock advances before each pass (default 1)
//     r  passes to run (default 1, at most MAX_REPEAT)
//     R  reset the board now, with these MCUSR flags (a power-on has PORF)
//     any other letter: the board's own (Board::setWorld)
//   A watchdog the sketch stopped feeding resets the board with WDRF once
//   its timeout has passed (checked after each pass).
//   and after an optional '|', bytes for Board::setWorldBytes.
//
// Changes made before the first pass (the board boots lazily) are in place
// when setup() runs. Checked for every board:
// - every byte it sends belongs to a "$...\r\n" line that its own
//   FrameParser accepts, of a BOARD type of ProtocolFrames.def with exactly
//   its fields, numbers where the table says so; an ERR's code and detail
//   token defined there for each other (a code without tokens: a TYPE);
// - SEQ counts up by one from boot, so no built frame is dropped;
// - every command it reads is answered with ACK or ERR carrying the
//   command's SEQ (ACK: and type) in the same loop pass, in order; frames of
//   board types are ignored; BAD_FRAME reports never outnumber bad lines.
#ifndef THERMOTILT_FUZZ_BOARD_HARNESS_H
#define THERMOTILT_FUZZ_BOARD_HARNESS_H

#include <Protocol.h>

#include <stddef.h>
#include <stdint.h>
#include <memory>

class Board {
public:
    virtual ~Board() {}
    // Once per input, after ArduinoShim::powerOn(): attach devices, set defaults.
    virtual void powerOn() {}
    // A world token that is not the harness's; `booted` says whether setup() ran.
    virtual void setWorld(char key, int32_t value, bool booted) = 0;
    virtual void setWorldBytes(const uint8_t* data, size_t length, bool booted)
    {
        (void)data, (void)length, (void)booted;
    }
    // setup() is about to run, after a power-on or a reset.
    virtual void boot() {}
    // Each frame the board sent, in order, after the common checks.
    virtual void sentFrame(const FrameParser& frame) { (void)frame; }
    // After setup() and after each loop pass.
    virtual void afterPass() {}
};

// Each board target's own: a fresh Board for one input. The harness defines
// the libFuzzer entry points around it.
std::unique_ptr<Board> makeBoard();

namespace BoardHarness {

const int32_t MAX_REPEAT = 5000;

// The MCUSR flags the board booted with last (valid in Board::boot()).
uint8_t bootResetFlags();

// Field `index` of a frame that passed the common checks, as text, or as an
// integer (the common checks made sure it is one when the table says so).
const char* text(const FrameParser& frame, uint8_t index);
int64_t integer(const FrameParser& frame, uint8_t index);

}  // namespace BoardHarness

#endif
