#include "ResetCause.h"

namespace {

const uint8_t OTHER_THAN_WATCHDOG = ResetCause::POWER_ON_FLAG | ResetCause::EXTERNAL_FLAG | ResetCause::BROWNOUT_FLAG;

}  // namespace

bool ResetCause::wasCommanded(uint8_t flags, bool commandMarked)
{
    return commandMarked && (flags & OTHER_THAN_WATCHDOG) == 0;
}

const char* ResetCause::name(uint8_t flags, bool commandMarked)
{
    if (wasCommanded(flags, commandMarked))
        return "COMMANDED";
    if (flags & WATCHDOG_FLAG)
        return "WATCHDOG";
    if (flags & BROWNOUT_FLAG)
        return "BROWNOUT";
    if (flags & EXTERNAL_FLAG)
        return "EXTERNAL";
    if (flags & POWER_ON_FLAG)
        return "POWER_ON";
    return "UNKNOWN";
}

bool ResetCause::wasAbnormal(uint8_t flags, bool commandMarked)
{
    return !wasCommanded(flags, commandMarked) && (flags & (WATCHDOG_FLAG | BROWNOUT_FLAG)) != 0;
}
