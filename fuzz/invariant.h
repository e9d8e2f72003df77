// An invariant of the code under test. A violation aborts, which libFuzzer
// reports as a crash, keeping the input that caused it.
#ifndef THERMOTILT_FUZZ_INVARIANT_H
#define THERMOTILT_FUZZ_INVARIANT_H

#include <stdio.h>
#include <stdlib.h>

inline void require(bool holds, const char* what)
{
    if (!holds) {
        fprintf(stderr, "invariant violated: %s\n", what);
        abort();
    }
}

#endif
