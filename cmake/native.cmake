# Host build: every Unity test as a native executable, and the simavr runner.
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
add_library(sim_board STATIC sim/board.c sim/lsm9ds0.c)
target_include_directories(sim_board PUBLIC sim ${SIMAVR_INCLUDE_DIR})
target_compile_options(sim_board PRIVATE ${PROJECT_WARNINGS})
target_link_libraries(sim_board PUBLIC ${SIMAVR_LIBRARY})

add_executable(avr_run sim/avr_run.c)
target_compile_options(avr_run PRIVATE ${PROJECT_WARNINGS})
target_link_libraries(avr_run PRIVATE sim_board)
