#ifndef THERMOTILT_FUZZ_AVR_INTERRUPT_H
#define THERMOTILT_FUZZ_AVR_INTERRUPT_H

// Nothing interrupts a fuzz target: the harness calls loop() between events.
inline void cli() {}
inline void sei() {}

#endif
