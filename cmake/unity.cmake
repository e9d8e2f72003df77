# A real Unity (ThrowTheSwitch) is used when UNITY_ROOT points at one, or when
# PlatformIO 6 installed one as a library for a test env
# (<libdeps_dir>/<env>/Unity, libdeps_dir found as PlatformIO finds it);
# otherwise the project's small fallback in cmake/unity stands in. Either way
# output is configured by cmake/unity_config/unity_config.h, as PlatformIO
# does for its targets. THERMOTILT_UNITY says which one a tree uses, for
# cmake/run-tests.sh.
set(UNITY_ROOT "$ENV{UNITY_ROOT}" CACHE PATH "Folder of a Unity checkout (holds src/unity.c)")
if(DEFINED ENV{PLATFORMIO_LIBDEPS_DIR})
  set(platformio_libdeps "$ENV{PLATFORMIO_LIBDEPS_DIR}")
elseif(DEFINED ENV{PLATFORMIO_WORKSPACE_DIR})
  set(platformio_libdeps "$ENV{PLATFORMIO_WORKSPACE_DIR}/libdeps")
else()
  set(platformio_libdeps "${CMAKE_SOURCE_DIR}/.pio/libdeps")
endif()
file(GLOB platformio_unity_dirs LIST_DIRECTORIES true "${platformio_libdeps}/*/Unity")
list(SORT platformio_unity_dirs)
set(UNITY_SOURCE_DIR "")
foreach(candidate "${UNITY_ROOT}" ${platformio_unity_dirs})
  if(candidate AND EXISTS "${candidate}/src/unity.c")
    set(UNITY_SOURCE_DIR "${candidate}/src")
    break()
  endif()
endforeach()
if(UNITY_SOURCE_DIR)
  file(STRINGS "${UNITY_SOURCE_DIR}/unity.h" unity_version_lines
    REGEX "^#define UNITY_VERSION_(MAJOR|MINOR|BUILD) +[0-9]+")
  set(unity_version "")
  foreach(line ${unity_version_lines})
    string(REGEX REPLACE "^#define UNITY_VERSION_[A-Z]+ +([0-9]+).*" "\\1" number "${line}")
    list(APPEND unity_version "${number}")
  endforeach()
  string(REPLACE ";" "." unity_version "${unity_version}")
  set(unity_description "ThrowTheSwitch Unity ${unity_version} from ${UNITY_SOURCE_DIR}")
else()
  set(UNITY_SOURCE_DIR "${CMAKE_SOURCE_DIR}/cmake/unity")
  set(unity_description "the fallback in cmake/unity (no real Unity: set UNITY_ROOT, or run `pio test -e native` once)")
endif()
message(STATUS "Unity: ${unity_description}")
set(THERMOTILT_UNITY "${unity_description}" CACHE INTERNAL "The Unity this tree's tests are built with")

add_library(unity STATIC "${UNITY_SOURCE_DIR}/unity.c")
target_include_directories(unity PUBLIC "${UNITY_SOURCE_DIR}" "${CMAKE_SOURCE_DIR}/cmake/unity_config")
target_compile_definitions(unity PUBLIC UNITY_INCLUDE_CONFIG_H)

file(GLOB TEST_DIRS LIST_DIRECTORIES true "${CMAKE_SOURCE_DIR}/test/test_*")
file(GLOB TEST_SHARED_SOURCES "${CMAKE_SOURCE_DIR}/test/*.cpp" "${CMAKE_SOURCE_DIR}/test/*.c")
