# AVR build for one MCU (AVR_MCU): Arduino core from Debian's arduino-core-avr,
# the firmware image for that board, and every Unity test run in simavr.
set(AVR_MCU "atmega328p" CACHE STRING "atmega328p (Arduino Nano) or atmega2560 (Arduino Mega 2560)")
set(AVR_FREQUENCY 16000000)
set(ARDUINO_AVR_DIR "/usr/share/arduino/hardware/arduino/avr" CACHE PATH "Arduino AVR core (Debian arduino-core-avr)")
set(AVR_RUN "" CACHE FILEPATH "The simavr runner built by the native configuration")

if(AVR_MCU STREQUAL "atmega328p")
  set(ARDUINO_VARIANT eightanaloginputs)
  set(ARDUINO_BOARD_DEFINE ARDUINO_AVR_NANO)
  set(FIRMWARES imu_reader)
elseif(AVR_MCU STREQUAL "atmega2560")
  set(ARDUINO_VARIANT mega)
  set(ARDUINO_BOARD_DEFINE ARDUINO_AVR_MEGA2560)
  set(FIRMWARES thermal_chamber)
else()
  message(FATAL_ERROR "AVR_MCU must be atmega328p or atmega2560, not '${AVR_MCU}'")
endif()
if(NOT EXISTS "${ARDUINO_AVR_DIR}/cores/arduino/Arduino.h")
  message(FATAL_ERROR "No Arduino AVR core at ${ARDUINO_AVR_DIR}: install Debian's arduino-core-avr")
endif()

# avr-gcc folds identical constants into one (-fipa-icf-variables) even when
# one is PROGMEM and the other in RAM, so one of them is read from the wrong
# memory: a PROGMEM {1, 5, 25, 125} beside the same table in RAM read 146 at
# index 3 without LTO and 0 from the RAM copy with it (simavr, gcc-avr 5.4).
add_compile_options(-mmcu=${AVR_MCU} -Os -ffunction-sections -fdata-sections -flto -fno-ipa-icf-variables
  $<$<COMPILE_LANGUAGE:CXX>:-fno-exceptions> $<$<COMPILE_LANGUAGE:CXX>:-fno-threadsafe-statics>)
add_compile_definitions(F_CPU=${AVR_FREQUENCY}L ARDUINO=10807 ARDUINO_ARCH_AVR ${ARDUINO_BOARD_DEFINE})
add_link_options(-mmcu=${AVR_MCU} -Os -flto -fuse-linker-plugin -Wl,--gc-sections)
set(PROJECT_WARNINGS -Wall -Wextra -Werror)
set(CMAKE_EXECUTABLE_SUFFIX .elf)
include(cmake/unity.cmake)

set(core_dir "${ARDUINO_AVR_DIR}/cores/arduino")
file(GLOB core_sources "${core_dir}/*.c" "${core_dir}/*.cpp" "${core_dir}/*.S")
add_library(arduino_core STATIC ${core_sources})
target_include_directories(arduino_core PUBLIC "${core_dir}" "${ARDUINO_AVR_DIR}/variants/${ARDUINO_VARIANT}"
  "${ARDUINO_AVR_DIR}/libraries/EEPROM/src")
# The core is third-party code: build it quietly, as the Arduino IDE does. (Not
# as SYSTEM includes: avr-gcc wraps system headers in extern "C".)
target_compile_options(arduino_core PRIVATE -w)
# gcc-avr 5.4 does not define DECIMAL_DIG in C++ mode, which WString.cpp needs.
set_source_files_properties("${core_dir}/WString.cpp" PROPERTIES COMPILE_DEFINITIONS DECIMAL_DIG=17)

add_thermotilt_libs("${PROJECT_WARNINGS}")

target_sources(unity PRIVATE "${CMAKE_SOURCE_DIR}/cmake/unity_config/unity_config_avr.cpp")
target_link_libraries(unity PUBLIC arduino_core)

function(add_hex_and_size target)
  add_custom_command(TARGET ${target} POST_BUILD
    COMMAND ${CMAKE_OBJCOPY} -O ihex -R .eeprom $<TARGET_FILE:${target}> $<TARGET_FILE_DIR:${target}>/${target}.hex
    COMMAND ${CMAKE_SIZE} --format=avr --mcu=${AVR_MCU} $<TARGET_FILE:${target}>
    VERBATIM)
endfunction()

foreach(firmware ${FIRMWARES})
  file(GLOB sources "${CMAKE_SOURCE_DIR}/firmware/${firmware}/*.cpp" "${CMAKE_SOURCE_DIR}/firmware/common/*.cpp")
  add_executable(${firmware} ${sources})
  target_include_directories(${firmware} PRIVATE "${CMAKE_SOURCE_DIR}/firmware/common")
  target_compile_options(${firmware} PRIVATE ${PROJECT_WARNINGS})
  target_link_libraries(${firmware} PRIVATE thermotilt_libs arduino_core m)
  add_hex_and_size(${firmware})
endforeach()

# The SRAM every test program's stack must leave untouched (avr_run fails it
# otherwise): what a test program's RAM varies by between builds (the Unity
# it runs, the compiler, the length of its source path) must not reach the
# stack. docs/testing.md gives each program's figures.
set(TEST_MIN_STACK_BYTES 256)
foreach(dir ${TEST_DIRS})
  add_test_program("${dir}" "${PROJECT_WARNINGS}")
  get_filename_component(test_name "${dir}" NAME)
  if(AVR_RUN)
    add_test(NAME ${AVR_MCU}.${test_name}
      COMMAND ${AVR_RUN} -m ${AVR_MCU} -f ${AVR_FREQUENCY} -t 600 --unity --min-stack ${TEST_MIN_STACK_BYTES}
        $<TARGET_FILE:${test_name}>)
  endif()
endforeach()
