// avr-libc's CRC-16/XMODEM step, from its documented C equivalent.
#ifndef THERMOTILT_FUZZ_UTIL_CRC16_H
#define THERMOTILT_FUZZ_UTIL_CRC16_H

#include <stdint.h>

static inline uint16_t _crc_xmodem_update(uint16_t crc, uint8_t data)
{
    crc = (uint16_t)(crc ^ ((uint16_t)data << 8));
    for (uint8_t i = 0; i < 8; ++i) {
        crc = (uint16_t)(crc & 0x8000 ? (crc << 1) ^ 0x1021 : crc << 1);
    }
    return crc;
}

#endif
