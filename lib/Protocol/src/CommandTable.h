#ifndef THERMOTILT_COMMAND_TABLE_H
#define THERMOTILT_COMMAND_TABLE_H

// A board's commands as one table in program memory: each command's frame
// type, the function that carries it out, and how many fields it needs.
// firmware/common/SerialLink's dispatch() looks a parsed frame up in it.

#include "Protocol.h"

namespace Protocol {

typedef void (*CommandHandler)(const FrameParser &command);

struct Command {
    const char *tag;  // in program memory, as FrameType's
    CommandHandler handler;
    // A command with fewer fields is refused with ERR BAD_ARG fieldsDetail
    // and its handler is not called.
    uint8_t minFields;
    const char *fieldsDetail;
};

// A command that has no fields, or whose handler checks them itself.
constexpr Command command(FrameType type, CommandHandler handler)
{
    return Command{type.tag, handler, 0, nullptr};
}

// A command that needs all the fields of its type.
constexpr Command command(FrameType type, CommandHandler handler, const char *fieldsDetail)
{
    return Command{type.tag, handler, type.fieldCount, fieldsDetail};
}

// Copies the entry of table (count entries in program memory) whose tag is
// type into found; false when no entry has it.
bool findCommand(const Command *table, uint8_t count, const char *type, Command &found);

}  // namespace Protocol

#endif
