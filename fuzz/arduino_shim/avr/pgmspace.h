// Natively flash and RAM are one address space.
#ifndef THERMOTILT_FUZZ_AVR_PGMSPACE_H
#define THERMOTILT_FUZZ_AVR_PGMSPACE_H

#include <stdint.h>
#include <string.h>

#define PROGMEM
#define PSTR(text) (text)
#define pgm_read_byte(address) (*(const uint8_t*)(address))
#define pgm_read_word(address) (*(const uint16_t*)(address))
#define pgm_read_dword(address) (*(const uint32_t*)(address))
#define pgm_read_float(address) (*(const float*)(address))
#define pgm_read_ptr(address) (*(const void* const*)(address))
#define strcpy_P strcpy
#define strcmp_P strcmp
#define strlen_P strlen
#define memcpy_P memcpy

#endif
