// Thermal chamber (Arduino Mega 2560): two NTC thermistors, the programmed
// temperature staircase and the proportional controller driving a Peltier
// cell through an L298N; CHS status frames on the serial port.
//
// Safety is this board's job, not the host's: a thermistor fault, a face
// outside its limits, a runaway (lib/ThermalGuard), a silent host (when the
// heartbeat is on) or a hung loop (the watchdog) turns the bridge off by
// itself. Faults latch: the bridge stays off until the host sends CLEAR.
#include <Arduino.h>

#include <ChamberControl.h>
#include <Program.h>
#include <Protocol.h>
#include <ThermalGuard.h>
#include <Thermistor.h>

#include "SerialLink.h"
#include "Watchdog.h"

namespace {

namespace Frame = Protocol::Frame;
namespace Error = Protocol::Error;
namespace Detail = Protocol::ErrorDetail;

const char FIRMWARE_VERSION[] = "0.2.0";
// The reference (inner) face is the controlled one; the outer face is the
// heatsink side, watched because each face's temperature depends on the other.
const uint8_t INNER_THERMISTOR_PIN = A0;
const uint8_t OUTER_THERMISTOR_PIN = A1;
const uint32_t CONTROL_PERIOD_MS = 250;
const uint8_t CONTROL_TICKS_PER_STATUS = 4;
const float CONTROL_PERIOD_S = (float)CONTROL_PERIOD_MS / 1000.0f;
// An hour: longer is no heartbeat at all.
const int32_t MAX_HEARTBEAT_S = 3600;

// The faults the board latches, each named as CHS and ERR name it.
enum Fault : uint8_t {
    NO_FAULT,
#define THERMOTILT_CHAMBER_FAULT(token, code) token,
#include <ProtocolFrames.def>
};

SerialLink link;
Thermistor thermistor;
ChamberController controller;
TemperatureProgram program;
ProgramRun programRun(program);
ThermalGuard guard;
// START runs only a program the host set and the board accepted.
bool programAccepted = false;
bool running = false;
uint16_t heartbeatS = 0;
// SETCTL's modes: the paper's P law, PI, and P on the error rounded to whole
// degC (a hypothesis about the paper's code, see lib/ChamberControl).
enum ControlMode : uint8_t { CONTROL_P, CONTROL_PI, CONTROL_PR };
const char* const CONTROL_MODE_NAMES[] = {"P", "PI", "PR"};
ControlMode controlMode = CONTROL_P;
// Program time runs by the real time between control ticks (lib/Program).
uint32_t lastProgramTickMs = 0;
uint32_t lastControlMs = 0;
uint8_t ticksSinceStatus = 0;
Fault fault = NO_FAULT;
ThermistorReading inner = {NAN, ThermistorStatus::Ok};
ThermistorReading outer = {NAN, ThermistorStatus::Ok};
ProgramState programState;
DriveCommand drive = {0, Direction::Off};

// Each fault's name and the ERR code it is reported with, in Fault's order.
const char* const FAULT_NAMES[] PROGMEM = {
    "OK",  // NO_FAULT, as CHS says it
#define THERMOTILT_CHAMBER_FAULT(token, code) Detail::token,
#include <ProtocolFrames.def>
};
const Protocol::ErrorCode FAULT_CODES[] PROGMEM = {
    Error::FAULT,  // NO_FAULT, never reported
#define THERMOTILT_CHAMBER_FAULT(token, code) Error::code,
#include <ProtocolFrames.def>
};

const char* faultName(Fault value)
{
    return (const char*)pgm_read_ptr(&FAULT_NAMES[value]);
}

Protocol::ErrorCode faultCategory(Fault value)
{
    return {(const char*)pgm_read_ptr(&FAULT_CODES[value].text)};
}

Fault faultOf(GuardFault value)
{
    switch (value) {
    case GuardFault::InnerHot: return INNER_HOT;
    case GuardFault::InnerCold: return INNER_COLD;
    case GuardFault::OuterHot: return OUTER_HOT;
    case GuardFault::OuterCold: return OUTER_COLD;
    case GuardFault::NoResponse: return NO_RESPONSE;
    case GuardFault::WrongWay: return WRONG_WAY;
    case GuardFault::HoldLost: return HOLD_LOST;
    default: return NO_FAULT;
    }
}

// Out of plausible range reads like an open circuit: no trustworthy value.
Fault thermistorFaultOf(const ThermistorReading& reading, Fault open, Fault shorted)
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
    FrameWriter& frame = link.start(Frame::CHS);
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

Fault presentThermistorFault()
{
    Fault found = thermistorFaultOf(inner, INNER_OPEN, INNER_SHORT);
    return found != NO_FAULT ? found : thermistorFaultOf(outer, OUTER_OPEN, OUTER_SHORT);
}

void trip(Fault detected)
{
    fault = detected;
    stopProgram();
    link.report(faultCategory(detected), faultName(detected));
}

bool hostSilent(uint32_t now)
{
    return running && heartbeatS != 0 && now - link.lastHostFrameMs() > (uint32_t)heartbeatS * 1000UL;
}

void controlTick(uint32_t now)
{
    inner = readFace(INNER_THERMISTOR_PIN);
    outer = readFace(OUTER_THERMISTOR_PIN);
    if (fault != NO_FAULT) {
        return;
    }
    if (running) {
        programState = programRun.advance(now - lastProgramTickMs, inner.celsius);
        lastProgramTickMs = now;
    }
    bool driving = running && programState.phase != ProgramPhase::Done && programState.driveEnabled;
    Fault detected = presentThermistorFault();
    if (detected == NO_FAULT) {
        // Limits and runaway, judged with the drive that produced these readings.
        detected = faultOf(guard.update(driving ? programState.setpoint_c : NAN, inner.celsius, outer.celsius, drive,
                                        CONTROL_PERIOD_S));
    }
    if (detected == NO_FAULT && hostSilent(now)) {
        detected = HOST_SILENT;
    }
    if (detected != NO_FAULT) {
        trip(detected);
        return;
    }
    if (!running) {
        return;
    }
    if (programState.phase == ProgramPhase::Done) {
        stopProgram();
    } else if (driving) {
        applyDrive(controller.update(programState.setpoint_c, inner.celsius, CONTROL_PERIOD_S));
    } else {
        controller.reset();
        applyDrive({0, Direction::Off});
    }
}

// SETPRG's and PRG's hold_start: T timed, F first step of each cycle waits,
// A all steps wait.
const char HOLD_START_LETTERS[] = "TFA";

char holdStartLetter(HoldStart value)
{
    return HOLD_START_LETTERS[(uint8_t)value];
}

bool parseHoldStart(const char* text, HoldStart& value)
{
    const char* found = text[0] != '\0' && text[1] == '\0' ? strchr(HOLD_START_LETTERS, text[0]) : NULL;
    if (found == NULL) {
        return false;
    }
    value = (HoldStart)(found - HOLD_START_LETTERS);
    return true;
}

void sendProgram()
{
    const ProgramSettings& settings = program.settings();
    FrameWriter& frame = link.start(Frame::PRG);
    frame.addFixed(settings.start_c, 2);
    frame.addFixed(settings.max_c, 2);
    frame.addFixed(settings.step_c, 2);
    frame.addUnsigned(settings.hold_s);
    frame.addUnsigned(settings.rest_s);
    frame.addUnsigned(settings.cycles);
    frame.addText(CONTROL_MODE_NAMES[controlMode]);
    frame.addFixed(controller.proportionalGain(), 3);
    frame.addFixed(controller.integralGain(), 3);
    frame.addUnsigned(programAccepted ? 1 : 0);
    frame.addChar(holdStartLetter(settings.hold_start));
    link.send();
}

// GRD's and SETGRD's guard fields, in their order in ProtocolFrames.def,
// with the decimals GRD reports them with.
struct GuardField {
    float GuardSettings::*member;
    uint8_t decimals;
};
const GuardField GUARD_FIELDS[] = {
    {&GuardSettings::band_c, 2},      {&GuardSettings::gain_c, 2},        {&GuardSettings::window_s, 1},
    {&GuardSettings::wrong_way_c, 2}, {&GuardSettings::max_error_c_s, 1}, {&GuardSettings::inner_min_c, 2},
    {&GuardSettings::inner_max_c, 2}, {&GuardSettings::outer_min_c, 2},   {&GuardSettings::outer_max_c, 2},
};
const uint8_t GUARD_FIELD_COUNT = sizeof GUARD_FIELDS / sizeof GUARD_FIELDS[0];
static_assert(GUARD_FIELD_COUNT == Protocol::FieldCount::SETGRD, "SETGRD carries the guard fields");
static_assert(GUARD_FIELD_COUNT + 1 == Protocol::FieldCount::GRD, "GRD carries them and heartbeat_s");

void sendGuard()
{
    const GuardSettings& settings = guard.settings();
    FrameWriter& frame = link.start(Frame::GRD);
    for (uint8_t i = 0; i < GUARD_FIELD_COUNT; ++i) {
        frame.addFixed(settings.*GUARD_FIELDS[i].member, GUARD_FIELDS[i].decimals);
    }
    frame.addUnsigned(heartbeatS);
    link.send();
}

const char* programErrorName(ProgramError error)
{
    switch (error) {
    case ProgramError::None: break;
#define THERMOTILT_PROGRAM_ERROR(enumerator, token) \
    case ProgramError::enumerator: { \
        return Detail::token; \
    }
#include <ProtocolFrames.def>
    }
    return "OK";
}

void onSetProgram(const FrameParser& command)
{
    int32_t hold = 0;
    int32_t rest = 0;
    int32_t cycles = 0;
    ProgramSettings settings;
    // hold_start was appended to protocol 2: without it, the default.
    const uint8_t holdStartField = Protocol::FieldCount::SETPRG - 1;
    bool parsed = command.fieldCount() >= holdStartField && command.fieldFloat(0, settings.start_c) &&
                  command.fieldFloat(1, settings.max_c) && command.fieldFloat(2, settings.step_c) &&
                  command.fieldInt(3, hold) && command.fieldInt(4, rest) && command.fieldInt(5, cycles) && hold >= 0 &&
                  rest >= 0 && cycles >= 0 && cycles <= 65535 &&
                  (command.fieldCount() == holdStartField ||
                   parseHoldStart(command.field(holdStartField), settings.hold_start));
    if (running) {
        link.reject(Error::BUSY, Detail::STOP_FIRST);
        return;
    }
    // A refused program must not leave an older one for START to run.
    programAccepted = false;
    if (!parsed) {
        link.reject(Error::BAD_ARG, Detail::SETPRG_FIELDS);
        return;
    }
    settings.hold_s = (uint32_t)hold;
    settings.rest_s = (uint32_t)rest;
    settings.cycles = (uint16_t)cycles;
    ProgramError error = program.configure(settings);
    if (error != ProgramError::None) {
        link.reject(Error::BAD_ARG, programErrorName(error));
        return;
    }
    programAccepted = true;
    link.acknowledge();
}

void onSetControl(const FrameParser& command)
{
    const char* mode = command.field(0);
    float kp = 0.0f;
    float ki = 0.0f;
    bool parsed = command.fieldFloat(1, kp) && command.fieldFloat(2, ki) && kp >= 0.0f && ki >= 0.0f && isfinite(kp) &&
                  isfinite(ki);
    uint8_t chosen = 0;
    while (parsed && chosen <= CONTROL_PR && strcmp(mode, CONTROL_MODE_NAMES[chosen]) != 0) {
        ++chosen;
    }
    if (!parsed || chosen > CONTROL_PR) {
        link.reject(Error::BAD_ARG, Detail::SETCTL_FIELDS);
        return;
    }
    controlMode = (ControlMode)chosen;
    controller.setProportionalGain(kp);
    controller.setIntegralGain(controlMode == CONTROL_PI ? ki : 0.0f);
    controller.setRoundedError(controlMode == CONTROL_PR);
    controller.reset();
    link.acknowledge();
}

const char* guardErrorName(GuardError error)
{
    switch (error) {
    case GuardError::None: break;
#define THERMOTILT_GUARD_ERROR(enumerator, token) \
    case GuardError::enumerator: { \
        return Detail::token; \
    }
#include <ProtocolFrames.def>
    }
    return "OK";
}

void onSetGuard(const FrameParser& command)
{
    GuardSettings settings;
    bool parsed = true;
    for (uint8_t i = 0; parsed && i < GUARD_FIELD_COUNT; ++i) {
        parsed = command.fieldFloat(i, settings.*GUARD_FIELDS[i].member);
    }
    if (!parsed) {
        link.reject(Error::BAD_ARG, Detail::SETGRD_FIELDS);
        return;
    }
    GuardError error = guard.configure(settings);
    if (error != GuardError::None) {
        link.reject(Error::BAD_ARG, guardErrorName(error));
        return;
    }
    link.acknowledge();
}

void onSetHeartbeat(const FrameParser& command)
{
    int32_t seconds = 0;
    if (!command.fieldInt(0, seconds) || seconds < 0 || seconds > MAX_HEARTBEAT_S) {
        link.reject(Error::BAD_ARG, Detail::HEARTBEAT_0_3600);
        return;
    }
    heartbeatS = (uint16_t)seconds;
    link.acknowledge();
}

// A latched fault clears only on request, and only once its cause is gone.
void onClear(const FrameParser&)
{
    Fault present = presentThermistorFault();
    if (present == NO_FAULT) {
        present = faultOf(guard.limitFault(inner.celsius, outer.celsius));
    }
    if (present != NO_FAULT) {
        link.reject(Error::FAULT, faultName(present));
        return;
    }
    fault = NO_FAULT;
    guard.reset();
    link.acknowledge();
}

void onStart(const FrameParser&)
{
    if (fault != NO_FAULT) {
        link.reject(Error::FAULT, faultName(fault));
        return;
    }
    if (!programAccepted) {
        link.reject(Error::NO_PROGRAM, Detail::SETPRG_FIRST);
        return;
    }
    running = true;
    guard.reset();
    lastProgramTickMs = link.lastHostFrameMs();
    controller.reset();
    programState = programRun.start(inner.celsius);
    link.acknowledge();
}

void onStop(const FrameParser&)
{
    stopProgram();
    link.acknowledge();
}

void onVersion(const FrameParser&)
{
    link.sendVersion("thermal_chamber", FIRMWARE_VERSION);
    link.acknowledge();
}

void onStatus(const FrameParser&)
{
    sendProgram();
    sendGuard();
    link.acknowledge();
}

// The commands of this board (docs/protocol.md), for SerialLink::dispatch.
// SETPRG checks its own fields: BUSY comes first, hold_start may be left
// off, and a refused SETPRG must also forget the accepted program.
constexpr Protocol::Command COMMANDS[] PROGMEM = {
    Protocol::command(Frame::START, onStart),
    Protocol::command(Frame::STOP, onStop),
    Protocol::command(Frame::VERSION, onVersion),
    Protocol::command(Frame::STATUS, onStatus),
    Protocol::command(Frame::SETPRG, onSetProgram),
    Protocol::command(Frame::SETCTL, onSetControl, Detail::SETCTL_FIELDS),
    Protocol::command(Frame::SETGRD, onSetGuard, Detail::SETGRD_FIELDS),
    Protocol::command(Frame::SETHB, onSetHeartbeat, Detail::HEARTBEAT_0_3600),
    Protocol::command(Frame::CLEAR, onClear),
};

}  // namespace

void setup()
{
    pinMode(kL298nIn1Pin, OUTPUT);
    pinMode(kL298nIn2Pin, OUTPUT);
    pinMode(kL298nEnaPin, OUTPUT);
    applyDrive({0, Direction::Off});
    startWatchdog();
    link.begin();
    link.announceStart("thermal_chamber", FIRMWARE_VERSION);
    lastControlMs = millis();
}

void loop()
{
    feedWatchdog();
    link.writePending();
    uint32_t now = millis();
    if (link.poll(now)) {
        link.dispatch(COMMANDS);
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
