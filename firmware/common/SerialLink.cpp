#include "SerialLink.h"

#include <Arduino.h>
#include <avr/sleep.h>
#include <string.h>

#include "Uart0.h"
#include "Watchdog.h"

namespace Detail = Protocol::ErrorDetail;

// BAD_FRAME's detail for each reason, in MalformedReason's order.
static const char* const MALFORMED_NAMES[] PROGMEM = {
    "UNKNOWN",  // MALFORMED_NONE, never reported
#define THERMOTILT_MALFORMED_REASON(token) Detail::token,
#include <ProtocolFrames.def>
};

SerialLink::SerialLink()
    : writer_(line_, sizeof line_),
      pending_(0),
      pendingLength_(0),
      nextSeq_(0),
      malformedSeen_(0),
      encodeFailures_(0),
      lastMalformedReportMs_(0),
      malformedReported_(false),
      lastHostFrameMs_(0)
{
}

void SerialLink::begin()
{
    Uart0::begin(SERIAL_BAUD);
}

bool SerialLink::poll(uint32_t nowMs)
{
    for (uint8_t read = 0; read < MAX_BYTES_PER_POLL && Uart0::available() > 0; ++read) {
        bool complete = parser_.feed((char)Uart0::read());
        if (parser_.malformedCount() != malformedSeen_) {
            malformedSeen_ = parser_.malformedCount();
            if (!malformedReported_ || nowMs - lastMalformedReportMs_ >= MALFORMED_REPORT_MS) {
                malformedReported_ = true;
                lastMalformedReportMs_ = nowMs;
                report(Protocol::Error::BAD_FRAME,
                       (const char*)pgm_read_ptr(&MALFORMED_NAMES[parser_.lastMalformedReason()]));
            }
        }
        if (complete && !Protocol::isBoardFrame(parser_.type())) {
            lastHostFrameMs_ = nowMs;
            return true;
        }
    }
    return false;
}

void SerialLink::dispatch(const Protocol::Command* commands, uint8_t count)
{
    Protocol::Command command;
    if (!Protocol::findCommand(commands, count, parser_.type(), command)) {
        reject(Protocol::Error::UNKNOWN_CMD, parser_.type());
    } else if (parser_.fieldCount() < command.minFields) {
        reject(Protocol::Error::BAD_ARG, command.fieldsDetail);
    } else {
        command.handler(parser_);
    }
}

void SerialLink::send()
{
    const char* text = writer_.finish();
    if (text) {
        pending_ = text;
        pendingLength_ = (uint8_t)strlen(text);
        writePending();
        return;
    }
    ++encodeFailures_;
    char type[Protocol::MAX_TYPE_LENGTH + 1];
    size_t typeLength = strcspn(line_ + 1, ",");
    if (typeLength > Protocol::MAX_TYPE_LENGTH) {
        typeLength = Protocol::MAX_TYPE_LENGTH;
    }
    memcpy(type, line_ + 1, typeLength);
    type[typeLength] = '\0';
    // An ERR always fits; the guard keeps a broken writer from recursing.
    if (strcmp_P(type, Protocol::Frame::ERR.tag) != 0) {
        report(Protocol::Error::FRAME_ENCODE, type);
    }
}

void SerialLink::writePending()
{
    if (!pendingLength_) {
        return;
    }
    uint8_t room = Uart0::availableForWrite();
    uint8_t count = room < pendingLength_ ? room : pendingLength_;
    Uart0::write(pending_, count);
    pending_ += count;
    pendingLength_ -= count;
}

bool SerialLink::hasWork() const
{
    if (Uart0::available() > 0) {
        return true;
    }
    if (!pendingLength_) {
        return false;
    }
    uint8_t room = Uart0::availableForWrite();
    return room >= pendingLength_ || room >= Uart0::RING_SIZE - 1;
}

void SerialLink::finishPending()
{
    if (pendingLength_) {
        Uart0::write(pending_, pendingLength_);
        pendingLength_ = 0;
    }
}

void SerialLink::flush()
{
    finishPending();
    Uart0::flush();
}

void SerialLink::sendVersion(const char* device, const char* firmwareVersion)
{
    FrameWriter& frame = start(Protocol::Frame::VER);
    frame.addText(device);
    frame.addText(firmwareVersion);
    frame.addUnsigned(Protocol::VERSION);
    frame.addText(resetCauseName());
    send();
}

void SerialLink::announceStart(const char* device, const char* firmwareVersion)
{
    sendVersion(device, firmwareVersion);
    if (resetWasAbnormal()) {
        report(Protocol::Error::RESET, resetCauseName());
    }
    // Whole before setup() goes on to the sensor: a host reads the
    // restart's VER and its ERR RESET together.
    finishPending();
}

void SerialLink::acknowledge()
{
    FrameWriter& frame = start(Protocol::Frame::ACK);
    frame.addUnsigned(parser_.seq());
    frame.addText(parser_.type());
    send();
}

void SerialLink::sendError(int32_t commandSeq, const char* code, const char* detail)
{
    FrameWriter& frame = start(Protocol::Frame::ERR);
    frame.addInt(commandSeq);
    frame.addText(code);
    frame.addText(detail);
    send();
}

void idleUntilInterrupt()
{
    set_sleep_mode(SLEEP_MODE_IDLE);
    sleep_mode();
}
