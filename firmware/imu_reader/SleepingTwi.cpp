#include "SleepingTwi.h"

#include <Arduino.h>
#include <avr/interrupt.h>
#include <avr/sleep.h>
#include <util/twi.h>

#include "Clock.h"

namespace {

enum Outcome : uint8_t { BUSY, DONE, FAILED };

// Shared with the interrupt, which moves the transfer on byte by byte.
volatile Outcome outcome = DONE;
volatile uint8_t addressWrite;
const uint8_t* volatile sendNext;
volatile uint8_t sendLeft;
uint8_t* volatile receiveNext;
volatile uint8_t receiveLeft;

// Writing TWINT clears it: the hardware then does what the other bits say.
const uint8_t GO = _BV(TWEN) | _BV(TWIE) | _BV(TWINT);

// TWINT is not set again after a STOP, so nothing follows this interrupt.
void stopWith(Outcome result)
{
    TWCR = GO | _BV(TWSTO);
    outcome = result;
}

}  // namespace

ISR(TWI_vect)
{
    switch (TW_STATUS) {
    case TW_START:
        TWDR = addressWrite;
        TWCR = GO;
        break;
    case TW_REP_START:
        TWDR = addressWrite | TW_READ;
        TWCR = GO;
        break;
    case TW_MT_SLA_ACK:
    case TW_MT_DATA_ACK:
        if (sendLeft) {
            TWDR = *sendNext;
            sendNext = sendNext + 1;
            --sendLeft;
            TWCR = GO;
        } else if (receiveLeft) {
            TWCR = GO | _BV(TWSTA);
        } else {
            stopWith(DONE);
        }
        break;
    case TW_MR_DATA_ACK:
        *receiveNext = TWDR;
        receiveNext = receiveNext + 1;
        --receiveLeft;
        // fall through: acknowledge every byte but the last
    case TW_MR_SLA_ACK: TWCR = receiveLeft > 1 ? (GO | _BV(TWEA)) : GO; break;
    case TW_MR_DATA_NACK:
        *receiveNext = TWDR;
        receiveLeft = 0;
        stopWith(DONE);
        break;
    case TW_MT_ARB_LOST:
        // Another master has the bus: let go of it without a STOP.
        TWCR = GO;
        outcome = FAILED;
        break;
    default:
        // An address or data byte not acknowledged, or a bus error (the
        // datasheet's recovery from that is a STOP too).
        stopWith(FAILED);
        break;
    }
}

void SleepingTwi::begin(uint32_t clockHz, uint8_t timeoutMs)
{
    digitalWrite(SDA, HIGH);
    digitalWrite(SCL, HIGH);
    bitRate_ = (uint8_t)((F_CPU / clockHz - 16) / 2);
    timeoutMs_ = timeoutMs;
    reset();
}

void SleepingTwi::reset()
{
    TWCR = 0;
    TWSR = 0;
    TWBR = bitRate_;
    TWCR = _BV(TWEN);
    outcome = DONE;
}

bool SleepingTwi::writeRegister(uint8_t address7, uint8_t reg, uint8_t value)
{
    const uint8_t bytes[2] = {reg, value};
    return transfer(address7, bytes, 2, 0, 0);
}

bool SleepingTwi::readRegisters(uint8_t address7, uint8_t firstReg, uint8_t* out, uint8_t count)
{
    return count > 0 && transfer(address7, &firstReg, 1, out, count);
}

bool SleepingTwi::transfer(uint8_t address7, const uint8_t* send, uint8_t sendCount, uint8_t* receive,
                           uint8_t receiveCount)
{
    uint32_t startMs = Clock::tickMs();
    // The last transfer's STOP is still on the bus for a few microseconds.
    while (TWCR & _BV(TWSTO)) {
        if (Clock::tickMs() - startMs >= timeoutMs_) {
            reset();
            return false;
        }
    }
    addressWrite = (uint8_t)(address7 << 1);
    sendNext = send;
    sendLeft = sendCount;
    receiveNext = receive;
    receiveLeft = receiveCount;
    outcome = BUSY;
    TWCR = GO | _BV(TWSTA);
    set_sleep_mode(SLEEP_MODE_IDLE);
    for (;;) {
        noInterrupts();
        if (outcome != BUSY) {
            interrupts();
            return outcome == DONE;
        }
        if (Clock::tickMs() - startMs >= timeoutMs_) {
            interrupts();
            reset();
            return false;
        }
        sleep_enable();
        // SEI's next instruction runs before any interrupt: no wake-up is lost.
        interrupts();
        sleep_cpu();
        sleep_disable();
    }
}
