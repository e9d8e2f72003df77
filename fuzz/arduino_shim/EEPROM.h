// The EEPROM library over the shim's in-memory EEPROM. An address outside it
// aborts: on the AVR it would silently wrap onto other data.
#ifndef THERMOTILT_FUZZ_EEPROM_H
#define THERMOTILT_FUZZ_EEPROM_H

#include <stdint.h>

class EEPROMClass {
public:
    uint8_t read(int address);
    void write(int address, uint8_t value);
    // The real one skips unchanged bytes to spare the cells; the same here.
    void update(int address, uint8_t value);
    uint16_t length();
    uint8_t& operator[](int address);

    template <typename T>
    T& get(int address, T& value)
    {
        uint8_t* bytes = (uint8_t*)&value;
        for (unsigned i = 0; i < sizeof(T); ++i) {
            bytes[i] = read(address + (int)i);
        }
        return value;
    }

    template <typename T>
    const T& put(int address, const T& value)
    {
        const uint8_t* bytes = (const uint8_t*)&value;
        for (unsigned i = 0; i < sizeof(T); ++i) {
            update(address + (int)i, bytes[i]);
        }
        return value;
    }
};

extern EEPROMClass EEPROM;

#endif
