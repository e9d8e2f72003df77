// Thermal chamber (Arduino Mega 2560): two NTC thermistors, the programmed
// temperature staircase and the proportional controller driving a Peltier
// cell through an L298N; CHS status frames on the serial port.
#include <Arduino.h>

#include <ChamberControl.h>
#include <Program.h>
#include <Protocol.h>
#include <Thermistor.h>

#include "SerialLink.h"

namespace {

const char FIRMWARE_VERSION[] = "0.1.0";
// The reference (inner) face is the controlled one; the outer face is the
// heatsink side, watched because each face's temperature depends on the other.
const uint8_t INNER_THERMISTOR_PIN = A0;
const uint8_t OUTER_THERMISTOR_PIN = A1;
const uint32_t CONTROL_PERIOD_MS = 250;
const uint8_t CONTROL_TICKS_PER_STATUS = 4;

enum Fault : uint8_t { NO_FAULT, INNER_OPEN, INNER_SHORT, OUTER_OPEN, OUTER_SHORT };

SerialLink link;
Thermistor thermistor;
ChamberController controller;
TemperatureProgram program;
bool running = false;
bool proportionalOnly = true;
uint32_t programStartMs = 0;
uint32_t lastControlMs = 0;
uint8_t ticksSinceStatus = 0;
Fault fault = NO_FAULT;
ThermistorReading inner = {NAN, ThermistorStatus::Ok};
ThermistorReading outer = {NAN, ThermistorStatus::Ok};
ProgramState programState;
DriveCommand drive = {0, Direction::Off};

const char* faultName(Fault value)
{
    switch (value) {
    case INNER_OPEN: return "INNER_OPEN";
    case INNER_SHORT: return "INNER_SHORT";
    case OUTER_OPEN: return "OUTER_OPEN";
    case OUTER_SHORT: return "OUTER_SHORT";
    default: return "OK";
    }
}

// Out of plausible range reads like an open circuit: no trustworthy value.
Fault faultOf(const ThermistorReading& reading, Fault open, Fault shorted)
{
    switch (reading.status) {
    case ThermistorStatus::Ok: return NO_FAULT;
    case ThermistorStatus::Short: return shorted;
    default: return open;
    }
}

// The paper estimates each face "as the average of two successive measurements".
ThermistorReading readFace(uint8_t pin)
{
    uint16_t first = (uint16_t)analogRead(pin);
    uint16_t second = (uint16_t)analogRead(pin);
    return thermistor.readAveraged(first, second);
}

void applyDrive(const DriveCommand& command)
{
    drive = command;
    L298nOutputs outputs = l298nPins(command);
    // Direction changes only with the bridge disabled, so the Peltier never
    // sees a short reversal at full duty.
    analogWrite(kL298nEnaPin, 0);
    digitalWrite(kL298nIn1Pin, outputs.in1High ? HIGH : LOW);
    digitalWrite(kL298nIn2Pin, outputs.in2High ? HIGH : LOW);
    analogWrite(kL298nEnaPin, outputs.enaDuty);
}

void stopProgram()
{
    running = false;
    controller.reset();
    applyDrive({0, Direction::Off});
}

char phaseLetter()
{
    if (fault != NO_FAULT) {
        return 'F';
    }
    if (!running) {
        return 'I';
    }
    switch (programState.phase) {
    case ProgramPhase::Warming: return 'W';
    case ProgramPhase::Cooling: return 'C';
    case ProgramPhase::Rest: return 'R';
    default: return 'D';
    }
}

char directionLetter(Direction direction)
{
    switch (direction) {
    case Direction::Heat: return 'H';
    case Direction::Cool: return 'C';
    default: return 'O';
    }
}

void sendStatus(uint32_t now)
{
    FrameWriter& frame = link.start(Protocol::Tag::CHS);
    frame.addUnsigned(now);
    frame.addChar(phaseLetter());
    frame.addUnsigned(running ? programState.step : 0);
    frame.addFixed(running && programState.driveEnabled ? programState.setpoint_c : NAN, 2);
    frame.addFixed(inner.celsius, 2);
    frame.addFixed(outer.celsius, 2);
    frame.addUnsigned(drive.pwm);
    frame.addChar(directionLetter(drive.direction));
    frame.addText(faultName(fault));
    link.send();
}

void controlTick(uint32_t now)
{
    inner = readFace(INNER_THERMISTOR_PIN);
    outer = readFace(OUTER_THERMISTOR_PIN);
    Fault detected = faultOf(inner, INNER_OPEN, INNER_SHORT);
    if (detected == NO_FAULT) {
        detected = faultOf(outer, OUTER_OPEN, OUTER_SHORT);
    }
    if (detected != fault) {
        fault = detected;
        if (fault != NO_FAULT) {
            // A program does not resume by itself after a sensor fault.
            stopProgram();
            link.report("THERMISTOR", faultName(fault));
        }
    }
    if (running) {
        programState = program.stateAt(now - programStartMs);
        if (programState.phase == ProgramPhase::Done) {
            stopProgram();
        } else if (programState.driveEnabled) {
            float dtSeconds = (float)CONTROL_PERIOD_MS / 1000.0f;
            applyDrive(controller.update(programState.setpoint_c, inner.celsius, dtSeconds));
        } else {
            controller.reset();
            applyDrive({0, Direction::Off});
        }
    }
}

void sendProgram()
{
    const ProgramSettings& settings = program.settings();
    FrameWriter& frame = link.start(Protocol::Tag::PRG);
    frame.addFixed(settings.start_c, 2);
    frame.addFixed(settings.max_c, 2);
    frame.addFixed(settings.step_c, 2);
    frame.addUnsigned(settings.hold_s);
    frame.addUnsigned(settings.rest_s);
    frame.addUnsigned(settings.cycles);
    frame.addText(proportionalOnly ? "P" : "PI");
    frame.addFixed(controller.proportionalGain(), 3);
    frame.addFixed(controller.integralGain(), 3);
    link.send();
}

const char* programErrorName(ProgramError error)
{
    switch (error) {
    case ProgramError::StartOutOfRange: return "START_RANGE";
    case ProgramError::MaxOutOfRange: return "MAX_RANGE";
    case ProgramError::StartNotBelowMax: return "START_GE_MAX";
    case ProgramError::StepNotPositive: return "STEP_LE_0";
    case ProgramError::StepLargerThanSpan: return "STEP_GT_SPAN";
    case ProgramError::StepTooSmall: return "STEP_TOO_SMALL";
    case ProgramError::HoldZero: return "HOLD_0";
    case ProgramError::CycleTooLong: return "TOO_LONG";
    default: return "OK";
    }
}

void setProgram(const FrameParser& command)
{
    int32_t hold = 0;
    int32_t rest = 0;
    int32_t cycles = 0;
    ProgramSettings settings;
    bool parsed = command.fieldCount() == Protocol::FieldCount::SETPRG && command.fieldFloat(0, settings.start_c) &&
                  command.fieldFloat(1, settings.max_c) && command.fieldFloat(2, settings.step_c) &&
                  command.fieldInt(3, hold) && command.fieldInt(4, rest) && command.fieldInt(5, cycles) &&
                  hold >= 0 && rest >= 0 && cycles >= 0 && cycles <= 65535;
    if (!parsed) {
        link.reject("BAD_ARG", "SETPRG_FIELDS");
        return;
    }
    if (running) {
        link.reject("BUSY", "STOP_FIRST");
        return;
    }
    settings.hold_s = (uint32_t)hold;
    settings.rest_s = (uint32_t)rest;
    settings.cycles = (uint16_t)cycles;
    ProgramError error = program.configure(settings);
    if (error != ProgramError::None) {
        link.reject("BAD_ARG", programErrorName(error));
        return;
    }
    link.acknowledge();
}

void setControl(const FrameParser& command)
{
    const char* mode = command.field(0);
    float kp = 0.0f;
    float ki = 0.0f;
    bool parsed = command.fieldCount() == Protocol::FieldCount::SETCTL && command.fieldFloat(1, kp) &&
                  command.fieldFloat(2, ki) && kp >= 0.0f && ki >= 0.0f && isfinite(kp) && isfinite(ki);
    bool proportional = parsed && strcmp(mode, "P") == 0;
    if (!parsed || (!proportional && strcmp(mode, "PI") != 0)) {
        link.reject("BAD_ARG", "SETCTL_FIELDS");
        return;
    }
    proportionalOnly = proportional;
    controller.setProportionalGain(kp);
    controller.setIntegralGain(proportional ? 0.0f : ki);
    controller.reset();
    link.acknowledge();
}

void handleCommand(uint32_t now)
{
    const FrameParser& command = link.command();
    if (link.commandIs(Protocol::Tag::START)) {
        if (fault != NO_FAULT) {
            link.reject("FAULT", faultName(fault));
            return;
        }
        running = true;
        programStartMs = now;
        controller.reset();
        programState = program.stateAt(0);
        link.acknowledge();
    } else if (link.commandIs(Protocol::Tag::STOP)) {
        stopProgram();
        link.acknowledge();
    } else if (link.commandIs(Protocol::Tag::VERSION)) {
        link.sendVersion("thermal_chamber", FIRMWARE_VERSION);
        link.acknowledge();
    } else if (link.commandIs(Protocol::Tag::STATUS)) {
        sendProgram();
        link.acknowledge();
    } else if (link.commandIs(Protocol::Tag::SETPRG)) {
        setProgram(command);
    } else if (link.commandIs(Protocol::Tag::SETCTL)) {
        setControl(command);
    } else {
        link.reject("UNKNOWN_CMD", command.type());
    }
}

}  // namespace

void setup()
{
    pinMode(kL298nIn1Pin, OUTPUT);
    pinMode(kL298nIn2Pin, OUTPUT);
    pinMode(kL298nEnaPin, OUTPUT);
    applyDrive({0, Direction::Off});
    link.begin();
    link.sendVersion("thermal_chamber", FIRMWARE_VERSION);
    lastControlMs = millis();
}

void loop()
{
    uint32_t now = millis();
    if (link.poll()) {
        handleCommand(now);
    }
    if (now - lastControlMs >= CONTROL_PERIOD_MS) {
        lastControlMs += CONTROL_PERIOD_MS;
        controlTick(now);
        if (++ticksSinceStatus >= CONTROL_TICKS_PER_STATUS) {
            ticksSinceStatus = 0;
            sendStatus(now);
        }
    }
    idleUntilInterrupt();
}
