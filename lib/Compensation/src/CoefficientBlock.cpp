#include <string.h>

#include "Compensation.h"

#include <Crc16.h>

namespace {

const uint8_t MAGIC_OFFSET = 0;
const uint8_t VERSION_OFFSET = 1;
const uint8_t FLOATS_OFFSET = 2;
const uint8_t SURFACE_COUNT = COMP_SET_COUNT * COMP_AXIS_COUNT;
const uint8_t SURFACE_BYTES = COMP_COEFFICIENT_COUNT * 4;
const uint8_t SENSOR_ID_OFFSET = FLOATS_OFFSET + SURFACE_COUNT * SURFACE_BYTES;
const uint8_t DOMAIN_OFFSET = SENSOR_ID_OFFSET + SENSOR_ID_LENGTH;
// Per set: the temperature range, then one range per axis; two int16 each.
const uint8_t SET_DOMAIN_BYTES = (1 + COMP_AXIS_COUNT) * 4;
const uint8_t CRC_OFFSET = DOMAIN_OFFSET + COMP_SET_COUNT * SET_DOMAIN_BYTES;
const uint8_t V1_CRC_OFFSET = COEFFICIENT_BLOCK_V1_SIZE - 2;
static_assert(CRC_OFFSET + 2 == COEFFICIENT_BLOCK_SIZE, "the version 2 layout fills the block");
static_assert(SENSOR_ID_OFFSET == V1_CRC_OFFSET, "version 2 keeps version 1's surfaces where they were");
// What an erased EEPROM cell reads.
const uint8_t ERASED_BYTE = 0xFF;

// Writes the block in order, byte by byte, with its CRC as it goes. Values
// go out least significant byte first rather than as the struct's bytes, so
// the block does not depend on the compiler's padding or the host's byte order.
class BlockEncoder {
public:
    BlockEncoder(WriteBlockByte write, void* context) : write_(write), context_(context), index_(0), crc_(0) {}

    void put(uint8_t value)
    {
        write_(context_, index_++, value);
        crc_ = crc16XmodemUpdate(crc_, value);
    }

    void putBits(uint32_t bits, uint8_t bytes)
    {
        for (uint8_t i = 0; i < bytes; ++i) {
            put((uint8_t)(bits >> (8 * i)));
        }
    }

    void putFloat(float value)
    {
        uint32_t bits;
        memcpy(&bits, &value, sizeof(bits));
        putBits(bits, 4);
    }

    void putRange(Int16Range range)
    {
        putBits((uint16_t)range.min, 2);
        putBits((uint16_t)range.max, 2);
    }

    void putCrc()
    {
        uint16_t crc = crc_;
        put((uint8_t)crc);
        put((uint8_t)(crc >> 8));
    }

private:
    WriteBlockByte write_;
    void* context_;
    uint8_t index_;
    uint16_t crc_;
};

class BlockDecoder {
public:
    BlockDecoder(ReadBlockByte read, const void* context) : read_(read), context_(context) {}

    uint8_t at(uint8_t index) const { return read_(context_, index); }

    uint32_t bits(uint8_t index, uint8_t bytes) const
    {
        uint32_t value = 0;
        for (uint8_t i = 0; i < bytes; ++i) {
            value |= (uint32_t)at((uint8_t)(index + i)) << (8 * i);
        }
        return value;
    }

    Int16Range range(uint8_t index) const
    {
        Int16Range value = {(int16_t)(uint16_t)bits(index, 2), (int16_t)(uint16_t)bits((uint8_t)(index + 2), 2)};
        return value;
    }

    // The index-th surface, in block order (set, then axis).
    AxisSurface surface(uint8_t index) const
    {
        AxisSurface value;
        uint8_t offset = (uint8_t)(FLOATS_OFFSET + index * SURFACE_BYTES);
        for (uint8_t k = 0; k < COMP_COEFFICIENT_COUNT; ++k) {
            uint32_t word = bits((uint8_t)(offset + 4 * k), 4);
            memcpy(&value.p[k], &word, sizeof(word));
        }
        return value;
    }

    bool erased() const
    {
        for (uint8_t i = 0; i < COEFFICIENT_BLOCK_SIZE; ++i) {
            if (at(i) != ERASED_BYTE) {
                return false;
            }
        }
        return true;
    }

    bool crcHolds(uint8_t crcOffset) const
    {
        uint16_t crc = 0;
        for (uint8_t i = 0; i < crcOffset; ++i) {
            crc = crc16XmodemUpdate(crc, at(i));
        }
        return crc == (uint16_t)bits(crcOffset, 2);
    }

    bool idField(SensorId& out) const
    {
        uint8_t field[SENSOR_ID_LENGTH];
        for (uint8_t i = 0; i < SENSOR_ID_LENGTH; ++i) {
            field[i] = at((uint8_t)(SENSOR_ID_OFFSET + i));
        }
        return getSensorIdField(field, out);
    }

private:
    ReadBlockByte read_;
    const void* context_;
};

uint8_t readArrayByte(const void* context, uint8_t index)
{
    return static_cast<const uint8_t*>(context)[index];
}

void writeArrayByte(void* context, uint8_t index, uint8_t value)
{
    static_cast<uint8_t*>(context)[index] = value;
}

}  // namespace

void encodeCoefficients(const Coefficients& in, const CalibratedDomain& domain, const char* sensorId,
                        WriteBlockByte write, void* context)
{
    BlockEncoder out(write, context);
    out.put(COEFFICIENT_BLOCK_MAGIC);
    out.put(COEFFICIENT_BLOCK_VERSION);
    for (uint8_t s = 0; s < COMP_SET_COUNT; ++s) {
        for (uint8_t a = 0; a < COMP_AXIS_COUNT; ++a) {
            for (uint8_t k = 0; k < COMP_COEFFICIENT_COUNT; ++k) {
                out.putFloat(in.set[s].axis[a].p[k]);
            }
        }
    }
    uint8_t field[SENSOR_ID_LENGTH];
    putSensorIdField(field, sensorId);
    for (uint8_t i = 0; i < SENSOR_ID_LENGTH; ++i) {
        out.put(field[i]);
    }
    for (uint8_t s = 0; s < COMP_SET_COUNT; ++s) {
        out.putRange(domain.set[s].temperatureCentiC);
        for (uint8_t a = 0; a < COMP_AXIS_COUNT; ++a) {
            out.putRange(domain.set[s].accelLsb[a]);
        }
    }
    out.putCrc();
}

void encodeCoefficients(const Coefficients& in, const CalibratedDomain& domain, const char* sensorId,
                        uint8_t out[COEFFICIENT_BLOCK_SIZE])
{
    encodeCoefficients(in, domain, sensorId, writeArrayByte, out);
}

BlockStatus decodeCoefficients(ReadBlockByte read, const void* context, const char* boardSensorId, Coefficients& out,
                               CalibratedDomain& domain)
{
    BlockDecoder in(read, context);
    if (in.erased()) {
        return BlockStatus::Blank;
    }
    if (in.at(MAGIC_OFFSET) != COEFFICIENT_BLOCK_MAGIC) {
        return BlockStatus::BadMagic;
    }
    uint8_t version = in.at(VERSION_OFFSET);
    if (version != 1 && version != COEFFICIENT_BLOCK_VERSION) {
        return BlockStatus::BadVersion;
    }
    if (!in.crcHolds(version == 1 ? V1_CRC_OFFSET : CRC_OFFSET)) {
        return BlockStatus::BadCrc;
    }
    for (uint8_t i = 0; i < SURFACE_COUNT; ++i) {
        if (!surfaceOutputFitsFrame(in.surface(i))) {
            return BlockStatus::BadValues;
        }
    }
    if (version != 1) {
        SensorId fittedFor;
        if (!in.idField(fittedFor)) {
            return BlockStatus::BadValues;
        }
        if (fittedFor.text[0] != '\0' && strcmp(fittedFor.text, boardSensorId) != 0) {
            return BlockStatus::OtherSensor;
        }
    }
    for (uint8_t i = 0; i < SURFACE_COUNT; ++i) {
        out.set[i / COMP_AXIS_COUNT].axis[i % COMP_AXIS_COUNT] = in.surface(i);
    }
    if (version == 1) {
        clearDomain(domain);
        return BlockStatus::Ok;
    }
    uint8_t offset = DOMAIN_OFFSET;
    for (uint8_t s = 0; s < COMP_SET_COUNT; ++s) {
        domain.set[s].temperatureCentiC = in.range(offset);
        offset += 4;
        for (uint8_t a = 0; a < COMP_AXIS_COUNT; ++a) {
            domain.set[s].accelLsb[a] = in.range(offset);
            offset += 4;
        }
    }
    return BlockStatus::Ok;
}

BlockStatus decodeCoefficients(const uint8_t in[COEFFICIENT_BLOCK_SIZE], const char* boardSensorId, Coefficients& out,
                               CalibratedDomain& domain)
{
    return decodeCoefficients(readArrayByte, in, boardSensorId, out, domain);
}
