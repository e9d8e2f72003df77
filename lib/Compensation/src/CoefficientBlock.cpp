#include <string.h>

#include "Compensation.h"

#include <Crc16.h>

namespace {

const uint8_t MAGIC_OFFSET = 0;
const uint8_t VERSION_OFFSET = 1;
const uint8_t FLOATS_OFFSET = 2;
const uint8_t CRC_OFFSET = COEFFICIENT_BLOCK_SIZE - 2;
const uint8_t SURFACE_COUNT = COMP_SET_COUNT * COMP_AXIS_COUNT;
const uint8_t SURFACE_BYTES = COMP_COEFFICIENT_COUNT * 4;
// What an erased EEPROM cell reads.
const uint8_t ERASED_BYTE = 0xFF;

// Byte by byte rather than copying the struct, so the block does not depend
// on the compiler's padding or the host's byte order.
void putFloat(uint8_t* out, float value)
{
    uint32_t bits;
    memcpy(&bits, &value, sizeof(bits));
    for (uint8_t i = 0; i < 4; ++i) {
        out[i] = (uint8_t)(bits >> (8 * i));
    }
}

float getFloat(const uint8_t* in)
{
    uint32_t bits = 0;
    for (uint8_t i = 0; i < 4; ++i) {
        bits |= (uint32_t)in[i] << (8 * i);
    }
    float value;
    memcpy(&value, &bits, sizeof(value));
    return value;
}

// The index-th surface of the block, in block order (set, then axis).
AxisSurface surfaceFromBlock(const uint8_t* in, uint8_t index)
{
    AxisSurface surface;
    const uint8_t* cursor = in + FLOATS_OFFSET + index * SURFACE_BYTES;
    for (uint8_t k = 0; k < COMP_COEFFICIENT_COUNT; ++k) {
        surface.p[k] = getFloat(cursor + 4 * k);
    }
    return surface;
}

bool isErased(const uint8_t* in)
{
    for (uint8_t i = 0; i < COEFFICIENT_BLOCK_SIZE; ++i) {
        if (in[i] != ERASED_BYTE) {
            return false;
        }
    }
    return true;
}

}  // namespace

void encodeCoefficients(const Coefficients& in, uint8_t out[COEFFICIENT_BLOCK_SIZE])
{
    out[MAGIC_OFFSET] = COEFFICIENT_BLOCK_MAGIC;
    out[VERSION_OFFSET] = COEFFICIENT_BLOCK_VERSION;
    uint8_t* cursor = out + FLOATS_OFFSET;
    for (uint8_t s = 0; s < COMP_SET_COUNT; ++s) {
        for (uint8_t a = 0; a < COMP_AXIS_COUNT; ++a) {
            for (uint8_t k = 0; k < COMP_COEFFICIENT_COUNT; ++k) {
                putFloat(cursor, in.set[s].axis[a].p[k]);
                cursor += 4;
            }
        }
    }
    uint16_t crc = crc16Xmodem(out, CRC_OFFSET);
    out[CRC_OFFSET] = (uint8_t)crc;
    out[CRC_OFFSET + 1] = (uint8_t)(crc >> 8);
}

BlockStatus decodeCoefficients(const uint8_t in[COEFFICIENT_BLOCK_SIZE], Coefficients& out)
{
    if (isErased(in)) {
        return BlockStatus::Blank;
    }
    if (in[MAGIC_OFFSET] != COEFFICIENT_BLOCK_MAGIC) {
        return BlockStatus::BadMagic;
    }
    if (in[VERSION_OFFSET] != COEFFICIENT_BLOCK_VERSION) {
        return BlockStatus::BadVersion;
    }
    uint16_t storedCrc = (uint16_t)(in[CRC_OFFSET] | ((uint16_t)in[CRC_OFFSET + 1] << 8));
    if (crc16Xmodem(in, CRC_OFFSET) != storedCrc) {
        return BlockStatus::BadCrc;
    }
    for (uint8_t i = 0; i < SURFACE_COUNT; ++i) {
        if (!surfaceOutputFitsFrame(surfaceFromBlock(in, i))) {
            return BlockStatus::BadValues;
        }
    }
    for (uint8_t i = 0; i < SURFACE_COUNT; ++i) {
        out.set[i / COMP_AXIS_COUNT].axis[i % COMP_AXIS_COUNT] = surfaceFromBlock(in, i);
    }
    return BlockStatus::Ok;
}
