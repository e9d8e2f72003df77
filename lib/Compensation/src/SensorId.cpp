#include "SensorId.h"

#include <string.h>

#include <Crc16.h>

namespace {

const uint8_t MAGIC_OFFSET = 0;
const uint8_t ID_OFFSET = 1;
const uint8_t CRC_OFFSET = ID_OFFSET + SENSOR_ID_LENGTH;
const uint8_t ERASED_BYTE = 0xFF;

bool isIdCharacter(char c)
{
    return (c >= 'A' && c <= 'Z') || (c >= 'a' && c <= 'z') || (c >= '0' && c <= '9') || c == '_' || c == '-';
}

}  // namespace

bool isValidSensorId(const char* text)
{
    uint8_t length = 0;
    for (; text[length] != '\0'; ++length) {
        if (length == SENSOR_ID_LENGTH || !isIdCharacter(text[length])) {
            return false;
        }
    }
    return true;
}

void putSensorIdField(uint8_t out[SENSOR_ID_LENGTH], const char* id)
{
    uint8_t i = 0;
    for (; i < SENSOR_ID_LENGTH && id[i] != '\0'; ++i) {
        out[i] = (uint8_t)id[i];
    }
    for (; i < SENSOR_ID_LENGTH; ++i) {
        out[i] = 0;
    }
}

bool getSensorIdField(const uint8_t in[SENSOR_ID_LENGTH], SensorId& out)
{
    bool ended = false;
    for (uint8_t i = 0; i < SENSOR_ID_LENGTH; ++i) {
        char c = (char)in[i];
        ended = ended || c == '\0';
        if (ended ? c != '\0' : !isIdCharacter(c)) {
            return false;
        }
        out.text[i] = c;
    }
    out.text[SENSOR_ID_LENGTH] = '\0';
    return true;
}

void encodeSensorIdRecord(const char* id, uint8_t out[SENSOR_ID_RECORD_SIZE])
{
    out[MAGIC_OFFSET] = SENSOR_ID_RECORD_MAGIC;
    putSensorIdField(out + ID_OFFSET, id);
    uint16_t crc = crc16Xmodem(out, CRC_OFFSET);
    out[CRC_OFFSET] = (uint8_t)crc;
    out[CRC_OFFSET + 1] = (uint8_t)(crc >> 8);
}

IdRecordStatus decodeSensorIdRecord(const uint8_t in[SENSOR_ID_RECORD_SIZE], SensorId& out)
{
    out.text[0] = '\0';
    bool erased = true;
    for (uint8_t i = 0; i < SENSOR_ID_RECORD_SIZE; ++i) {
        erased = erased && in[i] == ERASED_BYTE;
    }
    if (erased) {
        return IdRecordStatus::Blank;
    }
    uint16_t storedCrc = (uint16_t)(in[CRC_OFFSET] | ((uint16_t)in[CRC_OFFSET + 1] << 8));
    if (in[MAGIC_OFFSET] != SENSOR_ID_RECORD_MAGIC || crc16Xmodem(in, CRC_OFFSET) != storedCrc ||
        !getSensorIdField(in + ID_OFFSET, out)) {
        out.text[0] = '\0';
        return IdRecordStatus::Damaged;
    }
    return IdRecordStatus::Ok;
}
