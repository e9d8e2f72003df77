// The sketch's RAM as it is at boot, before setup(): every global of the
// sketch, firmware/common and lib/ sources after static construction (they
// live in the sections of sketch_sections.h). Put back before each boot the
// harness simulates, since each fuzz input starts a fresh board and a reset
// re-initialises RAM; .noinit variables are left alone, as on the AVR.
#ifndef THERMOTILT_FUZZ_SKETCH_STATE_H
#define THERMOTILT_FUZZ_SKETCH_STATE_H

namespace SketchState {

// Once, before any input: after static construction, before setup().
void capture();
void restore();

}  // namespace SketchState

#endif
