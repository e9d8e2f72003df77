#include "CommandTable.h"

#include <string.h>

#include <ProgramMemory.h>

bool Protocol::findCommand(const Command *table, uint8_t count, const char *type, Command &found)
{
    for (uint8_t i = 0; i < count; ++i) {
        if (strcmp_P(type, (const char *)pgm_read_ptr(&table[i].tag)) == 0) {
            memcpy_P(&found, &table[i], sizeof found);
            return true;
        }
    }
    return false;
}
