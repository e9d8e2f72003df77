#include "sketch_state.h"

#include <stddef.h>
#include <vector>

// Defined by the linker for sections whose names are C identifiers; weak,
// because a section nobody puts a variable into does not exist.
extern "C" char __start_thermotilt_sketch_data[] __attribute__((weak));
extern "C" char __stop_thermotilt_sketch_data[] __attribute__((weak));
extern "C" char __start_thermotilt_sketch_bss[] __attribute__((weak));
extern "C" char __stop_thermotilt_sketch_bss[] __attribute__((weak));

namespace {

struct Section {
    char* begin;
    char* end;
    std::vector<char> atBoot;
};

Section sections[] = {
    {__start_thermotilt_sketch_data, __stop_thermotilt_sketch_data, {}},
    {__start_thermotilt_sketch_bss, __stop_thermotilt_sketch_bss, {}},
};

// Byte by byte through volatile and without ASan's checks: the sections hold
// ASan's redzones between the variables, which a memcpy would report.
__attribute__((no_sanitize("address"))) void copy(volatile char* to, const volatile char* from, size_t length)
{
    for (size_t i = 0; i < length; ++i) {
        to[i] = from[i];
    }
}

}  // namespace

void SketchState::capture()
{
    for (Section& section : sections) {
        size_t length = section.begin ? (size_t)(section.end - section.begin) : 0;
        section.atBoot.resize(length);
        copy(section.atBoot.data(), section.begin, length);
    }
}

void SketchState::restore()
{
    for (Section& section : sections) {
        copy(section.begin, section.atBoot.data(), section.atBoot.size());
    }
}
