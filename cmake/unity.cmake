# A real Unity (ThrowTheSwitch) is used when UNITY_ROOT points at one, or when
# one is found in PlatformIO's package folder; otherwise the project's small
# fallback in cmake/unity stands in. Either way output is configured by
# cmake/unity_config/unity_config.h, as PlatformIO does for its targets.
set(UNITY_ROOT "$ENV{UNITY_ROOT}" CACHE PATH "Folder of a Unity checkout (holds src/unity.c)")
set(unity_candidates "${UNITY_ROOT}" "$ENV{HOME}/.platformio/packages/tool-unity")
set(UNITY_SOURCE_DIR "")
foreach(candidate ${unity_candidates})
  if(candidate AND EXISTS "${candidate}/src/unity.c")
    set(UNITY_SOURCE_DIR "${candidate}/src")
    break()
  endif()
endforeach()
if(UNITY_SOURCE_DIR)
  message(STATUS "Unity: ${UNITY_SOURCE_DIR}")
else()
  set(UNITY_SOURCE_DIR "${CMAKE_SOURCE_DIR}/cmake/unity")
  message(STATUS "Unity: no real Unity found, using the fallback in cmake/unity")
endif()

add_library(unity STATIC "${UNITY_SOURCE_DIR}/unity.c")
target_include_directories(unity PUBLIC "${UNITY_SOURCE_DIR}" "${CMAKE_SOURCE_DIR}/cmake/unity_config")
target_compile_definitions(unity PUBLIC UNITY_INCLUDE_CONFIG_H)

file(GLOB TEST_DIRS LIST_DIRECTORIES true "${CMAKE_SOURCE_DIR}/test/test_*")
file(GLOB TEST_SHARED_SOURCES "${CMAKE_SOURCE_DIR}/test/*.cpp" "${CMAKE_SOURCE_DIR}/test/*.c")
