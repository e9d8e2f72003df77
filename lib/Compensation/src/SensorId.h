// Which sensor a board carries. The LSM9DS0 has no serial number (WHO_AM_I is
// the part's code, 0x49 for every XM die), so the host assigns a short ID and
// the board keeps it in EEPROM, as PX4 binds thermal coefficients to a
// device ID (TC_A0_ID): a coefficient block fitted for one ID is not loaded
// on a board of another.
#ifndef THERMOTILT_SENSOR_ID_H
#define THERMOTILT_SENSOR_ID_H

#include <stdint.h>

// Up to 8 characters of [A-Za-z0-9_-]; empty means unassigned. A label
// printed on the board fits, and it is a text token of the serial protocol.
const uint8_t SENSOR_ID_LENGTH = 8;

struct SensorId {
    char text[SENSOR_ID_LENGTH + 1];  // NUL-terminated
};

// True for an ID of at most SENSOR_ID_LENGTH characters, each a letter, a
// digit, '_' or '-'; the empty text (unassigned) too.
bool isValidSensorId(const char* text);

// The ID's EEPROM record, little-endian: [0] magic 'I', [1..8] the ID,
// NUL-padded, [9..10] CRC-16/XMODEM of bytes 0..8. Its own record, so that
// assigning an ID writes nothing of the coefficient block.
const uint8_t SENSOR_ID_RECORD_MAGIC = 0x49;
const uint8_t SENSOR_ID_RECORD_SIZE = 11;

// Blank: every byte 0xFF, never assigned. Damaged: written, but with another
// magic, a failing CRC or characters an ID cannot hold.
enum class IdRecordStatus : uint8_t { Ok, Blank, Damaged };

// id must be valid (isValidSensorId).
void encodeSensorIdRecord(const char* id, uint8_t out[SENSOR_ID_RECORD_SIZE]);
// out is the ID when Ok, else empty (the board has no ID).
IdRecordStatus decodeSensorIdRecord(const uint8_t in[SENSOR_ID_RECORD_SIZE], SensorId& out);

// The ID field of the coefficient block and of the record: the text,
// NUL-padded to SENSOR_ID_LENGTH bytes.
void putSensorIdField(uint8_t out[SENSOR_ID_LENGTH], const char* id);
// False unless the field holds a valid ID followed by NULs only.
bool getSensorIdField(const uint8_t in[SENSOR_ID_LENGTH], SensorId& out);

#endif
