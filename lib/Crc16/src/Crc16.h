#ifndef THERMOTILT_CRC16_H
#define THERMOTILT_CRC16_H

#include <stdint.h>

// CRC-16/XMODEM: polynomial 0x1021, initial value 0, no reflection, no final
// XOR; check value 0x31C3 for "123456789". Python: binascii.crc_hqx(data, 0).
// It detects every error of up to three flipped bits and every odd number of
// flipped bits in messages far longer than a serial line or the EEPROM block.
uint16_t crc16XmodemUpdate(uint16_t crc, uint8_t data);
uint16_t crc16Xmodem(const uint8_t *data, uint16_t length);

#endif
