// IMU reader (Arduino Nano): LSM9DS0 accelerometer and temperature at 100 Hz,
// a Kalman filter per channel, decimation, on-device drift compensation and
// IMU frames on the serial port (docs/protocol.md).
#include <Arduino.h>
#include <EEPROM.h>
#include <avr/sleep.h>

#include <Compensation.h>
#include <ImuProcessing.h>
#include <LSM9DS0.h>
#include <Protocol.h>

#include "Clock.h"
#include "SerialLink.h"
#include "SleepingTwi.h"
#include "Watchdog.h"

namespace {

namespace Frame = Protocol::Frame;
namespace Error = Protocol::Error;
namespace Detail = Protocol::ErrorDetail;

const char FIRMWARE_VERSION[] = "0.4.1";
// CTRL_REG1_XM runs the accelerometer at 100 Hz, and sampling follows the
// sensor's own clock: a sample is read when INT2_XM says it is ready or,
// where that line is not wired or not trusted (DataReadyLine), when
// STATUS_REG_A says so, polled only near the end of each period.
const uint32_t SAMPLE_PERIOD_MS = 10;
const uint32_t DATA_READY_WINDOW_MS = 2;
// INT2_XM, optional (README, wiring); the pull-up holds an unwired pin high.
const uint8_t DATA_READY_PIN = 2;
// A trusted line idle this long is checked against STATUS_REG_A, early
// enough that the sample it missed is still there to read.
const uint32_t DATA_READY_LINE_SILENT_MS = SAMPLE_PERIOD_MS + DATA_READY_WINDOW_MS;
static_assert(DATA_READY_LINE_SILENT_MS + Clock::TICK_MS < 2 * SAMPLE_PERIOD_MS,
              "a silent line must be checked before the sample it missed is overwritten");
const uint32_t SENSOR_RETRY_MS = 1000;
// Ten periods without data-ready means the sensor stopped, even if it answers.
const uint32_t SENSOR_SILENT_MS = 100;
// OUT_TEMP_XM is refreshed at the magnetometer's rate, 50 Hz as CTRL_REG5_XM
// sets it, and holds its reset value until the first conversion; begin()
// starts the accelerometer before the temperature sensor, so a first sample
// can carry that value. Samples are dropped for two magnetometer periods:
// one for the first conversion, one because the datasheet gives the
// magnetometer no turn-on time.
const uint32_t TEMPERATURE_SETTLE_MS = 2 * 20;
// Longer than a 100 Hz period: a held bus is given up on, never waited for.
const uint8_t I2C_TIMEOUT_MS = 25;
// The LSM9DS0 supports 400 kHz fast mode; a sample's ~20 bus bytes then take
// ~0.5 ms instead of ~2 ms of the 10 ms period, and every byte costs a TWI
// interrupt. A level converter that cannot follow needs 100000 here.
const uint32_t I2C_CLOCK_HZ = 400000;
const int COEFFICIENTS_EEPROM_ADDRESS = 0;
// The sensor ID's record (lib/Compensation/SensorId.h), in the second half of
// the Nano's 1 KB: past the block of any version, so that writing one, or an
// EEPROM image of coefficients.bin at address 0, leaves the ID as it was.
const int SENSOR_ID_EEPROM_ADDRESS = 512;
static_assert(COEFFICIENTS_EEPROM_ADDRESS + COEFFICIENT_BLOCK_SIZE <= SENSOR_ID_EEPROM_ADDRESS,
              "the block and the ID record do not overlap");
const uint8_t AXES = IMU_AXES;

// Where the active coefficients came from, as the IMU frame reports it.
enum CoefficientSource : char { FROM_EEPROM = 'E', FROM_DEFAULTS = 'D', UPLOADED = 'U' };

SleepingTwi bus;
Lsm9ds0Accel sensor(bus);
SerialLink link;
// The filters, trend and decimation of every sample (lib/ImuProcessing).
ImuProcessing processing;
Coefficients coefficients;
// Where the active surfaces were fitted; the board's ID itself stays in
// EEPROM (readSensorId), read when a command or the start-up needs it.
CalibratedDomain domain;
char coefficientSource = FROM_DEFAULTS;
bool sensorReady = false;
bool streaming = true;
// Set by RESET: from then on the loop does nothing until the watchdog resets the board.
bool resetting = false;
uint32_t lastSampleMs = 0;
uint32_t lastSensorAttemptMs = 0;
DataReadyLine dataReadyLine;
// Set by the pin's interrupt; it only wakes the loop, which reads the level.
volatile bool dataReadyChanged = false;

void onDataReadyChange()
{
    dataReadyChanged = true;
}

bool dataReadyLevel()
{
    return digitalRead(DATA_READY_PIN) == HIGH;
}

const char* sensorStatusName(Lsm9ds0Accel::Status status)
{
    switch (status) {
    case Lsm9ds0Accel::Status::Ok: break;
#define THERMOTILT_SENSOR_STATUS(enumerator, token) \
    case Lsm9ds0Accel::Status::enumerator: { \
        return Detail::token; \
    }
#include <ProtocolFrames.def>
    }
    return "OK";
}

void connectSensor()
{
    lastSensorAttemptMs = Clock::nowMs();
    Lsm9ds0Accel::Status status = sensor.begin();
    sensorReady = status == Lsm9ds0Accel::Status::Ok;
    dataReadyLine.distrust();
    if (sensorReady) {
        processing.reset();
        lastSampleMs = lastSensorAttemptMs;
    } else {
        link.report(Error::SENSOR_MISSING, sensorStatusName(status));
    }
}

void sensorLost(const char* why)
{
    sensorReady = false;
    lastSensorAttemptMs = Clock::nowMs();
    link.report(Error::SENSOR_MISSING, why);
}

// The ERR code for a block that cannot be used; false for a good or blank one.
bool blockErrorCode(BlockStatus status, Protocol::ErrorCode& code)
{
    switch (status) {
    case BlockStatus::Ok:
    case BlockStatus::Blank: break;
#define THERMOTILT_BLOCK_STATUS(enumerator, name) \
    case BlockStatus::enumerator: { \
        code = Error::name; \
        return true; \
    }
#include <ProtocolFrames.def>
    }
    return false;
}

// LTO inlines setup(), loop() and what they call into main(), whose one frame
// then holds all their locals for good. Not inlined, these keep the ID
// record and the decoded ID on the stack only while they run.
__attribute__((noinline)) IdRecordStatus readSensorId(SensorId& id)
{
    uint8_t record[SENSOR_ID_RECORD_SIZE];
    EEPROM.get(SENSOR_ID_EEPROM_ADDRESS, record);
    return decodeSensorIdRecord(record, id);
}

// The coefficient block is read and written in place, a byte at a time.
uint8_t readBlockByte(const void*, uint8_t index)
{
    return EEPROM.read(COEFFICIENTS_EEPROM_ADDRESS + index);
}

// update() writes only the bytes that changed. Each write takes 3.3 ms
// (datasheet), a whole new block ~0.6 s: longer than the watchdog's
// timeout, which would cut the save short without the feeding.
void writeBlockByte(void*, uint8_t index, uint8_t value)
{
    EEPROM.update(COEFFICIENTS_EEPROM_ADDRESS + index, value);
    feedWatchdog();
}

// What the board runs after a reset: the EEPROM's block if it is sound and
// fitted for this board's ID (or for none), else the defaults.
__attribute__((noinline)) void loadCoefficients()
{
    SensorId boardId;
    if (readSensorId(boardId) == IdRecordStatus::Damaged) {
        link.report(Error::EEPROM_ID, Detail::NO_ID);
    }
    BlockStatus status = decodeCoefficients(readBlockByte, nullptr, boardId.text, coefficients, domain);
    if (status == BlockStatus::Ok) {
        coefficientSource = FROM_EEPROM;
        return;
    }
    loadDefaultCoefficients(coefficients);
    clearDomain(domain);
    coefficientSource = FROM_DEFAULTS;
    // A blank EEPROM (never saved) is normal; a damaged block is worth saying.
    Protocol::ErrorCode code;
    if (blockErrorCode(status, code)) {
        link.report(code, Detail::DEFAULTS);
    }
}

// The block is bound to the board's ID: the host checked that the fit was
// made for it before sending the surfaces (docs/calibration.md).
__attribute__((noinline)) void saveCoefficients()
{
    SensorId boardId;
    readSensorId(boardId);
    encodeCoefficients(coefficients, domain, boardId.text, writeBlockByte, nullptr);
    coefficientSource = FROM_EEPROM;
}

// The IMU frame's temp_domain: inside or outside the active set's calibrated
// temperature range, or unknown (no range: defaults, a version 1 block,
// surfaces sent without SETDOM).
char temperatureDomainCode(DomainCheck check)
{
    switch (check) {
    case DomainCheck::Inside: return 'I';
    case DomainCheck::Outside: return 'O';
    case DomainCheck::Unknown: break;
    }
    return 'U';
}

void sendImuFrame(const int16_t raw[AXES], const ImuOutput& out)
{
    FrameWriter& frame = link.start(Frame::IMU);
    frame.addUnsigned(Clock::nowMs());
    for (uint8_t axis = 0; axis < AXES; ++axis) {
        frame.addInt(raw[axis]);
    }
    for (uint8_t axis = 0; axis < AXES; ++axis) {
        frame.addFixed(out.filtered[axis], 1);
    }
    for (uint8_t axis = 0; axis < AXES; ++axis) {
        frame.addFixed(out.compensated[axis], 1);
    }
    frame.addFixed(out.temperatureC, 3);
    frame.addChar(out.set == CompSet::Warming ? 'W' : 'C');
    frame.addChar(coefficientSource);
    frame.addChar(temperatureDomainCode(checkTemperature(domain.set[(uint8_t)out.set], out.temperatureC)));
    link.send();
}

// A sample found ready, by the data-ready line (onLine) or by STATUS_REG_A,
// with the line at levelWhenReady. On the line's word the read starts at
// STATUS_REG_A, one byte more, so a line stuck at its active level cannot
// pass an old sample off as new.
void readSample(uint32_t now, bool onLine, bool levelWhenReady)
{
    int16_t raw[AXES];
    int16_t temperatureRaw;
    bool fresh = true;
    bool read = onLine ? sensor.readFreshAcceleration(raw, fresh) : sensor.readAcceleration(raw);
    // The read cleared data-ready: that edge needs no loop pass.
    dataReadyChanged = false;
    if (read && !fresh) {
        dataReadyLine.distrust();
        return;
    }
    if (!read || !sensor.readTemperatureRaw(temperatureRaw)) {
        sensorLost(Detail::READ_FAILED);
        return;
    }
    lastSampleMs = now;
    dataReadyLine.sampleRead(levelWhenReady, dataReadyLevel());
    // Read all the same, so the sensor hands over its next sample. While the
    // sensor is ready, the last attempt is the one that configured it.
    if (now - lastSensorAttemptMs < TEMPERATURE_SETTLE_MS) {
        return;
    }
    // Filtered while stopped too; only streaming counts samples towards a frame.
    ImuOutput out;
    if (processing.update(raw, temperatureRaw, coefficients, out, streaming)) {
        sendImuFrame(raw, out);
    }
}

// While the data-ready line is trusted, a tick of Clock brings nothing to do:
// sleep through the ticks until the line changes, the host sends a byte,
// Uart0 has room for the rest of a frame, or the line's silence is due to
// be checked. Otherwise one tick at a time, as the polling needs.
void idleUntilWork()
{
    if (!sensorReady || !dataReadyLine.trusted()) {
        idleUntilInterrupt();
        return;
    }
    set_sleep_mode(SLEEP_MODE_IDLE);
    // Signed: the tick's time can be a little before lastSampleMs.
    uint32_t silenceDueMs = lastSampleMs + DATA_READY_LINE_SILENT_MS;
    for (;;) {
        noInterrupts();
        if (dataReadyChanged || link.hasWork() || (int32_t)(Clock::tickMs() - silenceDueMs) >= 0) {
            interrupts();
            return;
        }
        sleep_enable();
        // SEI's next instruction runs before any interrupt: no wake-up is lost.
        interrupts();
        sleep_cpu();
        sleep_disable();
    }
}

bool parseSet(const FrameParser& command, uint8_t& set)
{
    const char* setText = command.field(0);
    if (!setText || setText[1] != '\0' || (setText[0] != 'W' && setText[0] != 'C')) {
        return false;
    }
    set = setText[0] == 'W' ? 0 : 1;
    return true;
}

bool parseSetAndAxis(const FrameParser& command, uint8_t& set, uint8_t& axis)
{
    const char* axisText = command.field(1);
    if (!parseSet(command, set) || !axisText || axisText[1] != '\0') {
        return false;
    }
    if (axisText[0] < 'X' || axisText[0] > 'Z') {
        return false;
    }
    axis = (uint8_t)(axisText[0] - 'X');
    return true;
}

// A temperature in degC as the domain's 1/100 degC; false beyond an int16.
bool parseCentiC(const FrameParser& command, uint8_t index, int16_t& centiC)
{
    float value = 0.0f;
    if (!command.fieldFloat(index, value)) {
        return false;
    }
    float rounded = roundf(value * 100.0f);
    // Written so that NaN fails too.
    if (!(rounded >= (float)INT16_MIN && rounded <= (float)INT16_MAX)) {
        return false;
    }
    centiC = (int16_t)rounded;
    return true;
}

bool parseLsb(const FrameParser& command, uint8_t index, int16_t& lsb)
{
    int32_t value = 0;
    if (!command.fieldInt(index, value) || value < INT16_MIN || value > INT16_MAX) {
        return false;
    }
    lsb = (int16_t)value;
    return true;
}

void sendCoefficients(uint8_t set, uint8_t axis)
{
    FrameWriter& frame = link.start(Frame::COE);
    frame.addChar(set == 0 ? 'W' : 'C');
    frame.addChar((char)('X' + axis));
    for (uint8_t term = 0; term < COMP_COEFFICIENT_COUNT; ++term) {
        frame.addScientific(coefficients.set[set].axis[axis].p[term]);
    }
    link.send();
}

// An unknown temperature range is nan; an axis range with min above max is none.
void sendDomain(uint8_t set)
{
    const SetDomain& setDomain = domain.set[set];
    FrameWriter& frame = link.start(Frame::DOM);
    frame.addChar(set == 0 ? 'W' : 'C');
    bool known = setDomain.temperatureCentiC.known();
    frame.addFixed(known ? setDomain.temperatureCentiC.min / 100.0f : NAN, 2);
    frame.addFixed(known ? setDomain.temperatureCentiC.max / 100.0f : NAN, 2);
    for (uint8_t axis = 0; axis < AXES; ++axis) {
        frame.addInt(setDomain.accelLsb[axis].min);
        frame.addInt(setDomain.accelLsb[axis].max);
    }
    link.send();
}

void sendConfiguration()
{
    SensorId boardId;
    readSensorId(boardId);
    FrameWriter& frame = link.start(Frame::ICF);
    frame.addUnsigned(processing.decimation());
    frame.addUnsigned(streaming ? 1 : 0);
    frame.addChar(coefficientSource);
    frame.addFixed(processing.hysteresisC(), 3);
    frame.addText(boardId.text);
    link.send();
}

void onStart(const FrameParser&)
{
    streaming = true;
    processing.restartDecimation();
    link.acknowledge();
}

void onStop(const FrameParser&)
{
    streaming = false;
    processing.restartDecimation();
    link.acknowledge();
}

// After a tilt-table move: the filters would take ~90 s to forget the old
// angle; seeded again, the next samples average from the new one.
void onReseed(const FrameParser&)
{
    processing.reset();
    link.acknowledge();
}

void onVersion(const FrameParser&)
{
    link.sendVersion("imu_reader", FIRMWARE_VERSION);
    link.acknowledge();
}

void onStatus(const FrameParser&)
{
    sendConfiguration();
    link.acknowledge();
}

void onSetDecimation(const FrameParser& command)
{
    int32_t factor = 0;
    if (!command.fieldInt(0, factor) || factor < 1 || factor > 255) {
        link.reject(Error::BAD_ARG, Detail::FACTOR_1_255);
        return;
    }
    processing.setDecimation((uint8_t)factor);
    link.acknowledge();
}

void onGetCoefficients(const FrameParser& command)
{
    uint8_t set = 0;
    uint8_t axis = 0;
    if (!parseSetAndAxis(command, set, axis)) {
        link.reject(Error::BAD_ARG, Detail::SET_AXIS);
        return;
    }
    sendCoefficients(set, axis);
    link.acknowledge();
}

void onSetCoefficients(const FrameParser& command)
{
    uint8_t set = 0;
    uint8_t axis = 0;
    AxisSurface surface;
    bool valid = parseSetAndAxis(command, set, axis);
    for (uint8_t term = 0; valid && term < COMP_COEFFICIENT_COUNT; ++term) {
        valid = command.fieldFloat((uint8_t)(2 + term), surface.p[term]) && isfinite(surface.p[term]);
    }
    if (!valid) {
        link.reject(Error::BAD_ARG, Detail::COEFFICIENTS);
        return;
    }
    if (!surfaceOutputFitsFrame(surface)) {
        link.reject(Error::BAD_ARG, Detail::OUTPUT_TOO_LARGE);
        return;
    }
    coefficients.set[set].axis[axis] = surface;
    // New surfaces: where they were fitted is unknown until SETDOM says.
    clearDomain(domain.set[set]);
    coefficientSource = UPLOADED;
    link.acknowledge();
}

void onGetDomain(const FrameParser& command)
{
    uint8_t set = 0;
    if (!parseSet(command, set)) {
        link.reject(Error::BAD_ARG, Detail::DOMAIN);
        return;
    }
    sendDomain(set);
    link.acknowledge();
}

// The calibrated domain of the set's surfaces, in RAM, saved by SAVECOE: a
// temperature range min <= max, and per axis a range (min above max: none).
void onSetDomain(const FrameParser& command)
{
    uint8_t set = 0;
    SetDomain setDomain;
    bool valid = parseSet(command, set) && parseCentiC(command, 1, setDomain.temperatureCentiC.min) &&
                 parseCentiC(command, 2, setDomain.temperatureCentiC.max) && setDomain.temperatureCentiC.known();
    for (uint8_t axis = 0; valid && axis < AXES; ++axis) {
        valid = parseLsb(command, (uint8_t)(3 + 2 * axis), setDomain.accelLsb[axis].min) &&
                parseLsb(command, (uint8_t)(4 + 2 * axis), setDomain.accelLsb[axis].max);
    }
    if (!valid) {
        link.reject(Error::BAD_ARG, Detail::DOMAIN);
        return;
    }
    domain.set[set] = setDomain;
    link.acknowledge();
}

// Not inlined: the record leaves the stack before loadCoefficients() runs.
__attribute__((noinline)) void writeSensorId(const char* id)
{
    uint8_t record[SENSOR_ID_RECORD_SIZE];
    encodeSensorIdRecord(id, record);
    // Up to 3.3 ms a byte (datasheet), fed like SAVECOE's.
    for (uint8_t i = 0; i < SENSOR_ID_RECORD_SIZE; ++i) {
        EEPROM.update(SENSOR_ID_EEPROM_ADDRESS + i, record[i]);
        feedWatchdog();
    }
}

// Writes the ID record alone; the coefficient block stays as it is. The
// board then runs what it would run after a reset with this ID: a block
// fitted for another ID stops loading (defaults, ERR EEPROM_SENSOR), so no
// sensor runs another's coefficients; one fitted for this ID or for none
// loads again. Surfaces uploaded but not saved are dropped with it.
void onSetSensorId(const FrameParser& command)
{
    const char* id = command.field(0);
    if (!isValidSensorId(id)) {
        link.reject(Error::BAD_ARG, Detail::SENSOR_ID);
        return;
    }
    writeSensorId(id);
    loadCoefficients();
    link.acknowledge();
}

void onSaveCoefficients(const FrameParser&)
{
    saveCoefficients();
    link.acknowledge();
}

void onDefaultCoefficients(const FrameParser&)
{
    loadDefaultCoefficients(coefficients);
    clearDomain(domain);
    coefficientSource = FROM_DEFAULTS;
    link.acknowledge();
}

void onReset(const FrameParser&)
{
    link.acknowledge();
    // The ACK leaves before the reset cuts the line.
    link.flush();
    startCommandedReset();
    resetting = true;
}

// The commands of this board (docs/protocol.md), for SerialLink::dispatch.
constexpr Protocol::Command COMMANDS[] PROGMEM = {
    Protocol::command(Frame::START, onStart),
    Protocol::command(Frame::STOP, onStop),
    Protocol::command(Frame::RESEED, onReseed),
    Protocol::command(Frame::VERSION, onVersion),
    Protocol::command(Frame::STATUS, onStatus),
    Protocol::command(Frame::SETDEC, onSetDecimation, Detail::FACTOR_1_255),
    Protocol::command(Frame::GETCOE, onGetCoefficients, Detail::SET_AXIS),
    Protocol::command(Frame::SETCOE, onSetCoefficients, Detail::COEFFICIENTS),
    Protocol::command(Frame::SAVECOE, onSaveCoefficients),
    Protocol::command(Frame::DEFCOE, onDefaultCoefficients),
    Protocol::command(Frame::GETDOM, onGetDomain, Detail::DOMAIN),
    Protocol::command(Frame::SETDOM, onSetDomain, Detail::DOMAIN),
    Protocol::command(Frame::SETID, onSetSensorId, Detail::SENSOR_ID),
    Protocol::command(Frame::RESET, onReset),
};

}  // namespace

void setup()
{
    Clock::begin();
    startWatchdog();
    link.begin();
    bus.begin(I2C_CLOCK_HZ, I2C_TIMEOUT_MS);
    link.announceStart("imu_reader", FIRMWARE_VERSION);
    pinMode(DATA_READY_PIN, INPUT_PULLUP);
    attachInterrupt(digitalPinToInterrupt(DATA_READY_PIN), onDataReadyChange, CHANGE);
    loadCoefficients();
    connectSensor();
}

// Not inlined either: its locals would sit under loadCoefficients() at start-up,
// the deepest the stack goes.
__attribute__((noinline)) void loop()
{
    if (resetting) {
        return;
    }
    feedWatchdog();
    link.writePending();
    if (link.poll(Clock::nowMs())) {
        link.dispatch(COMMANDS);
        if (resetting) {
            return;
        }
    }
    // After the command, which may have taken a while (SAVECOE ~0.6 s).
    uint32_t now = Clock::nowMs();
    if (!sensorReady) {
        if (now - lastSensorAttemptMs >= SENSOR_RETRY_MS) {
            connectSensor();
        }
    } else {
        dataReadyChanged = false;
        uint32_t sinceSample = now - lastSampleMs;
        uint32_t pollAfter = dataReadyLine.trusted() ? DATA_READY_LINE_SILENT_MS
                                                     : SAMPLE_PERIOD_MS - DATA_READY_WINDOW_MS;
        bool level = dataReadyLevel();
        if (dataReadyLine.saysReady(level)) {
            readSample(now, true, level);
        } else if (sinceSample >= pollAfter) {
            if (sensor.dataReady()) {
                level = dataReadyLevel();
                if (dataReadyLine.trusted() && !dataReadyLine.saysReady(level)) {
                    // It missed a sample that STATUS_REG_A has.
                    dataReadyLine.distrust();
                }
                readSample(now, false, level);
            } else if (sinceSample >= SENSOR_SILENT_MS) {
                sensorLost(Detail::NO_DATA);
            }
        }
    }
    idleUntilWork();
}
