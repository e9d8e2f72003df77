// The real thermal_chamber sketch on the Arduino shim (board_harness.h),
// with its thermistor inputs set by the input:
//   i, o  inner (A0) and outer (A1) thermistor ADC readings, 0..1023
// Besides the common checks, the L298N must be safe and truthfully reported:
// - no PWM on ENA while the last CHS frame says phase F (until a CLEAR is
//   acknowledged), nor after a STOP was acknowledged;
// - IN1/IN2 change only while ENA is off;
// - a CHS frame's pwm and dir are what the pins show when it is sent.
#include <ChamberControl.h>
#include <Protocol.h>

#include "arduino_shim/ArduinoShim.h"
#include "board_harness.h"
#include "invariant.h"

#include <string.h>

namespace {

const uint8_t INNER_CHANNEL = 0;
const uint8_t OUTER_CHANNEL = 1;
const int32_t ADC_MAX = 1023;
const uint8_t CHS_PHASE = 1;
const uint8_t CHS_PWM = 6;
const uint8_t CHS_DIR = 7;

uint8_t enaDuty()
{
    return ArduinoShim::pin(kL298nEnaPin).duty;
}

bool isHigh(uint8_t pin)
{
    return ArduinoShim::pin(pin).duty != 0;
}

void directionPinWritten(uint8_t pin, const ArduinoShim::PinState& before)
{
    if ((pin == kL298nIn1Pin || pin == kL298nIn2Pin) && ArduinoShim::pin(pin).duty != before.duty) {
        require(enaDuty() == 0, "an L298N direction pin changed while ENA was on");
    }
}

Direction directionOf(char letter)
{
    switch (letter) {
    case 'H': return Direction::Heat;
    case 'C': return Direction::Cool;
    default: return Direction::Off;
    }
}

class Chamber : public Board {
public:
    void powerOn() override { ArduinoShim::observePins(directionPinWritten); }

    void setWorld(char key, int32_t value, bool) override
    {
        uint16_t adc = (uint16_t)(value < 0 ? 0 : value > ADC_MAX ? ADC_MAX : value);
        if (key == 'i') {
            ArduinoShim::setAnalogInput(INNER_CHANNEL, adc);
        } else if (key == 'o') {
            ArduinoShim::setAnalogInput(OUTER_CHANNEL, adc);
        }
    }

    void boot() override
    {
        lastPhase_ = 0;
        stopAcknowledged_ = false;
        statusSent_ = false;
    }

    void sentFrame(const FrameParser& frame) override
    {
        if (frame.typeIs(Protocol::Tag::CHS)) {
            lastPhase_ = BoardHarness::text(frame, CHS_PHASE)[0];
            statusSent_ = true;
            reported_.pwm = (uint8_t)BoardHarness::integer(frame, CHS_PWM);
            reported_.direction = directionOf(BoardHarness::text(frame, CHS_DIR)[0]);
        } else if (frame.typeIs(Protocol::Tag::ACK)) {
            const char* command = BoardHarness::text(frame, 1);
            stopAcknowledged_ = strcmp(command, Protocol::Tag::STOP) == 0;
            // Faults latch until a CLEAR is accepted; then a START may drive
            // the bridge before the next CHS frame.
            if (strcmp(command, Protocol::Tag::CLEAR) == 0) {
                lastPhase_ = 0;
            }
        }
    }

    void afterPass() override
    {
        require(lastPhase_ != 'F' || enaDuty() == 0, "the bridge is on while the last CHS frame says phase F");
        require(!stopAcknowledged_ || enaDuty() == 0, "the bridge is on after STOP was acknowledged");
        if (statusSent_) {
            L298nOutputs expected = l298nPins(reported_);
            require(enaDuty() == expected.enaDuty && isHigh(kL298nIn1Pin) == expected.in1High &&
                        isHigh(kL298nIn2Pin) == expected.in2High,
                    "a CHS frame reports another drive than the L298N pins show");
        }
        stopAcknowledged_ = false;
        statusSent_ = false;
    }

private:
    char lastPhase_ = 0;
    bool stopAcknowledged_ = false;
    bool statusSent_ = false;
    DriveCommand reported_ = {0, Direction::Off};
};

}  // namespace

std::unique_ptr<Board> makeBoard()
{
    return std::unique_ptr<Board>(new Chamber);
}
