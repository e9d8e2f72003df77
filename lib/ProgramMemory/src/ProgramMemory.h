// Constant data in program memory: on the AVR, PROGMEM keeps it in flash,
// where avr-libc's pgm_read_* and *_P functions read it, instead of copying
// it into RAM at start-up (2 KB on the Nano). Elsewhere flash and RAM are one
// address space: PROGMEM is nothing and the names are the plain reads and
// functions. The fuzz targets' Arduino shim defines the same names alike.
#ifndef THERMOTILT_PROGRAM_MEMORY_H
#define THERMOTILT_PROGRAM_MEMORY_H

#ifdef __AVR__
#include <avr/pgmspace.h>
#else
#include <stdint.h>
#include <string.h>

#ifndef PROGMEM
#define PROGMEM
#endif
#ifndef pgm_read_word
#define pgm_read_word(address) (*(const uint16_t*)(address))
#endif
#ifndef pgm_read_dword
#define pgm_read_dword(address) (*(const uint32_t*)(address))
#endif
#ifndef pgm_read_float
#define pgm_read_float(address) (*(const float*)(address))
#endif
#ifndef pgm_read_ptr
#define pgm_read_ptr(address) (*(const void* const*)(address))
#endif
#ifndef strcmp_P
#define strcmp_P strcmp
#endif
#ifndef strncpy_P
#define strncpy_P strncpy
#endif
#ifndef memcpy_P
#define memcpy_P memcpy
#endif
#endif

#endif
