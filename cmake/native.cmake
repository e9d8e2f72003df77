# Host build: every Unity test as a native executable, the simavr runner and
# the digital twin's shared library.
set(PROJECT_WARNINGS -Wall -Wextra -Werror)
include(cmake/unity.cmake)

add_thermotilt_libs("${PROJECT_WARNINGS}")

foreach(dir ${TEST_DIRS})
  add_test_program("${dir}" "${PROJECT_WARNINGS}")
  get_filename_component(test_name "${dir}" NAME)
  add_test(NAME native.${test_name} COMMAND ${test_name})
endforeach()

find_library(SIMAVR_LIBRARY simavr REQUIRED)
find_path(SIMAVR_INCLUDE_DIR simavr/sim_avr.h REQUIRED)
# Position-independent, because libthermotilt_twin.so links it as well.
add_library(sim_board STATIC sim/board.c sim/byte_queue.c sim/l298n.c sim/lsm9ds0.c sim/line_noise.c sim/uart_bridge.c)
set_target_properties(sim_board PROPERTIES POSITION_INDEPENDENT_CODE ON)
target_include_directories(sim_board PUBLIC sim ${SIMAVR_INCLUDE_DIR})
target_compile_options(sim_board PRIVATE ${PROJECT_WARNINGS})
target_link_libraries(sim_board PUBLIC ${SIMAVR_LIBRARY})

add_executable(avr_run sim/avr_run.c)
target_compile_options(avr_run PRIVATE ${PROJECT_WARNINGS})
target_link_libraries(avr_run PRIVATE sim_board)

# Loaded by host/thermotilt/twin/boards.py through ctypes.
add_library(thermotilt_twin SHARED sim/twin.c)
target_compile_options(thermotilt_twin PRIVATE ${PROJECT_WARNINGS})
target_link_libraries(thermotilt_twin PRIVATE sim_board)

# `make bench`: corrupted frames the firmware's parser accepts (sim/line_noise.c is the twin's wire fault).
add_executable(integrity_bench sim/integrity_bench.cpp sim/line_noise.c)
target_include_directories(integrity_bench PRIVATE sim)
target_compile_options(integrity_bench PRIVATE ${PROJECT_WARNINGS})
target_link_libraries(integrity_bench PRIVATE thermotilt_libs)

# Loaded by host/thermotilt/native.py through ctypes: the IMU reader's
# per-sample processing (lib/ImuProcessing and what it uses) over a series,
# and the algorithms the host keeps Python copies of (lib/Program's staircase,
# lib/Compensation's trend, surface, coefficient block and sensor ID rule)
# and lib/ChamberControl's drive law
# over arrays, the same sources as the firmware, built position-independent for the host.
# No contraction into fused multiply-adds (which aarch64 hosts would emit):
# the Nano rounds every float operation on its own. --no-undefined: a source
# missing from this list fails the link, not the host's dlopen.
# Link-time optimisation and no semantic interposition let the compiler
# inline the filters into the per-sample loop across sources, which a
# replay runs on every 100 Hz sample: it halves that loop's time, and the
# outputs are still the frames the AVR sends (test_native_processing).
add_library(thermotilt_host SHARED host/native/imu_processing.cpp host/native/firmware_algorithms.cpp
  lib/ImuProcessing/src/ImuProcessing.cpp lib/Kalman/src/Kalman.cpp
  lib/Compensation/src/Compensation.cpp lib/Compensation/src/CoefficientBlock.cpp lib/Compensation/src/SensorId.cpp
  lib/Crc16/src/Crc16.cpp lib/LSM9DS0/src/LSM9DS0.cpp lib/Program/src/Program.cpp
  lib/ChamberControl/src/ChamberControl.cpp)
target_include_directories(thermotilt_host PRIVATE host/native ${LIBRARY_INCLUDES})
target_compile_options(thermotilt_host PRIVATE ${PROJECT_WARNINGS} -ffp-contract=off -fno-math-errno -fno-semantic-interposition)
target_link_options(thermotilt_host PRIVATE -Wl,--no-undefined)
set_property(TARGET thermotilt_host PROPERTY INTERPROCEDURAL_OPTIMIZATION TRUE)
target_link_libraries(thermotilt_host PRIVATE m)
