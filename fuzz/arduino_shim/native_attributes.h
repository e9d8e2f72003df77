// Force-included before the firmware sources in the fuzz build. avr-gcc's
// `naked` (no prologue or epilogue, for code placed in the .init sections
// that runs before the C runtime) allows C statements; clang on x86 does
// not. Natively such a function is an ordinary one, which the harness calls
// at each boot where the AVR would run it.
#define naked
