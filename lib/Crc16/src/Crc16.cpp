#include "Crc16.h"

#ifdef __AVR__
#include <util/crc16.h>
#endif

uint16_t crc16XmodemUpdate(uint16_t crc, uint8_t data)
{
#ifdef __AVR__
    return _crc_xmodem_update(crc, data);
#else
    // avr-libc's optimised routine exists only for AVR; this is the equivalent
    // C it documents, so host and device compute the same CRC.
    crc = (uint16_t)(crc ^ ((uint16_t)data << 8));
    for (uint8_t bit = 0; bit < 8; ++bit) {
        crc = (crc & 0x8000u) ? (uint16_t)((crc << 1) ^ 0x1021u) : (uint16_t)(crc << 1);
    }
    return crc;
#endif
}

uint16_t crc16Xmodem(const uint8_t *data, uint16_t length)
{
    uint16_t crc = 0;
    for (uint16_t i = 0; i < length; ++i) {
        crc = crc16XmodemUpdate(crc, data[i]);
    }
    return crc;
}
