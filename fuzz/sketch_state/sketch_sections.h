// Force-included (-include) before every sketch, firmware/common and lib/
// source of the fuzz build: their globals, static locals too, go to two
// sections of their own, which SketchState puts back to their values at
// boot before each input. Nothing but the placement of variables changes.
#pragma clang section bss = "thermotilt_sketch_bss" data = "thermotilt_sketch_data"
